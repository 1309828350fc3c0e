"""Hand silhouettes from a calibrated empty scene, and how well a predicted hand explains them.

The edge fit (:mod:`edge_fit`) minimises distances to the edges it finds, so a fit that has
taken a finger's edges from its neighbour, or slid along the fingers, can keep a small
residual. The silhouette is evidence it does not already minimise: a static camera's
foreground (the hand and forearm) against a background model the user captures once with
the scene empty (:class:`BackgroundModel`, the per-pixel mean of one or more empty frames;
a pixel is foreground when some channel differs from it by more than ``threshold`` grey
levels). No ground truth and no skin colour is used, so skin-coloured objects in the
background do not count as hand.

Two comparisons with a predicted hand (pixels of its link axes, fingertips and palm outline):

* off the silhouette: a point of the hand's axes outside the foreground, by the foreground's
  outside distance transform (:meth:`Silhouette.outside_distance`); every point of the hand
  projects inside its silhouette, whatever occludes it;
* unexplained: foreground pixels farther than a tolerance from every predicted link capsule,
  tip disc and the palm's outline (:meth:`Silhouette.unexplained`), leaving out the forearm:
  the pixels beyond the wrist, across the line through the wrist perpendicular to the
  projected hand axis.

The mask is computed at ``1 / scale`` of the image resolution (distances are returned in full
resolution pixels).
"""
from __future__ import annotations

import os
from collections.abc import Sequence
from dataclasses import dataclass

import cv2
import numpy as np

from colorglove_ros.core.errors import ColorGloveError
from colorglove_ros.core.tracking.edge_features import compiled_kernels

__all__ = ['SilhouetteError', 'SilhouetteConfig', 'BackgroundModel', 'Silhouette',
           'HandOutline', 'read_background']


class SilhouetteError(ColorGloveError):
    """Bad silhouette input: background frames, image shapes or settings."""


@dataclass(frozen=True)
class SilhouetteConfig:
    """Foreground threshold (grey levels, largest channel difference to the background), the
    mask's downscale factor, and the radius (mask pixels) of the opening that removes
    isolated noise pixels (0: none)."""

    threshold: float = 30.0
    scale: int = 2
    open_radius: int = 1

    def __post_init__(self) -> None:
        if not self.threshold > 0 or self.scale < 1 or self.open_radius < 0:
            raise SilhouetteError(f'need threshold > 0, scale >= 1, open_radius >= 0, got '
                                  f'{self.threshold}, {self.scale}, {self.open_radius}')


def _small(image: np.ndarray, scale: int) -> np.ndarray:
    """The image at 1 / scale (area averaging), (h, w, C) in its own dtype."""
    img = np.asarray(image)
    if img.ndim not in (2, 3) or (img.ndim == 3 and img.shape[2] > 4):
        raise SilhouetteError(f'image must be (H, W) or (H, W, C), got {np.shape(image)}')
    if scale > 1:
        h, w = img.shape[0] // scale, img.shape[1] // scale
        img = cv2.resize(img, (w, h), interpolation=cv2.INTER_AREA)
    return img.reshape(img.shape[0], img.shape[1], -1)


