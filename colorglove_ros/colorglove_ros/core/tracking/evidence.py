"""Colour consistency of a fitted pose with the segmented glove: the glove's patches the pose
shows in the image, compared with the blobs the segmenter found.

A fit can explain the blobs it matched and still be wrong: when the segmentation misses some
glove colours (washed out by another camera's colour processing, say), the rest of the hand
looks like a smaller hand farther away, and the lookup and the IK agree with it. The pose then
shows large patches of the missing colours where the image has none. :func:`glove_evidence`
measures that share; the gate on it is ``core.pipeline.missing_glove``. No rclpy import.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from colorglove_ros.core.camera import PinholeCamera
from colorglove_ros.core.tracking.patch_surface import PatchSurface
from colorglove_ros.core.tracking.types import Blobs

__all__ = ['GloveEvidence', 'glove_evidence']


@dataclass(frozen=True)
class GloveEvidence:
    """What the fitted pose shows against what was seen: the visible glove area at the pose
    (pixels), the share of it on patches with no same-colour blob near their visible part
    (``missing_share``; NaN when nothing is visible) and the colours of those patches."""

    shown_px: float
    missing_share: float
    missing_colors: tuple[int, ...]


def glove_evidence(surface: PatchSurface, patch_color: np.ndarray, q: np.ndarray,
                   camera: PinholeCamera, blobs: Blobs, *, min_patch_px: float,
                   near_patch_sizes: float, min_blob_share: float,
                   inside_image_only: bool = False) -> GloveEvidence:
    """Compare the glove at pose ``q`` (``surface``, ``patch_color`` per patch) in ``camera``
    with its observed ``blobs``. A patch counts when at least ``min_patch_px`` of it is
    visible (and, with ``inside_image_only``, for a hand the image border cuts, which shows
    nothing beyond it, the centroid of that part lies inside the image: an uncut hand's fit
    putting glove beyond the border is wrong, and counts); it is found when a blob of its
    colour holding at least ``min_blob_share`` of the patch's visible area lies within
    ``near_patch_sizes`` patch sizes (the square root of the visible area) of the visible
    part's centroid."""
    area, centroid = surface.visible_patches(q, camera)
    shown = float(area.sum())
    counted = area >= min_patch_px
    if inside_image_only:
        counted &= camera.in_image(centroid)
    counted = np.flatnonzero(counted)
    if len(counted) == 0:
        return GloveEvidence(shown, math.nan, ())
    colors = np.asarray(patch_color)[counted]
    found = np.zeros(len(counted), bool)
    if len(blobs):
        xy = camera.undistort_pixels(blobs.centroid_px)
        same = colors[:, None] == blobs.color[None, :]
        big = blobs.pixel_count[None, :] >= min_blob_share * area[counted, None]
        gap = np.linalg.norm(centroid[counted, None, :] - xy[None, :, :], axis=2)
        near = gap <= near_patch_sizes * np.sqrt(area[counted, None])
        found = np.any(same & big & near, axis=1)
    lost = area[counted][~found].sum()
    return GloveEvidence(shown, float(lost / area[counted].sum()),
                         tuple(sorted({int(c) for c in colors[~found]})))
