"""Glove segmentation of camera frames: colour lookup, bilateral filter, crop, tiny image, blobs."""
from __future__ import annotations

import functools
import threading
import time
from concurrent.futures import Future, ThreadPoolExecutor

import cv2
import numpy as np

from colorglove_ros.core.colorimetry import srgb_to_linear
from colorglove_ros.core.errors import ColorGloveError
from colorglove_ros.core.segmentation.background import StaticBackground
from colorglove_ros.core.segmentation.blobs import color_components
from colorglove_ros.core.segmentation.color_model import (
    ColorCalibration,
    index_tables,
    load_calibration,
    read_calibration_config,
)
from colorglove_ros.core.segmentation.color_processing import (
    WASHED_OUT_MAX_SATURATION,
    SaturationEstimate,
    estimate_saturation,
    reads_plain,
    saturation_matrix,
    window_colors,
)
from colorglove_ros.core.segmentation.crop import (
    CropTransform,
    compiled_kernels,
    crop_to_tiny,
    mean_shift_crop,
)
from colorglove_ros.core.segmentation.crop_prediction import (
    CropPrediction,
    covers,
    predicted_size_crop,
    prediction_bounds,
)
from colorglove_ros.core.segmentation.detection import (
    LARGEST_PATCH_WINDOW_SHARE,
    SCENE_COLOUR_BITS,
    border_lines,
    colour_diversity,
    drop_oversized_components,
    glove_region_mask,
    junction_window,
    keep_near_junctions,
    rejected_scene_colours,
    shed_oversized_patches,
    unsupported_regions,
)
from colorglove_ros.core.segmentation.light import estimate_light_gains, gain_table
from colorglove_ros.core.segmentation.types import Blob, Observation
from colorglove_ros.core.validation import SEGMENTER_RULES, validate_segmenter_settings

__all__ = [
    'SegmentationInputError', 'SegmentationConfigError', 'GloveSegmenter',
    'STATUS_OK',
    'STATUS_NO_GLOVE', 'STATUS_TOO_SMALL', 'STATUS_OUT_OF_FRAME', 'STATUS_FRAGMENTED',
    'STAGES', 'load_segmenter',
    'keep_multicolor_components', 'keep_reaching_components', 'relabel_borders',
    'image_edges', 'border_contact_px',
]

STATUS_OK = 'ok'
STATUS_NO_GLOVE = 'no_glove'          # (almost) no glove-coloured pixels in the frame
STATUS_TOO_SMALL = 'too_small'        # glove found but too few pixels for a tiny image
STATUS_OUT_OF_FRAME = 'out_of_frame'  # the crop window lies mostly outside the image
# glove colours scattered in specks (noise, fine-grained clutter): too few of the window's
# glove pixels lie in patch-sized blobs, where the printed glove's patches are solid
STATUS_FRAGMENTED = 'fragmented'
#: Timed stages, in pipeline order (``Observation.timings_ms`` also has ``'total'``);
#: 'coarse' includes estimating the light colour.
STAGES = ('coarse', 'filter', 'classify', 'cleanup', 'borders', 'crop', 'blobs')
# Glove-like coarse pixels, which never learn static background: within this many pixels of
# one whose neighbourhood (twice as wide) shows this many glove colours.
GLOVE_MARGIN_COARSE_PX = 2
GLOVE_LIKE_COLOURS = 3
# ... and the glove's single-colour regions up to this share of the crop window's area (the
# largest printed patch, the palm's, seen flat: about 0.12)
GLOVE_LIKE_PATCH_SHARE = 0.15
# The hand's scale from patch junctions needs this many junction pixels (coarse).
JUNCTION_MIN_PIXELS = 2


class SegmentationInputError(ColorGloveError, ValueError):
    """The image given to the segmenter is not a non-empty (H, W, 3) uint8 array."""


class SegmentationConfigError(ColorGloveError, ValueError):
    """Bad segmenter settings (unknown key or out-of-range value)."""


def keep_multicolor_components(labels: np.ndarray, min_colors: int = 3,
                               min_share: float = 0.03, min_pixels: int = 4,
                               reattach_radius: int = 0,
                               reattach_max_share: float = 0.2) -> np.ndarray:
    """Zero every 8-connected glove component with fewer than ``min_colors`` colours each
    holding at least ``min_share`` of its pixels (and ``min_pixels``). The printed glove shows
    many colours side by side; glove-coloured clutter and noise specks show one or two.

    With ``reattach_radius`` > 0, a component with too few colours is kept after all when it
    lies within that many pixels of a kept one (a gap of at most ``reattach_radius`` - 1
    pixels) and has at most ``reattach_max_share`` times the kept components' pixels: a
    fingertip or finger that a thin line of unclassified pixels has cut off from the hand shows
    only one or two colours by itself (how large such pieces get: docs/RESULTS.md, Tuning
    notes). Glove-coloured clutter within that reach is kept too, like clutter
    touching the glove."""
    if reattach_radius < 0 or not reattach_max_share >= 0.0:
        raise SegmentationConfigError(
            f'need reattach_radius >= 0 and reattach_max_share >= 0; got {reattach_radius}, '
            f'{reattach_max_share}')
    labels = np.asarray(labels, np.uint8)
    nl = int(labels.max()) + 1
    if nl <= 1:
        return labels
    # the components and each one's pixels of each colour, in one compiled pass
    comp, hist = compiled_kernels().glove_components(labels, nl)
    n = len(hist)
    hist = hist[:, 1:]
    size = hist.sum(axis=1, keepdims=True)
    big = (hist >= np.maximum(min_share * size, min_pixels)).sum(axis=1)
    keep = big >= min_colors
    keep[0] = True
    if keep.all():
        return labels
    if reattach_radius > 0 and keep[1:].any():
        kept_table = keep.view(np.uint8).copy()
        kept_table[0] = 0                       # background is not a kept component
        kept = kept_table.take(comp)
        width = 2 * int(reattach_radius) + 1
        near = cv2.dilate(kept, cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (width, width)))
        reached = np.zeros(n, dtype=bool)
        reached[comp[near > 0]] = True          # includes background (0), which stays kept
        small = size[:, 0] <= reattach_max_share * size[kept_table.view(bool), 0].sum()
        keep |= reached & small
    return labels * keep.view(np.uint8).take(comp)   # 5x faster than np.where


def keep_reaching_components(labels: np.ndarray, reached: np.ndarray, removed: np.ndarray
                             ) -> np.ndarray:
    """``labels`` (0 = background) with only the 8-connected glove components that hold a
    ``reached`` pixel, less the ``removed`` pixels (both (H, W) bool): how the finer grid of a
    two-resolution cleanup follows the coarser grid's decisions (``reached``: its kept glove,
    ``removed``: the glove it took out), shapes and thin gaps taken from the finer grid."""
    n, comp = cv2.connectedComponents((labels > 0).view(np.uint8), connectivity=8,
                                      ltype=cv2.CV_32S)
    keep = np.zeros(n, bool)
    keep[comp[reached]] = True
    keep[0] = False
    mask = keep.take(comp)
    mask &= ~removed
    return labels * mask.view(np.uint8)


#: sRGB byte -> linear RGB in 0..255 (float32): mixed pixels are linear mixes there.
_LINEAR_RGB = (255.0 * srgb_to_linear(np.arange(256) / 255.0)).astype(np.float32)
_CROSS = cv2.getStructuringElement(cv2.MORPH_CROSS, (3, 3))
_NO_SCENE = np.zeros(0, bool)   # no scene colours (the classification's empty table)


@functools.lru_cache(maxsize=64)
def _reference_steps(distances: tuple[int, ...], row_stride: int) -> np.ndarray:
    """Flat index steps (S,) to the pixels ``distances`` away along the 8 compass directions
    (cached: read only)."""
    steps = np.array([d * (sy * row_stride + sx) for d in distances
                      for sy in (-1, 0, 1) for sx in (-1, 0, 1) if sy or sx], np.int64)
    steps.flags.writeable = False
    return steps


