"""Finding the glove rather than its colours: what sets the printed glove apart from warm wood,
a red saucer, skin or dark speckle is many small patches of distinct glove colours side by side
at a hand's size. Two filters on a label image (0 = background, 1..N glove colours):

* :func:`colour_diversity` / :func:`glove_region_mask`: the number of distinct glove colours
  in a window around each pixel; the glove shows most of its colours within a window of a
  fraction of a hand, a background surface a few;
* :func:`drop_oversized_components`: a single-colour region far larger than any printed patch
  (a table top, a wall, clothing) is background;
* :func:`junction_window` / :func:`shed_oversized_patches`: the same at the hand's own
  scale, found where many glove colours meet: a single-colour region larger than the glove's
  largest patch can be within the hand's window (a petal, a sleeve or a wooden edge touching
  the glove) is background, and so is glove colour well outside that window;
* :func:`keep_near_junctions`: glove colour farther from every patch junction than the
  glove's largest patch reaches (at the hand's scale, from the junctions' own window) is a
  surface touching the glove, not the glove; the crop then holds the hand at its own size;
* :func:`unsupported_regions`: a single-colour region whose outline borders almost none of
  the colours its colour borders on the printed glove (the glove's known adjacency) is clutter:
  skin, wood or petals shade through red, orange and pink, pairs the glove never joins;
* :func:`scene_colour_table`: the colours of glove-labelled pixels found to be background
  in a frame are the scene's; the same colours near the hand are background too.
"""
from __future__ import annotations

import cv2
import numpy as np

from colorglove_ros.core.segmentation.crop import compiled_kernels, mean_shift_crop

__all__ = ['SCENE_COLOUR_BITS', 'colour_diversity', 'glove_region_mask',
           'drop_oversized_components', 'PATCH_OUTLINE_GLOVE_SHARE', 'JUNCTION_WINDOW_PX',
           'JUNCTION_COLORS', 'JUNCTION_STEP', 'LARGEST_PATCH_WINDOW_SHARE', 'junction_mask',
           'junction_window', 'shed_oversized_patches', 'keep_near_junctions',
           'scene_colour_table', 'rejected_scene_colours', 'border_lines',
           'unsupported_regions']

#: Bits per channel of the quantised colours of :func:`scene_colour_table`.
SCENE_COLOUR_BITS = 5


def colour_diversity(labels: np.ndarray, num_colors: int, window: int,
                     min_density: float) -> np.ndarray:
    """(H, W) uint8: how many of the glove colours 1..``num_colors`` cover at least
    ``min_density`` of the ``window`` x ``window`` box centred on each pixel."""
    labels = np.asarray(labels, np.uint8)
    counts = np.zeros(labels.shape, np.uint8)
    if window < 1 or not labels.size:
        return counts
    # the fewest pixels of a colour in the box, as an integer count (a colour with fewer
    # pixels in the whole image is never dense); a pixel's box: window // 2 pixels before it
    # on each axis (OpenCV's anchor), the rest after, counted inside each colour's rectangle
    need = max(int(np.ceil(min_density * window * window - 1e-9)), 1)
    kernels = compiled_kernels()
    present, boxes = kernels.label_boxes(labels, num_colors + 1)
    colours = np.flatnonzero(present[1:num_colors + 1] >= need).astype(np.int64) + 1
    kernels.box_colour_counts(labels, colours, boxes, window, need, counts)
    return counts


def glove_region_mask(labels: np.ndarray, num_colors: int, window: int, min_colors: int,
                      min_density: float) -> np.ndarray:
    """(H, W) bool: the pixels within ``window`` of a pixel whose window shows at least
    ``min_colors`` glove colours (:func:`colour_diversity`), and every glove-labelled
    8-connected region that reaches such a pixel: the hand, its fingers however long, and
    a margin around it; empty where no window is that colourful."""
    rich = colour_diversity(labels, num_colors, window, min_density) >= min_colors
    if not rich.any():
        return rich
    size = 2 * int(window) + 1
    # the dilation by a size x size square, as a box sum (its cost does not grow with size)
    near = cv2.boxFilter(rich.view(np.uint8), cv2.CV_32S, (size, size), normalize=False,
                         borderType=cv2.BORDER_CONSTANT) > 0
    return compiled_kernels().near_or_reaching(np.asarray(labels, np.uint8), rich, near)


