"""Fast forward kinematics and analytic point Jacobians of the hand model, for the IK."""
from __future__ import annotations

from typing import Any

import numpy as np

from colorglove_ros.core.geometry import rotvec_to_matrix_and_left_jacobian, vector_to_skew
from colorglove_ros.core.hand.model import NUM_DOFS, HandModel
from colorglove_ros.core.tracking.types import IKError

__all__ = ['FastKinematics']


def _field(obj: Any, *names: str) -> Any:
    for name in names:
        if hasattr(obj, name):
            return getattr(obj, name)
    raise IKError(f'hand-model joint has none of the fields {names}')


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
        self._K = vector_to_skew(self._axis)
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
        self._basis_skew = vector_to_skew(self._eye)
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
        T[0, :3, :3], jl = rotvec_to_matrix_and_left_jacobian(q[3:6])
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
        w_skew = vector_to_skew((Rs[1:] @ self._axis[:, :, None])[:, :, 0])          # (nj, 3, 3)
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
