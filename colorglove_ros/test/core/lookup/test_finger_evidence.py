"""Tests for the per-finger blend of the lookup's neighbours (core.lookup.finger_evidence) and its
use by the lookup, the IK covariances and the candidates message."""
from __future__ import annotations

import numpy as np
import pytest
from blend_reference import blend_reference
from small_databases import blob_database, poses_on_axis

from colorglove_ros.core.camera import PinholeCamera
from colorglove_ros.core.lookup.finger_evidence import (
    PALM_DIGIT,
    FingerEvidenceConfig,
    FingerEvidenceError,
    finger_blend,
    finger_scores,
    patch_digits,
)
from colorglove_ros.core.lookup.search import PoseLookup
from colorglove_ros.core.tracking.config import IKConfig
from colorglove_ros.core.tracking.types import IKError, PosePrior

CONFIG = FingerEvidenceConfig()


def test_patch_digits_from_vertex_links() -> None:
    vertex_link = np.array([0, 1, 3, 4, 13, 15])      # palm, thumb x2, index, little x2
    patch_vertex = np.array([[0, 1, 2, -1], [3, 4, 5, 0]])
    np.testing.assert_array_equal(patch_digits(patch_vertex, vertex_link),
                                  [[PALM_DIGIT, 0, 0, -1], [1, 4, 4, PALM_DIGIT]])
    with pytest.raises(FingerEvidenceError):
        patch_digits(np.array([[6]]), vertex_link)


def _two_entries():
    """Two entries with four patches: patch 0 on the thumb, 1 on the index, 2 and 3 on the
    palm. Entry 0 places the thumb patch on its blob, entry 1 the index patch."""
    digit = np.array([[0, 1, PALM_DIGIT, PALM_DIGIT]] * 2)
    color = np.array([1, 2, 3, 4])
    blob_xy = np.array([[5.0, 5.0], [20.0, 10.0], [30.0, 30.0]])
    xy = np.array([[[5.0, 5.0], [23.0, 10.0], [30.0, 30.0], [0.0, 0.0]],
                   [[8.0, 5.0], [20.0, 10.0], [30.0, 30.0], [0.0, 0.0]]])
    pixels = np.full((2, 4), 10.0)
    return xy, pixels, digit, color, np.array([1, 2, 3]), blob_xy, np.full(3, 10.0)


def test_scores_measure_each_finger_on_its_own_patches() -> None:
    s = finger_scores(*_two_entries(), CONFIG)
    assert s.shape == (2, 5)
    assert s[0, 0] == pytest.approx(0.0) and s[0, 1] == pytest.approx(3.0)
    assert s[1, 0] == pytest.approx(3.0) and s[1, 1] == pytest.approx(0.0)
    # middle, ring, little: no visible patch -> the cap
    np.testing.assert_allclose(s[:, 2:], CONFIG.cap_tiny_px)


@pytest.mark.parametrize('broken', ['xy_one_coordinate', 'xy_flat', 'areas_short'])
def test_scores_refuse_arrays_the_compiled_loop_would_read_past(broken: str) -> None:
    """Centroids without two coordinates, or fewer blob areas than blobs: a clear error."""
    xy, pixels, digit, color, bcol, bxy, bpix = _two_entries()
    if broken == 'xy_one_coordinate':
        xy = xy[..., :1]
    elif broken == 'xy_flat':
        xy = xy.reshape(2, -1)
    else:
        bpix = bpix[:2]
    with pytest.raises(FingerEvidenceError):
        finger_scores(xy, pixels, digit, color, bcol, bxy, bpix, CONFIG)