def drop_oversized_components(labels: np.ndarray, max_pixels: float) -> np.ndarray:
    """``labels`` with every 8-connected single-colour region of more than ``max_pixels``
    pixels set to background (0)."""
    labels = np.asarray(labels, np.uint8)
    if not labels.size or max_pixels <= 0:
        return labels
    out = labels
    for color in np.flatnonzero(compiled_kernels().label_boxes(labels, 1)[0][1:] > max_pixels) + 1:
        n, comp, stats, _ = cv2.connectedComponentsWithStats(
            (labels == color).view(np.uint8), connectivity=8, ltype=cv2.CV_32S)
        big = np.flatnonzero(stats[1:, cv2.CC_STAT_AREA] > max_pixels) + 1
        if len(big):
            if out is labels:
                out = labels.copy()
            drop = np.zeros(n, bool)
            drop[big] = True
            out[drop.take(comp)] = 0
    return out


#: A large single-colour region whose outline runs along other glove colours for at least
#: this share is a patch of the glove (surrounded by its neighbours), not a surface.
PATCH_OUTLINE_GLOVE_SHARE = 0.5


def _drop_surfaces(labels: np.ndarray, max_pixels: float) -> np.ndarray:
    """``labels`` with every 8-connected single-colour region of more than ``max_pixels``
    pixels set to background unless at least ``PATCH_OUTLINE_GLOVE_SHARE`` of the pixels
    just outside it are other glove colours."""
    labels = np.asarray(labels, np.uint8)
    if not labels.size or max_pixels <= 0:
        return labels
    out = labels
    for color in np.flatnonzero(np.bincount(labels.ravel())[1:] > max_pixels) + 1:
        n, comp, stats, _ = cv2.connectedComponentsWithStats(
            cv2.compare(labels, int(color), cv2.CMP_EQ), connectivity=8, ltype=cv2.CV_32S)
        for k in np.flatnonzero(stats[1:, cv2.CC_STAT_AREA] > max_pixels) + 1:
            if not _is_surface(labels, comp, stats, k):
                continue
            if out is labels:
                out = labels.copy()
            x, y, bw, bh = stats[k, :4]
            out[y:y + bh, x:x + bw][comp[y:y + bh, x:x + bw] == k] = 0
    return out


def _is_surface(labels: np.ndarray, comp: np.ndarray, stats: np.ndarray, k: int) -> bool:
    """Whether component ``k`` of ``comp`` (``cv2.connectedComponentsWithStats`` of one
    colour of ``labels``, with its ``stats``) has an outline running mostly along background:
    less than ``PATCH_OUTLINE_GLOVE_SHARE`` of the pixels just outside it (inside the image)
    are other glove colours."""
    h, w = labels.shape
    x, y, bw, bh = stats[k, :4]
    x0, y0 = max(x - 1, 0), max(y - 1, 0)
    x1, y1 = min(x + bw + 1, w), min(y + bh + 1, h)
    mine = (comp[y0:y1, x0:x1] == k).view(np.uint8)
    ring = cv2.dilate(mine, np.ones((3, 3), np.uint8)).view(bool) & ~mine.view(bool)
    return bool(np.count_nonzero(labels[y0:y1, x0:x1][ring])
                < PATCH_OUTLINE_GLOVE_SHARE * np.count_nonzero(ring))


#: The glove's largest printed patch (the palm's, seen flat: about 0.12) is at most this share
#: of the area of the hand's crop window.
LARGEST_PATCH_WINDOW_SHARE = 0.15

