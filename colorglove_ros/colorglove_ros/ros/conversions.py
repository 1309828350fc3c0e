"""Convert between core results (numpy, dataclasses) and ROS messages. No rclpy import: the
message classes work without ``rclpy.init`` so all of this is unit-testable in one process."""
from __future__ import annotations

import math
from array import array
from collections.abc import Sequence

import numpy as np
from builtin_interfaces.msg import Time
from colorglove_msgs.msg import GestureEvent as GestureEventMsg
from colorglove_msgs.msg import HandObservation, HandPoseCandidates
from geometry_msgs.msg import Point, Point32, PolygonStamped, Pose, PoseStamped, Quaternion
from sensor_msgs.msg import CameraInfo, JointState
from std_msgs.msg import ColorRGBA, Header
from visualization_msgs.msg import Marker, MarkerArray

from colorglove_ros.core.camera import PinholeCamera, camera_from_camera_info
from colorglove_ros.core.conventions import TINY_SIZE
from colorglove_ros.core.hand.gestures import EVENT_STATES, GestureError, GestureEvent
from colorglove_ros.core.hand.model import DOF_NAMES, FINGER_DOF_NAMES
from colorglove_ros.core.hand.overlay import SKELETON_BONES
from colorglove_ros.core.hand.pose_fields import pose_from_fields, wrist_quaternion
from colorglove_ros.core.lookup.types import LookupResult, ProjectionConstraints
from colorglove_ros.core.segmentation.crop import CropTransform
from colorglove_ros.core.segmentation.crop_prediction import CropPrediction
from colorglove_ros.core.segmentation.types import Observation
from colorglove_ros.core.tracking.types import Blobs, CameraObservation, PosePrior

__all__ = [
    'stamp_to_seconds', 'stamp_key', 'camera_to_camera_info_msg', 'camera_from_camera_info_msg',
    'pose_to_joint_state_msg',
    'pose_to_wrist_pose_msg', 'pose_from_joint_state_msg', 'pose_from_msgs',
    'crop_from_observation_msg',
    'tiny_labels_from_observation_msg', 'blob_count_of_observation_msg',
    'blobs_from_observation_msg', 'camera_observation_from_msg',
    'candidates_to_msg', 'candidate_arrays_from_msg', 'constraint_arrays_from_msg',
    'pose_prior_from_candidates_msg', 'skeleton_to_markers_msg',
    'observation_to_msg', 'wrist_pose_to_tf_msg', 'gesture_event_to_msg',
    'gesture_event_from_msg', 'crop_prediction_to_msg', 'crop_prediction_from_msg',
]


def stamp_to_seconds(stamp: Time) -> float:
    """A header stamp as float seconds."""
    return stamp.sec + stamp.nanosec * 1e-9


def stamp_key(stamp: Time) -> tuple[int, int]:
    """A header stamp as an exact, hashable key (sec, nanosec): what pairs a frame's messages."""
    return (stamp.sec, stamp.nanosec)


# GestureEvent.event constants by core event state ('start', 'end'), and back
_EVENT_CODES = {'start': GestureEventMsg.START, 'end': GestureEventMsg.END}
assert set(_EVENT_CODES) == set(EVENT_STATES)


def camera_to_camera_info_msg(camera: PinholeCamera, header: Header) -> CameraInfo:
    """``sensor_msgs/CameraInfo`` (plumb_bob or rational_polynomial) for a calibrated camera."""
    return CameraInfo(header=header, **camera.camera_info_fields())


def camera_from_camera_info_msg(msg: CameraInfo, *, rectified: bool = False) -> PinholeCamera:
    """The camera a ``CameraInfo`` describes (its frame_id, size, K, D and model; with
    ``rectified`` the projection matrix P and no distortion, for ``image_rect`` input)."""
    return camera_from_camera_info(
        int(msg.width), int(msg.height), list(msg.k), list(msg.d), str(msg.distortion_model),
        list(msg.p), rectified=rectified, frame_id=str(msg.header.frame_id) or
        'camera_optical_frame', where=f'CameraInfo of {msg.header.frame_id or "(no frame_id)"}')


