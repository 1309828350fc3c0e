"""Exact speed cuts of the IK (issue 19, ninth pass): the same bits as the code they replace,
with fewer numpy calls per frame."""
from __future__ import annotations

import math

import numpy as np
import pytest
from pose_samples import random_poses
from repo_paths import CONFIG_DIR

from colorglove_ros.core.camera import load_calibration
from colorglove_ros.core.hand.glove import default_hand
from colorglove_ros.core.hand.model import NUM_DOFS
from colorglove_ros.core.tracking import solver as solver_module
from colorglove_ros.core.tracking.config import IKCovariances
from colorglove_ros.core.tracking.kinematics import FastKinematics
from colorglove_ros.core.tracking.patch_surface import PatchSurface
from colorglove_ros.core.tracking.projection import project_correspondences
from colorglove_ros.core.tracking.solver import solve_ik
from colorglove_ros.core.tracking.types import Correspondences


@pytest.fixture(scope='module')
def hand():
    model, mesh, glove = default_hand()
    kin = FastKinematics(model)
    camera = load_calibration(CONFIG_DIR / 'calibration.yaml').cameras[0]
    return model, mesh, kin, PatchSurface(kin, mesh, glove.face_patch), camera


def _poses(model, count: int, seed: int) -> list[np.ndarray]:
    return random_poses(model, count, seed, rotation_sd=0.6)


def test_posed_elements_are_each_elements_frame_transform(hand):
    """The compiled posing (``ik_kernel.posed_elements``, tenth pass) against each element's
    own frame transform (numpy), to rounding."""
    model, _, _, surface, _ = hand
    for q in _poses(model, 40, 1):
        centre, normal = surface._posed(q)
        Rs, ts, _ = surface._kin.frames(q)
        R, t = Rs[surface._element_frame], ts[surface._element_frame]
        np.testing.assert_allclose(centre, np.einsum('eij,ej->ei', R, surface._centre) + t,
                                   rtol=0, atol=1e-15)
        np.testing.assert_allclose(normal, np.einsum('eij,ej->ei', R, surface._area_normal),
                                   rtol=0, atol=1e-15)


def _solve_reference(kin, cameras, corr, q_init, q_blend, cov, q_prev, max_iterations,
                     lambda_init, step_tol, min_depth_m, cost_tol, reference_focal_px):
    """``solve_ik``'s loop as it was (every iteration gathers the free block and builds the
    prior diagonals), without line features."""
    q = kin.clamp(np.asarray(q_init, dtype=float))
    q_inv = 1.0 / cov.q_var
    p_inv = 1.0 / cov.p_var if q_prev is not None else None
    per_point = solver_module.per_point_cameras(cameras, corr)
    w = (1.0 / cov.r_var_px2 / per_point.axis_scale(reference_focal_px) ** 2).reshape(-1)
    target = corr.target_px.reshape(-1)

    def evaluate(qq, jacobian):
        pix, J, depth = project_correspondences(kin, cameras, corr, qq, jacobian, per_point)
        if len(depth) and depth.min() <= min_depth_m:
            return math.inf, np.zeros(0), np.zeros((0, NUM_DOFS))
        r = target - pix.reshape(-1)
        c = float(r @ (w * r)) + float(((qq - q_blend) ** 2 * q_inv).sum())
        if p_inv is not None:
            c += float(((qq - q_prev) ** 2 * p_inv).sum())
        return c, r, J

    cost, r, J = evaluate(q, max_iterations > 0)
    lam, it, converged = lambda_init, 0, False
    while it < max_iterations and J is not None:
        JW = J.T * w
        H = JW @ J + np.diag(q_inv)
        g = JW @ r + q_inv * (q_blend - q)
        if p_inv is not None:
            H += np.diag(p_inv)
            g += p_inv * (q_prev - q)
        at_lo = (q <= kin.lower + 1e-9) & (g < 0)
        at_hi = (q >= kin.upper - 1e-9) & (g > 0)
        free = ~(at_lo | at_hi)
        Hf, gf = H[np.ix_(free, free)], g[free]
        accepted = False
        while it < max_iterations:
            it += 1
            A = Hf + lam * np.diag(np.diag(Hf))
            dq = np.zeros(NUM_DOFS)
            dq[free] = np.linalg.solve(A, gf)
            q_new = kin.clamp(q + dq)
            cost_new, r_new, J_new = evaluate(q_new, it < max_iterations)
            if cost_new < cost:
                step = float(np.abs(q_new - q).max())
                rel = (cost - cost_new) / max(cost, 1e-12)
                q, cost, r, J = q_new, cost_new, r_new, J_new
                lam = max(lam / 10.0, 1e-9)
                accepted = True
                converged = step < step_tol or rel < cost_tol
                break
            lam *= 10.0
        if not accepted or converged:
            break
    return q, it, cost


def _problem(hand, seed: int, at_bounds: bool):
    """A fit from a perturbed start to the projections of mesh vertices at a true pose
    (with fingers pushed beyond their limits when ``at_bounds``, so DOFs freeze)."""
    model, mesh, kin, _, camera = hand
    rng = np.random.default_rng(seed)
    q_true = _poses(model, 1, seed)[0]
    if at_bounds:
        q_true[6:] = model.lower_limits[6:] - 0.3
    verts = rng.choice(len(mesh.vertex_link), 24, replace=False)
    links = mesh.vertex_link[verts]
    local = mesh.local_vertices[verts]
    pw, _ = kin.points(q_true, links, local)
    target = camera.project(camera.world_to_camera(pw)) + rng.normal(0.0, 1.0, (24, 2))
    corr = Correspondences(np.zeros(24, np.int64), links, local, target, np.arange(24), verts)
    q0 = model.clamp(q_true + rng.normal(0.0, 0.05, NUM_DOFS))
    return kin, [camera], corr, q0, model.clamp(q_true)


@pytest.mark.parametrize('at_bounds', [False, True])
@pytest.mark.parametrize('smoothing', [False, True])
def test_solve_is_the_old_loops_pose(hand, at_bounds, smoothing):
    """The numpy loop as it was against the compiled normal equations and steps (tenth pass):
    the same iterations, the pose to rounding."""
    cov = IKCovariances([3.0, 3.0], np.full(NUM_DOFS, 0.2), np.full(NUM_DOFS, 0.1))
    for seed in range(6):
        kin, cameras, corr, q0, q_true = _problem(hand, seed, at_bounds)
        q_prev = q0 + 0.01 if smoothing else None
        args = (kin, cameras, corr, q0, q0, cov, q_prev, 4, 1e-3, 1e-5, 0.05, 1e-4, 600.0)
        sol = solve_ik(*args)
        q, iterations, cost = _solve_reference(*args)
        assert np.abs(sol.q - q).max() <= 1e-9 and sol.iterations == iterations
        assert sol.cost == pytest.approx(cost, rel=1e-9)