def test_area_mismatch_and_missing_colour_cost() -> None:
    xy, pixels, digit, color, bcol, bxy, bpix = _two_entries()
    s0 = finger_scores(xy, pixels, digit, color, bcol, bxy, bpix, CONFIG)
    bigger = bpix.copy()
    bigger[0] = 30.0                                   # thumb blob three times the area
    s1 = finger_scores(xy, pixels, digit, color, bcol, bxy, bigger, CONFIG)
    assert s1[0, 0] == pytest.approx(min(CONFIG.cap_tiny_px,
                                         CONFIG.area_weight * abs(np.log(11 / 31))))
    assert s1[0, 1] == pytest.approx(s0[0, 1])
    # no blob of the thumb patch's colour: the thumb's residual is the cap
    s2 = finger_scores(xy, pixels, digit, color, bcol[1:], bxy[1:], bpix[1:], CONFIG)
    np.testing.assert_allclose(s2[:, 0], CONFIG.cap_tiny_px)
    # no blobs at all: every finger at the cap
    empty = finger_scores(xy, pixels, digit, color, np.zeros(0, int), np.zeros((0, 2)),
                          np.zeros(0), CONFIG)
    np.testing.assert_allclose(empty, CONFIG.cap_tiny_px)


def _reference_scores(xy, pixels, digit, color, bcol, bxy, bpix, config) -> np.ndarray:
    """finger_scores written out patch by patch (each patch against every same-colour blob,
    the first of equal distances winning; its digit's mean residual)."""
    cap = config.cap_tiny_px
    scores = np.full((len(xy), 5), cap)
    for k in range(len(xy)):
        residual = np.full(len(color), cap)
        for p in range(len(color)):
            best = None
            for b in range(len(bcol)):
                d = np.hypot(*(xy[k, p] - bxy[b]))
                if bcol[b] == color[p] and (best is None or d < best[0]):
                    best = (d, b)
            if best is not None and np.isfinite(best[0]):
                term = abs(np.log((pixels[k, p] + 1.0) / (bpix[best[1]] + 1.0)))
                residual[p] = min(cap, best[0] + config.area_weight * term)
        for g in range(5):
            if (digit[k] == g).any():
                scores[k, g] = residual[digit[k] == g].mean()
    return scores


@pytest.mark.parametrize('seed', range(6))
def test_scores_match_a_patch_by_patch_reference(seed: int) -> None:
    """Against every blob of the patch's colour only, ties and hidden (NaN) patches
    included."""
    rng = np.random.default_rng(seed)
    k, p, b = 7, 20, int(rng.integers(1, 25))
    xy = np.round(rng.uniform(0, 40, (k, p, 2)))           # integer grid: equal distances
    xy[rng.random((k, p)) < 0.1] = np.nan
    args = (xy, rng.uniform(0, 50, (k, p)), rng.integers(-1, 6, (k, p)),
            rng.integers(1, 11, p), rng.integers(1, 11, b), np.round(rng.uniform(0, 40, (b, 2))),
            rng.uniform(1, 80, b))
    np.testing.assert_allclose(finger_scores(*args, CONFIG),
                               _reference_scores(*args, CONFIG), rtol=1e-12, atol=1e-12)


def test_scores_take_the_first_of_equally_near_blobs() -> None:
    """Two blobs of the patch's colour at the same distance: the first one's area counts."""
    xy, pixels, digit = np.array([[[10.0, 10.0]]]), np.array([[10.0]]), np.array([[1]])
    bxy = np.array([[13.0, 10.0], [0.0, 0.0], [7.0, 10.0]])       # blobs 0 and 2: 3 px away
    config = FingerEvidenceConfig(area_weight=0.5)
    for areas in ([10.0, 5.0, 30.0], [30.0, 5.0, 10.0]):
        s = finger_scores(xy, pixels, digit, np.array([2]), np.array([2, 1, 2]), bxy,
                          np.array(areas), config)
        assert s[0, 1] == pytest.approx(3.0 + 0.5 * abs(np.log(11.0 / (areas[0] + 1.0))))


