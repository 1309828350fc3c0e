"""Tests for the Hausdorff-like tiny-image distance."""
from __future__ import annotations

import numpy as np
import pytest

from colorglove_ros.core.lookup.distance import (
    ABSENT_PENALTY,
    DistanceError,
    QueryDistance,
    _dts_into,
    directed_distance,
    distance_transforms,
    image_distance,
    quantize_dts,
)


def _blobs(seed: int, n: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    out = np.zeros((n, 40, 40), np.uint8)
    yy, xx = np.mgrid[0:40, 0:40]
    for i in range(n):
        for _ in range(6):
            c, x, y, r = rng.integers(1, 11), *rng.integers(5, 35, 2), rng.integers(3, 8)
            out[i][(xx - x) ** 2 + (yy - y) ** 2 <= r * r] = c
    return out


def test_zero_for_identical_and_symmetric() -> None:
    imgs = _blobs(0, 6)
    for a in imgs:
        assert image_distance(a, a) == 0.0
    for a, b in zip(imgs[:-1], imgs[1:], strict=True):
        d = image_distance(a, b)
        assert d > 0.0
        assert d == pytest.approx(image_distance(b, a))


def test_hand_computed_case() -> None:
    a = np.zeros((40, 40), np.uint8)
    b = np.zeros((40, 40), np.uint8)
    a[5, 5] = 1
    b[5, 8] = 1            # same colour, 3 px to the right
    assert directed_distance(a, b) == pytest.approx(3.0)
    assert image_distance(a, b) == pytest.approx(3.0)
    b[9, 8] = 1            # b gets a second pixel 4 px below the first: 5 px from a's pixel
    assert directed_distance(b, a) == pytest.approx((3.0 + 5.0) / 2)
    assert directed_distance(a, b) == pytest.approx(3.0)
    a[20, 20] = 2          # colour 2 only in a: penalised, not infinite
    assert directed_distance(a, b) == pytest.approx((3.0 + ABSENT_PENALTY) / 2)
    assert image_distance(a, b) == pytest.approx(0.5 * ((3.0 + ABSENT_PENALTY) / 2 + 4.0))


def test_bounded_penalty_and_empty_images() -> None:
    empty = np.zeros((40, 40), np.uint8)
    full = np.full((40, 40), 3, np.uint8)
    other = np.full((40, 40), 4, np.uint8)
    assert image_distance(empty, empty) == 0.0
    assert image_distance(empty, full) == pytest.approx(ABSENT_PENALTY)
    assert image_distance(full, other) == pytest.approx(ABSENT_PENALTY)
    assert ABSENT_PENALTY == pytest.approx(40 * np.sqrt(2))
    imgs = _blobs(1, 10)
    assert max(image_distance(imgs[0], b) for b in imgs) <= ABSENT_PENALTY


def test_distance_transform_values() -> None:
    a = np.zeros((40, 40), np.uint8)
    a[0, 0] = 7
    dts = distance_transforms(a)
    assert dts.shape == (10, 40, 40)
    assert dts[6, 3, 4] == pytest.approx(5.0)
    assert dts[6, 39, 39] == pytest.approx(39 * np.sqrt(2), rel=1e-5)
    assert np.all(dts[0] == np.float32(ABSENT_PENALTY))


def test_query_against_many_matches_pairwise() -> None:
    imgs = _blobs(2, 40)
    query = QueryDistance(imgs[0])
    exact = np.array([image_distance(imgs[0], b) for b in imgs])
    from colorglove_ros.core.lookup.distance import distance_transforms_batch
    dts = distance_transforms_batch(imgs)
    np.testing.assert_allclose(query.to_many(imgs, dts), exact, rtol=1e-5, atol=1e-5)
    # uint8 storage rounds distances to 0.25 px: error at most 0.125 px
    approx = query.to_many(imgs, quantize_dts(dts))
    assert np.max(np.abs(approx - exact)) <= 0.125 + 1e-6
    assert approx[0] == 0.0
    empty = QueryDistance(np.zeros((40, 40), np.uint8))
    np.testing.assert_allclose(empty.to_many(imgs[:3]), ABSENT_PENALTY)


def test_rejects_bad_input() -> None:
    with pytest.raises(DistanceError):
        distance_transforms(np.zeros((20, 20), np.uint8))
    with pytest.raises(DistanceError):
        image_distance(np.full((40, 40), 11, np.uint8), np.zeros((40, 40), np.uint8))


def test_distance_transforms_do_not_depend_on_the_output_address() -> None:
    """OpenCV's precise transform rounds the last bit by its output's alignment: the same
    labels must give the same bits wherever the caller's array happens to lie (NumPy only
    aligns to 16 bytes), or the lookup's poses change from run to run."""
    rng = np.random.default_rng(7)
    labels = np.where(rng.random((40, 40)) < 0.4, rng.integers(1, 11, (40, 40)), 0).astype(np.uint8)
    reference = distance_transforms(labels)
    assert np.array_equal(QueryDistance(labels).dts, reference)
    nbytes = reference.nbytes
    raw = np.empty(nbytes + 128, np.uint8)
    base = -raw.ctypes.data % 64
    for offset in range(0, 64, 4):
        out = raw[base + offset:base + offset + nbytes].view(np.float32).reshape(reference.shape)
        _dts_into(labels, out)
        np.testing.assert_array_equal(out, reference, err_msg=f'output at 64n + {offset} bytes')
