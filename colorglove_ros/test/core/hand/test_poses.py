"""Tests for the natural pose collection, orientation sampling and the pose distance."""
from __future__ import annotations

import numpy as np
import pytest

from colorglove_ros.core.geometry import matrix_to_rotvec, rotvec_to_matrix
from colorglove_ros.core.hand.model import FINGER_DOF_NAMES
from colorglove_ros.core.hand.poses import (
    GESTURE_SHAPES,
    LETTER_SHAPES,
    NAMED_SHAPES,
    PINCH_SHAPES,
    PosesError,
    full_pose,
    named_neighbourhood_rows,
    pose_collection,
    pose_distance,
    pose_features,
    sample_global_rotations,
)


@pytest.fixture(scope='module')
def collection() -> np.ndarray:
    return pose_collection(seed=0)


def test_named_shapes(hand) -> None:
    model, _, _ = hand
    assert set(LETTER_SHAPES) == set('ABCDEFGHIJKLMNOPQRSTUVWXYZ')
    for k in ('fist', 'flat', 'point', 'pinch', 'ok', 'thumbs_up', 'victory', 'rock',
              'call_me', 'claw'):
        assert k in GESTURE_SHAPES
    lo, hi = model.lower_limits[6:], model.upper_limits[6:]
    for name, f in NAMED_SHAPES.items():
        assert f.shape == (20,), name
        assert np.all(f >= lo - 1e-12) and np.all(f <= hi + 1e-12), name
    # a fist curls every finger far more than the flat hand
    idx = [FINGER_DOF_NAMES.index(f'{d}_pip_flex') for d in ('index', 'middle', 'ring', 'little')]
    assert np.all(NAMED_SHAPES['fist'][idx] > 1.5) and np.all(NAMED_SHAPES['flat'][idx] == 0)


def test_collection_size_limits_determinism(hand, collection: np.ndarray) -> None:
    model, _, _ = hand
    assert collection.shape == (18000, 20)
    lo, hi = model.lower_limits[6:], model.upper_limits[6:]
    assert np.all(collection >= lo) and np.all(collection <= hi)
    assert np.array_equal(collection, pose_collection(seed=0))
    other = pose_collection(seed=1, size=500)
    assert other.shape == (500, 20) and not np.array_equal(other, collection[:500][::-1])
    assert not np.array_equal(other[100:], pose_collection(seed=2, size=500)[100:])
    # the named shapes come first, and the rows are diverse
    assert np.allclose(collection[:len(NAMED_SHAPES)], np.stack(list(NAMED_SHAPES.values())))
    assert len(np.unique(np.round(collection, 6), axis=0)) > 17900
    # every DOF uses a good part of its range
    span = collection.max(0) - collection.min(0)
    assert np.all(span > 0.6 * (hi - lo))


def test_named_neighbourhood_rows(collection: np.ndarray) -> None:
    rows = named_neighbourhood_rows(len(collection))
    named = np.stack(list(NAMED_SHAPES.values()))
    # every leading row is a named shape with 5 deg noise (largest DOF deviation from the
    # nearest named shape: about 2 sigma typically, below 5 sigma always); the rows after are
    # transitions between two shapes, farther from both
    def nearest(rows_: np.ndarray) -> np.ndarray:
        return np.degrees(np.abs(rows_[:, None] - named[None]).max(axis=2).min(axis=1))
    assert np.all(nearest(collection[:rows]) < 25.0)
    assert np.median(nearest(collection[:rows])) < 12.0
    assert np.median(nearest(collection[rows:rows + 500])) > 15.0
    assert rows == len(NAMED_SHAPES) + (18000 - len(NAMED_SHAPES)) // 4
    with pytest.raises(PosesError):
        named_neighbourhood_rows(len(NAMED_SHAPES) - 1)


def test_pinch_shapes_put_the_thumb_on_one_fingertip(hand) -> None:
    """Each pinch shape's thumb tip is near its finger's tip (the gesture evaluation's pinch
    range, 4-9 % of the hand length) and far from the others; the collection holds them only
    when asked, and is otherwise the same."""
    from colorglove_ros.core.hand.gestures import PINCH_FINGERS, gesture_features

    model, _, _ = hand
    assert len(PINCH_SHAPES) == 9 and not set(PINCH_SHAPES) & set(NAMED_SHAPES)
    for name, f in PINCH_SHAPES.items():
        finger = PINCH_FINGERS.index(name.split('_')[1])
        d = gesture_features(model, full_pose(model, f)).pinch_distance
        assert 0.04 < d[finger] < 0.09, name
        assert np.delete(d, finger).min() > 0.25, name
    plain = pose_collection(seed=0, size=600)
    with_pinches = pose_collection(seed=0, size=600, pinch_shapes=True)
    assert np.array_equal(plain, pose_collection(seed=0, size=600, pinch_shapes=False))
    k = len(NAMED_SHAPES)
    assert np.allclose(with_pinches[k:k + len(PINCH_SHAPES)],
                       np.stack(list(PINCH_SHAPES.values())))
    assert not any(np.isclose(plain, f, atol=1e-6).all(axis=1).any()
                   for f in PINCH_SHAPES.values())
    assert named_neighbourhood_rows(600, pinch_shapes=True) == \
        k + len(PINCH_SHAPES) + (600 - k - len(PINCH_SHAPES)) // 4


