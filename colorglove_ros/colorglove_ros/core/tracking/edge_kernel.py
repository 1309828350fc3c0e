"""Compiled (numba) kernels of the edge tracker's 1-D edge searches (:mod:`edge_features`):
the smoothed derivative of the sampled slices, the link slices' edge-pair search, the palm
outline's single-edge and the fingertips' end-edge searches with their sub-pixel peaks, the
distances of points to segments (:func:`segment_distances`: the silhouette targets of
:mod:`edge_fit`) and the prediction's occlusion tests (:func:`occluded_slices`,
:func:`behind_palm`).

The same arithmetic as the numpy code they replaced, in the same dtypes (the slices' float32
derivative, float64 pair scores, the first of equal maxima) and order, so the measurements are
the same bits; the transcendental parts (the width discount's ``exp``) stay in numpy. Every
kernel is compiled once and cached on disk (``cache=True``); :func:`compile_kernels` makes (or
loads) them ahead of the first frame and allows no other signature. Arrays passed in must be
C-contiguous and of the dtypes in ``_SIGNATURES``, as :mod:`edge_features` makes them.
"""
from __future__ import annotations

import numba
import numpy as np

from colorglove_ros.core.kernel_compile import compile_signatures

__all__ = ['derivative', 'pair_search', 'edge_peaks', 'tip_peaks', 'segment_distances',
           'occluded_slices', 'behind_palm', 'fit_lines', 'line_rows', 'axis_points',
           'silhouette_rows', 'probe_maps', 'probe_gradients', 'link_slice_maps',
           'pair_midpoints', 'axis_counts', 'link_prediction', 'tip_prediction',
           'palm_prediction', 'outline_drawing',
           'compile_kernels']

_JIT = {'cache': True, 'nogil': True}
_NO_EDGE = -1.0e9   # edge_features._NO_EDGE: any pair using such a sample scores < 0


@numba.njit(**_JIT)
def derivative(profile: np.ndarray, step: np.ndarray) -> np.ndarray:
    """``edge_features._derivative`` of (R, W) float32 slices with per-slice sample spacing
    ``step`` (R,): the [1 2 1] / 4 smoothing in float32, the central difference over
    ``2 step`` in float64 rounded to float32, 0 at the ends and where NaN."""
    rows, width = profile.shape
    out = np.zeros((rows, width), np.float32)
    quarter, half = np.float32(0.25), np.float32(0.5)
    for r in range(rows):
        p = profile[r]
        s = np.empty(width, np.float32)
        s[0], s[width - 1] = p[0], p[width - 1]
        for i in range(1, width - 1):
            s[i] = quarter * p[i - 1] + half * p[i] + quarter * p[i + 1]
        twice = 2.0 * step[r]
        for i in range(1, width - 1):
            v = np.float32(np.float64(s[i + 1] - s[i - 1]) / twice)
            out[r, i] = np.float32(0.0) if np.isnan(v) else v
    return out


@numba.njit(**_JIT)
def _subpixel(d: np.ndarray, index: int, sign: int) -> float:
    """``edge_features._subpixel`` of one float32 row at peak ``index`` (of ``-d`` where
    ``sign`` < 0): the parabola's vertex in float32, clipped to half a sample."""
    n = len(d)
    i = min(max(index, 1), n - 2)
    a, b, c = d[i - 1], d[i], d[i + 1]
    if sign < 0:
        a, b, c = -a, -b, -c
    den = a - np.float32(2.0) * b + c
    shift = np.float32(0.0)
    if abs(den) > np.float32(1e-9):
        shift = np.float32(0.5) * (a - c) / den
    shift = min(max(shift, np.float32(-0.5)), np.float32(0.5))
    return np.float64(i) + np.float64(shift)