def test_blend_takes_each_finger_from_the_entry_that_explains_it() -> None:
    poses = np.zeros((2, 26))
    poses[0, 6:10], poses[1, 6:10] = 0.2, 1.0         # thumb
    poses[0, 10:14], poses[1, 10:14] = 0.9, 0.1       # index
    poses[:, 14:] = 0.5
    fingers, spread, seen = finger_blend(poses, finger_scores(*_two_entries(), CONFIG), CONFIG)
    assert fingers.shape == spread.shape == (20,)
    np.testing.assert_array_equal(seen, [True, True, False, False, False])
    np.testing.assert_allclose(fingers[0:4], 0.2, atol=1e-3)      # thumb from entry 0
    np.testing.assert_allclose(fingers[4:8], 0.1, atol=1e-3)      # index from entry 1
    np.testing.assert_allclose(fingers[8:], 0.5)
    assert np.all(spread[:8] < 0.01) and np.allclose(spread[8:], 0.0)
    # equal evidence: plain mean and the full spread
    f, sd, _ = finger_blend(poses, np.zeros((2, 5)), CONFIG)
    np.testing.assert_allclose(f[0:4], 0.6)
    np.testing.assert_allclose(sd[0:4], 0.4)
    with pytest.raises(FingerEvidenceError):
        finger_blend(poses, np.zeros((3, 5)), CONFIG)


def test_prior_covariances_follow_the_spread() -> None:
    cfg = IKConfig(finger_spread_gain=1.0, finger_spread_floor_rad=0.1)
    spread = np.full(20, 0.05)
    spread[3] = 0.4
    cov = cfg.prior_covariances(spread)
    np.testing.assert_allclose(cov.q_var[6:9], 0.01)
    assert cov.q_var[9] == pytest.approx(0.16)
    np.testing.assert_array_equal(cov.q_var[:6], cfg.covariances.q_var[:6])
    off = IKConfig(finger_spread_gain=0.0)
    np.testing.assert_array_equal(off.prior_covariances(spread).q_var, off.covariances.q_var)
    np.testing.assert_array_equal(cfg.prior_covariances(None).q_var, cfg.covariances.q_var)
    with pytest.raises(IKError):
        cfg.prior_covariances(np.full(19, 0.1))


class _Blobs:
    def __init__(self, color, xy, pixels):
        self.color, self.centroid_px, self.pixel_count = color, xy, pixels


