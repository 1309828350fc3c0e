"""rosbag2 (MCAP) sequences of camera frames with hand ground truth, written and read with rosbags.

Topics (standard Jazzy types only, so ``ros2 bag play`` works on a native install; every
message of a frame carries the same header stamp and frame_id ``camera_optical_frame``):

* ``/camera/image_raw``: ``sensor_msgs/msg/Image``, ``rgb8`` (or another encoding a driver
  sends, ``image_codec.RGB8_ENCODERS``, e.g. usb_cam's ``yuv422_yuy2``);
* ``/camera/camera_info``: ``sensor_msgs/msg/CameraInfo`` (plumb_bob, from a PinholeCamera);
* ``/hand/ground_truth/joint_states``: ``sensor_msgs/msg/JointState``, the 20 finger joints
  named ``FINGER_DOF_NAMES`` (radians);
* ``/hand/ground_truth/wrist_pose``: ``geometry_msgs/msg/PoseStamped``, the hand frame
  (wrist) in the camera optical frame (``q[0:6]``);
* ``/hand/ground_truth/keypoints``: ``visualization_msgs/msg/MarkerArray`` holding marker
  ns ``keypoints`` id 0 of type POINTS with the 21 keypoints in ``KEYPOINT_NAMES`` order
  (metres, camera frame), plus ns ``skeleton`` id 1, a LINE_LIST of the bones for RViz;
* ``/tf``: ``tf2_msgs/msg/TFMessage``, the ground-truth camera -> hand root (``palm``)
  transform of the frame (what ik_node broadcasts for its estimate), so a viewer shows the
  hand from the bag alone.

A bag of a calibrated rig also holds, for every extra camera k >= 1 named ``NAME`` in the
calibration, ``/NAME/camera/image_raw`` and ``/NAME/camera/camera_info`` (the topics of a
``camera_node`` run in namespace ``NAME``) with the same stamps and that camera's frame_id;
within a frame they are written before the primary image, so a player paced on the primary
image has published every view of the frame when it waits. Ground truth stays in camera 0's
frame. Such a bag also holds ``/tf_static`` (``tf2_msgs/msg/TFMessage``, once at the first
stamp, offered transient-local as a latched static broadcaster's and recorded so in the
metadata as rosbag2 does): camera 0's optical frame -> each extra camera's optical frame from
the calibrated extrinsics.
"""
from __future__ import annotations

from collections.abc import Callable, Iterable, Iterator, Sequence
from contextlib import closing
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from rosbags.highlevel import AnyReader, AnyReaderError
from rosbags.interfaces import (
    Qos,
    QosDurability,
    QosHistory,
    QosLiveliness,
    QosReliability,
    QosTime,
)
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import Stores, get_typestore

from colorglove_ros.core.camera import CalibrationError, PinholeCamera
from colorglove_ros.core.conventions import DEFAULT_HAND_LENGTH_M
from colorglove_ros.core.errors import ColorGloveError
from colorglove_ros.core.geometry import matrix_to_rotvec, rotvec_to_quaternion
from colorglove_ros.core.hand.frames import hand_root_frame
from colorglove_ros.core.hand.model import FINGER_DOF_NAMES, KEYPOINT_NAMES, NUM_DOFS
from colorglove_ros.core.hand.overlay import SKELETON_BONES
from colorglove_ros.core.hand.pose_fields import pose_from_fields, wrist_quaternion
from colorglove_ros.ros.image_codec import (
    ImageEncodingError,
    image_to_rgb8,
    rgb8_to_encoding,
)

__all__ = [
    'BagError', 'BagFrame', 'SequenceBagWriter', 'bag_deserialize', 'bag_messages',
    'open_bag_reader',
    'write_sequence_bag', 'read_sequence_bag',
    'bag_camera', 'camera_info_to_pinhole', 'camera_topics', 'TOPIC_IMAGE',
    'TOPIC_CAMERA_INFO', 'TOPIC_JOINTS', 'TOPIC_WRIST', 'TOPIC_KEYPOINTS', 'FRAME_ID',
    'DEFAULT_START_NS', 'SKELETON_BONES', 'bag_size_bytes', 'SyntheticBag', 'write_synthetic_bag',
    'TOPIC_TF', 'TOPIC_TF_STATIC', 'INFINITE_QOS_TIME', 'STATIC_TF_QOS', 'BagTransform',
    'read_transforms',
]

