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
* :func:`scene_colour_table`: the colours of glove-labelled pixels found to be background
  in a frame are the scene's; the same colours near the hand are background too.
"""
from __future__ import annotations

import cv2
import numpy as np

from colorglove_ros.core.segmentation.crop import mean_shift_crop

__all__ = ['SCENE_COLOUR_BITS', 'colour_diversity', 'glove_region_mask',
           'drop_oversized_components', 'PATCH_OUTLINE_GLOVE_SHARE', 'junction_window',
           'shed_oversized_patches', 'scene_colour_table']

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
    # the fewest pixels of a colour in the box, as an integer count: the box sums are exact
    # in 32-bit integers, and a colour with fewer pixels in the whole image is never dense
    need = max(int(np.ceil(min_density * window * window - 1e-9)), 1)
    present = np.bincount(labels.ravel(), minlength=num_colors + 1)
    for color in np.flatnonzero(present[1:num_colors + 1] >= need) + 1:
        inside = cv2.boxFilter(cv2.compare(labels, int(color), cv2.CMP_EQ) >> 7, cv2.CV_32S,
                               (window, window), normalize=False,
                               borderType=cv2.BORDER_CONSTANT)
        counts += (inside >= need).view(np.uint8)
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
    n, comp = cv2.connectedComponents((np.asarray(labels) > 0).view(np.uint8), connectivity=8,
                                      ltype=cv2.CV_32S)
    reached = np.zeros(n, bool)
    reached[comp[rich]] = True
    reached[0] = False
    return near | reached[comp]


def drop_oversized_components(labels: np.ndarray, max_pixels: float) -> np.ndarray:
    """``labels`` with every 8-connected single-colour region of more than ``max_pixels``
    pixels set to background (0)."""
    labels = np.asarray(labels, np.uint8)
    if not labels.size or max_pixels <= 0:
        return labels
    out = labels
    for color in np.flatnonzero(np.bincount(labels.ravel())[1:] > max_pixels) + 1:
        n, comp, stats, _ = cv2.connectedComponentsWithStats(
            (labels == color).view(np.uint8), connectivity=8, ltype=cv2.CV_32S)
        big = np.flatnonzero(stats[1:, cv2.CC_STAT_AREA] > max_pixels) + 1
        if len(big):
            if out is labels:
                out = labels.copy()
            drop = np.zeros(n, bool)
            drop[big] = True
            out[drop[comp]] = 0
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
    ring_kernel = np.ones((3, 3), np.uint8)
    h, w = labels.shape
    for color in np.flatnonzero(np.bincount(labels.ravel())[1:] > max_pixels) + 1:
        n, comp, stats, _ = cv2.connectedComponentsWithStats(
            cv2.compare(labels, int(color), cv2.CMP_EQ), connectivity=8, ltype=cv2.CV_32S)
        for k in np.flatnonzero(stats[1:, cv2.CC_STAT_AREA] > max_pixels) + 1:
            x, y, bw, bh = stats[k, :4]
            x0, y0 = max(x - 1, 0), max(y - 1, 0)
            x1, y1 = min(x + bw + 1, w), min(y + bh + 1, h)
            mine = (comp[y0:y1, x0:x1] == k).view(np.uint8)
            ring = cv2.dilate(mine, ring_kernel).view(bool) & ~mine.view(bool)
            if np.count_nonzero(labels[y0:y1, x0:x1][ring]) >= (
                    PATCH_OUTLINE_GLOVE_SHARE * np.count_nonzero(ring)):
                continue
            if out is labels:
                out = labels.copy()
            out[y0:y1, x0:x1][mine.view(bool)] = 0
    return out


def junction_window(labels: np.ndarray, num_colors: int, min_pixels: int,
                    junction_window_px: int = 5, junction_colors: int = 3
                    ) -> tuple[tuple[float, float], float] | None:
    """The hand's window ((cx, cy), half) found from where glove colours meet: the window of
    :func:`mean_shift_crop` on the pixels whose ``junction_window_px`` box shows
    ``junction_colors`` glove colours (patch junctions, all over the glove; a surface of one
    or two colours has none inside it, so glove-coloured surfaces touching the glove do not
    pull this window out as they pull one found on every glove pixel). None when fewer than
    ``min_pixels`` junction pixels are found."""
    junctions = colour_diversity(labels, num_colors, junction_window_px,
                                 0.5 / junction_window_px ** 2) >= junction_colors
    return mean_shift_crop(junctions, min_pixels=min_pixels)


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


def scene_colour_table(rgb: np.ndarray, bits: int, min_pixels: float) -> np.ndarray:
    """(2^(3 bits),) bool: the quantised colours (``color_model.lut_index``) that at least
    ``min_pixels`` of the uint8 (N, 3) colours ``rgb`` fall in."""
    from colorglove_ros.core.segmentation.color_model import lut_index

    counts = np.bincount(lut_index(np.asarray(rgb, np.uint8).reshape(-1, 3), bits),
                         minlength=1 << (3 * bits))
    return counts >= max(float(min_pixels), 1.0)
