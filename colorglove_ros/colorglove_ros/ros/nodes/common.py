"""Helpers shared by the node shells: parameter declaration, start-up errors, the tracked-hand
topics (publishing a pose, subscribing to one) and the Jazzy ``main`` pattern."""
from __future__ import annotations

import gc
import math
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from functools import partial
from typing import Any

import numpy as np
import rclpy
from geometry_msgs.msg import PoseStamped
from rcl_interfaces.msg import (
    FloatingPointRange,
    IntegerRange,
    ParameterDescriptor,
    ParameterType,
)
from rclpy._rclpy_pybind11 import RCLError
from rclpy.callback_groups import CallbackGroup
from rclpy.event_handler import SubscriptionEventCallbacks
from rclpy.exceptions import InvalidHandle, InvalidParameterTypeException
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import QoSHistoryPolicy, QoSProfile, QoSReliabilityPolicy
from rclpy.subscription import Subscription
from sensor_msgs.msg import CameraInfo, JointState
from std_msgs.msg import Header, String
from visualization_msgs.msg import MarkerArray

from colorglove_ros.core.camera import (
    Calibration,
    CalibrationError,
    PinholeCamera,
    load_calibration,
)
from colorglove_ros.core.conventions import DEFAULT_HAND_LENGTH_M, HAND_LENGTH_RANGE_M
from colorglove_ros.core.errors import ColorGloveError
from colorglove_ros.core.hand.frames import (
    DEFAULT_FRAME_PREFIX,
    check_frame_prefix,
    finger_joint_names,
)
from colorglove_ros.core.hand.model import HandModel, calibrated_hand_model
from colorglove_ros.core.hand.observation_features import OBSERVATION_FEATURES, frame_features
from colorglove_ros.core.hand.pose_classifier import PoseClassifier, load_pose_classifier
from colorglove_ros.core.opencv_threads import OPENCV_THREADS, use_opencv_threads
from colorglove_ros.paths import resolve_path
from colorglove_ros.ros.conversions import (
    blobs_from_observation_msg,
    crop_from_observation_msg,
    pose_to_joint_state_msg,
    pose_to_wrist_pose_msg,
    skeleton_to_markers_msg,
    stamp_key,
    tiny_labels_from_observation_msg,
)
from colorglove_ros.ros.frame_camera import FrameCamera
from colorglove_ros.ros.heap_tuning import keep_freed_buffers
from colorglove_ros.ros.lean_executor import LeanExecutor
from colorglove_ros.ros.pose_pairing import PosePairer
from colorglove_ros.ros.shm_cleanup import clean_stale_fastdds_segments

__all__ = ['LATEST_ONLY', 'LATEST_IMAGE', 'declare', 'declare_limit', 'ending_on_shutdown',
           'run_node', 'prepare_node_process',
           'DEFAULT_CALIBRATION_FILE', 'DEFAULT_DATABASE_CONFIG', 'declare_database',
           'HAND_LENGTH_RANGE_M', 'startup_errors',
           'declare_calibration_file', 'declare_hand_length', 'declare_hand',
           'declare_frame_prefix',
           'CAMERA_INFO_TOPIC', 'OBSERVATION_TOPIC', 'CROP_PREDICTION_TOPIC',
           'declare_frame_camera',
           'declare_topic_list', 'extra_camera_info_topic', 'extra_frame_cameras',
           'TakenOnDemand', 'take_message',
           'declare_camera_index', 'calibrated_camera', 'OPENCV_THREADS', 'declare_opencv_threads',
           'hand_model_from_calibration', 'JOINT_STATES_TOPIC', 'WRIST_POSE_TOPIC',
           'MARKERS_TOPIC', 'TRACKING_STATUS_TOPIC',
           'PosePublishers', 'TrackerOutputs', 'subscribe_tracked_pose']

