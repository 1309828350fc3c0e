"""DigitEyes image features of a bare hand: finger-link axes and fingertip centres from edges.

Rehg & Kanade 1993, section 4: a local tracker is placed on each predicted finger link; the
image is sampled in 1-D slices perpendicular to the predicted axis; on every slice the two
silhouette edges are the derivative peaks of the right sign (entering, then leaving a link of
uniform brightness); a line fitted through the midpoints of the edge pairs is the measured
projected cylinder axis. A fingertip (a hemisphere) is measured by a slice along the measured
distal axis: its end edge, moved back by the projected tip radius, is the tip centre.

Everything here works on many links at once (one ``cv2.remap`` samples every slice of every
link) and knows nothing of the hand model: the caller gives predicted segments in pixels.

``polarity`` says which way the link's brightness differs from what surrounds it: +1 the link
is brighter (a hand before a dark backdrop, as in DigitEyes), -1 darker, 0 either (each edge
of a slice's pair may have either sign: a shaded finger before a mid-grey background is
often brighter than it on the lit side and darker on the other).
"""
from __future__ import annotations

import functools
from dataclasses import dataclass
from types import ModuleType

import cv2
import numpy as np

from colorglove_ros.core.errors import ColorGloveError

__all__ = [
    'EdgeFeatureError', 'EdgeSearchConfig', 'LinkAxes', 'TipPoints', 'measure_link_axes',
    'measure_outline_edges', 'measure_tips', 'to_grey', 'segment_distances', 'compiled_kernels',
    'fixed_linspace',
]




class EdgeFeatureError(ColorGloveError):
    """Bad input to the edge measurements (shapes, image type, configuration)."""


@dataclass(frozen=True)
class EdgeSearchConfig:
    """Geometry and thresholds of the local link and tip trackers (pixels, grey levels 0-255).

    ``slice_range`` is the part of each link (0 = base, 1 = end) where the slices are placed,
    avoiding the joints where neighbouring links overlap. A slice reaches ``search_px`` past the
    predicted half-width on both sides; an edge pair is accepted when both derivative peaks
    exceed ``min_gradient`` and the pair's width is within ``width_ratio`` of the predicted one.
    """

    slices_per_link: int = 6
    slice_range: tuple[float, float] = (0.2, 0.85)
    samples_per_slice: int = 33
    search_px: float = 8.0
    min_gradient: float = 3.0
    width_ratio: tuple[float, float] = (0.5, 1.6)
    width_sigma: float = 0.15
    min_slices: int = 3
    fit_outlier_px: float = 2.0
    tip_search_px: float = 10.0
    tip_samples: int = 33

    def __post_init__(self) -> None:
        if self.slices_per_link < 2 or self.samples_per_slice < 5 or self.tip_samples < 5:
            raise EdgeFeatureError('need >= 2 slices per link and >= 5 samples per slice')
        lo, hi = self.slice_range
        if not 0.0 <= lo < hi <= 1.0:
            raise EdgeFeatureError(f'slice_range must satisfy 0 <= lo < hi <= 1, got '
                                   f'{self.slice_range}')
        if not 0.0 < self.width_ratio[0] < 1.0 < self.width_ratio[1]:
            raise EdgeFeatureError(f'width_ratio must bracket 1, got {self.width_ratio}')
        if not 2 <= self.min_slices <= self.slices_per_link:
            raise EdgeFeatureError('min_slices must be in [2, slices_per_link]')
        if self.search_px <= 0 or self.tip_search_px <= 0 or self.min_gradient <= 0:
            raise EdgeFeatureError('search ranges and min_gradient must be positive')


@dataclass(frozen=True)
class LinkAxes:
    """Measured link axes, one row per requested link: the line ``normal . x = offset``
    (unit ``normal``, pixels), whether it was found, how many edge-pair midpoints carried it,
    the measured polarity (+1 brighter than the surroundings, -1 darker, 0 unknown) and the
    midpoints themselves ((L, S, 2), NaN where a slice found no pair)."""

    normal: np.ndarray      # (L, 2)
    offset: np.ndarray      # (L,)
    found: np.ndarray       # (L,) bool
    num_points: np.ndarray  # (L,) int
    polarity: np.ndarray    # (L,) int
    midpoints: np.ndarray   # (L, S, 2)


@dataclass(frozen=True)
class TipPoints:
    """Measured fingertip centres (T, 2) pixels and whether each was found."""

    centre: np.ndarray   # (T, 2)
    found: np.ndarray    # (T,) bool


