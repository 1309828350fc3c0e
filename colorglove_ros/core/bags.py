"""rosbag2 (MCAP) sequences of camera frames with hand ground truth, written and read with rosbags.

Topics (standard Jazzy types only, so ``ros2 bag play`` works on a native install; every
message of a frame carries the same header stamp and frame_id ``camera_optical_frame``):

* ``/camera/image_raw``: ``sensor_msgs/msg/Image``, ``rgb8``;
* ``/camera/camera_info``: ``sensor_msgs/msg/CameraInfo`` (plumb_bob, from a PinholeCamera);
* ``/hand/ground_truth/joint_states``: ``sensor_msgs/msg/JointState``, the 20 finger joints
  named ``FINGER_DOF_NAMES`` (radians);
* ``/hand/ground_truth/wrist_pose``: ``geometry_msgs/msg/PoseStamped``, the hand frame
  (wrist) in the camera optical frame (``q[0:6]``);
* ``/hand/ground_truth/keypoints``: ``visualization_msgs/msg/MarkerArray`` holding marker
  ns ``keypoints`` id 0 of type POINTS with the 21 keypoints in ``KEYPOINT_NAMES`` order
  (metres, camera frame), plus ns ``skeleton`` id 1, a LINE_LIST of the bones for RViz.
"""
from __future__ import annotations

from collections.abc import Iterable, Iterator
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from rosbags.highlevel import AnyReader
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import Stores, get_typestore
from scipy.spatial.transform import Rotation

from .camera import PinholeCamera
from .hand_model import FINGER_DOF_NAMES, KEYPOINT_NAMES, NUM_DOFS
from .overlay import SKELETON_BONES

__all__ = [
    'BagError', 'BagFrame', 'SequenceBagWriter', 'write_sequence_bag', 'read_sequence_bag',
    'bag_camera', 'image_msg_to_rgb', 'camera_info_to_pinhole', 'TOPIC_IMAGE',
    'TOPIC_CAMERA_INFO', 'TOPIC_JOINTS', 'TOPIC_WRIST', 'TOPIC_KEYPOINTS', 'FRAME_ID',
    'DEFAULT_START_NS', 'SKELETON_BONES', 'bag_size_bytes',
]

TOPIC_IMAGE = '/camera/image_raw'
TOPIC_CAMERA_INFO = '/camera/camera_info'
TOPIC_JOINTS = '/hand/ground_truth/joint_states'
TOPIC_WRIST = '/hand/ground_truth/wrist_pose'
TOPIC_KEYPOINTS = '/hand/ground_truth/keypoints'
FRAME_ID = 'camera_optical_frame'
DEFAULT_START_NS = 1_700_000_000 * 10**9     # fixed so bags from one seed are identical
_KEYPOINTS_NS = 'keypoints'

_TYPES = {
    TOPIC_IMAGE: 'sensor_msgs/msg/Image',
    TOPIC_CAMERA_INFO: 'sensor_msgs/msg/CameraInfo',
    TOPIC_JOINTS: 'sensor_msgs/msg/JointState',
    TOPIC_WRIST: 'geometry_msgs/msg/PoseStamped',
    TOPIC_KEYPOINTS: 'visualization_msgs/msg/MarkerArray',
}

# encoding -> (channels, dtype, channel order to reach RGB); alpha is dropped
_ENCODINGS: dict[str, tuple[int, str, tuple[int, ...]]] = {
    'rgb8': (3, 'u1', (0, 1, 2)), 'bgr8': (3, 'u1', (2, 1, 0)),
    'rgba8': (4, 'u1', (0, 1, 2)), 'bgra8': (4, 'u1', (2, 1, 0)),
    'mono8': (1, 'u1', (0, 0, 0)), '8UC3': (3, 'u1', (2, 1, 0)), '8UC1': (1, 'u1', (0, 0, 0)),
    'rgb16': (3, 'u2', (0, 1, 2)), 'bgr16': (3, 'u2', (2, 1, 0)),
    'rgba16': (4, 'u2', (0, 1, 2)), 'bgra16': (4, 'u2', (2, 1, 0)),
    'mono16': (1, 'u2', (0, 0, 0)),
}


class BagError(Exception):
    """A bag cannot be written or read, or holds an unsupported message."""


