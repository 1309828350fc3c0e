"""The edge tracker's compiled kernels (issue 17, thirteenth pass) against the numpy code they
replaced, kept here as the reference: the same bits (dtype, shape, values) on random slices,
images and predictions."""
from __future__ import annotations

import subprocess
import sys

import cv2
import numpy as np
import pytest
from numpy.lib.stride_tricks import sliding_window_view

from colorglove_ros.core.tracking import edge_features as ef
from colorglove_ros.core.tracking import edge_kernel

_NO_EDGE = -1.0e9


# ------------------------------------------------------------- the numpy code, as it was
def _derivative_ref(profile: np.ndarray, step: np.ndarray) -> np.ndarray:
    p = profile.copy()
    p[..., 1:-1] = 0.25 * profile[..., :-2] + 0.5 * profile[..., 1:-1] + 0.25 * profile[..., 2:]
    d = np.zeros_like(p)
    d[..., 1:-1] = (p[..., 2:] - p[..., :-2]) / (2.0 * step[..., None])
    d[np.isnan(d)] = 0.0
    return d


def _subpixel_ref(score, index, sign=None):
    n = score.shape[-1]
    i = np.clip(index, 1, n - 2)
    abc = np.take_along_axis(score, i[..., None] + np.arange(-1, 2), -1)
    if sign is not None:
        abc = np.where(sign[..., None] >= 0, abc, -abc)
    a, b, c = abc[..., 0], abc[..., 1], abc[..., 2]
    den = a - 2.0 * b + c
    shift = np.where(np.abs(den) > 1e-9, 0.5 * (a - c) / np.where(den == 0, 1.0, den), 0.0)
    return i + np.clip(shift, -0.5, 0.5)


def _pairs_ref(d, pol, min_gradient, agree, li, gaps):
    """measure_link_axes' pair search: found, sign_i, sign_j, ei, ej (where the best pair
    ran past the slice's end, which is never found, the numpy code raised an IndexError:
    here its leaving edge is read at the last sample, as the kernel does)."""
    W = d.shape[1]
    if np.all(pol == 0):
        enter = leave = np.abs(d)
    else:
        enter = np.where(pol == 0, np.abs(d), pol * d)
        leave = np.where(pol == 0, np.abs(d), -pol * d)
    enter = np.where(enter > min_gradient, enter, _NO_EDGE)
    leave = np.where(leave > min_gradient, leave, _NO_EDGE)
    g_lo, g_hi = gaps[0], gaps[-1]
    padded = np.concatenate([leave[:, g_lo:], np.full((len(d), g_hi), _NO_EDGE)], axis=1)
    later = sliding_window_view(padded, len(gaps), axis=1)[:, :W]
    pair = np.add(enter[..., None], later)
    pair *= agree[li][:, None, :]
    flat = pair.reshape(len(d), W * len(gaps))
    k = np.argmax(flat, axis=1)
    best_score = np.take_along_axis(flat, k[:, None], 1)[:, 0]
    best_i = k // len(gaps)
    best_j = best_i + gaps[k % len(gaps)]
    found = (best_score > 0) & (best_j < W)
    best_j = np.minimum(best_j, W - 1)
    sign_i = np.sign(np.take_along_axis(d, best_i[:, None], 1)[:, 0]).astype(np.int64)
    sign_j = np.sign(np.take_along_axis(d, best_j[:, None], 1)[:, 0]).astype(np.int64)
    return found, sign_i, sign_j, _subpixel_ref(d, best_i, sign_i), _subpixel_ref(d, best_j,
                                                                                    sign_j)


def _edge_peaks_ref(d, weight, min_gradient):
    score = np.abs(d) * weight[None, :]
    score[..., 0] = score[..., -1] = 0.0
    k = np.argmax(score, axis=1)
    valid = np.take_along_axis(np.abs(d), k[:, None], 1)[:, 0] > min_gradient
    sign = np.sign(np.take_along_axis(d, k[:, None], 1)[:, 0])
    return valid, sign, _subpixel_ref(d, k, sign)