#: A patch junction: a pixel whose box this many pixels wide shows ``JUNCTION_COLORS`` glove
#: colours (where three printed patches meet; a surface of one or two colours has none).
JUNCTION_WINDOW_PX = 5
JUNCTION_COLORS = 3
#: :func:`keep_near_junctions` decides on every this many pixels of every this many rows.
JUNCTION_STEP = 2


def junction_mask(labels: np.ndarray, num_colors: int,
                  junction_window_px: int = JUNCTION_WINDOW_PX,
                  junction_colors: int = JUNCTION_COLORS) -> np.ndarray:
    """(H, W) bool: the patch junctions, pixels whose ``junction_window_px`` box shows
    ``junction_colors`` glove colours."""
    return colour_diversity(labels, num_colors, junction_window_px,
                            0.5 / junction_window_px ** 2) >= junction_colors


def junction_window(labels: np.ndarray, num_colors: int, min_pixels: int,
                    junction_window_px: int = JUNCTION_WINDOW_PX,
                    junction_colors: int = JUNCTION_COLORS
                    ) -> tuple[tuple[float, float], float] | None:
    """The hand's window ((cx, cy), half) found from where glove colours meet: the window of
    :func:`mean_shift_crop` on the pixels whose ``junction_window_px`` box shows
    ``junction_colors`` glove colours (patch junctions, all over the glove; a surface of one
    or two colours has none inside it, so glove-coloured surfaces touching the glove do not
    pull this window out as they pull one found on every glove pixel). None when fewer than
    ``min_pixels`` junction pixels are found."""
    return mean_shift_crop(junction_mask(labels, num_colors, junction_window_px,
                                         junction_colors), min_pixels=min_pixels)


def shed_oversized_patches(labels: np.ndarray, max_window_share: float,
                           window: tuple[tuple[float, float], float] | None) -> np.ndarray:
    """``labels`` without the single-colour regions too large to be one of the glove's
    printed patches at the hand's scale: more than ``max_window_share`` of the area of the
    hand's ``window`` ((cx, cy), half: :func:`junction_window`) and with an outline running
    mostly along background (a surface touching the glove; a large patch of the glove is
    surrounded by its neighbours: ``PATCH_OUTLINE_GLOVE_SHARE``). Unchanged without a
    window or with ``max_window_share`` 0."""
    if window is None or max_window_share <= 0:
        return labels
    return _drop_surfaces(labels, max_window_share * (2.0 * window[1]) ** 2)


