"""ik_node: ``HandPoseCandidates`` -> ``JointState`` (URDF joint names), the wrist pose, a
skeleton ``MarkerArray`` and an overlay image, by Gauss-Newton IK with temporal smoothing over
one or several calibrated cameras.

Camera 0's intrinsics come from the newest ``camera/camera_info`` (``use_camera_info``, the
default) or from ``calibration_file``; candidates whose observation's image size or frame_id
does not match are refused ('no hand: camera: ...'). Each extra camera's intrinsics likewise
come from its own CameraInfo (``NS/camera/camera_info`` for observations on
``NS/hand/observation``) or from ``calibration_file``, and an observation that does not match
is ignored; the extra cameras' extrinsics and the user's hand (length and finger length
factors) come from ``calibration_file``. With ``hand: left`` the candidates come from a
left-hand segmentation_node's mirrored observation: the hand is tracked as the mirrored right
hand and its pose mirrored back before it is published (one camera). While someone
subscribes, every tracked frame's crop prediction (``core.pipeline.tracked_crop``: the window
the glove at the fitted pose fills in camera 0's image) goes to ``hand/crop_prediction``
(``geometry_msgs/PolygonStamped``, stamped with the frame), from which segmentation_node
crops the next frames."""
from __future__ import annotations

import sys
import traceback
from collections import deque
from dataclasses import replace
from typing import Any

from colorglove_msgs.msg import HandObservation, HandPoseCandidates
from geometry_msgs.msg import PolygonStamped
from rclpy.node import Node
from sensor_msgs.msg import Image

from colorglove_ros.core.camera import PinholeCamera, load_calibration
from colorglove_ros.core.hand.frame_evidence import tracking_status
from colorglove_ros.core.hand.frames import hand_root_frame
from colorglove_ros.core.hand.glove import calibrated_hand
from colorglove_ros.core.hand.handedness import (
    DEFAULT_HAND,
    from_right_frame,
    mirror_pixels_x,
    mirror_points,
)
from colorglove_ros.core.hand.overlay import draw_skeleton
from colorglove_ros.core.lookup.database import check_hand_length, read_database_build
from colorglove_ros.core.pipeline import (
    NODE_LIMITS,
    NoHand,
    Tracked,
    bad_prior,
    track,
    tracked_crop,
)
from colorglove_ros.core.tracking.config import IKConfig, load_ik_config
from colorglove_ros.core.tracking.tracker import HandTracker
from colorglove_ros.core.tracking.types import CameraObservation, IKError
from colorglove_ros.core.validation import InvalidInputError
from colorglove_ros.paths import resolve_path
from colorglove_ros.ros.conversions import (
    camera_observation_from_msg,
    crop_prediction_to_msg,
    pose_prior_from_candidates_msg,
    stamp_key,
    stamp_to_seconds,
    wrist_pose_to_tf_msg,
)
from colorglove_ros.ros.diagnostics import FrameStats, upstream
from colorglove_ros.ros.image import ImageEncodingError, array_to_image, image_to_rgb8
from colorglove_ros.ros.message_checks import checked_candidates_msg, checked_observation_msg
from colorglove_ros.ros.nodes.common import (
    CROP_PREDICTION_TOPIC,
    LATEST_IMAGE,
    LATEST_ONLY,
    StartupError,
    TrackerOutputs,
    declare,
    declare_calibration_file,
    declare_database,
    declare_frame_camera,
    declare_frame_prefix,
    declare_hand,
    declare_opencv_threads,
    declare_topic_list,
    extra_frame_cameras,
    run_node,
    startup_errors,
)
from colorglove_ros.ros.nodes.diagnostics_publisher import DiagnosticsPublisher
from colorglove_ros.ros.nodes.live_parameters import Apply, LiveParameters

STAMP_MATCH_TOLERANCE_S = 0.02   # an extra camera's frame within this of the primary's counts
# IKConfig settings that ik_node exposes as parameters settable at run time (start: ik_config's
# value; the tracker reads them every frame; IKConfig checks every new value)
LIVE_IK_SETTINGS = {
    'enable_ik': 'false: publish the blended lookup pose',
    'enable_smoothing': 'use the previous frame as a prior (temporal smoothing)',
    'gate_tiny_px': 'camera 0: a constraint matches a blob within max(gate_min_px, this times '
                    'the crop scale), px',
    'gate_min_px': 'camera 0: smallest matching gate, px',
    'extra_gate_px': 'other cameras: matching gate around the shifted projection, px',
    'outlier_px': 'constraints farther than this from their projection after the IK are '
                  'dropped and the pose re-solved, px (0 disables)',
}