# Between pipeline stages keep only the newest message: a slow stage drops old frames instead
# of queueing them without bound.
LATEST_ONLY = QoSProfile(history=QoSHistoryPolicy.KEEP_LAST, depth=1,
                         reliability=QoSReliabilityPolicy.RELIABLE)
# Camera images: sensor-data style (best effort matches reliable and best-effort publishers),
# newest frame only: whatever the offered rate, segmentation works on the latest frame and
# drops older ones, so latency stays bounded by the processing time plus a frame period.
LATEST_IMAGE = QoSProfile(history=QoSHistoryPolicy.KEEP_LAST, depth=1,
                          reliability=QoSReliabilityPolicy.BEST_EFFORT)
# CameraInfo: the same, so it matches every camera driver (reliable or sensor-data QoS): a
# reliable reader and a best-effort driver never connect, and the nodes take CameraInfo
# without QoS event handlers (below), so nothing would say why every frame waits for it
CAMERA_INFO_QOS = LATEST_IMAGE


def declare(node: Node, name: str, default: Any, description: str,
            minimum: float | None = None, maximum: float | None = None, *,
            read_only: bool = True) -> Any:
    """Declare a parameter with a description (and a range for numbers); return its value.

    Parameters are read at start-up unless ``read_only=False``: ROS then refuses a run-time
    change of a read-only one with its standard reason, so nobody believes it took effect.
    """
    descriptor = ParameterDescriptor(description=description, read_only=read_only)
    if minimum is not None and maximum is not None:
        if isinstance(default, bool):
            pass
        elif isinstance(default, int):
            descriptor.integer_range = [IntegerRange(from_value=int(minimum),
                                                     to_value=int(maximum), step=0)]
        elif isinstance(default, float):
            descriptor.floating_point_range = [FloatingPointRange(
                from_value=float(minimum), to_value=float(maximum), step=0.0)]
    return node.declare_parameter(name, default, descriptor).value



def declare_limit(node: Node, name: str, default: float, description: str,
                  maximum: float, off: float = 0.0) -> float:
    """Declare a limit that is off when infinite: the parameter reads ``off`` (0, or -1 where
    0 is a limit of its own) for off, as ROS parameters hold no infinity (``description``
    should say so), and is declared in [``off``, ``maximum``]; return the limit, ``math.inf``
    for ``off``."""
    value = declare(node, name, float(default) if math.isfinite(default) else float(off),
                    description, float(off), maximum)
    return float(value) if value > off else math.inf

def declare_opencv_threads(node: Node) -> int:
    """Declare ``opencv_threads`` (default :data:`OPENCV_THREADS`) and apply it to the process
    (``cv2.setNumThreads``, which is process-wide: in one process the last node started sets
    it); return it."""
    threads = declare(node, 'opencv_threads', OPENCV_THREADS,
                      'OpenCV threads of this process (cv2.setNumThreads): 1 runs every OpenCV '
                      'call in the calling thread; -1 OpenCV\'s own default (all cores)', -1, 64)
    return use_opencv_threads(threads)


@contextmanager
def ending_on_shutdown(context: rclpy.context.Context | None = None) -> Iterator[None]:
    """End a spin quietly when ROS is shut down: Ctrl-C, SIGTERM (rclpy's handlers shut the
    context down), an external shutdown, and the ``RCLError`` that the executor's wait set or a
    callback's publish raises when the shutdown lands while it runs. An ``RCLError`` while
    ``context`` (default: the global one) is still valid is a real failure and propagates."""
    try:
        yield
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except RCLError:
        if rclpy.ok(context=context):
            raise


def freeze_startup_objects() -> None:
    """Move every object made so far (modules, the node, its tables) into the garbage
    collector's permanent generation (``gc.freeze``): a full collection while frames run then
    walks only what was made since, not the whole start-up heap. Called once per process,
    after the nodes are constructed and before they spin."""
    gc.collect()
    gc.freeze()


