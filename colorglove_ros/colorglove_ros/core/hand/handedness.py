"""Left hand by mirroring: a left hand wearing the mirror-image glove looks exactly like a right
hand in the mirrored pose, seen in a mirror.

Mirror ``M = diag(-1, 1, 1)`` flips the camera frame's x axis (image columns about the
principal point ``cx``: ``u -> 2 cx - u``). The left hand model is the right one mirrored in
its own hand frame by ``S = diag(-1, 1, 1)``: same link lengths, joint names and joint-angle
meanings (positive flexion curls toward the palm, positive abduction moves a finger toward the
thumb), its hand frame right-handed with ``+x`` toward the little finger, ``+y`` toward the
forearm and ``+z`` out of the back of the hand. A left hand at pose ``q`` (wrist ``t``, ``R``)
has its points at ``t + R S p`` with ``p`` the right model's local points, so its mirror image
``M t + (M R S)(p)`` is a right hand at wrist ``M t``, rotation ``M R S``, same finger angles:
:func:`mirror_pose`. It is its own inverse, and the same map turns the pose tracked on a
mirrored query back into the left hand's pose.

The query of the lookup is mirrored with it (:func:`mirror_observation`): the 40x40 label image
flips left-right, the crop window's centre and the blob centroids mirror about ``cx``. This is
exact for a pinhole camera; with lens distortion it holds for the radial terms and the
tangential ``p1`` term, not for ``p2``.
"""
from __future__ import annotations

from dataclasses import replace
from typing import TYPE_CHECKING, Any

import numpy as np

from colorglove_ros.core.hand.model import NUM_DOFS, HandModel, HandModelError
from colorglove_ros.core.pipeline import Observer
from colorglove_ros.core.segmentation.crop import TINY_SIZE, CropTransform, TinyCrop
from colorglove_ros.core.segmentation.types import Blob, Observation
from colorglove_ros.core.tracking.types import Blobs, CameraObservation

if TYPE_CHECKING:
    from colorglove_ros.core.hand.mesh import HandMesh

__all__ = ['HANDS', 'DEFAULT_HAND', 'MIRROR', 'HandednessError', 'check_hand', 'mirror_pose',
           'mirror_points', 'mirror_pixels_x', 'mirror_tiny_labels', 'mirror_crop',
           'mirror_blobs', 'mirror_observation', 'mirror_camera_observation',
           'mirror_tiny_crop', 'mirrored_observer', 'to_right_frame', 'from_right_frame',
           'hand_keypoints', 'hand_vertices', 'hand_faces']

HANDS: tuple[str, ...] = ('right', 'left')
DEFAULT_HAND = 'right'
"""The hand the pose database and the tracker's model are (the left one is served mirrored)."""
MIRROR = np.diag([-1.0, 1.0, 1.0])


class HandednessError(HandModelError, ValueError):
    """A hand name that is neither 'right' nor 'left'."""


def check_hand(hand: str) -> str:
    """Return ``hand`` if it is one of :data:`HANDS`, else raise :class:`HandednessError`."""
    if hand not in HANDS:
        raise HandednessError(f'hand must be one of {HANDS}, got {hand!r}')
    return hand


def mirror_pose(q: np.ndarray) -> np.ndarray:
    """The mirrored pose (..., 26): a left hand's pose <-> the right-hand pose that looks like
    its mirror image (and back). ``t -> M t``, ``R -> M R S``, fingers unchanged; in rotation
    vectors ``(rx, ry, rz) -> (rx, -ry, -rz)``."""
    q = np.asarray(q, dtype=float)
    if q.shape[-1:] != (NUM_DOFS,):
        raise HandModelError(f'pose must have shape (..., 26), got {q.shape}')
    out = q.copy()
    out[..., 0] = -q[..., 0]
    out[..., 4:6] = -q[..., 4:6]
    return out


def mirror_points(points: np.ndarray) -> np.ndarray:
    """Camera-frame points (..., 3) mirrored by ``M`` (x negated)."""
    return np.asarray(points, dtype=float) * np.array([-1.0, 1.0, 1.0])


def mirror_pixels_x(x: np.ndarray | float, cx: float) -> np.ndarray:
    """Image columns mirrored about the principal point: ``2 cx - x``."""
    return 2.0 * cx - np.asarray(x, dtype=float)


def mirror_tiny_labels(tiny: np.ndarray) -> np.ndarray:
    """A tiny label image flipped left-right (colour labels unchanged: the left glove is the
    mirror image of the right one)."""
    tiny = np.asarray(tiny)
    if tiny.shape != (TINY_SIZE, TINY_SIZE):
        raise ValueError(f'tiny image must be {TINY_SIZE}x{TINY_SIZE}, got {tiny.shape}')
    return np.ascontiguousarray(tiny[:, ::-1])


