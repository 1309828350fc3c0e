"""Tests for the lookup: candidate selection with ties, blending, translation, exact match."""
from __future__ import annotations

import numpy as np
import pytest
from label_samples import random_blob_images
from scipy.spatial.transform import Rotation
from small_databases import RENDER_CAM, blob_database, poses_on_axis

from colorglove_ros.core.camera import PinholeCamera
from colorglove_ros.core.lookup.blend import blend_poses, blend_weights
from colorglove_ros.core.lookup.distance import image_distance
from colorglove_ros.core.lookup.search import (
    PoseLookup,
    SearchError,
    estimate_global_pose,
    top_k_with_ties,
)


def _blob_images(seed: int, n: int) -> np.ndarray:
    return random_blob_images(np.random.default_rng(seed), n)


@pytest.fixture(scope='module')
def blob_db():
    rng = np.random.default_rng(0)
    base = _blob_images(0, 150)
    shifted = [np.roll(base, (dy, dx), axis=(1, 2)) for dy, dx in ((1, 0), (0, -1), (2, 1))]
    tiny = np.concatenate([base, *shifted])
    n = len(tiny)
    poses = poses_on_axis(rng.normal(0.0, 0.4, (n, 3)), rng.uniform(0.0, 1.0, (n, 20)))
    crop = np.tile([1.2, 40.0, 41.0], (n, 1))
    patch_vertex = np.full((n, 20), -1, np.int32)
    patch_vertex[:, :3] = [[11, 22, 33]]
    patch_xy = np.full((n, 20, 2), np.nan, np.float32)
    patch_xy[:, :3] = [[5.0, 6.0], [10.0, 12.0], [20.0, 30.0]]
    return blob_database(tiny, poses, crop, num_bits=64, num_pairs=600,
                         patch_vertex=patch_vertex, patch_xy=patch_xy,
                         patch_pixels=np.ones((n, 20)), patch_color=np.arange(1, 21) % 10 + 1)


def test_top_k_keeps_ties() -> None:
    values = np.array([5, 0, 1, 1, 1, 2, 7], np.uint16)
    assert sorted(top_k_with_ties(values, 2).tolist()) == [1, 2, 3, 4]
    assert sorted(top_k_with_ties(values, 1).tolist()) == [1]
    assert sorted(top_k_with_ties(values, 5).tolist()) == [1, 2, 3, 4, 5]
    assert len(top_k_with_ties(values, 50)) == 7
    rng = np.random.default_rng(0)
    for _ in range(20):
        v = rng.integers(0, 40, 5000).astype(np.uint16)
        k = int(rng.integers(1, 400))
        got = top_k_with_ties(v, k)
        cut = np.sort(v)[k - 1]
        np.testing.assert_array_equal(got, np.flatnonzero(v <= cut))
        np.testing.assert_array_equal(top_k_with_ties(v.astype(np.float64), k), got)


def test_top_k_uint8_and_misleading_sample() -> None:
    rng = np.random.default_rng(1)
    for _ in range(20):
        v = rng.integers(0, 192, 20_000).astype(np.uint8)
        k = int(rng.integers(1, 2000))
        np.testing.assert_array_equal(top_k_with_ties(v, k),
                                      np.flatnonzero(v <= np.sort(v)[k - 1]))
    # the strided sample sees only zeros: its guess keeps too few entries, full histogram
    v = np.full(5000, 200, np.uint8)
    v[::2] = 0
    v[1] = 7
    got = top_k_with_ties(v, 2501)
    np.testing.assert_array_equal(got, np.sort(np.concatenate([[1], np.arange(0, 5000, 2)])))
    assert len(top_k_with_ties(v, 2502)) == 5000          # ties at 200 all kept


def test_blend_weights() -> None:
    d = np.array([1.0, 2.0, 3.0])
    w = blend_weights(d)
    want = np.exp(-(d / 2.0) ** 2)
    np.testing.assert_allclose(w, want / want.sum())
    assert np.all(np.diff(w) < 0)
    np.testing.assert_allclose(blend_weights(np.zeros(4)), 0.25)


def test_blend_poses_rotation_and_fingers() -> None:
    rng = np.random.default_rng(1)
    poses = np.zeros((10, 26))
    center = Rotation.from_rotvec([0.4, -1.2, 2.5])
    poses[:, 3:6] = (center * Rotation.from_rotvec(rng.normal(0, 0.15, (10, 3)))).as_rotvec()
    poses[:, 6:] = rng.uniform(0, 1, (10, 20))
    w = blend_weights(rng.uniform(0.5, 3.0, 10))
    q = blend_poses(poses, w)
    np.testing.assert_allclose(q[6:], w @ poses[:, 6:])
    ref = Rotation.from_rotvec(poses[:, 3:6]).mean(weights=w)
    assert (Rotation.from_rotvec(q[3:6]) * ref.inv()).magnitude() < 1e-9
    # rotation vectors near pi flip sign; a naive mean would fail here
    flip = np.zeros((2, 26))
    flip[0, 3:6] = [0, 0, np.pi - 0.01]
    flip[1, 3:6] = [0, 0, -(np.pi - 0.01)]
    q = blend_poses(flip, np.array([0.5, 0.5]))
    assert abs(abs(q[5]) - np.pi) < 1e-6


