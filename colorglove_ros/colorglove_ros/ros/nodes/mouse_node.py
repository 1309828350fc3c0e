"""mouse_node: the DigitEyes 3-D mouse. Any hand tracker's ``hand/joint_states`` +
``hand/wrist_pose`` (glove or edge tracker) -> ``mouse/cursor`` (``geometry_msgs/PointStamped``
in the table frame: palm position in the table plane, index-finger height as z) and
``mouse/buttons`` (``sensor_msgs/Joy``: buttons [thumb, little finger], axes [x, y, z] of the
cursor), smoothed; the mapping is documented in ``core.tracking.mouse``.

The table plane is ``table_origin`` + ``table_x_axis`` / ``table_y_axis`` (camera optical
frame, orthonormal) or, with ``table_tilt_deg`` > 0, the table seen by a camera tilted that
far from the vertical whose optical axis meets it ``table_distance_m`` away.

With ``press_max_residual_ratio`` > 0 a press needs evidence (``core.tracking.mouse``): each
pose waits for its frame's ``edge_tracker_node`` status line on ``hand/tracking_status``
(``core.hand.frame_evidence``, paired by the frame's stamp) and a button goes down only on a
pose whose edge residual is at most that many times the median of the last
``residual_window_s``; poses without such a line (another tracker's) press as before.
"""
from __future__ import annotations

import math
import sys

import numpy as np
from geometry_msgs.msg import Point, PointStamped, PoseStamped
from rclpy.node import Node
from sensor_msgs.msg import JointState, Joy
from std_msgs.msg import Header, String

from colorglove_ros.core.errors import ColorGloveError
from colorglove_ros.core.hand.frame_evidence import (
    EvidencePairer,
    FrameEvidence,
    parse_edge_tracking_status,
)
from colorglove_ros.core.hand.frames import finger_joint_names
from colorglove_ros.core.hand.model import HandModel
from colorglove_ros.core.tracking.mouse import Mouse3D, MouseConfig, TablePlane
from colorglove_ros.ros.conversions import pose_from_msgs, stamp_key, stamp_to_seconds
from colorglove_ros.ros.nodes.common import (
    JOINT_STATES_TOPIC,
    TRACKING_STATUS_TOPIC,
    WRIST_POSE_TOPIC,
    declare,
    declare_frame_prefix,
    declare_hand_length,
    declare_limit,
    run_node,
    startup_errors,
)

__all__ = ['MouseNode', 'main']


