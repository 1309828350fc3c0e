"""The segmenter's compiled loops (issue 19, eleventh, thirteenth and nineteenth passes): the
same labels, windows, components and bits as plain per-pixel references and the OpenCV and
numpy code they replaced (``segmentation_reference``), compiled before the first frame and
never again."""
from __future__ import annotations

import cv2
import numpy as np
import pytest
from segmentation_reference import (
    cell_labels_reference,
    color_components_reference,
    keep_multicolor_components_reference,
    keep_near_junctions_reference,
    mean_shift_reference,
    near_or_reaching_reference,
    relabel_borders_reference,
    small_patches_reached_reference,
    surface_regions_reference,
)

from colorglove_ros.core.segmentation import segmentation_kernel
from colorglove_ros.core.segmentation.blobs import color_components
from colorglove_ros.core.segmentation.color_model import index_tables, lut_index
from colorglove_ros.core.segmentation.crop import (
    CropTransform,
    compiled_kernels,
    crop_window,
    mean_shift_crop,
)
from colorglove_ros.core.segmentation.detection import (
    colour_diversity,
    drop_oversized_components,
    glove_region_mask,
    keep_near_junctions,
    scene_colour_table,
)
from colorglove_ros.core.segmentation.light import (
    LightEstimateError,
    colour_means,
    estimate_light_gains,
)
from colorglove_ros.core.segmentation.segmenter import (
    _LINEAR_RGB,
    keep_multicolor_components,
    relabel_borders,
)

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


