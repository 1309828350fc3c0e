"""The patch constraint model of the IK: visible-patch centroids predicted from the mesh faces."""
from __future__ import annotations

import numpy as np
import pytest
from repo_paths import CONFIG_DIR

from colorglove_ros.core.camera import load_calibration
from colorglove_ros.core.synthetic.frames import Synthesizer, render_frame
from colorglove_ros.core.synthetic.sequences import generate_sequence
from colorglove_ros.core.tracking.config import IKConfig, IKConfigError
from colorglove_ros.core.tracking.kinematics import FastKinematics
from colorglove_ros.core.tracking.patch_surface import PatchSurface
from colorglove_ros.core.tracking.projection import constraint_points, project_correspondences
from colorglove_ros.core.tracking.tracker import HandTracker
from colorglove_ros.core.tracking.types import Correspondences, IKError, VertexTable


@pytest.fixture(scope='module')
def scene():
    synth = Synthesizer()
    cam = load_calibration(CONFIG_DIR / 'calibration.yaml').cameras[0]
    kin = FastKinematics(synth.model)
    yield synth, cam, kin, PatchSurface(kin, synth.mesh, synth.glove.face_patch)
    synth.release()


def _patch_rows(surface: PatchSurface, kin: FastKinematics, cam, q: np.ndarray,
                patch_ids: np.ndarray) -> Correspondences:
    """Rows for the patches facing the camera (the others are dropped)."""
    link, local, weight, seen = surface.points(q, cam, patch_ids)
    n = int(seen.sum())
    z = np.zeros(n, np.int64)
    return Correspondences(z, link[seen], local[seen], np.zeros((n, 2)), patch_ids[seen], z,
                           weight[seen])


def test_predicted_centroids_match_the_rendered_patches(scene):
    synth, cam, kin, surface = scene
    errors, all_faces = [], []
    for q in generate_sequence(7, 6, camera=cam, model=synth.model):
        frame = render_frame(q, cam, np.random.default_rng(0), synthesizer=synth)
        ids = frame.patch_ids.astype(np.int64) - 1
        counts = np.bincount(ids[ids >= 0], minlength=20)
        visible = np.flatnonzero(counts >= 40)
        truth = np.array([np.argwhere(ids == p)[:, ::-1].mean(axis=0) for p in visible])
        corr = _patch_rows(surface, kin, cam, q, visible)
        assert len(corr) == len(visible)
        pix, _, _ = project_correspondences(kin, [cam], corr, q)
        errors.extend(np.linalg.norm(pix - truth, axis=1))
        # reference: the mean of all the patch's faces, seen or not
        verts = synth.mesh.skin(synth.model, q)
        face_c = verts[synth.mesh.faces].mean(axis=1)
        for p, t in zip(visible, truth, strict=True):
            c = face_c[synth.glove.face_patch == p].mean(axis=0)
            all_faces.append(np.linalg.norm(cam.project(c[None])[0] - t))
    assert np.median(errors) < 2.5
    assert np.mean(errors) < 0.6 * np.mean(all_faces)


def test_mixed_rows_have_the_weighted_point_jacobian(scene):
    synth, cam, kin, surface = scene
    q = generate_sequence(3, 1, camera=cam, model=synth.model)[0]
    corr = _patch_rows(surface, kin, cam, q, np.arange(20))
    assert len(corr) >= 10 and corr.link.shape[1] > 1 and np.allclose(corr.weight.sum(axis=1), 1.0)
    p, J = constraint_points(kin, corr, q, jacobian=True)
    num = np.zeros_like(J)
    for i in range(26):
        dq = np.zeros(26)
        dq[i] = 1e-6
        num[:, :, i] = (constraint_points(kin, corr, q + dq)[0]
                        - constraint_points(kin, corr, q - dq)[0]) / 2e-6
    np.testing.assert_allclose(J, num, atol=1e-7)
    # rows of several points padded to a common width keep their values when joined
    single = Correspondences(np.zeros(1, np.int64), np.array([3]), np.zeros((1, 3)),
                             np.zeros((1, 2)), np.zeros(1, np.int64), np.zeros(1, np.int64))
    joined = Correspondences.concat([single, corr])
    np.testing.assert_allclose(constraint_points(kin, joined, q)[0][1:], p, atol=1e-12)