def pose_to_joint_state_msg(pose: np.ndarray, header: Header,
                            joint_names: Sequence[str] = FINGER_DOF_NAMES) -> JointState:
    """The 20 finger joints of a 26-DOF pose as ``JointState`` (radians), named
    ``joint_names`` (``FINGER_DOF_NAMES`` order; default the plain URDF joint names, a
    prefixed hand's from ``core.hand.frames.finger_joint_names``)."""
    return JointState(header=header, name=_finger_joint_names(joint_names),
                      position=_packed('d', np.asarray(pose, np.float64)[6:26], np.float64))


def pose_from_joint_state_msg(msg: JointState,
                              joint_names: Sequence[str] = FINGER_DOF_NAMES) -> np.ndarray:
    """The 20 finger joint angles of a ``JointState``, in ``FINGER_DOF_NAMES`` order, read
    from the joints named ``joint_names`` (that order); a missing joint is a KeyError."""
    positions = dict(zip(msg.name, msg.position, strict=False))
    return np.array([positions[name] for name in _finger_joint_names(joint_names)])


def pose_from_msgs(joints: JointState, wrist: PoseStamped,
                   joint_names: Sequence[str] = FINGER_DOF_NAMES) -> np.ndarray:
    """The 26-DOF pose of a ``JointState`` (finger joints named ``joint_names``) and a wrist
    ``PoseStamped``."""
    p, o = wrist.pose.position, wrist.pose.orientation
    return pose_from_fields([p.x, p.y, p.z], [o.x, o.y, o.z, o.w],
                            pose_from_joint_state_msg(joints, joint_names))


def _finger_joint_names(joint_names: Sequence[str]) -> list[str]:
    names = list(joint_names)
    if len(names) != len(FINGER_DOF_NAMES):
        raise ValueError(f'{len(names)} joint names given, expected {len(FINGER_DOF_NAMES)} '
                         '(FINGER_DOF_NAMES order)')
    return names


def pose_to_wrist_pose_msg(pose: np.ndarray, header: Header) -> PoseStamped:
    """The wrist position and orientation of a 26-DOF pose as ``PoseStamped`` (camera frame)."""
    pose = np.asarray(pose, dtype=float)
    x, y, z, w = wrist_quaternion(pose)
    return PoseStamped(header=header, pose=Pose(
        position=Point(x=float(pose[0]), y=float(pose[1]), z=float(pose[2])),
        orientation=Quaternion(x=float(x), y=float(y), z=float(z), w=float(w))))


# --------------------------------------------------------------- observation and candidates
def crop_from_observation_msg(msg: HandObservation) -> CropTransform:
    """The tiny -> full-image crop transform carried by an observation."""
    return CropTransform(scale=msg.crop_scale, offset_x=msg.crop_offset_x,
                         offset_y=msg.crop_offset_y)


def tiny_labels_from_observation_msg(msg: HandObservation) -> np.ndarray:
    """The observation's 40x40 label image; raises ValueError if its size is wrong."""
    labels = np.asarray(msg.tiny_labels, dtype=np.uint8)
    if labels.size != TINY_SIZE * TINY_SIZE:
        raise ValueError(f'tiny_labels holds {labels.size} values, expected {TINY_SIZE ** 2}')
    return labels.reshape(TINY_SIZE, TINY_SIZE)


def blob_count_of_observation_msg(msg: HandObservation) -> int:
    """How many blobs the observation's parallel blob arrays describe; ValueError naming the
    arrays if their lengths disagree (one colour, one (x, y) and one pixel count a blob)."""
    count = len(msg.blob_colors)
    if len(msg.blob_centroids) != 2 * count or len(msg.blob_pixel_counts) != count:
        raise ValueError(f'blob arrays disagree: {count} blob_colors, '
                         f'{len(msg.blob_centroids)} blob_centroids values (expected '
                         f'{2 * count}), {len(msg.blob_pixel_counts)} blob_pixel_counts')
    return count