# The evidence gate's settings (core.pipeline.StageLimits), settable at run time: description
# and range.
LIVE_EVIDENCE_LIMITS = {
    'close_match_distance': (
        'a lookup whose nearest database image is at most this far (tiny pixels) is a close '
        'match; a fit after a farther one must explain min_explained_blob_share of the glove '
        'blobs', (0.0, 1000.0)),
    'min_explained_blob_share': (
        'share of the observed glove blobs the fitted hand must explain after a lookup that '
        'was not a close match, else no pose ("weak evidence"); 0 turns this off', (0.0, 1.0)),
    'max_weak_match_residual_px': (
        'mean reprojection residual (pixels at the IK\'s reference focal length) a fit may '
        'keep after a lookup that was not a close match, else no pose ("poor fit": depth from '
        'a crop that clutter pulled); 1000 lets every fit through', (0.0, 1000.0)),
    'max_missing_glove_share': (
        'share of the glove the fitted hand shows that may lack a blob of its colour near it, '
        'else no pose ("missing glove": colours the segmentation missed); 1 turns this off',
        (0.0, 1.0)),
    'max_outside_blob_share': (
        'share of the observed glove blob pixels that may lie in blobs centred beyond '
        'outside_reach crop windows of the fitted hand, else no pose ("glove outside the '
        'hand": clutter in the crop); 1 turns this off', (0.0, 1.0)),
    'outside_reach': (
        'how far from the fitted hand\'s crop window centre a blob is outside it, in crop '
        'window half sides', (0.0, 100.0)),
}