def test_constraint_model_is_checked():
    with pytest.raises(IKConfigError):
        IKConfig(constraint_model='blob')


def test_patch_model_needs_the_glove_of_its_mesh(scene):
    synth, cam, kin, _ = scene
    table = VertexTable(synth.mesh.vertex_link, synth.mesh.local_vertices)
    with pytest.raises(IKError, match='glove'):
        HandTracker(synth.model, table, [cam], IKConfig())
    HandTracker(synth.model, table, [cam], IKConfig(constraint_model='vertex'))
    HandTracker(synth.model, synth.mesh, [cam], IKConfig())     # the standard glove


def test_patch_colours_come_from_the_standard_glove_without_the_patch_model(scene):
    synth, cam, _, _ = scene
    tracker = HandTracker(synth.model, synth.mesh, [cam], IKConfig(constraint_model='vertex'))
    np.testing.assert_array_equal(tracker.patch_color, synth.glove.patch_color)
    table = VertexTable(synth.mesh.vertex_link, synth.mesh.local_vertices)
    other = HandTracker(synth.model, table, [cam], IKConfig(constraint_model='vertex'))
    with pytest.raises(IKError, match='not the standard mesh: pass glove='):
        _ = other.patch_color


def test_cameras_sharing_a_pose_get_the_same_points_as_alone(scene):
    """The posed glove is reused by the next camera at the same pose, and the primary
    camera skips its identity transform: neither may change the points of any camera."""
    synth, cam, kin, surface = scene
    stereo = load_calibration(CONFIG_DIR / 'calibration_stereo.yaml').cameras
    q = generate_sequence(5, 1, camera=cam, model=synth.model)[0]
    ids = np.arange(20)
    shared = [surface.points(q, c, ids) for c in stereo]         # second call reuses the pose
    for c, got in zip(stereo, shared, strict=True):
        alone = PatchSurface(kin, synth.mesh, synth.glove.face_patch).points(q, c, ids)
        for a, b in zip(got, alone, strict=True):
            np.testing.assert_allclose(a, b, atol=1e-12)
    # the second camera sees a different set of patch parts (the test is not vacuous)
    assert not np.allclose(shared[0][2], shared[1][2])


def test_points_by_camera_match_each_camera_alone(scene):
    """Rows of several cameras in one pass (interleaved, repeated patches) get exactly the
    points, weights and visibility each camera gets on its own."""
    synth, cam, kin, surface = scene
    stereo = load_calibration(CONFIG_DIR / 'calibration_stereo.yaml').cameras
    q = generate_sequence(7, 1, camera=cam, model=synth.model)[0]
    rng = np.random.default_rng(2)
    ids = rng.integers(0, surface.num_patches, 40)
    which = rng.integers(0, len(stereo), 40)
    got = surface.points_by_camera(q, stereo, which, ids)
    for c in range(len(stereo)):
        rows = which == c
        alone = PatchSurface(kin, synth.mesh, synth.glove.face_patch).points(q, stereo[c],
                                                                             ids[rows])
        for a, b in zip(got, alone, strict=True):
            np.testing.assert_allclose(a[rows], b, atol=1e-12)
    assert got[3].any() and not got[3].all()     # some rows seen, some not: not vacuous
    with pytest.raises(IKError, match='camera index'):
        surface.points_by_camera(q, stereo, np.full(40, 2), ids)


def test_a_min_link_weight_that_could_drop_every_link_of_a_patch_is_refused(scene):
    synth = scene[0]
    kin = FastKinematics(synth.model)
    surface = PatchSurface(kin, synth.mesh, synth.glove.face_patch)
    too_high = 1.0 / surface.max_links
    with pytest.raises(IKError, match='min_link_weight'):
        PatchSurface(kin, synth.mesh, synth.glove.face_patch, min_link_weight=too_high)
    with pytest.raises(IKError, match='min_link_weight'):
        PatchSurface(kin, synth.mesh, synth.glove.face_patch, min_link_weight=-0.1)
