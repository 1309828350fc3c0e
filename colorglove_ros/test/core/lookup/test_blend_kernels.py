"""The lookup blend's compiled steps (core.lookup.lookup_kernel: the per-finger residuals and
means, the weighted finger moments, the projection constraints' patches, the wrists on the
query's rays) against numpy's code (test/blend_reference.py): the same bits."""
from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest
from blend_reference import (
    blend_reference,
    blend_weights_reference,
    constraints_reference,
    finger_blend_reference,
    finger_scores_reference,
    place_wrists_reference,
    weighted_fingers_reference,
)

from colorglove_ros.core.camera import PinholeCamera
from colorglove_ros.core.lookup import lookup_kernel
from colorglove_ros.core.lookup.blend import blend_weights
from colorglove_ros.core.lookup.finger_evidence import (
    FingerEvidenceConfig,
    finger_blend,
    finger_scores,
    weighted_fingers,
)
from colorglove_ros.core.lookup.search import PoseLookup, _place_wrists
from colorglove_ros.core.segmentation.crop import tiny_to_full


@pytest.fixture(scope='module', autouse=True)
def _compiled() -> None:
    lookup_kernel.compile_kernels()


def _same(got: object, want: object, what: str) -> None:
    """Equal dtype, shape and bytes (None against None)."""
    if want is None:
        assert got is None, what
        return
    got, want = np.asarray(got), np.asarray(want)
    assert got.dtype == want.dtype and got.shape == want.shape, what
    assert got.tobytes() == want.tobytes(), what


@pytest.mark.parametrize('seed', range(24))
def test_finger_moments_are_the_einsums_bit_for_bit(seed: int) -> None:
    """The weighted finger moments and the per-finger blend: 1-40 entries, weights over many
    magnitudes, columns of zero weight (equal weights then), float32 poses as the lookup
    passes them, (K,) and (K, 5) weights."""
    rng = np.random.default_rng([seed, 23])
    k = int(rng.integers(1, 41))
    poses = rng.uniform(-2.0, 2.0, (k, 26)) * 10.0 ** rng.uniform(-3, 1)
    if seed % 2:
        poses = poses.astype(np.float32)
    scores = rng.uniform(0.0, 6.0, (k, 5))
    scores[:, seed % 5] = 1e3 if seed % 3 == 0 else scores[:, seed % 5]   # exp underflows: 0
    config = FingerEvidenceConfig(sigma_tiny_px=float(rng.uniform(0.3, 3.0)),
                                  cap_tiny_px=float(rng.uniform(2.0, 6.0)))
    got = finger_blend(poses, scores, config)
    want = finger_blend_reference(poses, scores, config.sigma_tiny_px, config.cap_tiny_px)
    for g, w, name in zip(got, want, ('mean', 'spread', 'seen'), strict=True):
        _same(g, w, name)
    weights = rng.uniform(0.0, 1.0, k)
    weights /= weights.sum()
    for w in (weights, rng.uniform(0.0, 1.0, (k, 5))):
        for g, r, name in zip(weighted_fingers(poses, w), weighted_fingers_reference(poses, w),
                              ('mean', 'std'), strict=True):
            _same(g, r, name)
    mean, std = np.empty(20), np.empty(20)
    w = np.exp(-(scores / config.sigma_tiny_px) ** 2)
    lookup_kernel.finger_moments(np.asarray(poses, np.float64), w, True, 6, mean, std)
    _same(mean, want[0], 'kernel mean')
    _same(std, want[1], 'kernel std')


@pytest.mark.parametrize('count', [1, 2, 7, 8, 10, 30, 129, 300])
def test_blend_weights_are_numpys_bit_for_bit(count: int) -> None:
    """The Gaussian weights of 1-300 distances (numpy's mean and sum: in order up to 8 terms,
    eight accumulators up to 128, halves above), all zero (equal weights), one far outlier."""
    rng = np.random.default_rng(count)
    for d in (rng.uniform(0.0, 3.0, count) * 10.0 ** rng.uniform(-3, 2), np.zeros(count),
              np.append(rng.uniform(0.5, 1.0, count - 1), 1e4)):
        _same(blend_weights(d), blend_weights_reference(d), f'{count} distances')
    sigma = lookup_kernel.gaussian_exponents(np.zeros(count), np.zeros(count))
    assert sigma == 0.0


