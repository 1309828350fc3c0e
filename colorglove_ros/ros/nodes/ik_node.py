"""ik_node: ``HandPoseCandidates`` -> ``JointState`` (URDF joint names), the wrist pose, a
skeleton ``MarkerArray`` and an overlay image, by Gauss-Newton IK with temporal smoothing over
one or several calibrated cameras."""
from __future__ import annotations

import sys
import traceback
from collections import deque
from dataclasses import replace

import numpy as np
from colorglove_msgs.msg import HandObservation, HandPoseCandidates
from geometry_msgs.msg import PoseStamped
from rclpy.node import Node
from sensor_msgs.msg import Image, JointState
from std_msgs.msg import String
from visualization_msgs.msg import MarkerArray

from colorglove_ros.core.camera import CalibrationError, load_calibration
from colorglove_ros.core.hand.glove import default_hand
from colorglove_ros.core.hand.overlay import draw_skeleton
from colorglove_ros.core.tracking.config import load_ik_config
from colorglove_ros.core.tracking.tracker import HandTracker
from colorglove_ros.core.tracking.types import CameraObservation, IKError
from colorglove_ros.core.validation import InvalidInputError, validate_hand_depth
from colorglove_ros.paths import resolve_path
from colorglove_ros.ros.conversions import (
    camera_observation_from_msg,
    pose_prior_from_candidates_msg,
    pose_to_joint_state_msg,
    pose_to_wrist_pose_msg,
    skeleton_to_markers_msg,
    stamp_to_seconds,
    wrist_pose_to_tf_msg,
)
from colorglove_ros.ros.image import ImageEncodingError, array_to_image, image_to_rgb8
from colorglove_ros.ros.message_checks import check_candidates_msg, check_observation_msg
from colorglove_ros.ros.nodes.common import (
    LATEST_IMAGE,
    LATEST_ONLY,
    StartupError,
    declare,
    run_node,
)

STAMP_MATCH_TOLERANCE_S = 0.02   # an extra camera's frame within this of the primary's counts


