"""Glove blobs: the connected components of each glove colour of a label image, found once for
the segmenter and for the tracker's observations."""
from __future__ import annotations

import cv2
import numpy as np

from colorglove_ros.core.conventions import NUM_COLORS
from colorglove_ros.core.segmentation.color_model import MAX_GLOVE_COLORS
from colorglove_ros.core.segmentation.crop import compiled_kernels
from colorglove_ros.core.tracking.types import Blobs, IKError

__all__ = ['color_components', 'extract_blobs']


def color_components(labels: np.ndarray, min_pixels: int, num_colors: int = NUM_COLORS,
                     crop_to_color: bool = True
                     ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """8-connected components of each glove colour 1..``num_colors`` of a 2-D label image
    (0 = background) with at least ``min_pixels`` pixels: colours (B,) int64, centroids (B, 2)
    (x, y in the label image's pixels) and pixel counts (B,) int64, colour by colour in
    ascending order and within a colour in OpenCV's order (by the first 2 x 2 block, in raster
    order of the blocks of the colour's rectangle, holding a pixel of the component).

    With ``crop_to_color`` (faster) each colour is labelled inside its bounding rectangle and
    its centroids shifted back, which agrees with labelling the whole image up to the
    rounding of that shift; on a uint8 image that is one compiled pass
    (``segmentation_kernel.colour_blobs``, the same components, order and bits as OpenCV's
    per colour)."""
    if (labels.dtype == np.uint8 and labels.ndim == 2 and crop_to_color
            and num_colors <= MAX_GLOVE_COLORS):
        return compiled_kernels().colour_blobs(labels, int(num_colors), int(min_pixels))
    counts = np.bincount(labels.ravel(), minlength=num_colors + 1)
    colors: list[int] = []
    cents: list[np.ndarray] = []
    areas: list[int] = []
    for c in np.flatnonzero(counts[1:num_colors + 1] >= min_pixels) + 1:
        if labels.dtype == np.uint8:
            m = cv2.compare(labels, int(c), cv2.CMP_EQ)
        else:
            m = np.equal(labels, c).view(np.uint8)
        bx, by, bw, bh = cv2.boundingRect(m) if crop_to_color else (0, 0, *m.shape[::-1])
        # 16-bit component labels (faster) whenever they cannot overflow
        ltype = cv2.CV_16U if bw * bh < np.iinfo(np.uint16).max else cv2.CV_32S
        n, _, stats, centroids = cv2.connectedComponentsWithStats(
            m[by:by + bh, bx:bx + bw], connectivity=8, ltype=ltype)
        for k in range(1, n):
            area = int(stats[k, cv2.CC_STAT_AREA])
            if area >= min_pixels:
                colors.append(int(c))
                cents.append(centroids[k] + (bx, by) if crop_to_color else centroids[k])
                areas.append(area)
    if not colors:
        return np.zeros(0, np.int64), np.zeros((0, 2)), np.zeros(0, np.int64)
    return np.array(colors, np.int64), np.array(cents, float), np.array(areas, np.int64)


def extract_blobs(labels: np.ndarray, min_pixels: int = 4,
                  num_colors: int = NUM_COLORS) -> Blobs:
    """The tracker's :class:`Blobs` of a whole label image (0 = background): every
    component of each glove colour with at least ``min_pixels`` pixels."""
    labels = np.asarray(labels)
    if labels.ndim != 2:
        raise IKError(f'label image must be 2-D, got shape {labels.shape}')
    colors, cents, areas = color_components(labels, min_pixels, num_colors, crop_to_color=False)
    if not len(colors):
        return Blobs.empty()
    return Blobs(colors, cents, areas.astype(float))
