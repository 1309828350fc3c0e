"""Tests for the lookup diagnosis: full-pose oracle distances and the (a)-(d) table."""
from __future__ import annotations

import numpy as np
import pytest
from label_samples import random_blob_images
from scipy.spatial.transform import Rotation
from small_databases import blob_database, poses_on_axis

from colorglove_ros.core.camera import PinholeCamera
from colorglove_ros.core.evaluation.diagnosis import (
    ESTIMATES,
    FullPoseIndex,
    QueryFrames,
    coverage,
    diagnose,
)
from colorglove_ros.core.hand.poses import pose_collection, sample_global_rotations
from colorglove_ros.core.lookup.search import PoseLookup


@pytest.fixture(scope='module')
def hand_db():
    """Blob images standing in for renders, with real finger configurations (12 configs x 10
    rotations) and the wrist on the optical axis."""
    rng = np.random.default_rng(0)
    n_cfg, views = 12, 10
    fingers = pose_collection(0, 200)[rng.choice(200, n_cfg, replace=False)]
    cfg = np.repeat(np.arange(n_cfg), views)
    poses = poses_on_axis(sample_global_rotations(rng, len(cfg)), fingers[cfg])
    tiny = random_blob_images(rng, len(poses))
    crop = np.tile([1.2, 40.0, 41.0], (len(poses), 1))
    return blob_database(tiny, poses, crop, config_index=cfg, num_bits=64, num_pairs=300)


def test_full_pose_distances_match_skinned_vertices(hand_db, hand) -> None:
    model, mesh, _ = hand
    poses = np.asarray(hand_db.poses, np.float64)
    index = FullPoseIndex(model, mesh, poses[:, 6:], hand_db.config_index, num_vertices=80)
    truth = poses[13].copy()
    truth[3:6] = (Rotation.from_rotvec(truth[3:6]) * Rotation.from_rotvec([0.1, 0, 0])).as_rotvec()
    got = index.pose_distances(truth, poses[:, 3:6])
    for e in (0, 13, 57):
        a, b = truth.copy(), poses[e].copy()
        a[0:3] = b[0:3] = 0.0
        va, vb = (mesh.skin_batch(model, np.stack([a, b]))[:, index.subset])
        assert got[e] == pytest.approx(np.sqrt(((va - vb) ** 2).sum() / len(va)), rel=1e-6)
    assert index.pose_distances(poses[13], poses[:, 3:6])[13] == pytest.approx(0.0, abs=1e-6)
    fd = index.finger_distances(poses[57, 6:])
    assert fd[index.entry_config[57]] == pytest.approx(0.0, abs=1e-7) and np.sum(fd < 1e-7) == 1


def test_diagnosis_of_exact_entries(hand_db, hand) -> None:
    """Queries that are database entries: the image NN and the pipeline's top-1 are exact
    matches, and the pose oracle is the entry itself (zero error)."""
    model, mesh, _ = hand
    lookup = PoseLookup(hand_db, num_candidates=40, num_blend=5, threads=1)
    entries = np.array([3, 44, 90])
    frames = QueryFrames(np.asarray(hand_db.tiny)[entries], np.asarray(hand_db.crop)[entries],
                         np.asarray(hand_db.poses, np.float64)[entries],
                         np.stack([entries, entries], axis=1))
    cam = PinholeCamera(128, 128, 150.0, 150.0, 63.5, 63.5)
    index = FullPoseIndex(model, mesh, np.asarray(hand_db.poses)[:, 6:], hand_db.config_index,
                          num_vertices=80)
    rows = {r['estimate']: r for r in diagnose(lookup, frames, cam, index)}
    assert list(rows) == list(ESTIMATES)
    for key in ('image_nn', 'top1'):
        assert rows[key]['image_distance_px'] == 0.0 and rows[key]['is_image_nn'] == 1.0
    oracle = rows['oracle_pose']
    assert oracle['pose_distance_mm'] < 1e-3 and oracle['joint_mae_deg'] < 1e-3
    assert oracle['rotation_deg'] < 1e-3 and oracle['fingertip_rel_wrist_mm'] < 1e-3
    assert rows['oracle_fingers']['joint_mae_deg'] < 1e-3
    assert rows['blended']['joint_mae_deg'] > 0.1           # other neighbours mixed in
    cov = coverage(lookup, frames, cam, index)
    assert cov['view_rotation_nn_deg_max'] < 1e-3 and cov['finger_nn_mm_max'] < 1e-3
    assert cov['off_axis_deg_max'] < 1e-6 and cov['view_rotation_inside_db_range'] == 1.0