def prepare_node_process() -> None:
    """What a process that runs nodes does before ``rclpy.init``: freed frame buffers stay in
    the heap (``ros.heap_tuning.keep_freed_buffers``) and the shared-memory segments of killed
    Fast DDS participants are removed (a respawned node must not pile them up;
    ``ros.shm_cleanup``)."""
    keep_freed_buffers()
    clean_stale_fastdds_segments()


def run_node(factory: Callable[[], Node], args: list[str] | None = None) -> int:
    """Init rclpy, spin the node made by ``factory`` until shutdown, and clean up (Jazzy style).

    A node that cannot start (bad configuration) logs the reason and exits with code 1.
    The process is prepared first (:func:`prepare_node_process`). The start-up objects are
    frozen before spinning (:func:`freeze_startup_objects`). The node spins on a
    :class:`LeanExecutor` (its wait set kept between wakes, ``ros.lean_executor``).
    """
    prepare_node_process()
    rclpy.init(args=args)
    node = None
    executor = None
    try:
        with ending_on_shutdown():
            node = factory()
            freeze_startup_objects()
            executor = LeanExecutor()
            executor.add_node(node)
            executor.spin()
    except StartupError as exc:
        print(f'[FATAL] {exc}', flush=True)
        return 1
    finally:
        if executor is not None:
            executor.shutdown()
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
    return 0


class StartupError(ColorGloveError):
    """A node cannot start: missing device, file, database or bad configuration."""


__all__ += ['StartupError', 'declare_classifier', 'declare_image_classifier',
            'ObservationFeatures', 'freeze_startup_objects']


# ------------------------------------------------------------------ start-up
DEFAULT_CALIBRATION_FILE = 'config/calibration.yaml'
"""Default of every node's ``calibration_file`` parameter."""
DEFAULT_DATABASE_CONFIG = 'config/database.yaml'
"""Default of the ``database_config`` parameter (lookup_node, ik_node)."""


@contextmanager
def startup_errors(executable: str, *also: type[Exception]) -> Iterator[None]:
    """Turn a typed error of the package (or one of ``also``) raised in the block into a
    :class:`StartupError` ``'<executable> cannot start: <reason>'``; a StartupError passes."""
    try:
        yield
    except StartupError:
        raise
    except (ColorGloveError, *also) as exc:
        raise StartupError(f'{executable} cannot start: {exc}') from exc


def declare_calibration_file(node: Node, description: str,
                             default: str = DEFAULT_CALIBRATION_FILE) -> str:
    """Declare the ``calibration_file`` parameter; return its value."""
    return declare(node, 'calibration_file', default, description)


def declare_database(node: Node) -> str:
    """Declare ``database_config`` and ``database_path`` (the pose database the lookup uses,
    whose manifest also names the glove and hand the IK must use); return the folder named."""
    database_config = declare(node, 'database_config', DEFAULT_DATABASE_CONFIG,
                              'YAML naming the pose database folder (database.path)')
    database_path = declare(node, 'database_path', '',
                            'pose database folder; overrides database_config when set')
    if database_path:
        return str(resolve_path(database_path))
    from colorglove_ros.core.lookup.database_build import read_database_config

    return str(read_database_config(database_config)[1])


def declare_hand_length(node: Node, description: str) -> float:
    """Declare the ``hand_length_m`` parameter (default: the standard hand); return its value."""
    return declare(node, 'hand_length_m', DEFAULT_HAND_LENGTH_M, description,
                   *HAND_LENGTH_RANGE_M)


def declare_hand(node: Node, executable: str) -> str:
    """Declare the ``hand`` parameter ('right' or 'left', ``core.hand.handedness``); return
    it, or stop the start if it is neither."""
    from colorglove_ros.core.hand.handedness import DEFAULT_HAND, HANDS, check_hand

    hand = declare(node, 'hand', DEFAULT_HAND,
                   f'which hand wears the glove, one of {", ".join(HANDS)}: a left hand (the '
                   'mirror-image glove) is looked up and tracked as the mirrored right hand')
    with startup_errors(executable, ValueError):
        return check_hand(hand)