def blobs_from_observation_msg(msg: HandObservation) -> Blobs:
    """The observation's glove blobs (colour, full-image centroid, pixel count), copied from
    its parallel arrays; ValueError if their lengths disagree."""
    if not blob_count_of_observation_msg(msg):
        return Blobs.empty()
    return Blobs(color=np.frombuffer(msg.blob_colors, np.uint8).astype(np.int64),
                 centroid_px=np.array(msg.blob_centroids, np.float64).reshape(-1, 2),
                 pixel_count=np.frombuffer(msg.blob_pixel_counts, np.uint32).astype(float))


def camera_observation_from_msg(msg: HandObservation, blobs: Blobs | None = None
                                ) -> CameraObservation:
    """An observation message as the IK's per-camera input (with ``blobs``, its blobs
    already converted by :func:`blobs_from_observation_msg`)."""
    if not msg.hand_found:
        return CameraObservation(hand_found=False)
    return CameraObservation(hand_found=True,
                             blobs=blobs_from_observation_msg(msg) if blobs is None else blobs,
                             crop=crop_from_observation_msg(msg),
                             cut_by_border=bool(msg.cut_by_border))


def _packed(typecode: str, values: np.ndarray, dtype: type) -> array:
    """``values`` as the ``array.array`` a message array field takes as it is (one copy of the
    bytes, no Python number per element)."""
    return array(typecode, np.ascontiguousarray(values, dtype).tobytes())


# HandPoseCandidates' per-candidate and per-constraint arrays: (field, array typecode, dtype)
_CANDIDATE_FIELDS = {'indices': ('candidate_indices', 'I', np.uint32),
                     'poses': ('candidate_poses', 'd', np.float64),
                     'distances': ('candidate_distances', 'd', np.float64),
                     'weights': ('candidate_weights', 'd', np.float64)}
_CONSTRAINT_FIELDS = {'patch_ids': ('constraint_patch_ids', 'H', np.uint16),
                      'colors': ('constraint_colors', 'B', np.uint8),
                      'vertices': ('constraint_vertices', 'I', np.uint32),
                      'tiny_xy': ('constraint_tiny_xy', 'f', np.float32),
                      'pixel_counts': ('constraint_pixel_counts', 'I', np.uint32)}


def candidates_to_msg(observation: HandObservation, result: LookupResult | None,
                   status: str = '', lookup_time_ms: float = 0.0) -> HandPoseCandidates:
    """The lookup node's output: neighbours, blend and the nearest entry's constraints, with
    the observation it came from. ``result`` None means no hand (``status`` says why)."""
    msg = HandPoseCandidates(header=observation.header, observation=observation,
                             dof_names=list(DOF_NAMES), lookup_time_ms=float(lookup_time_ms))
    if result is None:
        msg.hand_found = False
        msg.status = status or observation.status or 'no hand'
        return msg
    msg.hand_found = True
    for name, (field, typecode, dtype) in _CANDIDATE_FIELDS.items():
        setattr(msg, field, _packed(typecode, getattr(result, name), dtype))
    msg.blended_pose = _packed('d', result.blended, np.float64)
    if result.finger_std is not None:
        msg.finger_std = _packed('d', result.finger_std, np.float64)
    c = result.constraints
    for name, (field, typecode, dtype) in _CONSTRAINT_FIELDS.items():
        values = getattr(c, name)
        if name == 'pixel_counts':
            values = np.rint(values)
        setattr(msg, field, _packed(typecode, values, dtype))
    return msg


def candidate_arrays_from_msg(msg: HandPoseCandidates) -> dict[str, np.ndarray]:
    """The candidates of a candidates message as numpy arrays (views of the message's
    arrays): ``indices`` (K,), ``poses`` (K, 26) (as many rows as whole poses the array
    holds), ``distances`` (K,), ``weights`` (K,)."""
    out = {name: np.frombuffer(getattr(msg, field), dtype)
           for name, (field, _, dtype) in _CANDIDATE_FIELDS.items()}
    poses = out['poses']
    out['poses'] = poses[:len(poses) - len(poses) % len(DOF_NAMES)].reshape(-1, len(DOF_NAMES))
    return out


