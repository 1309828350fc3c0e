"""The hand's crop predicted from the tracked pose, fed forward to the next frame's segmentation.

The tracker knows where the hand is: its fitted pose, projected through the camera, gives the
glove's visible area in the image. The window the mean-shift crop (``core.segmentation.crop``)
would find on that area alone is the predicted crop (:func:`predict_crop`). The next frame's
segmenter looks for the glove only within a margin of it, so a glove-coloured surface touching
the glove outside that window no longer grows the crop; with no prediction (the track lost, or
the newest prediction too old) it searches the whole frame as before. The ik_node publishes
the prediction of every tracked frame (stamped with that frame), the segmentation node keeps
the newest (:class:`CropFeedback`), and the in-process pipeline runs the same feedback. No
rclpy import.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from colorglove_ros.core.segmentation.crop import (
    DEFAULT_BANDWIDTH_FACTOR,
    CropTransform,
    TinyCrop,
    crop_window,
)

if TYPE_CHECKING:
    from colorglove_ros.core.camera import PinholeCamera
    from colorglove_ros.core.tracking.patch_surface import PatchSurface

__all__ = ['CropPrediction', 'predict_crop', 'window_from_moments', 'CropFeedback',
           'DEFAULT_PREDICTION_MAX_AGE_S', 'prediction_bounds', 'covers',
           'predicted_size_crop']

#: A prediction older than this (seconds before the frame it would serve) is stale: the next
#: frame is searched as without one. The segmentation node's parameter default.
DEFAULT_PREDICTION_MAX_AGE_S = 0.1


@dataclass(frozen=True)
class CropPrediction:
    """Where the next frame's crop should be: the window (centre (x, y), half side, full-image
    pixels) the crop algorithm would find on the glove at the tracked pose, stamped with the
    frame (seconds) whose pose it came from, for an image of ``image_size`` (width, height)."""

    stamp: float
    center_xy: tuple[float, float]
    half_size: float
    image_size: tuple[int, int]


def window_from_moments(weight: np.ndarray, uv: np.ndarray,
                        bandwidth_factor: float = DEFAULT_BANDWIDTH_FACTOR
                        ) -> tuple[tuple[float, float], float] | None:
    """The mean-shift crop's converged window on a glove given as weighted image points
    (``uv`` (M, 2) pixels, ``weight`` (M,) their areas): centre = the weighted mean, half
    side = ``bandwidth_factor`` times the larger per-axis standard deviation (what
    :func:`core.segmentation.crop.mean_shift_crop` converges to on a glove alone). None when
    nothing is visible."""
    weight = np.asarray(weight, float)
    total = float(weight.sum())
    if not total > 0 or not np.all(np.isfinite(uv)):
        return None
    mean = weight @ np.asarray(uv, float) / total
    var = weight @ (np.asarray(uv, float) - mean) ** 2 / total
    return (float(mean[0]), float(mean[1])), bandwidth_factor * math.sqrt(float(var.max()))


def predict_crop(surface: PatchSurface, q: np.ndarray, camera: PinholeCamera, stamp: float
                 ) -> CropPrediction | None:
    """The crop predicted from pose ``q`` (``core.tracking.patch_surface.PatchSurface``'s
    visible glove faces in ``camera``, distorted back into the image), stamped ``stamp``;
    None when no glove is visible at the pose."""
    _, uv, area = surface.visible_faces(q, camera)
    if not len(uv):
        return None
    window = window_from_moments(area, camera.distort_pixels(uv))
    if window is None:
        return None
    center, half = window
    return CropPrediction(float(stamp), center, half, (int(camera.width), int(camera.height)))


def prediction_bounds(prediction: CropPrediction, margin: float, origin: tuple[float, float],
                      reduction: float, shape: tuple[int, int]) -> tuple[int, int, int, int]:
    """Bounds (x0, x1, y0, y1) in a label image of ``shape`` (rows, cols) whose pixel (0, 0)
    covers full-image pixels from ``origin`` (x, y), each ``reduction`` full pixels wide, of
    the window ``margin`` times the predicted one (clipped to the image; may be empty)."""
    (cx, cy), half = prediction.center_xy, margin * prediction.half_size
    ox, oy = origin
    x0 = int(np.floor((cx - half - ox) / reduction))
    x1 = int(np.ceil((cx + half - ox) / reduction)) + 1
    y0 = int(np.floor((cy - half - oy) / reduction))
    y1 = int(np.ceil((cy + half - oy) / reduction)) + 1
    rows, cols = shape
    return max(x0, 0), min(max(x1, 0), cols), max(y0, 0), min(max(y1, 0), rows)


def covers(prediction: CropPrediction, low: tuple[float, float],
           high: tuple[float, float]) -> bool:
    """Whether the box ``low`` <= (x, y) < ``high`` (full-image pixels) holds the predicted
    window's centre."""
    (cx, cy) = prediction.center_xy
    return low[0] <= cx < high[0] and low[1] <= cy < high[1]


