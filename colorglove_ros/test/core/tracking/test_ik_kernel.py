"""The compiled IK kernels (issue 19, tenth pass): the numbers of the hand model and of the
numpy code they replaced, compiled before the first frame, and the fits on recorded inputs.

``data/ik_reference.npz`` was recorded by ik_node on main (de73301, the numpy kinematics)
replaying the first 150 frames of the benchmark bag (``colorglove_benchmark``: seed 2, 640x480,
the 100,000-entry database): every tenth call of ``solve_ik``, ``estimate_translation``,
``PatchSurface.points_by_camera`` and ``PatchSurface.visible_patches`` with its inputs and what
it returned (``<kind><index>_<name>``; ``out_*`` the outputs; the camera and hand model in
``camera`` and ``hand``)."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from pose_samples import random_poses

from colorglove_ros.core.camera import PinholeCamera
from colorglove_ros.core.hand.glove import default_hand
from colorglove_ros.core.hand.model import NUM_DOFS
from colorglove_ros.core.tracking import ik_kernel
from colorglove_ros.core.tracking.config import IKCovariances
from colorglove_ros.core.tracking.kinematics import FastKinematics
from colorglove_ros.core.tracking.patch_surface import PatchSurface
from colorglove_ros.core.tracking.projection import estimate_translation
from colorglove_ros.core.tracking.solver import solve_ik
from colorglove_ros.core.tracking.types import Correspondences, IKError

REFERENCE = Path(__file__).parent / 'data' / 'ik_reference.npz'
# the fitted poses may differ from the numpy code's by rounding only
POSE_TOL = 1e-9
CORR_FIELDS = ('camera', 'link', 'local', 'target_px', 'patch_id', 'vertex', 'weight')


@pytest.fixture(scope='module')
def recorded():
    data = dict(np.load(REFERENCE))
    hand_length, *factors = data['hand'].tolist()
    model, mesh, glove = default_hand(hand_length, finger_length_factors=factors)
    kin = FastKinematics(model)
    width, height, fx, fy, cx, cy = data['camera'].tolist()
    camera = PinholeCamera(int(width), int(height), fx, fy, cx, cy)
    return data, model, kin, PatchSurface(kin, mesh, glove.face_patch), camera


def _calls(data: dict, kind: str) -> list[dict]:
    prefixes = sorted({key.split('_')[0] for key in data if key.startswith(kind)})
    assert prefixes, f'no {kind} calls recorded'
    return [{key[len(p) + 1:]: data[key] for key in data if key.startswith(p + '_')}
            for p in prefixes]


def _corr(call: dict) -> Correspondences:
    return Correspondences(*(call[f'corr_{name}'] for name in CORR_FIELDS))


def _optional(value: np.ndarray) -> np.ndarray | float | None:
    return None if np.all(np.isnan(value)) else value


def test_solves_on_recorded_inputs_match_the_numpy_code(recorded) -> None:
    data, _, kin, _, camera = recorded
    calls = _calls(data, 'solve')
    for call in calls:
        iterations, lam, step_tol, min_depth, cost_tol, focal = call['settings'].tolist()
        cov = IKCovariances(call['r_var'], call['q_var'], call['p_var'])
        sol = solve_ik(kin, [camera], _corr(call), call['q_init'], call['q_blend'], cov,
                       _optional(call['q_prev']), int(iterations), lam, step_tol, min_depth,
                       cost_tol, None if np.isnan(focal) else focal)
        assert np.abs(sol.q - call['out_q']).max() <= POSE_TOL
        assert sol.iterations == int(call['out_iterations'])
        assert sol.converged == bool(call['out_converged'])
        assert sol.cost == pytest.approx(float(call['out_cost']), rel=1e-9)
        assert sol.initial_cost == pytest.approx(float(call['out_initial_cost']), rel=1e-9)
        np.testing.assert_allclose(sol.residual_px, call['out_residual'], rtol=0, atol=1e-7)


def test_translation_fits_on_recorded_inputs_match_the_numpy_code(recorded) -> None:
    data, _, kin, _, camera = recorded
    for call in _calls(data, 'translation'):
        min_depth, r_var, outlier, focal = call['settings'].tolist()
        expected = _optional(call['out_q'])
        args = (kin, [camera], _corr(call), call['q'], min_depth, call['prior_var'], r_var,
                outlier, None if np.isnan(focal) else focal)
        if expected is None:
            with pytest.raises(IKError):
                estimate_translation(*args)
            continue
        assert np.abs(estimate_translation(*args) - expected).max() <= POSE_TOL


def test_patch_points_on_recorded_poses_match_the_numpy_code(recorded) -> None:
    data, _, _, surface, camera = recorded
    for call in _calls(data, 'points'):
        link, local, weight, seen = surface.points_by_camera(
            call['q'], [camera], call['camera_index'], call['patch_id'])
        np.testing.assert_array_equal(seen, call['out_seen'])
        np.testing.assert_allclose(weight, call['out_weight'], rtol=0, atol=1e-9)
        used = weight > 0
        np.testing.assert_array_equal(link[used], call['out_link'][used])
        np.testing.assert_allclose(local[used], call['out_local'][used], rtol=0, atol=1e-12)
    for call in _calls(data, 'visible'):
        area, centroid = surface.visible_patches(call['q'], camera)
        np.testing.assert_allclose(area, call['out_area'], rtol=1e-9, atol=1e-9)
        np.testing.assert_allclose(centroid, call['out_centroid'], rtol=0, atol=1e-9)


def _random_poses(model, count: int, seed: int) -> list[np.ndarray]:
    poses = random_poses(model, count, seed, rotation_sd=1.2)
    # a rotation vector on the small-angle branch
    poses.append(model.clamp(np.concatenate([[0.0, 0.0, 0.5], [1e-7, -2e-7, 0.0],
                                             poses[0][6:]])))
    return poses


def test_kernel_points_and_jacobians_are_the_hand_models(recorded) -> None:
    _, model, kin, _, _ = recorded
    rng = np.random.default_rng(3)
    num_links = len(model.link_transforms(model.rest_pose()))
    link = rng.integers(0, num_links, 40)
    local = rng.normal(0.0, 0.02, (40, 3))
    for q in _random_poses(model, 20, 7):
        p, J = kin.points(q, link, local, jacobian=True)
        np.testing.assert_allclose(p, model.transform_points(q, link, local), rtol=0,
                                   atol=1e-12)
        np.testing.assert_allclose(J, model.point_jacobian(q, link, local), rtol=0, atol=1e-9)
        p_only, none = kin.points(q, link, local)
        assert none is None
        np.testing.assert_array_equal(p_only, p)


def test_projected_rows_are_the_mixed_points_projected(recorded) -> None:
    """Each row the weighted mean of its points, projected; its Jacobian the projection's
    chained with the points' (against central differences)."""
    _, model, kin, _, camera = recorded
    rng = np.random.default_rng(5)
    rows, slots = 12, 3
    num_links = len(model.link_transforms(model.rest_pose()))
    link = rng.integers(0, num_links, (rows, slots))
    local = rng.normal(0.0, 0.02, (rows, slots, 3))
    weight = rng.uniform(0.0, 1.0, (rows, slots))
    weight[:, 1] = 0.0
    weight /= weight.sum(axis=1, keepdims=True)
    cam = np.repeat(np.eye(3)[None], rows, axis=0)
    t, f = np.zeros((rows, 3)), np.tile([camera.fx, camera.fy], (rows, 1))
    c = np.tile([camera.cx, camera.cy], (rows, 1))
    for q in _random_poses(model, 5, 11):
        pix, J, depth = kin.projected_points(q, link, local, weight, cam, t, f, c, True)
        points = np.einsum('ks,ksi->ki', weight,
                           model.transform_points(q, link.reshape(-1), local.reshape(-1, 3))
                           .reshape(rows, slots, 3))
        np.testing.assert_allclose(depth, points[:, 2], rtol=0, atol=1e-12)
        np.testing.assert_allclose(pix, points[:, :2] / points[:, 2:] * f + c, rtol=0,
                                   atol=1e-9)
        numeric = np.empty((2 * rows, NUM_DOFS))
        for d in range(NUM_DOFS):
            step = np.zeros(NUM_DOFS)
            step[d] = 1e-6
            hi, _, _ = kin.projected_points(q + step, link, local, weight, cam, t, f, c, False)
            lo, _, _ = kin.projected_points(q - step, link, local, weight, cam, t, f, c, False)
            numeric[:, d] = ((hi - lo) / 2e-6).reshape(-1)
        np.testing.assert_allclose(J, numeric, rtol=1e-5, atol=1e-3)


