"""Exact speed cuts of the IK (issue 19, ninth and twelfth passes): the same bits as the code
they replace, with fewer numpy calls per frame."""
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


def _points_reference(surface, q, cameras, camera_index, patch_id):
    """``PatchSurface.points_by_camera``'s numpy aggregation before ``ik_kernel.patch_points``
    (twelfth pass): bincounts over every camera's elements, then the rows' link weights."""
    pc, normal = surface._posed(q)
    nc, ng, np_ = len(cameras), len(surface._group_link), surface.num_patches
    weights = [surface._element_weights(pc, normal, cam) for cam in cameras]
    w = np.concatenate([front for _, front, _ in weights])
    w_vis = np.concatenate([vis for _, _, vis in weights])
    ne = len(surface._centre)
    cam = np.repeat(np.arange(nc), ne)
    group = cam * ng + np.tile(surface._group, nc)
    elem_patch = cam * np_ + np.tile(surface._elem_patch, nc)
    group_xyz = (3 * group[:, None] + np.arange(3)).reshape(-1)
    centre = np.tile(surface._centre, (nc, 1))
    vis_frac = (np.bincount(elem_patch, w_vis, nc * np_)
                / np.maximum(np.bincount(elem_patch, w, nc * np_), 1e-300))
    w = np.where(vis_frac[elem_patch] < surface.min_visible_fraction, w, w_vis)
    wg = np.bincount(group, w, nc * ng)
    mean = (np.bincount(group_xyz, (w[:, None] * centre).reshape(-1), 3 * nc * ng)
            .reshape(nc * ng, 3) / np.maximum(wg, 1e-300)[:, None])
    groups = surface._table[patch_id]
    valid = groups >= 0
    g = np.where(valid, groups, 0)
    gc = g + (camera_index * ng)[:, None]
    weight = np.where(valid, wg[gc], 0.0)
    total = weight.sum(axis=1)
    seen = total > 0
    weight = weight / np.where(seen, total, 1.0)[:, None]
    weight[weight < surface.min_link_weight] = 0.0
    weight /= np.where(seen, weight.sum(axis=1), 1.0)[:, None]
    return surface._group_link[g], mean[gc], weight, seen


def _visible_reference(surface, q, camera):
    """``PatchSurface.visible_patches``' numpy sums before ``ik_kernel.patch_areas``."""
    patch, uv, weight = surface.visible_faces(q, camera)
    n = surface.num_patches
    area = np.bincount(patch, weight, n)
    centroid = np.stack([np.bincount(patch, weight * uv[:, i], n) for i in range(2)], axis=1)
    with np.errstate(invalid='ignore', divide='ignore'):
        centroid = centroid / area[:, None]
    centroid[area <= 0] = np.nan
    return area, centroid


def test_patch_sums_are_the_numpy_codes_bits(hand):
    """The compiled patch-point aggregation and visible-patch sums (twelfth pass) give the
    numpy code's bits, with one camera and two, every row's patch drawn at random."""
    model, _, _, surface, camera = hand
    stereo = load_calibration(CONFIG_DIR / 'calibration_stereo.yaml').cameras
    assert surface.max_links < 8       # row sums in order are numpy's below 8 terms
    rng = np.random.default_rng(4)
    rows_seen = 0
    for q in _poses(model, 30, 6):
        for cameras in ([camera], list(stereo)):
            patch_id = rng.integers(0, surface.num_patches, 24)
            camera_index = rng.integers(0, len(cameras), 24)
            got = surface.points_by_camera(q, cameras, camera_index, patch_id)
            expected = _points_reference(surface, q, cameras, camera_index, patch_id)
            for a, b in zip(got, expected, strict=True):
                assert a.dtype == b.dtype and a.shape == b.shape
                np.testing.assert_array_equal(a, b)
            rows_seen += int(got[3].sum())
        for a, b in zip(surface.visible_patches(q, camera), _visible_reference(surface, q, camera),
                        strict=True):
            np.testing.assert_array_equal(a, b)
    assert rows_seen > 500              # the poses show the glove


def test_patch_kernels_have_one_signature(hand):
    """The patch sums run compiled (one signature each, compiling off): a strided patch id
    array is made contiguous by the caller, one of another dtype raises."""
    from colorglove_ros.core.tracking import ik_kernel

    model, _, _, surface, camera = hand
    for kernel in (ik_kernel.patch_points, ik_kernel.patch_areas):
        assert len(kernel.signatures) == 1
    q = _poses(model, 1, 7)[0]
    strided = np.arange(40, dtype=np.int64)[::2] % surface.num_patches
    surface.points(q, camera, strided)
    with pytest.raises(TypeError):
        ik_kernel.patch_areas(np.zeros((3, 3)), np.zeros(3), np.zeros(3, np.int32), 2,
                              1.0, 1.0, 0.0, 0.0)