class MouseNode(Node):
    """Hand pose in, cursor and buttons out."""

    def __init__(self, **kwargs) -> None:
        super().__init__('mouse', **kwargs)
        defaults = MouseConfig()
        tilt = declare(self, 'table_tilt_deg', 45.0,
                       'camera tilt from the vertical; > 0 derives the table plane from it and '
                       'table_distance_m, 0 uses table_origin/table_x_axis/table_y_axis',
                       0.0, 89.0)
        distance = declare(self, 'table_distance_m', 0.6,
                           'distance along the optical axis to the table, m', 0.05, 5.0)
        origin = declare(self, 'table_origin', [0.0, 0.0, 0.6],
                         'a point on the table, camera optical frame, m')
        x_axis = declare(self, 'table_x_axis', [1.0, 0.0, 0.0],
                         'cursor x direction on the table, camera frame (unit)')
        y_axis = declare(self, 'table_y_axis', [0.0, -0.7071067811865476, 0.7071067811865476],
                         'cursor y direction on the table, camera frame (unit, orthogonal to x)')
        self.frame_id = declare(self, 'table_frame_id', 'table', 'frame_id of the cursor')
        plane_gain = declare(self, 'plane_gain', defaults.plane_gain,
                             'cursor x, y per metre of palm motion', 0.01, 100.0)
        height_gain = declare(self, 'height_gain', defaults.height_gain,
                              'cursor z per metre of index-fingertip height', 0.01, 100.0)
        rest = declare(self, 'index_rest_height_m', defaults.index_rest_height_m,
                       'index fingertip height of the resting hand, m', -0.1, 0.2)
        press = declare(self, 'press_deg', list(defaults.press_deg),
                        'abduction (thumb, little) that presses each button, degrees')
        release = declare(self, 'release_deg', list(defaults.release_deg),
                          'abduction (thumb, little) that releases each button, degrees')
        smoothing = declare(self, 'smoothing_s', defaults.smoothing_s,
                            'low-pass time constant of cursor and angles, s (0 = none)',
                            0.0, 5.0)
        max_gap = declare(self, 'max_gap_s', defaults.max_gap_s,
                          'a longer gap between poses restarts the filter and releases the '
                          'buttons, s', 0.01, 10.0)
        ratio = declare_limit(self, 'press_max_residual_ratio',
                              defaults.press_max_residual_ratio,
                              'a button goes down only on a pose whose edge residual '
                              '(edge_tracker status line) is at most this many times the '
                              'recent median (0: off)', 100.0)
        window = declare(self, 'residual_window_s', defaults.residual_window_s,
                         'the recent residuals press_max_residual_ratio compares with, s',
                         0.1, 600.0)
        hand_length = declare_hand_length(self, 'hand length of the tracker, m')
        self.joint_names = finger_joint_names(declare_frame_prefix(self, 'mouse_node'))
        self.stamp_tolerance = declare(self, 'stamp_tolerance_s', 0.005,
                                       'joint state and wrist pose of one frame differ by '
                                       'at most this, s', 0.0, 1.0)
        with startup_errors('mouse_node', TypeError, ValueError):
            plane = (TablePlane.from_camera_tilt(tilt, distance) if tilt > 0 else
                     TablePlane(tuple(origin), tuple(x_axis), tuple(y_axis)))
            config = MouseConfig(plane, plane_gain, height_gain, rest, tuple(press),
                                 tuple(release), smoothing, max_gap,
                                 ratio, window)
            self.mouse = Mouse3D(HandModel(hand_length), config)
        self.wrist: PoseStamped | None = None
        self.pairer: EvidencePairer[tuple[np.ndarray, Header]] | None = None
        if math.isfinite(ratio):
            self.pairer = EvidencePairer()
            self.create_subscription(String, TRACKING_STATUS_TOPIC, self.on_status, 10)
        self.create_subscription(PoseStamped, WRIST_POSE_TOPIC, self.on_wrist, 10)
        self.create_subscription(JointState, JOINT_STATES_TOPIC, self.on_joints, 10)
        self.cursor_pub = self.create_publisher(PointStamped, 'mouse/cursor', 10)
        self.buttons_pub = self.create_publisher(Joy, 'mouse/buttons', 10)

    def on_wrist(self, msg: PoseStamped) -> None:
        """Keep the latest wrist pose."""
        self.wrist = msg

    def on_joints(self, msg: JointState) -> None:
        """Pair with the wrist pose of the same frame, update the mouse, publish."""
        stamp = stamp_to_seconds(msg.header.stamp)
        if self.wrist is None or abs(stamp_to_seconds(self.wrist.header.stamp) - stamp) \
                > self.stamp_tolerance:
            return
        try:
            q = pose_from_msgs(msg, self.wrist, self.joint_names)
        except (ColorGloveError, ValueError, KeyError) as exc:
            self.get_logger().warn(f'pose dropped: {exc}', throttle_duration_sec=1.0)
            return
        if self.pairer is None:
            self._update(q, msg.header, None)
            return
        for (q_ready, header), evidence in self.pairer.add_frame(
                stamp_key(msg.header.stamp), (q, msg.header)):
            self._update(q_ready, header, evidence)

    def on_status(self, msg: String) -> None:
        """Pair the edge tracker's evidence with its frame's pose."""
        if self.pairer is not None:
            for (q, header), evidence in self.pairer.add_status(
                    parse_edge_tracking_status(msg.data)):
                self._update(q, header, evidence)

    def _update(self, q: np.ndarray, header: Header, evidence: FrameEvidence | None) -> None:
        residual = math.nan if evidence is None else float(evidence.reprojection_px)
        try:
            state = self.mouse.update(q, stamp_to_seconds(header.stamp), residual)
        except (ColorGloveError, ValueError) as exc:
            self.get_logger().warn(f'pose dropped: {exc}', throttle_duration_sec=1.0)
            return
        header.frame_id = self.frame_id
        x, y, z = (float(v) for v in state.cursor)
        self.cursor_pub.publish(PointStamped(header=header, point=Point(x=x, y=y, z=z)))
        self.buttons_pub.publish(Joy(header=header, axes=[x, y, z],
                                     buttons=[int(b) for b in state.buttons]))


def main(args: list[str] | None = None) -> int:
    """Entry point of ``mouse_node``."""
    return run_node(MouseNode, args)


if __name__ == '__main__':
    sys.exit(main())