def test_global_pose_from_crop() -> None:
    g_e = np.array([[0.02, -0.03, 0.5, 0.3, -0.2, 1.0]])
    crop_e = np.array([[1.1, 40.0, 35.0]])
    cam = PinholeCamera(128, 128, 150.0, 150.0, 63.5, 63.5)
    np.testing.assert_allclose(
        estimate_global_pose(g_e, crop_e, RENDER_CAM, (1.1, 40.0, 35.0), cam), g_e, atol=1e-12)
    # the hand twice as far away looks half as big: same tiny image, half the crop scale
    big = PinholeCamera(640, 480, 600.0, 600.0, 320.0, 240.0)
    g = estimate_global_pose(g_e, crop_e, RENDER_CAM, (0.55 * 4.0, 100.0, 80.0), big)[0]
    assert np.linalg.norm(g[:3]) == pytest.approx(np.linalg.norm(g_e[0, :3]) * 2.0)
    # the wrist projects to the same tiny-image position in both crops
    u_e = 150.0 * g_e[0, 0] / g_e[0, 2] + 63.5
    tiny_x = (u_e - 40.0) / 1.1
    assert 600.0 * g[0] / g[2] + 320.0 == pytest.approx(100.0 + 2.2 * tiny_x)


@pytest.mark.parametrize('anchor', [None, np.array([0.01, -0.09, 0.004])])
def test_global_pose_anchor_keeps_pixel_and_range(anchor) -> None:
    """An entry rendered on the optical axis, placed off-axis: the anchor lies on the ray
    through its mapped tiny-image pixel at the range (not the depth) scaled by apparent
    size, and the rotation and the anchor's offset from the wrist are the entry's."""
    rng = np.random.default_rng(3)
    rv = Rotation.from_rotvec(rng.normal(0.0, 1.0, (6, 3)))
    local = np.zeros(3) if anchor is None else anchor
    g_e = np.zeros((6, 6))
    g_e[:, 3:6] = rv.as_rotvec()
    g_e[:, 0:3] = np.array([0.0, 0.0, 0.5]) - rv.apply(local)        # anchor on the axis
    crop_e = np.tile([0.6, 44.0, 52.0], (6, 1))
    cam = PinholeCamera(640, 480, 600.0, 600.0, 319.5, 239.5)
    tiny = (np.array([63.5, 63.5]) - [44.0, 52.0]) / 0.6              # the anchor's pixel
    for crop in [(2.0, 30.0, 20.0), (3.0, 500.0, 380.0), (2.5, 300.0, 200.0)]:
        g = estimate_global_pose(g_e, crop_e, RENDER_CAM, crop, cam, anchor)
        np.testing.assert_allclose(g[:, 3:6], g_e[:, 3:6])
        a_q = g[:, 0:3] + rv.apply(local)
        np.testing.assert_allclose(np.linalg.norm(a_q, axis=1),
                                   0.5 * (600.0 / 150.0) * 0.6 / crop[0], rtol=1e-12)
        np.testing.assert_allclose(a_q[:, :2] / a_q[:, 2:] * 600.0 + [319.5, 239.5],
                                   np.tile(np.array(crop[1:]) + crop[0] * tiny, (6, 1)))


def test_lookup_finds_exact_entry(blob_db) -> None:
    lookup = PoseLookup(blob_db, num_candidates=60, num_blend=10)
    cam = PinholeCamera(640, 480, 600.0, 600.0, 320.0, 240.0)
    for entry in (0, 37, 151, 420):
        res = lookup.lookup(blob_db.tiny[entry], (1.2, 40.0, 41.0), cam)
        assert res.indices[0] == entry
        assert res.distances[0] == 0.0
        assert np.argmax(res.weights) == 0
        assert res.weights.sum() == pytest.approx(1.0)
        assert np.all(np.diff(res.distances) >= 0)
        assert res.num_candidates >= 60
        # re-ranked distances are the exact distance (uint8 storage: within 0.125 px)
        for i, d in zip(res.indices[:3], res.distances[:3], strict=True):
            assert abs(d - image_distance(blob_db.tiny[entry], blob_db.tiny[i])) <= 0.125
        np.testing.assert_array_equal(res.constraints.vertices, [11, 22, 33])
        np.testing.assert_allclose(res.constraints.full_xy[1], [40.0 + 12.0, 41.0 + 14.4])
        assert set(res.timings_ms) >= {'hamming_ms', 'rerank_ms', 'blend_ms', 'total_ms'}
    # a shifted copy of an entry finds an entry of the same base image among the first few
    res = lookup.lookup(np.roll(blob_db.tiny[3], (1, 1), axis=(0, 1)), (1.2, 40.0, 41.0), cam)
    assert {3, 153, 303, 453} & set(res.indices[:4].tolist())