@dataclass
class BagFrame:
    """Everything a bag holds for one header stamp (None for topics it lacks)."""

    stamp_ns: int
    image_rgb: np.ndarray | None = None
    camera: PinholeCamera | None = None
    joint_names: list[str] = field(default_factory=list)
    joint_positions: np.ndarray | None = None     # (20,) in FINGER_DOF_NAMES order
    wrist_position: np.ndarray | None = None      # (3,) metres
    wrist_quaternion: np.ndarray | None = None    # (4,) x, y, z, w
    keypoints_3d: np.ndarray | None = None        # (21, 3)

    @property
    def pose(self) -> np.ndarray | None:
        """The 26-vector q, or None unless both the wrist pose and the joints are present."""
        if self.wrist_position is None or self.joint_positions is None:
            return None
        q = np.zeros(NUM_DOFS)
        q[0:3] = self.wrist_position
        q[3:6] = Rotation.from_quat(self.wrist_quaternion).as_rotvec()
        q[6:] = self.joint_positions
        return q


def _typestore():
    return get_typestore(Stores.ROS2_JAZZY)


class SequenceBagWriter:
    """Write frames one at a time: ``with SequenceBagWriter(path, camera) as w: w.write(f)``.
    A frame is anything with ``image_rgb`` (H, W, 3) uint8, ``pose`` (26,) and
    ``keypoints_3d`` (21, 3) attributes (e.g. ``synth.SyntheticFrame``)."""

    def __init__(self, path: str | Path, camera: PinholeCamera, *, fps: float = 30.0,
                 start_ns: int = DEFAULT_START_NS, frame_id: str = FRAME_ID) -> None:
        if fps <= 0:
            raise BagError(f'fps must be positive, got {fps}')
        self.path = Path(path)
        if self.path.exists():
            raise BagError(f'{self.path} exists; rosbag2 writers need a new directory')
        self.camera = camera
        self.fps = float(fps)
        self.start_ns = int(start_ns)
        self.frame_id = frame_id
        self.count = 0
        self._ts = _typestore()
        self._writer = Writer(self.path, version=9, storage_plugin=StoragePlugin.MCAP)
        self._conns: dict = {}

    def __enter__(self) -> SequenceBagWriter:
        self.open()
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        self.close()

    def open(self) -> None:
        """Create the bag directory and its topics."""
        self._writer.open()
        for topic, msgtype in _TYPES.items():
            self._conns[topic] = self._writer.add_connection(topic, msgtype, typestore=self._ts)

    def close(self) -> None:
        """Finish the bag (writes metadata.yaml)."""
        self._writer.close()

    def stamp_of(self, index: int) -> int:
        """Header stamp (ns) of frame ``index``."""
        return self.start_ns + int(round(index * 1e9 / self.fps))

    def write(self, frame: object, stamp_ns: int | None = None) -> int:
        """Write one frame's five messages; return its stamp (ns)."""
        image = np.asarray(frame.image_rgb)
        pose = np.asarray(frame.pose, dtype=float)
        keypoints = np.asarray(frame.keypoints_3d, dtype=float)
        cam = self.camera
        if image.dtype != np.uint8 or image.shape != (cam.height, cam.width, 3):
            raise BagError(f'image must be ({cam.height}, {cam.width}, 3) uint8, got '
                           f'{image.shape} {image.dtype}')
        if pose.shape != (NUM_DOFS,) or keypoints.shape != (len(KEYPOINT_NAMES), 3):
            raise BagError(f'pose must be (26,) and keypoints (21, 3), got {pose.shape}, '
                           f'{keypoints.shape}')
        stamp = self.stamp_of(self.count) if stamp_ns is None else int(stamp_ns)
        ts = self._ts
        t = ts.types
        header = t['std_msgs/msg/Header'](
            stamp=t['builtin_interfaces/msg/Time'](sec=stamp // 10**9, nanosec=stamp % 10**9),
            frame_id=self.frame_id)
        msgs = {
            TOPIC_IMAGE: t['sensor_msgs/msg/Image'](
                header=header, height=cam.height, width=cam.width, encoding='rgb8',
                is_bigendian=0, step=cam.width * 3,
                data=np.ascontiguousarray(image).reshape(-1)),
            TOPIC_CAMERA_INFO: _camera_info(ts, header, cam),
            TOPIC_JOINTS: t['sensor_msgs/msg/JointState'](
                header=header, name=list(FINGER_DOF_NAMES), position=pose[6:].copy(),
                velocity=np.zeros(0), effort=np.zeros(0)),
            TOPIC_WRIST: t['geometry_msgs/msg/PoseStamped'](
                header=header, pose=_pose_msg(ts, pose[0:3], Rotation.from_rotvec(
                    pose[3:6]).as_quat())),
            TOPIC_KEYPOINTS: _keypoint_markers(ts, header, keypoints),
        }
        for topic, msg in msgs.items():
            self._writer.write(self._conns[topic], stamp,
                               ts.serialize_cdr(msg, _TYPES[topic]))
        self.count += 1
        return stamp


def _pose_msg(ts, position: np.ndarray, quat_xyzw: np.ndarray):
    t = ts.types
    x, y, z = (float(v) for v in position)
    qx, qy, qz, qw = (float(v) for v in quat_xyzw)
    return t['geometry_msgs/msg/Pose'](
        position=t['geometry_msgs/msg/Point'](x=x, y=y, z=z),
        orientation=t['geometry_msgs/msg/Quaternion'](x=qx, y=qy, z=qz, w=qw))


def _camera_info(ts, header, cam: PinholeCamera):
    t = ts.types
    d = np.zeros(5)
    dist = np.asarray(cam.distortion, dtype=float)
    d[:min(5, len(dist))] = dist[:5]
    K = cam.K
    P = np.hstack([K, np.zeros((3, 1))])
    return t['sensor_msgs/msg/CameraInfo'](
        header=header, height=cam.height, width=cam.width, distortion_model='plumb_bob',
        d=d, k=K.reshape(-1).astype(float), r=np.eye(3).reshape(-1), p=P.reshape(-1),
        binning_x=0, binning_y=0,
        roi=t['sensor_msgs/msg/RegionOfInterest'](x_offset=0, y_offset=0, height=0, width=0,
                                                  do_rectify=False))


def _marker(ts, header, ns: str, marker_id: int, kind: int, points: np.ndarray,
            width: float, rgba: tuple[float, float, float, float]):
    t = ts.types
    Marker = t['visualization_msgs/msg/Marker']
    return Marker(
        header=header, ns=ns, id=marker_id, type=kind, action=Marker.ADD,
        pose=_pose_msg(ts, np.zeros(3), np.array([0.0, 0.0, 0.0, 1.0])),
        scale=t['geometry_msgs/msg/Vector3'](x=width, y=width, z=width),
        color=t['std_msgs/msg/ColorRGBA'](r=rgba[0], g=rgba[1], b=rgba[2], a=rgba[3]),
        lifetime=t['builtin_interfaces/msg/Duration'](sec=0, nanosec=0), frame_locked=False,
        points=[t['geometry_msgs/msg/Point'](x=float(p[0]), y=float(p[1]), z=float(p[2]))
                for p in points],
        colors=[], texture_resource='',
        texture=t['sensor_msgs/msg/CompressedImage'](header=header, format='',
                                                     data=np.zeros(0, np.uint8)),
        uv_coordinates=[], text='', mesh_resource='',
        mesh_file=t['visualization_msgs/msg/MeshFile'](filename='', data=np.zeros(0, np.uint8)),
        mesh_use_embedded_materials=False)


def _keypoint_markers(ts, header, keypoints: np.ndarray):
    Marker = ts.types['visualization_msgs/msg/Marker']
    bones = keypoints[np.array(SKELETON_BONES).reshape(-1)]
    return ts.types['visualization_msgs/msg/MarkerArray'](markers=[
        _marker(ts, header, _KEYPOINTS_NS, 0, Marker.POINTS, keypoints, 0.008,
                (1.0, 1.0, 0.0, 1.0)),
        _marker(ts, header, 'skeleton', 1, Marker.LINE_LIST, bones, 0.003, (0.0, 1.0, 0.0, 1.0)),
    ])


def write_sequence_bag(path: str | Path, frames: Iterable[object], camera: PinholeCamera, *,
                       fps: float = 30.0, start_ns: int = DEFAULT_START_NS) -> int:
    """Write frames (``image_rgb``, ``pose``, ``keypoints_3d``; e.g. SyntheticFrame) as an
    MCAP rosbag2 at ``fps``; return the number of frames written. On a failure the partial
    bag is closed (kept for inspection) and the exception re-raised."""
    with SequenceBagWriter(path, camera, fps=fps, start_ns=start_ns) as writer:
        for frame in frames:
            writer.write(frame)
        return writer.count


# ----------------------------------------------------------------------------- reading
def image_msg_to_rgb(msg: object) -> np.ndarray:
    """(H, W, 3) uint8 RGB from a sensor_msgs/Image honouring ``encoding``, ``step`` and
    ``is_bigendian`` (16-bit images keep their high byte; mono is replicated)."""
    enc = str(msg.encoding)
    if enc not in _ENCODINGS:
        raise BagError(f'unsupported image encoding {enc!r}')
    channels, kind, order = _ENCODINGS[enc]
    h, w, step = int(msg.height), int(msg.width), int(msg.step)
    itemsize = 2 if kind == 'u2' else 1
    row = w * channels * itemsize
    data = np.asarray(msg.data, dtype=np.uint8)
    if step < row or data.size < h * step:
        raise BagError(f'image data too short: {data.size} bytes for {h} rows of step {step}')
    rows = data[:h * step].reshape(h, step)[:, :row]
    if itemsize == 2:
        dtype = np.dtype('>u2' if msg.is_bigendian else '<u2')
        pix = np.ascontiguousarray(rows).view(dtype).reshape(h, w, channels)
        pix = (pix >> 8).astype(np.uint8)
    else:
        pix = rows.reshape(h, w, channels)
    return np.ascontiguousarray(pix[..., list(order)])


def camera_info_to_pinhole(msg: object, name: str = 'camera') -> PinholeCamera:
    """A PinholeCamera from a sensor_msgs/CameraInfo (K and D; identity extrinsics)."""
    K = np.asarray(msg.k, dtype=float).reshape(3, 3)
    return PinholeCamera(int(msg.width), int(msg.height), float(K[0, 0]), float(K[1, 1]),
                         float(K[0, 2]), float(K[1, 2]), np.asarray(msg.d, dtype=float).copy(),
                         name=name, frame_id=str(msg.header.frame_id))


def _stamp(msg: object) -> int:
    return int(msg.header.stamp.sec) * 10**9 + int(msg.header.stamp.nanosec)


def read_sequence_bag(path: str | Path, *, with_images: bool = True,
                      window_ns: int = 2 * 10**9) -> Iterator[BagFrame]:
    """Yield :class:`BagFrame` s of a bag written by :func:`write_sequence_bag` (or any bag
    using those topics), one per header stamp in stamp order. Messages are grouped by
    header stamp; a frame is emitted once the log time has moved ``window_ns`` past it."""
    path = Path(path)
    if not path.exists():
        raise BagError(f'bag not found: {path}')
    pending: dict[int, BagFrame] = {}
    with AnyReader([path], default_typestore=_typestore()) as reader:
        topics = set(_TYPES) if with_images else set(_TYPES) - {TOPIC_IMAGE}
        conns = [c for c in reader.connections if c.topic in topics]
        if not conns:
            raise BagError(f'{path} holds none of the topics {sorted(_TYPES)}')
        for conn, log_ns, raw in reader.messages(connections=conns):
            msg = reader.deserialize(raw, conn.msgtype)
            stamp = _stamp(msg.markers[0]) if conn.topic == TOPIC_KEYPOINTS and msg.markers \
                else (_stamp(msg) if hasattr(msg, 'header') else log_ns)
            frame = pending.setdefault(stamp, BagFrame(stamp))
            _fill(frame, conn.topic, msg)
            done = sorted(s for s in pending if s < log_ns - window_ns)
            for s in done:
                yield pending.pop(s)
    for s in sorted(pending):
        yield pending.pop(s)


def _fill(frame: BagFrame, topic: str, msg: object) -> None:
    if topic == TOPIC_IMAGE:
        frame.image_rgb = image_msg_to_rgb(msg)
    elif topic == TOPIC_CAMERA_INFO:
        frame.camera = camera_info_to_pinhole(msg)
    elif topic == TOPIC_JOINTS:
        names = list(msg.name)
        pos = np.asarray(msg.position, dtype=float)
        frame.joint_names = names
        try:
            frame.joint_positions = pos[[names.index(n) for n in FINGER_DOF_NAMES]]
        except ValueError as exc:
            raise BagError(f'joint state lacks a finger joint: {exc}') from exc
    elif topic == TOPIC_WRIST:
        p, o = msg.pose.position, msg.pose.orientation
        frame.wrist_position = np.array([p.x, p.y, p.z])
        frame.wrist_quaternion = np.array([o.x, o.y, o.z, o.w])
    elif topic == TOPIC_KEYPOINTS:
        for marker in msg.markers:
            if marker.ns == _KEYPOINTS_NS:
                frame.keypoints_3d = np.array([[p.x, p.y, p.z] for p in marker.points])


def bag_camera(path: str | Path) -> PinholeCamera:
    """The camera of the first CameraInfo message in a bag."""
    with AnyReader([Path(path)], default_typestore=_typestore()) as reader:
        conns = [c for c in reader.connections if c.topic == TOPIC_CAMERA_INFO]
        for conn, _, raw in reader.messages(connections=conns):
            return camera_info_to_pinhole(reader.deserialize(raw, conn.msgtype))
    raise BagError(f'{path} has no {TOPIC_CAMERA_INFO} message')


def bag_size_bytes(path: str | Path) -> int:
    """Total size of the files of a bag directory."""
    return sum(f.stat().st_size for f in Path(path).rglob('*') if f.is_file())