def declare_frame_prefix(node: Node, executable: str) -> str:
    """Declare the ``frame_prefix`` parameter (the hand's name in front of every frame and
    joint name, ``core.hand.frames``); return it, or stop the start if it is not valid."""
    prefix = declare(node, 'frame_prefix', DEFAULT_FRAME_PREFIX,
                     'hand name put in front of every frame and joint name (e.g. "right_" '
                     'gives right_palm); "" keeps the plain names')
    with startup_errors(executable):
        return check_frame_prefix(prefix)


def declare_classifier(node: Node, executable: str, default: str, feature_set: str,
                       what: str) -> PoseClassifier | None:
    """Declare ``classifier_file`` (a trained ``core.hand.pose_classifier`` file, ``default``
    relative to the package root; '' = the hand-written ``what``); return it loaded, or stop
    the start if it cannot be read or classifies other features."""
    path = declare(node, 'classifier_file', default,
                   f'trained classifier file (colorglove_train_hand_classifiers); "" uses the '
                   f'{what}')
    if not path:
        return None
    with startup_errors(executable):
        return load_pose_classifier(resolve_path(path), feature_set)


def declare_image_classifier(node: Node, executable: str, default: str, trained_by: str,
                             default_weight: float) -> tuple[PoseClassifier | None, float]:
    """Declare ``image_classifier_file`` (a classifier of the image evidence, feature set
    ``tiny_observation``, trained by ``trained_by``; '' reads the pose alone) and its
    ``image_weight`` (default ``default_weight``, the core config's); return the classifier
    loaded (None for '') and the weight, or stop the start if it cannot be read."""
    path = declare(node, 'image_classifier_file', default,
                   f'classifier of the image evidence ({trained_by}); "" reads the pose alone')
    weight = float(declare(node, 'image_weight', default_weight,
                           "the image classifier's weight", 0.0, 100.0))
    if not path:
        return None, weight
    with startup_errors(executable):
        return load_pose_classifier(resolve_path(path), OBSERVATION_FEATURES), weight


class ObservationFeatures:
    """Subscribes to ``hand/observation`` (segmentation_node's ``HandObservation``) and keeps
    each found hand's observation features (``core.hand.observation_features``) by stamp until
    the pose of that stamp takes them (:meth:`pop`); the oldest of more than ``kept`` go."""

    def __init__(self, node: Node, kept: int = 30) -> None:
        from colorglove_msgs.msg import HandObservation

        self.node = node
        self.kept = kept
        self.features: dict[tuple[int, int], np.ndarray] = {}
        node.create_subscription(HandObservation, OBSERVATION_TOPIC, self.on_observation, 10)

    def on_observation(self, msg: Any) -> None:
        """Keep a found hand's observation features."""
        if not msg.hand_found or not len(msg.tiny_labels):
            return
        try:
            features = frame_features(tiny_labels_from_observation_msg(msg),
                                      crop_from_observation_msg(msg),
                                      blobs_from_observation_msg(msg))
        except (ColorGloveError, ValueError) as exc:
            self.node.get_logger().warn(f'bad observation: {exc}', throttle_duration_sec=1.0)
            return
        self.features[stamp_key(msg.header.stamp)] = features
        while len(self.features) > self.kept:
            del self.features[next(iter(self.features))]

    def pop(self, stamp: Any) -> np.ndarray | None:
        """The features of the observation of ``stamp`` (a ``builtin_interfaces/Time``), taken
        out; None when it has not come."""
        return self.features.pop(stamp_key(stamp), None)


CAMERA_INFO_TOPIC = 'camera/camera_info'
"""CameraInfo of camera 0 (remap it to the driver's), read by the glove pipeline nodes."""
OBSERVATION_TOPIC = 'hand/observation'
"""What segmentation_node publishes (``HandObservation``), relative to its namespace."""
CROP_PREDICTION_TOPIC = 'hand/crop_prediction'
"""The crop window ik_node predicts from each tracked frame's pose for the next frames
(``geometry_msgs/PolygonStamped``, ``ros.conversions.crop_prediction_to_msg``; stamped with
the tracked frame), which segmentation_node reads."""