class IKNode(Node):
    """Refines the looked-up pose and publishes the tracker's outputs."""

    def __init__(self, **kwargs) -> None:
        super().__init__('ik', **kwargs)
        calibration_file = declare(self, 'calibration_file', 'config/calibration.yaml',
                                   'camera calibration YAML; camera 0 is the lookup camera')
        ik_config = declare(self, 'ik_config', 'config/ik.yaml', 'IK settings and covariances')
        enable_ik = declare(self, 'enable_ik', True, 'false: publish the blended lookup pose')
        enable_smoothing = declare(self, 'enable_smoothing', True,
                                   'use the previous frame as a prior (temporal smoothing)')
        self.publish_overlay = declare(
            self, 'publish_overlay', False,
            'also draw the fitted skeleton on the camera image and publish it on hand/overlay '
            '(subscribes to the camera images; a few ms of CPU per frame)')
        extra_topics = declare(self, 'extra_observation_topics', '',
                               'comma-separated HandObservation topics of cameras 1..N-1')
        wait_s = declare(self, 'extra_observation_wait_s', 0.05,
                         'longest wait for the extra cameras\' observations of a frame, seconds',
                         0.0, 1.0)
        try:
            calibration = load_calibration(resolve_path(calibration_file))
            config = load_ik_config(resolve_path(ik_config))
            model, mesh, _ = default_hand(calibration.hand_length_m)
            config = replace(config, enable_ik=enable_ik, enable_smoothing=enable_smoothing)
            self.tracker = HandTracker(model, mesh, calibration.cameras, config)
        except (CalibrationError, IKError, ValueError) as exc:
            raise StartupError(f'ik_node cannot start: {exc}') from exc
        self.model = model
        self.num_vertices = mesh.num_vertices
        self.cameras = calibration.cameras
        topics = [t.strip() for t in extra_topics.split(',') if t.strip()]
        if len(topics) != len(self.cameras) - 1:
            raise StartupError(
                f'ik_node cannot start: {len(self.cameras)} cameras calibrated but '
                f'{len(topics)} extra observation topic(s) given; set extra_observation_topics')
        self.extra_observations: list[deque[HandObservation]] = [deque(maxlen=30)
                                                                 for _ in topics]
        for index, topic in enumerate(topics):
            self.create_subscription(HandObservation, topic,
                                     lambda msg, i=index: self.on_extra_observation(i, msg), 10)
        # candidates waiting for the other cameras' observations of the same frame
        self.pending: HandPoseCandidates | None = None
        self.pending_timer = self.create_timer(wait_s, self._process_pending, autostart=False)
        self.recent_images: deque[Image] = deque(maxlen=15)
        self.joint_pub = self.create_publisher(JointState, 'hand/joint_states', 10)
        self.wrist_pub = self.create_publisher(PoseStamped, 'hand/wrist_pose', 10)
        self.marker_pub = self.create_publisher(MarkerArray, 'hand/markers', 10)
        self.overlay_pub = self.create_publisher(Image, 'hand/overlay', 2)
        self.status_pub = self.create_publisher(String, 'hand/tracking_status', 10)
        self.create_subscription(HandPoseCandidates, 'hand/pose_candidates', self.on_candidates,
                                 LATEST_ONLY)
        if self.publish_overlay:
            self.create_subscription(Image, 'camera/image_raw',
                                     lambda image: self.recent_images.append(image), LATEST_IMAGE)
        self.hand_was_found = False
        self.tf_pub = self._tf_publisher()
        self.get_logger().info(f'tracking with {len(self.cameras)} camera(s)')

    def _tf_publisher(self):
        """A /tf publisher for the camera -> palm transform (so robot_state_publisher's URDF
        frames hang off the camera), when tf2_msgs is installed (native ROS 2; it is not on
        PyPI, where the wrist pose is on /hand/wrist_pose only)."""
        try:
            from tf2_msgs.msg import TFMessage
        except ImportError:
            self.get_logger().info('tf2_msgs not installed: camera->palm TF not broadcast '
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
        matching in time, or whose frame_id is not its calibrated one, did not see the hand."""
        observations = []
        for index, camera in enumerate(self.cameras[1:]):
            match = self._matching_observation(index, stamp)
            if match is not None and match.header.frame_id != camera.frame_id:
                self.get_logger().warn(
                    f'observation of camera {index + 1} has frame_id '
                    f'{match.header.frame_id!r}, calibrated {camera.frame_id!r}: ignored',
                    throttle_duration_sec=1.0)
                match = None
            if match is not None and match.hand_found:
                try:
                    check_observation_msg(match, (camera.width, camera.height))
                except InvalidInputError as exc:
                    self.get_logger().warn(f'observation of camera {index + 1} ignored: {exc}',
                                           throttle_duration_sec=1.0)
                    match = None
            observations.append(CameraObservation(hand_found=False) if match is None
                                else camera_observation_from_msg(match))
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

    def _check_depth(self, q: np.ndarray) -> np.ndarray:
        """Refuse a pose with any hand keypoint at an implausible depth from any camera
        (behind or just in front of its plane, or far away); return the keypoints."""
        keypoints = self.model.keypoints(q)
        for camera in self.cameras:
            validate_hand_depth(camera.world_to_camera(keypoints), camera.name)
        return keypoints

    def track(self, msg: HandPoseCandidates) -> None:
        """Run the tracker on one frame's candidates and publish the results. Candidates
        that fail validation, and results without a matched constraint or at an implausible
        depth, give 'no hand' with the reason; no message stops the node."""
        try:
            self._track(msg)
        except Exception as exc:   # last line of defence: a message must never stop the node
            self.get_logger().error(f'tracking failed: {exc!r}\n{traceback.format_exc()}',
                                    throttle_duration_sec=1.0)
            self.tracker.reset()
            self._report_no_hand(msg, f'tracking failed: {exc!r}')

    def _track(self, msg: HandPoseCandidates) -> None:
        stamp = stamp_to_seconds(msg.header.stamp)
        try:
            prior = None
            if msg.hand_found:
                camera = self.cameras[0]
                blended = check_candidates_msg(msg, self.num_vertices,
                                               (camera.width, camera.height))
                self._check_depth(blended)
                prior = pose_prior_from_candidates_msg(msg)
            observations = [camera_observation_from_msg(msg.observation),
                            *self._extra_camera_observations(stamp)]
            result = self.tracker.update(prior, observations, stamp)
        except (IKError, InvalidInputError, ValueError) as exc:
            self.get_logger().warn(f'bad candidates message: {exc}', throttle_duration_sec=1.0)
            self.tracker.reset()
            self._report_no_hand(msg, f'bad candidates: {exc}')
            return
        if not result.found:
            self._report_no_hand(msg, msg.status or 'lost')
            return
        reason = ''
        keypoints = None
        if result.num_constraints == 0:
            reason = 'no constraint matched an observed blob'
        elif not np.all(np.isfinite(result.q)):
            reason = 'non-finite pose'
        else:
            try:
                keypoints = self._check_depth(result.q)
            except InvalidInputError as exc:
                reason = f'fitted pose refused: {exc}'
        if reason:
            self.get_logger().warn(f'no pose published: {reason}', throttle_duration_sec=1.0)
            self.tracker.reset()
            self._report_no_hand(msg, reason)
            return
        self.hand_was_found = True
        self.joint_pub.publish(pose_to_joint_state_msg(result.q, msg.header))
        wrist = pose_to_wrist_pose_msg(result.q, msg.header)
        self.wrist_pub.publish(wrist)
        if self.tf_pub is not None:
            self.tf_pub.publish(wrist_pose_to_tf_msg(wrist, child_frame_id='palm'))
        self.marker_pub.publish(skeleton_to_markers_msg(keypoints, msg.header))
        per_camera = ', '.join(f'{camera.name} {count}' for camera, count in
                               zip(self.cameras, result.constraints_per_camera, strict=False))
        self.status_pub.publish(String(
            data=f'tracking: {result.num_constraints} constraints ({per_camera}), reprojection '
                 f'{result.reprojection_error_px:.1f} px, IK {result.time_ms:.1f} ms'))
        if self.publish_overlay:
            self._publish_overlay(msg, keypoints, result.reprojection_error_px)

    def _report_no_hand(self, msg: HandPoseCandidates, reason: str) -> None:
        if self.hand_was_found:
            self.marker_pub.publish(skeleton_to_markers_msg(None, msg.header))
        self.hand_was_found = False
        self.status_pub.publish(String(data=f'no hand: {reason}'))

    def _publish_overlay(self, msg: HandPoseCandidates, keypoints, error_px: float) -> None:
        stamp = msg.header.stamp
        image = next((m for m in reversed(self.recent_images) if m.header.stamp == stamp), None)
        if image is None:
            return
        try:
            rgb = image_to_rgb8(image)
        except ImageEncodingError:
            return
        drawn = draw_skeleton(rgb, keypoints, self.cameras[0],
                              label=f'reprojection {error_px:.1f} px')
        self.overlay_pub.publish(array_to_image(drawn, 'rgb8', msg.header))


def main(args: list[str] | None = None) -> int:
    """Entry point of ``ik_node``."""
    return run_node(IKNode, args)


if __name__ == '__main__':
    sys.exit(main())
