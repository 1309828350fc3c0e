"""The segmenter's compiled loops (issue 19, eleventh and thirteenth passes): the same labels
and windows as plain per-pixel references (``segmentation_reference``), compiled before the
first frame and never again."""
from __future__ import annotations

import cv2
import numpy as np
import pytest
from segmentation_reference import (
    keep_near_junctions_reference,
    mean_shift_reference,
    relabel_borders_reference,
)

from colorglove_ros.core.segmentation import segmentation_kernel
from colorglove_ros.core.segmentation.blobs import color_components
from colorglove_ros.core.segmentation.color_model import index_tables, lut_index
from colorglove_ros.core.segmentation.crop import compiled_kernels, mean_shift_crop
from colorglove_ros.core.segmentation.detection import (
    colour_diversity,
    keep_near_junctions,
    scene_colour_table,
)
from colorglove_ros.core.segmentation.segmenter import relabel_borders

KERNELS = compiled_kernels()


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


def _random_labels(rng: np.random.Generator, trial: int) -> np.ndarray:
    """Label images of many kinds: sizes from 1 pixel, empty, speckled, a label of 64 or more,
    and views with strides."""
    h, w = (int(v) for v in rng.integers(1, 60, 2))
    labels = _blocky_labels(rng, h, w, colours=int(rng.integers(1, 11)))
    if trial % 5 == 0:
        labels[:] = 0
    if trial % 7 == 0:
        labels[rng.random((h, w)) < 0.02] = 70
    return labels[:: 1 + trial % 2, trial % 3:] if w > 3 else labels


@pytest.mark.parametrize('trial', range(40))
def test_label_boxes_are_the_bincount_and_the_bounding_rectangles(trial: int) -> None:
    labels = _random_labels(np.random.default_rng([trial, 29]), trial)
    counts, boxes = KERNELS.label_boxes(labels, 11)
    np.testing.assert_array_equal(counts, np.bincount(labels.ravel(), minlength=11))
    for label in range(11):
        mask = np.ascontiguousarray(labels == label).view(np.uint8)
        assert tuple(boxes[label]) == (cv2.boundingRect(mask) if labels.size else (0, 0, 0, 0))


@pytest.mark.parametrize('trial', range(12))
def test_classify_and_the_scene_colours_histogram_are_the_table_lookups(trial: int) -> None:
    rng = np.random.default_rng([trial, 31])
    image = rng.integers(0, 256, (int(rng.integers(1, 50)), int(rng.integers(1, 50)), 3),
                         dtype=np.uint8)[:, :: 1 + trial % 2]
    bits = 6
    lut = rng.integers(0, 11, 1 << (3 * bits)).astype(np.uint8)
    table = None if trial % 2 else rng.integers(0, 256, (1, 256, 3)).astype(np.uint8)
    scene = rng.random(1 << 15) < 0.3
    want = lut.take(lut_index(image, bits, table))
    got = KERNELS.classify(image, lut, index_tables(bits, table), np.zeros(0, bool),
                           index_tables(5))
    np.testing.assert_array_equal(got, want)
    want[scene.take(lut_index(image, 5))] = 0
    got = KERNELS.classify(image, lut, index_tables(bits, table), scene, index_tables(5))
    np.testing.assert_array_equal(got, want)
    where = rng.random(image.shape[:2]) < 0.5
    np.testing.assert_array_equal(scene_colour_table(image, 5, 2, where),
                                  scene_colour_table(image[where], 5, 2))


def _colour_diversity_reference(labels: np.ndarray, num_colors: int, window: int,
                                min_density: float) -> np.ndarray:
    """Each pixel's box (``window // 2`` pixels before it on each axis) counted whole."""
    need = max(int(np.ceil(min_density * window * window - 1e-9)), 1)
    before, h, w = window // 2, *labels.shape
    out = np.zeros(labels.shape, np.uint8)
    for y in range(h):
        for x in range(w):
            box = labels[max(y - before, 0):y - before + window, max(x - before, 0):x - before
                         + window]
            counts = np.bincount(box.ravel(), minlength=num_colors + 1)[1:num_colors + 1]
            out[y, x] = np.count_nonzero(counts >= need)
    return out


@pytest.mark.parametrize('trial', range(12))
def test_colour_diversity_counts_each_pixels_whole_box(trial: int) -> None:
    rng = np.random.default_rng([trial, 37])
    labels = _random_labels(rng, trial)
    window = (1, 2, 5, 9, 24)[trial % 5]
    np.testing.assert_array_equal(colour_diversity(labels, 10, window, 0.02),
                                  _colour_diversity_reference(labels, 10, window, 0.02))