def declare_frame_camera(node: Node, calibrated: PinholeCamera) -> FrameCamera:
    """Declare ``use_camera_info``; return the :class:`FrameCamera` giving each frame its
    camera model (fed from ``camera/camera_info`` when true, else ``calibrated``). Frames
    before the first CameraInfo are refused ('camera: waiting for CameraInfo')."""
    use_camera_info = declare(
        node, 'use_camera_info', True,
        'true: intrinsics from the newest CameraInfo on camera/camera_info (frames whose size '
        'or frame_id differ from it are refused); false: camera 0 of calibration_file (frames '
        'of another size are refused)')
    return _frame_camera(node, calibrated, use_camera_info, CAMERA_INFO_TOPIC)


def _frame_camera(node: Node, calibrated: PinholeCamera, use_camera_info: bool,
                  info_topic: str, calibrated_frame_id: bool = False) -> FrameCamera:
    """A :class:`FrameCamera` of ``calibrated``, fed from ``info_topic`` when
    ``use_camera_info``."""
    take = None
    if use_camera_info:
        # the newest only, like every input of the pipeline, and taken when a frame asks for
        # its camera: the subscription is the node's (remapped, listed and destroyed with it)
        # but in a callback group no executor runs, so a CameraInfo never wakes the node; no
        # QoS event handlers (rclpy's incompatible-QoS warning): they would wake it instead
        subscription = node.create_subscription(
            CameraInfo, info_topic, _never_called, CAMERA_INFO_QOS,
            callback_group=TakenOnDemand(),
            event_callbacks=SubscriptionEventCallbacks(use_default_callbacks=False))
        take = partial(take_message, subscription)
    return FrameCamera(calibrated, use_camera_info, calibrated_frame_id=calibrated_frame_id,
                       take_camera_info=take)


def _never_called(msg: Any) -> None:
    raise AssertionError('a TakenOnDemand subscription is read by take_message, not spun')


class TakenOnDemand(CallbackGroup):
    """A callback group no executor runs: its subscriptions stay out of the executor's wait set
    (no wake per message) and are read with :func:`take_message` when needed. Nothing of theirs
    may wait in the executor: a QoS event handler would wake it on every unread message."""

    def can_execute(self, entity: Any) -> bool:
        return False

    def beginning_execution(self, entity: Any) -> bool:
        return False

    def ending_execution(self, entity: Any) -> None:
        pass


def take_message(subscription: Subscription) -> Any | None:
    """The next message waiting on ``subscription`` (None if none, or once it is destroyed)."""
    try:
        with subscription.handle:
            taken = subscription.handle.take_message(subscription.msg_type, subscription.raw)
    except InvalidHandle:
        return None
    return None if taken is None else taken[0]


def declare_topic_list(node: Node, name: str, default: list[str], description: str,
                       executable: str, items: str = 'topic names') -> list[str]:
    """Declare a read-only topic-list parameter (``string[]``, ``default`` when not given,
    which may be empty); return its topics. Any other type (such as a comma-separated string)
    stops the start with the reason. ``items`` names what the strings are (e.g. 'files')."""
    def descriptor(read_only: bool) -> ParameterDescriptor:
        return ParameterDescriptor(description=f'{description} (list of {items})',
                                   type=ParameterType.PARAMETER_STRING_ARRAY, read_only=read_only)
    try:
        value = node.declare_parameter(name, Parameter.Type.STRING_ARRAY,
                                       descriptor(False)).value
    except InvalidParameterTypeException as exc:
        raise StartupError(f'{executable} cannot start: {name} must be a list of {items}, '
                           f'e.g. [/camera2/hand/observation]: {exc}') from exc
    if value is None:
        # rclpy cannot infer string[] from an empty default: set it once typed, then freeze it
        value = list(default)
        node.set_parameters([Parameter(name, Parameter.Type.STRING_ARRAY, value)])
    node.set_descriptor(name, descriptor(True))
    return [str(topic) for topic in value]