def test_kernels_compiled_before_the_first_frame_and_never_again(recorded) -> None:
    """Making a FastKinematics compiles every kernel for one signature and turns compiling
    off: an argument of another layout raises instead of compiling on a frame."""
    for kernel in (ik_kernel.forward_frames, ik_kernel.link_points, ik_kernel.projected_rows):
        assert len(kernel.signatures) == 1
    assert ik_kernel.compile_kernels() < 1.0          # nothing left to compile
    _, _, kin, _, _ = recorded
    q = np.zeros(2 * NUM_DOFS)[::2]                   # not contiguous
    q[2] = 0.5
    Rs, ts, jl = kin.frames(q)                        # frames() makes its own copies
    with pytest.raises(TypeError):
        ik_kernel.link_points(Rs, ts, jl, kin._axis, kin._ancestors, kin._dof, NUM_DOFS,
                              np.zeros(4, np.int64)[::2], np.zeros((2, 3)), False)


def test_wrist_rotation_and_left_jacobian_match_the_geometry_module():
    """The compiled wrist rotation and its SO(3) left Jacobian (one pass, Taylor terms below
    1e-5 rad) equal ``core.geometry``'s separate functions, on both branches."""
    from colorglove_ros.core.geometry import rotvec_to_matrix, so3_left_jacobian

    kin = FastKinematics(default_hand()[0])
    rng = np.random.default_rng(3)
    rotvecs = [rng.normal(size=3) * scale for scale in (1.0, 0.3, 1e-6, 0.0) for _ in range(10)]
    for r in rotvecs:
        q = np.zeros(NUM_DOFS)
        q[3:6] = r
        Rs, _, jl = kin.frames(q)
        np.testing.assert_allclose(Rs[0], rotvec_to_matrix(r), atol=1e-15)
        np.testing.assert_allclose(jl, so3_left_jacobian(r), atol=1e-15)