def to_grey(image: np.ndarray) -> np.ndarray:
    """(H, W) or (H, W, 3) uint8/float image -> (H, W) float32 grey levels (RGB order)."""
    img = np.asarray(image)
    if img.ndim == 3 and img.shape[2] == 3:
        img = cv2.cvtColor(np.ascontiguousarray(img), cv2.COLOR_RGB2GRAY) \
            if img.dtype == np.uint8 else img @ np.array([0.299, 0.587, 0.114])
    elif img.ndim != 2:
        raise EdgeFeatureError(f'image must be (H, W) or (H, W, 3), got {img.shape}')
    return np.asarray(img, dtype=np.float32)


def _sample(grey: np.ndarray, xy: np.ndarray) -> np.ndarray:
    """Bilinear samples of ``grey`` at (..., 2) pixel positions (NaN outside the image)."""
    shape = xy.shape[:-1]
    if not np.size(xy):
        return np.zeros(shape, dtype=np.float32)
    flat = xy.reshape(-1, 2).astype(np.float32)
    mx = np.ascontiguousarray(flat[:, 0]).reshape(-1, 1)
    my = np.ascontiguousarray(flat[:, 1]).reshape(-1, 1)
    out = cv2.remap(grey, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT,
                    borderValue=np.nan)
    return out.reshape(shape)


_KERNELS: list[ModuleType] = []      # edge_kernel, once compiled


def compiled_kernels() -> ModuleType:
    """The edge searches' compiled kernels (:mod:`edge_kernel`): numba is imported, and the
    kernels compiled or loaded from their on-disk cache, on the first call (so importing this
    module, or the nodes that import it, loads no numba)."""
    if not _KERNELS:
        from colorglove_ros.core.tracking import edge_kernel

        edge_kernel.compile_kernels()
        _KERNELS.append(edge_kernel)
    return _KERNELS[0]


@functools.lru_cache(maxsize=64)
def fixed_linspace(start: float, stop: float, num: int) -> np.ndarray:
    """``np.linspace(start, stop, num)``, remembered and read-only: the slices' places and
    sample offsets, the same every frame."""
    out = np.linspace(start, stop, num)
    out.setflags(write=False)
    return out


def _derivative(profile: np.ndarray, step: np.ndarray) -> np.ndarray:
    """Smoothed ([1 2 1] / 4) central-difference derivative along the last axis of float32
    samples, per pixel (``step``: the leading axes' spacing); the end samples get 0, NaN 0
    (``edge_kernel.derivative``)."""
    shape = profile.shape
    rows = np.ascontiguousarray(profile, dtype=np.float32).reshape(-1, shape[-1])
    spacing = np.ascontiguousarray(np.broadcast_to(step, shape[:-1]), dtype=float).reshape(-1)
    return compiled_kernels().derivative(rows, spacing).reshape(shape)