def test_hamming_scan_matches_naive(blob_db) -> None:
    lookup = PoseLookup(blob_db)
    ham = lookup.hamming(blob_db.tiny[9])
    codes = np.ascontiguousarray(blob_db.codes.T)
    bits = np.unpackbits(codes.view(np.uint8), axis=1, bitorder='little')
    np.testing.assert_array_equal(ham, (bits != bits[9]).sum(axis=1))


def test_lookup_rejects_empty_query(blob_db) -> None:
    lookup = PoseLookup(blob_db)
    cam = PinholeCamera(640, 480, 600.0, 600.0, 320.0, 240.0)
    with pytest.raises(SearchError):
        lookup.lookup(np.zeros((40, 40), np.uint8), (1.0, 0.0, 0.0), cam)
    with pytest.raises(SearchError):
        lookup.lookup(blob_db.tiny[0], (0.0, 0.0, 0.0), cam)


def test_lookup_poses_match_estimate_global_pose(blob_db) -> None:
    """The precomputed per-entry terms give the same global poses as the public function,
    with and without lens distortion and with the hand-centre anchor."""
    lookup = PoseLookup(blob_db, num_candidates=60, num_blend=10)
    from colorglove_ros.core.lookup.search import _entry_place_terms

    lookup._anchor = np.array([0.01, -0.09, 0.004])
    lookup._place_table = _entry_place_terms(lookup._a['poses'][:, 0:6], lookup._a['crop'],
                                             blob_db.render_camera, lookup._anchor)
    for dist in (np.zeros(5), np.array([0.1, -0.05, 0.001, 0.002, 0.0])):
        cam = PinholeCamera(640, 480, 520.0, 515.0, 320.0, 240.0, distortion=dist)
        crop = (2.5, 100.0, 60.0)
        res = lookup.lookup(blob_db.tiny[7], crop, cam)
        idx = res.indices
        want = estimate_global_pose(lookup._a['poses'][idx, 0:6], lookup._a['crop'][idx],
                                    blob_db.render_camera, crop, cam, lookup._anchor)
        np.testing.assert_allclose(res.poses[:, 0:6], want, rtol=1e-9, atol=1e-12)
        np.testing.assert_allclose(res.poses[:, 6:], lookup._a['poses'][idx, 6:])
        assert np.ptp(want[:, 0]) > 1e-3                   # the rotated anchors differ


def test_a_search_blended_is_the_lookup(blob_db) -> None:
    """``search`` then ``blend`` give what ``lookup`` gives (the two-hand layer blends only the
    lookups a hand is tracked from); the search's nearest distance is the result's first, and
    ``core.pipeline``'s ``search`` and ``blend`` refuse a far match as ``look_up`` does."""
    from colorglove_ros.core.pipeline import NoHand, StageLimits, blend, look_up, search
    from colorglove_ros.core.segmentation.crop import CropTransform, TinyCrop

    lookup = PoseLookup(blob_db, num_candidates=60, num_blend=10)
    cam = PinholeCamera(640, 480, 600.0, 600.0, 320.0, 240.0)
    crop = (1.2, 40.0, 41.0)
    shifted = np.roll(blob_db.tiny[3], (1, 1), axis=(0, 1))
    for tiny in (blob_db.tiny[37], shifted):
        whole = lookup.lookup(tiny, crop, cam)
        found = lookup.search(tiny, crop)
        assert found.nearest == whole.distances[0]
        parts = lookup.blend(found, cam)
        for name in ('indices', 'distances', 'weights', 'poses', 'blended'):
            np.testing.assert_array_equal(getattr(parts, name), getattr(whole, name))
        np.testing.assert_array_equal(parts.constraints.full_xy, whole.constraints.full_xy)
        assert parts.num_candidates == whole.num_candidates
        query = TinyCrop(tiny, CropTransform(*crop))
        for limit in (np.inf, 0.5 * whole.distances[0]):
            limits = StageLimits(max_image_distance=limit)
            one, two = look_up(lookup, query, cam, None, limits), blend(
                lookup, search(lookup, query), cam, None, limits)
            assert isinstance(one, NoHand) == isinstance(two, NoHand) == (limit < np.inf
                                                                          and limit > 0)
            if isinstance(one, NoHand):
                assert one.reason == two.reason
    assert isinstance(search(lookup, TinyCrop(np.zeros((40, 40), np.uint8),
                                              CropTransform(*crop))), NoHand)