def _tip_peaks_ref(d, pol, min_gradient):
    leave_bright = np.where((pol >= 0)[:, None], -d, -np.inf)
    leave_dark = np.where((pol <= 0)[:, None], d, -np.inf)
    score = np.maximum(leave_bright, leave_dark)
    sign = np.where(leave_bright >= leave_dark, -1.0, 1.0)
    k = np.argmax(score, axis=1)
    best = np.take_along_axis(score, k[:, None], 1)[:, 0]
    row_sign = np.take_along_axis(sign, k[:, None], 1)
    return best > min_gradient, _subpixel_ref(row_sign * d, k)


def _segment_distances_ref(points, seg_a, seg_b):
    p = np.asarray(points, dtype=float)[:, None, :]
    a = np.asarray(seg_a, dtype=float)[None]
    ab = np.asarray(seg_b, dtype=float)[None] - a
    den = np.maximum((ab * ab).sum(-1), 1e-12)
    s = np.clip(((p - a) * ab).sum(-1) / den, 0.0, 1.0)
    closest = a + s[..., None] * ab
    return np.linalg.norm(p - closest, axis=-1), s


def _occluded_ref(centres, S, base, end, zb, ze, hw, z_self, margin, usable, exempt):
    L = len(base)
    dist, along = _segment_distances_ref(centres, base, end)
    dist = dist.reshape(L, S, L)
    z_other = zb[None, None, :] + along.reshape(L, S, L) * (ze - zb)[None, None, :]
    covered = dist < hw[None, None, :] + hw[:, None, None] + margin
    nearer = z_other < z_self.reshape(L, S)[:, :, None]
    return np.any(covered & nearer & usable[None, None, :] & ~exempt[:, None, :], 2).reshape(-1)


def _behind_palm_ref(hull, flat, pix, depth, near_px2, z_self, radius):
    if len(hull) < 3:
        inside = np.zeros(len(flat), dtype=bool)
    else:
        edge = np.roll(hull, -1, axis=0) - hull
        rel = flat[:, None, :] - hull[None, :, :]
        cross = edge[None, :, 0] * rel[..., 1] - edge[None, :, 1] * rel[..., 0]
        inside = np.all(cross >= 0, axis=1) | np.all(cross <= 0, axis=1)
    out = np.zeros(len(flat), dtype=bool)
    if inside.any():
        d2 = ((flat[inside, None, :] - pix[None, :, :]) ** 2).sum(-1)
        near = d2 <= near_px2
        near[np.arange(len(d2)), np.argmin(d2, axis=1)] = True
        z_palm = np.where(near, depth[None, :], np.inf).min(axis=1)
        out[inside] = z_self[inside] > z_palm + radius[inside]
    return out


def _same(a: np.ndarray, b: np.ndarray) -> bool:
    a, b = np.asarray(a), np.asarray(b)
    return a.dtype == b.dtype and a.shape == b.shape and a.tobytes() == b.tobytes()


def _slices(rng: np.random.Generator, rows: int, width: int) -> np.ndarray:
    """Grey-level profiles with edges, flat runs (zero derivatives) and NaN ends."""
    x = np.cumsum(rng.normal(0, 4, (rows, width)), axis=1) + 100
    x[rng.random((rows, width)) < 0.2] = 0.0
    x[:, :3] = np.where(rng.random((rows, 1)) < 0.2, np.nan, x[:, :3])
    x = np.round(x * 4) / 4       # ties in the scores
    return x.astype(np.float32)


