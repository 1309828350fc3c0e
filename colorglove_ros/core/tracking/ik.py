"""Gauss-Newton IK on patch projection constraints, with temporal smoothing and N cameras."""
from __future__ import annotations

import math
import time
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from functools import cached_property
from pathlib import Path
from typing import Any, Protocol

import cv2
import numpy as np
import yaml
from scipy.optimize import linear_sum_assignment

from colorglove_ros.core.camera import Calibration, PinholeCamera
from colorglove_ros.core.errors import ColorGloveError
from colorglove_ros.core.hand.glove import default_hand
from colorglove_ros.core.hand.mesh import build_hand_mesh
from colorglove_ros.core.hand.model import DOF_NAMES, NUM_DOFS, HandModel
from colorglove_ros.core.yaml_io import load_yaml_mapping

__all__ = [
    'IK_CONFIG_VERSION', 'COVARIANCE_FORMAT', 'COVARIANCE_VERSION',
    'IKError', 'IKConfigError', 'FastKinematics', 'EntryConstraints', 'Blobs',
    'CameraObservation', 'PosePrior', 'Correspondences', 'IKCovariances', 'IKConfig',
    'IKSolution', 'IKResult', 'MeshLike', 'VertexTable', 'PatchSurface', 'TRACKER_MODES',
    'CONSTRAINT_MODELS',
    'default_covariances', 'load_covariances', 'save_covariances', 'load_ik_config',
    'extract_blobs', 'match_by_color', 'match_primary', 'match_extra_camera',
    'constraint_points', 'project_correspondences', 'estimate_translation', 'solve_ik',
    'reprojection_errors', 'HandTracker', 'align_rotation_vector',
]

IK_CONFIG_VERSION = 1
COVARIANCE_FORMAT = 'colorglove_ik_covariances'
COVARIANCE_VERSION = 1
TRACKER_MODES = ('blend', 'ik', 'ik_smooth')
CONSTRAINT_MODELS = ('vertex', 'patch')
_EPS_LIMIT = 1e-9


class IKError(ColorGloveError):
    """Invalid input to the inverse kinematics (shapes, cameras, model mismatch)."""


class IKConfigError(IKError):
    """An IK configuration or covariance file is missing, malformed or of another version."""


def _skew(v: np.ndarray) -> np.ndarray:
    K = np.zeros(v.shape[:-1] + (3, 3))
    K[..., 0, 1], K[..., 0, 2] = -v[..., 2], v[..., 1]
    K[..., 1, 0], K[..., 1, 2] = v[..., 2], -v[..., 0]
    K[..., 2, 0], K[..., 2, 1] = -v[..., 1], v[..., 0]
    return K


def _field(obj: Any, *names: str) -> Any:
    for name in names:
        if hasattr(obj, name):
            return getattr(obj, name)
    raise IKError(f'hand-model joint has none of the fields {names}')