def test_dip_pip_coupling(collection: np.ndarray) -> None:
    for d in ('index', 'middle', 'ring', 'little'):
        pip = collection[:, FINGER_DOF_NAMES.index(f'{d}_pip_flex')]
        dip = collection[:, FINGER_DOF_NAMES.index(f'{d}_dip_flex')]
        slope = np.polyfit(pip, dip, 1)[0]
        assert 0.5 < slope < 0.85
        assert np.corrcoef(pip, dip)[0, 1] > 0.9
    with pytest.raises(PosesError):
        pose_collection(size=10)


def test_global_rotation_range() -> None:
    rng = np.random.default_rng(0)
    r = sample_global_rotations(rng, 4000)
    assert r.shape == (4000, 3)
    R = rotvec_to_matrix(r)
    fingers_dir = R @ np.array([0.0, -1.0, 0.0])   # hand -y in the camera frame
    palm_normal = R @ np.array([0.0, 0.0, -1.0])   # palm faces hand -z
    # palm always toward the camera (camera looks along +z)
    assert np.all(palm_normal[:, 2] < 0.0)
    # fingers point up in the image up to the +-90 deg roll (at most 0.62 = sin60 sin45 down)
    assert np.all(fingers_dir[:, 1] < 0.62) and fingers_dir[:, 1].mean() < -0.5
    # angles stay below pi, so rotation vectors are continuous in the range
    assert np.linalg.norm(r, axis=1).max() < np.pi - 0.3
    roll = np.arctan2(fingers_dir[:, 0], -fingers_dir[:, 1])
    assert roll.min() < -1.3 and roll.max() > 1.3
    assert np.allclose(matrix_to_rotvec(R), r, atol=1e-9)
    back = sample_global_rotations(np.random.default_rng(0), 1000, back_fraction=1.0)
    assert np.all((rotvec_to_matrix(back) @ np.array([0.0, 0.0, -1.0]))[:, 2] > 0.0)


def test_pose_distance(hand, collection: np.ndarray) -> None:
    model, mesh, _ = hand
    flat, fist = NAMED_SHAPES['flat'], NAMED_SHAPES['fist']
    assert pose_distance(mesh, model, flat, flat) == pytest.approx(0.0, abs=1e-7)
    d = pose_distance(mesh, model, flat, fist)
    # direct RMS over all vertices with the global pose fixed
    va = mesh.skin(model, full_pose(model, flat))
    vb = mesh.skin(model, full_pose(model, fist))
    ref = np.sqrt(np.mean(np.sum((va - vb) ** 2, axis=1)))
    assert d == pytest.approx(ref, rel=1e-5)
    assert 0.02 < d < 0.08  # a few centimetres
    many = pose_distance(mesh, model, flat, collection[:300], chunk=128)
    assert many.shape == (300,)
    assert np.allclose(many[[0, 1, 2]],
                       [pose_distance(mesh, model, flat, collection[i]) for i in range(3)],
                       rtol=1e-5)
    fa = pose_features(mesh, model, collection[:50])
    dist = np.linalg.norm(fa[:, None] - fa[None], axis=2)
    assert np.allclose(dist[0], pose_distance(mesh, model, collection[0], collection[:50]),
                       atol=1e-6)
    # symmetric and triangle inequality on a sample
    assert np.allclose(dist, dist.T, atol=1e-7)
    assert np.all(dist[0][:, None] <= dist[0][None, :] + dist + 1e-6)


def test_subsampled_features_approximate(hand, collection: np.ndarray) -> None:
    model, mesh, _ = hand
    sample = collection[::97]
    exact = pose_features(mesh, model, sample)
    approx = pose_features(mesh, model, sample, max_vertices=300)
    assert approx.shape == (len(sample), 900)
    de = np.linalg.norm(exact[:, None] - exact[None], axis=2)
    da = np.linalg.norm(approx[:, None] - approx[None], axis=2)
    off = ~np.eye(len(sample), dtype=bool)
    rel = np.abs(da[off] - de[off]) / de[off]
    assert np.median(rel) < 0.05 and np.corrcoef(da[off], de[off])[0, 1] > 0.99
