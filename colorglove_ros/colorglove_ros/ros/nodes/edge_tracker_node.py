"""edge_tracker_node: bare-hand DigitEyes tracking from grey-scale edges, one or two cameras.

Subscribes to one ``sensor_msgs/Image`` per camera (mono8 or colour; ``image_topics``) and
publishes what ``ik_node`` publishes: ``hand/joint_states`` (URDF joint names),
``hand/wrist_pose``, ``hand/markers`` and ``hand/tracking_status``. Cameras come from
``calibration_file`` (required for two cameras: the extrinsics); with ``calibration_file``
empty, one camera is taken from the first ``CameraInfo`` on ``camera_info_topic``.

Silhouettes: ``background_images`` names one image of the empty scene per camera (the hand
out of view, same camera settings; PNG or JPEG, colour or grey like the camera's images).
Each frame's foreground against it then enters the fit (``silhouette_weight``) and its drift
checks (``max_unexplained``); empty: edges only. ``finger_refit`` (on by default) re-fits a
finger that leaves part of the hand's silhouette unexplained; ``silhouette_palm`` (on by
default) lets the unexplained foreground next to the palm pull the whole hand; both act only
with ``background_images``.
With ``max_finger_off_silhouette`` below 1 (off by default) a frame where a finger's axis lies
off the silhouette (not the thumb) publishes no pose and says which finger on the status
topic; the track is kept. ``retry_dofs`` (empty by default; the 3-D mouse's buttons are
``[thumb_cmc_abd]``) names joints re-tried from farther starts, ``retry_step_deg`` apart,
when the fit misses their digit's links or fails (a fast click out of the edge search's reach).

Start: hold the flat hand still, palm to the (primary) camera, at the marked spot
``init_wrist_position``; or publish a starting pose on ``edge_tracker/init_joint_states`` +
``edge_tracker/init_wrist_pose`` (e.g. remapped from the glove tracker's outputs). Frames
without a trustworthy fit publish no pose, only the reason on the status topic.
"""
from __future__ import annotations

import sys
from dataclasses import replace

from geometry_msgs.msg import PoseStamped
from rclpy.node import Node
from sensor_msgs.msg import CameraInfo, Image, JointState

from colorglove_ros.core.camera import PinholeCamera, load_calibration
from colorglove_ros.core.errors import ColorGloveError
from colorglove_ros.core.hand.frame_evidence import edge_tracking_status
from colorglove_ros.core.hand.frames import finger_joint_names
from colorglove_ros.core.hand.model import HandModel
from colorglove_ros.core.tracking.edge_fit import EdgeTrackerConfig
from colorglove_ros.core.tracking.edge_tracker import EdgeTracker
from colorglove_ros.core.tracking.silhouette import SilhouetteConfig, read_background
from colorglove_ros.paths import resolve_path
from colorglove_ros.ros.bags import camera_info_to_pinhole
from colorglove_ros.ros.conversions import pose_from_msgs, stamp_key
from colorglove_ros.ros.diagnostics import FrameStats
from colorglove_ros.ros.image import ImageEncodingError, image_to_array
from colorglove_ros.ros.nodes.common import (
    CAMERA_INFO_QOS,
    LATEST_IMAGE,
    StartupError,
    TrackerOutputs,
    declare,
    declare_calibration_file,
    declare_frame_prefix,
    declare_hand_length,
    declare_limit,
    declare_opencv_threads,
    declare_topic_list,
    run_node,
    startup_errors,
)
from colorglove_ros.ros.nodes.diagnostics_publisher import DiagnosticsPublisher

__all__ = ['EdgeTrackerNode', 'main']