def _rotvec_matrix_and_jl(r: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Rotation matrix and SO(3) left Jacobian of one rotation vector (scalar fast path)."""
    theta = math.sqrt(float(r @ r))
    K = np.array([[0.0, -r[2], r[1]], [r[2], 0.0, -r[0]], [-r[1], r[0], 0.0]])
    KK = K @ K
    if theta < 1e-5:
        a, b = 1.0 - theta**2 / 6.0, 0.5 - theta**2 / 24.0
        c = 1.0 / 6.0 - theta**2 / 120.0
    else:
        st, ct = math.sin(theta), math.cos(theta)
        a, b = st / theta, (1.0 - ct) / theta**2
        c = (theta - st) / theta**3
    eye = np.eye(3)
    return eye + a * K + b * KK, eye + b * K + c * KK


class FastKinematics:
    """Forward kinematics and analytic point Jacobians of a :class:`HandModel` in one pass.

    Same numbers as ``model.transform_points`` / ``model.point_jacobian`` (checked at
    construction), with the joints processed level by level so one IK iteration costs a
    few dozen numpy calls instead of several hundred.
    """

    def __init__(self, model: HandModel) -> None:
        joints = model.joints
        self.model = model
        self.lower = np.asarray(model.lower_limits, dtype=float)
        self.upper = np.asarray(model.upper_limits, dtype=float)
        n = len(joints)
        self._parent = np.array([j.parent_frame for j in joints], dtype=np.int64)
        if np.any(self._parent > np.arange(n)):
            raise IKError('joint parents must precede their children')
        self._fixed_R = np.stack([np.asarray(_field(j, 'fixed_rot', 'fixed_R'), float)
                                  for j in joints])
        self._fixed_t = np.stack([np.asarray(_field(j, 'fixed_trans', 'fixed_t'), float)
                                  for j in joints])
        axes = np.stack([np.asarray(j.axis, float) for j in joints])
        self._axis = axes / np.linalg.norm(axes, axis=1, keepdims=True)
        self._K = _skew(self._axis)
        self._KK = self._K @ self._K
        self._dof = np.array([j.dof for j in joints], dtype=np.int64)
        if len(set(self._dof.tolist())) != n:
            raise IKError('each joint must drive its own DOF')
        contiguous = np.array_equal(self._dof, np.arange(self._dof[0], self._dof[0] + n))
        self._joint_dofs: slice | np.ndarray = (slice(int(self._dof[0]), int(self._dof[0]) + n)
                                                if contiguous else self._dof)
        depth = np.zeros(n + 1, dtype=np.int64)
        ancestors = np.zeros((n + 1, n), dtype=float)
        for f, j in enumerate(joints, start=1):
            depth[f] = depth[j.parent_frame] + 1
            ancestors[f] = ancestors[j.parent_frame]
            ancestors[f, f - 1] = 1.0
        self._levels = [np.flatnonzero(depth == d) for d in range(1, int(depth.max()) + 1)]
        self._ancestors = ancestors
        # joints in level order, each level's joint transforms a slice of the stacked
        # homogeneous link transforms (fixed translation, rotation filled per pose)
        self._level_order = np.concatenate(self._levels) - 1
        bounds = np.cumsum([0, *(len(lvl) for lvl in self._levels)])
        self._level_data = [(lvl, self._parent[lvl - 1], slice(int(a), int(b)))
                            for lvl, a, b in zip(self._levels, bounds[:-1], bounds[1:],
                                                 strict=True)]
        self._local_T = np.zeros((n, 4, 4))
        self._local_T[:, :3, 3] = self._fixed_t[self._level_order]
        self._local_T[:, 3, 3] = 1.0
        self._eye = np.eye(3)
        self._basis_skew = _skew(self._eye)
        self._cache: dict[bytes, tuple[np.ndarray, np.ndarray, np.ndarray]] = {}
        rng = np.random.default_rng(0)
        lo = np.where(np.isfinite(self.lower), self.lower, -1.0)
        hi = np.where(np.isfinite(self.upper), self.upper, 1.0)
        q = lo + (hi - lo) * rng.uniform(0.2, 0.8, NUM_DOFS)
        Rs, ts, _ = self.frames(q)
        T = model.link_transforms(q)
        link_frame = []
        for li in range(len(T)):
            err = (np.abs(Rs - T[li, :3, :3]).sum(axis=(1, 2))
                   + np.abs(ts - T[li, :3, 3]).sum(axis=1))
            f = int(np.argmin(err))
            if err[f] > 1e-9:
                raise IKError(f'link {li} matches no kinematic frame (error {err[f]:.3g})')
            link_frame.append(f)
        self.link_frame = np.array(link_frame, dtype=np.int64)

    def frames(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Rotations (F, 3, 3) and origins (F, 3) of all kinematic frames (0 = palm), and the
        SO(3) left Jacobian of the wrist rotation vector (read-only arrays). The frames
        relative to the wrist position of the last few poses are remembered, as a frame's
        matching, translation fit, IK and error checks revisit the same rotation and fingers."""
        q = np.asarray(q, dtype=float)
        Rs, ts_wrist, jl = self._wrist_frames(q)
        ts = ts_wrist + q[0:3]
        ts.setflags(write=False)
        return Rs, ts, jl

    def _wrist_frames(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """:meth:`frames` with the wrist at the origin (cached by ``q[3:]``)."""
        key = q[3:].tobytes()
        hit = self._cache.get(key)
        if hit is not None:
            return hit
        n = len(self._dof)
        T = np.zeros((n + 1, 4, 4))
        T[0, :3, :3], jl = _rotvec_matrix_and_jl(q[3:6])
        T[0, 3, 3] = 1.0
        ang = q[self._dof]
        Rj = self._eye + np.sin(ang)[:, None, None] * self._K
        Rj += (1.0 - np.cos(ang))[:, None, None] * self._KK
        local_T = self._local_T.copy()
        local_T[:, :3, :3] = (self._fixed_R @ Rj)[self._level_order]
        # one homogeneous product per level: a frame's rotation and origin together
        for lvl, p, rows in self._level_data:
            T[lvl] = T[p] @ local_T[rows]
        Rs = np.ascontiguousarray(T[:, :3, :3])
        ts = np.ascontiguousarray(T[:, :3, 3])
        for a in (Rs, ts, jl):
            a.setflags(write=False)
        if len(self._cache) >= 8:
            del self._cache[next(iter(self._cache))]
        self._cache[key] = (Rs, ts, jl)
        return Rs, ts, jl

    def points(self, q: np.ndarray, link: np.ndarray, local: np.ndarray,
               jacobian: bool = False) -> tuple[np.ndarray, np.ndarray | None]:
        """Camera-frame points (N, 3) of link-fixed points and optionally d/dq (N, 3, 26)."""
        Rs, ts, jl = self.frames(q)
        fr = self.link_frame[link]
        p = (Rs[fr] @ local[:, :, None])[:, :, 0] + ts[fr]
        if not jacobian:
            return p, None
        J = np.empty((len(p), 3, NUM_DOFS))
        J[:, :, 0:3] = self._eye
        # -[p - o]_x jl, with [d]_x = sum_k d_k [e_k]_x: one (N, 3) @ (3, 9) product
        d = p - ts[0]                                                      # wrist-relative
        J[:, :, 3:6] = (-d @ (self._basis_skew @ jl).reshape(3, 9)).reshape(-1, 3, 3)
        # revolute joint j: w_j x (p - o_j) = [w_j]_x d - w_j x (o_j - o_0), zero unless
        # joint j moves p; all joints in one (N, 3) @ (3, 3 nj) product
        w_skew = _skew((Rs[1:] @ self._axis[:, :, None])[:, :, 0])          # (nj, 3, 3)
        nj = len(w_skew)
        offset = (w_skew @ (ts[1:] - ts[0])[:, :, None])[:, :, 0].T        # (3, nj)
        cross = (d @ w_skew.transpose(2, 1, 0).reshape(3, 3 * nj)).reshape(-1, 3, nj)
        cross -= offset
        cross *= self._ancestors[fr][:, None, :]
        J[:, :, self._joint_dofs] = cross
        return p, J

    def clamp(self, q: np.ndarray) -> np.ndarray:
        """Clip a pose into the joint limits."""
        return np.clip(q, self.lower, self.upper)


# ---------------------------------------------------------------------------- data types
def _arr(x: Any, dtype: Any, shape_tail: tuple[int, ...], name: str) -> np.ndarray:
    a = np.asarray(x, dtype=dtype)
    if a.ndim == 1 and shape_tail == () or a.ndim == 2 and a.shape[1:] == shape_tail:
        return a
    if a.size == 0:
        return a.reshape((0, *shape_tail))
    raise IKError(f'{name} must have shape (N, {", ".join(map(str, shape_tail))}), got {a.shape}')


@dataclass(frozen=True)
class EntryConstraints:
    """Projection constraints of one database entry: per visible patch its id, colour
    (1..10), the mesh vertex nearest its centroid, the centroid in the entry's 40x40 tiny
    image (x, y) and its pixel count."""

    patch_id: np.ndarray
    color: np.ndarray
    vertex: np.ndarray
    tiny_xy: np.ndarray
    pixel_count: np.ndarray

    def __post_init__(self) -> None:
        object.__setattr__(self, 'patch_id', _arr(self.patch_id, np.int64, (), 'patch_id'))
        object.__setattr__(self, 'color', _arr(self.color, np.int64, (), 'color'))
        object.__setattr__(self, 'vertex', _arr(self.vertex, np.int64, (), 'vertex'))
        object.__setattr__(self, 'tiny_xy', _arr(self.tiny_xy, float, (2,), 'tiny_xy'))
        object.__setattr__(self, 'pixel_count',
                           _arr(self.pixel_count, float, (), 'pixel_count'))
        n = len(self.patch_id)
        if not all(len(a) == n for a in (self.color, self.vertex, self.tiny_xy,
                                          self.pixel_count)):
            raise IKError('EntryConstraints arrays must all have the same length')

    def __len__(self) -> int:
        return len(self.patch_id)


@dataclass(frozen=True)
class Blobs:
    """Measured glove blobs of one camera image: colour (1..10), centroid in full-image
    pixels (x, y, as measured, i.e. still distorted) and pixel count."""

    color: np.ndarray
    centroid_px: np.ndarray
    pixel_count: np.ndarray

    def __post_init__(self) -> None:
        object.__setattr__(self, 'color', _arr(self.color, np.int64, (), 'color'))
        object.__setattr__(self, 'centroid_px', _arr(self.centroid_px, float, (2,), 'centroid'))
        object.__setattr__(self, 'pixel_count',
                           _arr(self.pixel_count, float, (), 'pixel_count'))
        if not len(self.color) == len(self.centroid_px) == len(self.pixel_count):
            raise IKError('Blobs arrays must all have the same length')

    def __len__(self) -> int:
        return len(self.color)

    @classmethod
    def empty(cls) -> Blobs:
        """No blob."""
        return cls(np.zeros(0, np.int64), np.zeros((0, 2)), np.zeros(0))


@dataclass(frozen=True)
class CameraObservation:
    """What one camera saw in a frame: whether the glove was found, its blobs, and (for
    the primary camera) the crop transform tiny -> full image of the lookup query."""

    hand_found: bool
    blobs: Blobs = field(default_factory=Blobs.empty)
    crop: Any = None    # core.crop.CropTransform (scale, offset_x, offset_y)


@dataclass(frozen=True)
class PosePrior:
    """The lookup result the IK starts from: blended pose and the nearest entry's
    projection constraints."""

    q_blend: np.ndarray
    constraints: EntryConstraints
    finger_std: np.ndarray | None = None    # (20,) spread of the neighbours' fingers (rad)

    @classmethod
    def from_lookup(cls, result: Any) -> PosePrior:
        """From a ``core.search.LookupResult`` (``blended`` and ``constraints`` with
        ``patch_ids, colors, vertices, tiny_xy, pixel_counts``; ``finger_std`` if any)."""
        try:
            c = result.constraints
            cons = EntryConstraints(c.patch_ids, c.colors, c.vertices, c.tiny_xy,
                                    c.pixel_counts)
            q_blend = np.asarray(result.blended, dtype=float)
        except AttributeError as exc:
            raise IKError(f'not a lookup result: {exc}') from exc
        if q_blend.shape != (NUM_DOFS,):
            raise IKError(f'blended pose must have shape (26,), got {q_blend.shape}')
        spread = getattr(result, 'finger_std', None)
        return cls(q_blend, cons, None if spread is None else np.asarray(spread, float))


@dataclass(frozen=True)
class Correspondences:
    """Matched constraints over all cameras: camera index, the constrained point, the
    undistorted target pixel, patch id and the database's constraint vertex.

    The constrained point of row k is the weighted mean of S link-fixed points
    (``link[k, s]``, ``local[k, s]`` in that link's frame, ``weight[k, s]`` summing to 1):
    one vertex (S = 1), or the visible part of a glove patch spread over several links
    (:class:`PatchSurface`). 1-D ``link`` and (K, 3) ``local`` mean S = 1."""

    camera: np.ndarray
    link: np.ndarray
    local: np.ndarray
    target_px: np.ndarray
    patch_id: np.ndarray
    vertex: np.ndarray
    weight: np.ndarray | None = None

    def __post_init__(self) -> None:
        link = np.asarray(self.link, np.int64)
        local = np.asarray(self.local, float)
        if link.ndim == 1:
            link, local = link[:, None], local.reshape(-1, 1, 3)
        weight = (np.ones(link.shape) if self.weight is None
                  else np.asarray(self.weight, float))
        if local.shape != (*link.shape, 3) or weight.shape != link.shape \
                or len(link) != len(self.camera):
            raise IKError(f'correspondence points: link {link.shape}, local {local.shape}, '
                          f'weight {weight.shape} for {len(self.camera)} rows')
        object.__setattr__(self, 'link', link)
        object.__setattr__(self, 'local', local)
        object.__setattr__(self, 'weight', weight)

    def __len__(self) -> int:
        return len(self.camera)

    @classmethod
    def empty(cls) -> Correspondences:
        """No correspondence."""
        z = np.zeros(0, np.int64)
        return cls(z, z, np.zeros((0, 3)), np.zeros((0, 2)), z, z)

    @classmethod
    def concat(cls, items: Sequence[Correspondences]) -> Correspondences:
        """Join several sets (e.g. one per camera); point lists are padded with zero weights
        to the longest."""
        items = [c for c in items if len(c)]
        if not items:
            return cls.empty()
        s = max(c.link.shape[1] for c in items)
        k = sum(len(c) for c in items)
        link, local, weight = np.zeros((k, s), np.int64), np.zeros((k, s, 3)), np.zeros((k, s))
        row = 0
        for c in items:
            n, m = c.link.shape
            link[row:row + n, :m], local[row:row + n, :m] = c.link, c.local
            weight[row:row + n, :m] = c.weight
            row += n
        cat = {key: np.concatenate([getattr(c, key) for c in items])
               for key in ('camera', 'target_px', 'patch_id', 'vertex')}
        return cls(cat['camera'], link, local, cat['target_px'], cat['patch_id'], cat['vertex'],
                   weight)

    def select(self, mask: np.ndarray) -> Correspondences:
        """The subset picked by a boolean mask or index array."""
        return Correspondences(self.camera[mask], self.link[mask], self.local[mask],
                               self.target_px[mask], self.patch_id[mask], self.vertex[mask],
                               self.weight[mask])

    @cached_property
    def point_mix(self) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
        """The points of non-zero weight (links (M,), link-frame points (M, 3)) and the
        (K, M) matrix averaging them into the rows (None when every row is one point)."""
        if self.link.shape[1] == 1:
            return self.link[:, 0], self.local[:, 0], None
        rows, cols = np.nonzero(self.weight)
        mix = np.zeros((len(self), len(rows)))
        mix[rows, np.arange(len(rows))] = self.weight[rows, cols]
        return self.link[rows, cols], self.local[rows, cols], mix

    def same_as(self, other: Correspondences) -> bool:
        """True if both hold the same (camera, patch, target) triples in the same order."""
        return (len(self) == len(other) and np.array_equal(self.camera, other.camera)
                and np.array_equal(self.patch_id, other.patch_id)
                and np.array_equal(self.target_px, other.target_px))

    def counts(self, num_cameras: int) -> tuple[int, ...]:
        """Number of correspondences per camera."""
        return tuple(int(v) for v in np.bincount(self.camera, minlength=num_cameras))


class MeshLike(Protocol):
    """What the tracker needs from ``core.hand_mesh.HandMesh``."""

    vertex_link: np.ndarray
    local_vertices: np.ndarray


@dataclass(frozen=True)
class VertexTable:
    """Minimal :class:`MeshLike`: link index and link-frame position per vertex."""

    vertex_link: np.ndarray
    local_vertices: np.ndarray


class PatchSurface:
    """The glove's patches as link-fixed mesh faces, to predict the centroid of the part of
    each patch a camera sees: the projected-area-weighted mean of the patch's visible faces
    (weight = area x cosine toward the camera / depth^2), kept per link as one link-fixed
    point so the weights stay fixed while the pose is solved.

    A face is visible if it faces the camera and no front face projecting into the same
    cell of a coarse depth buffer (cells ``cell_m`` wide at the hand's depth) is more than
    ``depth_tol_m`` nearer. A patch whose visible faces carry less than
    ``min_visible_fraction`` of its front-facing weight (hidden, or the pose is off) uses
    all its front faces instead. Faces are merged into elements (same patch, link and facing,
    one ``element_m`` voxel); links with less than ``min_link_weight`` of a patch's visible
    weight are left out."""

    def __init__(self, kin: FastKinematics, mesh: MeshLike, face_patch: np.ndarray,
                 cell_m: float = 0.004, depth_tol_m: float = 0.004,
                 element_m: float = 0.006, min_link_weight: float = 0.1,
                 min_visible_fraction: float = 0.2) -> None:
        faces = np.asarray(getattr(mesh, 'faces', np.zeros((0, 3))), np.int64)
        face_patch = np.asarray(face_patch, np.int64)
        links = np.asarray(mesh.vertex_link, np.int64)
        if faces.ndim != 2 or faces.shape[1] != 3 or len(faces) == 0 \
                or len(face_patch) != len(faces):
            raise IKError(f'the patch model needs mesh faces (F, 3) and one patch per face; got '
                          f'{faces.shape} faces and {face_patch.shape} patch ids')
        face_link = links[faces[:, 0]]
        if np.any(links[faces[:, 1]] != face_link) or np.any(links[faces[:, 2]] != face_link):
            raise IKError('the patch model needs every mesh face on one link')
        v = np.asarray(mesh.local_vertices, float)[faces]                  # (F, 3, 3)
        centre = v.mean(axis=1)
        area_normal = 0.5 * np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0])
        area = np.linalg.norm(area_normal, axis=1)
        # surface elements: the faces of one patch and link in one element_m voxel, facing the
        # same way (dominant normal axis and sign); sorted by kinematic frame, so each
        # frame's block of elements moves with one transform
        dominant = np.argmax(np.abs(area_normal), axis=1)
        facing = 2 * dominant + (area_normal[np.arange(len(faces)), dominant] > 0)
        key = np.column_stack([kin.link_frame[face_link], face_patch, face_link, facing,
                               np.floor(centre / element_m).astype(np.int64)])
        keys, elem = np.unique(key, axis=0, return_inverse=True)
        elem = elem.reshape(-1)
        n = len(keys)
        elem_area = np.bincount(elem, area, n)
        self._centre = np.stack([np.bincount(elem, area * centre[:, i], n) for i in range(3)],
                                axis=1) / elem_area[:, None]
        self._area_normal = np.stack([np.bincount(elem, area_normal[:, i], n)
                                      for i in range(3)], axis=1)
        frame, elem_patch, elem_link = keys[:, 0], keys[:, 1], keys[:, 2]
        self._block_frame, start = np.unique(frame, return_index=True)
        self._blocks = [slice(int(a), int(b)) for a, b in
                        zip(start, [*start[1:], len(frame)], strict=True)]
        self._elem_patch = elem_patch
        self._kin = kin
        pairs, self._group = np.unique(np.stack([elem_patch, elem_link], axis=1), axis=0,
                                       return_inverse=True)
        self._group = self._group.reshape(-1)
        num_patches = int(elem_patch.max()) + 1
        slots = np.bincount(pairs[:, 0], minlength=num_patches)
        self.max_links = int(slots.max())
        self._table = np.full((num_patches, self.max_links), -1, np.int64)
        first = np.concatenate([[0], np.cumsum(slots)[:-1]])
        for g, (p, _) in enumerate(pairs):
            self._table[p, g - first[p]] = g
        self._group_link = pairs[:, 1]
        self.num_patches = num_patches
        self.cell_m = float(cell_m)
        self.depth_tol_m = float(depth_tol_m)
        self.min_visible_fraction = float(min_visible_fraction)
        self.min_link_weight = float(min_link_weight)
        self._posed_cache: tuple[bytes, tuple[np.ndarray, np.ndarray]] | None = None
        self._bins: dict[int, tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]] = {}
        self._eye = np.eye(3)

    def _visible(self, pc: np.ndarray, front: np.ndarray, camera: PinholeCamera) -> np.ndarray:
        """Front elements not hidden behind another front element (coarse depth buffer)."""
        idx = np.flatnonzero(front)
        if len(idx) == 0:
            return front
        z = pc[idx, 2]
        cell_px = self.cell_m / float(z.mean())
        u = np.floor(pc[idx, 0] / z / cell_px * camera.fx / camera.fy).astype(np.int64)
        v = np.floor(pc[idx, 1] / z / cell_px).astype(np.int64)
        u -= u.min()
        v -= v.min()
        cell = v * (int(u.max()) + 1) + u
        zbuf = np.full(int(cell.max()) + 1, np.inf)
        np.minimum.at(zbuf, cell, z)
        out = np.zeros(len(front), dtype=bool)
        out[idx] = z <= zbuf[cell] + self.depth_tol_m
        return out

    def _posed(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Element centres and area normals (E, 3) in the primary camera frame at pose ``q``
        (read-only; the last pose is remembered, as every camera of a frame asks for it)."""
        q = np.asarray(q, dtype=float)
        key = q.tobytes()
        if self._posed_cache is not None and self._posed_cache[0] == key:
            return self._posed_cache[1]
        Rs, ts, _ = self._kin.frames(q)
        R, t = Rs[self._block_frame], ts[self._block_frame]
        centre = np.empty_like(self._centre)
        normal = np.empty_like(self._centre)
        for b, sl in enumerate(self._blocks):
            Rt = np.ascontiguousarray(R[b].T)             # the fast matmul path
            np.dot(self._centre[sl], Rt, out=centre[sl])
            centre[sl] += t[b]
            np.dot(self._area_normal[sl], Rt, out=normal[sl])
        centre.setflags(write=False)
        normal.setflags(write=False)
        self._posed_cache = (key, (centre, normal))
        return centre, normal

    def points(self, q: np.ndarray, camera: PinholeCamera, patch_id: np.ndarray
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """For each patch id: links (K, S), link-frame points (K, S, 3) and weights (K, S)
        of its visible part seen by ``camera`` at pose ``q``, and whether any of it faces the
        camera (K,) (rows that do not keep weight 0)."""
        patch_id = np.asarray(patch_id, np.int64)
        return self.points_by_camera(q, [camera], np.zeros(len(patch_id), np.int64), patch_id)

    def _element_weights(self, pc: np.ndarray, normal: np.ndarray, camera: PinholeCamera
                         ) -> tuple[np.ndarray, np.ndarray]:
        """Projected-area weight (E,) of every element facing ``camera``, and the same with
        the elements hidden in the depth buffer set to 0."""
        if not (np.array_equal(camera.rotation, self._eye) and not camera.translation.any()):
            Rt = np.ascontiguousarray(camera.rotation.T)     # the fast matmul path
            pc = pc @ Rt + camera.translation
            normal = normal @ Rt
        dist = np.sqrt(np.einsum('fi,fi->f', pc, pc))
        depth = np.maximum(pc[:, 2], 1e-3)
        w = np.maximum(-np.einsum('fi,fi->f', normal, pc), 0.0) / (dist * depth**2)
        return w, np.where(self._visible(pc, (w > 0) & (pc[:, 2] > 0), camera), w, 0.0)

    def _camera_bins(self, num_cameras: int) -> tuple[np.ndarray, np.ndarray, np.ndarray,
                                                      np.ndarray]:
        """Per element of every camera: patch bin, group bin, group xyz bins and centre,
        the bins of camera c offset past those of cameras 0..c-1 (kept per camera count)."""
        hit = self._bins.get(num_cameras)
        if hit is None:
            nc, ne, ng = num_cameras, len(self._centre), len(self._group_link)
            cam = np.repeat(np.arange(nc), ne)
            group = cam * ng + np.tile(self._group, nc)
            hit = (cam * self.num_patches + np.tile(self._elem_patch, nc), group,
                   (3 * group[:, None] + np.arange(3)).reshape(-1),
                   np.tile(self._centre, (nc, 1)))
            self._bins[num_cameras] = hit
        return hit

    def points_by_camera(self, q: np.ndarray, cameras: Sequence[PinholeCamera],
                         camera_index: np.ndarray, patch_id: np.ndarray
                         ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """:meth:`points` for rows seen by different cameras (row k by
        ``cameras[camera_index[k]]``) in one pass over the posed glove."""
        patch_id = np.asarray(patch_id, np.int64)
        camera_index = np.asarray(camera_index, np.int64)
        if len(patch_id) and (patch_id.min() < 0 or patch_id.max() >= self.num_patches):
            raise IKError(f'patch id outside [0, {self.num_patches})')
        if len(camera_index) != len(patch_id) or (
                len(camera_index) and (camera_index.min() < 0
                                       or camera_index.max() >= len(cameras))):
            raise IKError(f'camera index outside [0, {len(cameras)}) or not one per patch id')
        pc, normal = self._posed(q)
        nc, ng, np_ = len(cameras), len(self._group_link), self.num_patches
        # per camera: all front weights and the visible ones, all cameras summed in one call
        weights = [self._element_weights(pc, normal, cam) for cam in cameras]
        w = np.concatenate([front for front, _ in weights])
        w_vis = np.concatenate([vis for _, vis in weights])
        elem_patch, group, group_xyz, centre = self._camera_bins(nc)
        # patches mostly hidden in the depth buffer fall back to all their front faces
        vis_frac = (np.bincount(elem_patch, w_vis, nc * np_)
                    / np.maximum(np.bincount(elem_patch, w, nc * np_), 1e-300))
        w = np.where(vis_frac[elem_patch] < self.min_visible_fraction, w, w_vis)
        wg = np.bincount(group, w, nc * ng)
        mean = (np.bincount(group_xyz, (w[:, None] * centre).reshape(-1), 3 * nc * ng)
                .reshape(nc * ng, 3) / np.maximum(wg, 1e-300)[:, None])
        groups = self._table[patch_id]                                       # (K, S)
        valid = groups >= 0
        g = np.where(valid, groups, 0)
        gc = g + (camera_index * ng)[:, None]
        weight = np.where(valid, wg[gc], 0.0)
        total = weight.sum(axis=1)
        seen = total > 0
        weight = weight / np.where(seen, total, 1.0)[:, None]
        # links holding a sliver of the visible patch are dropped (fewer points to move)
        weight[weight < self.min_link_weight] = 0.0
        weight /= np.where(seen, weight.sum(axis=1), 1.0)[:, None]
        return self._group_link[g], mean[gc], weight, seen


# ---------------------------------------------------------------------------- covariances
@dataclass(frozen=True)
class IKCovariances:
    """Diagonal covariances: R per pixel axis (px^2), Q (blended pose error) and P
    (frame-to-frame deviation) per DOF in m^2 / rad^2."""

    r_var_px2: np.ndarray
    q_var: np.ndarray
    p_var: np.ndarray
    source: str = 'defaults'

    def __post_init__(self) -> None:
        r = np.asarray(self.r_var_px2, float).reshape(-1)
        if r.size == 1:
            r = np.repeat(r, 2)
        q = np.asarray(self.q_var, float).reshape(-1)
        p = np.asarray(self.p_var, float).reshape(-1)
        if r.shape != (2,) or q.shape != (NUM_DOFS,) or p.shape != (NUM_DOFS,):
            raise IKConfigError(f'covariances need r (2), q (26), p (26); got {r.shape}, '
                                f'{q.shape}, {p.shape}')
        for name, v in (('r_var_px2', r), ('q_var', q), ('p_var', p)):
            if not np.all(np.isfinite(v)) or np.any(v <= 0):
                raise IKConfigError(f'{name} must be finite and positive, got {v.tolist()}')
        object.__setattr__(self, 'r_var_px2', r)
        object.__setattr__(self, 'q_var', q)
        object.__setattr__(self, 'p_var', p)


def _group_std(entry: Any, where: str) -> np.ndarray:
    """26 standard deviations from {translation_m: 3|1, rotation_rad: 3|1, fingers_rad: 20|1}."""
    if not isinstance(entry, dict):
        raise IKConfigError(f'{where} must be a mapping with translation_m, rotation_rad, '
                            'fingers_rad')
    out = []
    for key, n in (('translation_m', 3), ('rotation_rad', 3), ('fingers_rad', 20)):
        try:
            v = np.asarray(entry[key], dtype=float).reshape(-1)
        except (KeyError, TypeError, ValueError) as exc:
            raise IKConfigError(f'{where}.{key} missing or not numeric: {exc}') from exc
        if v.size == 1:
            v = np.repeat(v, n)
        if v.size != n:
            raise IKConfigError(f'{where}.{key} needs 1 or {n} values, got {v.size}')
        out.append(v)
    return np.concatenate(out)


def default_covariances() -> IKCovariances:
    """Hand-set covariances used when no learned file is given (same as config/ik.yaml)."""
    q_std = np.concatenate([[0.03, 0.03, 0.08], [0.2] * 3, [0.25] * 20])
    p_std = np.concatenate([[0.01, 0.01, 0.015], [0.06] * 3, [0.12] * 20])
    return IKCovariances(np.array([3.0**2, 3.0**2]), q_std**2, p_std**2)


def save_covariances(path: str | Path, cov: IKCovariances, **provenance: Any) -> Path:
    """Write learned covariances to a versioned YAML file."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    data = {
        'format': COVARIANCE_FORMAT, 'version': COVARIANCE_VERSION,
        'dof_names': list(DOF_NAMES),
        'r_var_px2': [float(v) for v in cov.r_var_px2],
        'q_var': [float(v) for v in cov.q_var],
        'p_var': [float(v) for v in cov.p_var],
        'provenance': {k: (v if isinstance(v, (int, float, str, bool)) else str(v))
                       for k, v in provenance.items()},
    }
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return path