def extra_camera_info_topic(observation_topic: str) -> str:
    """The CameraInfo topic of the extra camera whose observations come on
    ``observation_topic``: a segmentation_node in namespace ``NS`` publishes ``NS/``
    :data:`OBSERVATION_TOPIC` and reads ``NS/`` :data:`CAMERA_INFO_TOPIC` (the topics of a
    camera in a bag, ``ros.bags.camera_topics``). Raises :class:`StartupError` for a topic of
    another form."""
    if observation_topic != OBSERVATION_TOPIC \
            and not observation_topic.endswith('/' + OBSERVATION_TOPIC):
        raise StartupError(
            f'extra observation topic {observation_topic!r} does not end in '
            f'{OBSERVATION_TOPIC!r}: its camera\'s CameraInfo topic (NS/{CAMERA_INFO_TOPIC}) '
            'cannot be told; remap the segmentation output, or set use_camera_info false')
    return observation_topic[:-len(OBSERVATION_TOPIC)] + CAMERA_INFO_TOPIC


def extra_frame_cameras(node: Node, calibrated: Sequence[PinholeCamera],
                        observation_topics: Sequence[str], use_camera_info: bool
                        ) -> list[FrameCamera]:
    """One :class:`FrameCamera` per extra camera (cameras 1.. of the calibration, in the order
    of their ``observation_topics``): with ``use_camera_info`` its intrinsics come from its own
    CameraInfo (:func:`extra_camera_info_topic`), extrinsics staying the calibration's; else the
    calibrated camera, whose frame_id the observations must carry too."""
    return [_frame_camera(node, camera, use_camera_info,
                          extra_camera_info_topic(topic) if use_camera_info else '',
                          calibrated_frame_id=True)
            for camera, topic in zip(calibrated, observation_topics, strict=True)]


def declare_camera_index(node: Node, description: str) -> int:
    """Declare the ``camera_index`` parameter (which camera of ``calibration_file`` the node
    serves); return it (:func:`calibrated_camera` picks the camera)."""
    return declare(node, 'camera_index', 0, description, 0, 63)


def calibrated_camera(calibration: Calibration, index: int, calibration_file: str
                      ) -> PinholeCamera:
    """Camera ``index`` of ``calibration``; :class:`CalibrationError` naming the file if it
    lists fewer cameras."""
    if not 0 <= index < len(calibration.cameras):
        raise CalibrationError(f'camera_index {index}, but {calibration_file} lists '
                               f'{len(calibration.cameras)} camera(s)')
    return calibration.cameras[index]


def hand_model_from_calibration(node: Node, executable: str) -> HandModel:
    """Declare ``calibration_file`` and return the user's hand model (hand length and finger
    length factors, ``calibrated_hand_model``); a file that cannot be read stops the start with
    a :class:`StartupError` naming it."""
    calibration_file = declare_calibration_file(node, 'camera calibration YAML (for the hand '
                                                      'length and finger proportions)')
    with startup_errors(executable, ValueError):
        return calibrated_hand_model(load_calibration(resolve_path(calibration_file)))


# ------------------------------------------------------------------ tracked-hand topics
JOINT_STATES_TOPIC = 'hand/joint_states'
"""Finger joints (URDF names) of the tracked hand, from every hand tracker node."""
WRIST_POSE_TOPIC = 'hand/wrist_pose'
"""Wrist pose of the tracked hand in the camera frame, same stamp as its joint state."""
MARKERS_TOPIC = 'hand/markers'
"""Skeleton markers of the tracked hand (cleared when the hand is lost)."""
TRACKING_STATUS_TOPIC = 'hand/tracking_status'
"""One line per frame: ``tracking: ...`` or ``no hand: <reason>``."""