def constraint_arrays_from_msg(msg: HandPoseCandidates) -> dict[str, np.ndarray]:
    """The projection constraints of a candidates message as numpy arrays (views of the
    message's arrays), keyed as :class:`ProjectionConstraints`' fields; ``tiny_xy`` (C, 2)
    holds as many rows as whole pairs the array holds."""
    out = {name: np.frombuffer(getattr(msg, field), dtype)
           for name, (field, _, dtype) in _CONSTRAINT_FIELDS.items()}
    xy = out['tiny_xy']
    out['tiny_xy'] = xy[:len(xy) - len(xy) % 2].reshape(-1, 2)
    return out


def pose_prior_from_candidates_msg(msg: HandPoseCandidates) -> PosePrior:
    """The IK's starting point from a candidates message (blended pose + constraints, and the
    nearest candidate's image distance: NaN, i.e. not a close match, when unknown)."""
    if list(msg.dof_names) != list(DOF_NAMES):
        raise ValueError(f'candidates carry DOFs {list(msg.dof_names)[:3]}..., '
                         f'expected {list(DOF_NAMES)[:3]}...')
    blended = np.frombuffer(msg.blended_pose, np.float64)
    if len(blended) != len(DOF_NAMES) or not np.all(np.isfinite(blended)):
        raise ValueError('blended_pose must hold 26 finite values')
    c = constraint_arrays_from_msg(msg)
    if len(c['tiny_xy']) != len(c['patch_ids']) or not np.isfinite(c['tiny_xy']).all():
        raise ValueError('constraint centroids must be finite, one (x, y) per constraint')
    finger_std = None
    if len(msg.finger_std):
        finger_std = np.array(msg.finger_std, dtype=float)
        if finger_std.shape != (len(DOF_NAMES) - 6,) or not np.all(np.isfinite(finger_std)) \
                or np.any(finger_std < 0):
            raise ValueError('finger_std must be empty or hold 20 finite values >= 0')
    distances = msg.candidate_distances
    nearest = float(distances[0]) if len(distances) else math.nan
    return PosePrior(
        finger_std=finger_std,
        image_distance=nearest if math.isfinite(nearest) and nearest >= 0 else math.nan,
        q_blend=blended.copy(), constraints=ProjectionConstraints(**c))


def skeleton_to_markers_msg(keypoints_camera: np.ndarray | None, header: Header,
                            namespace: str = 'hand') -> MarkerArray:
    """The hand skeleton as a LINE_LIST (bones) and a SPHERE_LIST (joints) in the camera frame;
    ``None`` (no hand) clears the markers."""
    if keypoints_camera is None:
        return MarkerArray(markers=[Marker(header=header, ns=namespace, action=Marker.DELETEALL)])
    points = [Point(x=float(x), y=float(y), z=float(z)) for x, y, z in keypoints_camera]
    bones = Marker(header=header, ns=namespace, id=0, type=Marker.LINE_LIST, action=Marker.ADD)
    bones.scale.x = 0.004
    bones.color = ColorRGBA(r=1.0, g=0.8, b=0.1, a=1.0)
    bones.points = [points[i] for bone in SKELETON_BONES for i in bone]
    bones.pose.orientation.w = 1.0
    joints = Marker(header=header, ns=namespace, id=1, type=Marker.SPHERE_LIST,
                    action=Marker.ADD, points=points)
    joints.scale.x = joints.scale.y = joints.scale.z = 0.008
    joints.color = ColorRGBA(r=1.0, g=1.0, b=1.0, a=1.0)
    joints.pose.orientation.w = 1.0
    return MarkerArray(markers=[bones, joints])