def load_covariances(path: str | Path) -> IKCovariances:
    """Read a covariance file written by :func:`save_covariances`; raise
    :class:`IKConfigError` naming what is wrong."""
    path = Path(path)
    data = load_yaml_mapping(path, IKConfigError, 'IK covariance file')
    if data.get('format') != COVARIANCE_FORMAT:
        raise IKConfigError(f'{path} is not a {COVARIANCE_FORMAT} file')
    if data.get('version') != COVARIANCE_VERSION:
        raise IKConfigError(f'{path} has version {data.get("version")!r}, '
                            f'expected {COVARIANCE_VERSION}')
    if list(data.get('dof_names', [])) != list(DOF_NAMES):
        raise IKConfigError(f'{path}: dof_names do not match the 26-DOF hand model')
    try:
        return IKCovariances(data['r_var_px2'], data['q_var'], data['p_var'], source=str(path))
    except KeyError as exc:
        raise IKConfigError(f'{path}: missing field {exc}') from exc
    except (TypeError, ValueError) as exc:
        raise IKConfigError(f'{path}: bad values: {exc}') from exc


# ---------------------------------------------------------------------------- configuration
@dataclass(frozen=True)
class IKConfig:
    """Tracker options (see ``config/ik.yaml`` for the meaning of each)."""

    enable_ik: bool = True
    enable_smoothing: bool = True
    max_iterations: int = 3
    multi_camera_iterations: int = 2
    refine_iterations: int = 2
    lambda_init: float = 1e-3
    step_tol: float = 1e-5
    cost_tol: float = 1e-4
    init_translation: bool = True
    min_constraints: int = 3
    min_blob_pixels: int = 4
    gate_tiny_px: float = 8.0
    gate_min_px: float = 10.0
    extra_gate_px: float = 30.0
    extra_shift_max_px: float = 150.0
    extra_inlier_px: float = 15.0
    extra_rematch: bool = False
    outlier_px: float = 20.0
    max_gap_s: float = 0.25
    min_depth_m: float = 0.05
    constraint_model: str = 'patch'
    glove_seed: int = 0
    finger_spread_gain: float = 1.0
    finger_spread_floor_rad: float = 0.13
    covariances: IKCovariances = field(default_factory=default_covariances)

    def with_mode(self, mode: str) -> IKConfig:
        """The evaluation variants: 'blend' (blended NN only), 'ik', 'ik_smooth'."""
        if mode not in TRACKER_MODES:
            raise IKConfigError(f'unknown tracker mode {mode!r}, expected one of {TRACKER_MODES}')
        return replace(self, enable_ik=mode != 'blend', enable_smoothing=mode == 'ik_smooth')

    def __post_init__(self) -> None:
        if self.constraint_model not in CONSTRAINT_MODELS:
            raise IKConfigError(f'constraint_model must be one of {CONSTRAINT_MODELS}, got '
                                f'{self.constraint_model!r}')
        if not (0 <= self.finger_spread_gain < math.inf
                and 0 < self.finger_spread_floor_rad < math.inf):
            raise IKConfigError('finger_spread_gain must be finite and >= 0, '
                                'finger_spread_floor_rad finite and > 0')

    def prior_covariances(self, finger_std: np.ndarray | None) -> IKCovariances:
        """The covariances for one frame: with ``finger_spread_gain`` > 0 and the lookup's
        per-finger spread (20,), each finger DOF's Q variance is max(floor^2, gain *
        spread^2), so the prior holds a finger the neighbours agree on and lets the image
        move one they disagree on (this replaces the configured or learned finger Q);
        otherwise the configured Q."""
        if finger_std is None or self.finger_spread_gain <= 0:
            return self.covariances
        spread = np.asarray(finger_std, float).reshape(-1)
        if spread.shape != (NUM_DOFS - 6,) or not np.all(np.isfinite(spread)):
            raise IKError(f'finger spread must be 20 finite values, got shape {spread.shape}')
        q_var = self.covariances.q_var.copy()
        q_var[6:] = np.maximum(self.finger_spread_floor_rad ** 2,
                               self.finger_spread_gain * spread ** 2)
        return replace(self.covariances, q_var=q_var)


