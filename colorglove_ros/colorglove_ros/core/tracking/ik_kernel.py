"""Compiled (numba) kernels of the IK's inner loop: the hand's forward kinematics, link-fixed
points with their analytic Jacobians, the projected residual rows of the correspondences, and
the glove's surface elements posed and weighted as a camera sees them, and the patch sums
over them (the patch points of the constraints, each patch's visible area; :mod:`patch_surface`).

The same arithmetic as the numpy code they replaced, written as loops over small fixed-size
arrays, so one call replaces the dozens of numpy calls whose per-call overhead dominated the
fit. Every kernel is compiled once and cached on disk (``cache=True``); :func:`compile_kernels`
makes (or loads) them ahead of the first frame. Arrays passed in must be C-contiguous float64 /
int64, as the callers (:mod:`kinematics`, :mod:`projection`, :mod:`solver`,
:mod:`patch_surface`) make them.
"""
from __future__ import annotations

import math

import numba
import numpy as np

from colorglove_ros.core.kernel_compile import compile_signatures

__all__ = ['forward_frames', 'link_points', 'projected_rows', 'prior_cost', 'normal_equations',
           'damped_step', 'translation_fit',
           'posed_elements', 'element_weights', 'patch_points', 'patch_areas', 'compile_kernels',
           'SINGULAR', 'BEHIND']

#: :func:`translation_fit` outcomes besides 0 (solved): the normal equations are singular,
#: the solution puts a point behind its camera.
SINGULAR, BEHIND = 1, 2

_JIT = {'cache': True, 'nogil': True}


@numba.njit(**_JIT)
def _matmul3(A: np.ndarray, B: np.ndarray) -> np.ndarray:
    """A @ B of two 3 x 3 matrices."""
    out = np.empty((3, 3))
    for a in range(3):
        for b in range(3):
            out[a, b] = A[a, 0] * B[0, b] + A[a, 1] * B[1, b] + A[a, 2] * B[2, b]
    return out


