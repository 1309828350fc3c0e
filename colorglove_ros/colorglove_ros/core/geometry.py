"""Rotation conversions: skew matrices, rotation vectors, rotation matrices, quaternions and the
SO(3) left Jacobian, written once for the hand model, the lookup blend, the tracker and the ROS
message fields.

Conventions (all functions):

* a rotation vector ``r`` (..., 3) is ``angle * unit axis`` (right-handed, radians);
* a rotation matrix ``R`` (..., 3, 3) acts on column vectors, ``x' = R @ x``;
* a quaternion is ``(x, y, z, w)`` (scalar last, as ``geometry_msgs/Quaternion`` and scipy);
  functions that return one return a unit quaternion, functions that read one accept any
  norm and either sign;
* the SO(3) left Jacobian ``J_l(r)`` satisfies ``exp(r + d) ~ exp(J_l(r) d) exp(r)`` for small
  ``d``.

Plain numpy; scipy is imported only by :func:`matrix_to_rotvec`, on first use.
"""
from __future__ import annotations

import math

import numpy as np

from colorglove_ros.core.errors import ColorGloveError

__all__ = [
    'GeometryError', 'vector_to_skew', 'rotvec_to_matrix', 'matrix_to_rotvec', 'so3_left_jacobian',
    'rotvec_to_quaternion', 'quaternion_to_rotvec',
    'align_rotation_vector',
]


class GeometryError(ColorGloveError, ValueError):
    """A rotation input that represents no rotation (the zero quaternion)."""


def vector_to_skew(v: np.ndarray) -> np.ndarray:
    """(..., 3) vectors -> (..., 3, 3) cross-product matrices ``[v]_x`` (``[v]_x @ u = v x u``)."""
    v = np.asarray(v, dtype=float)
    K = np.zeros(v.shape[:-1] + (3, 3))
    K[..., 0, 1] = -v[..., 2]
    K[..., 0, 2] = v[..., 1]
    K[..., 1, 0] = v[..., 2]
    K[..., 1, 2] = -v[..., 0]
    K[..., 2, 0] = -v[..., 1]
    K[..., 2, 1] = v[..., 0]
    return K


def rotvec_to_matrix(r: np.ndarray) -> np.ndarray:
    """Rodrigues: (..., 3) rotation vectors -> (..., 3, 3) rotation matrices (Taylor terms
    below an angle of 1e-6 rad)."""
    r = np.asarray(r, dtype=float)
    theta = np.linalg.norm(r, axis=-1)[..., None, None]
    K = vector_to_skew(r)
    small = theta < 1e-6
    safe = np.where(small, 1.0, theta)
    a = np.where(small, 1.0 - theta**2 / 6.0, np.sin(safe) / safe)
    b = np.where(small, 0.5 - theta**2 / 24.0, (1.0 - np.cos(safe)) / safe**2)
    return np.eye(3) + a * K + b * (K @ K)


def matrix_to_rotvec(R: np.ndarray) -> np.ndarray:
    """(..., 3, 3) rotation matrices -> (..., 3) rotation vectors with angle in [0, pi]."""
    from scipy.spatial.transform import Rotation

    R = np.asarray(R, dtype=float)
    flat = Rotation.from_matrix(R.reshape(-1, 3, 3)).as_rotvec()
    return flat.reshape(R.shape[:-2] + (3,))


def so3_left_jacobian(r: np.ndarray) -> np.ndarray:
    """Left Jacobian (3, 3) of SO(3) at one rotation vector r (3,) (Taylor terms below an angle
    of 1e-5 rad)."""
    r = np.asarray(r, dtype=float)
    theta = float(np.linalg.norm(r))
    K = vector_to_skew(r)
    if theta < 1e-5:
        a = 0.5 - theta**2 / 24.0
        b = 1.0 / 6.0 - theta**2 / 120.0
    else:
        a = (1.0 - np.cos(theta)) / theta**2
        b = (theta - np.sin(theta)) / theta**3
    return np.eye(3) + a * K + b * (K @ K)


def rotvec_to_quaternion(r: np.ndarray) -> np.ndarray:
    """(..., 3) rotation vectors -> (..., 4) unit quaternions (x, y, z, w), w >= 0 for angles up
    to pi."""
    r = np.asarray(r, dtype=float)
    rv = r.reshape(-1, 3)
    angle = np.sqrt(np.einsum('ij,ij->i', rv, rv))
    half = 0.5 * angle
    k = np.sin(half)
    small = angle <= 1e-8
    np.divide(k, angle, out=k, where=~small)
    k[small] = 0.5            # sin(a/2)/a = 1/2 - a^2/48 + ...: exactly 1/2 in doubles here
    out = np.empty((len(rv), 4))
    np.multiply(rv, k[:, None], out=out[:, :3])
    np.cos(half, out=out[:, 3])
    return out.reshape(r.shape[:-1] + (4,))


def quaternion_to_rotvec(q: np.ndarray) -> np.ndarray:
    """One quaternion (x, y, z, w) of any sign and non-zero norm -> rotation vector (3,) with
    angle in [0, pi]."""
    x, y, z, w = np.asarray(q, np.float64).reshape(4).tolist()
    if w < 0.0:
        x, y, z, w = -x, -y, -z, -w
    s = math.sqrt(x * x + y * y + z * z)
    norm = math.hypot(s, w)
    if norm == 0.0:
        raise GeometryError('the zero quaternion is no rotation')
    if s < 1e-12 * norm:
        f = 2.0 / norm
    else:
        f = 2.0 * math.atan2(s, w) / s
    return np.array([x * f, y * f, z * f])


def align_rotation_vector(r: np.ndarray, ref: np.ndarray) -> np.ndarray:
    """The rotation vector equivalent to ``r`` (angle +- 2 pi along its axis) closest to
    ``ref``, so that differences such as ``q_b - q`` stay small across the pi wrap."""
    r = np.asarray(r, dtype=float)
    theta = float(np.linalg.norm(r))
    if theta < 1e-9:
        return r.copy()
    axis = r / theta
    cands = [axis * (theta + 2.0 * math.pi * k) for k in (-1, 0, 1)]
    return min(cands, key=lambda c: float(np.sum((c - ref) ** 2)))