def relabel_borders(image: np.ndarray, labels: np.ndarray, passes: int = 3,
                    distances: tuple[int, ...] = (2, 4), mix_tolerance: float = 0.25,
                    min_residual: float = 10.0) -> np.ndarray:
    """Re-decide the labels of pixels on a label border, i.e. with a 4-neighbour of another
    label (colour borders and the glove silhouette).

    Such pixels often mix two colours (anti-aliasing, motion blur, JPEG chroma subsampling)
    and so fall outside every colour model (background) or into a third colour between the
    two (orange between red and yellow). Each takes the label of the *sure* pixel (not on a
    border), among those ``distances`` pixels away in the 8 compass directions, whose
    linear-RGB colour ``a`` is nearest its own ``c``: for a mix of two colours, the one it
    holds more of. A pixel with a glove label keeps it, though, when ``c`` is no mix of
    ``a`` and the nearest sure colour ``b`` of another label: farther from the segment
    ``a``-``b`` than ``mix_tolerance`` times its length and than ``min_residual`` (linear
    RGB, 0..255); so a thin patch of a real colour survives. With no sure pixel in reach a
    label stays. ``passes`` repeats this: a band of wrong labels 3 or more pixels wide has a
    sure core of its own, and each pass peels a pixel off each side. Only the bounding box
    of the border pixels is read; ``image`` is the (H, W, 3) uint8 RGB image ``labels`` came
    from.
    """
    labels = np.asarray(labels, dtype=np.uint8)
    if passes < 1 or not distances or min(labels.shape) < 3:
        return labels
    kernels = compiled_kernels()
    border, rect = kernels.label_borders(np.ascontiguousarray(labels))
    bx, by, bw, bh = (int(v) for v in rect)
    if not bw:
        return labels
    pad = max(distances)
    h, w = labels.shape
    y0, y1 = max(by - pad, 0), min(by + bh + pad, h)
    x0, x1 = max(bx - pad, 0), min(bx + bw + pad, w)
    # The bounding box padded by the reach (its frame not sure): a step is a flat offset.
    box = cv2.copyMakeBorder(labels[y0:y1, x0:x1], pad, pad, pad, pad, cv2.BORDER_CONSTANT,
                             value=kernels.UNSURE)
    rgb = cv2.copyMakeBorder(np.ascontiguousarray(image[y0:y1, x0:x1]), pad, pad, pad, pad,
                             cv2.BORDER_CONSTANT)
    border_box = np.zeros(box.shape, np.uint8)
    border_box[pad:-pad, pad:-pad] = border[y0:y1, x0:x1]
    kernels.relabel_passes(
        box, rgb.reshape(-1, 3), _LINEAR_RGB, border_box,
        _reference_steps(tuple(distances), box.shape[1]), pad, passes,
        np.float32(mix_tolerance ** 2), np.float32(min_residual ** 2))
    inner = box[pad:-pad, pad:-pad]
    out = labels.copy()
    out[y0:y1, x0:x1] = inner
    return out


def image_edges(roi: tuple[int, int, int, int], reduction: int, width: int,
                height: int) -> tuple[bool, bool, bool, bool]:
    """Which sides (left, right, top, bottom) of the region of interest ``roi`` = (x0, x1,
    y0, y1) (full-image bounds, labels ``reduction`` pixels wide) are the border of the
    ``width`` x ``height`` image."""
    x0, x1, y0, y1 = roi
    return x0 == 0, x1 + reduction > width, y0 == 0, y1 + reduction > height


def border_contact_px(labels: np.ndarray, roi: tuple[int, int, int, int], reduction: int,
                      width: int, height: int,
                      window: tuple[int, int, int, int] | None = None) -> int:
    """How many full-image pixels along the image's outermost rows and columns the glove
    labels of the region of interest ``roi`` = (x0, x1, y0, y1) (full-image bounds of
    ``labels``, each label ``reduction`` pixels wide) cover; with ``window`` = (x0, x1, y0,
    y1) (bounds in ``labels``' pixels: the hand's crop window) only the border pixels inside
    it (glove-coloured clutter running off the image elsewhere does not cut the hand)."""
    rows, cols = labels.shape
    wx0, wx1, wy0, wy1 = window if window is not None else (0, cols, 0, rows)
    wx0, wy0 = max(wx0, 0), max(wy0, 0)
    wx1, wy1 = min(wx1, cols), min(wy1, rows)
    if wx1 <= wx0 or wy1 <= wy0:
        return 0
    left, right, top, bottom = image_edges(roi, reduction, width, height)
    on_border = (left and wx0 == 0, right and wx1 == cols, top and wy0 == 0,
                 bottom and wy1 == rows)
    return reduction * sum(int(np.count_nonzero(line))
                           for line in border_lines(labels[wy0:wy1, wx0:wx1], on_border))


def _coarse_indices(coarse_shape: tuple[int, int], origin: tuple[int, int], r: int,
                    shape: tuple[int, int], image_hw: tuple[int, int]
                    ) -> tuple[np.ndarray, np.ndarray]:
    """The coarse rows and columns (int64) of a mask over the downsampled frame (of
    ``coarse_shape``) at the pixels of a region of interest starting at full pixel
    ``origin`` (x, y), ``r`` full pixels a side, ``shape`` (rows, cols); ``image_hw`` is the
    full frame's size."""
    ch, cw = coarse_shape
    h, w = image_hw
    xs = origin[0] + r * np.arange(shape[1]) + 0.5 * (r - 1)
    ys = origin[1] + r * np.arange(shape[0]) + 0.5 * (r - 1)
    cols = np.clip((xs + 0.5) * cw / w, 0, cw - 1).astype(np.int64)
    rows = np.clip((ys + 0.5) * ch / h, 0, ch - 1).astype(np.int64)
    return rows, cols


#: What :meth:`GloveSegmenter._without_search` gives: the hand's window ((cx, cy), half; full
#: pixels), the light table, the scene colours, the static background and the coarse frame.
_Followed = tuple[tuple[tuple[float, float], float], 'np.ndarray | None', 'np.ndarray | None',
                  'np.ndarray | None', np.ndarray]


#: What the region of interest's labelling rules out with (:meth:`GloveSegmenter._label_roi`):
#: the light table, the scene colours, the static background and the crop prediction.
_Masks = tuple['np.ndarray | None', 'np.ndarray | None', 'np.ndarray | None',
               'CropPrediction | None']
#: The coarser grid of ``cleanup_factor`` needs at least this many cells a side.
MIN_CLEANUP_CELLS = 8