class EdgeTrackerNode(Node):
    """Images in, hand pose out (see the module docstring)."""

    def __init__(self, **kwargs) -> None:
        super().__init__('edge_tracker', **kwargs)
        declare_opencv_threads(self)
        calibration_file = declare_calibration_file(
            self, 'camera calibration YAML (all its cameras are used; camera 0 is the primary); '
            'empty: one camera from the first CameraInfo on camera_info_topic', default='')
        topics = declare_topic_list(self, 'image_topics', ['camera/image_raw'],
                                    'image topics, one per calibrated camera',
                                    'edge_tracker_node')
        self.info_topic = declare(self, 'camera_info_topic', 'camera/camera_info',
                                  'CameraInfo topic read when calibration_file is empty')
        hand_length = declare_hand_length(self, 'hand length when no calibration file gives it, m')
        frame_prefix = declare_frame_prefix(self, 'edge_tracker_node')
        self.joint_names = finger_joint_names(frame_prefix)
        self.stamp_tolerance = declare(self, 'stamp_tolerance_s', 0.02,
                                       'images within this of each other form one frame, s',
                                       0.0, 1.0)
        defaults = EdgeTrackerConfig()
        init_wrist = declare(self, 'init_wrist_position', list(defaults.init_wrist_position),
                             'marked spot: wrist position of the initialisation pose in the '
                             'primary camera frame (x, y, z), m')
        hold = declare(self, 'init_hold_frames', defaults.init_hold_frames,
                       'frames the hand must hold still at the marked spot to start', 1, 300)
        search = declare(self, 'search_px', defaults.search.search_px,
                         'how far past a predicted link edge the 1-D searches reach, px',
                         1.0, 50.0)
        min_gradient = declare(self, 'min_gradient', defaults.search.min_gradient,
                               'smallest grey-level derivative counted as an edge, per px',
                               0.1, 100.0)
        max_rms = declare(self, 'max_rms_px', defaults.max_rms_px,
                          'largest edge residual (weighted RMS) of a published fit, px',
                          0.1, 50.0)
        min_found = declare(self, 'min_found_fraction', defaults.min_found_fraction,
                            'fraction of the visible links all cameras together must find',
                            0.05, 1.0)
        min_camera = declare(self, 'min_camera_found_fraction',
                             defaults.min_camera_found_fraction,
                             'fraction of its visible links each camera must find', 0.0, 1.0)
        patience = declare(self, 'loss_patience', defaults.loss_patience,
                           'bad frames in a row that declare the track lost', 1, 100)
        rounds = declare(self, 'measurement_rounds', defaults.measurement_rounds,
                         'measure-and-fit rounds per tracked frame', 1, 10)
        fault_round = declare(self, 'fault_round', defaults.fault_round,
                              'a tracked frame whose fit fails a check is measured and '
                              'fitted once more from that fit before it is judged')
        min_move = declare(self, 'round_min_move_px', defaults.round_min_move_px,
                           'a further measurement round only after a round that moved some '
                           'feature point by more than this, px (0: every round)', 0.0, 100.0)
        polarity = declare(self, 'polarity', defaults.polarity,
                           '+1 hand brighter than the background, -1 darker, 0 either', -1, 1)
        camera_check = declare(self, 'camera_check', defaults.camera_check,
                               'two or more cameras: also fit the primary camera alone and '
                               'count a frame as drift when the fits disagree')
        max_disagreement = declare(self, 'max_camera_disagreement_mm',
                                   defaults.max_camera_disagreement_mm,
                                   'camera_check: largest fingertip distance (relative to the '
                                   'wrist) between the two fits, mm', 0.1, 1000.0)
        backgrounds = declare_topic_list(self, 'background_images', [],
                                         'empty-scene image per camera for the silhouettes; '
                                         'empty: edges only', 'edge_tracker_node', 'files')
        threshold = declare(self, 'silhouette_threshold', SilhouetteConfig().threshold,
                            'foreground: some channel differs from the empty scene by more '
                            'than this, grey levels', 1.0, 255.0)
        silhouette_weight = declare(self, 'silhouette_weight', defaults.silhouette_weight,
                                    'weight of the silhouette residuals in the fit (0: off)',
                                    0.0, 100.0)
        max_unexplained = declare(self, 'max_unexplained', defaults.max_unexplained,
                                  'largest share of the hand silhouette no part of the fitted '
                                  'hand explains, in any camera, before a frame counts as '
                                  'drift (1: never)', 0.0, 1.0)
        finger_refit = declare(self, 'finger_refit', defaults.finger_refit,
                               'with silhouettes: re-fit a digit (and its neighbours) that '
                               'leaves part of the hand unexplained, from its last explained '
                               'angles')
        max_finger_unexplained = declare(self, 'max_finger_unexplained',
                                         defaults.max_finger_unexplained,
                                         'finger_refit: share of the hand silhouette left '
                                         'unexplained near one digit that triggers its re-fit',
                                         0.0, 1.0)
        refit_dofs = declare(self, 'finger_refit_dofs', defaults.finger_refit_dofs,
                             'finger_refit: what a re-fit candidate fits (hand: every DOF; '
                             'abduction: all but the digit\'s abduction; digit: the digit\'s '
                             'DOFs; flexion: its flexions), the rest held at the frame\'s fit')
        refit_abduction = declare(self, 'finger_refit_abduction',
                                  defaults.finger_refit_abduction,
                                  'finger_refit: where a candidate\'s abduction starts (start: '
                                  'with its other start angles; kept: at the frame\'s fit; '
                                  'both: one candidate of each; spread: kept, and moved '
                                  'finger_refit_spread_deg out and in)')
        refit_spread = declare(self, 'finger_refit_spread_deg', defaults.finger_refit_spread_deg,
                               'finger_refit_abduction spread: how far the abduction is '
                               'moved, degrees', 0.1, 90.0)
        silhouette_palm = declare(self, 'silhouette_palm', defaults.silhouette_palm,
                                  'with silhouettes: the unexplained foreground next to the '
                                  'palm pulls the palm (the whole hand) toward it')
        max_finger_off = declare(self, 'max_finger_off_silhouette',
                                 defaults.max_finger_off_silhouette,
                                 'with silhouettes: largest share of a finger\'s axis points '
                                 '(not the thumb\'s) off the silhouette in any camera before '
                                 'the frame is withheld (track kept, no pose; 1: never)',
                                 0.0, 1.0)
        retry_dofs = declare_topic_list(self, 'retry_dofs', list(defaults.retry_dofs),
                                        'joints re-tried from farther starts when the fit '
                                        'misses their digit\'s links or fails; empty: none',
                                        'edge_tracker_node', 'joint DOF names')
        retry_step = declare(self, 'retry_step_deg', defaults.retry_step_deg,
                             'retry_dofs: step between the starts tried (up to '
                             f'{defaults.retry_steps} steps each way), degrees', 1.0, 90.0)
        retry_wrist = declare_limit(self, 'retry_max_wrist_move_m', defaults.retry_max_wrist_move_m,
                                    'retry_dofs: a retried fit is kept only with its wrist '
                                    'within this of the previous pose, m (0: off)', 1.0)
        retry_margin = declare_limit(self, 'retry_rest_margin_px', defaults.retry_rest_margin_px,
                                     'retry_dofs: a retried fit is kept only when the rest of '
                                     'the hand fits as well as the last good frame, within '
                                     'this, px (-1: off)', 100.0, off=-1.0)
        with startup_errors('edge_tracker_node', ValueError):
            if len(init_wrist) != 3:
                raise ColorGloveError(f'init_wrist_position needs 3 values, got {init_wrist}')
            self.config = replace(
                defaults, search=replace(defaults.search, search_px=float(search),
                                         min_gradient=float(min_gradient)),
                init_wrist_position=tuple(float(v) for v in init_wrist),
                init_hold_frames=int(hold), max_rms_px=float(max_rms),
                min_found_fraction=float(min_found),
                min_camera_found_fraction=float(min_camera), loss_patience=int(patience),
                measurement_rounds=int(rounds), fault_round=bool(fault_round),
                round_min_move_px=float(min_move),
                polarity=int(polarity), camera_check=bool(camera_check),
                max_camera_disagreement_mm=float(max_disagreement),
                silhouette_weight=float(silhouette_weight),
                max_unexplained=float(max_unexplained), finger_refit=bool(finger_refit),
                max_finger_unexplained=float(max_finger_unexplained),
                finger_refit_dofs=str(refit_dofs), finger_refit_abduction=str(refit_abduction),
                finger_refit_spread_deg=float(refit_spread),
                silhouette_palm=bool(silhouette_palm),
                max_finger_off_silhouette=float(max_finger_off),
                retry_dofs=tuple(retry_dofs), retry_step_deg=float(retry_step),
                retry_max_wrist_move_m=retry_wrist, retry_rest_margin_px=retry_margin)
            self.backgrounds = [read_background(resolve_path(f), SilhouetteConfig(
                threshold=float(threshold))) for f in backgrounds]
            cameras: tuple[PinholeCamera, ...] = ()
            if calibration_file:
                calibration = load_calibration(resolve_path(calibration_file))
                cameras, hand_length = calibration.cameras, calibration.hand_length_m
            self.model = HandModel(hand_length)
            self.image_topics = topics
            if cameras and len(self.image_topics) != len(cameras):
                raise ColorGloveError(f'{len(cameras)} calibrated camera(s) but '
                                      f'{len(self.image_topics)} image topic(s); set image_topics')
            if self.backgrounds and len(self.backgrounds) != len(self.image_topics):
                raise ColorGloveError(f'{len(self.image_topics)} image topic(s) but '
                                      f'{len(self.backgrounds)} background_images')
            if not cameras and len(self.image_topics) != 1:
                raise ColorGloveError('several image topics need a calibration_file with their '
                                      'extrinsics')
        self.tracker: EdgeTracker | None = None
        if cameras:
            self._make_tracker(cameras)
        else:
            self.create_subscription(CameraInfo, self.info_topic, self.on_camera_info,
                                     CAMERA_INFO_QOS)
        self.pending: dict[int, list[Image | None]] = {}
        for index, topic in enumerate(self.image_topics):
            self.create_subscription(Image, topic, lambda m, i=index: self.on_image(i, m),
                                     LATEST_IMAGE)
        self.init_wrist: PoseStamped | None = None
        self.create_subscription(PoseStamped, 'edge_tracker/init_wrist_pose',
                                 self.on_init_wrist, 10)
        self.create_subscription(JointState, 'edge_tracker/init_joint_states',
                                 self.on_init_joints, 10)
        self.outputs = TrackerOutputs(self, frame_prefix)
        self.stats = FrameStats()
        self.diagnostics = DiagnosticsPublisher(
            self, 'edge tracking',
            lambda: self.tracker.cameras[0].frame_id if self.tracker is not None else '',
            self.stats)

    def _make_tracker(self, cameras: tuple[PinholeCamera, ...]) -> None:
        with startup_errors('edge_tracker_node'):
            self.tracker = EdgeTracker(self.model, cameras, self.config,
                                       self.backgrounds or None)
        self.get_logger().info(f'edge tracking with {len(cameras)} camera(s)')

    def on_camera_info(self, msg: CameraInfo) -> None:
        """Take the single camera from its first CameraInfo."""
        if self.tracker is not None:
            return
        try:
            self._make_tracker((camera_info_to_pinhole(msg),))
        except (ColorGloveError, StartupError) as exc:
            self.get_logger().warn(f'unusable CameraInfo: {exc}', throttle_duration_sec=5.0)

    def on_init_wrist(self, msg: PoseStamped) -> None:
        """Keep the wrist half of a given starting pose."""
        self.init_wrist = msg

    def on_init_joints(self, msg: JointState) -> None:
        """Start tracking from a given pose (joint state + the latest init wrist pose)."""
        if self.tracker is None or self.init_wrist is None:
            self.get_logger().warn('starting pose ignored: no camera yet or no '
                                   'edge_tracker/init_wrist_pose received',
                                   throttle_duration_sec=1.0)
            return
        try:
            self.tracker.initialize(pose_from_msgs(msg, self.init_wrist, self.joint_names))
        except (ColorGloveError, ValueError, KeyError) as exc:
            self.get_logger().warn(f'bad starting pose: {exc}', throttle_duration_sec=1.0)
            return
        self.outputs.publish_status('initialised from a given pose')

    def on_image(self, index: int, msg: Image) -> None:
        """Collect one frame's images from all cameras, then track it."""
        if self.tracker is None:
            self.stats.no_hand('waiting for CameraInfo', error=True)
            self.outputs.publish_no_hand(msg.header, 'waiting for CameraInfo')
            return
        stamp_ns = int(msg.header.stamp.sec) * 10**9 + int(msg.header.stamp.nanosec)
        tol_ns = int(self.stamp_tolerance * 1e9)
        key = next((k for k in self.pending if abs(k - stamp_ns) <= tol_ns), stamp_ns)
        slot = self.pending.setdefault(key, [None] * len(self.image_topics))
        slot[index] = msg
        for old in [k for k in self.pending if k < key - 10 * max(tol_ns, 1)]:
            del self.pending[old]
        if all(m is not None for m in slot):
            del self.pending[key]
            self.track(slot)

    def track(self, images: list[Image]) -> None:
        """Run the tracker on one frame and publish its pose or the reason there is none."""
        header = images[0].header
        latency_s = self.diagnostics.latency_s(header.stamp)
        try:
            arrays = [image_to_array(m) for m in images]
            result = self.tracker.update(arrays)
        except (ImageEncodingError, ColorGloveError, ValueError) as exc:
            self.get_logger().warn(f'frame dropped: {exc}', throttle_duration_sec=1.0)
            self.stats.no_hand(f'bad frame: {exc}', error=True, latency_s=latency_s)
            self.outputs.publish_no_hand(header, f'bad frame: {exc}')
            return
        if result.q is None:
            self.stats.no_hand(result.reason, latency_s=latency_s)
            self.outputs.publish_no_hand(header, result.reason)
            return
        header.frame_id = self.tracker.cameras[0].frame_id
        self.outputs.publish_pose(result.q, self.model.keypoints(result.q), header)
        fit = result.fit
        links = [(c.name, n) for c, n in zip(self.tracker.cameras, fit.links_found, strict=True)]
        self.stats.hand(latency_s, **{f'links found {name}': n for name, n in links})
        self.outputs.publish_status(edge_tracking_status(
            links, fit.rms_px, result.time_ms, stamp_key(header.stamp)))


def main(args: list[str] | None = None) -> int:
    """Entry point of ``edge_tracker_node``."""
    return run_node(EdgeTrackerNode, args)


if __name__ == '__main__':
    sys.exit(main())