def test_lookup_blends_fingers_from_blobs() -> None:
    """Two entries with the same image: entry 0 is the nearest (ties go to the lower index)
    and the only one blended (num_blend 1); entry 1, among the 2 the fingers are chosen from,
    has its thumb patch on the observed blob. The thumb comes from entry 1, with entry 1's
    thumb patches as constraints (none of entry 0's); fingers without evidence keep the
    image-weighted blend."""
    rng = np.random.default_rng(3)
    n = 40
    tiny = np.zeros((n, 40, 40), np.uint8)
    for i in range(n):
        y, x = rng.integers(5, 30, 2)
        tiny[i, y:y + 8, x:x + 8] = 1 + i % 10
    tiny[1] = tiny[0]
    poses = poses_on_axis(fingers=rng.uniform(0.0, 1.0, (n, 20)))
    patch_vertex = np.full((n, 20), -1, np.int32)
    patch_vertex[:, 0] = 1                            # vertex 1: on the thumb
    patch_vertex[:, 1] = 0                            # vertex 0: on the palm
    patch_vertex[0, 2] = 1                            # entry 0 also shows thumb patch 2
    patch_xy = np.full((n, 20, 2), np.nan, np.float32)
    patch_xy[:, 0] = [30.0, 30.0]
    patch_xy[:, 1] = [20.0, 20.0]
    patch_xy[0, 0] = [10.0, 10.0]
    patch_xy[0, 2] = [25.0, 25.0]
    patch_xy[1, 0] = [13.0, 10.0]                     # entry 1: thumb patch at (13, 10)
    color = np.arange(20) % 10 + 1
    db = blob_database(tiny, poses, num_bits=32, num_pairs=200, patch_vertex=patch_vertex,
                       patch_xy=patch_xy, patch_pixels=np.full((n, 20), 5.0), patch_color=color)
    lookup = PoseLookup(db, num_candidates=n, num_blend=1, threads=1,
                        finger_evidence=FingerEvidenceConfig(num_neighbours=2),
                        vertex_link=np.array([0, 1, 2]))
    cam = PinholeCamera(640, 480, 600.0, 600.0, 320.0, 240.0)
    crop = (2.0, 100.0, 50.0)
    plain = lookup.lookup(tiny[0], crop, cam)
    assert plain.finger_std is None
    assert plain.indices.tolist() == [0]
    np.testing.assert_allclose(plain.constraints.tiny_xy,
                               [[10.0, 10.0], [20.0, 20.0], [25.0, 25.0]])
    blobs = _Blobs(np.array([color[0]]), np.array([[100.0 + 2.0 * 13.0, 50.0 + 2.0 * 10.0]]),
                   np.array([5.0 * 4.0]))
    res = lookup.lookup(tiny[0], crop, cam, blobs)
    np.testing.assert_array_equal(res.indices, plain.indices)
    np.testing.assert_allclose(res.blended[6:10], poses[1, 6:10], atol=1e-3)
    # no evidence for the other fingers: the image-weighted blend (here entry 0 alone)
    np.testing.assert_allclose(res.blended[10:], plain.blended[10:])
    np.testing.assert_allclose(res.finger_std[4:], 0.0)
    assert res.finger_std.shape == (20,)
    np.testing.assert_array_equal(res.blended[:6], plain.blended[:6])
    # the thumb's constraints are entry 1's (its patch 0; entry 0's thumb patch 2 dropped),
    # the palm patch the nearest entry's
    np.testing.assert_array_equal(res.constraints.patch_ids, [0, 1])
    np.testing.assert_allclose(res.constraints.tiny_xy, [[13.0, 10.0], [20.0, 20.0]])
    np.testing.assert_allclose(res.constraints.full_xy[0], [126.0, 70.0])
    prior = PosePrior.from_lookup(res)
    np.testing.assert_array_equal(prior.finger_std, res.finger_std)
    # no blobs at all, or only unusable ones: no evidence, the paper's blend
    for empty in (_Blobs(np.zeros(0, int), np.zeros((0, 2)), np.zeros(0)),
                  _Blobs(np.array([1]), np.array([[np.nan, 1.0]]), np.array([5.0]))):
        none = lookup.lookup(tiny[0], crop, cam, empty)
        assert none.finger_std is None
        np.testing.assert_array_equal(none.blended, plain.blended)


def test_candidates_message_carries_the_spread() -> None:
    from colorglove_msgs.msg import HandObservation

    from colorglove_ros.core.lookup.types import LookupResult, ProjectionConstraints
    from colorglove_ros.ros.conversions import candidates_to_msg, pose_prior_from_candidates_msg

    cons = ProjectionConstraints(np.array([0]), np.array([1]), np.array([5]),
                                 np.array([[3.0, 4.0]]), np.array([6.0]),
                                 full_xy=np.array([[10.0, 12.0]]))
    spread = np.linspace(0.01, 0.2, 20)
    result = LookupResult(np.array([7]), np.array([0.5]), np.array([1.0]), np.zeros((1, 26)),
                          np.zeros(26), cons, 1, finger_std=spread)
    msg = candidates_to_msg(HandObservation(hand_found=True), result)
    np.testing.assert_allclose(pose_prior_from_candidates_msg(msg).finger_std, spread)
    plain = candidates_to_msg(HandObservation(hand_found=True),
                           LookupResult(np.array([7]), np.array([0.5]), np.array([1.0]),
                                        np.zeros((1, 26)), np.zeros(26), cons, 1))
    assert pose_prior_from_candidates_msg(plain).finger_std is None
    msg.finger_std = [0.1] * 19
    with pytest.raises(ValueError):
        pose_prior_from_candidates_msg(msg)


