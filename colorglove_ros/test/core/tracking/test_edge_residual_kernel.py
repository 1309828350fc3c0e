"""The edge fit's residual rows compiled (issue 17, session 28) against the numpy code they
replaced, kept here as the reference: the same bits on random lines, tips and weights, and
the remembered projections the same as fresh ones."""
from __future__ import annotations

import numpy as np
import pytest

from colorglove_ros.core.camera import PinholeCamera
from colorglove_ros.core.tracking import edge_fit, edge_kernel
from colorglove_ros.core.tracking.edge_fit import (
    _blend,
    _robust,
    link_axis_residuals,
    tip_residuals,
)


@pytest.fixture(autouse=True, scope='module')
def _compiled() -> None:
    """The kernels compiled for their one signature before any is called here (a call first
    would compile another, for writable arrays)."""
    edge_kernel.compile_kernels()


def _same(a: np.ndarray, b: np.ndarray) -> bool:
    """Same dtype, shape and bits, NaN wherever the other is NaN (of any sign or payload)."""
    if a.dtype != b.dtype or a.shape != b.shape:
        return False
    nan = np.isnan(a) if a.dtype.kind == 'f' else np.zeros(a.shape, bool)
    return bool(np.array_equal(nan, np.isnan(b) if b.dtype.kind == 'f' else nan)) \
        and a[~nan].tobytes() == b[~nan].tobytes()


def _line_rows_ref(pix, Jpix, rows_b, rows_e, alpha, normal, offset, n_link, tips, centre,
                   k, loss, tip_weight, palm_weight, camera_weight, jacobian):
    """stack_residuals' link, tip and palm rows of one camera as main computed them."""
    cam_r, cam_J, cam_w = [], [], []
    if len(rows_b):
        r, J = link_axis_residuals(
            normal, offset, _blend(pix, rows_b, alpha), _blend(pix, rows_e, alpha),
            _blend(Jpix, rows_b, alpha) if jacobian else np.zeros((len(rows_b), 2, 1)),
            _blend(Jpix, rows_e, alpha) if jacobian else np.zeros((len(rows_b), 2, 1)))
        w = _robust(r, k, loss)
        cam_r.append(r[:2 * n_link])
        cam_J.append(J[:2 * n_link])
        cam_w.append(w[:2 * n_link])
    if len(tips):
        rt, Jt = tip_residuals(pix[tips], centre,
                               Jpix[tips] if jacobian else np.zeros((len(tips), 2, 1)))
        cam_r.append(rt)
        cam_J.append(Jt)
        cam_w.append(tip_weight * _robust(rt, k, loss))
    if len(rows_b) > n_link:
        cam_r.append(r[2 * n_link:])
        cam_J.append(J[2 * n_link:])
        cam_w.append(palm_weight * w[2 * n_link:])
    if camera_weight is not None:
        cam_w = [camera_weight * w for w in cam_w]
    if not cam_r:
        return np.zeros(0), np.zeros((0, Jpix.shape[2])), np.zeros(0)
    return np.concatenate(cam_r), np.concatenate(cam_J), np.concatenate(cam_w)


@pytest.mark.parametrize('loss, k', [('cauchy', 3.0), ('huber', 3.0), ('cauchy', 0.0),
                                     ('huber', 0.4)])
