"""The IK solve: Levenberg-damped Gauss-Newton on the projection constraints with the blended
pose (Q) and previous pose (P) priors, inside the joint limits (DigitEyes / Wang-Popovic)."""
from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from colorglove_ros.core.camera import PinholeCamera
from colorglove_ros.core.hand.model import NUM_DOFS
from colorglove_ros.core.tracking.config import IKCovariances
from colorglove_ros.core.tracking.kinematics import FastKinematics
from colorglove_ros.core.tracking.line_constraints import ExtraConstraints
from colorglove_ros.core.tracking.projection import (
    per_point_cameras,
    project_correspondences,
)
from colorglove_ros.core.tracking.types import Correspondences, IKError

__all__ = ['IKSolution', 'solve_ik']

_EPS_LIMIT = 1e-9


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


def solve_ik(kin: FastKinematics, cameras: Sequence[PinholeCamera], corr: Correspondences,
             q_init: np.ndarray, q_blend: np.ndarray, cov: IKCovariances,
             q_prev: np.ndarray | None = None, max_iterations: int = 6,
             lambda_init: float = 1e-3, step_tol: float = 1e-5,
             min_depth_m: float = 0.05, cost_tol: float = 1e-4,
             reference_focal_px: float | None = None,
             extra: ExtraConstraints | None = None) -> IKSolution:
    """Minimise |f(q) - c|^2_{R^-1} + |q - q_b|^2_{Q^-1} (+ |q - q_prev|^2_{P^-1}) by
    Levenberg-damped Gauss-Newton steps
    dq = (J^T R^-1 J + Q^-1 + P^-1 + lambda diag)^-1 (J^T R^-1 (c - f) + Q^-1 (q_b - q)
    + P^-1 (q_prev - q)), projected onto the joint limits (DOFs at a bound whose step
    points outward are frozen). ``max_iterations`` counts linear solves; it stops early when
    the largest DOF change is below ``step_tol`` or the cost falls by less than the
    fraction ``cost_tol``. R is in pixels of a camera of focal length ``reference_focal_px``
    (each residual divided by its camera's ``pixel_scale`` per axis; None: each camera's own
    pixels), so the pose does not depend on the image resolution. ``extra`` adds residual
    rows of other kinds (the line features, :mod:`line_constraints`) with their own weights."""
    q = kin.clamp(np.asarray(q_init, dtype=float))
    q_blend = np.ascontiguousarray(q_blend, dtype=float)
    q_inv = 1.0 / cov.q_var
    smoothing = q_prev is not None
    # without smoothing the kernels ignore these two
    q_prev = np.ascontiguousarray(q_prev, dtype=float) if smoothing else q_blend
    p_inv = 1.0 / cov.p_var
    per_point = per_point_cameras(cameras, corr)
    w = (1.0 / cov.r_var_px2 / per_point.axis_scale(reference_focal_px) ** 2).reshape(-1)
    target = corr.target_px.reshape(-1)
    rows = len(target)
    if extra is not None:
        w = np.concatenate([w, extra.weights])

    def evaluate(qq: np.ndarray, jacobian: bool) -> tuple[float, np.ndarray, np.ndarray | None]:
        pix, J, depth = project_correspondences(kin, cameras, corr, qq, jacobian, per_point)
        if len(depth) and depth.min() <= min_depth_m:
            return math.inf, np.zeros(0), np.zeros((0, NUM_DOFS))
        r = target - pix.reshape(-1)
        if extra is not None:
            r_extra, J_extra = extra.residuals(qq, jacobian)
            r = np.concatenate([r, r_extra])
            J = None if J is None else np.concatenate([J, J_extra])
        return kin.kernels.prior_cost(r, w, qq, q_blend, q_inv, q_prev, p_inv, smoothing), r, J

    cost, r, J = evaluate(q, max_iterations > 0)
    if not math.isfinite(cost):
        raise IKError('initial pose puts constraint points behind a camera')
    initial = cost
    lam = lambda_init
    it = 0
    converged = False
    # a DOF is frozen at a bound when it sits there and its step would point outward
    lower, upper = kin.lower + _EPS_LIMIT, kin.upper - _EPS_LIMIT
    while it < max_iterations and J is not None:
        H, g, free = kin.kernels.normal_equations(np.ascontiguousarray(J), w, r, q, q_blend, q_inv,
                                                q_prev, p_inv, smoothing, lower, upper)
        accepted = False
        while it < max_iterations:
            it += 1
            try:
                dq = kin.kernels.damped_step(H, g, free, lam)
            except np.linalg.LinAlgError:
                lam *= 10.0
                continue
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
    return IKSolution(q, it, cost, initial, converged, r[:rows].reshape(-1, 2))