def predicted_size_crop(labels: np.ndarray, found: TinyCrop,
                        window: tuple[tuple[float, float], float], max_ratio: float,
                        min_pixels: int, iterations: int = 1) -> TinyCrop | None:
    """``found`` (the crop of ``labels``), or, when its size is more than ``max_ratio`` times
    the predicted ``window``'s ((cx, cy), half, in ``labels``' pixels) or less than its
    inverse, the crop of the predicted size: the predicted window moved ``iterations`` times
    to the mean of the glove pixels inside it (a fixed-size mean shift; more steps drift
    into a large surface touching the hand), None when fewer than ``min_pixels`` glove
    pixels are inside. ``max_ratio`` 0: ``found`` always."""
    half = window[1]
    if max_ratio <= 0 or 1.0 / max_ratio <= found.transform.half_size / half <= max_ratio:
        return found
    glove = np.asarray(labels) > 0
    rows, cols = glove.shape
    (cx, cy) = window[0]
    for _ in range(iterations):
        x0, x1 = max(int(np.ceil(cx - half)), 0), min(int(np.floor(cx + half)) + 1, cols)
        y0, y1 = max(int(np.ceil(cy - half)), 0), min(int(np.floor(cy + half)) + 1, rows)
        ys, xs = np.nonzero(glove[y0:y1, x0:x1])
        if len(xs) < min_pixels:
            return None
        nx, ny = float(xs.mean()) + x0, float(ys.mean()) + y0
        done = abs(nx - cx) < 0.05 and abs(ny - cy) < 0.05
        cx, cy = nx, ny
        if done:
            break
    transform = CropTransform.from_window((cx, cy), half)
    return TinyCrop(crop_window(labels, transform), transform)


class CropFeedback:
    """The newest crop prediction, kept for the next frames: :meth:`offer` gives it a
    prediction (the ik_node's message, or the in-process tracker's), :meth:`for_frame` the
    prediction a frame stamped ``stamp`` may use: the newest, unless it is more than
    ``max_age_s`` older than the frame (stale) or not older than it. :meth:`select` also
    keeps that choice as ``selected``, for the observer of the frame being processed. (The
    segmenter ignores a prediction for another image size.) ``max_age_s`` 0 turns the
    feedback off."""

    def __init__(self, max_age_s: float = DEFAULT_PREDICTION_MAX_AGE_S) -> None:
        if not max_age_s >= 0 or not math.isfinite(max_age_s):
            raise ValueError(f'max_age_s must be finite and >= 0, got {max_age_s!r}')
        self.max_age_s = float(max_age_s)
        self._newest: CropPrediction | None = None
        self.selected: CropPrediction | None = None

    def offer(self, prediction: CropPrediction | None) -> None:
        """Keep ``prediction`` if it is newer than the one kept (None: nothing to keep)."""
        if prediction is not None and (self._newest is None
                                       or prediction.stamp >= self._newest.stamp):
            self._newest = prediction

    def clear(self) -> None:
        """Forget the kept prediction (frames that do not follow each other)."""
        self._newest = self.selected = None

    def for_frame(self, stamp: float) -> CropPrediction | None:
        """The prediction a frame stamped ``stamp`` (seconds) may use, or None."""
        p = self._newest
        if p is None or self.max_age_s <= 0:
            return None
        age = stamp - p.stamp
        return p if 0.0 < age <= self.max_age_s + 1e-9 else None

    def select(self, stamp: float) -> CropPrediction | None:
        """:meth:`for_frame`, kept as ``selected``."""
        self.selected = self.for_frame(stamp)
        return self.selected