def _check_segments(base: np.ndarray, end: np.ndarray, half_width: np.ndarray
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    base = np.asarray(base, dtype=float)
    end = np.asarray(end, dtype=float)
    half_width = np.asarray(half_width, dtype=float)
    if base.ndim != 2 or base.shape[1] != 2 or end.shape != base.shape \
            or half_width.shape != (len(base),):
        raise EdgeFeatureError('base_px and end_px must be (L, 2) and half_width_px (L,)')
    return base, end, half_width


def _fit_lines(base: np.ndarray, end: np.ndarray, centres: np.ndarray, n: np.ndarray,
               frac: np.ndarray, off: np.ndarray, valid: np.ndarray, cfg: EdgeSearchConfig
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Lines through measured points: per segment ``base -> end`` (L, 2) the points lie at
    ``off`` (L, S) along the normal ``n`` (L, 2) from the slice ``centres`` (L, S, 2) placed
    at fractions ``frac`` (S,); the offset along n is fitted as a linear function of the
    position along the segment (least squares), then refitted without the points farther than
    ``fit_outlier_px``. Returns the lines' unit normals (L, 2) and offsets (L,), the kept
    points' weights (L, S) and the points (L, S, 2; NaN where not kept)
    (``edge_kernel.fit_lines``)."""
    return compiled_kernels().fit_lines(
        np.ascontiguousarray(base), np.ascontiguousarray(end), np.ascontiguousarray(centres),
        np.ascontiguousarray(n), np.ascontiguousarray(frac), np.ascontiguousarray(off),
        np.ascontiguousarray(valid, dtype=bool), float(cfg.fit_outlier_px))


def measure_link_axes(grey: np.ndarray, base_px: np.ndarray, end_px: np.ndarray,
                      half_width_px: np.ndarray, config: EdgeSearchConfig | None = None,
                      polarity: np.ndarray | int = 0,
                      slice_valid: np.ndarray | None = None) -> LinkAxes:
    """Measure the projected axes of L links predicted as segments ``base_px -> end_px`` with
    projected radii ``half_width_px`` in the grey image. ``slice_valid`` (L, S) switches off
    slices known to be occluded or outside the image. Returns :class:`LinkAxes`."""
    cfg = config or EdgeSearchConfig()
    base, end, hw = _check_segments(base_px, end_px, half_width_px)
    base, end, hw = (np.ascontiguousarray(x) for x in (base, end, hw))
    L, S, W = len(base), cfg.slices_per_link, cfg.samples_per_slice
    frac = fixed_linspace(cfg.slice_range[0], cfg.slice_range[1], S)
    kernels = compiled_kernels()
    # the slices' normals, centres, reach and spacing, and the sample maps of those that may
    # be measured (R rows of the (L, S) slices): edge_kernel.link_slice_maps
    n, centres, reach, step, rows, li, mx, my = kernels.link_slice_maps(
        base, end, hw, frac, fixed_linspace(-1.0, 1.0, W), float(cfg.search_px),
        np.ones(L * S, dtype=bool) if slice_valid is None
        else np.ascontiguousarray(slice_valid, dtype=bool).reshape(-1))
    profile = np.zeros((0, W), np.float32) if not len(rows) else cv2.remap(
        grey, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT,
        borderValue=np.nan).reshape(len(rows), W)                              # (R, W)
    d = kernels.derivative(np.ascontiguousarray(profile, dtype=np.float32), step[li])
    pol = np.broadcast_to(np.asarray(polarity, dtype=np.int64), (L,))[li][:, None]
    # edge strengths: a link brighter than its surroundings rises then falls (+1), a darker
    # one falls then rises (-1); with polarity 0 each edge may have either sign, since a
    # shaded cylinder before a mid-grey background can be brighter on one side and darker
    # on the other. Pairs: entering edge at sample i, leaving edge at i + g for the gaps g
    # that give a width within the ratio for some link, scored by their strength discounted
    # by how far the width is from the predicted one (a shaded finger's inner brightness
    # ramp must not beat its true, slightly weaker rim): edge_kernel.pair_search
    lo, hi = cfg.width_ratio
    g_lo = max(1, int(np.floor((2.0 * hw * lo / step).min())))
    g_hi = max(g_lo, min(W - 1, int(np.ceil((2.0 * hw * hi / step).max()))))
    gaps = np.arange(g_lo, g_hi + 1)                                           # (G,)
    width = gaps[None, :] * step[:, None]                                      # (L, G)
    ok_width = (width >= 2.0 * hw[:, None] * lo) & (width <= 2.0 * hw[:, None] * hi)
    agree = np.where(ok_width, np.exp(-0.5 * ((width - 2.0 * hw[:, None])
                                              / (cfg.width_sigma * 2.0 * hw[:, None])) ** 2),
                     0.0)
    found_pair, sign_i, sign_j, ei, ej = kernels.pair_search(
        d, np.ascontiguousarray(pol[:, 0]), bool(np.any(pol != 0)), float(cfg.min_gradient),
        agree, li, g_lo)
    # back to (L, S); a slice not searched has no pair (its offset 0 is weighted 0)
    valid, best_sign, mid_off = kernels.pair_midpoints(found_pair, sign_i, sign_j, ei, ej,
                                                       rows, L, S, W, reach)
    normal, offset, w, midpoints = _fit_lines(base, end, centres, n, frac, mid_off, valid, cfg)
    found, count, sign = kernels.axis_counts(w, best_sign, cfg.min_slices)
    return LinkAxes(normal, offset, found, count, sign, midpoints)


def measure_outline_edges(grey: np.ndarray, base_px: np.ndarray, end_px: np.ndarray,
                          outward_px: np.ndarray, config: EdgeSearchConfig | None = None,
                          slice_valid: np.ndarray | None = None,
                          slice_range: tuple[float, float] | None = None) -> LinkAxes:
    """Measure L single silhouette edges (e.g. the sides of the palm) predicted as segments
    ``base_px -> end_px``: on each slice across the segment (``slice_range`` of it, default
    the config's) the strongest derivative peak within ``search_px`` of the prediction (either
    sign, discounted by its distance from the prediction with a Gaussian of sigma
    ``search_px / 2``) is the edge; a line is fitted through the edge points as for
    :func:`measure_link_axes`. ``outward_px`` (L, 2) is any vector pointing out of the shape
    (only its side matters): the returned normals point outward. Returns :class:`LinkAxes`
    (polarity +1 where the shape is brighter than its surroundings)."""
    cfg = config or EdgeSearchConfig()
    base, end, _ = _check_segments(base_px, end_px, np.zeros(len(np.atleast_2d(base_px))))
    out = np.asarray(outward_px, dtype=float).reshape(base.shape)
    L, S, W = len(base), cfg.slices_per_link, cfg.samples_per_slice
    axis = end - base
    u = axis / np.maximum(np.linalg.norm(axis, axis=1), 1e-9)[:, None]
    n = np.stack([-u[:, 1], u[:, 0]], axis=1)
    n *= np.where(np.einsum('ij,ij->i', n, out) < 0, -1.0, 1.0)[:, None]
    frac = fixed_linspace(*(slice_range or cfg.slice_range), S)
    centres = base[:, None, :] + frac[None, :, None] * axis[:, None, :]        # (L, S, 2)
    t = fixed_linspace(-cfg.search_px, cfg.search_px, W)                       # (W,)
    step = np.full((L, S), 2.0 * cfg.search_px / (W - 1))
    xy = centres[:, :, None, :] + t[None, None, :, None] * n[:, None, None, :]
    d = _derivative(_sample(grey, xy), step).reshape(L * S, W)
    # the strongest edge, discounted by its distance from the prediction (edge_kernel)
    valid, sign, refined = compiled_kernels().edge_peaks(
        d, np.exp(-0.5 * (t / (0.5 * cfg.search_px)) ** 2), float(cfg.min_gradient))
    valid, sign, refined = valid.reshape(L, S), sign.reshape(L, S), refined.reshape(L, S)
    if slice_valid is not None:
        valid &= np.asarray(slice_valid, dtype=bool).reshape(L, S)
    off = -cfg.search_px + refined * step
    normal, offset, w, points = _fit_lines(base, end, centres, n, frac, off, valid, cfg)
    # re-orient the fitted normals outward (they follow the direction of n)
    flip = np.einsum('ij,ij->i', normal, n) < 0
    normal = np.where(flip[:, None], -normal, normal)
    offset = np.where(flip, -offset, offset)
    # brighter inside: the grey level falls going outward
    signs = np.where(w > 0, -sign, 0).sum(1)
    return LinkAxes(normal, offset, w.sum(1) >= cfg.min_slices, w.sum(1).astype(np.int64),
                    np.sign(signs).astype(np.int64), points)


def measure_tips(grey: np.ndarray, axis_point_px: np.ndarray, direction_px: np.ndarray,
                 predicted_end_px: np.ndarray, radius_px: np.ndarray,
                 config: EdgeSearchConfig | None = None,
                 polarity: np.ndarray | int = 0) -> TipPoints:
    """Measure T fingertip centres. Each distal axis is given by a point on it and its unit
    direction toward the tip (the measured line, or the predicted one); the slice runs along
    it from ``tip_search_px`` before to ``tip_search_px`` past the predicted extremity
    ``predicted_end_px`` (its projection on the axis). The end edge is the strongest
    derivative peak leaving the finger (sign from ``polarity``; 0 takes the stronger of the
    two); the centre is that edge moved back by ``radius_px`` along the axis."""
    cfg = config or EdgeSearchConfig()
    p0 = np.asarray(axis_point_px, dtype=float)
    u = np.asarray(direction_px, dtype=float)
    end = np.asarray(predicted_end_px, dtype=float)
    r = np.asarray(radius_px, dtype=float)
    if p0.ndim != 2 or p0.shape[1] != 2 or u.shape != p0.shape or end.shape != p0.shape \
            or r.shape != (len(p0),):
        raise EdgeFeatureError('tip inputs must be (T, 2) points/directions and (T,) radii')
    u = u / np.maximum(np.linalg.norm(u, axis=1, keepdims=True), 1e-9)
    along_end = np.einsum('ij,ij->i', end - p0, u)
    start = p0 + (along_end - cfg.tip_search_px - r)[:, None] * u              # (T, 2)
    span = 2.0 * cfg.tip_search_px + r
    t = fixed_linspace(0.0, 1.0, cfg.tip_samples)
    pos = span[:, None] * t[None, :]                                           # (T, N)
    xy = start[:, None, :] + pos[..., None] * u[:, None, :]
    profile = _sample(grey, xy)
    step = span / (cfg.tip_samples - 1)
    d = _derivative(profile, step)
    pol = np.ascontiguousarray(np.broadcast_to(np.asarray(polarity, dtype=np.int64), (len(p0),)))
    # a brighter finger's grey level drops past its end, a darker one's rises (edge_kernel)
    found, refined = compiled_kernels().tip_peaks(d, pol, float(cfg.min_gradient))
    edge = start + (refined * step)[:, None] * u
    return TipPoints(edge - r[:, None] * u, found)


def segment_distances(points: np.ndarray, seg_a: np.ndarray, seg_b: np.ndarray
                      ) -> tuple[np.ndarray, np.ndarray]:
    """Distance from each of (P, 2) points to each of (M, 2)->(M, 2) segments, (P, M), and
    the position of the closest point along each segment in [0, 1], (P, M)
    (``edge_kernel.segment_distances``)."""
    p, a, b = (np.ascontiguousarray(x, dtype=float).reshape(-1, 2)
               for x in (points, seg_a, seg_b))
    return compiled_kernels().segment_distances(p, a, b)
