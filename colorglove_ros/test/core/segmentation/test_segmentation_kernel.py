"""The segmenter's compiled loops (issue 19, eleventh pass): the same labels and windows as
plain per-pixel references (``segmentation_reference``), compiled before the first frame and
never again."""
from __future__ import annotations

import cv2
import numpy as np
import pytest
from segmentation_reference import mean_shift_reference, relabel_borders_reference

from colorglove_ros.core.segmentation import segmentation_kernel
from colorglove_ros.core.segmentation.crop import compiled_kernels, mean_shift_crop
from colorglove_ros.core.segmentation.segmenter import relabel_borders


def _blocky_labels(rng: np.random.Generator, h: int, w: int, colours: int = 6,
                   noise: float = 0.1) -> np.ndarray:
    """Patches of ``colours`` labels (0 background) a few pixels wide, with speckle."""
    cell = int(rng.integers(2, 7))
    grid = rng.integers(0, colours + 1, (h // cell + 1, w // cell + 1)).astype(np.uint8)
    labels = cv2.resize(grid, (w, h), interpolation=cv2.INTER_NEAREST)
    speckle = rng.random((h, w)) < noise
    labels[speckle] = rng.integers(0, colours + 1, int(speckle.sum()))
    return labels


def _image_of(rng: np.random.Generator, labels: np.ndarray) -> np.ndarray:
    """An RGB image of ``labels``: a colour per label, blurred across the borders (mixed
    pixels) and with noise."""
    palette = rng.integers(0, 256, (256, 3)).astype(np.float32)
    image = cv2.GaussianBlur(palette[labels], (3, 3), float(rng.uniform(0.3, 1.2)))
    image += rng.normal(0.0, 6.0, image.shape).astype(np.float32)
    return np.clip(image, 0, 255).astype(np.uint8)


@pytest.mark.parametrize('seed', range(12))
def test_relabel_borders_gives_the_per_pixel_references_labels(seed: int) -> None:
    rng = np.random.default_rng([seed, 19])
    h, w = (int(v) for v in rng.integers(12, 40, 2))
    labels = _blocky_labels(rng, h, w)
    if seed % 3 == 0:   # a glove region on background, the usual case
        labels[:, : w // 3] = 0
    image = _image_of(rng, labels)
    passes = 1 + seed % 3
    distances = ((2, 4), (1,), (3,), (1, 2))[seed % 4]
    mix_tolerance, min_residual = ((0.25, 10.0), (0.6, 30.0))[seed % 2]
    got = relabel_borders(image, labels, passes, distances, mix_tolerance, min_residual)
    want = relabel_borders_reference(image, labels, passes, distances, mix_tolerance,
                                     min_residual)
    assert (got != labels).any()          # the case decides something
    np.testing.assert_array_equal(got, want)


def test_relabel_borders_keeps_a_thin_real_colour_and_leaves_its_input() -> None:
    """A one-pixel line of a colour that is no mix of its neighbours keeps its label; the
    input labels are not written to."""
    labels = np.zeros((20, 20), np.uint8)
    labels[:, 10:] = 1
    labels[:, 9] = 2                    # a thin line between 0 and 1 ...
    image = np.zeros((20, 20, 3), np.uint8)
    image[:, 10:] = (200, 0, 0)
    image[:, 9] = (0, 0, 250)           # ... of a colour that is no mix of theirs
    before = labels.copy()
    out = relabel_borders(image, labels)
    np.testing.assert_array_equal(labels, before)
    assert (out[:, 9] == 2).all()
    np.testing.assert_array_equal(out, relabel_borders_reference(image, labels, 3, (2, 4),
                                                                 0.25, 10.0))


@pytest.mark.parametrize('seed', range(10))
def test_mean_shift_crop_gives_the_references_window(seed: int) -> None:
    rng = np.random.default_rng([seed, 23])
    h, w = (int(v) for v in rng.integers(20, 90, 2))
    mask = np.zeros((h, w), bool)
    for _ in range(int(rng.integers(1, 5))):   # blobs of several sizes, and specks
        cx, cy, r = rng.uniform(0, w), rng.uniform(0, h), rng.uniform(2, 0.3 * min(h, w))
        yy, xx = np.mgrid[:h, :w]
        mask |= (xx - cx) ** 2 + (yy - cy) ** 2 < r * r
    mask |= rng.random((h, w)) < 0.02
    start = None if seed % 2 else ((rng.uniform(0, w), rng.uniform(0, h)), rng.uniform(3, 20))
    factors = (2.5, 2.0) if seed % 3 else (2.0, 2.0)
    got = mean_shift_crop(mask, factors[0], 5, initial_bandwidth_factor=factors[1],
                          start=start)
    want = mean_shift_reference(mask, factors[0], factors[1], 5, start)
    assert got == want                 # to the bit: every moment is a sum of whole numbers


def test_kernels_are_compiled_once_for_one_signature() -> None:
    """After set-up every kernel has exactly one compiled signature and compiles no other:
    an argument of another type raises instead of compiling on a frame."""
    compiled_kernels()
    compiled_kernels()                  # again: nothing more to compile
    for kernel in segmentation_kernel._SIGNATURES:
        assert len(kernel.signatures) == 1
    sat = np.zeros((5, 5), np.int64)    # int64, not the int32 of cv2.integral
    with pytest.raises(TypeError):
        segmentation_kernel.mean_shift(sat, 2.0, 2.0, 2.0, np.array([2.5]), 1, 50, 0.05, 2.0)
