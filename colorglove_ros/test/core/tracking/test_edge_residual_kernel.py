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


def _same(a: np.ndarray, b: np.ndarray) -> bool:
    return a.dtype == b.dtype and a.shape == b.shape and a.tobytes() == b.tobytes()


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