_CONFIG_FIELDS = {
    'enable_ik': bool, 'enable_smoothing': bool, 'max_iterations': int,
    'multi_camera_iterations': int, 'refine_iterations': int, 'lambda_init': float,
    'step_tol': float, 'cost_tol': float,
    'init_translation': bool, 'min_constraints': int, 'min_blob_pixels': int,
    'gate_tiny_px': float, 'gate_min_px': float, 'extra_gate_px': float,
    'extra_shift_max_px': float, 'extra_inlier_px': float, 'extra_rematch': bool,
    'outlier_px': float,
    'max_gap_s': float, 'min_depth_m': float, 'constraint_model': str, 'glove_seed': int,
    'finger_spread_gain': float, 'finger_spread_floor_rad': float,
}


def load_ik_config(path: str | Path) -> IKConfig:
    """Read ``config/ik.yaml``; a non-empty ``covariance_file`` (relative to the YAML's
    folder or absolute) overrides the default covariances written in the file."""
    path = Path(path)
    data = load_yaml_mapping(path, IKConfigError, 'IK config file')
    if data.get('version') != IK_CONFIG_VERSION:
        raise IKConfigError(f'IK config {path} has version {data.get("version")!r}, '
                            f'expected {IK_CONFIG_VERSION}')
    unknown = set(data) - set(_CONFIG_FIELDS) - {'version', 'covariances', 'covariance_file'}
    if unknown:
        raise IKConfigError(f'IK config {path}: unknown keys {sorted(unknown)}')
    kwargs: dict[str, Any] = {}
    for key, typ in _CONFIG_FIELDS.items():
        if key in data:
            value = data[key]
            if typ is bool and not isinstance(value, bool):
                raise IKConfigError(f'IK config {path}: {key} must be true or false')
            try:
                kwargs[key] = typ(value)
            except (TypeError, ValueError) as exc:
                raise IKConfigError(f'IK config {path}: {key}: {exc}') from exc
    cov_file = data.get('covariance_file') or ''
    if cov_file:
        cov_path = Path(cov_file)
        if not cov_path.is_absolute():
            cov_path = path.parent / cov_path
        kwargs['covariances'] = load_covariances(cov_path)
    elif 'covariances' in data:
        c = data['covariances']
        if not isinstance(c, dict):
            raise IKConfigError(f'IK config {path}: covariances must be a mapping')
        try:
            r_std = np.asarray(c['r_std_px'], dtype=float)
        except (KeyError, TypeError, ValueError) as exc:
            raise IKConfigError(f'IK config {path}: covariances.r_std_px: {exc}') from exc
        q_std = _group_std(c.get('q_std'), f'{path}: covariances.q_std')
        p_std = _group_std(c.get('p_std'), f'{path}: covariances.p_std')
        kwargs['covariances'] = IKCovariances(r_std**2, q_std**2, p_std**2, source=str(path))
    return IKConfig(**kwargs)