# ------------------------------------------------------------------------------- tests
def test_the_slice_kernels_give_the_numpy_codes_bits() -> None:
    rng = np.random.default_rng(3)
    for _ in range(60):
        R, W = int(rng.integers(1, 90)), int(rng.integers(5, 40))
        profile = _slices(rng, R, W)
        step = rng.uniform(0.3, 2.0, R)
        d = ef._derivative(profile, step)
        assert _same(d, _derivative_ref(profile, step))
        L = int(rng.integers(1, 15))
        li = np.sort(rng.integers(0, L, R)).astype(np.int64)
        g_lo = int(rng.integers(1, max(2, W // 3)))
        gaps = np.arange(g_lo, int(rng.integers(g_lo, W)) + 1)
        agree = np.where(rng.random((L, len(gaps))) < 0.3, 0.0, rng.random((L, len(gaps))))
        for pol in (np.zeros(R, np.int64), rng.integers(-1, 2, R).astype(np.int64)):
            for low in (3.0, 2.7):
                got = edge_kernel.pair_search(d, pol, bool(np.any(pol != 0)), low, agree, li,
                                              g_lo)
                want = _pairs_ref(d, pol[:, None], low, agree, li, gaps)
                found = want[0]
                assert _same(got[0], found)
                for g, w in zip(got[1:], want[1:], strict=True):   # kept where a pair is
                    assert _same(g[found], w[found])
        weight = np.exp(-0.5 * np.linspace(-2, 2, W) ** 2)
        got = edge_kernel.edge_peaks(d, weight, 3.0)
        want = _edge_peaks_ref(d, weight, 3.0)
        assert _same(got[0], want[0]) and _same(got[2], want[2])
        assert np.array_equal(got[1], want[1])           # int64 here, float32 signs there
        pol = rng.integers(-1, 2, R).astype(np.int64)
        for g, w in zip(edge_kernel.tip_peaks(d, pol, 3.0), _tip_peaks_ref(d, pol, 3.0),
                        strict=True):
            assert _same(g, w)


def _image(rng: np.random.Generator) -> np.ndarray:
    grey = (rng.random((240, 320)) * 255).astype(np.float32)
    grey = cv2.GaussianBlur(grey, (0, 0), 2.5)
    cv2.line(grey, (60, 200), (150, 40), 230.0, 14)
    cv2.line(grey, (200, 220), (260, 60), 20.0, 10)
    return grey


def test_the_edge_measurements_are_the_numpy_codes() -> None:
    """measure_link_axes, measure_outline_edges and measure_tips on an image, with their
    slices' search as it was (``_pairs_ref`` and the peaks) against the kernels."""
    rng = np.random.default_rng(5)
    grey = _image(rng)
    cfg = ef.EdgeSearchConfig()
    for trial in range(40):
        L = int(rng.integers(1, 15))
        base = rng.uniform(20, 300, (L, 2))
        base[:, 1] = np.minimum(base[:, 1], 220)
        end = base + rng.uniform(-60, 60, (L, 2))
        hw = rng.uniform(2, 10, L)
        valid = rng.random((L, cfg.slices_per_link)) > 0.2
        pol = rng.integers(-1, 2, L) if trial % 2 else 0
        got = ef.measure_link_axes(grey, base, end, hw, cfg, pol, valid)
        want = _link_axes_ref(grey, base, end, hw, cfg, pol, valid)
        for name in got.__dataclass_fields__:
            assert _same(getattr(got, name), getattr(want, name)), name
    for _ in range(20):
        T = int(rng.integers(1, 6))
        p0 = rng.uniform(40, 280, (T, 2))
        u = rng.normal(size=(T, 2))
        tip_end = p0 + rng.uniform(-30, 30, (T, 2))
        radius = rng.uniform(2, 8, T)
        pol = rng.integers(-1, 2, T)
        got = ef.measure_tips(grey, p0, u, tip_end, radius, cfg, pol)
        u1 = u / np.maximum(np.linalg.norm(u, axis=1, keepdims=True), 1e-9)
        start = p0 + (np.einsum('ij,ij->i', tip_end - p0, u1) - cfg.tip_search_px
                      - radius)[:, None] * u1
        span = 2.0 * cfg.tip_search_px + radius
        xy = start[:, None, :] + (span[:, None] * np.linspace(0, 1, cfg.tip_samples)
                                  )[..., None] * u1[:, None, :]
        step = span / (cfg.tip_samples - 1)
        found, refined = _tip_peaks_ref(_derivative_ref(ef._sample(grey, xy), step), pol,
                                        cfg.min_gradient)
        edge = start + (refined * step)[:, None] * u1
        assert _same(got.found, found) and _same(got.centre, edge - radius[:, None] * u1)
        out = rng.normal(size=(T, 2))
        valid = rng.random((T, cfg.slices_per_link)) > 0.3
        got = ef.measure_outline_edges(grey, p0, tip_end, out, cfg, valid, (0.15, 0.95))
        want = _outline_ref(grey, p0, tip_end, out, cfg, valid, (0.15, 0.95))
        for name in got.__dataclass_fields__:
            assert _same(getattr(got, name), getattr(want, name)), name


def _outline_ref(grey, base_px, end_px, outward_px, cfg, slice_valid, slice_range):
    """measure_outline_edges as it was."""
    base, end, _ = ef._check_segments(base_px, end_px, np.zeros(len(base_px)))
    out = np.asarray(outward_px, dtype=float).reshape(base.shape)
    L, S, W = len(base), cfg.slices_per_link, cfg.samples_per_slice
    axis = end - base
    u = axis / np.maximum(np.linalg.norm(axis, axis=1), 1e-9)[:, None]
    n = np.stack([-u[:, 1], u[:, 0]], axis=1)
    n *= np.where(np.einsum('ij,ij->i', n, out) < 0, -1.0, 1.0)[:, None]
    frac = np.linspace(*slice_range, S)
    centres = base[:, None, :] + frac[None, :, None] * axis[:, None, :]
    t = np.linspace(-cfg.search_px, cfg.search_px, W)
    step = np.full((L, S), 2.0 * cfg.search_px / (W - 1))
    xy = centres[:, :, None, :] + t[None, None, :, None] * n[:, None, None, :]
    d = _derivative_ref(ef._sample(grey, xy), step)
    score = np.abs(d) * np.exp(-0.5 * (t / (0.5 * cfg.search_px)) ** 2)[None, None, :]
    score[..., 0] = score[..., -1] = 0.0
    k = np.argmax(score, axis=2)
    valid = np.take_along_axis(np.abs(d), k[..., None], 2)[..., 0] > cfg.min_gradient
    valid &= np.asarray(slice_valid, dtype=bool).reshape(L, S)
    sign = np.sign(np.take_along_axis(d, k[..., None], 2)[..., 0])
    off = -cfg.search_px + _subpixel_ref(d, k, sign) * step
    normal, offset, w, points = ef._fit_lines(base, end, centres, n, frac, off, valid, cfg)
    flip = np.einsum('ij,ij->i', normal, n) < 0
    normal = np.where(flip[:, None], -normal, normal)
    offset = np.where(flip, -offset, offset)
    signs = np.where(w > 0, -sign, 0).sum(1)
    return ef.LinkAxes(normal, offset, w.sum(1) >= cfg.min_slices, w.sum(1).astype(np.int64),
                       np.sign(signs).astype(np.int64), points)


def _link_axes_ref(grey, base_px, end_px, half_width_px, cfg, polarity, slice_valid):
    """measure_link_axes as it was, from the slices' samples to the fitted lines."""
    base, end, hw = ef._check_segments(base_px, end_px, half_width_px)
    L, S, W = len(base), cfg.slices_per_link, cfg.samples_per_slice
    axis = end - base
    u = axis / np.maximum(np.linalg.norm(axis, axis=1), 1e-9)[:, None]
    n = np.stack([-u[:, 1], u[:, 0]], axis=1)
    frac = np.linspace(cfg.slice_range[0], cfg.slice_range[1], S)
    centres = base[:, None, :] + frac[None, :, None] * axis[:, None, :]
    reach = hw + cfg.search_px
    offsets = reach[:, None] * np.linspace(-1.0, 1.0, W)[None, :]
    step = 2.0 * reach / (W - 1)
    rows = np.flatnonzero(np.asarray(slice_valid, dtype=bool).reshape(-1))
    li = rows // S
    xy = centres.reshape(-1, 2)[rows][:, None, :] + offsets[li][:, :, None] * n[li][:, None, :]
    d = _derivative_ref(ef._sample(grey, xy), step[li])
    pol = np.broadcast_to(np.asarray(polarity, dtype=np.int64), (L,))[li][:, None]
    lo, hi = cfg.width_ratio
    g_lo = max(1, int(np.floor((2.0 * hw * lo / step).min())))
    g_hi = max(g_lo, min(W - 1, int(np.ceil((2.0 * hw * hi / step).max()))))
    gaps = np.arange(g_lo, g_hi + 1)
    width = gaps[None, :] * step[:, None]
    ok_width = (width >= 2.0 * hw[:, None] * lo) & (width <= 2.0 * hw[:, None] * hi)
    agree = np.where(ok_width, np.exp(-0.5 * ((width - 2.0 * hw[:, None])
                                              / (cfg.width_sigma * 2.0 * hw[:, None])) ** 2),
                     0.0)
    found_pair, sign_i, sign_j, ei, ej = _pairs_ref(d, pol, cfg.min_gradient, agree, li, gaps)
    valid = np.zeros(L * S, dtype=bool)
    valid[rows] = found_pair
    best_sign = np.zeros(L * S, dtype=np.int64)
    best_sign[rows] = np.where(sign_i == -sign_j, sign_i, 0)
    mid_t = np.zeros(L * S)
    mid_t[rows] = (ei + ej) / (W - 1) - 1.0
    mid_off = mid_t.reshape(L, S) * reach[:, None]
    normal, offset, w, midpoints = ef._fit_lines(base, end, centres, n, frac, mid_off,
                                                 valid.reshape(L, S), cfg)
    signs = np.where(w > 0, best_sign.reshape(L, S), 0).sum(1)
    return ef.LinkAxes(normal, offset, w.sum(1) >= cfg.min_slices, w.sum(1).astype(np.int64),
                       np.sign(signs).astype(np.int64), midpoints)


def test_the_geometry_kernels_give_the_numpy_codes_bits() -> None:
    """segment_distances and the prediction's occlusion tests, with degenerate segments,
    points on the hull's edges and ties."""
    rng = np.random.default_rng(8)
    for _ in range(60):
        L, S = int(rng.integers(1, 15)), int(rng.integers(2, 8))
        base = np.round(rng.uniform(0, 100, (L, 2)))
        end = base + np.round(rng.uniform(-30, 30, (L, 2)))
        end[0] = base[0]                                            # a point segment
        centres = np.round(rng.uniform(0, 100, (L * S, 2)) * 2) / 2
        got = ef.segment_distances(centres, base, end)
        for g, w in zip(got, _segment_distances_ref(centres, base, end), strict=True):
            assert _same(g, w)
        zb, ze = rng.uniform(0.3, 0.5, L), rng.uniform(0.3, 0.5, L)
        hw = rng.uniform(2, 12, L)
        z_self = rng.uniform(0.3, 0.5, L * S)
        usable = rng.random(L) > 0.2
        exempt = np.eye(L, dtype=bool) | (rng.random((L, L)) < 0.2)
        assert _same(edge_kernel.occluded_slices(centres, S, base, end, zb, ze, hw, z_self,
                                                 2.0, usable, exempt),
                     _occluded_ref(centres, S, base, end, zb, ze, hw, z_self, 2.0, usable,
                                   exempt))
        pix = np.round(rng.uniform(20, 80, (int(rng.integers(3, 40)), 2)))
        depth = rng.uniform(0.3, 0.5, len(pix))
        hull = cv2.convexHull(pix.astype(np.float32))[:, 0, :].astype(float)
        flat = np.concatenate([centres, hull[:2], pix[:3]])        # on the hull, on points
        zs = rng.uniform(0.3, 0.5, len(flat))
        radius = rng.uniform(0.005, 0.01, len(flat))
        for h in (hull, hull[:2]):
            assert _same(edge_kernel.behind_palm(h, flat, pix, depth, 100.0, zs, radius),
                         _behind_palm_ref(h, flat, pix, depth, 100.0, zs, radius))


def test_each_kernel_has_its_one_signature() -> None:
    """Compiled for one signature each, no other: another dtype raises instead of compiling;
    asking again costs nothing (``kernel_compile.compile_signatures`` remembers the table)."""
    edge_kernel.compile_kernels()
    assert edge_kernel.compile_kernels() == 0.0
    for kernel in edge_kernel._SIGNATURES:
        assert len(kernel.signatures) == 1
    with pytest.raises(TypeError):
        edge_kernel.derivative(np.zeros((2, 5)), np.ones(2))   # float64 slices
    with pytest.raises(TypeError):
        edge_kernel.segment_distances(np.zeros((2, 2), np.float32), np.zeros((1, 2)),
                                      np.zeros((1, 2)))


def test_importing_the_edge_tracker_node_loads_no_numba() -> None:
    """The kernels come with the first measurement (``edge_features.compiled_kernels``), not
    with the import."""
    code = ('import sys, colorglove_ros.ros.nodes.edge_tracker_node\n'
            'print(sorted(m for m in ("scipy", "numba") if m in sys.modules))')
    run = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True,
                         timeout=120)
    assert run.returncode == 0, run.stderr
    assert run.stdout.strip() == '[]'