@numba.njit(**_JIT)
def pair_search(d: np.ndarray, polarity: np.ndarray, signed: bool, min_gradient: float,
                agree: np.ndarray, link: np.ndarray, g_lo: int
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The edge-pair search of ``edge_features.measure_link_axes`` on R slices' derivatives
    ``d`` (R, W float32): per slice the entering edge at sample i and the leaving edge at
    i + g (gaps ``g_lo`` .. ``g_lo + G - 1``) maximising their strengths' sum times the width
    agreement ``agree[link[r], g - g_lo]`` (L, G); edges of strength at most
    ``min_gradient`` count as none. ``polarity`` (R,) as there; ``signed`` whether any is
    non-zero (then the strengths are float64, else float32, as numpy's). Returns whether a
    pair was found, the signs of the two edges (int64) and their sub-pixel positions."""
    rows, width = d.shape
    gaps = agree.shape[1]
    found = np.zeros(rows, np.bool_)
    sign_i = np.zeros(rows, np.int64)
    sign_j = np.zeros(rows, np.int64)
    ei = np.zeros(rows)
    ej = np.zeros(rows)
    enter = np.empty(width)
    leave = np.empty(width)
    low32 = np.float32(min_gradient)
    for r in range(rows):
        pol = polarity[r]
        for i in range(width):
            v = d[r, i]
            if signed:
                a = abs(np.float64(v)) if pol == 0 else np.float64(pol) * np.float64(v)
                b = abs(np.float64(v)) if pol == 0 else -np.float64(pol) * np.float64(v)
                enter[i] = a if a > min_gradient else _NO_EDGE
                leave[i] = b if b > min_gradient else _NO_EDGE
            else:
                a32 = abs(v)
                enter[i] = np.float64(a32) if a32 > low32 else _NO_EDGE
                leave[i] = enter[i]
        row = agree[link[r]]
        best, bi, bj = -np.inf, 0, 0
        for i in range(width):
            for k in range(gaps):
                j = i + g_lo + k
                later = leave[j] if j < width else _NO_EDGE
                score = (enter[i] + later) * row[k]
                if score > best:
                    best, bi, bj = score, i, j
        found[r] = best > 0 and bj < width
        bj = min(bj, width - 1)   # a pair past the slice's end is never found
        si, sj = d[r, bi], d[r, bj]
        sign_i[r] = 1 if si > 0 else (-1 if si < 0 else 0)
        sign_j[r] = 1 if sj > 0 else (-1 if sj < 0 else 0)
        ei[r] = _subpixel(d[r], bi, sign_i[r])
        ej[r] = _subpixel(d[r], bj, sign_j[r])
    return found, sign_i, sign_j, ei, ej


@numba.njit(**_JIT)
def edge_peaks(d: np.ndarray, weight: np.ndarray, min_gradient: float
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The single-edge search of ``edge_features.measure_outline_edges`` on R slices'
    derivatives ``d`` (R, W float32): per slice the sample maximising ``|d|`` times
    ``weight`` (W,; the end samples never), whether its ``|d|`` exceeds ``min_gradient``
    (float32, as numpy compares it), its sign and its sub-pixel position."""
    rows, width = d.shape
    strong = np.zeros(rows, np.bool_)
    sign = np.zeros(rows, np.int64)
    refined = np.zeros(rows)
    low32 = np.float32(min_gradient)
    for r in range(rows):
        best, k = -np.inf, 0
        for i in range(width):
            score = 0.0 if i == 0 or i == width - 1 else np.float64(abs(d[r, i])) * weight[i]
            if score > best:
                best, k = score, i
        v = d[r, k]
        strong[r] = abs(v) > low32
        sign[r] = 1 if v > 0 else (-1 if v < 0 else 0)
        refined[r] = _subpixel(d[r], k, sign[r])
    return strong, sign, refined


@numba.njit(**_JIT)
def tip_peaks(d: np.ndarray, polarity: np.ndarray, min_gradient: float
              ) -> tuple[np.ndarray, np.ndarray]:
    """The end-edge search of ``edge_features.measure_tips`` on T slices' derivatives ``d``
    (T, N float32) along the distal axes: per slice the strongest drop (a brighter finger,
    ``polarity`` >= 0) or rise (a darker one, <= 0), whether it exceeds ``min_gradient``
    (float32) and its sub-pixel position (the parabola of the signed derivative in float64,
    as numpy promotes it)."""
    rows, width = d.shape
    found = np.zeros(rows, np.bool_)
    refined = np.zeros(rows)
    low32 = np.float32(min_gradient)
    row = np.empty(width)
    for r in range(rows):
        pol = polarity[r]
        best, k, k_sign = np.float32(-np.inf), 0, 1.0
        for i in range(width):
            bright = -d[r, i] if pol >= 0 else np.float32(-np.inf)
            dark = d[r, i] if pol <= 0 else np.float32(-np.inf)
            score = bright if bright >= dark else dark     # np.maximum: no NaN here
            if score > best:
                best, k, k_sign = score, i, -1.0 if bright >= dark else 1.0
        found[r] = best > low32
        for i in range(width):
            row[i] = k_sign * np.float64(d[r, i])
        i = min(max(k, 1), width - 2)
        a, b, c = row[i - 1], row[i], row[i + 1]
        den = a - 2.0 * b + c
        shift = 0.5 * (a - c) / den if abs(den) > 1e-9 else 0.0
        refined[r] = np.float64(i) + min(max(shift, -0.5), 0.5)
    return found, refined


@numba.njit(inline='always', **_JIT)
def _at_least(x: float, floor: float) -> float:
    """``np.maximum(x, floor)`` of one value (NaN kept)."""
    return x if x >= floor or np.isnan(x) else floor


@numba.njit(inline='always', **_JIT)
def _closest(px: float, py: float, ax: float, ay: float, bx: float, by: float, den: float
             ) -> tuple[float, float]:
    """Distance from (px, py) to the segment from (ax, ay) along (bx, by) (``den``: its
    squared length, at least 1e-12) and the closest point's place on it in [0, 1], in
    numpy's order of operations (``np.clip`` keeps NaN)."""
    s = ((px - ax) * bx + (py - ay) * by) / den
    if not (np.isnan(s) or s > 0.0):
        s = 0.0
    if not (np.isnan(s) or s < 1.0):
        s = 1.0
    dx, dy = px - (ax + s * bx), py - (ay + s * by)
    return np.sqrt(dx * dx + dy * dy), s


@numba.njit(inline='always', **_JIT)
def _squared_length(bx: float, by: float) -> float:
    """``np.maximum(bx^2 + by^2, 1e-12)`` (NaN kept)."""
    den = bx * bx + by * by
    return _at_least(den, 1e-12)


@numba.njit(**_JIT)
def segment_distances(points: np.ndarray, seg_a: np.ndarray, seg_b: np.ndarray
                      ) -> tuple[np.ndarray, np.ndarray]:
    """``edge_features.segment_distances``: the distance from each of (P, 2) points to each
    of (M, 2) -> (M, 2) segments (P, M) and the closest point's place along it in [0, 1]."""
    P, M = len(points), len(seg_a)
    dist = np.empty((P, M))
    along = np.empty((P, M))
    for m in range(M):
        ax, ay = seg_a[m, 0], seg_a[m, 1]
        bx, by = seg_b[m, 0] - ax, seg_b[m, 1] - ay
        den = _squared_length(bx, by)
        for p in range(P):
            dist[p, m], along[p, m] = _closest(points[p, 0], points[p, 1], ax, ay, bx, by, den)
    return dist, along


@numba.njit(**_JIT)
def occluded_slices(centres: np.ndarray, slices: int, base: np.ndarray, end: np.ndarray,
                    zb: np.ndarray, ze: np.ndarray, hw: np.ndarray, z_self: np.ndarray,
                    margin: float, usable: np.ndarray, exempt: np.ndarray) -> np.ndarray:
    """The link occlusion test of ``edge_fit.predict_features``: slice k (of ``slices`` per
    link, centres (L * slices, 2), depths ``z_self``) of link l is occluded where a usable
    link m not ``exempt[l, m]`` (itself, its parent or child) lies nearer the camera at the
    slice's closest point (depths ``zb`` -> ``ze`` along it) and their projected capsules
    (half-widths ``hw``) overlap, widened by ``margin``."""
    L = len(base)
    out = np.zeros(len(centres), np.bool_)
    for m in range(L):
        if not usable[m]:
            continue
        ax, ay = base[m, 0], base[m, 1]
        bx, by = end[m, 0] - ax, end[m, 1] - ay
        den = _squared_length(bx, by)
        for k in range(len(centres)):
            if out[k] or exempt[k // slices, m]:
                continue
            dist, s = _closest(centres[k, 0], centres[k, 1], ax, ay, bx, by, den)
            if dist < hw[m] + hw[k // slices] + margin \
                    and zb[m] + s * (ze[m] - zb[m]) < z_self[k]:
                out[k] = True
    return out


@numba.njit(**_JIT)
def behind_palm(hull: np.ndarray, centres: np.ndarray, palm_px: np.ndarray,
                palm_depth: np.ndarray, near_px2: float, z_self: np.ndarray,
                radius: np.ndarray) -> np.ndarray:
    """The palm occlusion test of ``edge_fit._behind_palm``: which slice centres (N, 2)
    inside or on the convex polygon ``hull`` (K, 2; none for fewer than 3 vertices) lie
    farther (``z_self``) than the nearest palm point (pixels ``palm_px`` (V, 2), depths
    ``palm_depth``) within ``sqrt(near_px2)`` pixels, or the nearest one, plus the slice's
    link ``radius``."""
    N, K, V = len(centres), len(hull), len(palm_px)
    out = np.zeros(N, np.bool_)
    if K < 3:
        return out
    for n in range(N):
        px, py = centres[n, 0], centres[n, 1]
        pos = neg = True
        for k in range(K):
            j = k + 1 if k + 1 < K else 0
            ex, ey = hull[j, 0] - hull[k, 0], hull[j, 1] - hull[k, 1]
            cross = ex * (py - hull[k, 1]) - ey * (px - hull[k, 0])
            pos = pos and cross >= 0
            neg = neg and cross <= 0
        if not (pos or neg):
            continue
        z_palm, nearest, best = np.inf, np.inf, np.inf
        for v in range(V):
            dx, dy = px - palm_px[v, 0], py - palm_px[v, 1]
            d2 = dx * dx + dy * dy
            if d2 < best:
                best, nearest = d2, palm_depth[v]
            if d2 <= near_px2 and palm_depth[v] < z_palm:
                z_palm = palm_depth[v]
        z_palm = min(z_palm, nearest)
        out[n] = z_self[n] > z_palm + radius[n]
    return out


@numba.njit('float64(float64[::1], int64, int64)', **_JIT)   # typed: it calls itself
def _pairwise_sum(a: np.ndarray, start: int, n: int) -> float:
    """numpy's pairwise sum of ``a[start:start + n]`` (float64; what ``ndarray.sum`` along a
    contiguous axis adds): in order below 8 values, 8 running sums up to 128, halves
    beyond."""
    if n < 8:
        res = 0.0
        for i in range(n):
            res += a[start + i]
        return res
    if n <= 128:
        r = np.empty(8)
        for j in range(8):
            r[j] = a[start + j]
        i = 8
        while i < n - (n % 8):
            for j in range(8):
                r[j] += a[start + i + j]
            i += 8
        res = ((r[0] + r[1]) + (r[2] + r[3])) + ((r[4] + r[5]) + (r[6] + r[7]))
        while i < n:
            res += a[start + i]
            i += 1
        return res
    n2 = n // 2
    n2 -= n2 % 8
    return _pairwise_sum(a, start, n2) + _pairwise_sum(a, start + n2, n - n2)


@numba.njit(error_model='numpy', **_JIT)      # 0 / 0 is NaN, as numpy's
def fit_lines(base: np.ndarray, end: np.ndarray, centres: np.ndarray, n: np.ndarray,
              frac: np.ndarray, off: np.ndarray, valid: np.ndarray, outlier_px: float
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """``edge_features._fit_lines``, numpy's operations in numpy's order (sums over a
    segment's slices as ``_pairwise_sum``): per segment ``base -> end`` (L, 2) the offset
    ``off`` (L, S) of its valid points along ``n`` (L, 2) from the slice ``centres`` (L, S, 2)
    at fractions ``frac`` (S,) fitted as a linear function of the place along the segment,
    then again without the points farther than ``outlier_px``. Returns the lines' unit
    normals (L, 2), offsets (L,), the kept points' weights (L, S) and the points (L, S, 2;
    NaN where not kept)."""
    L, S = off.shape
    normal = np.empty((L, 2))
    offset = np.empty(L)
    w = np.empty((L, S))
    points = np.empty((L, S, 2))
    s_along = np.empty(S)
    tmp = np.empty(S)
    for li in range(L):
        ax, ay = end[li, 0] - base[li, 0], end[li, 1] - base[li, 1]
        length = np.sqrt(ax * ax + ay * ay)
        safe_len = _at_least(length, 1e-9)
        ux, uy = ax / safe_len, ay / safe_len
        for k in range(S):
            s_along[k] = (frac[k] - 0.5) * length
            w[li, k] = 1.0 if valid[li, k] else 0.0
        a = b = 0.0
        for _ in range(2):
            sw = _pairwise_sum(w[li], 0, S)
            safe = _at_least(sw, 1e-9)
            for k in range(S):
                tmp[k] = w[li, k] * s_along[k]
            ms = _pairwise_sum(tmp, 0, S) / safe
            for k in range(S):
                tmp[k] = w[li, k] * off[li, k]
            mo = _pairwise_sum(tmp, 0, S) / safe
            for k in range(S):
                ds = s_along[k] - ms
                tmp[k] = w[li, k] * (ds * ds)
            var = _pairwise_sum(tmp, 0, S)
            for k in range(S):
                tmp[k] = (w[li, k] * (s_along[k] - ms)) * (off[li, k] - mo)
            cov = _pairwise_sum(tmp, 0, S)
            b = cov / _at_least(var, 1e-9) if var > 1e-9 else 0.0
            a = mo - b * ms
            for k in range(S):
                resid = abs(off[li, k] - (a + b * s_along[k]))
                w[li, k] = 1.0 if valid[li, k] and resid <= outlier_px else 0.0
        nx, ny = n[li, 0], n[li, 1]
        dx, dy = ux + b * nx, uy + b * ny
        norm = np.sqrt(dx * dx + dy * dy)
        dx, dy = dx / norm, dy / norm
        normal[li, 0], normal[li, 1] = -dy, dx
        mx = 0.5 * (base[li, 0] + end[li, 0]) + a * nx
        my = 0.5 * (base[li, 1] + end[li, 1]) + a * ny
        offset[li] = (0.0 + -dy * mx) + dx * my
        for k in range(S):
            if w[li, k] > 0:
                points[li, k, 0] = centres[li, k, 0] + off[li, k] * nx
                points[li, k, 1] = centres[li, k, 1] + off[li, k] * ny
            else:
                points[li, k, 0] = points[li, k, 1] = np.nan
    return normal, offset, w, points


@numba.njit(inline='always', **_JIT)
def _robust_weight(r: float, k: float, cauchy: bool) -> float:
    """``edge_fit._robust`` of one residual: 1 for ``k`` <= 0, else Cauchy's
    ``1 / (1 + (|r| / k)^2)`` or Huber's ``1`` within ``k``, ``k / max(|r|, 1e-12)`` beyond."""
    if k <= 0.0:
        return 1.0
    a = abs(r)
    if cauchy:
        s = a / k
        return 1.0 / (1.0 + s * s)
    if a <= k:
        return 1.0
    return k / _at_least(a, 1e-12)


@numba.njit(**_JIT)
def line_rows(pix: np.ndarray, jpix: np.ndarray, rows_b: np.ndarray, rows_e: np.ndarray,
              alpha: np.ndarray, normal: np.ndarray, offset: np.ndarray, num_links: int,
              tip_rows: np.ndarray, tip_centre: np.ndarray, k: float, cauchy: bool,
              tip_weight: float, palm_weight: float, camera_weight: float, scaled: bool,
              jacobian: bool) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """One camera's link, tip and palm-side rows of ``edge_fit.stack_residuals`` from the
    projected feature points ``pix`` (N, 2) and their Jacobians ``jpix`` (N, 2, D; read only
    with ``jacobian``): the lines' end points blended between a row and the one two rows on
    by ``alpha`` (``edge_fit._blend``), their signed distances ``n . x - rho`` (two rows a
    line, ``edge_fit.link_axis_residuals``), the tips' predicted minus measured centres (two
    rows a tip), the robust weights (the tips' times ``tip_weight``, the palm sides' times
    ``palm_weight``, all times ``camera_weight`` when ``scaled``), numpy's operations in
    numpy's order. Rows: links (the first ``num_links`` lines), tips, palm sides; returns
    the residuals, their Jacobian ((rows, D), (rows, 0) without ``jacobian``) and weights."""
    lines, tips = len(rows_b), len(tip_rows)
    dofs = jpix.shape[2] if jacobian else 0
    rows = 2 * lines + 2 * tips
    r = np.empty(rows)
    J = np.empty((rows, dofs))
    w = np.empty(rows)
    for i in range(lines):
        out = 2 * i if i < num_links else 2 * i + 2 * tips
        a = alpha[i]
        n0, n1 = normal[i, 0], normal[i, 1]
        for side in range(2):
            row = rows_b[i] if side == 0 else rows_e[i]
            x = (1.0 - a) * pix[row, 0] + a * pix[row + 2, 0]
            y = (1.0 - a) * pix[row, 1] + a * pix[row + 2, 1]
            v = ((0.0 + n0 * x) + n1 * y) - offset[i]       # einsum's sum starts at 0
            r[out + side] = v
            weight = _robust_weight(v, k, cauchy)
            if i >= num_links:
                weight = palm_weight * weight
            w[out + side] = camera_weight * weight if scaled else weight
            for d in range(dofs):
                jx = (1.0 - a) * jpix[row, 0, d] + a * jpix[row + 2, 0, d]
                jy = (1.0 - a) * jpix[row, 1, d] + a * jpix[row + 2, 1, d]
                J[out + side, d] = (0.0 + n0 * jx) + n1 * jy
    for t in range(tips):
        out = 2 * num_links + 2 * t
        for c in range(2):
            v = pix[tip_rows[t], c] - tip_centre[t, c]
            r[out + c] = v
            weight = tip_weight * _robust_weight(v, k, cauchy)
            w[out + c] = camera_weight * weight if scaled else weight
            for d in range(dofs):
                J[out + c, d] = jpix[tip_rows[t], c, d]
    return r, J, w


@numba.njit(**_JIT)
def axis_points(pix: np.ndarray, links: int, tip_start: int, tips: int, width: int,
                height: int) -> tuple[np.ndarray, np.ndarray]:
    """``edge_fit._axis_points``' pixels: of the hand's axis points (each link's base, middle
    and end, the links' bases at even rows of ``pix`` from 0 and their ends after them, then
    the tip centres every second row from ``tip_start``), in that order (bases, middles,
    ends, tips), those inside the ``width`` x ``height`` image (M, 2) and their places in
    that order (M,)."""
    total = 3 * links + tips
    px = np.empty((total, 2))
    place = np.empty(total, np.int64)
    m = 0
    for k in range(total):
        if k < links:
            x, y = pix[2 * k, 0], pix[2 * k, 1]
        elif k < 2 * links:
            i = k - links
            x = 0.5 * (pix[2 * i, 0] + pix[2 * i + 1, 0])
            y = 0.5 * (pix[2 * i, 1] + pix[2 * i + 1, 1])
        elif k < 3 * links:
            x, y = pix[2 * (k - 2 * links) + 1, 0], pix[2 * (k - 2 * links) + 1, 1]
        else:
            x, y = pix[tip_start + 2 * (k - 3 * links), 0], pix[tip_start + 2 * (k - 3 * links), 1]
        if x >= 0 and x < width and y >= 0 and y < height:
            px[m, 0], px[m, 1] = x, y
            place[m] = k
            m += 1
    return px[:m].copy(), place[:m].copy()


@numba.njit(**_JIT)
def silhouette_rows(pix: np.ndarray, jpix: np.ndarray, depth: np.ndarray, links: int,
                    tip_start: int, place: np.ndarray, distance: np.ndarray,
                    gradient: np.ndarray, tolerance: float, target_px: np.ndarray,
                    target_link: np.ndarray, target_along: np.ndarray,
                    target_direction: np.ndarray, radius: np.ndarray, focal: float
                    ) -> tuple[np.ndarray, np.ndarray]:
    """``edge_fit._silhouette_residuals``' axis and link rows, numpy's operations in numpy's
    dtypes and order: each axis point (``place`` as :func:`axis_points` gives it) whose
    outside distance (float32, with its float32 ``gradient``) exceeds the tolerance gives
    that excess (in float32) and the gradient times the point's pixel Jacobian; each
    unexplained pixel ``target_px`` gives its distance along ``target_direction`` from the
    point ``target_along`` of the way along its link ``target_link`` less the link's
    projected radius (``radius`` times ``focal`` over the depth) and the tolerance, and minus
    that distance's Jacobian, where the distance is positive."""
    dofs = jpix.shape[2]
    n_axis, n_target = len(place), len(target_px)
    r = np.empty(n_axis + n_target)
    J = np.empty((n_axis + n_target, dofs))
    tol32 = np.float32(tolerance)
    row = 0
    for m in range(n_axis):
        if not distance[m] > tol32:
            continue
        r[row] = np.float64(np.float32(distance[m] - tol32))
        g0, g1 = np.float64(gradient[m, 0]), np.float64(gradient[m, 1])
        k = place[m]
        for d in range(dofs):
            if k < links:
                jx, jy = jpix[2 * k, 0, d], jpix[2 * k, 1, d]
            elif k < 2 * links:
                i = k - links
                jx = 0.5 * (jpix[2 * i, 0, d] + jpix[2 * i + 1, 0, d])
                jy = 0.5 * (jpix[2 * i, 1, d] + jpix[2 * i + 1, 1, d])
            elif k < 3 * links:
                i = 2 * (k - 2 * links) + 1
                jx, jy = jpix[i, 0, d], jpix[i, 1, d]
            else:
                i = tip_start + 2 * (k - 3 * links)
                jx, jy = jpix[i, 0, d], jpix[i, 1, d]
            J[row, d] = (0.0 + g0 * jx) + g1 * jy
        row += 1
    for j in range(n_target):
        li, s = target_link[j], target_along[j]
        b, e = 2 * li, 2 * li + 1
        cx = (1.0 - s) * pix[b, 0] + s * pix[e, 0]
        cy = (1.0 - s) * pix[b, 1] + s * pix[e, 1]
        z = 0.5 * (depth[b] + depth[e])
        hw = radius[li] * focal / _at_least(z, 1e-6)
        dx, dy = target_direction[j, 0], target_direction[j, 1]
        v = (((0.0 + dx * (target_px[j, 0] - cx)) + dy * (target_px[j, 1] - cy)) - hw) \
            - tolerance
        if not v > 0:
            continue
        r[row] = v
        for d in range(dofs):
            jx = (1.0 - s) * jpix[b, 0, d] + s * jpix[e, 0, d]
            jy = (1.0 - s) * jpix[b, 1, d] + s * jpix[e, 1, d]
            J[row, d] = -((0.0 + dx * jx) + dy * jy)
        row += 1
    return r[:row].copy(), J[:row].copy()


@numba.njit(**_JIT)
def link_prediction(pix: np.ndarray, depth: np.ndarray, links: int, radius: np.ndarray,
                    focal: float, frac: np.ndarray, min_depth: float, min_length: float,
                    search_px: float, width: int, height: int
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray,
                               np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """``edge_fit.predict_features``' links, numpy's operations in numpy's order: from the
    projected feature points (``pix`` (N, 2), ``depth`` (N,); link l's base at row 2l, its end
    at 2l + 1) each link's base and end (L, 2), their depths (L,), projected radius
    (``radius`` times ``focal`` over the mean depth), whether it is usable (both ends
    farther than ``min_depth``, at least ``min_length`` pixels long), its slice centres at
    ``frac`` (L * S, 2), which lie inside the image by the radius plus ``search_px`` (L, S)
    and their depths (L * S,)."""
    L, S = links, len(frac)
    base = np.empty((L, 2))
    end = np.empty((L, 2))
    zb = np.empty(L)
    ze = np.empty(L)
    hw = np.empty(L)
    usable = np.empty(L, np.bool_)
    centres = np.empty((L * S, 2))
    inside = np.empty((L, S), np.bool_)
    z_self = np.empty(L * S)
    for li in range(L):
        for c in range(2):
            base[li, c], end[li, c] = pix[2 * li, c], pix[2 * li + 1, c]
        zb[li], ze[li] = depth[2 * li], depth[2 * li + 1]
        z = 0.5 * (zb[li] + ze[li])
        hw[li] = radius[li] * focal / _at_least(z, 1e-6)
        dx, dy = end[li, 0] - base[li, 0], end[li, 1] - base[li, 1]
        usable[li] = zb[li] > min_depth and ze[li] > min_depth \
            and np.sqrt(dx * dx + dy * dy) >= min_length
        margin = hw[li] + search_px
        for k in range(S):
            cx = base[li, 0] + frac[k] * dx
            cy = base[li, 1] + frac[k] * dy
            centres[li * S + k, 0], centres[li * S + k, 1] = cx, cy
            inside[li, k] = cx >= margin and cx < width - margin and cy >= margin \
                and cy < height - margin
            z_self[li * S + k] = zb[li] + frac[k] * (ze[li] - zb[li])
    return base, end, zb, ze, hw, usable, centres, inside, z_self


@numba.njit(**_JIT)
def tip_prediction(pix: np.ndarray, depth: np.ndarray, tip_start: int, tips: int,
                   tip_radius: np.ndarray, focal: float, tip_row: np.ndarray,
                   link_usable: np.ndarray, min_depth: float, search_px: float, width: int,
                   height: int, base: np.ndarray, end: np.ndarray, zb: np.ndarray,
                   ze: np.ndarray, hw: np.ndarray, usable: np.ndarray
                   ) -> tuple[np.ndarray, np.ndarray]:
    """``edge_fit.predict_features``' tips, numpy's operations in numpy's order: each tip's
    projected radius (T,) and whether it may be measured: its distal link (row ``tip_row``,
    -1: none) usable, its centre (row ``tip_start + 2t``) farther than ``min_depth``, its
    extremity (the next row) inside the image by ``search_px`` plus its radius, and not on
    another usable link's capsule (``base -> end``, half-widths ``hw``) nearer the camera."""
    radius = np.empty(tips)
    ok = np.empty(tips, np.bool_)
    for t in range(tips):
        zt = depth[tip_start + 2 * t]
        radius[t] = tip_radius[t] * focal / _at_least(zt, 1e-6)
        row = tip_row[t]
        x, y = pix[tip_start + 2 * t + 1, 0], pix[tip_start + 2 * t + 1, 1]
        margin = search_px + radius[t]
        good = row >= 0 and zt > min_depth and link_usable[max(row, 0)] \
            and x >= margin and x < width - margin and y >= margin and y < height - margin
        for m in range(len(base)):
            if not good:
                break
            if m == row or not usable[m]:
                continue
            ax, ay = base[m, 0], base[m, 1]
            bx, by = end[m, 0] - ax, end[m, 1] - ay
            dist, s = _closest(x, y, ax, ay, bx, by, _squared_length(bx, by))
            if dist < hw[m] + radius[t] and zb[m] + s * (ze[m] - zb[m]) < zt:
                good = False
        ok[t] = good
    return radius, ok


@numba.njit(**_JIT)
def palm_prediction(pix: np.ndarray, depth: np.ndarray, rows_b: np.ndarray,
                    rows_e: np.ndarray, alpha: np.ndarray, centre_rows: np.ndarray,
                    frac: np.ndarray, min_depth: float, min_length: float, search_px: float,
                    width: int, height: int, base: np.ndarray, end: np.ndarray,
                    zb: np.ndarray, ze: np.ndarray, hw: np.ndarray, link_usable: np.ndarray,
                    min_slices: int
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """``edge_fit._predict_palm`` after the generators' choice, numpy's operations in numpy's
    order: per palm side its generator's base and end (P, 2; rows ``rows_b``, ``rows_e``
    blended with the rows two on by ``alpha``), the unit normal pointing away from the palm's
    centre (row ``centre_rows``), which slices at ``frac`` lie inside the image by
    ``search_px`` and not behind a nearer usable link's capsule (``base -> end``, half-widths
    ``hw`` plus ``search_px``) on a side in front of the camera and long enough (P, S), and
    which sides have at least ``min_slices`` of them."""
    P, S, L = len(rows_b), len(frac), len(base)
    pb = np.empty((P, 2))
    pe = np.empty((P, 2))
    n = np.empty((P, 2))
    valid = np.empty((P, S), np.bool_)
    usable = np.empty(P, np.bool_)
    for i in range(P):
        a = alpha[i]
        for c in range(2):
            pb[i, c] = (1.0 - a) * pix[rows_b[i], c] + a * pix[rows_b[i] + 2, c]
            pe[i, c] = (1.0 - a) * pix[rows_e[i], c] + a * pix[rows_e[i] + 2, c]
        zpb = (1.0 - a) * depth[rows_b[i]] + a * depth[rows_b[i] + 2]
        zpe = (1.0 - a) * depth[rows_e[i]] + a * depth[rows_e[i] + 2]
        dx, dy = pe[i, 0] - pb[i, 0], pe[i, 1] - pb[i, 1]
        length = np.sqrt(dx * dx + dy * dy)
        safe = _at_least(length, 1e-9)
        nx, ny = -(dy / safe), dx / safe
        cx, cy = pix[centre_rows[i], 0], pix[centre_rows[i], 1]
        flip = -1.0 if (0.0 + nx * (pb[i, 0] - cx)) + ny * (pb[i, 1] - cy) < 0 else 1.0
        n[i, 0], n[i, 1] = nx * flip, ny * flip
        side_ok = zpb > min_depth and zpe > min_depth and length >= min_length
        count = 0
        for k in range(S):
            sx = pb[i, 0] + frac[k] * dx
            sy = pb[i, 1] + frac[k] * dy
            ok = side_ok and sx >= search_px and sx < width - search_px \
                and sy >= search_px and sy < height - search_px
            z_self = zpb + frac[k] * (zpe - zpb)
            for m in range(L):
                if not ok:
                    break
                if not link_usable[m]:
                    continue
                ax, ay = base[m, 0], base[m, 1]
                bx, by = end[m, 0] - ax, end[m, 1] - ay
                dist, s = _closest(sx, sy, ax, ay, bx, by, _squared_length(bx, by))
                if dist < hw[m] + search_px and zb[m] + s * (ze[m] - zb[m]) < z_self:
                    ok = False
            valid[i, k] = ok
            count += ok
        usable[i] = count >= min_slices
    return pb, pe, n, valid, usable


@numba.njit(**_JIT)
def link_slice_maps(base: np.ndarray, end: np.ndarray, half_width: np.ndarray,
                    frac: np.ndarray, t: np.ndarray, search_px: float, valid: np.ndarray
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray,
                               np.ndarray, np.ndarray, np.ndarray]:
    """``edge_features.measure_link_axes``' slices, numpy's operations in numpy's order: per
    link ``base -> end`` (L, 2) of projected radius ``half_width`` (L,) the unit normal
    (L, 2), the slice centres at ``frac`` (L, S, 2), the reach past the radius and the
    sample spacing (L,); the slices to search (``valid`` (L * S,)) as rows (R,) and their
    links (R,); their samples at ``t`` (W,) times the reach along the normal as float32 x and
    y maps (R * W, 1) each."""
    L, S, W = len(base), len(frac), len(t)
    n = np.empty((L, 2))
    centres = np.empty((L, S, 2))
    reach = np.empty(L)
    step = np.empty(L)
    for li in range(L):
        ax, ay = end[li, 0] - base[li, 0], end[li, 1] - base[li, 1]
        length = np.sqrt(ax * ax + ay * ay)
        safe = _at_least(length, 1e-9)
        n[li, 0], n[li, 1] = -(ay / safe), ax / safe
        for k in range(S):
            centres[li, k, 0] = base[li, 0] + frac[k] * ax
            centres[li, k, 1] = base[li, 1] + frac[k] * ay
        reach[li] = half_width[li] + search_px
        step[li] = 2.0 * reach[li] / (W - 1)
    rows = np.flatnonzero(valid)
    links = rows // S
    mx = np.empty((len(rows) * W, 1), np.float32)
    my = np.empty((len(rows) * W, 1), np.float32)
    for r in range(len(rows)):
        li, k = links[r], rows[r] % S
        for j in range(W):
            off = reach[li] * t[j]
            mx[r * W + j, 0] = np.float32(centres[li, k, 0] + off * n[li, 0])
            my[r * W + j, 0] = np.float32(centres[li, k, 1] + off * n[li, 1])
    return n, centres, reach, step, rows, links, mx, my


@numba.njit(**_JIT)
def pair_midpoints(found: np.ndarray, sign_i: np.ndarray, sign_j: np.ndarray,
                   ei: np.ndarray, ej: np.ndarray, rows: np.ndarray, links: int,
                   slices: int, samples: int, reach: np.ndarray
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`pair_search`'s pairs of the searched ``rows`` back on the (L, S) slices: where
    a pair was found, the sign of its entering edge where the two edges' signs are opposite
    (else 0), and the pair's midpoint offset along the normal (the mean of the two sample
    positions in [-1, 1] times the reach; 0 where nothing was searched)."""
    valid = np.zeros((links, slices), np.bool_)
    best_sign = np.zeros((links, slices), np.int64)
    mid_t = np.zeros((links, slices))
    for r in range(len(rows)):
        li, k = rows[r] // slices, rows[r] % slices
        valid[li, k] = found[r]
        best_sign[li, k] = sign_i[r] if sign_i[r] == -sign_j[r] else 0
        mid_t[li, k] = (ei[r] + ej[r]) / (samples - 1) - 1.0
    mid_off = np.empty((links, slices))
    for li in range(links):
        for k in range(slices):
            mid_off[li, k] = mid_t[li, k] * reach[li]
    return valid, best_sign, mid_off


@numba.njit(**_JIT)
def axis_counts(w: np.ndarray, sign: np.ndarray, min_slices: int
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per line of (L, S) kept-point weights (0 or 1): whether at least ``min_slices`` were
    kept, how many, and the sign of the kept slices' summed ``sign`` (L,) each."""
    L, S = w.shape
    found = np.empty(L, np.bool_)
    count = np.empty(L, np.int64)
    polarity = np.empty(L, np.int64)
    for li in range(L):
        total, signs = 0.0, 0
        for k in range(S):
            total += w[li, k]
            if w[li, k] > 0:
                signs += sign[li, k]
        found[li] = total >= min_slices
        count[li] = np.int64(total)
        polarity[li] = 1 if signs > 0 else (-1 if signs < 0 else 0)
    return found, count, polarity


@numba.njit(**_JIT)
def outline_drawing(base: np.ndarray, end: np.ndarray, half_width: np.ndarray,
                    tip: np.ndarray, tip_radius: np.ndarray, shift: np.ndarray, scale: int,
                    tolerance: float
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """``silhouette.Silhouette.unexplained``'s drawing of a hand outline, numpy's operations
    in numpy's order: the capsules with finite ends (``base -> end`` less ``shift``, as cv2
    drawing coordinates with 4 fractional bits at 1 / ``scale``; (K, 2, 2) int32) sorted by
    their line thickness (the half-width plus ``tolerance``, at least 1; (K,), stable), and
    the finite tips' centres (T, 2) int32 and radii (T,) in drawing units."""
    L = len(base)
    keep = np.empty(L, np.int64)
    thick_all = np.empty(L, np.int64)
    K = 0
    s = np.float64(scale)
    for i in range(L):
        if np.isfinite(base[i, 0]) and np.isfinite(base[i, 1]) and np.isfinite(end[i, 0]) \
                and np.isfinite(end[i, 1]):
            keep[K] = i
            v = np.rint(2.0 * (half_width[i] + tolerance) / s)
            thick_all[K] = np.int64(_at_least(v, 1.0))
            K += 1
    order = np.argsort(thick_all[:K], kind='mergesort')
    ends = np.empty((K, 2, 2), np.int32)
    thick = np.empty(K, np.int64)
    for j in range(K):
        i = keep[order[j]]
        thick[j] = thick_all[order[j]]
        for c in range(2):
            ends[j, 0, c] = np.int32(np.rint((base[i, c] - shift[c] + 0.5) / s * 16 - 8))
            ends[j, 1, c] = np.int32(np.rint((end[i, c] - shift[c] + 0.5) / s * 16 - 8))
    T = 0
    centres = np.empty((len(tip), 2), np.int32)
    radii = np.empty(len(tip), np.int64)
    for t in range(len(tip)):
        if np.isfinite(tip[t, 0]) and np.isfinite(tip[t, 1]):
            for c in range(2):
                centres[T, c] = np.int32(np.rint((tip[t, c] - shift[c] + 0.5) / s * 16 - 8))
            v = np.rint(16 * (tip_radius[t] + tolerance) / s)
            radii[T] = np.int64(_at_least(v, 1.0))
            T += 1
    return ends, thick, centres[:T].copy(), radii[:T].copy()


_PROBES = ((0.0, 0.0), (1.0, 0.0), (-1.0, 0.0), (0.0, 1.0), (0.0, -1.0))


@numba.njit(**_JIT)
def probe_maps(px: np.ndarray, scale: int, offset: np.ndarray
               ) -> tuple[np.ndarray, np.ndarray]:
    """``silhouette.Silhouette.outside_distance``'s sample maps: each of (N, 2) pixels and its
    four neighbours ``scale`` pixels away (right, left, down, up) as float32 mask coordinates
    (the mask ``scale`` times smaller, its first pixel at ``offset``), x and y (5N, 1) each,
    in numpy's dtypes and order."""
    n = len(px)
    mx = np.empty((5 * n, 1), np.float32)
    my = np.empty((5 * n, 1), np.float32)
    h = np.float64(scale)
    half, s32 = np.float32(0.5), np.float32(scale)
    for i in range(n):
        for k in range(5):
            x = np.float32(px[i, 0] + h * _PROBES[k][0])
            y = np.float32(px[i, 1] + h * _PROBES[k][1])
            mx[5 * i + k, 0] = np.float32(np.float64((x + half) / s32 - half) - offset[0])
            my[5 * i + k, 0] = np.float32(np.float64((y + half) / s32 - half) - offset[1])
    return mx, my


@numba.njit(**_JIT)
def probe_gradients(values: np.ndarray, scale: int) -> tuple[np.ndarray, np.ndarray]:
    """The outside distances at N pixels and their central-difference gradients (N, 2) from
    the samples of :func:`probe_maps` (5N, 1) float32, in float32."""
    n = len(values) // 5
    dist = np.empty(n, np.float32)
    grad = np.empty((n, 2), np.float32)
    twice = np.float32(2.0 * np.float64(scale))
    for i in range(n):
        dist[i] = values[5 * i, 0]
        grad[i, 0] = (values[5 * i + 1, 0] - values[5 * i + 2, 0]) / twice
        grad[i, 1] = (values[5 * i + 3, 0] - values[5 * i + 4, 0]) / twice
    return dist, grad


def _array(dtype: object, ndim: int) -> object:
    """A read-only C-contiguous array type (writable arrays convert to it)."""
    return numba.types.Array(dtype, ndim, 'C', readonly=True)


_F1, _F2 = _array(numba.float64, 1), _array(numba.float64, 2)
_I1 = _array(numba.int64, 1)
_SIGNATURES = {
    derivative: (_array(numba.float32, 2), _F1),
    pair_search: (_array(numba.float32, 2), _array(numba.int64, 1), numba.boolean,
                  numba.float64, _F2, _array(numba.int64, 1), numba.int64),
    edge_peaks: (_array(numba.float32, 2), _F1, numba.float64),
    tip_peaks: (_array(numba.float32, 2), _array(numba.int64, 1), numba.float64),
    segment_distances: (_F2, _F2, _F2),
    occluded_slices: (_F2, numba.int64, _F2, _F2, _F1, _F1, _F1, _F1, numba.float64,
                      _array(numba.boolean, 1), _array(numba.boolean, 2)),
    behind_palm: (_F2, _F2, _F2, _F1, numba.float64, _F1, _F1),
    line_rows: (_F2, _array(numba.float64, 3), _I1, _I1, _F1, _F2, _F1, numba.int64, _I1, _F2,
                numba.float64, numba.boolean, numba.float64, numba.float64, numba.float64,
                numba.boolean, numba.boolean),
    fit_lines: (_F2, _F2, _array(numba.float64, 3), _F2, _F1, _F2, _array(numba.boolean, 2),
                numba.float64),
    link_prediction: (_F2, _F1, numba.int64, _F1, numba.float64, _F1, numba.float64,
                      numba.float64, numba.float64, numba.int64, numba.int64),
    tip_prediction: (_F2, _F1, numba.int64, numba.int64, _F1, numba.float64, _I1,
                     _array(numba.boolean, 1), numba.float64, numba.float64, numba.int64,
                     numba.int64, _F2, _F2, _F1, _F1, _F1, _array(numba.boolean, 1)),
    palm_prediction: (_F2, _F1, _I1, _I1, _F1, _I1, _F1, numba.float64, numba.float64,
                      numba.float64, numba.int64, numba.int64, _F2, _F2, _F1, _F1, _F1,
                      _array(numba.boolean, 1), numba.int64),
    link_slice_maps: (_F2, _F2, _F1, _F1, _F1, numba.float64, _array(numba.boolean, 1)),
    pair_midpoints: (_array(numba.boolean, 1), _I1, _I1, _F1, _F1, _I1, numba.int64,
                     numba.int64, numba.int64, _F1),
    axis_counts: (_F2, _array(numba.int64, 2), numba.int64),
    outline_drawing: (_F2, _F2, _F1, _F2, _F1, _F1, numba.int64, numba.float64),
    probe_maps: (_F2, numba.int64, _F1),
    probe_gradients: (_array(numba.float32, 2), numba.int64),
    axis_points: (_F2, numba.int64, numba.int64, numba.int64, numba.int64, numba.int64),
    silhouette_rows: (_F2, _array(numba.float64, 3), _F1, numba.int64, numba.int64, _I1,
                      _array(numba.float32, 1), _array(numba.float32, 2), numba.float64, _F2,
                      _I1, _F1, _F2, _F1, numba.float64),
}


def compile_kernels() -> float:
    """Compile every kernel for its one signature (or load it from numba's on-disk cache)
    and allow no other; returns the seconds it took (none once done in this process)."""
    return compile_signatures(_SIGNATURES)