class PosePublishers:
    """Publishes a 26-DOF pose as a ``JointState`` (joint names with ``frame_prefix``) plus a
    wrist ``PoseStamped``."""

    def __init__(self, node: Node, joints_topic: str = JOINT_STATES_TOPIC,
                 wrist_topic: str = WRIST_POSE_TOPIC,
                 frame_prefix: str = DEFAULT_FRAME_PREFIX) -> None:
        self.joint_names = finger_joint_names(frame_prefix)
        self.joints = node.create_publisher(JointState, joints_topic, 10)
        self.wrist = node.create_publisher(PoseStamped, wrist_topic, 10)

    def publish(self, q: np.ndarray, header: Header, *, wrist_wanted: bool = True
                ) -> PoseStamped | None:
        """Publish pose ``q`` with ``header``; return the wrist message. With ``wrist_wanted``
        false the wrist message is built (and published, and returned) only while something
        subscribes to it, else None: the caller needs it for nothing else."""
        self.joints.publish(pose_to_joint_state_msg(q, header, self.joint_names))
        if not (wrist_wanted or self.wrist.get_subscription_count()):
            return None
        wrist = pose_to_wrist_pose_msg(q, header)
        self.wrist.publish(wrist)
        return wrist


class TrackerOutputs:
    """What a hand tracker node publishes: the pose (joints + wrist), skeleton markers and a
    status line per frame; a frame without a pose clears the markers once and says why.
    Joint names carry ``frame_prefix``."""

    def __init__(self, node: Node, frame_prefix: str = DEFAULT_FRAME_PREFIX) -> None:
        self.pose = PosePublishers(node, frame_prefix=frame_prefix)
        self.markers = node.create_publisher(MarkerArray, MARKERS_TOPIC, 10)
        self.status = node.create_publisher(String, TRACKING_STATUS_TOPIC, 10)
        self.hand_was_found = False

    def publish_pose(self, q: np.ndarray, keypoints: np.ndarray, header: Header, *,
                     wrist_wanted: bool = True) -> PoseStamped | None:
        """Publish a tracked frame's pose and skeleton (``keypoints`` of ``q``; built only
        while something subscribes to the markers); return the wrist message (None when not
        ``wrist_wanted`` and nothing subscribes to it: :meth:`PosePublishers.publish`). The
        status line is the caller's (:meth:`publish_status`)."""
        self.hand_was_found = True
        wrist = self.pose.publish(q, header, wrist_wanted=wrist_wanted)
        if self.markers.get_subscription_count():
            self.markers.publish(skeleton_to_markers_msg(keypoints, header))
        return wrist

    def publish_no_hand(self, header: Header, reason: str) -> None:
        """Report a frame without a pose: ``no hand: <reason>``; clear a shown skeleton."""
        if self.hand_was_found and self.markers.get_subscription_count():
            self.markers.publish(skeleton_to_markers_msg(None, header))
        self.hand_was_found = False
        self.publish_status(f'no hand: {reason}')

    def publish_status(self, text: str) -> None:
        """Publish one status line."""
        self.status.publish(String(data=text))


def subscribe_tracked_pose(node: Node,
                           on_pose: Callable[[np.ndarray, PoseStamped], None],
                           frame_prefix: str = DEFAULT_FRAME_PREFIX) -> None:
    """Subscribe to the tracked hand's joint states (joint names with ``frame_prefix``) and
    wrist pose; call ``on_pose(q, wrist message)`` once both halves of a frame (same stamp)
    are in."""
    pairer = PosePairer(finger_joint_names(frame_prefix))

    def deliver(paired: tuple[np.ndarray, PoseStamped] | None) -> None:
        if paired is not None:
            on_pose(*paired)

    node.create_subscription(JointState, JOINT_STATES_TOPIC,
                             lambda msg: deliver(pairer.add_joints(msg)), 10)
    node.create_subscription(PoseStamped, WRIST_POSE_TOPIC,
                             lambda msg: deliver(pairer.add_wrist(msg)), 10)

