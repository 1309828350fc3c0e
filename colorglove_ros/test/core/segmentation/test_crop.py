"""Tests for the mean-shift crop and the label-preserving tiny-image scaling."""
from __future__ import annotations

import numpy as np
import pytest

from colorglove_ros.core.conventions import TINY_SIZE
from colorglove_ros.core.segmentation.crop import (
    CropError,
    CropTransform,
    crop_to_tiny,
    crop_window,
    mean_shift_crop,
)


def _hand_like(h: int = 480, w: int = 640, cx: int = 400, cy: int = 260) -> np.ndarray:
    """A palm (label 3) with four fingers (labels 4..7) and a thin stripe (label 9)."""
    lab = np.zeros((h, w), np.uint8)
    lab[cy - 40:cy + 40, cx - 35:cx + 35] = 3
    for i, x in enumerate(range(cx - 33, cx + 35, 18)):
        lab[cy - 100:cy - 40, x:x + 12] = 4 + i
    lab[cy:cy + 3, cx - 35:cx + 35] = 9
    return lab


def test_transform_roundtrip_and_window_edges() -> None:
    t = CropTransform.from_window((100.0, 50.0), 20.0)
    assert t.scale == pytest.approx(1.0)
    # Tiny pixel edges map to the crop window edges.
    np.testing.assert_allclose(t.to_full(np.array([-0.5, -0.5])), [80.0, 30.0])
    np.testing.assert_allclose(t.to_full(np.array([TINY_SIZE - 0.5, TINY_SIZE - 0.5])),
                               [120.0, 70.0])
    pts = np.array([[0.0, 0.0], [12.3, 39.0], [-4.0, 7.5]])
    np.testing.assert_allclose(t.to_tiny(t.to_full(pts)), pts, atol=1e-12)
    assert t.center_xy == pytest.approx((100.0, 50.0))
    assert t.half_size == pytest.approx(20.0)


def test_mean_shift_finds_glove_despite_outliers() -> None:
    lab = _hand_like()
    ys, xs = np.nonzero(lab)
    true_c = np.array([xs.mean(), ys.mean()])
    rng = np.random.default_rng(0)
    noisy = lab.copy()
    # Background false positives: scattered specks and a sizeable blob far away.
    noisy[rng.integers(0, 480, 400), rng.integers(0, 640, 400)] = 2
    noisy[20:60, 20:70] = 8
    result = mean_shift_crop(noisy)
    assert result is not None
    (cx, cy), half = result
    assert np.hypot(cx - true_c[0], cy - true_c[1]) < 4.0
    # The window holds the whole glove (extents x +-35, y -100..+40 about the palm) but not
    # the distant blob.
    assert cx - half <= xs.min() + 2 and cx + half >= xs.max() - 2
    assert cy - half <= ys.min() + 8 and cy + half >= ys.max() - 2
    assert half < 120
    assert not (cx - half < 70 and cy - half < 60)


def test_mean_shift_fixed_point_is_bandwidth_times_std() -> None:
    lab = np.zeros((200, 200), np.uint8)
    lab[50:150, 70:130] = 1  # 60 wide, 100 tall: larger std is 100 / sqrt(12)
    (cx, cy), half = mean_shift_crop(lab, bandwidth_factor=2.0)
    assert (cx, cy) == pytest.approx((99.5, 99.5), abs=1e-6)
    assert half == pytest.approx(2.0 * np.sqrt((100 ** 2 - 1) / 12.0), rel=1e-3)


def test_mean_shift_none_when_too_few_pixels() -> None:
    lab = np.zeros((64, 64), np.uint8)
    assert mean_shift_crop(lab) is None
    lab[3, 3] = 1
    assert mean_shift_crop(lab, min_pixels=5) is None
    assert crop_to_tiny(lab, min_pixels=5) is None


@pytest.mark.parametrize('bad', [np.zeros((4, 4, 3), np.uint8), np.zeros((0, 0), np.uint8)])
def test_bad_input_raises(bad: np.ndarray) -> None:
    with pytest.raises(CropError):
        mean_shift_crop(bad)


def test_crop_to_tiny_is_deterministic_and_keeps_thin_patches() -> None:
    lab = _hand_like()
    a = crop_to_tiny(lab)
    b = crop_to_tiny(lab.copy())
    assert a is not None and b is not None
    assert a.labels.shape == (TINY_SIZE, TINY_SIZE) and a.labels.dtype == np.uint8
    np.testing.assert_array_equal(a.labels, b.labels)
    assert a.transform == b.transform
    assert a.transform.scale > 3.0  # a real downsample
    # All colours survive, including the 3-pixel stripe (< 1 cell) and every finger.
    assert set(np.unique(a.labels)) == {0, 3, 4, 5, 6, 7, 9}
    # Patch centroids mapped back to the full image agree with the originals.
    for label in (4, 5, 6, 7, 9):
        ty, tx = np.nonzero(a.labels == label)
        fy, fx = np.nonzero(lab == label)
        back = a.transform.to_full(np.array([tx.mean(), ty.mean()]))
        assert np.hypot(*(back - [fx.mean(), fy.mean()])) < a.transform.scale


def test_crop_is_scale_invariant() -> None:
    small = _hand_like(160, 214, 133, 110)[::1, ::1]
    big = np.repeat(np.repeat(small, 3, axis=0), 3, axis=1)
    ts, tb = crop_to_tiny(small), crop_to_tiny(big)
    assert ts is not None and tb is not None
    assert tb.transform.scale == pytest.approx(3 * ts.transform.scale, rel=0.01)
    assert np.mean(ts.labels == tb.labels) > 0.95


def test_crop_window_majority_and_upsampling() -> None:
    lab = np.zeros((8, 8), np.uint8)
    lab[:, :5] = 2
    lab[:, 5:] = 6
    # One cell covering the whole image: label 2 has 5/8 of the pixels.
    t = CropTransform.from_window((3.5, 3.5), 4.0, size=1)
    assert crop_window(lab, t, size=1)[0, 0] == 2
    # Mostly background (10% glove) -> background; 50% glove -> glove.
    sparse = np.zeros((10, 10), np.uint8)
    sparse[0, :] = 5
    t1 = CropTransform.from_window((4.5, 4.5), 5.0, size=1)
    assert crop_window(sparse, t1, size=1)[0, 0] == 0
    sparse[:5, :] = 5
    assert crop_window(sparse, t1, size=1)[0, 0] == 5
    # Upsampling a 10x10 square into 40x40: nearest labels, no holes.
    sq = np.zeros((20, 20), np.uint8)
    sq[5:15, 5:15] = 4
    tiny = crop_to_tiny(sq)
    assert tiny is not None and tiny.transform.scale < 1.0
    inside = tiny.labels[12:28, 12:28]
    assert np.all(inside == 4)
    assert tiny.labels[0, 0] == 0
