"""segmentation_node: camera ``Image`` (or ``CompressedImage``, ``image_transport:
compressed``) -> ``HandObservation`` (per-pixel glove colour classification, mean-shift crop,
40x40 tiny label image, patch blobs).

A frame is segmented only when its camera model is known: with ``use_camera_info`` (default)
the newest ``camera/camera_info`` must have the image's size and frame_id, else camera
``camera_index`` of ``calibration_file`` its size; other frames give 'camera: ...'
observations without a hand. With ``hand: left`` (a left hand in the mirror-image glove) the
published observation is that of the mirrored image (``core.hand.handedness``), the query the
right-hand database and tracker serve; ik_node with the same ``hand`` mirrors the pose back.
An extra camera's segmentation_node runs in the camera's
namespace ``NS`` (``NS/camera/image_raw``, ``NS/camera/camera_info`` -> ``NS/hand/observation``,
which ik_node's ``extra_observation_topics`` names). The segmenter's settings
(``segmenter.<name>``) and ``publish_debug_image`` can be changed at run time; health goes to
``/diagnostics``.

Crop prediction: the node keeps the newest crop window ik_node predicts from a tracked frame
(``hand/crop_prediction``, ``core.segmentation.crop_prediction.CropFeedback``) and gives it to
the segmenter of every frame at most ``prediction_max_age_s`` newer than that tracked frame
with the same frame_id (older: stale, ignored); the segmenter uses it when its
``prediction_margin`` is above 0 (the node subscribes only then)."""
from __future__ import annotations

import sys
import traceback
from array import array
from collections.abc import Callable
from typing import Any

import numpy as np
from builtin_interfaces.msg import Time
from colorglove_msgs.msg import HandObservation
from geometry_msgs.msg import PolygonStamped
from rclpy.node import Node
from sensor_msgs.msg import CompressedImage, Image
from std_msgs.msg import Header

from colorglove_ros.core.camera import load_calibration
from colorglove_ros.core.hand.glove import GLOVE_PALETTE_RGB
from colorglove_ros.core.hand.handedness import DEFAULT_HAND, mirror_observation
from colorglove_ros.core.pipeline import NoHand, bad_image, segment_frame
from colorglove_ros.core.segmentation.color_model import ColorCalibrationError
from colorglove_ros.core.segmentation.crop_prediction import (
    DEFAULT_PREDICTION_MAX_AGE_S,
    CropFeedback,
)
from colorglove_ros.core.segmentation.segmenter import (
    SegmentationConfigError,
    load_segmenter,
)
from colorglove_ros.core.segmentation.types import Observation
from colorglove_ros.core.validation import (
    SEGMENTER_RULES,
    validate_image_size,
    validate_segmenter_settings,
)
from colorglove_ros.paths import resolve_path
from colorglove_ros.ros.conversions import (
    crop_prediction_from_msg,
    observation_to_msg,
    stamp_to_seconds,
)
from colorglove_ros.ros.diagnostics import FrameStats
from colorglove_ros.ros.image import (
    ImageEncodingError,
    array_to_image,
    compressed_image_to_rgb8,
    image_to_rgb8,
)
from colorglove_ros.ros.image_codec import image_from_cdr
from colorglove_ros.ros.nodes.common import (
    CROP_PREDICTION_TOPIC,
    LATEST_IMAGE,
    LATEST_ONLY,
    OBSERVATION_TOPIC,
    StartupError,
    calibrated_camera,
    declare,
    declare_calibration_file,
    declare_camera_index,
    declare_frame_camera,
    declare_hand,
    declare_opencv_threads,
    run_node,
    startup_errors,
)
from colorglove_ros.ros.nodes.diagnostics_publisher import DiagnosticsPublisher
from colorglove_ros.ros.nodes.live_parameters import Apply, LiveParameters