def observation_to_msg(observation: Observation, header: Header) -> HandObservation:
    """The segmentation result as a ``HandObservation`` (stamp and frame from the camera)."""
    msg = HandObservation(header=header, hand_found=bool(observation.hand_found),
                          image_width=int(observation.image_width),
                          image_height=int(observation.image_height),
                          glove_pixel_count=int(observation.glove_pixel_count),
                          cut_by_border=bool(observation.cut_by_border),
                          processing_time_ms=float(observation.timings_ms.get('total', 0.0)))
    msg.status = '' if observation.hand_found else observation.status
    if observation.crop is not None:
        msg.crop_scale = float(observation.crop.scale)
        msg.crop_offset_x = float(observation.crop.offset_x)
        msg.crop_offset_y = float(observation.crop.offset_y)
    if observation.hand_found and observation.tiny_labels is not None:
        # uint8[] takes an array.array('B') as it is: no list of Python ints
        msg.tiny_labels = array('B', np.ascontiguousarray(observation.tiny_labels,
                                                          np.uint8).tobytes())
    blobs = sorted(observation.blobs, key=lambda b: -b.pixel_count)
    # the numeric arrays take an array.array of their own type as it is (no per-element check)
    msg.blob_colors = array('B', [int(b.color_label) for b in blobs])
    msg.blob_centroids = array('d', [value for b in blobs
                                     for value in (float(b.centroid_x), float(b.centroid_y))])
    msg.blob_pixel_counts = array('I', [int(b.pixel_count) for b in blobs])
    return msg


def wrist_pose_to_tf_msg(pose: PoseStamped, child_frame_id: str):
    """A ``tf2_msgs/TFMessage`` carrying ``pose`` as the transform header.frame_id -> child
    (tf2_msgs is imported here because it exists only on native ROS 2 installs)."""
    from geometry_msgs.msg import Transform, TransformStamped, Vector3
    from tf2_msgs.msg import TFMessage

    p = pose.pose.position
    transform = Transform(translation=Vector3(x=p.x, y=p.y, z=p.z),
                          rotation=pose.pose.orientation)
    return TFMessage(transforms=[TransformStamped(header=pose.header,
                                                  child_frame_id=child_frame_id,
                                                  transform=transform)])


def gesture_event_to_msg(event: GestureEvent, header: Header, hand: str) -> GestureEventMsg:
    """A core gesture event as ``colorglove_msgs/GestureEvent`` (the header is the caller's:
    the deciding frame's stamp and the hand frame)."""
    return GestureEventMsg(header=header, hand=hand, gesture=event.name,
                           event=_EVENT_CODES[event.state],
                           confidence=float(event.confidence))


def gesture_event_from_msg(msg: GestureEventMsg) -> GestureEvent:
    """The core event of a ``GestureEvent`` message (stamp from its header); raises
    ``GestureError`` for an unknown event code."""
    states = {code: state for state, code in _EVENT_CODES.items()}
    if msg.event not in states:
        raise GestureError(f'unknown gesture event code {msg.event}')
    return GestureEvent(str(msg.gesture), states[msg.event], float(msg.confidence),
                        stamp_to_seconds(msg.header.stamp))


def crop_prediction_to_msg(prediction: CropPrediction, header: Header) -> PolygonStamped:
    """A crop prediction as ``PolygonStamped``: the predicted crop window's four corners
    (x, y in image pixels, pixel centres, z 0; top-left, top-right, bottom-right,
    bottom-left) in ``header``, the tracked frame's (its stamp is the prediction's)."""
    (cx, cy), h = prediction.center_xy, prediction.half_size
    corners = ((cx - h, cy - h), (cx + h, cy - h), (cx + h, cy + h), (cx - h, cy + h))
    msg = PolygonStamped(header=header)
    msg.polygon.points = [Point32(x=float(x), y=float(y), z=0.0) for x, y in corners]
    return msg


def crop_prediction_from_msg(msg: PolygonStamped, image_size: tuple[int, int]
                             ) -> CropPrediction:
    """The crop prediction of :func:`crop_prediction_to_msg`'s message for images of
    ``image_size`` (width, height; the message does not carry it): the centre and half side
    of the corners' bounding square. Raises ``ValueError`` on a message without corners or
    with non-finite ones."""
    xy = np.array([[p.x, p.y] for p in msg.polygon.points], dtype=float).reshape(-1, 2)
    if not len(xy) or not np.all(np.isfinite(xy)):
        raise ValueError(f'a crop prediction needs finite corners, got {len(xy)} point(s)')
    low, high = xy.min(axis=0), xy.max(axis=0)
    centre = 0.5 * (low + high)
    return CropPrediction(stamp_to_seconds(msg.header.stamp), (float(centre[0]),
                          float(centre[1])), 0.5 * float(max(high - low)),
                          (int(image_size[0]), int(image_size[1])))