# ---------------------------------------------------------------------------- blobs, matching
def extract_blobs(labels: np.ndarray, min_pixels: int = 4, num_colors: int = 10) -> Blobs:
    """Connected components of each glove colour of a label image (0 = background)."""
    labels = np.asarray(labels)
    if labels.ndim != 2:
        raise IKError(f'label image must be 2-D, got shape {labels.shape}')
    colors, cents, counts = [], [], []
    for c in np.unique(labels):
        if c == 0 or c > num_colors:
            continue
        n, _, stats, centroids = cv2.connectedComponentsWithStats(
            (labels == c).astype(np.uint8), connectivity=8)
        for k in range(1, n):
            area = int(stats[k, cv2.CC_STAT_AREA])
            if area >= min_pixels:
                colors.append(int(c))
                cents.append(centroids[k])
                counts.append(area)
    if not colors:
        return Blobs.empty()
    return Blobs(np.array(colors), np.array(cents, float), np.array(counts, float))


def match_by_color(pred_xy: np.ndarray, pred_color: np.ndarray, blob_xy: np.ndarray,
                   blob_color: np.ndarray, gate_px: float) -> tuple[np.ndarray, np.ndarray]:
    """One-to-one matching of predicted points to blobs of the same colour (Hungarian on
    distance per colour); pairs farther than ``gate_px`` are dropped. Returns index arrays
    (into the predictions, into the blobs)."""
    pred_xy = np.asarray(pred_xy, float).reshape(-1, 2)
    blob_xy = np.asarray(blob_xy, float).reshape(-1, 2)
    empty = np.zeros(0, np.int64)
    if len(pred_xy) == 0 or len(blob_xy) == 0:
        return empty, empty
    d = np.linalg.norm(pred_xy[:, None, :] - blob_xy[None, :, :], axis=2)
    ok = (np.asarray(pred_color)[:, None] == np.asarray(blob_color)[None, :]) & (d <= gate_px)
    if not ok.any():
        return empty, empty
    # one assignment over all colours: forbidden pairs cost more than any allowed set
    big = (gate_px + 1.0) * (min(d.shape) + 1)
    r, c = linear_sum_assignment(np.where(ok, d, big))
    keep = ok[r, c]
    return r[keep].astype(np.int64), c[keep].astype(np.int64)


def _usable(blobs: Blobs, min_pixels: int) -> np.ndarray:
    return np.flatnonzero(blobs.pixel_count >= min_pixels)


def match_primary(constraints: EntryConstraints, blobs: Blobs, crop: Any,
                  camera: PinholeCamera, mesh: MeshLike, gate_tiny_px: float = 8.0,
                  gate_min_px: float = 10.0, min_blob_pixels: int = 4) -> Correspondences:
    """Match the entry's constraints (tiny-image centroids mapped to full-image pixels with
    the query's crop, ``full = offset + scale * tiny``) to same-colour blobs of the primary
    camera; targets are the undistorted blob centroids."""
    if crop is None:
        raise IKError('the primary observation needs the crop transform of the lookup query')
    if len(constraints) == 0 or len(blobs) == 0:
        return Correspondences.empty()
    scale = float(crop.scale)
    pred = constraints.tiny_xy * scale + np.array([float(crop.offset_x), float(crop.offset_y)])
    keep = _usable(blobs, min_blob_pixels)
    gate = max(gate_min_px, gate_tiny_px * scale)
    k, m = match_by_color(pred, constraints.color, blobs.centroid_px[keep],
                          blobs.color[keep], gate)
    m = keep[m]
    return _make_corr(0, constraints, k, camera.undistort_pixels(blobs.centroid_px[m]), mesh)


def _make_corr(cam: int, constraints: EntryConstraints, k: np.ndarray, target: np.ndarray,
               mesh: MeshLike) -> Correspondences:
    v = constraints.vertex[k]
    nv = len(mesh.vertex_link)
    if np.any((v < 0) | (v >= nv)):
        raise IKError(f'constraint vertex index out of range [0, {nv})')
    return Correspondences(np.full(len(k), cam, np.int64),
                           np.asarray(mesh.vertex_link, np.int64)[v],
                           np.asarray(mesh.local_vertices, float)[v],
                           np.asarray(target, float).reshape(-1, 2),
                           constraints.patch_id[k].copy(), v.copy())