TOPIC_IMAGE = '/camera/image_raw'
TOPIC_CAMERA_INFO = '/camera/camera_info'
TOPIC_JOINTS = '/hand/ground_truth/joint_states'
TOPIC_WRIST = '/hand/ground_truth/wrist_pose'
TOPIC_KEYPOINTS = '/hand/ground_truth/keypoints'
TOPIC_TF = '/tf'
TOPIC_TF_STATIC = '/tf_static'
FRAME_ID = 'camera_optical_frame'
HAND_FRAME = hand_root_frame()
DEFAULT_START_NS = 1_700_000_000 * 10**9     # fixed so bags from one seed are identical
_KEYPOINTS_NS = 'keypoints'

_TYPES = {
    TOPIC_IMAGE: 'sensor_msgs/msg/Image',
    TOPIC_CAMERA_INFO: 'sensor_msgs/msg/CameraInfo',
    TOPIC_JOINTS: 'sensor_msgs/msg/JointState',
    TOPIC_WRIST: 'geometry_msgs/msg/PoseStamped',
    TOPIC_KEYPOINTS: 'visualization_msgs/msg/MarkerArray',
    TOPIC_TF: 'tf2_msgs/msg/TFMessage',
}
INFINITE_QOS_TIME = QosTime(2**31 - 1, 2**32 - 1)
"""How rosbag2 metadata writes an unset (infinite) QoS duration."""
STATIC_TF_QOS = Qos(QosHistory.KEEP_LAST, 1, QosReliability.RELIABLE,
                    QosDurability.TRANSIENT_LOCAL, INFINITE_QOS_TIME, INFINITE_QOS_TIME,
                    QosLiveliness.AUTOMATIC, INFINITE_QOS_TIME, False)
"""The QoS a static transform broadcaster (tf2_ros) offers on ``/tf_static``: reliable,
transient local, depth 1, as recorded in a bag's metadata."""

class BagError(ColorGloveError):
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
        return pose_from_fields(self.wrist_position, self.wrist_quaternion,
                                self.joint_positions)


def _typestore():
    return get_typestore(Stores.ROS2_JAZZY)


def open_bag_reader(path: str | Path, typestore: Any = None) -> AnyReader:
    """An opened rosbags reader of the bag folder ``path`` (``typestore``: the types the bag
    may not define itself, default Jazzy's); a bag whose metadata or files cannot be read is a
    :class:`BagError` naming it. The caller closes the reader (``with closing(...)``; not
    ``with`` the reader itself, which would open it again)."""
    try:
        reader = AnyReader([Path(path)], default_typestore=typestore or _typestore())
        reader.open()
    except (AnyReaderError, OSError) as error:   # OSError: no metadata.yaml, unreadable files
        raise BagError(f'cannot read the bag {path}: ' + ' '.join(str(error).split())) from error
    return reader


def bag_deserialize(reader: AnyReader, rawdata: Any, msgtype: str, path: str | Path) -> Any:
    """One message of ``reader`` decoded; undecodable bytes are a :class:`BagError` naming
    the bag ``path``."""
    try:
        return reader.deserialize(rawdata, msgtype)
    except Exception as error:        # whatever the damaged bytes made the decoder raise
        raise BagError(f'cannot decode a {msgtype} message of the bag {path}: '
                       f'{type(error).__name__}: {error}') from error


def bag_messages(reader: AnyReader, connections: Sequence[Any], path: str | Path
                 ) -> Iterator[tuple[Any, int, Any]]:
    """``reader``'s messages on ``connections`` in time order; one the reader cannot read (a
    damaged file) ends them with a :class:`BagError` naming the bag ``path``."""
    messages = reader.messages(connections=list(connections))
    while True:
        try:
            yield next(messages)
        except StopIteration:
            return
        except Exception as error:     # whatever the damaged bytes made the reader raise
            raise BagError(f'cannot read the bag {path} any further: '
                           f'{type(error).__name__}: {error}') from error


def camera_topics(camera: PinholeCamera, index: int) -> tuple[str, str]:
    """The image and CameraInfo topics of camera ``index`` of a rig: the default topics for
    camera 0, those of a ``camera_node`` in namespace ``camera.name`` for the others."""
    prefix = '' if index == 0 else f'/{camera.name}'
    return prefix + TOPIC_IMAGE, prefix + TOPIC_CAMERA_INFO