class IKNode(Node):
    """Refines the looked-up pose and publishes the tracker's outputs."""

    def __init__(self, **kwargs) -> None:
        super().__init__('ik', **kwargs)
        declare_opencv_threads(self)
        calibration_file = declare_calibration_file(
            self, 'camera calibration YAML; camera 0 is the lookup camera')
        ik_config = declare(self, 'ik_config', 'config/ik.yaml', 'IK settings and covariances')
        topics = declare_topic_list(self, 'extra_observation_topics', [],
                                    'HandObservation topics of cameras 1..N-1, in calibration '
                                    'order', 'ik_node')
        wait_s = declare(self, 'extra_observation_wait_s', 0.05,
                         'longest wait for the extra cameras\' observations of a frame, seconds',
                         0.0, 1.0)
        frame_prefix = declare_frame_prefix(self, 'ik_node')
        self.hand = declare_hand(self, 'ik_node')
        self.hand_frame = hand_root_frame(frame_prefix)
        with startup_errors('ik_node', ValueError):
            calibration = load_calibration(resolve_path(calibration_file))
            config = load_ik_config(resolve_path(ik_config))
            # the glove and hand of the lookup's database (its manifest; no array is read)
            database = declare_database(self)
            build = read_database_build(database)
            check_hand_length(build, calibration.hand_length_m, calibration_file, database)
            model, mesh, glove = calibrated_hand(calibration, build.glove_seed)
            self.live = LiveParameters(self)
            config = replace(config, **self._declare_live_ik_settings(config))
            self.tracker = HandTracker(model, mesh, calibration.cameras, config, glove)
        self.limits = replace(NODE_LIMITS, **{
            name: self.live.declare(name, getattr(NODE_LIMITS, name), description,
                                    lambda v, name=name: self._check_limit(name, v), *bounds)
            for name, (description, bounds) in LIVE_EVIDENCE_LIMITS.items()})
        self.limits = replace(self.limits, follow_cut_hands=bool(self.live.declare(
            'follow_cut_hands', NODE_LIMITS.follow_cut_hands,
            'a hand tracked on the frame before that the image border now cuts is followed '
            'from its last pose without the lookup and gated as after a far lookup; false: no '
            'pose until it is fully in view again (a hand first seen cut never has one)',
            lambda v: self._check_limit('follow_cut_hands', v, bool))))
        self.overlay_subscription = None
        self.publish_overlay = self.live.declare(
            'publish_overlay', False,
            'also draw the fitted skeleton on the camera image and publish it on hand/overlay '
            '(subscribes to the camera images; a few ms of CPU per frame)',
            self._check_publish_overlay)
        self.num_vertices = mesh.num_vertices
        self.cameras = calibration.cameras
        self.frame_camera = declare_frame_camera(self, calibration.primary)
        if self.hand != DEFAULT_HAND and len(self.cameras) > 1:
            raise StartupError(f'ik_node cannot start: a {self.hand} hand is tracked on its '
                               'mirrored observation, with one camera only')
        if len(topics) != len(self.cameras) - 1:
            raise StartupError(
                f'ik_node cannot start: {len(self.cameras)} cameras calibrated but '
                f'{len(topics)} extra observation topic(s) given; set extra_observation_topics')
        self.extra_observations: list[deque[HandObservation]] = [deque(maxlen=30)
                                                                 for _ in topics]
        with startup_errors('ik_node'):
            self.extra_frame_cameras = extra_frame_cameras(
                self, self.cameras[1:], topics, self.frame_camera.use_camera_info)
        for index, topic in enumerate(topics):
            self.create_subscription(HandObservation, topic,
                                     lambda msg, i=index: self.on_extra_observation(i, msg), 10)
        # candidates waiting for the other cameras' observations of the same frame
        self.pending: HandPoseCandidates | None = None
        self.pending_timer = self.create_timer(wait_s, self._process_pending, autostart=False)
        self.recent_images: deque[Image] = deque(maxlen=15)
        self.outputs = TrackerOutputs(self, frame_prefix)
        self.overlay_pub = self.create_publisher(Image, 'hand/overlay', 2)
        self.crop_prediction_pub = self.create_publisher(PolygonStamped, CROP_PREDICTION_TOPIC,
                                                         LATEST_ONLY)
        self.create_subscription(HandPoseCandidates, 'hand/pose_candidates', self.on_candidates,
                                 LATEST_ONLY)
        self._subscribe_images(self.publish_overlay)
        self.stats = FrameStats({'camera': self.frame_camera.refused})
        self.diagnostics = DiagnosticsPublisher(self, 'tracking', calibration.primary.frame_id,
                                                self.stats)
        self.tf_pub = self._tf_publisher()
        self.get_logger().info(f'tracking with {len(self.cameras)} camera(s)')

    # ------------------------------------------------------------------ run-time parameters
    def _declare_live_ik_settings(self, config: IKConfig) -> dict[str, Any]:
        """Declare the IK settings settable at run time (:data:`LIVE_IK_SETTINGS`), starting
        from ``config``'s values (``ik_config``'s, or the tracker's defaults); return their
        start values."""
        return {name: self.live.declare(name, getattr(config, name), description,
                                        lambda v, name=name: self._check_ik_setting(name, v))
                for name, description in LIVE_IK_SETTINGS.items()}

    def _check_ik_setting(self, name: str, value: Any) -> Apply:
        """A new value of an IK setting, checked by the IK config's own rules."""
        replace(self.tracker.config, **{name: value})

        def apply() -> None:
            self.tracker.config = replace(self.tracker.config, **{name: value})
        return apply

    def _check_limit(self, name: str, value: Any, kind: type = float) -> Apply:
        """A new value of an evidence-gate setting, as ``kind`` (its range and type are the
        parameter's)."""
        converted = kind(value)

        def apply() -> None:
            self.limits = replace(self.limits, **{name: converted})
        return apply

    def _check_publish_overlay(self, value: Any) -> Apply:
        def apply() -> None:
            self.publish_overlay = bool(value)
            self._subscribe_images(self.publish_overlay)
        return apply

    def _subscribe_images(self, overlay: bool) -> None:
        """Receive the camera images (for the overlay) only while ``overlay``."""
        if overlay and self.overlay_subscription is None:
            self.overlay_subscription = self.create_subscription(
                Image, 'camera/image_raw', lambda image: self.recent_images.append(image),
                LATEST_IMAGE)
        elif not overlay and self.overlay_subscription is not None:
            self.destroy_subscription(self.overlay_subscription)
            self.overlay_subscription = None
            self.recent_images.clear()

    def _tf_publisher(self):
        """A /tf publisher for the camera -> hand root (``<frame_prefix>palm``) transform (so
        robot_state_publisher's URDF frames hang off the camera), when tf2_msgs is installed
        (native ROS 2; it is not on PyPI, where the wrist pose is on /hand/wrist_pose only)."""
        try:
            from tf2_msgs.msg import TFMessage
        except ImportError:
            self.get_logger().info('tf2_msgs not installed: camera->hand TF not broadcast '
                                   '(the wrist pose is on hand/wrist_pose)')
            return None
        return self.create_publisher(TFMessage, '/tf', 10)

    def _matching_observation(self, index: int, stamp: float) -> HandObservation | None:
        """Extra camera ``index``'s observation nearest to ``stamp``, if within tolerance."""
        match = min(self.extra_observations[index],
                    key=lambda m: abs(stamp_to_seconds(m.header.stamp) - stamp), default=None)
        if match is None or abs(stamp_to_seconds(match.header.stamp) - stamp) > \
                STAMP_MATCH_TOLERANCE_S:
            return None
        return match

    def _extra_camera_observations(self, stamp: float) -> list[CameraObservation]:
        """The extra cameras' observations of the frame at ``stamp``; a camera with none
        matching in time, or whose size or frame_id does not match its camera model, did not
        see the hand."""
        observations = []
        for index in range(1, len(self.cameras)):
            match = self._matching_observation(index - 1, stamp)
            camera = None if match is None else self._camera_model(index, match)
            if isinstance(camera, NoHand):
                self.get_logger().warn(f'observation of camera {index} ignored: {camera.reason}',
                                       throttle_duration_sec=1.0)
            if not isinstance(camera, PinholeCamera):
                match = None
            blobs = None
            if match is not None and match.hand_found:
                try:
                    _, blobs = checked_observation_msg(match, (camera.width, camera.height))
                except InvalidInputError as exc:
                    self.get_logger().warn(f'observation of camera {index} ignored: {exc}',
                                           throttle_duration_sec=1.0)
                    match = None
            observations.append(CameraObservation(hand_found=False) if match is None
                                else camera_observation_from_msg(match, blobs))
        return observations

    def _all_extras_arrived(self, msg: HandPoseCandidates) -> bool:
        stamp = stamp_to_seconds(msg.header.stamp)
        return all(self._matching_observation(i, stamp) is not None
                   for i in range(len(self.extra_observations)))

    def on_extra_observation(self, index: int, msg: HandObservation) -> None:
        """Keep an extra camera's observation; release waiting candidates once complete."""
        self.extra_observations[index].append(msg)
        if self.pending is not None and self._all_extras_arrived(self.pending):
            self._process_pending()

    def _process_pending(self) -> None:
        """Track the waiting frame with whatever the extra cameras delivered."""
        self.pending_timer.cancel()
        msg, self.pending = self.pending, None
        if msg is not None:
            self.track(msg)

    def on_candidates(self, msg: HandPoseCandidates) -> None:
        """Track a frame now, or once the extra cameras' observations of it have arrived
        (at most ``extra_observation_wait_s`` later)."""
        self._process_pending()
        if not msg.hand_found or self._all_extras_arrived(msg):
            self.track(msg)
            return
        self.pending = msg
        self.pending_timer.reset()

    def track(self, msg: HandPoseCandidates) -> None:
        """Run the tracker on one frame's candidates (``core.pipeline.track``) and publish the
        results. Candidates that fail validation, and results the pipeline refuses, give 'no
        hand' with the reason; no message stops the node."""
        try:
            outcome = self._track(msg)
            if isinstance(outcome, NoHand):
                if outcome.warn:
                    self.get_logger().warn(f'no pose published: {outcome.reason}',
                                           throttle_duration_sec=1.0)
                self.stats.no_hand(outcome.reason if msg.hand_found else upstream(outcome.reason),
                                   outcome.warn, self.diagnostics.latency_s(msg.header.stamp))
                self.outputs.publish_no_hand(msg.header, outcome.reason)
            else:
                self._publish(msg, outcome)
        except Exception as exc:   # last line of defence: a message must never stop the node
            self.get_logger().error(f'tracking failed: {exc!r}\n{traceback.format_exc()}',
                                    throttle_duration_sec=1.0)
            self.tracker.reset()
            self.stats.no_hand(f'tracking failed: {exc!r}', error=True)
            self.outputs.publish_no_hand(msg.header, f'tracking failed: {exc!r}')

    def _track(self, msg: HandPoseCandidates) -> Tracked | NoHand:
        """The tracker's outcome for one frame's candidates and the extra cameras'
        observations of it."""
        stamp = stamp_to_seconds(msg.header.stamp)
        try:
            prior = blobs = None
            seen_cut = msg.observation.hand_found and msg.observation.cut_by_border
            if msg.hand_found or seen_cut:
                camera = self._camera_model(0, msg.observation)
                if isinstance(camera, NoHand):
                    self.tracker.reset()
                    return camera
            if msg.hand_found:
                _, blobs = checked_candidates_msg(msg, self.num_vertices,
                                                  (camera.width, camera.height))
                prior = pose_prior_from_candidates_msg(msg)
            elif seen_cut:      # a cut hand the lookup refused may still be followed
                _, blobs = checked_observation_msg(msg.observation,
                                                   (camera.width, camera.height))
            observations = [camera_observation_from_msg(msg.observation, blobs),
                            *self._extra_camera_observations(stamp)]
        except (IKError, InvalidInputError, ValueError) as exc:
            return bad_prior(self.tracker, exc)
        return track(self.tracker, prior, observations, stamp, self.limits,
                     upstream_reason=msg.status)

    def _camera_model(self, index: int, observation: HandObservation
                      ) -> PinholeCamera | NoHand:
        """Camera ``index``'s model for this observation (its CameraInfo's or the calibrated
        one; the tracker switches to it when it changed), or why the observation is
        refused (its size or frame_id does not match)."""
        frame_camera = (self.frame_camera if index == 0
                        else self.extra_frame_cameras[index - 1])
        camera = frame_camera.camera_for(observation.image_width, observation.image_height,
                                         observation.header.frame_id)
        if not isinstance(camera, NoHand) and camera is not self.tracker.cameras[index]:
            self.tracker.set_camera(index, camera)
            self.get_logger().info(
                f'camera {index}: {camera.width}x{camera.height}, fx {camera.fx:.1f}, fy '
                f'{camera.fy:.1f}, cx {camera.cx:.1f}, cy {camera.cy:.1f} '
                f'({"CameraInfo" if frame_camera.use_camera_info else "calibration"})')
        return camera

    def _publish(self, msg: HandPoseCandidates, tracked: Tracked) -> None:
        """Publish a tracked frame: joint state, wrist pose and TF (each while something
        subscribes to it), markers, status line and the overlay."""
        result, keypoints = tracked.result, tracked.keypoints
        q = from_right_frame(result.q, self.hand)
        if self.hand != DEFAULT_HAND:     # tracked as the mirrored right hand
            keypoints = mirror_points(keypoints)
        # the wrist and its transform are built only for a subscriber
        tf_wanted = self.tf_pub is not None and self.tf_pub.get_subscription_count() > 0
        wrist = self.outputs.publish_pose(q, keypoints, msg.header, wrist_wanted=tf_wanted)
        if tf_wanted:
            self.tf_pub.publish(wrist_pose_to_tf_msg(wrist, child_frame_id=self.hand_frame))
        per_camera = ', '.join(f'{camera.name} {count}' for camera, count in
                               zip(self.tracker.cameras, result.constraints_per_camera,
                                   strict=False))
        self.outputs.publish_status(tracking_status(
            result.num_constraints, per_camera, result.reprojection_error_px, result.time_ms,
            stamp_key(msg.header.stamp), followed=result.followed))
        self.stats.hand(self.diagnostics.latency_s(msg.header.stamp),
                        constraints=result.num_constraints,
                        **{f'constraints {camera.name}': count for camera, count in
                           zip(self.tracker.cameras, result.constraints_per_camera,
                               strict=False)},
                        **{'reprojection (px)': f'{result.reprojection_error_px:.1f}'})
        self._publish_crop_prediction(msg, result.q)
        if self.publish_overlay:
            self._publish_overlay(msg, keypoints, result.reprojection_error_px)

    def _publish_crop_prediction(self, msg: HandPoseCandidates, q) -> None:
        """The crop the tracked pose ``q`` (the tracker's, right-hand frame) predicts for the
        next frames, in the image's own columns (mirrored back for a left hand); computed only
        for a subscriber (segmentation_node subscribes while its segmenter uses predictions)."""
        if self.crop_prediction_pub.get_subscription_count() == 0:
            return
        prediction = tracked_crop(self.tracker, q, stamp_to_seconds(msg.header.stamp))
        if prediction is None:
            return
        if self.hand != DEFAULT_HAND:
            x, y = prediction.center_xy
            prediction = replace(prediction, center_xy=(
                float(mirror_pixels_x(x, self.tracker.cameras[0].cx)), y))
        self.crop_prediction_pub.publish(crop_prediction_to_msg(prediction, msg.header))

    def _publish_overlay(self, msg: HandPoseCandidates, keypoints, error_px: float) -> None:
        stamp = msg.header.stamp
        image = next((m for m in reversed(self.recent_images) if m.header.stamp == stamp), None)
        if image is None:
            return
        try:
            rgb = image_to_rgb8(image)
        except ImageEncodingError:
            return
        drawn = draw_skeleton(rgb, keypoints, self.tracker.cameras[0],
                              label=f'reprojection {error_px:.1f} px')
        self.overlay_pub.publish(array_to_image(drawn, 'rgb8', msg.header))


def main(args: list[str] | None = None) -> int:
    """Entry point of ``ik_node``."""
    return run_node(IKNode, args)


if __name__ == '__main__':
    sys.exit(main())