@numba.njit(**_JIT)
def _rotvec_and_left_jacobian(r: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Rotation matrix and SO(3) left Jacobian of one rotation vector in one pass, sharing the
    skew matrix and its square (Taylor terms below 1e-5 rad): ``core.geometry``'s
    ``rotvec_to_matrix`` and ``so3_left_jacobian`` to rounding (``test_ik_kernel``)."""
    theta = math.sqrt(r[0] * r[0] + r[1] * r[1] + r[2] * r[2])
    K = np.zeros((3, 3))
    K[0, 1], K[0, 2] = -r[2], r[1]
    K[1, 0], K[1, 2] = r[2], -r[0]
    K[2, 0], K[2, 1] = -r[1], r[0]
    KK = _matmul3(K, K)
    if theta < 1e-5:
        a, b = 1.0 - theta**2 / 6.0, 0.5 - theta**2 / 24.0
        c = 1.0 / 6.0 - theta**2 / 120.0
    else:
        st, ct = math.sin(theta), math.cos(theta)
        a, b = st / theta, (1.0 - ct) / theta**2
        c = (theta - st) / theta**3
    R = np.eye(3) + a * K + b * KK
    jl = np.eye(3) + b * K + c * KK
    return R, jl


@numba.njit(**_JIT)
def forward_frames(rotvec: np.ndarray, angles: np.ndarray, K: np.ndarray, KK: np.ndarray,
                   fixed_R: np.ndarray, fixed_t: np.ndarray, parent: np.ndarray
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Rotations (F, 3, 3) and origins (F, 3) of the kinematic frames with the wrist at the
    origin (frame 0 the palm, frame j + 1 moved by joint j, parents first) and the left
    Jacobian of the wrist rotation vector: joint j turns ``angles[j]`` about the axis whose
    skew matrix is ``K[j]`` (Rodrigues), after its fixed transform (``fixed_R[j]``,
    ``fixed_t[j]``) from frame ``parent[j]``."""
    n = len(angles)
    Rs = np.zeros((n + 1, 3, 3))
    ts = np.zeros((n + 1, 3))
    R0, jl = _rotvec_and_left_jacobian(rotvec)
    Rs[0] = R0
    Rj = np.empty((3, 3))
    for j in range(n):
        s, c1 = math.sin(angles[j]), 1.0 - math.cos(angles[j])
        for a in range(3):
            for b in range(3):
                Rj[a, b] = (1.0 if a == b else 0.0) + s * K[j, a, b] + c1 * KK[j, a, b]
        local = _matmul3(fixed_R[j], Rj)
        p = parent[j]
        for a in range(3):
            for b in range(3):
                Rs[j + 1, a, b] = (Rs[p, a, 0] * local[0, b] + Rs[p, a, 1] * local[1, b]
                                   + Rs[p, a, 2] * local[2, b])
            ts[j + 1, a] = (Rs[p, a, 0] * fixed_t[j, 0] + Rs[p, a, 1] * fixed_t[j, 1]
                            + Rs[p, a, 2] * fixed_t[j, 2] + ts[p, a])
    return Rs, ts, jl


@numba.njit(**_JIT)
def _joint_axes(Rs: np.ndarray, ts: np.ndarray, axis: np.ndarray
                ) -> tuple[np.ndarray, np.ndarray]:
    """Every joint's axis w_j in the camera frame (nj, 3) and w_j x (o_j - o_0) (nj, 3)."""
    nj = len(axis)
    w = np.empty((nj, 3))
    offset = np.empty((nj, 3))
    for j in range(nj):
        R = Rs[j + 1]
        for a in range(3):
            w[j, a] = R[a, 0] * axis[j, 0] + R[a, 1] * axis[j, 1] + R[a, 2] * axis[j, 2]
        ox, oy, oz = ts[j + 1, 0] - ts[0, 0], ts[j + 1, 1] - ts[0, 1], ts[j + 1, 2] - ts[0, 2]
        offset[j, 0] = w[j, 1] * oz - w[j, 2] * oy
        offset[j, 1] = w[j, 2] * ox - w[j, 0] * oz
        offset[j, 2] = w[j, 0] * oy - w[j, 1] * ox
    return w, offset


@numba.njit(**_JIT)
def _add_point(Rs: np.ndarray, ts: np.ndarray, jl: np.ndarray, w: np.ndarray,
               offset: np.ndarray, ancestors: np.ndarray, dof: np.ndarray, frame: int,
               local: np.ndarray, weight: float, p_out: np.ndarray, J_out: np.ndarray,
               jacobian: bool) -> None:
    """Add ``weight`` times the camera-frame point of ``local`` fixed in kinematic frame
    ``frame`` (and its d/dq (3, 26)) to ``p_out`` (and ``J_out``)."""
    R, o = Rs[frame], ts[frame]
    p = np.empty(3)
    for a in range(3):
        p[a] = R[a, 0] * local[0] + R[a, 1] * local[1] + R[a, 2] * local[2] + o[a]
        p_out[a] += weight * p[a]
    if not jacobian:
        return
    # wrist-relative point d; d/dq: identity (translation), -[d]_x jl (rotation vector),
    # w_j x d - w_j x (o_j - o_0) for every joint j that moves the point
    d0, d1, d2 = p[0] - ts[0, 0], p[1] - ts[0, 1], p[2] - ts[0, 2]
    for a in range(3):
        J_out[a, a] += weight
    for b in range(3):
        J_out[0, 3 + b] += weight * -(-d2 * jl[1, b] + d1 * jl[2, b])
        J_out[1, 3 + b] += weight * -(d2 * jl[0, b] - d0 * jl[2, b])
        J_out[2, 3 + b] += weight * -(-d1 * jl[0, b] + d0 * jl[1, b])
    for j in range(len(dof)):
        if ancestors[frame, j] == 0.0:
            continue
        col = dof[j]
        J_out[0, col] += weight * ((w[j, 1] * d2 - w[j, 2] * d1) - offset[j, 0])
        J_out[1, col] += weight * ((w[j, 2] * d0 - w[j, 0] * d2) - offset[j, 1])
        J_out[2, col] += weight * ((w[j, 0] * d1 - w[j, 1] * d0) - offset[j, 2])


@numba.njit(**_JIT)
def link_points(Rs: np.ndarray, ts: np.ndarray, jl: np.ndarray, axis: np.ndarray,
                ancestors: np.ndarray, dof: np.ndarray, num_dofs: int,
                frame: np.ndarray, local: np.ndarray, jacobian: bool
                ) -> tuple[np.ndarray, np.ndarray]:
    """Camera-frame points (N, 3) of the link-fixed points ``local`` (N, 3) in kinematic
    frames ``frame`` (N,) and, if ``jacobian``, their d/dq (N, 3, ``num_dofs``; else (0, 3,
    ``num_dofs``)). ``Rs``, ``ts``, ``jl``: ``FastKinematics.frames``; joint j turns about
    ``axis[j]`` (its frame's axes), drives DOF ``dof[j]`` and moves the points of the frames
    f with ``ancestors[f, j]`` non-zero."""
    n = len(frame)
    p = np.zeros((n, 3))
    J = np.zeros((n if jacobian else 0, 3, num_dofs))
    if jacobian:
        w, offset = _joint_axes(Rs, ts, axis)
    else:
        w, offset = np.zeros((0, 3)), np.zeros((0, 3))
    scratch = np.zeros((3, num_dofs))
    for i in range(n):
        Ji = J[i] if jacobian else scratch
        _add_point(Rs, ts, jl, w, offset, ancestors, dof, frame[i], local[i], 1.0, p[i], Ji,
                   jacobian)
    return p, J


@numba.njit(**_JIT)
def projected_rows(Rs: np.ndarray, ts: np.ndarray, jl: np.ndarray, axis: np.ndarray,
                   ancestors: np.ndarray, dof: np.ndarray, num_dofs: int,
                   frame: np.ndarray, local: np.ndarray, weight: np.ndarray,
                   cam_R: np.ndarray, cam_t: np.ndarray, focal: np.ndarray,
                   centre: np.ndarray, jacobian: bool
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Predicted pixels (K, 2), pixel Jacobian (2K, ``num_dofs``, rows x0, y0, x1, ...; (0,
    ``num_dofs``) without ``jacobian``) and camera depths (K,) of K constrained points, each
    the ``weight``-ed mean (K, S) of its link-fixed points ``local`` (K, S, 3) in frames
    ``frame`` (K, S) (zero weights skipped), seen by a pinhole camera with rotation
    ``cam_R[k]``, translation ``cam_t[k]``, focal lengths ``focal[k]`` and centre
    ``centre[k]`` (no distortion; a depth within 1e-9 of 0 is taken as 1e-9); the
    kinematic arguments as :func:`link_points`."""
    k_rows, slots = frame.shape
    pix = np.empty((k_rows, 2))
    depth = np.empty(k_rows)
    J = np.zeros((2 * k_rows if jacobian else 0, num_dofs))
    if jacobian:
        w, offset = _joint_axes(Rs, ts, axis)
    else:
        w, offset = np.zeros((0, 3)), np.zeros((0, 3))
    p = np.empty(3)
    Jp = np.empty((3, num_dofs))
    pc = np.empty(3)
    for k in range(k_rows):
        p[:] = 0.0
        Jp[:, :] = 0.0
        for s in range(slots):
            if weight[k, s] != 0.0:
                _add_point(Rs, ts, jl, w, offset, ancestors, dof, frame[k, s], local[k, s],
                           weight[k, s], p, Jp, jacobian)
        R = cam_R[k]
        for a in range(3):
            pc[a] = R[a, 0] * p[0] + R[a, 1] * p[1] + R[a, 2] * p[2] + cam_t[k, a]
        depth[k] = pc[2]
        z = 1e-9 if abs(pc[2]) < 1e-9 else pc[2]
        x, y = pc[0] / z, pc[1] / z
        pix[k, 0] = x * focal[k, 0] + centre[k, 0]
        pix[k, 1] = y * focal[k, 1] + centre[k, 1]
        if jacobian:
            # d pixel / d point = (f / z) (R[0:2] - xy R[2]), chained with the point's d/dq
            for i in range(2):
                xy = x if i == 0 else y
                fz = focal[k, i] / z
                a0 = fz * (R[i, 0] - xy * R[2, 0])
                a1 = fz * (R[i, 1] - xy * R[2, 1])
                a2 = fz * (R[i, 2] - xy * R[2, 2])
                for d in range(num_dofs):
                    J[2 * k + i, d] = a0 * Jp[0, d] + a1 * Jp[1, d] + a2 * Jp[2, d]
    return pix, J, depth


@numba.njit(**_JIT)
def prior_cost(r: np.ndarray, w: np.ndarray, q: np.ndarray, q_blend: np.ndarray,
               q_inv: np.ndarray, q_prev: np.ndarray, p_inv: np.ndarray, smoothing: bool
               ) -> float:
    """|r|^2_w + |q - q_blend|^2_{q_inv} (+ |q - q_prev|^2_{p_inv} with ``smoothing``): the
    IK's cost (``solver.solve_ik``)."""
    data = 0.0
    for i in range(len(r)):
        data += r[i] * (w[i] * r[i])
    blend = 0.0
    prev = 0.0
    for d in range(len(q)):
        blend += (q[d] - q_blend[d]) ** 2 * q_inv[d]
        if smoothing:
            prev += (q[d] - q_prev[d]) ** 2 * p_inv[d]
    return data + blend + prev if smoothing else data + blend


@numba.njit(**_JIT)
def normal_equations(J: np.ndarray, w: np.ndarray, r: np.ndarray, q: np.ndarray,
                     q_blend: np.ndarray, q_inv: np.ndarray, q_prev: np.ndarray,
                     p_inv: np.ndarray, smoothing: bool, lower: np.ndarray, upper: np.ndarray
                     ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The Gauss-Newton system of :func:`prior_cost` at ``q``: H = J^T W J + Q^-1 (+ P^-1),
    g = J^T W r + Q^-1 (q_blend - q) (+ P^-1 (q_prev - q)), and the DOFs free to move (not
    at a bound, ``lower`` / ``upper`` already moved inward by the solver's margin, with the
    step pointing outward)."""
    n = len(q)
    H = np.zeros((n, n))
    g = np.zeros(n)
    for row in range(len(r)):
        for a in range(n):
            wa = J[row, a] * w[row]
            if wa == 0.0:
                continue
            g[a] += wa * r[row]
            for b in range(n):
                H[a, b] += wa * J[row, b]
    free = np.empty(n, np.bool_)
    for d in range(n):
        H[d, d] += q_inv[d]
        g[d] += q_inv[d] * (q_blend[d] - q[d])
        if smoothing:
            H[d, d] += p_inv[d]
            g[d] += p_inv[d] * (q_prev[d] - q[d])
        free[d] = not ((q[d] <= lower[d] and g[d] < 0) or (q[d] >= upper[d] and g[d] > 0))
    return H, g, free


@numba.njit(**_JIT)
def damped_step(H: np.ndarray, g: np.ndarray, free: np.ndarray, lam: float) -> np.ndarray:
    """The step dq (zero on the frozen DOFs) solving (H + lam diag(H)) dq = g on the free
    DOFs; raises ``numpy.linalg.LinAlgError`` when that matrix is singular."""
    index = np.flatnonzero(free)
    m = len(index)
    dq = np.zeros(len(g))
    if m == 0:
        return dq
    A = np.empty((m, m))
    b = np.empty(m)
    for i in range(m):
        for j in range(m):
            A[i, j] = H[index[i], index[j]]
        A[i, i] += lam * A[i, i]
        b[i] = g[index[i]]
    x = np.linalg.solve(A, b)
    for i in range(m):
        dq[index[i]] = x[i]
    return dq


@numba.njit(**_JIT)
def _solve3(H: np.ndarray, g: np.ndarray) -> tuple[np.ndarray, bool]:
    """H^-1 g of a 3 x 3 system by Gaussian elimination with partial pivoting (LAPACK's
    gesv for n = 3); False when a pivot is exactly 0 (singular, where numpy raises)."""
    A = H.copy()
    b = g.copy()
    for col in range(3):
        pivot = col
        for row in range(col + 1, 3):
            if abs(A[row, col]) > abs(A[pivot, col]):
                pivot = row
        if A[pivot, col] == 0.0:
            return b, False
        if pivot != col:
            for k in range(3):
                A[col, k], A[pivot, k] = A[pivot, k], A[col, k]
            b[col], b[pivot] = b[pivot], b[col]
        for row in range(col + 1, 3):
            f = A[row, col] / A[col, col]
            for k in range(col, 3):
                A[row, k] -= f * A[col, k]
            b[row] -= f * b[col]
    x = np.empty(3)
    for row in range(2, -1, -1):
        acc = b[row]
        for k in range(row + 1, 3):
            acc -= A[row, k] * x[k]
        x[row] = acc / A[row, row]
    return x, True


@numba.njit(**_JIT)
def _pixel_depth(p: np.ndarray, dt: np.ndarray, R: np.ndarray, t: np.ndarray, f: np.ndarray,
                 c: np.ndarray) -> tuple[float, float, float]:
    """Pixel (x, y) and depth of point ``p + dt`` in a camera (a depth within 1e-9 of 0
    divides as 1e-9)."""
    pc = np.empty(3)
    for a in range(3):
        pc[a] = (R[a, 0] * (p[0] + dt[0]) + R[a, 1] * (p[1] + dt[1])
                 + R[a, 2] * (p[2] + dt[2])) + t[a]
    z = 1e-9 if abs(pc[2]) < 1e-9 else pc[2]
    return pc[0] / z * f[0] + c[0], pc[1] / z * f[1] + c[1], pc[2]


@numba.njit(**_JIT)
def translation_fit(p: np.ndarray, cam_R: np.ndarray, cam_t: np.ndarray, focal: np.ndarray,
                    centre: np.ndarray, target: np.ndarray, scale: np.ndarray,
                    reg: np.ndarray, min_depth_m: float, r_var_px2: float, outlier_px: float
                    ) -> tuple[np.ndarray, int]:
    """The wrist shift dt (3,) that best projects points ``p`` (K, 3) onto pixels ``target``
    (K, 2), each in its camera (``cam_R``, ``cam_t``, ``focal``, ``centre`` per point):
    weighted linear least squares on the cross-multiplied projection equations, regularised
    by ``reg`` (3, 3), refitted once without the points farther than ``outlier_px`` (in
    pixels over ``scale`` (K, 2); 0 = no refit) when at least 3 remain; with the outcome (0,
    :data:`SINGULAR`, :data:`BEHIND`: a point within ``min_depth_m`` of its camera's plane).
    ``projection.estimate_translation`` describes the weights."""
    k_rows = len(p)
    G = np.empty((k_rows, 2, 3))
    y = np.empty((k_rows, 2))
    w = np.empty((k_rows, 2))
    zero = np.zeros(3)
    for k in range(k_rows):
        R, t = cam_R[k], cam_t[k]
        _, _, depth = _pixel_depth(p[k], zero, R, t, focal[k], centre[k])
        for i in range(2):
            coef = (target[k, i] - centre[k, i]) / focal[k, i]
            acc = 0.0
            for j in range(3):
                G[k, i, j] = R[i, j] - coef * R[2, j]
                acc += G[k, i, j] * p[k, j]
            y[k, i] = -acc - (t[i] - coef * t[2])
            w[k, i] = (focal[k, i] / scale[k, i] / max(depth, min_depth_m)) ** 2 / r_var_px2
    keep = np.ones(k_rows, np.bool_)
    dt = np.zeros(3)
    for _ in range(2 if outlier_px > 0 else 1):
        H = reg.copy()
        g = np.zeros(3)
        for k in range(k_rows):
            if not keep[k]:
                continue
            for i in range(2):
                for a in range(3):
                    wa = G[k, i, a] * w[k, i]
                    g[a] += wa * y[k, i]
                    for b in range(3):
                        H[a, b] += wa * G[k, i, b]
        dt, solved = _solve3(H, g)
        if not solved:
            return dt, SINGULAR
        if outlier_px <= 0:
            break
        good = 0
        for k in range(k_rows):
            x_px, y_px, _ = _pixel_depth(p[k], dt, cam_R[k], cam_t[k], focal[k], centre[k])
            ex = (x_px - target[k, 0]) / scale[k, 0]
            ey = (y_px - target[k, 1]) / scale[k, 1]
            keep[k] = math.sqrt(ex * ex + ey * ey) <= outlier_px
            good += keep[k]
        if good == k_rows or good < 3:
            break
    for k in range(k_rows):
        _, _, depth = _pixel_depth(p[k], dt, cam_R[k], cam_t[k], focal[k], centre[k])
        if depth <= min_depth_m:
            return dt, BEHIND
    return dt, 0


@numba.njit(**_JIT)
def posed_elements(Rs: np.ndarray, ts: np.ndarray, frame: np.ndarray, centre: np.ndarray,
                   normal: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Centres (E, 3) and normals (E, 3) of link-fixed surface elements (``centre``,
    ``normal`` in the frames ``frame`` (E,)) in the primary camera frame, the frames being
    ``Rs``, ``ts`` (``FastKinematics.frames``)."""
    n = len(frame)
    c_out = np.empty((n, 3))
    n_out = np.empty((n, 3))
    for e in range(n):
        R, t = Rs[frame[e]], ts[frame[e]]
        for a in range(3):
            c_out[e, a] = (centre[e, 0] * R[a, 0] + centre[e, 1] * R[a, 1]
                           + centre[e, 2] * R[a, 2]) + t[a]
            n_out[e, a] = (normal[e, 0] * R[a, 0] + normal[e, 1] * R[a, 1]
                           + normal[e, 2] * R[a, 2])
    return c_out, n_out


@numba.njit(**_JIT)
def element_weights(centre: np.ndarray, normal: np.ndarray, cam_R: np.ndarray,
                    cam_t: np.ndarray, fx: float, fy: float, cell_m: float, depth_tol_m: float
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Surface elements (primary-frame ``centre``, ``normal`` (E, 3)) seen by a camera
    (rotation ``cam_R``, translation ``cam_t``, focal lengths ``fx``, ``fy``): centres in its
    frame (E, 3), projected-area weights (E,) (area x cosine toward the camera / depth^2; 0
    facing away) and the same with the elements hidden in a coarse depth buffer set to 0 (a
    front element is hidden when another front element in its cell, ``cell_m`` wide at the
    front elements' mean depth, is more than ``depth_tol_m`` nearer)."""
    n = len(centre)
    pc = np.empty((n, 3))
    w = np.empty(n)
    w_vis = np.zeros(n)
    front = np.zeros(n, np.bool_)
    z_sum, count = 0.0, 0
    for e in range(n):
        for a in range(3):
            pc[e, a] = (cam_R[a, 0] * centre[e, 0] + cam_R[a, 1] * centre[e, 1]
                        + cam_R[a, 2] * centre[e, 2]) + cam_t[a]
        nc0 = cam_R[0, 0] * normal[e, 0] + cam_R[0, 1] * normal[e, 1] + cam_R[0, 2] * normal[e, 2]
        nc1 = cam_R[1, 0] * normal[e, 0] + cam_R[1, 1] * normal[e, 1] + cam_R[1, 2] * normal[e, 2]
        nc2 = cam_R[2, 0] * normal[e, 0] + cam_R[2, 1] * normal[e, 1] + cam_R[2, 2] * normal[e, 2]
        x, y, z = pc[e, 0], pc[e, 1], pc[e, 2]
        dist = math.sqrt(x * x + y * y + z * z)
        depth = max(z, 1e-3)
        w[e] = max(-(nc0 * x + nc1 * y + nc2 * z), 0.0) / (dist * depth**2)
        if w[e] > 0 and z > 0:
            front[e] = True
            z_sum += z
            count += 1
    if count == 0:
        return pc, w, w_vis
    cell_px = cell_m / (z_sum / count)
    u = np.zeros(n, np.int64)
    v = np.zeros(n, np.int64)
    u_min, v_min, u_max, v_max = 2**62, 2**62, -2**62, -2**62
    for e in range(n):
        if front[e]:
            z = pc[e, 2]
            u[e] = int(math.floor(pc[e, 0] / z / cell_px * fx / fy))
            v[e] = int(math.floor(pc[e, 1] / z / cell_px))
            u_min, u_max = min(u_min, u[e]), max(u_max, u[e])
            v_min, v_max = min(v_min, v[e]), max(v_max, v[e])
    width = u_max - u_min + 1
    zbuf = np.full((v_max - v_min + 1) * width, np.inf)
    for e in range(n):
        if front[e]:
            cell = (v[e] - v_min) * width + (u[e] - u_min)
            u[e] = cell
            zbuf[cell] = min(zbuf[cell], pc[e, 2])
    for e in range(n):
        if front[e] and pc[e, 2] <= zbuf[u[e]] + depth_tol_m:
            w_vis[e] = w[e]
    return pc, w, w_vis


@numba.njit(**_JIT)
def patch_points(w: np.ndarray, w_vis: np.ndarray, elem_patch: np.ndarray, group: np.ndarray,
                 centre: np.ndarray, num_patches: int, group_link: np.ndarray,
                 table: np.ndarray, patch_id: np.ndarray, camera_index: np.ndarray,
                 min_visible_fraction: float, min_link_weight: float
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """``PatchSurface.points_by_camera`` after the element weights: the front weights ``w``
    and visible weights ``w_vis`` (C * E,) of the E elements (patch ``elem_patch``, patch-link
    group ``group``, link-frame ``centre``) in each of C cameras; per row k (patch
    ``patch_id[k]`` seen by camera ``camera_index[k]``, its groups ``table[patch_id[k]]``,
    -1 padded) the links (K, S), their weighted mean element centres (K, S, 3), the weights
    (K, S) and whether any of it faces the camera (K,). Sums run in element order, and over a
    row's S groups in order (numpy's ``bincount`` and, for S < 8, its row sums)."""
    ne, ng = len(elem_patch), len(group_link)
    nc = len(w) // ne
    front = np.zeros(nc * num_patches)
    vis = np.zeros(nc * num_patches)
    for i in range(nc * ne):
        p = (i // ne) * num_patches + elem_patch[i % ne]
        vis[p] += w_vis[i]
        front[p] += w[i]
    wg = np.zeros(nc * ng)
    acc = np.zeros((nc * ng, 3))
    for i in range(nc * ne):
        e = i % ne
        p = (i // ne) * num_patches + elem_patch[e]
        d = front[p] if front[p] >= 1e-300 or front[p] != front[p] else 1e-300
        we = w[i] if vis[p] / d < min_visible_fraction else w_vis[i]
        g = (i // ne) * ng + group[e]
        wg[g] += we
        for a in range(3):
            acc[g, a] += we * centre[e, a]
    k_rows, s_cols = len(patch_id), table.shape[1]
    link = np.empty((k_rows, s_cols), np.int64)
    point = np.empty((k_rows, s_cols, 3))
    weight = np.empty((k_rows, s_cols))
    seen = np.empty(k_rows, np.bool_)
    for k in range(k_rows):
        total = 0.0
        for s in range(s_cols):
            gid = table[patch_id[k], s]
            g = gid if gid >= 0 else 0
            gc = g + camera_index[k] * ng
            link[k, s] = group_link[g]
            d = wg[gc] if wg[gc] >= 1e-300 or wg[gc] != wg[gc] else 1e-300
            for a in range(3):
                point[k, s, a] = acc[gc, a] / d
            weight[k, s] = wg[gc] if gid >= 0 else 0.0
            total += weight[k, s]
        seen[k] = total > 0
        kept = 0.0
        for s in range(s_cols):
            weight[k, s] = weight[k, s] / (total if seen[k] else 1.0)
            if weight[k, s] < min_link_weight:
                weight[k, s] = 0.0
            kept += weight[k, s]
        for s in range(s_cols):
            weight[k, s] /= kept if seen[k] else 1.0
    return link, point, weight, seen


@numba.njit(**_JIT)
def patch_areas(pc: np.ndarray, w_vis: np.ndarray, elem_patch: np.ndarray, num_patches: int,
                fx: float, fy: float, cx: float, cy: float) -> tuple[np.ndarray, np.ndarray]:
    """``PatchSurface.visible_patches`` from a camera's element centres ``pc`` (E, 3) and
    visible weights ``w_vis`` (E,) (``element_weights``): each patch's visible area (P,
    pixels) and the undistorted pixel centroid of it (P, 2; NaN where none is visible),
    summed in element order."""
    area = np.zeros(num_patches)
    moment = np.zeros((num_patches, 2))
    scale = fx * fy
    for e in range(len(w_vis)):
        if w_vis[e] > 0:
            p = elem_patch[e]
            a = w_vis[e] * scale
            area[p] += a
            moment[p, 0] += a * (pc[e, 0] / pc[e, 2] * fx + cx)
            moment[p, 1] += a * (pc[e, 1] / pc[e, 2] * fy + cy)
    centroid = np.full((num_patches, 2), np.nan)
    for p in range(num_patches):
        if area[p] > 0:
            centroid[p, 0] = moment[p, 0] / area[p]
            centroid[p, 1] = moment[p, 1] / area[p]
    return area, centroid


def _array(dtype: object, ndim: int) -> object:
    """A read-only C-contiguous array type (writable arrays convert to it)."""
    return numba.types.Array(dtype, ndim, 'C', readonly=True)


_F1, _F2, _F3 = (_array(numba.float64, n) for n in (1, 2, 3))
_I1, _I2 = (_array(numba.int64, n) for n in (1, 2))
_KINEMATIC = (_F3, _F2, _F2, _F2, _F2, _I1, numba.int64)
_SIGNATURES = {
    forward_frames: (_F1, _F1, _F3, _F3, _F3, _F2, _I1),
    link_points: (*_KINEMATIC, _I1, _F2, numba.boolean),
    projected_rows: (*_KINEMATIC, _I2, _F3, _F2, _F3, _F2, _F2, _F2, numba.boolean),
    prior_cost: (_F1, _F1, _F1, _F1, _F1, _F1, _F1, numba.boolean),
    normal_equations: (_F2, _F1, _F1, _F1, _F1, _F1, _F1, _F1, numba.boolean, _F1, _F1),
    damped_step: (_F2, _F1, _array(numba.boolean, 1), numba.float64),
    translation_fit: (_F2, _F3, _F2, _F2, _F2, _F2, _F2, _F2, numba.float64, numba.float64,
                      numba.float64),
    posed_elements: (_F3, _F2, _I1, _F2, _F2),
    element_weights: (_F2, _F2, _F2, _F1, numba.float64, numba.float64, numba.float64,
                      numba.float64),
    patch_points: (_F1, _F1, _I1, _I1, _F2, numba.int64, _I1, _I2, _I1, _I1, numba.float64,
                   numba.float64),
    patch_areas: (_F2, _F1, _I1, numba.int64, numba.float64, numba.float64, numba.float64,
                  numba.float64),
}


def compile_kernels() -> float:
    """Compile every kernel for the one signature the tracker calls it with (or load it from
    numba's on-disk cache) and allow no other, so no frame pays for a compilation (and an
    argument of another type or layout raises rather than compiles); returns the seconds it
    took (about none once done in this process)."""
    return compile_signatures(_SIGNATURES)