@pytest.mark.parametrize('patches', [1, 7, 8, 20, 129, 300])
def test_digit_means_follow_numpys_pairwise_sums(patches: int) -> None:
    """The per-digit mean residuals with any number of patches: numpy sums up to 8 terms in
    order, up to 128 with eight accumulators, and longer rows in halves."""
    rng = np.random.default_rng(patches)
    k = 12
    xy = rng.uniform(0.0, 40.0, (k, patches, 2))
    pixels = rng.uniform(0.0, 50.0, (k, patches)).astype(np.float32)
    digit = rng.integers(-1, 6, (k, patches)).astype(np.int8)
    digit[0] = 2                                             # one digit with every patch
    color = rng.integers(1, 11, patches)
    bcol = rng.integers(1, 9, 30)
    bxy = rng.uniform(0.0, 40.0, (30, 2))
    bpix = rng.uniform(0.5, 80.0, 30)
    for config in (FingerEvidenceConfig(cap_tiny_px=9.0),
                   FingerEvidenceConfig(cap_tiny_px=50.0, area_weight=0.0)):
        args = (xy, pixels, digit, color, bcol, bxy, bpix, config)
        _same(finger_scores(*args), finger_scores_reference(*args), f'{patches} patches')
    residual = np.empty((k, 5))
    d = np.full((k, patches), np.inf)
    lookup_kernel.digit_mean_residuals(d, np.zeros((k, patches)), digit.astype(np.int64), 5,
                                       2.7, 3.0, residual)
    no_blobs = finger_scores_reference(xy, pixels, digit, color, bcol[:0], bxy[:0], bpix[:0],
                                       FingerEvidenceConfig(cap_tiny_px=2.7))
    _same(residual, no_blobs, 'no blobs: the cap, averaged as numpy does')


@pytest.mark.parametrize('seed', range(16))
def test_constraint_patches_are_numpys(seed: int) -> None:
    """The constraints' patches: each digit from its best entry, that entry the nearest one,
    one entry best for several digits, hidden patches, palm patches, and none at all."""
    rng = np.random.default_rng([seed, 7])
    n, p = 9, 20
    vertex = rng.integers(0, 700, (n, p)).astype(np.int32)
    vertex[rng.random((n, p)) < 0.3] = -1
    digit = rng.integers(0, 6, (n, p)).astype(np.int8)
    digit[vertex < 0] = -1
    xy = rng.uniform(0.0, 40.0, (n, p, 2)).astype(np.float32)
    pixels = rng.uniform(0.0, 30.0, (n, p)).astype(np.float32)
    color = rng.integers(1, 11, p).astype(np.uint8)
    entry = int(rng.integers(0, n))
    if seed == 0:
        vertex[entry] = -1
        digit[entry] = -1
    crop = (float(rng.uniform(0.5, 4.0)), float(rng.uniform(0, 300)), float(rng.uniform(0, 200)))
    for finger in (None, rng.integers(0, n, 5), np.full(5, entry),
                   np.where(rng.random(5) < 0.5, entry, rng.integers(0, n, 5))):
        want = constraints_reference(vertex, digit, xy, pixels, color, entry, crop, finger)
        got = lookup_kernel.constraint_patches(
            entry, np.zeros(0, np.int64) if finger is None else finger.astype(np.int64),
            vertex, digit, xy, pixels, color)
        got = (*got, tiny_to_full(got[3], *crop))
        for g, w, name in zip(got, want, ('ids', 'colors', 'vertices', 'tiny', 'pixels', 'full'),
                              strict=True):
            _same(g, w, name)