@pytest.mark.parametrize('trial', range(24))
def test_box_colour_counts_are_the_whole_box_counts(trial: int) -> None:
    """The summed-area tables and the block bounds count the same boxes as a whole-box
    count, windows from 1 pixel to wider than the image (blocks of 1 to 8 pixels, cut by the
    image's edges), at densities from 1 pixel to 30 % of the box; colours above
    ``num_colors`` are not counted."""
    rng = np.random.default_rng([trial, 43])
    labels = _random_labels(rng, trial)
    window = (1, 3, 4, 5, 9, 17, 24, 32, 33, 48, 70, 96)[trial % 12]
    density = (0.5 / window ** 2, 0.02, 0.3)[trial % 3]
    num_colors = (10, 4)[trial % 2]
    want = _colour_diversity_reference(labels, num_colors, window, density)
    np.testing.assert_array_equal(colour_diversity(labels, num_colors, window, density), want)
    counts = np.zeros(labels.shape, np.uint8)
    need = max(int(np.ceil(density * window * window - 1e-9)), 1)
    present, boxes = KERNELS.label_boxes(labels, num_colors + 1)
    colours = np.flatnonzero(present[1:num_colors + 1] >= need).astype(np.int64) + 1
    KERNELS.box_colour_counts(labels, colours, boxes, window, need, counts)
    np.testing.assert_array_equal(counts, want)


@pytest.mark.parametrize('trial', range(8))
def test_clear_cells_clears_the_chosen_labels_of_the_set_cells(trial: int) -> None:
    rng = np.random.default_rng([trial, 47])
    labels = np.ascontiguousarray(_random_labels(rng, trial))
    step = 1 + trial % 3
    h, w = labels.shape
    cells = rng.random(((h + step - 1) // step, (w + step - 1) // step)) < 0.4
    cleared = rng.random(256) < 0.5
    want = labels.copy()
    spread = np.repeat(np.repeat(cells, step, 0), step, 1)[:h, :w]
    want[spread & cleared[labels]] = 0
    got = KERNELS.clear_cells(labels, cells, step, cleared)
    np.testing.assert_array_equal(got, want)
    assert got is not labels


def _cluttered_glove(rng: np.random.Generator) -> np.ndarray:
    """A patchwork glove (patches of 10 colours, 3-5 pixels) with one-colour surfaces and
    strips touching it or not, some running off the image, some of a glove colour inside."""
    h, w = (int(v) for v in rng.integers(90, 180, 2))
    labels = np.zeros((h, w), np.uint8)
    gh, gw = (int(v) for v in rng.integers(20, 40, 2))
    gy, gx = int(rng.integers(10, h - gh - 10)), int(rng.integers(10, w - gw - 10))
    cell = int(rng.integers(3, 6))
    grid = rng.integers(1, 11, (gh // cell + 1, gw // cell + 1)).astype(np.uint8)
    labels[gy:gy + gh, gx:gx + gw] = cv2.resize(grid, (gw, gh),
                                                interpolation=cv2.INTER_NEAREST)
    for _ in range(int(rng.integers(1, 5))):
        y0, x0 = int(rng.integers(0, h - 4)), int(rng.integers(0, w - 4))
        y1, x1 = y0 + int(rng.integers(4, h)), x0 + int(rng.integers(4, w))
        labels[y0:y1, x0:x1][labels[y0:y1, x0:x1] == 0] = int(rng.integers(1, 11))
    return labels[:, :: 1 + int(rng.integers(0, 2))]


def _trim_case(trial: int) -> tuple[np.ndarray, dict]:
    """A cluttered glove and trim settings: with and without edges, surfaces only, the two
    gates and steps 1-3."""
    rng = np.random.default_rng([trial, 53])
    labels = _cluttered_glove(rng)
    edges = (None, (False, False, False, True), (True, True, True, True))[trial % 3]
    return labels, dict(num_colors=10, reach=float(rng.uniform(0.2, 0.6)), min_pixels=2,
                        max_patch_share=float(rng.choice([0.05, 0.15])), step=1 + trial % 3,
                        edges=edges, surfaces_only=bool(trial % 2),
                        min_pull=(0.0, 1.3)[trial % 4 // 2],
                        max_window_kept=(0.0, 0.92)[trial % 5 // 4])


@pytest.mark.parametrize('trial', range(30))
def test_keep_near_junctions_is_the_whole_image_trim(trial: int) -> None:
    """Each oversized colour labelled inside its bounding rectangle and the dropped cells
    cleared in one pass: the label image of the trim on the whole grid (main's before the
    thirteenth pass)."""
    labels, settings = _trim_case(trial)
    np.testing.assert_array_equal(keep_near_junctions(labels, **settings),
                                  keep_near_junctions_reference(labels, **settings))


def test_the_trim_cases_include_trimmed_images() -> None:
    """Most of the cases above are trimmed (the comparison is not of untouched images)."""
    trimmed = 0
    for trial in range(30):
        labels, settings = _trim_case(trial)
        trimmed += bool((keep_near_junctions(labels, **settings) != labels).any())
    assert trimmed >= 15


@pytest.mark.parametrize('trial', range(12))
def test_color_components_inside_each_rectangle_are_the_whole_images(trial: int) -> None:
    """Each colour labelled inside the rectangle the kernel found: the components of the
    whole image (the same order, areas and centroids up to the shift's rounding)."""
    labels = _random_labels(np.random.default_rng([trial, 41]), trial)
    colours, centroids, areas = color_components(labels, 2, 10)
    whole = color_components(labels, 2, 10, crop_to_color=False)
    np.testing.assert_array_equal(colours, whole[0])
    np.testing.assert_array_equal(areas, whole[2])
    np.testing.assert_allclose(centroids, whole[1], rtol=0, atol=1e-9)