def match_extra_camera(cam_index: int, camera: PinholeCamera, constraints: EntryConstraints,
                       predicted_world: np.ndarray, blobs: Blobs, mesh: MeshLike,
                       gate_px: float = 30.0, shift_max_px: float = 150.0,
                       inlier_px: float = 15.0, min_blob_pixels: int = 4,
                       min_depth_m: float = 0.05,
                       normals_world: np.ndarray | None = None) -> Correspondences:
    """Match constraints to same-colour blobs of a camera with no lookup: project the
    constraint vertices (``predicted_world``, (K, 3) in the primary frame, at the current
    pose), find the common image shift with most same-colour inliers (absorbs the weak
    depth of the pose), then Hungarian-match inside ``gate_px``. With ``normals_world``
    (K, 3), vertices whose surface faces away from this camera are skipped."""
    if len(constraints) == 0 or len(blobs) == 0:
        return Correspondences.empty()
    pc = camera.world_to_camera(predicted_world)
    front = pc[:, 2] > min_depth_m
    if normals_world is not None:
        center = -camera.rotation.T @ camera.translation
        front &= np.einsum('ni,ni->n', normals_world, center - predicted_world) > 0.0
    pred = np.full((len(pc), 2), np.nan)
    pred[front] = camera.project(pc[front])
    margin = gate_px
    inside = front & (pred[:, 0] > -margin) & (pred[:, 0] < camera.width + margin) \
        & (pred[:, 1] > -margin) & (pred[:, 1] < camera.height + margin)
    ks = np.flatnonzero(inside)
    keep = _usable(blobs, min_blob_pixels)
    if len(ks) == 0 or len(keep) == 0:
        return Correspondences.empty()
    bxy = camera.undistort_pixels(blobs.centroid_px[keep])
    bcol = blobs.color[keep]
    kcol = constraints.color[ks]
    # same-colour (constraint, blob) pairs, grouped by constraint (row-major order)
    pair_k, pair_m = np.nonzero(kcol[:, None] == bcol[None, :])
    diff = bxy[pair_m] - pred[ks[pair_k]]                  # (P, 2)
    shift = np.zeros(2)
    hyp = diff[np.linalg.norm(diff, axis=1) <= shift_max_px]
    if len(hyp):
        # per hypothesis, distance of every shifted prediction to its nearest same-colour
        # blob (constraints without one never count)
        pair_dist = np.linalg.norm(diff[None] - hyp[:, None, :], axis=2)     # (H, P)
        first = np.flatnonzero(np.diff(pair_k, prepend=-1))
        dist = np.minimum.reduceat(pair_dist, first, axis=1)                 # (H, K with pairs)
        inl = dist <= inlier_px
        score = inl.sum(axis=1) - 1e-3 * np.where(inl, dist, 0.0).sum(axis=1) / inlier_px
        best = int(np.argmax(score))
        if inl[best].sum() >= 2:
            # refine: mean residual of the inliers to their nearest same-colour blob
            nearest = np.lexsort((pair_dist[best], pair_k))[first]
            rows = np.flatnonzero(inl[best])
            shift = hyp[best] + (diff[nearest[rows]] - hyp[best]).mean(axis=0)
    k, m = match_by_color(pred[ks] + shift, kcol, bxy, bcol, gate_px)
    return _make_corr(cam_index, constraints, ks[k], bxy[m], mesh)


def align_rotation_vector(r: np.ndarray, ref: np.ndarray) -> np.ndarray:
    """The rotation vector equivalent to ``r`` (angle +- 2 pi along its axis) closest to
    ``ref``, so that differences such as ``q_b - q`` stay small across the pi wrap."""
    r = np.asarray(r, dtype=float)
    theta = float(np.linalg.norm(r))
    if theta < 1e-9:
        return r.copy()
    axis = r / theta
    cands = [axis * (theta + 2.0 * math.pi * k) for k in (-1, 0, 1)]
    return min(cands, key=lambda c: float(np.sum((c - ref) ** 2)))


# ---------------------------------------------------------------------------- projection / IK
@dataclass(frozen=True)
class _PerPoint:
    """Camera parameters repeated per correspondence, so all cameras project in one pass."""

    R: np.ndarray       # (K, 3, 3)
    t: np.ndarray       # (K, 3)
    f: np.ndarray       # (K, 2)
    c: np.ndarray       # (K, 2)


def _per_point(cameras: Sequence[PinholeCamera], corr: Correspondences) -> _PerPoint:
    if len(corr) and (corr.camera.min() < 0 or corr.camera.max() >= len(cameras)):
        raise IKError(f'correspondence camera index outside [0, {len(cameras)})')
    Rs = np.stack([c.rotation for c in cameras])
    ts = np.stack([c.translation for c in cameras])
    fs = np.array([[c.fx, c.fy] for c in cameras])
    cs = np.array([[c.cx, c.cy] for c in cameras])
    k = corr.camera
    return _PerPoint(Rs[k], ts[k], fs[k], cs[k])


def constraint_points(kin: FastKinematics, corr: Correspondences, q: np.ndarray,
                      jacobian: bool = False) -> tuple[np.ndarray, np.ndarray | None]:
    """Primary-frame constrained points (K, 3) at pose ``q`` (each the weighted mean of its
    link-fixed points) and optionally d/dq (K, 3, 26), the same weighted mean of the point
    Jacobians."""
    link, local, mix = corr.point_mix
    p, Jp = kin.points(q, link, local, jacobian)
    if mix is None:
        return p, Jp
    if Jp is not None:
        Jp = (mix @ Jp.reshape(len(p), -1)).reshape(len(mix), 3, NUM_DOFS)
    return mix @ p, Jp


def project_correspondences(kin: FastKinematics, cameras: Sequence[PinholeCamera],
                            corr: Correspondences, q: np.ndarray, jacobian: bool = False,
                            per_point: _PerPoint | None = None
                            ) -> tuple[np.ndarray, np.ndarray | None, np.ndarray]:
    """Predicted pixels f(q) (K, 2), optionally df/dq (2K, 26) (rows x0, y0, x1, ...) and
    the depth of every point in its camera (K,). Pinhole projection without distortion
    (targets are undistorted); each camera's rotation is chained into the Jacobian."""
    pp = per_point if per_point is not None else _per_point(cameras, corr)
    p, Jp = constraint_points(kin, corr, q, jacobian)
    return _project_points(pp, p, Jp if jacobian else None)


def _project_points(pp: _PerPoint, p: np.ndarray, Jp: np.ndarray | None
                    ) -> tuple[np.ndarray, np.ndarray | None, np.ndarray]:
    """Pixels, pixel Jacobian (if ``Jp``, the points' d/dq, is given) and depths of
    primary-frame points ``p``, each in its own camera."""
    pc = np.einsum('nij,nj->ni', pp.R, p) + pp.t
    depth = pc[:, 2].copy()
    z = np.where(np.abs(depth) < 1e-9, 1e-9, depth)
    xy = pc[:, :2] / z[:, None]
    pix = xy * pp.f + pp.c
    if Jp is None:
        return pix, None, depth
    # d pixel / d world point (K, 2, 3) = (f / z) (R[0:2] - xy R[2]), chained with Jp
    A = (pp.f / z[:, None])[:, :, None] * (pp.R[:, :2, :] - xy[:, :, None] * pp.R[:, 2:3, :])
    J = np.einsum('nik,nkd->nid', A, Jp)
    return pix, J.reshape(-1, NUM_DOFS), depth


def reprojection_errors(kin: FastKinematics, cameras: Sequence[PinholeCamera],
                        corr: Correspondences, q: np.ndarray) -> np.ndarray:
    """Euclidean pixel distance between each constraint's projection and its target."""
    if len(corr) == 0:
        return np.zeros(0)
    pix, _, _ = project_correspondences(kin, cameras, corr, q)
    return np.linalg.norm(pix - corr.target_px, axis=1)


def estimate_translation(kin: FastKinematics, cameras: Sequence[PinholeCamera],
                         corr: Correspondences, q: np.ndarray,
                         min_depth_m: float = 0.05, prior_var: np.ndarray | None = None,
                         r_var_px2: float = 9.0, outlier_px: float = 0.0) -> np.ndarray:
    """Keep rotation and fingers of ``q`` and solve the wrist translation that best
    projects the constraint points onto their targets: linear least squares on the
    cross-multiplied projection equations of all cameras, each row weighted as a pixel
    residual of variance ``r_var_px2``, optionally regularised toward ``q[0:3]`` with
    per-axis variances ``prior_var`` (m^2), and refitted once without the constraints
    farther than ``outlier_px`` (0 = no trimming). Returns the new pose; raises
    :class:`IKError` if the points are too few or the solution is behind a camera."""
    if len(corr) < 2:
        raise IKError('translation needs at least 2 correspondences')
    p, _ = constraint_points(kin, corr, q)
    pp = _per_point(cameras, corr)
    # per correspondence and pixel axis i: (R_i - a_i R_2) (p + dt) + t_i - a_i t_2 = 0 with
    # a the target's normalised image coordinates
    coef = (corr.target_px - pp.c) / pp.f                                  # (K, 2)
    G = pp.R[:, :2, :] - coef[:, :, None] * pp.R[:, 2:3, :]                 # (K, 2, 3)
    y = -np.einsum('kij,kj->ki', G, p) - (pp.t[:, :2] - coef * pp.t[:, 2:3])
    _, _, depth = _project_points(pp, p, None)
    w = (pp.f / np.maximum(depth, min_depth_m)[:, None]) ** 2 / r_var_px2  # residual * f / z
    A, y, w = G.reshape(-1, 3), y.reshape(-1), w.reshape(-1)
    reg = np.zeros((3, 3)) if prior_var is None else np.diag(1.0 / np.asarray(prior_var, float))
    keep = np.ones(len(A), dtype=bool)
    dt = np.zeros(3)
    for _ in range(2 if outlier_px > 0 else 1):
        Ak, wk = A[keep], w[keep]
        H = (Ak.T * wk) @ Ak + reg
        try:
            dt = np.linalg.solve(H, (Ak.T * wk) @ y[keep])
        except np.linalg.LinAlgError as exc:
            raise IKError('translation is not determined by the correspondences') from exc
        if outlier_px <= 0:
            break
        pix, _, _ = _project_points(pp, p + dt, None)
        good = np.linalg.norm(pix - corr.target_px, axis=1) <= outlier_px
        if good.all() or good.sum() < 3:
            break
        keep = np.repeat(good, 2)                    # rows x0, y0, x1, y1, ...
    out = np.array(q, dtype=float)
    out[0:3] = q[0:3] + dt
    _, _, depth = _project_points(pp, p + dt, None)
    if np.any(depth <= min_depth_m):
        raise IKError('translation estimate puts the hand behind a camera')
    return kin.clamp(out)