def test_the_line_rows_kernel_gives_the_numpy_codes_bits(loss: str, k: float) -> None:
    """Links, palm sides blended between two generators, tips, robust and camera weights;
    empty sets, with and without Jacobians."""
    rng = np.random.default_rng(17)
    for trial in range(80):
        N, D = int(rng.integers(12, 60)), 26
        pix = rng.normal(300.0, 120.0, (N, 2))
        Jpix = rng.normal(0.0, 500.0, (N, 2, D))
        Jpix[:, :, rng.random(D) < 0.3] = 0.0
        n_link = min(int(rng.integers(0, 8)), N // 2 - 2) if trial % 7 else 0
        n_palm = int(rng.integers(0, 3))
        f = np.sort(rng.choice(N // 2 - 2, n_link, replace=False))
        palm = rng.integers(0, N - 3, n_palm)
        rows_b = np.concatenate([2 * f, palm]).astype(np.int64)
        rows_e = np.concatenate([2 * f + 1, palm + 1]).astype(np.int64)
        alpha = np.concatenate([np.zeros(n_link), rng.random(n_palm)])
        angle = rng.uniform(-np.pi, np.pi, n_link + n_palm)
        normal = np.stack([np.cos(angle), np.sin(angle)], axis=1)
        offset = rng.normal(200.0, 150.0, n_link + n_palm)
        tips = np.sort(rng.choice(N, int(rng.integers(0, 5)), replace=False)).astype(np.int64)
        centre = pix[tips] + rng.normal(0.0, 4.0, (len(tips), 2))
        if trial % 5 == 0:
            centre[:1] = pix[tips[:1]]                      # a zero residual
        weights = (rng.uniform(0.2, 2.0), rng.uniform(0.2, 2.0))
        camera_weight = None if trial % 3 == 0 else float(rng.uniform(0.1, 1.0))
        for jacobian in (True, False):
            got = edge_kernel.line_rows(
                pix, Jpix if jacobian else np.zeros((0, 2, D)), rows_b, rows_e, alpha, normal,
                offset, n_link, tips, centre, k, loss == 'cauchy', *weights,
                1.0 if camera_weight is None else camera_weight, camera_weight is not None,
                jacobian)
            want = _line_rows_ref(pix, Jpix, rows_b, rows_e, alpha, normal, offset, n_link,
                                  tips, centre, k, loss, *weights, camera_weight, jacobian)
            assert _same(got[0], want[0]) and _same(got[2], want[2])
            if jacobian:
                assert _same(got[1], want[1])
            else:
                assert got[1].shape == (len(want[0]), 0)


def test_a_remembered_projection_is_the_fresh_one_and_read_only() -> None:
    """The same points (another array of the same values) give the same pixels, depths and,
    for the same Jacobian array, the same pixel Jacobians; another Jacobian array is
    projected afresh; the arrays handed out cannot be written."""
    rng = np.random.default_rng(3)
    cam = PinholeCamera(640, 480, 600.0, 610.0, 320.0, 240.0,
                        rotation=np.array([[1.0, 0, 0], [0, 0.8, -0.6], [0, 0.6, 0.8]]),
                        translation=np.array([0.01, -0.2, 0.1]))
    p = rng.normal(0.0, 0.05, (40, 3)) + [0.0, 0.1, 0.5]
    J = rng.normal(0.0, 1.0, (40, 3, 26))
    fresh = edge_fit._project(cam, p, J)
    first = edge_fit._project_points(cam, p, J)
    again = edge_fit._project_points(cam, p.copy(), J)
    alone = edge_fit._project_points(cam, p.copy(), None)
    for a, b, c in zip(fresh, first, again, strict=True):
        assert _same(a, b) and b is c
    assert alone[0] is first[0] and alone[1] is None and alone[2] is first[2]
    J2 = J * 2.0
    other = edge_fit._project_points(cam, p, J2)
    assert _same(other[1], edge_fit._project(cam, p, J2)[1])
    assert not _same(other[1], first[1])
    for a in first:
        with pytest.raises(ValueError):
            a[0] = 0.0


def _axis_ref(pix, L, tip_slice, width, height, Jpix=None):
    """edge_fit._axis_points as main computed it (pixels, Jacobians)."""
    base, end = pix[0:2 * L:2], pix[1:2 * L:2]
    px = np.concatenate([base, 0.5 * (base + end), end, pix[tip_slice]])
    inside = (px[:, 0] >= 0) & (px[:, 0] < width) & (px[:, 1] >= 0) & (px[:, 1] < height)
    J = None
    if Jpix is not None:
        Jb, Je = Jpix[0:2 * L:2], Jpix[1:2 * L:2]
        J = np.concatenate([Jb, 0.5 * (Jb + Je), Je, Jpix[tip_slice]])[inside]
    return px[inside], J


def _silhouette_rows_ref(pix, Jpix, depth, L, tip_slice, width, height, d, grad, tol, t_px,
                         t_link, t_along, t_dir, radius, focal):
    """The axis and link rows of edge_fit._silhouette_residuals as main computed them."""
    off = d > tol
    r = [d[off] - tol]
    J = [np.zeros((0, Jpix.shape[-1]))]
    if off.any():
        J = [np.einsum('ij,ijd->id', grad[off],
                       _axis_ref(pix, L, tip_slice, width, height, Jpix)[1][off])]
    if len(t_px):
        Jb, Je = Jpix[0:2 * L:2][t_link], Jpix[1:2 * L:2][t_link]
        c = (1.0 - t_along)[:, None] * pix[0:2 * L:2][t_link] + t_along[:, None] \
            * pix[1:2 * L:2][t_link]
        z = 0.5 * (depth[0:2 * L:2] + depth[1:2 * L:2])[t_link]
        hw = radius[t_link] * focal / np.maximum(z, 1e-6)
        rl = np.einsum('ij,ij->i', t_dir, t_px - c) - hw - tol
        Jl = -np.einsum('ij,ijd->id', t_dir,
                        (1.0 - t_along)[:, None, None] * Jb + t_along[:, None, None] * Je)
        keep = rl > 0
        r.append(rl[keep])
        J.append(Jl[keep])
    return np.concatenate(r).astype(float), np.concatenate(J)


def test_the_silhouette_row_kernels_give_the_numpy_codes_bits() -> None:
    """Axis points inside and outside the image, off and on the foreground (float32
    distances and gradients), unexplained pixels on either side of their capsules."""
    rng = np.random.default_rng(29)
    width, height = 640, 480
    for trial in range(80):
        L, T, D = int(rng.integers(1, 15)), int(rng.integers(0, 6)), 26
        N = 2 * L + 2 * T + int(rng.integers(0, 6))
        tip_slice = slice(2 * L, 2 * L + 2 * T, 2)
        pix = rng.uniform(-60.0, 700.0, (N, 2))
        Jpix = rng.normal(0.0, 300.0, (N, 2, D))
        depth = rng.uniform(0.3, 0.7, N)
        if trial % 9 == 0:
            depth[0] = 0.0                                  # the 1e-6 floor
        ax, place = edge_kernel.axis_points(pix, L, tip_slice.start, T, width, height)
        assert _same(ax, _axis_ref(pix, L, tip_slice, width, height)[0])
        d = np.abs(rng.normal(3.0, 4.0, len(ax))).astype(np.float32)
        d[rng.random(len(ax)) < 0.3] = 0.0
        grad = rng.normal(0.0, 1.0, (len(ax), 2)).astype(np.float32)
        M = int(rng.integers(0, 30)) if trial % 4 else 0
        t_link = rng.integers(0, L, M)
        t_along = np.clip(rng.uniform(-0.2, 1.2, M), 0.0, 1.0)
        t_px = rng.uniform(0.0, 640.0, (M, 2))
        angle = rng.uniform(-np.pi, np.pi, M)
        t_dir = np.stack([np.cos(angle), np.sin(angle)], axis=1)
        radius = rng.uniform(0.005, 0.011, L)
        got = edge_kernel.silhouette_rows(pix, Jpix, depth, L, tip_slice.start, place, d, grad,
                                          4.0, t_px, t_link, t_along, t_dir, radius, 605.0)
        want = _silhouette_rows_ref(pix, Jpix, depth, L, tip_slice, width, height, d, grad,
                                    4.0, t_px, t_link, t_along, t_dir, radius, 605.0)
        assert _same(got[0], want[0]) and _same(got[1], want[1])


def _fit_lines_ref(base, end, centres, n, frac, off, valid, outlier_px):
    """edge_features._fit_lines as main computed it."""
    L = len(base)
    axis = end - base
    length = np.linalg.norm(axis, axis=1)
    u = axis / np.maximum(length, 1e-9)[:, None]
    s_along = (frac[None, :] - 0.5) * length[:, None]
    w = valid.astype(float)
    a = b = np.zeros(L)
    for _ in range(2):
        sw = w.sum(1)
        safe = np.maximum(sw, 1e-9)
        ms = (w * s_along).sum(1) / safe
        mo = (w * off).sum(1) / safe
        var = (w * (s_along - ms[:, None]) ** 2).sum(1)
        cov = (w * (s_along - ms[:, None]) * (off - mo[:, None])).sum(1)
        b = np.where(var > 1e-9, cov / np.maximum(var, 1e-9), 0.0)
        a = mo - b * ms
        resid = np.abs(off - (a[:, None] + b[:, None] * s_along))
        w = (valid & (resid <= outlier_px)).astype(float)
    direction = u + b[:, None] * n
    with np.errstate(invalid='ignore'):
        direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    normal = np.stack([-direction[:, 1], direction[:, 0]], axis=1)
    mid_point = 0.5 * (base + end) + a[:, None] * n
    offset = np.einsum('ij,ij->i', normal, mid_point)
    points = centres + off[..., None] * n[:, None, :]
    return normal, offset, w, np.where((w > 0)[..., None], points, np.nan)


@pytest.mark.parametrize('slices', [2, 6, 9, 17])
def test_the_line_fit_kernel_gives_the_numpy_codes_bits(slices: int) -> None:
    """Segments of every direction (one of zero length), a few or no valid slices, outliers,
    slice counts on both sides of numpy's eight-way pairwise sums."""
    rng = np.random.default_rng(slices)
    for _ in range(60):
        L = int(rng.integers(1, 16))
        base = rng.uniform(0.0, 640.0, (L, 2))
        end = base + rng.normal(0.0, 40.0, (L, 2))
        end[0] = base[0] if L > 2 else end[0]
        axis = end - base
        u = axis / np.maximum(np.linalg.norm(axis, axis=1), 1e-9)[:, None]
        n = np.stack([-u[:, 1], u[:, 0]], axis=1)
        frac = np.linspace(0.2, 0.85, slices)
        centres = base[:, None, :] + frac[None, :, None] * axis[:, None, :]
        off = rng.normal(0.0, 1.5, (L, slices)) + rng.normal(0.0, 3.0, (L, 1))
        off[rng.random((L, slices)) < 0.15] += 9.0                    # outliers
        valid = rng.random((L, slices)) < 0.8
        valid[-1] = False
        got = edge_kernel.fit_lines(base, end, centres, n, frac, off, valid, 2.0)
        for g, w in zip(got, _fit_lines_ref(base, end, centres, n, frac, off, valid, 2.0),
                        strict=True):
            assert _same(g, w)


def test_the_pairwise_sum_is_numpys() -> None:
    """Every length from 0 to 300 (in order, eight running sums, halves) on values of mixed
    sizes."""
    rng = np.random.default_rng(5)
    a = rng.normal(0.0, 1.0, 300) * 10.0 ** rng.uniform(-6, 6, 300)
    for n in range(301):
        for start in (0, 3):
            assert edge_kernel._pairwise_sum(a, start, min(n, 300 - start)) \
                == a[start:start + n].sum()


def _unexplained_ref(sil, outline, tolerance_px, pixels=True):
    """Silhouette.unexplained as main computed it (the covered parts and the forearm drawn
    into images of their own, then masked out)."""
    import cv2

    def _fixed(xy, scale):
        return np.round((np.asarray(xy) + 0.5) / scale * 16 - 8).astype(np.int32)

    def _pts(xy, scale):
        return [tuple(p) for p in _fixed(xy, scale).tolist()]

    s = sil.scale
    covered = np.zeros(sil.mask.shape, np.uint8)
    tol = float(tolerance_px)
    shift = s * sil.offset
    ok = np.isfinite(outline.base).all(1) & np.isfinite(outline.end).all(1)
    thick = np.maximum(1, np.round(2.0 * (outline.half_width + tol) / s)).astype(int)
    ends = np.stack([_fixed(outline.base[ok] - shift, s), _fixed(outline.end[ok] - shift, s)],
                    axis=1)
    for t in np.unique(thick[ok]):
        cv2.polylines(covered, list(ends[thick[ok] == t]), False, 1, int(t), cv2.LINE_8, 4)
    ok = np.isfinite(outline.tip).all(1)
    radius = np.maximum(1, np.round(16 * (outline.tip_radius + tol) / s)).astype(int)
    for c, r in zip(_pts(outline.tip[ok] - shift, s), radius[ok], strict=True):
        cv2.circle(covered, c, int(r), 1, -1, cv2.LINE_8, 4)
    if len(outline.palm) >= 3 and np.all(np.isfinite(outline.palm)):
        hull = cv2.convexHull(np.round(((outline.palm - shift + 0.5) / s - 0.5) * 16)
                              .astype(np.int32))
        cv2.fillConvexPoly(covered, hull, 1, cv2.LINE_8, 4)
        if tol > 0:
            cv2.polylines(covered, [hull], True, 1, max(1, int(round(2.0 * tol / s))),
                          cv2.LINE_8, 4)
    h, w = sil.mask.shape
    big = 4.0 * (h + w + np.abs(sil.offset).sum())
    a = np.asarray(outline.axis, dtype=float)
    across = np.array([-a[1], a[0]])
    start = (outline.wrist - shift + 0.5) / s - 0.5 - (tol / s) * a
    arm = np.zeros_like(covered)
    quad = start + big * np.array([across, -across, -across - a, across - a])
    cv2.fillConvexPoly(arm, np.round(quad * 16).astype(np.int32), 1, cv2.LINE_8, 4)
    hand = cv2.bitwise_and(sil._mask_u8, 1 - arm)
    count = cv2.countNonZero(hand)
    if count == 0:
        return np.zeros((0, 2)), 0.0
    loose = cv2.bitwise_and(hand, 1 - covered)
    if not pixels:
        return np.zeros((0, 2)), float(cv2.countNonZero(loose)) / float(count)
    found = cv2.findNonZero(loose)
    if found is None:
        return np.zeros((0, 2)), 0.0
    pix = (found.reshape(-1, 2) + sil.offset + 0.5) * s - 0.5
    return pix, float(len(pix)) / float(count)


@pytest.mark.parametrize('scale', [1, 2])
def test_the_unexplained_pixels_are_main_codes(scale: int) -> None:
    """Random hands (capsules, some not finite, tips, palms) over random blobs, offsets and
    tolerances: the same pixels and shares, listed or not."""
    from colorglove_ros.core.tracking.silhouette import HandOutline, Silhouette
    rng = np.random.default_rng(11 + scale)
    for trial in range(60):
        h, w = int(rng.integers(20, 120)), int(rng.integers(20, 120))
        mask = np.zeros((h, w), bool)
        for _ in range(int(rng.integers(0, 6))):
            y, x, r = rng.integers(0, h), rng.integers(0, w), rng.integers(2, 25)
            yy, xx = np.ogrid[:h, :w]
            mask |= (yy - y) ** 2 + (xx - x) ** 2 <= r * r
        sil = Silhouette(mask, scale, (int(rng.integers(0, 30)), int(rng.integers(0, 30))))
        origin = sil.offset * scale
        L, T = int(rng.integers(0, 12)), int(rng.integers(0, 6))
        base = origin + rng.uniform(-20, w * scale + 20, (L, 2))
        end = base + rng.normal(0, 25, (L, 2))
        if L and trial % 5 == 0:
            end[0] = np.nan
        tip = origin + rng.uniform(0, w * scale, (T, 2))
        palm = origin + rng.uniform(0, w * scale, (int(rng.choice([0, 2, 8])), 2))
        axis = rng.normal(0, 1, 2)
        outline = HandOutline(base, end, rng.uniform(1, 9, L), tip, rng.uniform(2, 8, T), palm,
                              origin + rng.uniform(0, w * scale, 2), axis / np.linalg.norm(axis))
        ends, thick, tips, radii = edge_kernel.outline_drawing(
            base, end, outline.half_width, tip, outline.tip_radius, sil.offset * scale, scale,
            4.0)
        ok = np.isfinite(base).all(1) & np.isfinite(end).all(1)
        fixed = np.round((np.stack([base[ok], end[ok]], axis=1) - sil.offset * scale + 0.5)
                         / scale * 16 - 8).astype(np.int32)
        width = np.maximum(1, np.round(2.0 * (outline.half_width[ok] + 4.0) / scale)).astype(int)
        order = np.argsort(width, kind='stable')
        assert _same(ends, fixed[order]) and _same(thick, width[order])
        assert _same(tips, np.round((tip - sil.offset * scale + 0.5) / scale * 16 - 8)
                     .astype(np.int32))
        assert _same(radii, np.maximum(1, np.round(16 * (outline.tip_radius + 4.0) / scale))
                     .astype(int))
        for tol in (0.0, 4.0):
            for pixels in (True, False):
                got = sil.unexplained(outline, tol, pixels)
                want = _unexplained_ref(sil, outline, tol, pixels)
                assert got[1] == want[1] and _same(got[0], want[0])


def _outside_distance_ref(sil, px):
    """Silhouette.outside_distance as main computed it."""
    import cv2

    px = np.asarray(px, dtype=float).reshape(-1, 2)
    h = float(sil.scale)
    probe = px[:, None, :] + h * np.array([[0, 0], [1, 0], [-1, 0], [0, 1], [0, -1]])
    if not np.size(probe):
        v = np.zeros(probe.shape[:-1], np.float32)
    else:
        flat = ((np.asarray(probe, np.float32).reshape(-1, 2) + 0.5) / sil.scale - 0.5
                - sil.offset).astype(np.float32)
        v = cv2.remap(sil._outside, np.ascontiguousarray(flat[:, :1]),
                      np.ascontiguousarray(flat[:, 1:]), cv2.INTER_LINEAR,
                      borderMode=cv2.BORDER_REPLICATE).reshape(probe.shape[:-1])
    grad = np.stack([v[:, 1] - v[:, 2], v[:, 3] - v[:, 4]], axis=1) / (2.0 * h)
    return v[:, 0], grad


@pytest.mark.parametrize('scale', [1, 2, 3])
def test_the_outside_distances_are_main_codes(scale: int) -> None:
    """Pixels on, off and far off random blobs, fractional, outside the mask, none."""
    from colorglove_ros.core.tracking.silhouette import Silhouette
    rng = np.random.default_rng(scale)
    for _ in range(40):
        h, w = int(rng.integers(10, 90)), int(rng.integers(10, 90))
        yy, xx = np.ogrid[:h, :w]
        mask = (yy - rng.integers(0, h)) ** 2 + (xx - rng.integers(0, w)) ** 2 \
            <= rng.integers(0, 30) ** 2
        sil = Silhouette(mask, scale, (int(rng.integers(0, 40)), int(rng.integers(0, 40))))
        px = rng.uniform(-20.0, (w + 60) * scale, (int(rng.integers(0, 50)), 2)) \
            + sil.offset * scale
        if len(px):
            probe = px[:, None, :] + scale * np.array([[0, 0], [1, 0], [-1, 0], [0, 1], [0, -1]])
            flat = ((probe.astype(np.float32).reshape(-1, 2) + 0.5) / scale - 0.5
                    - sil.offset).astype(np.float32)
            mx, my = edge_kernel.probe_maps(px, scale, sil.offset)
            assert _same(mx, flat[:, :1].copy()) and _same(my, flat[:, 1:].copy())
        for got, want in zip(sil.outside_distance(px), _outside_distance_ref(sil, px),
                             strict=True):
            assert _same(got, want)


def _link_prediction_ref(pix, depth, L, radius, focal, frac, min_depth, min_len, search,
                         width, height):
    """predict_features' links as main computed them."""
    base, end = pix[0:2 * L:2], pix[1:2 * L:2]
    zb, ze = depth[0:2 * L:2], depth[1:2 * L:2]
    hw = radius * focal / np.maximum(0.5 * (zb + ze), 1e-6)
    usable = (zb > min_depth) & (ze > min_depth) \
        & (np.linalg.norm(end - base, axis=1) >= min_len)
    centres = base[:, None, :] + frac[None, :, None] * (end - base)[:, None, :]
    margin = hw[:, None] + search
    inside = ((centres[..., 0] >= margin) & (centres[..., 0] < width - margin)
              & (centres[..., 1] >= margin) & (centres[..., 1] < height - margin))
    z_self = zb[:, None] + frac[None, :] * (ze - zb)[:, None]
    return (base.copy(), end.copy(), zb.copy(), ze.copy(), hw, usable,
            centres.reshape(-1, 2), inside, z_self.reshape(-1))


def _tip_prediction_ref(pix, depth, L, T, tip_radius, focal, rows, link_usable, min_depth,
                        search, width, height, base, end, zb, ze, hw, usable):
    """predict_features' tips as main computed them."""
    from colorglove_ros.core.tracking.edge_features import segment_distances
    tip_slice = slice(2 * L, 2 * L + 2 * T, 2)
    tip_end = pix[2 * L + 1:2 * L + 2 * T:2]
    zt = depth[tip_slice]
    tip_r = tip_radius * focal / np.maximum(zt, 1e-6)
    tip_ok = (rows >= 0) & (zt > min_depth)
    tip_ok &= np.where(rows >= 0, link_usable[np.maximum(rows, 0)], False)
    margin_t = search + tip_r
    tip_ok &= ((tip_end[:, 0] >= margin_t) & (tip_end[:, 0] < width - margin_t)
               & (tip_end[:, 1] >= margin_t) & (tip_end[:, 1] < height - margin_t))
    if T:
        dt, st = segment_distances(tip_end, base, end)
        zt_other = zb[None, :] + st * (ze - zb)[None, :]
        mask = np.zeros((T, L), dtype=bool)
        mask[np.arange(T)[rows >= 0], rows[rows >= 0]] = True
        over = (dt < hw[None, :] + tip_r[:, None]) & (zt_other < zt[:, None]) & ~mask
        tip_ok &= ~np.any(over & usable[None, :], axis=1)
    return tip_r, tip_ok


def test_the_prediction_kernels_give_the_numpy_codes_bits() -> None:
    """Links behind the camera, short, at the image's border; tips without a distal link,
    on nearer links, outside the image."""
    rng = np.random.default_rng(41)
    width, height = 640, 480
    for trial in range(80):
        L, T = int(rng.integers(1, 15)), int(rng.integers(0, 6))
        N = 2 * L + 2 * T + 3
        pix = rng.uniform(-40.0, 680.0, (N, 2))
        if trial % 3 == 0:                  # tips close to links
            pix[2 * L:2 * L + 2 * T] = pix[:2 * T] + rng.normal(0, 5, (2 * T, 2)) \
                if 2 * T <= 2 * L else pix[2 * L:2 * L + 2 * T]
        depth = rng.uniform(-0.05, 0.7, N)
        radius = rng.uniform(0.005, 0.011, L)
        frac = np.linspace(0.2, 0.85, int(rng.integers(2, 9)))
        got = edge_kernel.link_prediction(pix, depth, L, radius, 605.0, frac, 0.1, 10.0, 8.0,
                                          width, height)
        want = _link_prediction_ref(pix, depth, L, radius, 605.0, frac, 0.1, 10.0, 8.0, width,
                                    height)
        for g, w in zip(got, want, strict=True):
            assert _same(g, w)
        base, end, zb, ze, hw, usable = want[:6]
        rows = rng.integers(-1, L, T).astype(np.int64)
        link_usable = rng.random(L) < 0.8
        tip_radius = rng.uniform(0.007, 0.01, T)
        got = edge_kernel.tip_prediction(pix, depth, 2 * L, T, tip_radius, 605.0, rows,
                                         link_usable, 0.1, 10.0, width, height, base, end, zb,
                                         ze, hw, usable)
        want = _tip_prediction_ref(pix, depth, L, T, tip_radius, 605.0, rows, link_usable, 0.1,
                                   10.0, width, height, base, end, zb, ze, hw, usable)
        for g, w in zip(got, want, strict=True):
            assert _same(g, w)


def _palm_prediction_ref(pix, depth, rb, re, alpha, centre_rows, frac, min_depth, min_len,
                         search, width, height, base, end, zb, ze, hw, link_usable,
                         min_slices):
    """_predict_palm after the generators' choice, as main computed it."""
    from colorglove_ros.core.tracking.edge_features import segment_distances
    P, S = len(rb), len(frac)
    pb, pe = _blend(pix, rb, alpha), _blend(pix, re, alpha)
    zpb, zpe = _blend(depth, rb, alpha), _blend(depth, re, alpha)
    pc = pix[centre_rows]
    u = (pe - pb) / np.maximum(np.linalg.norm(pe - pb, axis=1, keepdims=True), 1e-9)
    n = np.stack([-u[:, 1], u[:, 0]], axis=1)
    n *= np.where(np.einsum('ij,ij->i', n, pb - pc) < 0, -1.0, 1.0)[:, None]
    in_front = (zpb > min_depth) & (zpe > min_depth)
    long_enough = np.linalg.norm(pe - pb, axis=1) >= min_len
    centres = pb[:, None, :] + frac[None, :, None] * (pe - pb)[:, None, :]
    inside = ((centres[..., 0] >= search) & (centres[..., 0] < width - search)
              & (centres[..., 1] >= search) & (centres[..., 1] < height - search))
    dist, along = segment_distances(centres.reshape(-1, 2), base, end)
    dist, along = dist.reshape(P, S, len(base)), along.reshape(P, S, len(base))
    z_link = zb[None, None, :] + along * (ze - zb)[None, None, :]
    z_self = (zpb[:, None] + frac[None, :] * (zpe - zpb)[:, None])[..., None]
    covered = (dist < hw[None, None, :] + search) & (z_link < z_self) \
        & link_usable[None, None, :]
    slice_valid = (in_front & long_enough)[:, None] & inside & ~np.any(covered, axis=2)
    return pb, pe, n, slice_valid, slice_valid.sum(1) >= min_slices


def test_the_palm_prediction_kernel_gives_the_numpy_codes_bits() -> None:
    """Palm sides between two generators, behind the camera, short, behind nearer links."""
    rng = np.random.default_rng(43)
    for trial in range(80):
        L, P, N = int(rng.integers(1, 15)), int(rng.integers(1, 3)), 60
        pix = rng.uniform(-20.0, 660.0, (N, 2))
        depth = rng.uniform(-0.05, 0.7, N)
        rb = rng.integers(0, N - 3, P).astype(np.int64)
        re = (rb + 1).astype(np.int64)
        alpha = rng.random(P)
        centre_rows = rng.integers(0, N, P).astype(np.int64)
        base = rng.uniform(0.0, 640.0, (L, 2))
        end = base + rng.normal(0.0, 60.0, (L, 2))
        if trial % 4 == 0:                              # links over the palm's side
            base[0] = pix[rb[0]] + rng.normal(0, 3, 2)
            end[0] = pix[re[0]] + rng.normal(0, 3, 2)
        zb, ze = rng.uniform(0.2, 0.6, L), rng.uniform(0.2, 0.6, L)
        hw = rng.uniform(3.0, 12.0, L)
        link_usable = rng.random(L) < 0.8
        frac = np.linspace(0.15, 0.95, int(rng.integers(2, 9)))
        args = (pix, depth, rb, re, alpha, centre_rows, frac, 0.1, 10.0, 8.0, 640, 480, base,
                end, zb, ze, hw, link_usable, 3)
        for g, w in zip(edge_kernel.palm_prediction(*args), _palm_prediction_ref(*args),
                        strict=True):
            assert _same(g, w)