def _reduced(image: np.ndarray, box: tuple[int, int, int, int], r: int) -> np.ndarray:
    """``image``'s pixels in ``box`` (x0, x1, y0, y1; sides multiples of ``r``), averaged over
    ``r`` x ``r`` blocks (a view when ``r`` is 1)."""
    x0, x1, y0, y1 = box
    if r == 1:
        return image[y0:y1, x0:x1]
    return cv2.resize(image[y0:y1, x0:x1], ((x1 - x0) // r, (y1 - y0) // r),
                      interpolation=cv2.INTER_AREA)


def _cells(mask: np.ndarray, factor: int, box: tuple[int, int, int, int]) -> np.ndarray:
    """``mask`` (a label grid each of whose cells is ``factor`` x ``factor`` pixels of a finer
    grid) at the finer grid's pixels in ``box`` (x0, x1, y0, y1); pixels past the last cell
    take the last cell's value."""
    x0, x1, y0, y1 = box
    rows = np.minimum(np.arange(y0, y1) // factor, mask.shape[0] - 1)
    cols = np.minimum(np.arange(x0, x1) // factor, mask.shape[1] - 1)
    return mask[rows][:, cols]


_LEARNER: list[ThreadPoolExecutor] = []
_LEARNER_LOCK = threading.Lock()


def _in_region(found: tuple[tuple[float, float], float] | None, x0: int, y0: int
               ) -> tuple[tuple[float, float], float] | None:
    """A coarse window ``found`` ((cx, cy), half) of the whole coarse frame in the pixels of
    a region starting at (``x0``, ``y0``)."""
    return None if found is None else ((found[0][0] - x0, found[0][1] - y0), found[1])


def _learner() -> ThreadPoolExecutor:
    """The one worker thread on which segmenters with ``learn_in_thread`` learn their
    static background (started on first use, shared by every segmenter of the process)."""
    with _LEARNER_LOCK:
        if not _LEARNER:
            _LEARNER.append(ThreadPoolExecutor(1, thread_name_prefix='static-background'))
        return _LEARNER[0]


def _check_image(image: object) -> np.ndarray:
    if not isinstance(image, np.ndarray):
        raise SegmentationInputError(f'expected a numpy array, got {type(image).__name__}')
    if image.dtype != np.uint8:
        raise SegmentationInputError(f'expected dtype uint8, got {image.dtype}')
    if image.ndim != 3 or image.shape[2] != 3:
        raise SegmentationInputError(f'expected shape (H, W, 3), got {image.shape}')
    if image.shape[0] == 0 or image.shape[1] == 0:
        raise SegmentationInputError(f'empty image of shape {image.shape}')
    return image


class GloveSegmenter:
    """Turns RGB camera frames into :class:`Observation` s (paper section 4.3).

    Pipeline: a coarse pass (area-downsampled frame, table lookup, median, mean-shift) finds
    the glove, and its glove pixels against the calibration's reference colours give the
    light colour (:func:`estimate_light_gains`, refined ``light_passes`` - 1 times on the
    corrected coarse frame; 0 for no correction). Only a region around the glove
    (``roi_margin`` times the coarse window, reduced so the crop spans at most
    ``max_roi_cells`` pixels) is bilateral-filtered, classified at (near) full resolution
    with the light colour divided out (von Kries in linear RGB, fused into the table
    lookup) and cleaned (median filter, :func:`keep_multicolor_components` with cut-off
    fingertips within ``reattach_radius`` region pixels re-attached, then
    :func:`relabel_borders`); :func:`crop_to_tiny` there gives the tiny image and crop;
    connected components per colour give the blobs. A glove whose pixels run along the
    image border for more than ``max_border_contact`` times the crop window's side is
    ``cut_by_border`` (partly outside the image; a fingertip grazing the border is not).

    Finding the glove, not its colours (``core.segmentation.detection``): on both passes,
    single-colour regions larger than ``max_patch_fraction`` of the image are background,
    and only pixels within ``diversity_window`` coarse pixels of a window showing
    ``min_region_colors`` glove colours (each on ``diversity_density`` of it) count; then a
    single-colour region larger than ``max_patch_window_share`` of the hand's window whose
    outline runs mostly along background (a petal, a sleeve, a wooden edge touching the
    glove, which the filters above keep as part of its region) is background: on the coarse
    pass with the window found where three glove colours meet (``junction_window``), in the
    region of interest with the coarse window (``shed_oversized_patches``); 0, the default,
    turns this off (0.15: the palm's patch seen flat is about 0.12 of the window). In the
    region of interest, after the border relabelling, a single-colour region larger than
    ``junction_min_share`` of the hand's window (by default any printed patch,
    ``LARGEST_PATCH_WINDOW_SHARE``) keeps only its pixels within ``junction_reach`` times the
    hand's half window of a patch junction (``keep_near_junctions``; 0 turns this off): the
    crop and the blobs then hold the hand and not the surface it touches. With
    ``junction_surfaces_only`` 1 only such regions whose outline runs mostly along background
    are trimmed (a petal or a face touching the glove; a patch inside the glove, however
    large, is surrounded by its neighbours, though one at the glove's silhouette may not be),
    so a share under the largest patch's reaches the smaller pieces of clutter while sparing
    most of the glove's own patches. Two gates keep a glove without clutter whole: the trim
    runs only on a frame whose crop is pulled, the window of every glove pixel more than
    ``junction_min_pull`` times the junctions' own (0: every frame), and is kept only where it
    shrinks that window to at most ``junction_max_window_kept`` of its size (0: always kept;
    a finger cut back at the silhouette moves it little). The same for the
    regions that reach the image's border only, with ``sleeve_reach`` (0 off), oversized
    meaning larger than ``sleeve_min_share`` of the hand's window: a sleeve of a glove colour
    (a red sleeve is glove red) runs off the image, and joined to the glove it would pull the
    crop down the forearm and make the hand look cut by the border, however short its
    visible piece. Colours
    the coarse pass labelled glove but found to be background (at least
    ``scene_colour_min_share`` of the coarse frame in one quantised colour: surfaces, not
    small clutter) are the scene's own colours in this frame: the region of interest labels
    them background (0 disables). Last, with ``glove_contact_share`` > 0, a single-colour
    region of the region of interest less of whose outline than that borders a colour its
    colour borders on the printed glove (``unsupported_regions``; the standard glove's colour
    adjacency, ``core.hand.glove.default_colour_adjacency``) is background, and so are the
    components left with too few colours: a face, wood or petals labelled red, orange and pink
    meet in pairs the glove never joins, beside or touching the hand. With
    ``glove_contact_min_drop`` > 0 the regions are dropped only when they hold at least that
    share of the region of interest's glove pixels (0: always): clutter beside the hand is
    many such pixels, while on a glove without clutter the few are its own patches at the
    silhouette (a fingertip meeting the palm, colours the printed glove never joins), whose
    loss makes the hand look smaller.

    Static background (``background_frames`` > 0, ``core.segmentation.background``): a coarse
    pixel that held its colour that many frames, outside the glove-like pixels, is background;
    with ``background_memory`` 1 a pixel uncovered showing the colour it had when it was last
    learnt is background at once (the band a moving arm sweeps, glove-coloured surfaces
    beside the hand, would otherwise wait ``background_frames`` frames again).

    Crop following (``follow_margin`` > 0): a segmenter is fed one camera's frames in order.
    After a frame with a hand, the next frame's coarse search looks only within
    ``follow_margin`` times the hand's coarse window around where it was, and the static
    background learns its glove-like mask there; when the hand is not found there, or its
    region of interest reaches past that region's edge inside the image, the whole coarse
    frame is searched again (as after a frame without a hand). :meth:`lose_track` forgets
    the hand for frames that do not follow each other. With ``search_every`` > 1 the coarse
    pass runs on only one frame in ``search_every`` while the hand is found: on the frames
    between, the region of interest is placed around the last frame's crop (at the last
    search's window size) and classified with the last search's light colour and scene
    colours and this frame's learnt static background (which learns from the frame with the
    last search's glove-like pixels kept out); a frame whose hand is not found there with its
    crop window inside the region of interest is searched after all.

    Crop prediction (``prediction_margin`` > 0; :meth:`process`'s ``prediction``, the crop
    window the tracked hand of an earlier frame predicts,
    ``core.segmentation.crop_prediction``): when its centre lies in the region of interest,
    glove labels farther than ``prediction_margin`` times its window are background (a
    glove-coloured surface touching the hand is cut there) and the crop's mean shift starts
    at it; with ``prediction_max_ratio`` (0 off; above 1) a crop more than that many times
    larger or smaller than the predicted one is trimmed to the predicted size
    (``predicted_size_crop``).

    Two resolutions (``cleanup_factor`` > 1; 1 is off): the region of interest's wide clutter
    filters (:meth:`_glove_only`: oversized single-colour regions, the colour-diversity region
    and its margin) run on it averaged over ``cleanup_factor`` x ``cleanup_factor`` blocks, a
    grid with that many times fewer pixels a side; at the region's own resolution only the
    box around the glove kept there is filtered and classified, and there a glove component
    stays when it reaches a kept cell (:func:`keep_reaching_components`) less the pixels of
    the cells the coarser filter removed. The multi-colour component test, the border
    relabelling, the crop, the tiny image and the blobs are the region's own resolution as
    before. A region of interest under ``MIN_CLEANUP_CELLS`` cells a side on that grid is
    cleaned at its own resolution.

    Another camera's colour processing (``saturation_rate`` > 0; 0, the default, is off):
    a camera that washes colours out (or boosts them) shows the glove's palette with its
    saturation scaled, and washed-out yellow and lime fall outside the colour model first.
    Each frame with a hand, the coarse glove pixels inside its window (patch interiors)
    against the calibration's reference colours give the saturation that explains them best
    under one light colour (``core.segmentation.color_processing.estimate_saturation``); a
    running value moves ``saturation_rate`` of the way to it per such frame, and the colour
    table used from then on undoes the settled saturation (compiled once per value,
    ``resaturated_lut``), with the light colour estimated against the references seen through
    it.

    The static background's learning from a frame (its glove-like mask and update) is
    needed only by the next frame: with ``learn_in_thread`` 1 (0, inline, is the class's
    default and ``config/color_calibration.yaml``'s) it runs on one worker thread shared
    by the process's segmenters while the region of interest is segmented (OpenCV and NumPy
    release the GIL), and :meth:`process` waits for it before returning, so the
    observations and what is learnt are the same. A caller that publishes the observation
    can also have it wait (``process(..., defer_learning=True)``) and run it after
    publishing (:meth:`learn_deferred`): off the frame's latency, with the same observations
    (the next :meth:`process` runs a learning still pending first).

    Every setting is checked (ranges, odd median kernel, finite numbers) by
    ``core.validation.validate_segmenter_settings`` however the segmenter is built; a bad one
    raises :class:`SegmentationConfigError` naming ``source`` (the settings' file, if any)
    and the setting.
    """

    def __init__(self, calibration: ColorCalibration, *, coarse_factor: int = 4,
                 roi_margin: float = 1.5, max_roi_cells: int = 160,
                 bilateral_diameter: int = 3, bilateral_sigma_color: float = 45.0,
                 bilateral_sigma_space: float = 3.0, median_size: int = 3,
                 border_passes: int = 3, border_distances: tuple[int, ...] = (2, 4),
                 min_glove_pixels: int = 300, min_inside_fraction: float = 0.5,
                 min_blob_pixels: int = 12, min_component_colors: int = 3,
                 reattach_radius: int = 3, reattach_max_share: float = 0.2,
                 light_passes: int = 1, min_blob_share: float = 0.85,
                 max_border_contact: float = 0.1, diversity_window: int = 24,
                 min_region_colors: int = 6, diversity_density: float = 0.01,
                 max_patch_fraction: float = 0.1, max_patch_window_share: float = 0.0,
                 junction_reach: float = 0.0,
                 junction_min_share: float = LARGEST_PATCH_WINDOW_SHARE,
                 junction_surfaces_only: int = 0, junction_min_pull: float = 0.0,
                 junction_max_window_kept: float = 0.0, sleeve_reach: float = 0.0,
                 sleeve_min_share: float = LARGEST_PATCH_WINDOW_SHARE,
                 glove_contact_share: float = 0.0, glove_contact_min_drop: float = 0.0,
                 scene_colour_min_share: float = 0.001,
                 background_frames: int = 0, background_tolerance: float = 12.0,
                 background_memory: int = 0,
                 follow_margin: float = 0.0, search_every: int = 1,
                 prediction_margin: float = 0.0, prediction_max_ratio: float = 0.0,
                 saturation_rate: float = 0.0, washed_out_colors: int = 0,
                 cleanup_factor: int = 1,
                 learn_in_thread: int = 0,
                 source: str = 'GloveSegmenter') -> None:
        # every keyword argument but ``source`` is a setting named in SEGMENTER_RULES: checked
        # and converted (int, float, tuple of ints) in one place, kept as the attribute of
        # the same name
        given = {name: value for name, value in locals().items() if name in SEGMENTER_RULES}
        self.calibration = calibration
        for name, value in validate_segmenter_settings(given, source,
                                                       SegmentationConfigError).items():
            setattr(self, name, value)
        self.source = source
        self.background = StaticBackground(self.background_frames, self.background_tolerance,
                                           remember=bool(self.background_memory))
        # the camera's saturation, settled over the frames with a hand (saturation_rate > 0)
        # or by a search for a glove the colour table misses (washed_out_colors > 0)
        self._saturation = (None if self.saturation_rate <= 0 and self.washed_out_colors <= 0
                            else SaturationEstimate(calibration.lut, calibration.bits,
                                                    self.saturation_rate or 1.0))
        # the hand's coarse window of the last frame with a hand ((cx, cy), half in coarse
        # pixels, and the coarse frame's shape), which the next frame's search follows
        self._followed: tuple[tuple[tuple[float, float], float], tuple[int, int]] | None = None
        self._found: tuple[tuple[tuple[float, float], float], tuple[int, int]] | None = None
        # search_every > 1: the last coarse search's light table and scene colours, the frames
        # since it, and the window ((cx, cy), half in full pixels; the frame's (h, w)) the
        # next frame's region of interest follows without a search
        self._searched: tuple[np.ndarray | None, np.ndarray | None] | None = None
        self._since_search = 0
        self._window: tuple[tuple[tuple[float, float], float], tuple[int, int]] | None = None
        self._glove_like_mask: np.ndarray | None = None   # the last search's, coarse
        self._washed_out_turn = 0   # which saturation the next search for a missed glove tries
        # which colours border each other on the printed glove: built when the glove-contact
        # filter first runs (glove_contact_share > 0, a public attribute, may be set later)
        self._adjacency: np.ndarray | None = None
        # learn_in_thread: the static background's learning from this frame, running on
        # the shared worker while the region of interest is segmented (done before
        # :meth:`process` returns)
        self._learning: Future[None] | None = None
        # process(defer_learning=True): this frame's learning, left for learn_deferred
        self._defer_learning = False
        self._deferred: tuple[np.ndarray, tuple[int, int, int, int], np.ndarray,
                              tuple[tuple[float, float], float] | None] | None = None
        compiled_kernels()   # (compiled or loaded now, not on the first frame)

    def lose_track(self) -> None:
        """Forget the followed hand: the next frame is searched whole (for frames that do not
        follow each other, such as a set of independent test images)."""
        self._followed = self._found = self._window = self._searched = None

    def settings(self) -> dict[str, object]:
        """The segmenter's settings (the keyword arguments it was built with, checked)."""
        return {name: getattr(self, name) for name in SEGMENTER_RULES}

    def fresh(self, **changed: object) -> GloveSegmenter:
        """A segmenter with the same calibration and settings but ``changed`` (checked like
        any setting) and nothing learnt (its own static background): one per camera stream,
        or this one with new settings."""
        return GloveSegmenter(self.calibration, **{**self.settings(), **changed},
                              source=self.source)

    # ------------------------------------------------------------------ helpers
    def _classify(self, image: np.ndarray, table: np.ndarray | None,
                  scene: np.ndarray | None = None) -> np.ndarray:
        """The calibration's labels of ``image`` after the light ``table``, with the
        camera's settled saturation undone (``saturation_rate`` > 0); 0 where ``scene`` (the
        frame's scene colours, :func:`scene_colour_table`) holds the pixel's colour."""
        return compiled_kernels().classify(
            image, self._lut(), index_tables(self.calibration.bits, table),
            _NO_SCENE if scene is None else scene, index_tables(SCENE_COLOUR_BITS))

    def _lut(self) -> np.ndarray:
        """The colour table :meth:`_classify` labels by: the calibration's, or with the
        camera's settled saturation undone (``saturation_rate`` > 0)."""
        return self.calibration.lut if self._saturation is None else self._saturation.lut()

    def _reference(self) -> np.ndarray:
        """The glove's reference colours (linear RGB) as this camera shows them: through its
        settled saturation (``saturation_rate`` > 0), which the table then undoes."""
        ref = self.calibration.reference_linear_rgb
        if self._saturation is None:
            return ref
        return ref @ saturation_matrix(self._saturation.saturation).T

    def _glove_only(self, labels: np.ndarray, reduction: float, image_pixels: int,
                    oversized_dropped: bool = False) -> np.ndarray:
        """Background surfaces out of a label image whose pixels are ``reduction`` image
        pixels wide: single-colour regions larger than ``max_patch_fraction`` of the image
        (``image_pixels``; with ``oversized_dropped`` the caller has dropped them, and then
        only set pixels to background, which leaves none), then everything farther than
        ``diversity_window`` (coarse pixels) from a window showing ``min_region_colors``
        glove colours (``core.segmentation.detection``)."""
        if not oversized_dropped:
            labels = drop_oversized_components(
                labels, self.max_patch_fraction * image_pixels / reduction ** 2)
        if self.diversity_window > 0:
            window = max(int(round(self.diversity_window * self.coarse_factor / reduction)), 1)
            labels = labels * glove_region_mask(labels, self.calibration.num_colors, window,
                                                self.min_region_colors,
                                                self.diversity_density).view(np.uint8)
        return labels

    def _glove_like(self, labels: np.ndarray,
                    window: tuple[tuple[float, float], float] | None) -> np.ndarray:
        """(H, W) bool: the coarse pixels that may be the glove, which must not become
        static background however still the hand is held: those within
        ``GLOVE_MARGIN_COARSE_PX`` of a pixel whose small neighbourhood shows at least
        ``GLOVE_LIKE_COLOURS`` glove colours, and the single-colour regions reaching such a
        pixel that are no larger than a printed patch can be in the coarse crop ``window``
        (``GLOVE_LIKE_PATCH_SHARE`` of its area). A uniform or two-coloured surface beside
        the hand is not glove-like."""
        side = 2 * GLOVE_MARGIN_COARSE_PX + 1
        mixed = colour_diversity(labels, self.calibration.num_colors, 2 * side - 1,
                                 0.5 / side ** 2) >= GLOVE_LIKE_COLOURS
        out = cv2.dilate(mixed.view(np.uint8), cv2.getStructuringElement(
            cv2.MORPH_RECT, (side, side))).view(bool)
        if window is None or not mixed.any():
            return out
        # (one compiled pass labels every colour's regions)
        compiled_kernels().small_patches_reached(
            labels, self.calibration.num_colors, mixed,
            GLOVE_LIKE_PATCH_SHARE * (2.0 * window[1]) ** 2, out)
        return out

    def _label_roi(self, roi: np.ndarray, origin: tuple[int, int], r: int,
                   image_hw: tuple[int, int], masks: _Masks) -> np.ndarray:
        """Labels of ``roi`` (filtered RGB of the region of interest, or of a box in it,
        whose pixel (0, 0) starts at full pixel ``origin`` (x, y), each ``r`` full pixels a
        side) with the light ``table`` of ``masks`` and without what it rules out: glove
        colour outside the predicted window, the frame's scene colours, the learnt static
        background."""
        table, scene, static, prediction = masks
        labels = self._classify(roi, table, scene)
        if prediction is not None:   # glove colour outside the predicted window is not the hand
            px0, px1, py0, py1 = prediction_bounds(prediction, self.prediction_margin,
                                                   origin, r, labels.shape)
            inside = labels[py0:py1, px0:px1].copy()
            labels[...] = 0
            labels[py0:py1, px0:px1] = inside
        if static is not None:
            rows, cols = _coarse_indices(static.shape, origin, r, labels.shape, image_hw)
            compiled_kernels().clear_coarse(labels, static, rows, cols)
        return labels

    def _clean_roi(self, labels: np.ndarray, r: int, image_pixels: int, chalf: float,
                   region: bool = True) -> np.ndarray:
        """The region of interest's (median-filtered) ``labels``, each ``r`` full pixels a
        side, without what is not the glove (:meth:`_glove_only` unless not ``region``,
        :func:`keep_multicolor_components`, :func:`shed_oversized_patches` at the coarse
        window's half side ``chalf``)."""
        if region:
            labels = self._glove_only(labels, r, image_pixels)
        if self.min_component_colors > 1:
            labels = keep_multicolor_components(labels, self.min_component_colors,
                                                min_pixels=max(self.min_blob_pixels // (r * r), 2),
                                                reattach_radius=self.reattach_radius,
                                                reattach_max_share=self.reattach_max_share)
        # single-colour surfaces larger than a patch at the (coarse) hand window's scale
        return shed_oversized_patches(labels, self.max_patch_window_share,
                                      ((0.0, 0.0), chalf / r))

    def _two_resolution(self, image: np.ndarray, roi_box: tuple[int, int, int, int], r: int,
                        masks: _Masks, chalf: float
                        ) -> tuple[np.ndarray, np.ndarray, int, int] | None:
        """The region of interest ``roi_box`` (full-pixel bounds, sides multiples of ``r``)
        cleaned in two resolutions (``cleanup_factor``; the class docstring): (the glove's
        box's filtered RGB at ``r``, its cleaned labels, its origin (x, y) in the ROI's label
        pixels). None when the coarser grid would be too small (then the ROI is cleaned at
        ``r``)."""
        f = self.cleanup_factor
        x0, x1, y0, y1 = roi_box
        big = r * f
        rows_c, cols_c = (y1 - y0) // big, (x1 - x0) // big
        if min(rows_c, cols_c) < MIN_CLEANUP_CELLS:
            return None
        h, w = image.shape[:2]
        small = self._filter(_reduced(image, (x0, x0 + cols_c * big, y0, y0 + rows_c * big),
                                      big))
        found = self._median(self._label_roi(small, (x0, y0), big, (h, w), masks))
        kept = self._glove_only(found, big, h * w) > 0
        rows, cols = (y1 - y0) // r, (x1 - x0) // r
        kx, ky, kw, kh = cv2.boundingRect(kept.view(np.uint8))
        if not kw:
            return (np.zeros((1, 1, 3), np.uint8), np.zeros((1, 1), np.uint8), 0, 0)
        # the kept cells' box at r, padded so that the filters and the border relabelling
        # inside it read the pixels they would read in the whole region of interest
        pad = (f + self.bilateral_diameter // 2 + self.median_size // 2
               + max(self.border_distances, default=0) + 1)
        bx0, bx1 = max(kx * f - pad, 0), min((kx + kw) * f + pad, cols)
        by0, by1 = max(ky * f - pad, 0), min((ky + kh) * f + pad, rows)
        roi = self._filter(_reduced(image, (x0 + bx0 * r, x0 + bx1 * r, y0 + by0 * r,
                                            y0 + by1 * r), r))
        labels = self._median(self._label_roi(roi, (x0 + bx0 * r, y0 + by0 * r), r, (h, w),
                                              masks))
        box = (bx0, bx1, by0, by1)
        labels = keep_reaching_components(labels, _cells(kept, f, box),
                                          _cells((found > 0) & ~kept, f, box))
        return roi, self._clean_roi(labels, r, h * w, chalf, region=False), bx0, by0

    def _coarse_labels(self, small: np.ndarray, table: np.ndarray | None = None,
                       reduction: float = 1.0, image_pixels: int = 0,
                       static: np.ndarray | None = None) -> np.ndarray:
        labels = self._median(self._classify(small, table))
        if static is not None:
            # a surface larger than any glove is judged whole, before the learnt background
            # cuts it into pieces that each pass for smaller (joined to the glove, they would
            # swamp the glove's share of colours in keep_multicolor_components)
            labels = drop_oversized_components(
                labels, self.max_patch_fraction * (image_pixels or labels.size) / reduction ** 2)
            labels[static] = 0
        # (removing pixels only shrinks regions: none is oversized any more)
        labels = self._glove_only(labels, reduction, image_pixels or labels.size,
                                  oversized_dropped=static is not None)
        if self.max_patch_window_share > 0:   # (finding the junctions costs a few loops)
            labels = shed_oversized_patches(
                labels, self.max_patch_window_share,
                junction_window(labels, self.calibration.num_colors, JUNCTION_MIN_PIXELS))
        if self.min_component_colors > 1:
            # no re-attaching here: it changes neither the coarse window nor the light estimate
            labels = keep_multicolor_components(labels, self.min_component_colors, min_pixels=2)
        return labels

    def _follow_region(self, shape: tuple[int, int]) -> tuple[int, int, int, int] | None:
        """Coarse-pixel bounds (x0, x1, y0, y1) of the region the search follows the last
        frame's hand in, or None (nothing to follow, following off, another frame size)."""
        if self.follow_margin <= 0.0 or self._followed is None or self._followed[1] != shape:
            return None
        (cx, cy), half = self._followed[0]
        reach = self.follow_margin * half
        x0, x1 = max(int(np.floor(cx - reach)), 0), min(int(np.ceil(cx + reach)) + 1, shape[1])
        y0, y1 = max(int(np.floor(cy - reach)), 0), min(int(np.ceil(cy + reach)) + 1, shape[0])
        return (x0, x1, y0, y1) if x1 - x0 >= 2 and y1 - y0 >= 2 else None

    def _inside(self, found: tuple[tuple[float, float], float],
                region: tuple[int, int, int, int], shape: tuple[int, int]) -> bool:
        """Whether the region of interest of coarse window ``found`` (``roi_margin`` times
        it) stays inside ``region``, except where ``region`` reaches the frame's edge."""
        (cx, cy), half = found
        reach = self.roi_margin * half
        x0, x1, y0, y1 = region
        return ((x0 == 0 or cx - reach >= x0) and (x1 == shape[1] or cx + reach <= x1 - 1)
                and (y0 == 0 or cy - reach >= y0) and (y1 == shape[0] or cy + reach <= y1 - 1))

    def _detect(self, small: np.ndarray, region: tuple[int, int, int, int], reduction: float,
                pixels: int, static: np.ndarray | None, min_px: int
                ) -> tuple[tuple[tuple[float, float], float] | None, np.ndarray | None,
                           np.ndarray]:
        """The coarse search within ``region`` (coarse-pixel bounds) of the coarse frame
        ``small``: the hand's window ((cx, cy), half) in coarse pixels or None, the light
        correction table and the region's labels (``pixels``: the full
        frame's pixel count; ``min_px``: the fewest glove pixels of a hand, coarse)."""
        x0, x1, y0, y1 = region
        part = small[y0:y1, x0:x1]
        static_part = None if static is None else static[y0:y1, x0:x1]
        labels = self._coarse_labels(part, None, reduction, pixels, static_part)
        table = None
        gains = np.ones(3)
        seen = part
        for k in range(self.light_passes):
            if k:   # refine: classify the corrected coarse frame, estimate what is left
                seen = cv2.LUT(part, table)
                labels = self._coarse_labels(part, table, reduction, pixels, static_part)
            gains = gains * estimate_light_gains(seen, labels, self._reference(),
                                                 table=_LINEAR_RGB)
            table = gain_table(gains)
        found = mean_shift_crop(labels, min_pixels=min_px)
        if found is not None:
            (cx, cy), half = found
            found = ((cx + x0, cy + y0), half)
        return found, table, labels

    def _window_saturation(self, small: np.ndarray, region: tuple[int, int, int, int],
                           labels: np.ndarray, found: tuple[tuple[float, float], float]
                           ) -> float | None:
        """This frame's estimate of the camera's saturation (:func:`estimate_saturation`)
        from the coarse glove ``labels`` of ``region`` inside the hand's window ``found``
        ((cx, cy), half; coarse pixels)."""
        rx0, rx1, ry0, ry1 = region
        (cx, cy), half = found
        x0, x1 = max(int(cx - half) - rx0, 0), min(int(np.ceil(cx + half)) + 1 - rx0, rx1 - rx0)
        y0, y1 = max(int(cy - half) - ry0, 0), min(int(np.ceil(cy + half)) + 1 - ry0, ry1 - ry0)
        part = small[ry0 + y0:ry0 + y1, rx0 + x0:rx0 + x1]
        inside = labels[y0:y1, x0:x1]
        # patch interiors only: a coarse pixel on a colour border mixes two colours
        inside = inside * (cv2.erode(inside, _CROSS) == cv2.dilate(inside, _CROSS))
        return estimate_saturation(cv2.LUT(part, _LINEAR_RGB), inside,
                                   self.calibration.reference_linear_rgb)

    def _washed_out_search(self, small: np.ndarray, region: tuple[int, int, int, int],
                           reduction: float, pixels: int, static: np.ndarray | None,
                           min_px: int, detected: tuple[tuple[tuple[float, float], float] | None,
                                                        np.ndarray | None, np.ndarray]
                           ) -> tuple[tuple[tuple[float, float], float] | None,
                                      np.ndarray | None, np.ndarray]:
        """``detected`` (:meth:`_detect` of ``region``), or the same search with the colour
        table undoing another settled saturation (``SaturationEstimate.trials``, one per
        frame in turn), which then becomes the camera's: one whose hand window shows at
        least ``washed_out_colors`` glove colours (``window_colors``) and more than
        ``detected``'s (a camera that washes colours out hides most of the glove from the
        calibration's table) and whose glove's palette confirms it (:meth:`_washed_out`), or,
        under an undone saturation with that many shown, the calibration's own table if it
        shows as many (undoing a plain camera's saturation boosts it, and clutter turns
        glove-coloured). With the calibration's table and that many shown, no other is
        tried. Before all that, under an undone saturation, a glove whose palette reads
        plain (:func:`reads_plain` of its saturation estimate under the table that found
        it) sends the camera back to the calibration's table, which searches the frame
        again: after odd frames (noise) switched a plain camera, its boosted table shows as
        many colours as the calibration's or more, so the colour count cannot return it."""
        est = self._saturation
        assert est is not None
        x0, _, y0, _ = region
        kept = est.step
        if (kept != 0 and detected[0] is not None
                and reads_plain(self._window_saturation(small, region, detected[2],
                                                        detected[0]))):
            kept = 0   # a plain camera's glove: back to the calibration's table
            est.settle(kept)
            detected = self._detect(small, region, reduction, pixels, static, min_px)
        shown = window_colors(detected[2], _in_region(detected[0], x0, y0))
        plain = shown >= self.washed_out_colors
        if plain and kept == 0:
            return detected
        trials = est.trials()
        step = trials[self._washed_out_turn % len(trials)]
        self._washed_out_turn += 1
        est.settle(step)
        tried = self._detect(small, region, reduction, pixels, static, min_px)
        found = window_colors(tried[2], _in_region(tried[0], x0, y0))
        if (found >= shown if plain and step == 0
                else found >= self.washed_out_colors and found > shown
                and (step == 0 or self._washed_out(small, region, tried))):
            return tried
        est.settle(kept)
        return detected

    def _washed_out(self, small: np.ndarray, region: tuple[int, int, int, int],
                    tried: tuple[tuple[tuple[float, float], float] | None, np.ndarray | None,
                                 np.ndarray]) -> bool:
        """Whether the glove a search found under an undone saturation (``tried``,
        :meth:`_detect` of ``region``) shows the calibration's palette washed out: its
        saturation estimate (:meth:`_window_saturation`) below the dead band of 1 (clutter a
        boosted table turns glove-coloured, or a camera that boosts saturation, is not)."""
        if tried[0] is None:
            return False
        estimate = self._window_saturation(small, region, tried[2], tried[0])
        return estimate is not None and estimate < WASHED_OUT_MAX_SATURATION

    def _scene_colours(self, small: np.ndarray, table: np.ndarray | None,
                       region: tuple[int, int, int, int], labels: np.ndarray
                       ) -> np.ndarray | None:
        """The frame's scene colours (:func:`scene_colour_table`): those of the coarse pixels
        classified glove but not kept as glove by the search, whose ``labels`` cover
        ``region``; outside it (a followed hand) every pixel classified glove counts."""
        if self.scene_colour_min_share <= 0:
            return None
        x0, _, y0, _ = region
        # (one compiled pass: :meth:`_classify` 's glove pixels less those ``labels`` keep)
        return rejected_scene_colours(small, self._lut(),
                                      index_tables(self.calibration.bits, table), labels,
                                      (x0, y0), SCENE_COLOUR_BITS,
                                      self.scene_colour_min_share
                                      * (small.shape[0] * small.shape[1]))

    def _small(self, image: np.ndarray) -> tuple[np.ndarray, float, float]:
        """The coarse frame (``image`` downsampled by ``coarse_factor``) and its x and y
        reduction."""
        f = self.coarse_factor
        h, w = image.shape[:2]
        if f > 1 and h >= 2 * f and w >= 2 * f:
            return (cv2.resize(image, (w // f, h // f), interpolation=cv2.INTER_LINEAR),
                    w / (w // f), h / (h // f))
        return image, 1.0, 1.0

    def _without_search(self, image: np.ndarray) -> _Followed | None:
        """What :meth:`_coarse` gives, without its search, for a frame that follows a hand
        found without fail (``search_every`` > 1, fewer than ``search_every`` - 1 frames
        since the last search): the last frame's window, the last search's light table and
        scene colours, this frame's learnt static background and the coarse frame (which the
        static background learns from once the hand is found). None when this frame needs
        the search."""
        if (self.search_every <= 1 or self._window is None or self._searched is None
                or self._window[1] != image.shape[:2]
                or self._since_search + 1 >= self.search_every):
            return None
        small, _, _ = self._small(image)
        return (self._window[0], *self._searched, self.background.match(small), small)

    def _coarse(self, image: np.ndarray, learn: bool = False
                ) -> tuple[tuple[tuple[float, float], float] | None, np.ndarray | None,
                           np.ndarray | None, np.ndarray | None]:
        """Find the glove on the downsampled frame: (centre (x, y), half window) in full
        pixels or None, the light-colour correction table (None for no correction), the
        frame's scene colours (:func:`scene_colour_table`; None when off) and the coarse
        pixels that are learnt static background (None when none). With ``learn`` the
        static background learns from this frame."""
        h, w = image.shape[:2]
        small, sx, sy = self._small(image)
        reduction = float(np.sqrt(sx * sy))
        static = self.background.match(small) if learn else None
        region = self._follow_region(small.shape[:2]) if learn else None
        min_px = max(int(self.min_glove_pixels / (sx * sy)), 1)
        detected = None
        if region is not None:
            detected = self._detect(small, region, reduction, h * w, static, min_px)
            if detected[0] is None or not self._inside(detected[0], region, small.shape[:2]):
                detected = None     # lost, or leaving the followed region: search it all
        if detected is None:
            region = (0, small.shape[1], 0, small.shape[0])
            detected = self._detect(small, region, reduction, h * w, static, min_px)
        if learn and self.washed_out_colors > 0:
            detected = self._washed_out_search(small, region, reduction, h * w, static, min_px,
                                               detected)
        found, table, labels = detected
        if (learn and found is not None and self._saturation is not None
                and self.saturation_rate > 0):
            self._saturation.update(self._window_saturation(small, region, labels, found))
        scene = self._scene_colours(small, table, region, labels)
        self._found = None if found is None else (found, small.shape[:2])
        if learn and self.background.enabled:
            if self._defer_learning:
                self._deferred = (small, region, labels, found)
            elif self.learn_in_thread:
                self._learning = _learner().submit(self._learn, small, region, labels, found)
            else:
                self._learn(small, region, labels, found)
        if found is None:
            return None, table, scene, static
        (cx, cy), half = found
        # small pixel u covers full pixels [u * s, (u + 1) * s): centre (u + 0.5) s - 0.5
        return ((((cx + 0.5) * sx - 0.5, (cy + 0.5) * sy - 0.5), half * max(sx, sy)), table,
                scene, static)

    def _learn(self, small: np.ndarray, region: tuple[int, int, int, int],
               labels: np.ndarray, found: tuple[tuple[float, float], float] | None) -> None:
        """The static background learns from coarse frame ``small`` (given to its match)
        but where the coarse ``labels`` of the searched ``region`` are glove-like around the
        coarse window ``found`` (None: none found); that mask is kept for the frames that
        follow without a search."""
        rx0, rx1, ry0, ry1 = region
        glove = np.zeros(small.shape[:2], bool)
        glove[ry0:ry1, rx0:rx1] = self._glove_like(
            labels, None if found is None else ((found[0][0] - rx0, found[0][1] - ry0),
                                                found[1]))
        self.background.update(small, glove)
        self._glove_like_mask = glove

    def learn_deferred(self) -> None:
        """Run the static background's learning from the last frame that
        :meth:`process` was given with ``defer_learning`` (nothing if there is none): what
        it would have learnt before returning, for a caller that first publishes the
        observation."""
        deferred, self._deferred = self._deferred, None
        if deferred is not None:
            self._learn(*deferred)

    def _learnt(self) -> None:
        """Wait for the static background's learning on the worker (``learn_in_thread``),
        if any; its error, if it failed, is raised here."""
        learning, self._learning = self._learning, None
        if learning is not None:
            learning.result()

    def _without_sleeve(self, labels: np.ndarray, edges: tuple[bool, bool, bool, bool]
                        ) -> np.ndarray:
        """The region of interest's ``labels`` (its sides ``edges``, left, right, top,
        bottom, on the image's border: :func:`image_edges`) with a glove-coloured sleeve cut
        back to the glove: an oversized single-colour region reaching the image's border keeps
        only its pixels within ``sleeve_reach`` times the hand's half window of a patch
        junction (``keep_near_junctions``); oversized here: larger than ``sleeve_min_share`` of
        the hand's window (a sleeve's visible piece is short while the wrist is near the
        border). Nothing is done (or spent) unless some glove label lies on the image's
        border."""
        if self.sleeve_reach <= 0 or not any(line.any() for line in border_lines(labels, edges)):
            return labels
        return keep_near_junctions(labels, self.calibration.num_colors, self.sleeve_reach,
                                   JUNCTION_MIN_PIXELS, self.sleeve_min_share, edges=edges)

    def _glove_adjacency(self) -> np.ndarray:
        """Which glove colours border each other on the printed glove (the standard glove,
        ``core.hand.glove.default_colour_adjacency``), for a calibration of its colours."""
        from colorglove_ros.core.hand.glove import default_colour_adjacency

        adjacency = default_colour_adjacency()
        if adjacency.shape[0] != self.calibration.num_colors + 1:
            raise SegmentationConfigError(
                f'{self.source}: glove_contact_share needs a calibration of the glove\'s '
                f'{adjacency.shape[0] - 1} colours, got {self.calibration.num_colors}')
        return adjacency

    def _on_glove_contacts(self, labels: np.ndarray) -> np.ndarray:
        """The region of interest's ``labels`` without the single-colour regions that border
        too few of the colours their colour borders on the glove (``unsupported_regions``
        with ``glove_contact_share``), then without the components left with too few colours
        (:func:`keep_multicolor_components`): skin, wood or petals labelled glove colours
        beside or touching the hand. Unchanged when off, or when those regions hold less than
        ``glove_contact_min_drop`` of the glove pixels."""
        if self.glove_contact_share <= 0:
            return labels
        if self._adjacency is None:
            self._adjacency = self._glove_adjacency()
        drop = unsupported_regions(labels, self._adjacency, self.glove_contact_share)
        dropped = np.count_nonzero(drop)
        if not dropped or dropped < self.glove_contact_min_drop * np.count_nonzero(labels):
            return labels
        labels = np.where(drop, np.uint8(0), labels)
        return keep_multicolor_components(labels, self.min_component_colors, min_pixels=2,
                                          reattach_radius=self.reattach_radius,
                                          reattach_max_share=self.reattach_max_share)

    def _blobs(self, labels: np.ndarray, r: int, x0: int, y0: int,
               window: tuple[int, int, int, int]) -> list[Blob]:
        """Connected components of each colour inside ``window`` (ROI pixel bounds)."""
        wx0, wx1, wy0, wy1 = window
        min_px = max(int(np.ceil(self.min_blob_pixels / (r * r))), 1)
        colors, cents, areas = color_components(labels[wy0:wy1, wx0:wx1], min_px,
                                                self.calibration.num_colors)
        fx = x0 + r * (cents[:, 0] + wx0) + 0.5 * (r - 1)
        fy = y0 + r * (cents[:, 1] + wy0) + 0.5 * (r - 1)
        return [Blob(c, x, y, area * r * r) for c, x, y, area in zip(
            colors.tolist(), fx.tolist(), fy.tolist(), areas.tolist(), strict=True)]

    def _filter(self, image: np.ndarray) -> np.ndarray:
        if self.bilateral_diameter > 0 and min(image.shape[:2]) > self.bilateral_diameter:
            return cv2.bilateralFilter(np.ascontiguousarray(image), self.bilateral_diameter,
                                       self.bilateral_sigma_color, self.bilateral_sigma_space)
        return image

    def _median(self, labels: np.ndarray) -> np.ndarray:
        if self.median_size > 1 and min(labels.shape) >= self.median_size:
            return cv2.medianBlur(labels, self.median_size)
        return labels

    def classify_full(self, image_rgb: np.ndarray) -> np.ndarray:
        """Filter, classify, median-filter and relabel borders on a whole frame at full
        resolution (as :meth:`process` does inside its region of interest, less the clutter
        filter), with the same light-colour correction; for evaluation and debug images."""
        image = _check_image(image_rgb)
        filtered = self._filter(image)
        labels = self._median(self._classify(filtered, self._coarse(image)[1]))
        return relabel_borders(filtered, labels, self.border_passes,
                               self.border_distances)

    # ------------------------------------------------------------------ main entry
    def process(self, image_rgb: np.ndarray, keep_labels: bool = False,
                prediction: CropPrediction | None = None,
                defer_learning: bool = False) -> Observation:
        """Segment one (H, W, 3) uint8 RGB frame. Never raises on such a frame; raises
        :class:`SegmentationInputError` on anything else. ``prediction``: the hand's crop
        predicted from the tracked pose (``core.segmentation.crop_prediction``), used when
        ``prediction_margin`` > 0 and it is for this frame's size. ``defer_learning``: the
        static background learns from this frame only in :meth:`learn_deferred` (or at the
        start of the next call), not before this one returns."""
        image = _check_image(image_rgb)
        self.learn_deferred()     # the last frame's, if its caller left it pending
        if (self.prediction_margin <= 0 or prediction is None
                or prediction.image_size != (image.shape[1], image.shape[0])):
            prediction = None
        t0 = time.perf_counter()
        self._defer_learning = bool(defer_learning)
        try:
            followed = self._without_search(image)
            obs = (None if followed is None
                   else self._segment(image, keep_labels, t0, prediction, followed))
            if obs is None:   # not found whole inside the followed region: search after all
                obs = self._segment(image, keep_labels, t0, prediction)
        finally:
            self._defer_learning = False
            self._learnt()
        assert obs is not None   # (only a frame without the search is given up)
        # the learning is in the total unless it was deferred (defer_learning)
        obs.timings_ms['total'] = (time.perf_counter() - t0) * 1e3
        return obs

    def _segment(self, image: np.ndarray, keep_labels: bool, t0: float,
                 prediction: CropPrediction | None = None, followed: _Followed | None = None
                 ) -> Observation | None:
        """Segment ``image`` (checked; ``t0``: when :meth:`process` started; ``prediction``:
        :meth:`process`'s, checked) with the coarse search, or with ``followed``
        (:meth:`_without_search`) instead: then None unless the hand is found (status ok)
        with its crop window inside the region of interest."""
        h, w = image.shape[:2]
        timings: dict[str, float] = {}
        obs = Observation(False, STATUS_NO_GLOVE, w, h, timings_ms=timings)

        def tick(stage: str, t: float) -> float:
            now = time.perf_counter()
            timings[stage] = (now - t) * 1e3
            return now

        started = time.perf_counter()
        if followed is None:
            coarse, table, scene, static = self._coarse(image, learn=True)
            # follow this frame's hand in the next frame only if it is found (set at the end)
            found, self._found, self._followed = self._found, None, None
            self._searched, self._since_search, self._window = (table, scene), 0, None
        else:
            coarse, table, scene, static, small = followed
            found = None
        t = tick('coarse', started)
        if coarse is None:
            timings['total'] = (time.perf_counter() - t0) * 1e3
            return obs
        (ccx, ccy), chalf = coarse
        # Region of interest around the coarse window, at an integer reduction r.
        rhalf = chalf * self.roi_margin
        x0, x1 = max(int(np.floor(ccx - rhalf)), 0), min(int(np.ceil(ccx + rhalf)) + 1, w)
        y0, y1 = max(int(np.floor(ccy - rhalf)), 0), min(int(np.ceil(ccy + rhalf)) + 1, h)
        r = max(1, int(np.floor(2.0 * chalf / self.max_roi_cells)))
        x1 = x0 + max((x1 - x0) // r, 1) * r
        y1 = y0 + max((y1 - y0) // r, 1) * r
        if prediction is not None and not covers(prediction, (x0, y0), (x1, y1)):
            prediction = None    # the glove was found away from the predicted hand
        start = None
        if prediction is not None:   # the crop's mean shift starts at the predicted window
            (pcx, pcy), start_half = prediction.center_xy, prediction.half_size / r
            start = (((pcx - x0 - 0.5 * (r - 1)) / r, (pcy - y0 - 0.5 * (r - 1)) / r),
                     start_half)
        roi_box = (x0, x1, y0, y1)
        masks = (table, scene, static, prediction)
        box = None
        if self.cleanup_factor > 1:
            box = self._two_resolution(image, roi_box, r, masks, chalf)
        if box is None:
            roi = self._filter(_reduced(image, roi_box, r))
            t = tick('filter', t)
            labels = self._label_roi(roi, (x0, y0), r, (h, w), masks)
            t = tick('classify', t)
            labels = self._clean_roi(self._median(labels), r, h * w, chalf)
            box = (roi, labels, 0, 0)
        roi, labels, bx0, by0 = box
        t = tick('cleanup', t)
        min_px = max(int(self.min_glove_pixels / (r * r)), 1)
        labels = relabel_borders(roi, labels, self.border_passes, self.border_distances)
        if labels.shape != ((y1 - y0) // r, (x1 - x0) // r):   # the glove's box: into the ROI
            whole = np.zeros(((y1 - y0) // r, (x1 - x0) // r), np.uint8)
            whole[by0:by0 + labels.shape[0], bx0:bx0 + labels.shape[1]] = labels
            labels = whole
        # glove colour out of a patch's reach of every junction: a surface touching the glove
        labels = keep_near_junctions(labels, self.calibration.num_colors, self.junction_reach,
                                     JUNCTION_MIN_PIXELS, self.junction_min_share,
                                     surfaces_only=bool(self.junction_surfaces_only),
                                     min_pull=self.junction_min_pull,
                                     max_window_kept=self.junction_max_window_kept)
        labels = self._without_sleeve(labels, image_edges((x0, x1, y0, y1), r, w, h))
        labels = self._on_glove_contacts(labels)
        t = tick('borders', t)
        if keep_labels:
            full = np.zeros((h, w), np.uint8)
            up = labels if r == 1 else np.repeat(np.repeat(labels, r, 0), r, 1)
            full[y0:y0 + up.shape[0], x0:x0 + up.shape[1]] = up
            obs.label_image = full
        tiny = crop_to_tiny(labels, min_pixels=min_px, start=start)
        if start is not None and tiny is not None:   # far off the predicted size: trimmed
            tiny = predicted_size_crop(labels, tiny, start, self.prediction_max_ratio, min_px)
        t = tick('crop', t)
        if tiny is None and followed is not None:
            return None
        if tiny is None:
            obs.status = STATUS_TOO_SMALL
            timings['total'] = (time.perf_counter() - t0) * 1e3
            return obs
        tr = tiny.transform
        crop = CropTransform(scale=tr.scale * r, offset_x=x0 + r * tr.offset_x + 0.5 * (r - 1),
                             offset_y=y0 + r * tr.offset_y + 0.5 * (r - 1))
        obs.crop = crop
        obs.tiny_labels = tiny.labels
        # Glove pixels inside the crop window, in full-resolution pixel units.
        cx, cy = tr.center_xy
        half = tr.half_size
        wx0, wx1 = max(int(np.ceil(cx - half)), 0), int(np.floor(cx + half)) + 1
        wy0, wy1 = max(int(np.ceil(cy - half)), 0), int(np.floor(cy + half)) + 1
        obs.glove_pixel_count = int(np.count_nonzero(labels[wy0:wy1, wx0:wx1])) * r * r
        obs.cut_by_border = (border_contact_px(labels, (x0, x1, y0, y1), r, w, h,
                                               (wx0, wx1, wy0, wy1))
                             > self.max_border_contact * 2.0 * crop.half_size)
        obs.blobs = self._blobs(labels, r, x0, y0, (wx0, wx1, wy0, wy1))
        tick('blobs', t)
        # Reasons to reject: crop mostly outside the frame, or too little glove.
        fcx, fcy = crop.center_xy
        fh = crop.half_size
        inside_w = max(0.0, min(fcx + fh, w - 0.5) - max(fcx - fh, -0.5))
        inside_h = max(0.0, min(fcy + fh, h - 0.5) - max(fcy - fh, -0.5))
        inside = inside_w * inside_h / max((2.0 * fh) ** 2, 1e-9)
        if inside < self.min_inside_fraction:
            obs.status = STATUS_OUT_OF_FRAME
        elif obs.glove_pixel_count < self.min_glove_pixels:
            obs.status = STATUS_TOO_SMALL
        elif (sum(b.pixel_count for b in obs.blobs)
              < self.min_blob_share * obs.glove_pixel_count):
            obs.status = STATUS_FRAGMENTED
        else:
            obs.status = STATUS_OK
            obs.hand_found = True
        if followed is not None:
            # the crop window must lie inside the region of interest (but where that ends at
            # the image's edge): else the hand may reach past it
            if not (obs.hand_found and (x0 == 0 or fcx - fh >= x0)
                    and (x1 + r > w or fcx + fh <= x1) and (y0 == 0 or fcy - fh >= y0)
                    and (y1 + r > h or fcy + fh <= y1)):
                return None
            self._since_search += 1
            if self.background.enabled:    # (a frame searched after all learns there)
                self.background.update(small, self._glove_like_mask)
            small_h, small_w = small.shape[:2]
            sx, sy = w / small_w, h / small_h
            found = (((fcx + 0.5) / sx - 0.5, (fcy + 0.5) / sy - 0.5), chalf / max(sx, sy))
            self._found, self._followed = None, (found, (small_h, small_w))
        elif obs.hand_found:
            self._followed = found
        if obs.hand_found and self.search_every > 1:
            self._window = (((fcx, fcy), chalf), (h, w))
        timings['total'] = (time.perf_counter() - t0) * 1e3
        return obs


def load_segmenter(config_path: str = 'config/color_calibration.yaml') -> GloveSegmenter:
    """A segmenter with the calibration file and settings named in a colour config YAML."""
    cfg = read_calibration_config(config_path)
    source = str(cfg['config_path'])
    # a bad setting is refused before the calibration is read (GloveSegmenter checks again)
    settings = validate_segmenter_settings(cfg['segmenter'], source, SegmentationConfigError)
    return GloveSegmenter(load_calibration(cfg['calibration_file']), **settings, source=source)