@dataclass(frozen=True)
class BackgroundModel:
    """One camera's empty scene: the mean of the calibration frames at ``1 / config.scale``
    resolution, (h, w, C) float32, and the full image size."""

    mean: np.ndarray
    width: int
    height: int
    config: SilhouetteConfig

    @classmethod
    def from_frames(cls, frames: Sequence[np.ndarray],
                    config: SilhouetteConfig | None = None) -> BackgroundModel:
        """The model of one camera from frames of its empty scene (all the same shape)."""
        cfg = config or SilhouetteConfig()
        if not len(frames):
            raise SilhouetteError('need at least one empty-scene frame')
        shapes = {np.shape(f) for f in frames}
        if len(shapes) != 1:
            raise SilhouetteError(f'empty-scene frames differ in shape: {sorted(shapes)}')
        height, width = np.shape(frames[0])[:2]
        mean = np.mean([_small(f, cfg.scale) for f in frames], axis=0, dtype=np.float32)
        return cls(mean, int(width), int(height), cfg)

    def silhouette(self, image: np.ndarray,
                   region: tuple[float, float, float, float] | None = None) -> Silhouette:
        """The foreground of ``image`` (same size and channels as the empty frames), only
        within ``region`` (x0, y0, x1, y1 full-resolution pixels, clipped to the image; None:
        everywhere): nothing outside it counts as foreground."""
        if np.shape(image)[:2] != (self.height, self.width):
            raise SilhouetteError(f'image is {np.shape(image)[1]}x{np.shape(image)[0]}, the '
                                  f'background {self.width}x{self.height}')
        s = self.config.scale
        h, w = self.mean.shape[:2]
        x0, y0, x1, y1 = (0, 0, w, h)
        if region is not None:
            lo = np.floor(np.asarray(region[:2], dtype=float) / s)
            hi = np.ceil(np.asarray(region[2:], dtype=float) / s)
            x0, y0 = (int(v) for v in np.clip(lo, 0, (w, h)))
            x1, y1 = (int(v) for v in np.clip(hi, 0, (w, h)))
        if x1 <= x0 or y1 <= y0:
            return Silhouette(np.zeros((1, 1), bool), s, (0, 0))
        img = np.asarray(image)[y0 * s:y1 * s, x0 * s:x1 * s]
        small = _small(img, s)
        mean = self.mean[y0:y1, x0:x1]
        if small.shape[2] != mean.shape[2]:
            raise SilhouetteError(f'image has {small.shape[2]} channel(s), the background '
                                  f'{mean.shape[2]}')
        diff = cv2.absdiff(small.astype(np.float32), mean)
        if diff.ndim == 3:
            diff = np.maximum.reduce([diff[..., c] for c in range(diff.shape[2])])
        mask = (diff > self.config.threshold).astype(np.uint8)
        r = self.config.open_radius
        if r > 0:
            kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * r + 1, 2 * r + 1))
            mask = cv2.morphologyEx(mask, cv2.MORPH_OPEN, kernel)
        return Silhouette(mask.astype(bool), s, (x0, y0))


def read_background(path: str | os.PathLike, config: SilhouetteConfig | None = None
                    ) -> BackgroundModel:
    """The background model of one empty-scene image file (colour as RGB, or grey)."""
    image = cv2.imread(os.fspath(path), cv2.IMREAD_UNCHANGED)
    if image is None:
        raise SilhouetteError(f'cannot read the empty-scene image {os.fspath(path)!r}')
    if image.ndim == 3:
        image = cv2.cvtColor(image, cv2.COLOR_BGRA2RGB if image.shape[2] == 4
                             else cv2.COLOR_BGR2RGB)
    return BackgroundModel.from_frames([image], config)


@dataclass(frozen=True)
class HandOutline:
    """A predicted hand in one camera's pixels: link capsules (segments ``base`` -> ``end``
    (L, 2) with half-widths (L,)), tip discs (centres (T, 2), radii (T,)), the palm's
    outline as a polygon (K, 2), the wrist pixel and the hand axis's direction from the wrist
    toward the fingers (2,)."""

    base: np.ndarray
    end: np.ndarray
    half_width: np.ndarray
    tip: np.ndarray
    tip_radius: np.ndarray
    palm: np.ndarray
    wrist: np.ndarray
    axis: np.ndarray