@pytest.mark.parametrize('seed', range(8))
def test_wrists_on_rays_are_numpys(seed: int) -> None:
    """The wrists placed on the query's rays, with and without lens distortion, through the
    kernel and through ``search._place_wrists``."""
    rng = np.random.default_rng([seed, 11])
    k = int(rng.integers(1, 40))
    terms = np.column_stack([rng.uniform(0, 40, (k, 2)), rng.uniform(0.2, 2.0, k),
                             rng.normal(size=(k, 4)), rng.uniform(-0.1, 0.1, (k, 3))])
    render = {'fx': 150.0, 'fy': 151.0, 'cx': 63.5, 'cy': 63.5}
    crop = (float(rng.uniform(0.5, 5.0)), float(rng.uniform(0, 300)), float(rng.uniform(0, 200)))
    for distortion in (np.zeros(5), np.array([0.1, -0.05, 0.001, 0.002, 0.0])):
        cam = PinholeCamera(640, 480, 520.0 + seed, 515.0, 320.5, 239.0, distortion=distortion)
        want = place_wrists_reference(terms, render, crop, cam)
        _same(_place_wrists(terms, render, crop, cam), want, 'place')
        if not distortion.any():
            out = np.empty((k, 3))
            full = tiny_to_full(terms[:, 0:2], *crop)
            lookup_kernel.wrists_on_rays(full, terms, cam.cx, cam.cy, cam.fx, cam.fy,
                                         (cam.fx + cam.fy) / (render['fx'] + render['fy'])
                                         / crop[0], out)
            _same(out, want, 'kernel')


def _blobs_near(lookup: PoseLookup, entry: int, crop: tuple[float, float, float],
                rng: np.random.Generator) -> SimpleNamespace:
    """Blobs where ``entry``'s visible patches would be seen, moved a little, some dropped, one
    of a colour no patch of it has, one with a NaN centroid and one of no pixels."""
    xy = lookup._a['patch_xy'][entry].astype(np.float64)
    seen = np.flatnonzero(np.isfinite(xy).all(axis=1) & (rng.random(len(xy)) < 0.8))
    full = tiny_to_full(xy[seen], *crop) + rng.normal(0.0, 2.0, (len(seen), 2))
    color = np.append(lookup._a['patch_color'][seen].astype(np.int64), [10, 3, 4])
    centroid = np.vstack([full, [[50.0, 60.0], [np.nan, 3.0], [70.0, 80.0]]])
    pixels = np.append(lookup._a['patch_pixels'][entry, seen] * crop[0] ** 2
                       * rng.uniform(0.7, 1.4, len(seen)), [30.0, 20.0, 0.0])
    return SimpleNamespace(color=color, centroid_px=centroid, pixel_count=pixels)


@pytest.mark.parametrize('seed', range(6))
def test_lookup_blend_is_numpys_bit_for_bit(small_database, seed: int) -> None:
    """``PoseLookup.blend`` on rendered entries (their label images, shifted), with blobs
    (the per-finger blend) and without (the paper's), with and without lens distortion: every
    array of the result as numpy's blend made it."""
    rng = np.random.default_rng([seed, 3])
    lookup = PoseLookup(small_database, num_candidates=40, num_blend=10)
    distortion = np.zeros(5) if seed % 2 else np.array([0.05, -0.02, 0.001, 0.0, 0.0])
    cam = PinholeCamera(640, 480, 600.0, 590.0, 321.0, 241.0, distortion=distortion)
    for _ in range(4):
        entry = int(rng.integers(0, len(small_database)))
        tiny = np.roll(small_database.tiny[entry], tuple(rng.integers(-1, 2, 2)), axis=(0, 1))
        crop = (float(rng.uniform(1.0, 4.0)), float(rng.uniform(50, 300)),
                float(rng.uniform(20, 200)))
        found = lookup.search(tiny, crop)
        for blobs in (None, _blobs_near(lookup, entry, crop, rng)):
            got = lookup.blend(found, cam, blobs)
            want = blend_reference(lookup, found, cam, blobs)
            for name, value in want.items():
                owner, _, field = name.rpartition('.')
                _same(getattr(got.constraints if owner else got, field), value, name)