def _large_labels(rng: np.random.Generator, trial: int) -> np.ndarray:
    """Label images from 1 pixel to 330 pixels a side (a colour's rectangle past 65535
    pixels: OpenCV's 32-bit components), patches of 1 to 12 pixels with speckle, labels
    above the glove's colours, and views with strides."""
    h, w = (int(v) for v in rng.integers(1, (12, 60, 330)[trial % 3], 2))
    cell = int(rng.integers(1, 13))
    grid = rng.integers(0, 13, (h // cell + 1, w // cell + 1)).astype(np.uint8)
    labels = cv2.resize(grid, (w, h), interpolation=cv2.INTER_NEAREST)
    speckle = rng.random((h, w)) < rng.uniform(0.0, 0.3)
    labels[speckle] = rng.integers(0, 11, int(speckle.sum()))
    if trial % 7 == 0:
        labels[:] = 0
    if trial % 4 == 1 and w > 2:
        labels = labels[:, 1::2]
    return labels


@pytest.mark.parametrize('trial', range(48))
def test_colour_blobs_are_opencvs_components_colour_by_colour(trial: int) -> None:
    """The compiled blobs: OpenCV's components of each colour inside its rectangle, in its
    order (by 2 x 2 blocks, not pixels), with its areas and its centroids' bits."""
    rng = np.random.default_rng([trial, 59])
    labels = _large_labels(rng, trial)
    min_pixels = int(rng.integers(1, 20))
    want = color_components_reference(labels, min_pixels, 10)
    for got in (KERNELS.colour_blobs(labels, 10, min_pixels),
                color_components(labels, min_pixels, 10)):
        for a, b in zip(got, want, strict=True):
            assert a.dtype == b.dtype and a.shape == b.shape
            assert a.tobytes() == b.tobytes()


def test_colour_blobs_follow_opencvs_block_order_not_raster_order() -> None:
    """Two blobs of a colour whose first pixels come in one order by rows and in the other
    by 2 x 2 blocks: OpenCV's (and so the blobs') order is the blocks'."""
    labels = np.zeros((4, 8), np.uint8)
    labels[0, 5] = labels[0, 6] = 3    # first by rows (row 0), in block column 2
    labels[1, 0] = labels[1, 1] = 3    # first by blocks (block column 0)
    labels[0, 0] = 1                   # the colour's rectangle starts at column 0, row 0
    colours, centroids, areas = KERNELS.colour_blobs(labels, 10, 1)
    np.testing.assert_array_equal(colours, [1, 3, 3])
    np.testing.assert_array_equal(centroids[1:], [[0.5, 1.0], [5.5, 0.0]])
    want = color_components_reference(labels, 1, 10)
    np.testing.assert_array_equal(centroids, want[1])


@pytest.mark.parametrize('trial', range(30))
def test_small_patches_reached_are_each_colours_opencv_components(trial: int) -> None:
    rng = np.random.default_rng([trial, 61])
    labels = _large_labels(rng, trial)
    reached = rng.random(labels.shape) < (0.0, 0.002, 0.02)[trial % 3]
    max_area = float(rng.choice([0.0, 3.0, 40.5, 1e9]))
    start = rng.random(labels.shape) < 0.1
    want, got = start.copy(), start.copy()
    small_patches_reached_reference(labels, 10, reached, max_area, want)
    KERNELS.small_patches_reached(labels, 10, reached, max_area, got)
    np.testing.assert_array_equal(got, want)


@pytest.mark.parametrize('trial', range(30))
def test_colour_components_are_opencvs_components_colour_by_colour(trial: int) -> None:
    """Each single-colour 8-connected component of OpenCV's (labels above num_colors as
    background) is one component of the kernel's, numbered 1..n by its first pixel."""
    rng = np.random.default_rng([trial, 71])
    labels = _large_labels(rng, trial)
    num_colors = (10, 6)[trial % 2]
    comp, count = KERNELS.colour_components(labels, num_colors)
    want = np.zeros(labels.shape, np.int64)
    n = 0
    for colour in range(1, num_colors + 1):
        k, part = cv2.connectedComponents(np.equal(labels, colour).view(np.uint8),
                                          connectivity=8, ltype=cv2.CV_32S)
        want[part > 0] = part[part > 0] + n
        n += k - 1
    assert count == n
    assert (comp == 0).sum() == (want == 0).sum() and np.array_equal(comp == 0, want == 0)
    pairs = np.unique(np.stack([comp[want > 0], want[want > 0]]), axis=1)
    assert pairs.shape[1] == n and len(np.unique(pairs[0])) == n    # one to one
    first = np.unique(comp.ravel(), return_index=True)[1][1:]       # numbered in raster order
    assert np.all(np.diff(first) > 0)


@pytest.mark.parametrize('trial', range(30))
def test_near_or_reaching_is_the_reach_of_opencvs_glove_components(trial: int) -> None:
    rng = np.random.default_rng([trial, 67])
    labels = _large_labels(rng, trial)
    reach = rng.random(labels.shape) < (0.0, 0.001, 0.02)[trial % 3]
    near = rng.random(labels.shape) < 0.05
    np.testing.assert_array_equal(KERNELS.near_or_reaching(labels, reach, near),
                                  near_or_reaching_reference(labels, reach, near))
    for window in (3, 24):
        rich = colour_diversity(labels, 10, window, 0.02) >= 4
        size = 2 * window + 1
        near = cv2.boxFilter(rich.view(np.uint8), cv2.CV_32S, (size, size), normalize=False,
                             borderType=cv2.BORDER_CONSTANT) > 0
        want = (near_or_reaching_reference(labels, rich, near) if rich.any()
                else np.zeros(labels.shape, bool))
        np.testing.assert_array_equal(glove_region_mask(labels, 10, window, 4, 0.02), want)


@pytest.mark.parametrize('trial', range(36))
def test_keep_multicolor_components_are_the_opencv_and_numpy_test(trial: int) -> None:
    """The compiled components and colour counts keep and re-attach the same components."""
    rng = np.random.default_rng([trial, 71])
    labels = _large_labels(rng, trial)
    labels[labels > 10] = 0
    settings = dict(min_colors=int(rng.integers(1, 5)), min_share=float(rng.choice([0.0, 0.03])),
                    min_pixels=int(rng.integers(1, 6)), reattach_radius=int(trial % 4),
                    reattach_max_share=float(rng.choice([0.0, 0.2, 5.0])))
    got = keep_multicolor_components(labels, **settings)
    want = keep_multicolor_components_reference(labels, **settings)
    assert got.dtype == want.dtype == np.uint8
    np.testing.assert_array_equal(got, want)


def test_keep_multicolor_component_cases_drop_and_reattach_some() -> None:
    """The cases above are not all kept whole: some drop components, some re-attach."""
    dropped = reattached = 0
    for trial in range(36):
        rng = np.random.default_rng([trial, 71])
        labels = _large_labels(rng, trial)
        labels[labels > 10] = 0
        settings = dict(min_colors=int(rng.integers(1, 5)),
                        min_share=float(rng.choice([0.0, 0.03])),
                        min_pixels=int(rng.integers(1, 6)), reattach_radius=int(trial % 4),
                        reattach_max_share=float(rng.choice([0.0, 0.2, 5.0])))
        got = keep_multicolor_components(labels, **settings)
        plain = keep_multicolor_components(labels, **{**settings, 'reattach_radius': 0})
        dropped += bool((got != labels).any())
        reattached += bool((got != plain).any())
    assert dropped >= 8 and reattached >= 3


@pytest.mark.parametrize('trial', range(40))
def test_cell_labels_are_the_numpy_votes_and_rescue(trial: int) -> None:
    """The compiled cell labels: numpy's majority (ties to the lower label), glove fraction
    and thin-patch rescue, cell by cell; through ``crop_window`` on crops of every scale."""
    rng = np.random.default_rng([trial, 73])
    labels_n, cells = int(rng.integers(2, 12)), int(rng.integers(1, 50))
    counts = rng.integers(0, 4, (labels_n, cells)) * (rng.random((labels_n, cells)) < 0.4)
    if trial % 3 == 0:
        counts[int(rng.integers(1, labels_n))] = rng.random(cells) < 0.1   # thin: rescued
    counts = np.ascontiguousarray(counts, np.int64)
    fraction, rescue = float(rng.choice([0.0, 0.4, 0.9])), float(rng.choice([0.0, 0.2, 0.5]))
    want = cell_labels_reference(counts, fraction, rescue)
    got = KERNELS.cell_labels(counts, fraction, rescue)
    assert got.dtype == want.dtype and got.tobytes() == want.tobytes()
    labels = _large_labels(rng, trial)
    if labels.size:
        h, w = labels.shape
        half = float(rng.uniform(0.5, 0.7 * max(h, w)))
        transform = CropTransform.from_window((float(rng.uniform(0, w)),
                                               float(rng.uniform(0, h))), half)
        np.testing.assert_array_equal(crop_window(labels, transform, rescue_share=rescue),
                                      _crop_window_reference(labels, transform, rescue))


def _crop_window_reference(labels: np.ndarray, transform: CropTransform,
                           rescue_share: float) -> np.ndarray:
    """``crop_window`` with its cell labels from the numpy reference."""
    kernels = segmentation_kernel
    real = kernels.cell_labels
    try:
        kernels.cell_labels = cell_labels_reference   # (what crop_window calls)
        return crop_window(labels, transform, rescue_share=rescue_share)
    finally:
        kernels.cell_labels = real


@pytest.mark.parametrize('trial', range(16))
def test_colour_means_through_a_table_are_the_float_images(trial: int) -> None:
    """Means and light gains from the bytes and the linear table: the bits of those of the
    table applied first (``cv2.LUT``); labels above the glove's colours are not counted."""
    rng = np.random.default_rng([trial, 79])
    labels = _large_labels(rng, trial)
    image = rng.integers(0, 256, (*labels.shape, 3), dtype=np.uint8)
    if trial % 2 and labels.shape[1] > 2:
        image, labels = image[:, ::2], labels[:, ::2]
    linear = cv2.LUT(np.ascontiguousarray(image), _LINEAR_RGB)
    for min_pixels in (1, 20):
        want = colour_means(linear, labels, 10, min_pixels)
        got = colour_means(image, labels, 10, min_pixels, table=_LINEAR_RGB)
        for a, b in zip(got, want, strict=True):
            assert a.dtype == b.dtype and a.tobytes() == b.tobytes()
    reference = rng.uniform(5.0, 250.0, (10, 3))
    np.testing.assert_array_equal(
        estimate_light_gains(image, labels, reference, table=_LINEAR_RGB),
        estimate_light_gains(linear, labels, reference))


@pytest.mark.parametrize('image_shape, labels_shape, table_shape', [
    ((8, 9, 3), (9, 8), (256,)),      # labels of another region
    ((8, 9), (8, 9), (256,)),         # a grey image
    ((8, 9, 4), (8, 9), (256,)),      # four channels
    ((8, 9, 3), (8, 9), (255,)),      # a short table
])
def test_colour_means_through_a_table_refuse_shapes_that_do_not_belong_together(
        image_shape: tuple[int, ...], labels_shape: tuple[int, ...],
        table_shape: tuple[int, ...]) -> None:
    """The compiled pass reads the image at every label's pixel and the table at every byte:
    mismatched shapes are a clear error, not reads past the arrays."""
    image = np.full(image_shape, 200, np.uint8)
    labels = np.ones(labels_shape, np.uint8)
    with pytest.raises(LightEstimateError, match='belong|need'):
        colour_means(image, labels, 10, 1, table=np.ones(table_shape, np.float32))


@pytest.mark.parametrize('trial', range(16))
def test_a_second_oversized_drop_after_removing_pixels_drops_nothing(trial: int) -> None:
    """What lets the coarse pass skip its second drop: once the oversized single-colour
    regions are dropped, setting any pixels to background leaves none to drop."""
    rng = np.random.default_rng([trial, 83])
    labels = _large_labels(rng, trial)
    max_pixels = float(rng.choice([3.0, 30.0, 400.0]))
    dropped = drop_oversized_components(labels, max_pixels).copy()
    dropped[rng.random(labels.shape) < rng.uniform(0.0, 0.5)] = 0
    np.testing.assert_array_equal(drop_oversized_components(dropped, max_pixels), dropped)


@pytest.mark.parametrize('trial', range(12))
def test_clear_coarse_clears_the_pixels_of_the_set_coarse_cells(trial: int) -> None:
    """The learnt static background (a coarse mask) cleared from a region's labels in
    place: numpy's gather of the coarse cells and masked store."""
    rng = np.random.default_rng([trial, 89])
    labels = _large_labels(rng, trial)
    if not labels.size:
        return
    coarse = rng.random((int(rng.integers(1, 40)), int(rng.integers(1, 40)))) < 0.3
    rows = rng.integers(0, coarse.shape[0], labels.shape[0]).astype(np.int64)
    cols = np.sort(rng.integers(0, coarse.shape[1], labels.shape[1])).astype(np.int64)
    want = labels.copy()
    want[coarse[rows][:, cols]] = 0
    got = labels.copy()
    KERNELS.clear_coarse(got, coarse, rows, cols)
    np.testing.assert_array_equal(got, want)


@pytest.mark.parametrize('trial', range(30))
def test_surface_regions_are_each_labels_opencv_components_and_outlines(trial: int) -> None:
    """The junction trim's oversized regions from one compiled pass: OpenCV's components of
    each candidate label, larger than the limit, off the image's flagged sides, with an
    outline mostly of background."""
    rng = np.random.default_rng([trial, 97])
    labels = _cluttered_glove(rng) if trial % 2 else _large_labels(rng, trial)
    candidate = rng.random(256) < 0.5
    candidate[0] = False   # (background is no region)
    max_pixels = float(rng.choice([0.0, 5.0, 60.0]))
    sides = rng.random(4) < 0.5
    off_image, surfaces = bool(trial % 3 == 1), bool(trial % 3 == 2 or trial % 4 == 0)
    share = float(rng.choice([0.3, 0.5, 0.8]))
    want = surface_regions_reference(labels, candidate, max_pixels, sides, off_image,
                                     surfaces, share)
    got = KERNELS.surface_regions(labels, candidate, max_pixels, sides, off_image, surfaces,
                                  share)
    np.testing.assert_array_equal(got, want)


@pytest.mark.parametrize('trial', range(16))
def test_label_borders_are_the_cross_erosion_against_dilation(trial: int) -> None:
    rng = np.random.default_rng([trial, 101])
    labels = np.ascontiguousarray(_large_labels(rng, trial))
    if trial % 5 == 0:
        labels[:] = 3
    border, rect = KERNELS.label_borders(labels)
    cross = cv2.getStructuringElement(cv2.MORPH_CROSS, (3, 3))
    want = (cv2.erode(labels, cross) != cv2.dilate(labels, cross) if labels.size
            else np.zeros(labels.shape, bool))
    np.testing.assert_array_equal(border, want)
    assert tuple(rect) == (cv2.boundingRect(want.view(np.uint8)) if labels.size
                           else (0, 0, 0, 0))


@pytest.mark.parametrize('trial', range(20))
def test_region_contacts_count_each_components_label_borders(trial: int) -> None:
    """Per component of ``colour_components``: the 4-neighbour pairs across a label border
    inside the image from each side (its outline, sides of label 0 in entry 0 and not
    counted as outline) and those whose labels a random adjacency joins, as NumPy counts
    them pair by pair."""
    rng = np.random.default_rng([trial, 73])
    labels = _large_labels(rng, trial)
    adjacency = rng.random((13, 13)) < 0.4        # (labels up to 12; components of 1..10)
    adjacency = adjacency | adjacency.T
    adjacency[0] = adjacency[:, 0] = False
    comp, count = KERNELS.colour_components(labels, 10)
    beside, outline = KERNELS.region_contacts(labels, comp, count, adjacency)
    want_beside = np.zeros(count + 1, np.int64)
    want_outline = np.zeros(count + 1, np.int64)
    for a, b, ca, cb in ((labels[:, :-1], labels[:, 1:], comp[:, :-1], comp[:, 1:]),
                         (labels[:-1], labels[1:], comp[:-1], comp[1:])):
        differ = a != b
        a, b, ca, cb = a[differ], b[differ], ca[differ], cb[differ]
        ok = adjacency[a, b]
        np.add.at(want_beside, ca[ok], 1)
        np.add.at(want_beside, cb[ok], 1)
        np.add.at(want_outline, ca[a > 0], 1)
        np.add.at(want_outline, cb[b > 0], 1)
    np.testing.assert_array_equal(beside, want_beside)
    np.testing.assert_array_equal(outline, want_outline)
    assert outline.sum() > 0 or len(np.unique(labels)) < 2