def keep_near_junctions(labels: np.ndarray, num_colors: int, reach: float, min_pixels: int,
                        max_patch_share: float = LARGEST_PATCH_WINDOW_SHARE,
                        step: int = JUNCTION_STEP,
                        edges: tuple[bool, bool, bool, bool] | None = None,
                        surfaces_only: bool = False, min_pull: float = 0.0,
                        max_window_kept: float = 0.0) -> np.ndarray:
    """``labels`` with the glove pixels of oversized single-colour regions that lie farther
    than ``reach`` times the hand's half window from every patch junction set to background.

    The hand's window is :func:`junction_window`'s (the junctions' own, which single-colour
    surfaces do not pull out); an oversized region is an 8-connected single-colour region
    larger than ``max_patch_share`` of that window's area, more than any printed patch. A
    petal, a sleeve or a wooden edge touching the glove is one: only its part near the hand's
    junctions stays, so the crop holds the hand at about its own size; a finger (patches of
    a patch's size, with junctions only where it meets the palm) stays whole. All of it is
    decided on every ``step``-th pixel of every ``step``-th row (``min_pixels`` junctions
    there at least; fewer: unchanged) and applied to the pixels each stands for. Unchanged
    with ``reach`` 0. With ``edges`` (left, right, top, bottom: which sides of ``labels`` are
    the image's border) only the oversized regions reaching one of those sides with an
    outline running mostly along background are trimmed (a sleeve: the forearm always runs
    off the image; a patch of a glove cut by the border is surrounded by its neighbours);
    with ``surfaces_only`` every oversized region with such an outline, wherever it lies.
    Two gates keep a glove without clutter whole: with ``min_pull`` > 0 nothing is trimmed (or
    spent past the junctions' window) unless the crop is pulled, the window of every glove
    pixel (:func:`mean_shift_crop`, as the crop finds it) more than ``min_pull`` times the
    junctions' (on a glove alone the two differ by the fingers beyond the junctions); with
    ``max_window_kept`` > 0 the trim is kept only when it shrinks that window to at most
    ``max_window_kept`` of its size (clutter pulling the crop out; a finger cut back at the
    silhouette moves it little)."""
    labels = np.asarray(labels, np.uint8)
    if reach <= 0 or not labels.size:
        return labels
    step = max(int(step), 1)
    small = np.ascontiguousarray(labels[::step, ::step])
    junctions = junction_mask(small, num_colors)
    window = mean_shift_crop(junctions, min_pixels=min_pixels)
    if window is None:
        return labels
    crop = (mean_shift_crop(small, min_pixels=min_pixels)
            if min_pull > 0 or max_window_kept > 0 else None)
    if min_pull > 0 and (crop is None or crop[1] <= min_pull * window[1]):
        return labels
    max_pixels = max_patch_share * (2.0 * window[1]) ** 2
    kernels = compiled_kernels()
    counts = kernels.label_boxes(small, num_colors + 1)[0]
    big_colours = np.flatnonzero(counts[1:] > max_pixels) + 1
    if not len(big_colours):
        return labels
    far = cv2.distanceTransform((~junctions).view(np.uint8), cv2.DIST_L2, 3) > (
        reach * window[1])
    # (a colour with no pixel that far keeps every pixel: its regions need not be found)
    reaching_far = np.bincount(small[far], minlength=num_colors + 1)[big_colours] > 0
    candidate = np.zeros(256, bool)
    candidate[big_colours[reaching_far]] = True
    # every candidate colour's regions labelled in one compiled pass; with edges, sleeves
    # only (off the image), and with edges or surfaces_only, only those among background
    sides = np.array(edges if edges is not None else (False,) * 4, bool)
    drop = kernels.surface_regions(small, candidate, float(max_pixels), sides,
                                   edges is not None, bool(surfaces_only),
                                   PATCH_OUTLINE_GLOVE_SHARE)
    drop &= far
    if not drop.any() or (max_window_kept > 0 and not _shrinks(small, drop, crop,
                                                                max_window_kept, min_pixels)):
        return labels
    oversized = np.zeros(256, bool)
    oversized[big_colours] = True
    # (a pixel of another colour in the cell stays)
    return kernels.clear_cells(np.ascontiguousarray(labels), drop, step, oversized)


def _shrinks(labels: np.ndarray, drop: np.ndarray,
             crop: tuple[tuple[float, float], float] | None, max_window_kept: float,
             min_pixels: int) -> bool:
    """Whether setting the ``drop`` pixels of ``labels`` to background shrinks the window of
    every glove pixel (``crop``, ((cx, cy), half), that of ``labels``) to at most
    ``max_window_kept`` of its half size."""
    kept = mean_shift_crop(np.where(drop, 0, labels), min_pixels=min_pixels)
    return crop is not None and kept is not None and kept[1] <= max_window_kept * crop[1]


def border_lines(array: np.ndarray, edges: tuple[bool, bool, bool, bool]) -> list[np.ndarray]:
    """The outermost column or row of ``array`` on each of its sides that ``edges`` (left,
    right, top, bottom) flags, e.g. the sides lying on the image's border."""
    left, right, top, bottom = edges
    return [line for on, line in ((left, array[:, 0]), (right, array[:, -1]), (top, array[0]),
                                  (bottom, array[-1])) if on]


