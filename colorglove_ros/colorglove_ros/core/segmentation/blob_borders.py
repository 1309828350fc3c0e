"""Which glove blobs share a border in the label image, and over how many pixels.

Two patches that touch on the glove (a thumb pad pressed on a fingertip, or neighbouring
patches of one finger) show as two blobs of different colours whose pixels lie next to each
other in the label image; two that only lie side by side in the view have background between
them unless one occludes the other. :func:`blob_borders` measures, for every pair of blobs, the
pixels of one within ``reach`` pixels (8-neighbourhood steps) of the other.
"""
from __future__ import annotations

import cv2
import numpy as np

from colorglove_ros.core.errors import ColorGloveError

__all__ = ['BlobBorderError', 'DEFAULT_REACH_PX', 'blob_borders']

DEFAULT_REACH_PX = 2        # pixels of background a border may have between two blobs
_MATCH_PX = 1.5             # a blob is the component whose centroid lies this close


class BlobBorderError(ColorGloveError, ValueError):
    """Arrays of inconsistent shapes."""


def _offsets(reach: int) -> list[tuple[int, int]]:
    """Half of the steps (dy, dx) with max(|dy|, |dx|) <= reach, one of each +- pair."""
    return [(dy, dx) for dy in range(0, reach + 1) for dx in range(-reach, reach + 1)
            if (dy, dx) > (0, 0)]


def blob_borders(label_image: np.ndarray, colors: np.ndarray, centroids: np.ndarray,
                 reach: int = DEFAULT_REACH_PX) -> np.ndarray:
    """(B, B) symmetric int64: entry (a, b) the number of label-image pixel pairs, one in blob
    ``a`` and one in blob ``b``, at most ``reach`` pixels apart (Chebyshev), 0 on the
    diagonal. Blobs are given by colour label (B,) and centroid (B, 2; x, y in the label
    image's pixels) and found as the 8-connected component of their colour whose centroid is
    within 1.5 px; a blob with no such component has no border."""
    labels = np.asarray(label_image)
    colors = np.asarray(colors, np.int64).reshape(-1)
    centroids = np.asarray(centroids, float).reshape(-1, 2)
    if labels.ndim != 2 or len(colors) != len(centroids):
        raise BlobBorderError(f'need a 2-D label image and one centroid per colour, got '
                              f'{labels.shape}, {colors.shape}, {centroids.shape}')
    if reach < 1:
        raise BlobBorderError(f'reach must be at least 1 pixel, got {reach}')
    b = len(colors)
    out = np.zeros((b, b), np.int64)
    ys, xs = np.nonzero(labels)
    if b < 2 or not len(ys):
        return out
    y0, x0 = max(ys.min() - reach, 0), max(xs.min() - reach, 0)
    crop = np.ascontiguousarray(labels[y0:ys.max() + 1 + reach, x0:xs.max() + 1 + reach],
                                np.uint8)
    owner = np.zeros(crop.shape, np.int32)          # blob index + 1 of every pixel, 0: none
    for c in np.unique(colors):
        mine = np.flatnonzero(colors == c)
        n, comp, _, cents = cv2.connectedComponentsWithStats(
            cv2.compare(crop, int(c), cv2.CMP_EQ), connectivity=8)
        if n < 2:
            continue
        cents = cents[1:] + (x0, y0)
        for k in mine:
            d = np.hypot(*(cents - centroids[k]).T)
            j = int(np.argmin(d))
            if d[j] <= _MATCH_PX:
                owner[comp == j + 1] = k + 1
    h, w = owner.shape
    for dy, dx in _offsets(reach):
        a = owner[0:h - dy, max(-dx, 0):w - max(dx, 0)]
        c = owner[dy:h, max(dx, 0):w - max(-dx, 0)]
        both = (a > 0) & (c > 0) & (a != c)
        if both.any():
            np.add.at(out, (a[both] - 1, c[both] - 1), 1)
    return out + out.T
