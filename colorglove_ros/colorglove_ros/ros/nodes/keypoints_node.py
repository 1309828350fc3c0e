"""keypoints_node: the tracked hand's 21 keypoints (MediaPipe / MANO order) as
``geometry_msgs/PoseArray`` in the camera frame (``hand/keypoints``) and in the hand's wrist
frame (``hand/keypoints_wrist``), from ``hand/joint_states`` + ``hand/wrist_pose``."""
from __future__ import annotations

import sys

import numpy as np
from geometry_msgs.msg import Point, Pose, PoseArray, PoseStamped, Quaternion
from rclpy.node import Node
from scipy.spatial.transform import Rotation
from std_msgs.msg import Header

from colorglove_ros.core.hand.frames import hand_root_frame
from colorglove_ros.core.hand.keypoints import HandKeypoints, hand_keypoints
from colorglove_ros.ros.nodes.common import (
    declare,
    declare_frame_prefix,
    hand_model_from_calibration,
    run_node,
    subscribe_tracked_pose,
)

__all__ = ['KeypointsNode', 'pose_array_from_keypoints', 'main']


def pose_array_from_keypoints(keypoints: HandKeypoints, header: Header) -> PoseArray:
    """21 poses in ``keypoints`` order: position = keypoint, orientation = its link's."""
    quaternions = Rotation.from_matrix(keypoints.rotations).as_quat()
    return PoseArray(header=header, poses=[
        Pose(position=Point(x=float(p[0]), y=float(p[1]), z=float(p[2])),
             orientation=Quaternion(x=float(o[0]), y=float(o[1]), z=float(o[2]), w=float(o[3])))
        for p, o in zip(keypoints.positions, quaternions, strict=True)])


class KeypointsNode(Node):
    """Publishes the keypoints of every tracked frame."""

    def __init__(self, **kwargs) -> None:
        super().__init__('keypoints', **kwargs)
        self.model = hand_model_from_calibration(self, 'keypoints_node')
        frame_prefix = declare_frame_prefix(self, 'keypoints_node')
        self.hand_frame = declare(self, 'hand_frame', '',
                                  'frame_id of hand/keypoints_wrist; empty: the hand root link '
                                  '<frame_prefix>palm') or hand_root_frame(frame_prefix)
        self.camera_pub = self.create_publisher(PoseArray, 'hand/keypoints', 10)
        self.wrist_pub = self.create_publisher(PoseArray, 'hand/keypoints_wrist', 10)
        subscribe_tracked_pose(self, self.publish, frame_prefix)

    def publish(self, q: np.ndarray, wrist: PoseStamped) -> None:
        """Publish both keypoint arrays of a complete frame."""
        try:
            camera = hand_keypoints(self.model, q, 'camera')
            in_wrist = hand_keypoints(self.model, q, 'wrist')
        except ValueError as exc:
            self.get_logger().warn(f'bad pose: {exc}', throttle_duration_sec=1.0)
            return
        self.camera_pub.publish(pose_array_from_keypoints(camera, wrist.header))
        self.wrist_pub.publish(pose_array_from_keypoints(
            in_wrist, Header(stamp=wrist.header.stamp, frame_id=self.hand_frame)))


def main(args: list[str] | None = None) -> int:
    """Entry point of ``keypoints_node``."""
    return run_node(KeypointsNode, args)


if __name__ == '__main__':
    sys.exit(main())