class Silhouette:
    """One frame's foreground mask ((h, w) bool at ``1 / scale`` resolution, its first pixel
    at ``offset`` (x, y) mask pixels into the image) with its outside distance transform."""

    def __init__(self, mask: np.ndarray, scale: int, offset: tuple[int, int] = (0, 0)) -> None:
        self.mask = np.asarray(mask, dtype=bool)
        self._mask_u8 = self.mask.astype(np.uint8)
        self.scale = int(scale)
        self.offset = np.array(offset, dtype=float)
        if self.mask.any():
            outside = cv2.distanceTransform((~self.mask).astype(np.uint8), cv2.DIST_L2, 3)
        else:
            outside = np.full(self.mask.shape, np.float32(max(self.mask.shape)))
        self._outside = np.ascontiguousarray(outside * np.float32(self.scale))

    @property
    def area_px(self) -> float:
        """Foreground area in full-resolution pixels."""
        return float(self.mask.sum()) * self.scale ** 2

    def outside_distance(self, px: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Distance (full-resolution pixels, 0 inside) from each of (N, 2) pixels to the
        foreground, and its gradient (N, 2) (central differences one mask pixel apart)."""
        px = np.ascontiguousarray(px, dtype=float).reshape(-1, 2)
        if not len(px):
            return np.zeros(0, np.float32), np.zeros((0, 2), np.float32)
        kernels = compiled_kernels()
        mx, my = kernels.probe_maps(px, self.scale, self.offset)
        v = cv2.remap(self._outside, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
        return kernels.probe_gradients(v.reshape(-1, 1), self.scale)

    def unexplained(self, outline: HandOutline, tolerance_px: float, pixels: bool = True
                    ) -> tuple[np.ndarray, float]:
        """Foreground pixels (full-resolution coordinates, (M, 2); none listed unless
        ``pixels``) farther than ``tolerance_px`` from every part of ``outline``, and their
        share of the hand's foreground (the forearm, beyond the wrist, left out of both)."""
        s = self.scale
        tol = float(tolerance_px)
        shift = s * self.offset
        # the forearm: the half-plane beyond the line through the wrist across the hand axis,
        # cleared from a copy of the mask
        h, w = self.mask.shape
        big = 4.0 * (h + w + np.abs(self.offset).sum())
        a = np.asarray(outline.axis, dtype=float)
        across = np.array([-a[1], a[0]])
        start = (outline.wrist - shift + 0.5) / s - 0.5 - (tol / s) * a
        quad = start + big * np.array([across, -across, -across - a, across - a])
        hand = self._mask_u8.copy()
        cv2.fillConvexPoly(hand, np.round(quad * 16).astype(np.int32), 0, cv2.LINE_8, 4)
        count = cv2.countNonZero(hand)
        if count == 0:
            return np.zeros((0, 2)), 0.0
        # what the hand explains (capsules, tip discs, the palm's hull, each widened by the
        # tolerance) cleared from it in turn: the pixels left are the unexplained ones
        loose = hand
        ends, thick, tips, radii = compiled_kernels().outline_drawing(
            np.ascontiguousarray(outline.base, dtype=float),
            np.ascontiguousarray(outline.end, dtype=float),
            np.ascontiguousarray(outline.half_width, dtype=float),
            np.ascontiguousarray(outline.tip, dtype=float).reshape(-1, 2),
            np.ascontiguousarray(outline.tip_radius, dtype=float), shift, s, tol)
        # one call per thickness (the capsules come sorted by it): a two-point polyline is
        # drawn as cv2.line draws it
        start = 0
        for stop in [*np.flatnonzero(np.diff(thick)) + 1, len(thick)]:
            if stop > start:
                cv2.polylines(loose, list(ends[start:stop]), False, 0, int(thick[start]),
                              cv2.LINE_8, 4)
            start = stop
        for c, r in zip(tips.tolist(), radii.tolist(), strict=True):
            cv2.circle(loose, tuple(c), r, 0, -1, cv2.LINE_8, 4)
        if len(outline.palm) >= 3 and np.all(np.isfinite(outline.palm)):
            hull = cv2.convexHull(np.round(((outline.palm - shift + 0.5) / s - 0.5) * 16)
                                  .astype(np.int32))
            cv2.fillConvexPoly(loose, hull, 0, cv2.LINE_8, 4)
            if tol > 0:
                cv2.polylines(loose, [hull], True, 0, max(1, int(round(2.0 * tol / s))),
                              cv2.LINE_8, 4)
        if not pixels:
            return np.zeros((0, 2)), float(cv2.countNonZero(loose)) / float(count)
        found = cv2.findNonZero(loose)
        if found is None:
            return np.zeros((0, 2)), 0.0
        pix = (found.reshape(-1, 2) + self.offset + 0.5) * s - 0.5
        return pix, float(len(pix)) / float(count)