# Label image -> colours for the debug image: background black, glove colours as printed.
DEBUG_PALETTE = np.vstack([[0, 0, 0], GLOVE_PALETTE_RGB]).astype(np.uint8)
IMAGE_TOPIC = 'camera/image_raw'
# image_transport's transports this node reads: raw Image on the base topic, CompressedImage
# (jpeg, png) on '<base topic>/compressed'
IMAGE_TRANSPORTS = ('raw', 'compressed')
SEGMENTER_PARAMETER_PREFIX = 'segmenter.'


def _parameter_value(value: Any) -> Any:
    """A segmenter setting as a parameter value: a sequence of ints (a checked setting's tuple,
    an integer-array parameter's array) as a list, anything else as it is."""
    return list(value) if isinstance(value, (tuple, list, array)) else value


class SegmentationNode(Node):
    """Segments every camera frame into a glove observation."""

    def __init__(self, **kwargs) -> None:
        super().__init__('segmentation', **kwargs)
        declare_opencv_threads(self)
        config = declare(self, 'color_calibration_file', 'config/color_calibration.yaml',
                         'colour calibration config YAML (calibration file + segmenter settings)')
        transport = declare(self, 'image_transport', 'raw',
                            'raw: sensor_msgs/Image on camera/image_raw; compressed: '
                            'sensor_msgs/CompressedImage (jpeg, png) on '
                            'camera/image_raw/compressed, as image_transport names it')
        calibration_file = declare_calibration_file(
            self, 'camera calibration YAML (camera camera_index: the image size expected when '
                  'use_camera_info is false)')
        camera_index = declare_camera_index(
            self, 'which camera of calibration_file this node segments (used when '
                  'use_camera_info is false)')
        if transport not in IMAGE_TRANSPORTS:
            raise StartupError(f'segmentation_node cannot start: image_transport {transport!r} '
                               f'is not one of {", ".join(IMAGE_TRANSPORTS)}')
        try:
            self.segmenter = load_segmenter(config)
        except (ColorCalibrationError, OSError, ValueError) as exc:
            raise StartupError(f'segmentation_node cannot start: {exc}') from exc
        with startup_errors('segmentation_node', ValueError):
            calibration = load_calibration(resolve_path(calibration_file))
            camera = calibrated_camera(calibration, camera_index, calibration_file)
        self.live = LiveParameters(self)
        self.publish_debug = self.live.declare(
            'publish_debug_image', False,
            'also publish the per-pixel classification as an image on hand/segmentation_debug',
            self._check_publish_debug)
        self._declare_segmenter_settings()
        self.feedback = CropFeedback(self.live.declare(
            'prediction_max_age_s', DEFAULT_PREDICTION_MAX_AGE_S,
            'a crop prediction from ik_node (hand/crop_prediction) serves the frames at most '
            'this many seconds newer than its tracked frame (0: never; used when the '
            'segmenter\'s prediction_margin > 0)', self._check_prediction_max_age, 0.0, 10.0))
        # the size of the last frame segmented: a prediction comes from such a frame (the
        # message does not carry the image size)
        self.frame_size: tuple[int, int] = (0, 0)
        self.prediction_frame_id = ''
        self.prediction_subscription = None
        self._subscribe_predictions_if_used()
        self.hand = declare_hand(self, 'segmentation_node')
        self.frame_camera = declare_frame_camera(self, camera)
        self.stats = FrameStats({'camera': self.frame_camera.refused})
        self.diagnostics = DiagnosticsPublisher(self, 'segmentation', camera.frame_id,
                                                self.stats)
        self.publisher = self.create_publisher(HandObservation, OBSERVATION_TOPIC, 10)
        self.debug_publisher = self.create_publisher(Image, 'hand/segmentation_debug', 2)
        if transport == 'compressed':
            topic = f'{self.resolve_topic_name(IMAGE_TOPIC)}/compressed'
            self.create_subscription(CompressedImage, topic, self.on_compressed_image,
                                     LATEST_IMAGE)
        else:
            topic = IMAGE_TOPIC
            # serialized: the pixels are read in place, not converted to a Python message
            self.create_subscription(Image, topic, self.on_serialized_image, LATEST_IMAGE,
                                     raw=True)
        self.get_logger().info(f'colour calibration from {config}; {transport} images on {topic}')

    # ------------------------------------------------------------------ run-time parameters
    def _check_publish_debug(self, value: Any) -> Apply:
        def apply() -> None:
            self.publish_debug = bool(value)
        return apply

    def _declare_segmenter_settings(self) -> None:
        """``segmenter.<name>`` for every segmenter setting (``SEGMENTER_RULES``), starting
        from the colour config's values; a value given at start-up is applied like a later
        change."""
        start = {}
        for name, value in self.segmenter.settings().items():
            kind, low, high, _ = SEGMENTER_RULES[name]
            start[name] = _parameter_value(self.live.declare(
                SEGMENTER_PARAMETER_PREFIX + name, _parameter_value(value),
                f'segmenter setting {name} (starts from color_calibration_file)',
                lambda v, name=name: self._check_segmenter_setting(name, v),
                *((low, high) if kind != 'ints' else ())))
        changed = {name: value for name, value in start.items()
                   if value != _parameter_value(self.segmenter.settings()[name])}
        if changed:
            with startup_errors('segmentation_node'):
                self.segmenter = self.segmenter.fresh(**changed)

    def _check_prediction_max_age(self, value: Any) -> Apply:
        max_age = CropFeedback(float(value)).max_age_s   # checked by the feedback's own rule

        def apply() -> None:
            self.feedback.max_age_s = max_age
        return apply

    def on_crop_prediction(self, msg: PolygonStamped) -> None:
        """Keep ik_node's newest crop prediction (for the size of the frames segmented)."""
        try:
            prediction = crop_prediction_from_msg(msg, self.frame_size)
        except ValueError as exc:
            self.get_logger().warn(f'crop prediction ignored: {exc}', throttle_duration_sec=1.0)
            return
        self.feedback.offer(prediction)
        self.prediction_frame_id = msg.header.frame_id

    def _check_segmenter_setting(self, name: str, value: Any) -> Apply:
        checked = validate_segmenter_settings({name: _parameter_value(value)},
                                              'segmenter parameter',
                                              SegmentationConfigError)[name]

        def apply() -> None:
            self.segmenter = self.segmenter.fresh(**{name: checked})
            self._subscribe_predictions_if_used()
        return apply

    def _subscribe_predictions_if_used(self) -> None:
        """Subscribe to ik_node's crop predictions while the segmenter uses them
        (``prediction_margin`` > 0), and not otherwise: ik_node computes and publishes a
        prediction only for a subscriber."""
        used = self.segmenter.settings()['prediction_margin'] > 0
        if used and self.prediction_subscription is None:
            self.prediction_subscription = self.create_subscription(
                PolygonStamped, CROP_PREDICTION_TOPIC, self.on_crop_prediction, LATEST_ONLY)
        elif not used and self.prediction_subscription is not None:
            self.destroy_subscription(self.prediction_subscription)
            self.prediction_subscription = None
            self.feedback.clear()

    # ------------------------------------------------------------------ frames
    def _segment(self, header: Header, rgb: np.ndarray) -> Observation | NoHand:
        """The frame's observation (``core.pipeline.segment_frame``), or 'no hand' when its
        camera model is not known."""
        height, width = rgb.shape[:2]
        camera = self.frame_camera.camera_for(width, height, header.frame_id)
        if isinstance(camera, NoHand):
            return camera
        self.frame_size = (width, height)
        prediction = None
        if header.frame_id == self.prediction_frame_id:
            prediction = self.feedback.for_frame(stamp_to_seconds(header.stamp))
        # the static background learns from the frame after its observation is published
        observation = segment_frame(self.segmenter, rgb, keep_labels=self.publish_debug,
                                    prediction=prediction, defer_learning=True)
        if self.hand == DEFAULT_HAND or isinstance(observation, NoHand):
            return observation
        # a left hand's query is the mirrored image's (the debug image stays as seen)
        mirrored = mirror_observation(observation, camera.cx)
        mirrored.label_image = observation.label_image
        return mirrored

    def on_image(self, image: Image) -> None:
        """Segment one raw frame."""
        def decode() -> np.ndarray:
            validate_image_size(image.width, image.height, error=ImageEncodingError)
            return image_to_rgb8(image)
        self._process(image.header, (image.width, image.height), decode)

    def on_serialized_image(self, data: bytes) -> None:
        """Segment one raw frame received serialized (``ros.image_codec.image_from_cdr``: its
        pixels are a view of the received bytes)."""
        try:
            image = image_from_cdr(data)
        except ImageEncodingError as exc:   # no header to answer with: counted and logged
            self.get_logger().error(f'bad image: {exc}', throttle_duration_sec=1.0)
            self.stats.no_hand(bad_image(exc).reason, error=True)
            return
        header = Header(frame_id=image.frame_id,
                        stamp=Time(sec=image.stamp_sec, nanosec=image.stamp_nanosec))

        def decode() -> np.ndarray:
            validate_image_size(image.width, image.height, error=ImageEncodingError)
            return image_to_rgb8(image, read_only=True)
        self._process(header, (image.width, image.height), decode)

    def on_compressed_image(self, image: CompressedImage) -> None:
        """Decode and segment one compressed frame."""
        self._process(image.header, (0, 0), lambda: compressed_image_to_rgb8(image))

    def _process(self, header: Header, size: tuple[int, int],
                 decode: Callable[[], np.ndarray]) -> None:
        """Answer one frame (:meth:`_answer`), then let the segmenter learn from it: the
        static background's learning is needed only by the next frame, so it runs after the
        observation is published, off the frame's latency. A failure of the learning is
        logged and counted as a fault in the diagnostics; the node keeps running."""
        try:
            self._answer(header, size, decode)
        finally:
            try:
                self.segmenter.learn_deferred()
            except Exception as exc:   # a frame must never stop the node
                self.stats.fault(f'background learning: {exc!r}')
                self.get_logger().error(f'background learning failed: {exc!r}\n'
                                        f'{traceback.format_exc()}', throttle_duration_sec=1.0)

    def _answer(self, header: Header, size: tuple[int, int],
                decode: Callable[[], np.ndarray]) -> None:
        """Decode (``size``: the image's, as far as known before) and segment one frame; an
        image that does not decode is a bad image (a throttled error), and such frames and
        observations that fail their own checks are reported as 'no hand' with the reason and
        counted in the diagnostics. No message stops the node."""
        width, height = size
        try:
            try:
                rgb = decode()
            except ImageEncodingError as exc:
                self.get_logger().error(f'bad image: {exc}', throttle_duration_sec=1.0)
                observation: Observation | NoHand = bad_image(exc)
            else:
                height, width = rgb.shape[:2]
                observation = self._segment(header, rgb)
                if isinstance(observation, NoHand) and observation.warn:
                    self.get_logger().warn(observation.reason, throttle_duration_sec=1.0)
            if not isinstance(observation, NoHand):
                msg = observation_to_msg(observation, header)
        except Exception as exc:   # last line of defence: a frame must never stop the node
            self.get_logger().error(f'segmentation failed: {exc!r}\n{traceback.format_exc()}',
                                    throttle_duration_sec=1.0)
            observation = NoHand(f'segmentation failed: {exc!r}', warn=True)
        latency_s = self.diagnostics.latency_s(header.stamp)
        if isinstance(observation, NoHand):
            self.stats.no_hand(observation.reason, observation.warn, latency_s)
            self.publisher.publish(HandObservation(header=header, hand_found=False,
                                                   status=observation.reason,
                                                   image_width=width, image_height=height))
            return
        if observation.hand_found:
            self.stats.hand(latency_s)
        else:
            self.stats.no_hand(observation.status, latency_s=latency_s)
        self.publisher.publish(msg)
        if self.publish_debug and observation.label_image is not None:
            self.debug_publisher.publish(array_to_image(DEBUG_PALETTE[observation.label_image],
                                                        'rgb8', header))


def main(args: list[str] | None = None) -> int:
    """Entry point of ``segmentation_node``."""
    return run_node(SegmentationNode, args)


if __name__ == '__main__':
    sys.exit(main())