def _random_patch_database(seed: int, n: int = 60, vertex_limit: int = 3):
    """A database whose entries show random patches on vertices 0..vertex_limit - 1
    (-1: hidden) and the (palm, thumb, index) vertex -> link table of three vertices."""
    rng = np.random.default_rng(seed)
    tiny = np.zeros((n, 40, 40), np.uint8)
    for i in range(n):
        y, x = rng.integers(5, 30, 2)
        tiny[i, y:y + 8, x:x + 8] = 1 + i % 10
    patch_vertex = rng.integers(-1, vertex_limit, (n, 20)).astype(np.int32)
    patch_xy = rng.uniform(0.0, 40.0, (n, 20, 2)).astype(np.float32)
    db = blob_database(tiny, poses_on_axis(fingers=rng.uniform(0.0, 1.0, (n, 20))),
                       num_bits=32, num_pairs=200, patch_vertex=patch_vertex,
                       patch_xy=patch_xy, patch_pixels=rng.uniform(1.0, 9.0, (n, 20)),
                       patch_color=np.arange(20) % 10 + 1)
    return db, tiny, rng


def test_lookup_takes_patch_digits_from_its_table(monkeypatch: pytest.MonkeyPatch) -> None:
    """The entries' patch digits are computed once when the lookup is made (equal to
    ``patch_digits`` on the whole database) and no lookup computes them again; the lookups'
    results are those of a lookup that computes them per call (``patch_digits`` of the
    chosen rows, as before)."""
    from colorglove_ros.core.lookup import search

    link = np.array([0, 1, 4])
    db, tiny, rng = _random_patch_database(5)
    calls = []
    real = search.patch_digits
    monkeypatch.setattr(search, 'patch_digits', lambda *a: calls.append(1) or real(*a))
    lookup = PoseLookup(db, num_candidates=12, num_blend=3, threads=1,
                        finger_evidence=FingerEvidenceConfig(num_neighbours=6), vertex_link=link)
    made = len(calls)
    np.testing.assert_array_equal(lookup._patch_digit, patch_digits(db.patch_vertex, link))
    assert lookup._patch_digit.dtype == np.int8
    cam = PinholeCamera(640, 480, 600.0, 600.0, 320.0, 240.0)
    crop = (2.0, 100.0, 50.0)
    queries = []
    for i in range(8):
        blobs = _Blobs(rng.integers(1, 11, 6), rng.uniform(100.0, 180.0, (6, 2)),
                       rng.uniform(4.0, 40.0, 6))
        queries.append((tiny[i], blobs))
    got = [lookup.lookup(t, crop, cam, b) for t, b in queries]
    assert len(calls) == made                           # none per lookup
    # the reference: numpy's blend with a table that is patch_digits of the rows asked for,
    # per call
    monkeypatch.setattr(lookup, '_patch_digit', _RowsPerCall(db.patch_vertex, link, real))
    for a, (t, b) in zip(got, queries, strict=True):
        assert a.finger_std is not None
        want = blend_reference(lookup, lookup.search(t, crop), cam, b)
        for name in ('indices', 'blended', 'finger_std', 'poses', 'weights'):
            np.testing.assert_array_equal(getattr(a, name), want[name])
        for name in ('patch_ids', 'colors', 'vertices', 'tiny_xy', 'pixel_counts', 'full_xy'):
            np.testing.assert_array_equal(getattr(a.constraints, name),
                                          want[f'constraints.{name}'])


class _RowsPerCall:
    """``patch_digits`` of the rows an index asks for, computed at each indexing."""

    def __init__(self, patch_vertex, link, digits) -> None:
        self._pv, self._link, self._digits = np.asarray(patch_vertex), link, digits

    def __getitem__(self, rows):
        return self._digits(self._pv[rows], self._link)


def test_lookup_refuses_a_patch_vertex_beyond_the_mesh_when_made() -> None:
    """A database entry whose patch vertex lies beyond the vertex -> link table is refused
    when the lookup is made, not at the first lookup that blends that entry."""
    from colorglove_ros.core.lookup.search import SearchError

    db, _, _ = _random_patch_database(6, vertex_limit=4)    # vertex 3: beyond a 3-vertex table
    with pytest.raises(SearchError, match='beyond the mesh'):
        PoseLookup(db, num_candidates=12, threads=1, vertex_link=np.array([0, 1, 4]))