@dataclass(frozen=True)
class IKSolution:
    """Result of :func:`solve_ik`; ``residual_px`` (K, 2) is target minus projection of each
    correspondence at ``q``."""

    q: np.ndarray
    iterations: int
    cost: float
    initial_cost: float
    converged: bool
    residual_px: np.ndarray

    @property
    def errors_px(self) -> np.ndarray:
        """Pixel distance of each correspondence from its target at ``q`` (as
        :func:`reprojection_errors`)."""
        return np.linalg.norm(self.residual_px, axis=1)


def _cost(r: np.ndarray, w: np.ndarray, q: np.ndarray, q_blend: np.ndarray, q_inv: np.ndarray,
          q_prev: np.ndarray | None, p_inv: np.ndarray | None) -> float:
    c = float(r @ (w * r)) + float(((q - q_blend) ** 2 * q_inv).sum())
    if q_prev is not None and p_inv is not None:
        c += float(((q - q_prev) ** 2 * p_inv).sum())
    return c


def solve_ik(kin: FastKinematics, cameras: Sequence[PinholeCamera], corr: Correspondences,
             q_init: np.ndarray, q_blend: np.ndarray, cov: IKCovariances,
             q_prev: np.ndarray | None = None, max_iterations: int = 6,
             lambda_init: float = 1e-3, step_tol: float = 1e-5,
             min_depth_m: float = 0.05, cost_tol: float = 1e-4) -> IKSolution:
    """Minimise |f(q) - c|^2_{R^-1} + |q - q_b|^2_{Q^-1} (+ |q - q_prev|^2_{P^-1}) by
    Levenberg-damped Gauss-Newton steps
    dq = (J^T R^-1 J + Q^-1 + P^-1 + lambda diag)^-1 (J^T R^-1 (c - f) + Q^-1 (q_b - q)
    + P^-1 (q_prev - q)), projected onto the joint limits (DOFs at a bound whose step
    points outward are frozen). ``max_iterations`` counts linear solves; it stops early when
    the largest DOF change is below ``step_tol`` or the cost falls by less than the
    fraction ``cost_tol``."""
    q = kin.clamp(np.asarray(q_init, dtype=float))
    q_blend = np.asarray(q_blend, dtype=float)
    q_inv = 1.0 / cov.q_var
    p_inv = 1.0 / cov.p_var if q_prev is not None else None
    w = np.tile(1.0 / cov.r_var_px2, len(corr))
    target = corr.target_px.reshape(-1)
    per_point = _per_point(cameras, corr)

    def evaluate(qq: np.ndarray, jacobian: bool) -> tuple[float, np.ndarray, np.ndarray | None]:
        pix, J, depth = project_correspondences(kin, cameras, corr, qq, jacobian, per_point)
        if len(depth) and depth.min() <= min_depth_m:
            return math.inf, np.zeros(0), np.zeros((0, NUM_DOFS))
        r = target - pix.reshape(-1)
        return _cost(r, w, qq, q_blend, q_inv, q_prev, p_inv), r, J

    cost, r, J = evaluate(q, max_iterations > 0)
    if not math.isfinite(cost):
        raise IKError('initial pose puts constraint points behind a camera')
    initial = cost
    lam = lambda_init
    it = 0
    converged = False
    while it < max_iterations and J is not None:
        JW = J.T * w
        H = JW @ J + np.diag(q_inv)
        g = JW @ r + q_inv * (q_blend - q)
        if p_inv is not None:
            H += np.diag(p_inv)
            g += p_inv * (q_prev - q)
        at_lo = (q <= kin.lower + _EPS_LIMIT) & (g < 0)
        at_hi = (q >= kin.upper - _EPS_LIMIT) & (g > 0)
        free = ~(at_lo | at_hi)
        Hf = H[np.ix_(free, free)]
        gf = g[free]
        accepted = False
        while it < max_iterations:
            it += 1
            A = Hf + lam * np.diag(np.diag(Hf))
            try:
                dqf = np.linalg.solve(A, gf)
            except np.linalg.LinAlgError:
                lam *= 10.0
                continue
            dq = np.zeros(NUM_DOFS)
            dq[free] = dqf
            q_new = kin.clamp(q + dq)
            # the last linear solve's pose needs no Jacobian
            cost_new, r_new, J_new = evaluate(q_new, it < max_iterations)
            if cost_new < cost:
                step = float(np.abs(q_new - q).max())
                rel = (cost - cost_new) / max(cost, 1e-12)
                q, cost, r, J = q_new, cost_new, r_new, J_new
                lam = max(lam / 10.0, 1e-9)
                accepted = True
                if step < step_tol or rel < cost_tol:
                    converged = True
                break
            lam *= 10.0
        if not accepted or converged:
            converged = converged or not accepted and lam > 1e6
            break
    return IKSolution(q, it, cost, initial, converged, r.reshape(-1, 2))


# ---------------------------------------------------------------------------- tracker
@dataclass(frozen=True)
class IKResult:
    """One tracker output. ``reprojection_error_px`` is the mean pixel distance of the
    matched constraints at the output pose (NaN when none); ``q`` is None when no hand.
    ``q_blend`` is the lookup's blended pose as given, ``q_prior`` the IK prior q_b (the
    blend with its translation refitted to the constraints)."""

    found: bool
    stamp: float
    q: np.ndarray | None = None
    q_blend: np.ndarray | None = None
    reprojection_error_px: float = math.nan
    reprojection_error_per_camera: tuple[float, ...] = ()
    iterations: int = 0
    time_ms: float = 0.0
    num_constraints: int = 0
    constraints_per_camera: tuple[int, ...] = ()
    smoothed: bool = False
    reset: bool = False
    correspondences: Correspondences | None = None
    num_rejected: int = 0
    q_prior: np.ndarray | None = None


def _local_vertex_normals(mesh: MeshLike) -> np.ndarray | None:
    """Area-weighted vertex normals in the link frames, or None if the mesh has no faces
    (then no back-facing test is made for the other cameras)."""
    faces = getattr(mesh, 'faces', None)
    if faces is None:
        return None
    faces = np.asarray(faces, dtype=np.int64)
    links = np.asarray(mesh.vertex_link)
    if faces.ndim != 2 or faces.shape[1] != 3 or np.any(links[faces[:, 0]] != links[faces[:, 1]]) \
            or np.any(links[faces[:, 0]] != links[faces[:, 2]]):
        return None
    v = np.asarray(mesh.local_vertices, float)
    fn = np.cross(v[faces[:, 1]] - v[faces[:, 0]], v[faces[:, 2]] - v[faces[:, 0]])
    n = np.zeros_like(v)
    for k in range(3):
        np.add.at(n, faces[:, k], fn)
    norm = np.linalg.norm(n, axis=1, keepdims=True)
    return n / np.where(norm > 0, norm, 1.0)