class SequenceBagWriter:
    """Write frames one at a time: ``with SequenceBagWriter(path, camera) as w: w.write(f)``.
    A frame is anything with ``image_rgb`` (H, W, 3) uint8, ``pose`` (26,) and
    ``keypoints_3d`` (21, 3) attributes (e.g. ``synth.SyntheticFrame``). ``extra_cameras``
    (cameras 1.. of a calibrated rig) add their images at the same stamps (and their
    extrinsics on ``/tf_static``). Images are written in ``encoding``
    (``image_codec.RGB8_ENCODERS``); ``hand_frame`` is the child frame of ``/tf``."""

    def __init__(self, path: str | Path, camera: PinholeCamera, *, fps: float = 30.0,
                 start_ns: int = DEFAULT_START_NS, frame_id: str = FRAME_ID,
                 extra_cameras: Sequence[PinholeCamera] = (), encoding: str = 'rgb8',
                 hand_frame: str = HAND_FRAME) -> None:
        if fps <= 0:
            raise BagError(f'fps must be positive, got {fps}')
        self.path = Path(path)
        if self.path.exists():
            raise BagError(f'{self.path} exists; rosbag2 writers need a new directory')
        self.camera = camera
        self.extra_cameras = tuple(extra_cameras)
        names = [c.name for c in self.extra_cameras]
        if len(set(names)) != len(names) or not all(n.isidentifier() for n in names):
            raise BagError(f'extra cameras need distinct names usable as a namespace: {names}')
        self.fps = float(fps)
        self.start_ns = int(start_ns)
        self.frame_id = frame_id
        self.encoding = encoding
        self.hand_frame = hand_frame
        try:
            rgb8_to_encoding(np.zeros((2, 2, 3), np.uint8), encoding)
        except ImageEncodingError as exc:
            raise BagError(str(exc)) from exc
        self.count = 0
        self._ts = _typestore()
        self._writer = Writer(self.path, version=9, storage_plugin=StoragePlugin.MCAP)
        self._conns: dict = {}

    def __enter__(self) -> SequenceBagWriter:
        self.open()
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        self.close()

    def _topic_types(self) -> dict[str, str]:
        types = {}
        for index, camera in enumerate(self.extra_cameras, start=1):
            image, info = camera_topics(camera, index)
            types[image] = _TYPES[TOPIC_IMAGE]
            types[info] = _TYPES[TOPIC_CAMERA_INFO]
        return {**types, **_TYPES}

    def open(self) -> None:
        """Create the bag directory and its topics."""
        self._writer.open()
        for topic, msgtype in self._topic_types().items():
            self._conns[topic] = (self._writer.add_connection(topic, msgtype,
                                                              typestore=self._ts), msgtype)
        if self.extra_cameras:
            msgtype = _TYPES[TOPIC_TF]
            connection = self._writer.add_connection(
                TOPIC_TF_STATIC, msgtype, typestore=self._ts,
                offered_qos_profiles=[STATIC_TF_QOS])
            header = self._header(self.start_ns, self.frame_id)
            static = self._ts.types[msgtype](transforms=[
                _transform(self._ts, header, camera.frame_id,
                           -camera.rotation.T @ camera.translation,
                           rotvec_to_quaternion(matrix_to_rotvec(camera.rotation.T)))
                for camera in self.extra_cameras])
            self._writer.write(connection, self.start_ns,
                               self._ts.serialize_cdr(static, msgtype))

    def close(self) -> None:
        """Finish the bag (writes metadata.yaml)."""
        self._writer.close()

    def stamp_of(self, index: int) -> int:
        """Header stamp (ns) of frame ``index``."""
        return self.start_ns + int(round(index * 1e9 / self.fps))

    def _header(self, stamp: int, frame_id: str):
        t = self._ts.types
        return t['std_msgs/msg/Header'](
            stamp=t['builtin_interfaces/msg/Time'](sec=stamp // 10**9, nanosec=stamp % 10**9),
            frame_id=frame_id)

    def _camera_msgs(self, camera: PinholeCamera, index: int, image: np.ndarray, header
                     ) -> dict:
        image = np.asarray(image)
        if image.dtype != np.uint8 or image.shape != (camera.height, camera.width, 3):
            raise BagError(f'image of camera {index} must be ({camera.height}, {camera.width}, '
                           f'3) uint8, got {image.shape} {image.dtype}')
        t = self._ts.types
        image_topic, info_topic = camera_topics(camera, index)
        try:
            pixels = rgb8_to_encoding(image, self.encoding)
        except ImageEncodingError as exc:
            raise BagError(f'camera {index}: {exc}') from exc
        # the CameraInfo first: a reader keeps the newest one and refuses images before it
        return {
            info_topic: _camera_info(self._ts, header, camera),
            image_topic: t['sensor_msgs/msg/Image'](
                header=header, height=camera.height, width=camera.width,
                encoding=self.encoding, is_bigendian=0,
                step=camera.width * pixels.shape[2], data=pixels.reshape(-1)),
        }

    def write(self, frame: object, stamp_ns: int | None = None,
              extra_images: Sequence[np.ndarray] = ()) -> int:
        """Write one frame's messages (``extra_images``: one RGB image per extra camera, seen
        at the same instant); return its stamp (ns)."""
        pose = np.asarray(frame.pose, dtype=float)
        keypoints = np.asarray(frame.keypoints_3d, dtype=float)
        if pose.shape != (NUM_DOFS,) or keypoints.shape != (len(KEYPOINT_NAMES), 3):
            raise BagError(f'pose must be (26,) and keypoints (21, 3), got {pose.shape}, '
                           f'{keypoints.shape}')
        if len(extra_images) != len(self.extra_cameras):
            raise BagError(f'{len(self.extra_cameras)} extra camera(s) but '
                           f'{len(extra_images)} extra image(s)')
        stamp = self.stamp_of(self.count) if stamp_ns is None else int(stamp_ns)
        ts = self._ts
        t = ts.types
        msgs = {}
        for index, (camera, image) in enumerate(zip(self.extra_cameras, extra_images,
                                                    strict=True), start=1):
            msgs.update(self._camera_msgs(camera, index, image,
                                          self._header(stamp, camera.frame_id)))
        header = self._header(stamp, self.frame_id)
        msgs.update(self._camera_msgs(self.camera, 0, frame.image_rgb, header))
        msgs.update({
            TOPIC_JOINTS: t['sensor_msgs/msg/JointState'](
                header=header, name=list(FINGER_DOF_NAMES), position=pose[6:].copy(),
                velocity=np.zeros(0), effort=np.zeros(0)),
            TOPIC_WRIST: t['geometry_msgs/msg/PoseStamped'](
                header=header, pose=_pose_msg(ts, pose[0:3], wrist_quaternion(pose))),
            TOPIC_KEYPOINTS: _keypoint_markers(ts, header, keypoints),
            TOPIC_TF: t['tf2_msgs/msg/TFMessage'](transforms=[
                _transform(ts, header, self.hand_frame, pose[0:3], wrist_quaternion(pose))]),
        })
        for topic, msg in msgs.items():
            connection, msgtype = self._conns[topic]
            self._writer.write(connection, stamp, ts.serialize_cdr(msg, msgtype))
        self.count += 1
        return stamp


def _pose_msg(ts, position: np.ndarray, quat_xyzw: np.ndarray):
    t = ts.types
    x, y, z = (float(v) for v in position)
    qx, qy, qz, qw = (float(v) for v in quat_xyzw)
    return t['geometry_msgs/msg/Pose'](
        position=t['geometry_msgs/msg/Point'](x=x, y=y, z=z),
        orientation=t['geometry_msgs/msg/Quaternion'](x=qx, y=qy, z=qz, w=qw))


def _transform(ts, header, child: str, translation: np.ndarray, quat_xyzw: np.ndarray):
    """A ``geometry_msgs/TransformStamped`` header.frame_id -> ``child``: the child frame's
    origin (``translation``) and axes (``quat_xyzw``) in the parent frame."""
    t = ts.types
    x, y, z = (float(v) for v in translation)
    qx, qy, qz, qw = (float(v) for v in quat_xyzw)
    return t['geometry_msgs/msg/TransformStamped'](
        header=header, child_frame_id=child, transform=t['geometry_msgs/msg/Transform'](
            translation=t['geometry_msgs/msg/Vector3'](x=x, y=y, z=z),
            rotation=t['geometry_msgs/msg/Quaternion'](x=qx, y=qy, z=qz, w=qw)))


def _camera_info(ts, header, cam: PinholeCamera):
    t = ts.types
    fields = cam.camera_info_fields()
    arrays = {key: np.asarray(fields[key], dtype=float) for key in ('d', 'k', 'r', 'p')}
    return t['sensor_msgs/msg/CameraInfo'](
        header=header, height=fields['height'], width=fields['width'],
        distortion_model=fields['distortion_model'], **arrays, binning_x=0, binning_y=0,
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


@dataclass(frozen=True)
class SyntheticBag:
    """A synthetic sequence written as a bag: its folder, frames written and the imaging
    conditions of the sequence (``core.synthetic.conditions.FrameConditions``)."""

    path: Path
    frames: int
    conditions: Any


def write_synthetic_bag(path: str | Path, cameras: Sequence[PinholeCamera], *, seed: int = 1,
                        num_frames: int = 300, fps: float = 30.0,
                        hand_length_m: float = DEFAULT_HAND_LENGTH_M, split: str = 'test',
                        progress: Callable[[Iterable[int]], Iterable[int]] | None = None,
                        encoding: str = 'rgb8') -> SyntheticBag:
    """Render synthetic sequence ``seed`` (``core.synthetic.sequences.SyntheticSequenceRenderer``
    with ``split`` conditions) as every camera of ``cameras`` sees it, primary first, and write
    it to a new MCAP bag at ``path`` (extra cameras on ``/NAME/camera/...``). ``progress``
    wraps the frame indices (e.g. ``tqdm``); images in ``encoding``. Raises ``SynthError`` for
    bad sequence settings
    and :class:`BagError` for a bag that cannot be written."""
    from colorglove_ros.core.synthetic.sequences import SyntheticSequenceRenderer

    sequence = SyntheticSequenceRenderer(cameras[0], seed=seed, num_frames=num_frames, fps=fps,
                                         hand_length_m=hand_length_m, split=split)
    try:
        with SequenceBagWriter(path, cameras[0], fps=fps, extra_cameras=cameras[1:],
                               encoding=encoding) as writer:
            indices = range(num_frames)
            for i in (progress(indices) if progress is not None else indices):
                # one instant seen by every camera, primary first
                views = sequence.render_views(i, cameras)
                writer.write(views[0], extra_images=[v.image_rgb for v in views[1:]])
    finally:
        sequence.close()
    return SyntheticBag(Path(path), writer.count, sequence.conditions)


# ----------------------------------------------------------------------------- reading
def camera_info_to_pinhole(msg: object, name: str = 'camera') -> PinholeCamera:
    """A PinholeCamera from a sensor_msgs/CameraInfo (K and D; identity extrinsics); a D
    that does not fit its distortion model is a :class:`BagError`."""
    K = np.asarray(msg.k, dtype=float).reshape(3, 3)
    try:
        camera = PinholeCamera(int(msg.width), int(msg.height), float(K[0, 0]), float(K[1, 1]),
                               float(K[0, 2]), float(K[1, 2]),
                               np.asarray(msg.d, dtype=float).copy(), name=name,
                               frame_id=str(msg.header.frame_id))
    except CalibrationError as exc:
        raise BagError(f'CameraInfo: {exc}') from exc
    if camera.distortion_model != msg.distortion_model:
        raise BagError(f'CameraInfo: distortion model {msg.distortion_model!r} with '
                       f'{len(camera.distortion)} coefficients')
    return camera


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
    with closing(open_bag_reader(path)) as reader:
        topics = set(_TYPES) - {TOPIC_TF} - (set() if with_images else {TOPIC_IMAGE})
        conns = [c for c in reader.connections if c.topic in topics]
        if not conns:
            raise BagError(f'{path} holds none of the topics {sorted(_TYPES)}')
        for conn, log_ns, raw in bag_messages(reader, conns, path):
            msg = bag_deserialize(reader, raw, conn.msgtype, path)
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
        try:
            frame.image_rgb = image_to_rgb8(msg, allow_mono=True)
        except ImageEncodingError as exc:
            raise BagError(f'{TOPIC_IMAGE}: {exc}') from exc
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
    with closing(open_bag_reader(path)) as reader:
        conns = [c for c in reader.connections if c.topic == TOPIC_CAMERA_INFO]
        for conn, _, raw in bag_messages(reader, conns, path):
            return camera_info_to_pinhole(bag_deserialize(reader, raw, conn.msgtype, path))
    raise BagError(f'{path} has no {TOPIC_CAMERA_INFO} message')


def bag_size_bytes(path: str | Path) -> int:
    """Total size of the files of a bag directory."""
    return sum(f.stat().st_size for f in Path(path).rglob('*') if f.is_file())


@dataclass(frozen=True)
class BagTransform:
    """One transform of a ``/tf`` or ``/tf_static`` message: ``parent`` -> ``child`` at
    ``stamp_ns``, the child's origin (3,) and axes as a quaternion (x, y, z, w) in the
    parent frame."""

    stamp_ns: int
    parent: str
    child: str
    translation: np.ndarray
    rotation_xyzw: np.ndarray


def read_transforms(path: str | Path, topic: str = TOPIC_TF) -> list[BagTransform]:
    """Every transform on ``topic`` (``/tf`` or ``/tf_static``) of a bag, in bag order."""
    out = []
    with closing(open_bag_reader(path)) as reader:
        conns = [c for c in reader.connections if c.topic == topic]
        for conn, _, raw in bag_messages(reader, conns, path):
            for tf in bag_deserialize(reader, raw, conn.msgtype, path).transforms:
                v, q = tf.transform.translation, tf.transform.rotation
                out.append(BagTransform(_stamp(tf), str(tf.header.frame_id),
                                        str(tf.child_frame_id), np.array([v.x, v.y, v.z]),
                                        np.array([q.x, q.y, q.z, q.w])))
    return out
