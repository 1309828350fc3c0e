"""Convert between core results (numpy, dataclasses) and ROS messages. No rclpy import: the
message classes work without ``rclpy.init`` so all of this is unit-testable in one process."""
from __future__ import annotations

import numpy as np
from builtin_interfaces.msg import Time
from geometry_msgs.msg import Point, Pose, PoseStamped, Quaternion
from scipy.spatial.transform import Rotation
from sensor_msgs.msg import CameraInfo, JointState
from std_msgs.msg import Header

from colorglove_ros.core.camera import PinholeCamera
from colorglove_ros.core.hand_model import FINGER_DOF_NAMES

__all__ = [
    'stamp_to_seconds', 'seconds_to_stamp', 'camera_info_from_camera', 'joint_state_from_pose',
    'pose_stamped_from_pose', 'pose_from_joint_state',
]


def stamp_to_seconds(stamp: Time) -> float:
    """A header stamp as float seconds."""
    return stamp.sec + stamp.nanosec * 1e-9


def seconds_to_stamp(seconds: float) -> Time:
    """Float seconds as a header stamp."""
    sec = int(np.floor(seconds))
    return Time(sec=sec, nanosec=min(int(round((seconds - sec) * 1e9)), 999_999_999))


def camera_info_from_camera(camera: PinholeCamera, header: Header) -> CameraInfo:
    """``sensor_msgs/CameraInfo`` (plumb_bob) for a calibrated camera."""
    info = CameraInfo(header=header, width=camera.width, height=camera.height)
    info.distortion_model = 'plumb_bob'
    info.d = [float(v) for v in camera.distortion]
    info.k = [float(v) for v in camera.K.ravel()]
    info.r = [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]
    projection = np.zeros((3, 4))
    projection[:, :3] = camera.K
    info.p = [float(v) for v in projection.ravel()]
    return info


def joint_state_from_pose(pose: np.ndarray, header: Header) -> JointState:
    """The 20 finger joints of a 26-DOF pose as ``JointState`` (URDF joint names, radians)."""
    return JointState(header=header, name=list(FINGER_DOF_NAMES),
                      position=[float(v) for v in np.asarray(pose)[6:26]])


def pose_from_joint_state(msg: JointState) -> np.ndarray:
    """The 20 finger joint angles of a ``JointState``, in ``FINGER_DOF_NAMES`` order."""
    positions = dict(zip(msg.name, msg.position, strict=False))
    return np.array([positions[name] for name in FINGER_DOF_NAMES])


def pose_stamped_from_pose(pose: np.ndarray, header: Header) -> PoseStamped:
    """The wrist position and orientation of a 26-DOF pose as ``PoseStamped`` (camera frame)."""
    pose = np.asarray(pose, dtype=float)
    x, y, z, w = Rotation.from_rotvec(pose[3:6]).as_quat()
    return PoseStamped(header=header, pose=Pose(
        position=Point(x=float(pose[0]), y=float(pose[1]), z=float(pose[2])),
        orientation=Quaternion(x=float(x), y=float(y), z=float(z), w=float(w))))