def scene_colour_table(rgb: np.ndarray, bits: int, min_pixels: float,
                       where: np.ndarray | None = None) -> np.ndarray:
    """(2^(3 bits),) bool: the quantised colours (``color_model.lut_index``) that at least
    ``min_pixels`` of the uint8 (N, 3) colours ``rgb`` fall in; with ``where`` ((H, W) bool)
    ``rgb`` is an (H, W, 3) image, and its pixels there count."""
    from colorglove_ros.core.segmentation.color_model import index_tables, lut_index

    if where is not None:
        counts = compiled_kernels().colour_histogram(rgb, where, index_tables(bits),
                                                     1 << (3 * bits))
    else:
        counts = np.bincount(lut_index(np.asarray(rgb, np.uint8).reshape(-1, 3), bits),
                             minlength=1 << (3 * bits))
    return _frequent(counts, min_pixels)


def rejected_scene_colours(image: np.ndarray, lut: np.ndarray, index: np.ndarray,
                           kept: np.ndarray, origin: tuple[int, int], bits: int,
                           min_pixels: float) -> np.ndarray:
    """:func:`scene_colour_table` of the pixels of the (H, W, 3) uint8 ``image`` that the
    colour table ``lut`` (``color_model.lut_index`` through the per-channel ``index`` (3, 256)
    int32: ``color_model.index_tables``) labels glove but the labels ``kept`` ((h, w) uint8,
    0 = not kept; their pixel (0, 0) at ``origin`` (x, y) of ``image``) do not keep: the
    colours of glove-labelled pixels found to be background. One compiled pass, no label
    image."""
    from colorglove_ros.core.segmentation.color_model import index_tables

    counts = compiled_kernels().rejected_colour_histogram(
        image, lut, index, np.asarray(kept, np.uint8), int(origin[1]), int(origin[0]),
        index_tables(bits), 1 << (3 * bits))
    return _frequent(counts, min_pixels)


def _frequent(counts: np.ndarray, min_pixels: float) -> np.ndarray:
    """The quantised colours that at least ``min_pixels`` (and one) pixels fall in."""
    return counts >= max(float(min_pixels), 1.0)


def unsupported_regions(labels: np.ndarray, adjacency: np.ndarray, min_share: float
                        ) -> np.ndarray:
    """(H, W) bool: the pixels of every 8-connected single-colour region of ``labels`` (0 =
    background, 1..N glove colours) less than ``min_share`` of whose outline (its pixels'
    4-neighbours of another label inside the image) is a colour that ``adjacency`` ((N + 1,
    N + 1) bool, ``core.hand.glove.colour_adjacency``) says borders its colour on the glove.

    A printed patch meets its neighbours along much of its outline; glove-coloured clutter
    meets background and colours the glove never puts beside its own (a face or a petal
    shading from red through orange to pink), so it has almost no such contacts. Empty with
    ``min_share`` 0; labels above N are background."""
    adjacency = np.asarray(adjacency, bool)
    labels = np.asarray(labels, np.uint8)
    if labels.max(initial=0) >= adjacency.shape[0]:
        labels = np.where(labels < adjacency.shape[0], labels, np.uint8(0))
    out = np.zeros(labels.shape, bool)
    if min_share <= 0 or labels.size == 0:
        return out
    x, y, bw, bh = cv2.boundingRect(cv2.compare(labels, 0, cv2.CMP_GT))
    if not bw:
        return out
    # the glove labels' box grown by the pixel beside it (inside the image): every contact
    y0, y1, x0, x1 = max(y - 1, 0), min(y + bh + 1, labels.shape[0]), max(x - 1, 0), min(
        x + bw + 1, labels.shape[1])
    out[y0:y1, x0:x1] = _unsupported(np.ascontiguousarray(labels[y0:y1, x0:x1]),
                                     adjacency, min_share)
    return out


def _unsupported(labels: np.ndarray, adjacency: np.ndarray, min_share: float) -> np.ndarray:
    """:func:`unsupported_regions` of a label image with a glove label."""
    kernels = compiled_kernels()
    comp, count = kernels.colour_components(labels, adjacency.shape[0] - 1)
    # (background borders nothing in adjacency)
    beside, outline = kernels.region_contacts(labels, comp, count, adjacency)
    drop = beside < min_share * np.maximum(outline, 1)
    drop[0] = False
    return drop.take(comp)