class HandTracker:
    """Temporal IK tracker: blended lookup pose -> refined pose, several cameras.

    The world frame is the primary camera's optical frame (``cameras[0]`` must have
    identity extrinsics); poses are expressed in it. With ``constraint_model: patch`` the
    tracker needs the glove's patch of every mesh face: ``glove`` (a ``core.glove.Glove``),
    or else the standard glove ``default_hand(hand length, config.glove_seed)``, which must
    have been made on the same mesh.
    """

    def __init__(self, model: HandModel, mesh: MeshLike, cameras: Sequence[PinholeCamera],
                 config: IKConfig | None = None, glove: Any = None) -> None:
        if not cameras:
            raise IKError('the tracker needs at least one camera')
        c0 = cameras[0]
        if not (np.allclose(c0.rotation, np.eye(3)) and np.allclose(c0.translation, 0.0)):
            raise IKError('cameras[0] (primary) must have identity extrinsics')
        if len(mesh.vertex_link) != len(mesh.local_vertices):
            raise IKError('mesh vertex_link and local_vertices differ in length')
        self.model = model
        self.kin = FastKinematics(model)
        self.mesh = mesh
        self.cameras = tuple(cameras)
        self.config = config or IKConfig()
        self._q_prev: np.ndarray | None = None
        self._stamp_prev: float | None = None
        self._local_normals = _local_vertex_normals(mesh)
        self._patches = (PatchSurface(self.kin, mesh, self._face_patch(glove))
                         if self.config.constraint_model == 'patch' else None)

    def _face_patch(self, glove: Any) -> np.ndarray:
        if glove is None:
            _, std_mesh, glove = default_hand(self.model.hand_length_m, self.config.glove_seed)
            faces = getattr(self.mesh, 'faces', None)
            if faces is None or not np.array_equal(np.asarray(faces), std_mesh.faces):
                raise IKError('constraint_model patch: pass the glove of this mesh (the '
                              'standard glove is made on another mesh)')
        return np.asarray(glove.face_patch)

    def _with_patch_points(self, corr: Correspondences, q: np.ndarray) -> Correspondences:
        """``corr`` with each constraint moved from its vertex to the predicted centroid of
        the patch's visible part at pose ``q`` (rows whose patch faces away keep the
        vertex)."""
        if self._patches is None or not len(corr):
            return corr
        s = self._patches.max_links
        link = np.zeros((len(corr), s), np.int64)
        local = np.zeros((len(corr), s, 3))
        weight = np.zeros((len(corr), s))
        link[:, 0], local[:, 0], weight[:, 0] = corr.link[:, 0], corr.local[:, 0], 1.0
        used, cam_index = np.unique(corr.camera, return_inverse=True)
        lk, lc, wt, seen = self._patches.points_by_camera(
            q, [self.cameras[int(c)] for c in used], cam_index.reshape(-1), corr.patch_id)
        link[seen], local[seen], weight[seen] = lk[seen], lc[seen], wt[seen]
        return replace(corr, link=link, local=local, weight=weight)

    @classmethod
    def from_calibration(cls, calibration: Calibration, config: IKConfig | None = None,
                         mesh: MeshLike | None = None) -> HandTracker:
        """A tracker for a calibrated rig: the hand model (and, if not given, the mesh) is
        scaled to the user's ``hand_length_m``."""
        model = HandModel(calibration.hand_length_m)
        if mesh is None:
            mesh = build_hand_mesh(model)
        mesh_length = getattr(mesh, 'hand_length_m', None)
        if mesh_length is not None and abs(float(mesh_length) - model.hand_length_m) > 1e-9:
            raise IKError(f'mesh is for a {mesh_length} m hand, calibration says '
                          f'{model.hand_length_m} m')
        return cls(model, mesh, calibration.cameras, config)

    def reset(self) -> None:
        """Forget the previous pose (hand lost, long gap, new sequence)."""
        self._q_prev = None
        self._stamp_prev = None

    @property
    def previous_pose(self) -> np.ndarray | None:
        """The last output pose, or None after a reset."""
        return None if self._q_prev is None else self._q_prev.copy()

    def _match_extras(self, prior: PosePrior, observations: Sequence[CameraObservation],
                      q: np.ndarray, patch_points: bool = True) -> Correspondences:
        """The other cameras' correspondences matched at pose ``q`` (constraints moved to
        the patch points at ``q`` unless ``patch_points`` is false)."""
        cfg = self.config
        cons = prior.constraints
        v = cons.vertex
        if np.any((v < 0) | (v >= len(self.mesh.vertex_link))):
            raise IKError('constraint vertex index out of range of the mesh')
        links = np.asarray(self.mesh.vertex_link)[v]
        pw, _ = self.kin.points(q, links, np.asarray(self.mesh.local_vertices, float)[v])
        normals = None
        if self._local_normals is not None:
            Rs, _, _ = self.kin.frames(q)
            normals = (Rs[self.kin.link_frame[links]] @ self._local_normals[v][:, :, None])[..., 0]
        out = []
        for ci in range(1, len(self.cameras)):
            obs = observations[ci] if ci < len(observations) else None
            if obs is None or not obs.hand_found or len(obs.blobs) == 0:
                continue
            out.append(match_extra_camera(
                ci, self.cameras[ci], cons, pw, obs.blobs, self.mesh, cfg.extra_gate_px,
                cfg.extra_shift_max_px, cfg.extra_inlier_px, cfg.min_blob_pixels,
                cfg.min_depth_m, normals))
        out = Correspondences.concat(out)
        return self._with_patch_points(out, q) if patch_points else out

    def _solve(self, corr: Correspondences, q_init: np.ndarray, q_b: np.ndarray,
               q_prev: np.ndarray | None, iterations: int,
               covariances: IKCovariances) -> IKSolution:
        cfg = self.config
        return solve_ik(self.kin, self.cameras, corr, q_init, q_b, covariances, q_prev,
                        iterations, cfg.lambda_init, cfg.step_tol, cfg.min_depth_m,
                        cfg.cost_tol)

    def update(self, prior: PosePrior | Any | None, observations: Sequence[CameraObservation],
               stamp: float) -> IKResult:
        """Track one frame: ``prior`` from the lookup on the primary camera (a
        :class:`PosePrior` or a ``core.search.LookupResult``; None if the lookup found
        nothing), one observation per camera (primary first), time in seconds."""
        t0 = time.perf_counter()
        cfg = self.config
        if prior is not None and not isinstance(prior, PosePrior):
            prior = PosePrior.from_lookup(prior)
        primary = observations[0] if observations else None
        if prior is None or primary is None or not primary.hand_found:
            self.reset()
            return IKResult(False, stamp, reset=True, time_ms=1e3 * (time.perf_counter() - t0))
        was_reset = False
        if self._stamp_prev is not None:
            gap = stamp - self._stamp_prev
            if not 0.0 < gap <= cfg.max_gap_s:
                self.reset()
                was_reset = True
        q_blend = self.kin.clamp(np.asarray(prior.q_blend, dtype=float).reshape(NUM_DOFS))
        if self._q_prev is not None:
            q_blend[3:6] = align_rotation_vector(q_blend[3:6], self._q_prev[3:6])
        corr0 = match_primary(prior.constraints, primary.blobs, primary.crop, self.cameras[0],
                              self.mesh, cfg.gate_tiny_px, cfg.gate_min_px,
                              cfg.min_blob_pixels)
        multi = len(self.cameras) > 1
        # IK on several cameras, tracking: the other cameras are matched at the last pose and
        # every camera's visible patches predicted there, in one pass (the blend is the
        # coarser guess)
        tracked: Correspondences | None = None
        if multi and cfg.enable_ik and self._q_prev is not None:
            tracked = self._with_patch_points(Correspondences.concat(
                [corr0, self._match_extras(prior, observations, self._q_prev, False)]),
                self._q_prev)
            corr0 = tracked.select(tracked.camera == 0)
        else:
            corr0 = self._with_patch_points(corr0, q_blend)
        q_b = q_blend
        if cfg.init_translation and len(corr0) >= 3:
            try:
                q_b = estimate_translation(
                    self.kin, self.cameras, corr0, q_blend, cfg.min_depth_m,
                    cfg.covariances.q_var[0:3], float(cfg.covariances.r_var_px2.mean()),
                    cfg.outlier_px)
            except IKError:
                q_b = q_blend
        q_prev = self._q_prev if (cfg.enable_smoothing and self._q_prev is not None) else None
        cov = cfg.prior_covariances(prior.finger_std)
        iterations = 0
        q = q_b
        corr = corr0
        rejected = 0
        err: np.ndarray | None = None
        if cfg.enable_ik and (len(corr0) >= cfg.min_constraints or multi):
            if not multi:
                sol = self._solve(corr0, q_b, q_b, q_prev, cfg.max_iterations, cov)
                q, iterations, err = sol.q, sol.iterations, sol.errors_px
            else:
                # predict the other cameras' patches from the last pose while tracking, else
                # from a short primary-camera solve; then solve on all cameras together
                # (a patch seen by one camera only still counts)
                q_start = q_b
                if tracked is not None:
                    corr = tracked
                else:
                    if len(corr0) >= cfg.min_constraints:
                        sol = self._solve(corr0, q_b, q_b, q_prev, cfg.refine_iterations, cov)
                        q_start = q = sol.q
                        iterations = sol.iterations
                    corr = Correspondences.concat(
                        [corr0, self._match_extras(prior, observations, q_start)])
                if len(corr) >= cfg.min_constraints:
                    sol = self._solve(corr, q_start, q_b, q_prev, cfg.multi_camera_iterations, cov)
                    q, err = sol.q, sol.errors_px
                    iterations += sol.iterations
                    if cfg.extra_rematch and len(corr) > len(corr0):
                        again = Correspondences.concat(
                            [corr0, self._match_extras(prior, observations, q)])
                        if not again.same_as(corr) and len(again) >= cfg.min_constraints:
                            corr = again
                            sol = self._solve(corr, q, q_b, q_prev, cfg.refine_iterations, cov)
                            q, err = sol.q, sol.errors_px
                            iterations += sol.iterations
            if cfg.outlier_px > 0 and err is not None:
                bad = err > cfg.outlier_px
                if bad.any() and int((~bad).sum()) >= cfg.min_constraints:
                    rejected = int(bad.sum())
                    corr = corr.select(~bad)
                    sol = self._solve(corr, q, q_b, q_prev, cfg.refine_iterations, cov)
                    q, err = sol.q, sol.errors_px
                    iterations += sol.iterations
        elif multi:
            corr = Correspondences.concat([corr0, self._match_extras(prior, observations, q)])
        if err is None:
            err = reprojection_errors(self.kin, self.cameras, corr, q)
        q = q.copy()
        q[3:6] = align_rotation_vector(q[3:6], np.zeros(3))      # angle in [0, pi]
        n_cam = len(self.cameras)
        per_cam = tuple(float(err[corr.camera == c].mean()) if np.any(corr.camera == c)
                        else math.nan for c in range(n_cam))
        self._q_prev = q.copy()
        self._stamp_prev = stamp
        return IKResult(
            True, stamp, q.copy(), q_blend, float(err.mean()) if len(err) else math.nan,
            per_cam, iterations, 1e3 * (time.perf_counter() - t0), len(corr),
            corr.counts(n_cam), q_prev is not None and iterations > 0, was_reset, corr, rejected,
            q_b.copy())
