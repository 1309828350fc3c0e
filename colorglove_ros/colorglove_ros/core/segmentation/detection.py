"""Finding the glove rather than its colours: what sets the printed glove apart from warm wood,
a red saucer, skin or dark speckle is many small patches of distinct glove colours side by side
at a hand's size. Two filters on a label image (0 = background, 1..N glove colours):

* :func:`colour_diversity` / :func:`glove_region_mask`: the number of distinct glove colours
  in a window around each pixel; the glove shows most of its colours within a window of a
  fraction of a hand, a background surface a few;
* :func:`drop_oversized_components`: a single-colour region far larger than any printed patch
  (a table top, a wall, clothing) is background;
* :func:`scene_colour_table`: the colours of glove-labelled pixels found to be background
  in a frame are the scene's; the same colours near the hand are background too.
"""
from __future__ import annotations

import cv2
import numpy as np

__all__ = ['SCENE_COLOUR_BITS', 'colour_diversity', 'glove_region_mask',
           'drop_oversized_components', 'scene_colour_table']

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
    present = np.bincount(labels.ravel(), minlength=num_colors + 1)
    for color in np.flatnonzero(present[1:num_colors + 1]) + 1:
        density = cv2.boxFilter((labels == color).view(np.uint8), cv2.CV_32F, (window, window),
                                borderType=cv2.BORDER_CONSTANT)
        counts += (density >= min_density).view(np.uint8)
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
    near = cv2.dilate(rich.view(np.uint8),
                      cv2.getStructuringElement(cv2.MORPH_RECT, (size, size))).view(bool)
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


def scene_colour_table(rgb: np.ndarray, bits: int, min_pixels: float) -> np.ndarray:
    """(2^(3 bits),) bool: the quantised colours (``color_model.lut_index``) that at least
    ``min_pixels`` of the uint8 (N, 3) colours ``rgb`` fall in."""
    from colorglove_ros.core.segmentation.color_model import lut_index

    counts = np.bincount(lut_index(np.asarray(rgb, np.uint8).reshape(-1, 3), bits),
                         minlength=1 << (3 * bits))
    return counts >= max(float(min_pixels), 1.0)
