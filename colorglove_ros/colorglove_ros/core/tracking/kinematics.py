"""Fast forward kinematics and analytic point Jacobians of the hand model, for the IK."""
from __future__ import annotations

from types import ModuleType
from typing import Any

import numpy as np

from colorglove_ros.core.geometry import vector_to_skew
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
    construction), computed by the compiled kernels of :mod:`ik_kernel` (``kernels``: imported,
    and compiled or loaded from their cache, when the first instance is made, so a module that
    only imports this one loads neither numba nor scipy).
    """

    def __init__(self, model: HandModel) -> None:
        from colorglove_ros.core.tracking import ik_kernel

        ik_kernel.compile_kernels()
        self.kernels: ModuleType = ik_kernel
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
        ancestors = np.zeros((n + 1, n), dtype=float)
        for f, j in enumerate(joints, start=1):
            ancestors[f] = ancestors[j.parent_frame]
            ancestors[f, f - 1] = 1.0
        self._ancestors = ancestors
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
        q = np.ascontiguousarray(q, dtype=float)
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
        Rs, ts, jl = self.kernels.forward_frames(q[3:6], q[self._dof], self._K, self._KK,
                                              self._fixed_R, self._fixed_t, self._parent)
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
        p, J = self.kernels.link_points(
            Rs, ts, jl, self._axis, self._ancestors, self._dof, NUM_DOFS,
            np.ascontiguousarray(self.link_frame[link]),
            np.ascontiguousarray(local, dtype=float), jacobian)
        return p, (J if jacobian else None)

    def projected_points(self, q: np.ndarray, link: np.ndarray, local: np.ndarray,
                         weight: np.ndarray, cam_R: np.ndarray, cam_t: np.ndarray,
                         focal: np.ndarray, centre: np.ndarray, jacobian: bool
                         ) -> tuple[np.ndarray, np.ndarray | None, np.ndarray]:
        """Pixels (K, 2), optionally d pixel / dq (2K, 26) (rows x0, y0, x1, ...) and camera
        depths (K,) of K points, each the ``weight``-ed mean (K, S) of link-fixed points
        (``link``, ``local``: (K, S), (K, S, 3)), row k seen by a pinhole camera with rotation
        ``cam_R[k]``, translation ``cam_t[k]``, focal lengths ``focal[k]`` and centre
        ``centre[k]`` (``ik_kernel.projected_rows``; C-contiguous arrays)."""
        Rs, ts, jl = self.frames(q)
        pix, J, depth = self.kernels.projected_rows(
            Rs, ts, jl, self._axis, self._ancestors, self._dof, NUM_DOFS, self.link_frame[link],
            local, weight, cam_R, cam_t, focal, centre, jacobian)
        return pix, (J if jacobian else None), depth

    def clamp(self, q: np.ndarray) -> np.ndarray:
        """Clip a pose into the joint limits."""
        return np.clip(q, self.lower, self.upper)