def mirror_crop(crop: CropTransform, cx: float) -> CropTransform:
    """The crop of the mirrored image: same scale and rows, the window centre mirrored about
    ``cx``; tiny column ``i`` of the result is tiny column ``TINY_SIZE - 1 - i`` mirrored."""
    offset_x = 2.0 * cx - crop.offset_x - (TINY_SIZE - 1) * crop.scale
    return CropTransform(scale=crop.scale, offset_x=offset_x, offset_y=crop.offset_y)


def mirror_blobs(blobs: list[Blob], cx: float) -> list[Blob]:
    """Blobs with their centroids mirrored about ``cx``."""
    return [replace(b, centroid_x=float(mirror_pixels_x(b.centroid_x, cx))) for b in blobs]


def mirror_observation(observation: Observation, cx: float) -> Observation:
    """A segmenter observation as the mirrored image would give it (tiny image, crop, blobs
    and, when kept, the label image; the label image mirrors exactly only when ``cx`` is the
    image centre ``(width - 1) / 2``)."""
    out = replace(observation, blobs=mirror_blobs(observation.blobs, cx),
                  timings_ms=dict(observation.timings_ms))
    if observation.tiny_labels is not None:
        out.tiny_labels = mirror_tiny_labels(observation.tiny_labels)
    if observation.crop is not None:
        out.crop = mirror_crop(observation.crop, cx)
    if observation.label_image is not None:
        out.label_image = np.ascontiguousarray(observation.label_image[:, ::-1])
    return out


def mirror_camera_observation(observation: CameraObservation, cx: float) -> CameraObservation:
    """A tracker's camera observation as the mirrored image gives it (blob centroids and the
    crop window mirrored about ``cx``; colours, pixel counts and flags unchanged)."""
    blobs = observation.blobs
    if len(blobs):
        centroids = np.array(blobs.centroid_px, dtype=float, copy=True)
        centroids[:, 0] = mirror_pixels_x(centroids[:, 0], cx)
        blobs = Blobs(blobs.color, centroids, blobs.pixel_count)
    crop = None if observation.crop is None else mirror_crop(observation.crop, cx)
    return replace(observation, blobs=blobs, crop=crop)


def mirror_tiny_crop(tiny: TinyCrop, cx: float) -> TinyCrop:
    """A lookup query (tiny image and its crop) as the mirrored image gives it."""
    return TinyCrop(mirror_tiny_labels(tiny.labels), mirror_crop(tiny.transform, cx))


def mirrored_observer(observer: Observer, cx: float) -> Observer:
    """An observer (``core.pipeline.Observer``) whose observations and lookup query are those
    of the mirrored image: a left hand seen through it is a right hand at
    :func:`mirror_pose` of its pose (one camera: a second camera's extrinsics would have to
    be mirrored too)."""
    def observe(view: Any, primary: bool) -> tuple[CameraObservation, TinyCrop | None]:
        if not primary:
            raise HandednessError('a mirrored (left-hand) query is defined for one camera')
        seen, tiny = observer(view, primary)
        return (mirror_camera_observation(seen, cx),
                None if tiny is None else mirror_tiny_crop(tiny, cx))
    return observe


def to_right_frame(q: np.ndarray, hand: str) -> np.ndarray:
    """The right-hand pose a ``hand`` pose is tracked as (the mirrored pose of a left hand,
    a right hand's pose as it is)."""
    return mirror_pose(q) if check_hand(hand) == 'left' else np.asarray(q, dtype=float)


from_right_frame = to_right_frame
"""The ``hand`` pose of a pose tracked as a right hand (the mirror is its own inverse)."""


def hand_keypoints(model: HandModel, q: np.ndarray, hand: str = DEFAULT_HAND) -> np.ndarray:
    """(..., 21, 3) camera-frame keypoints of a ``hand`` at pose(s) ``q`` (a left hand is the
    right model mirrored in its hand frame)."""
    q = np.asarray(q, dtype=float)
    keypoints = model.keypoints_batch if q.ndim == 2 else model.keypoints
    if check_hand(hand) == 'right':
        return keypoints(q)
    return mirror_points(keypoints(mirror_pose(q)))


def hand_vertices(mesh: HandMesh, model: HandModel, q: np.ndarray,
                  hand: str = DEFAULT_HAND) -> np.ndarray:
    """(V, 3) camera-frame vertices of the gloved ``hand`` mesh at pose ``q``."""
    if check_hand(hand) == 'right':
        return mesh.skin(model, q)
    return mirror_points(mesh.skin(model, mirror_pose(q)))


def hand_faces(faces: np.ndarray, hand: str = DEFAULT_HAND) -> np.ndarray:
    """The triangles of a ``hand`` mesh: a mirrored (left) mesh reverses their winding so
    they keep facing outward."""
    faces = np.asarray(faces)
    return faces if check_hand(hand) == 'right' else np.ascontiguousarray(faces[:, ::-1])
