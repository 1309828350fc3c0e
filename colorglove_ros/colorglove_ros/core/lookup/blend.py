"""Blend the nearest database poses into one (paper section 4.5, eq. 1): Gaussian weights of the
image distances; translation and finger DOFs averaged linearly, the global rotation as the
weighted quaternion mean."""
from __future__ import annotations

import numpy as np

from colorglove_ros.core.geometry import quaternion_to_rotvec, rotvec_to_quaternion

__all__ = ['blend_weights', 'blend_poses', 'blend_poses_with_quaternions']


def blend_weights(distances: np.ndarray) -> np.ndarray:
    """Normalised weights exp(-d^2 / sigma^2) with sigma = mean distance (paper eq. 1); if all
    distances are zero the weights are equal."""
    from colorglove_ros.core.lookup import lookup_kernel

    d = np.ascontiguousarray(distances, np.float64)
    flat = d.reshape(-1)
    if not len(flat):
        return np.empty(d.shape)
    lookup_kernel.compile_kernels()
    w = np.empty(len(flat))
    # the mean, sums and powers in numpy's order, exp by numpy
    if lookup_kernel.gaussian_exponents(flat, w) <= 0.0:
        return np.full(len(d), 1.0 / len(d))
    np.exp(w, out=w)
    lookup_kernel.divide_by_sum(w)
    return w.reshape(d.shape)


def blend_poses(poses: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """Weighted blend of (k, 26) poses: translation and finger DOFs linearly, the global
    rotation as the weighted quaternion mean (Markley), returned as a rotation vector."""
    poses = np.asarray(poses, np.float64)
    return blend_poses_with_quaternions(poses, rotvec_to_quaternion(poses[:, 3:6]),
                                        np.asarray(weights, np.float64))


def blend_poses_with_quaternions(poses: np.ndarray, quats: np.ndarray, weights: np.ndarray
                                 ) -> np.ndarray:
    """:func:`blend_poses` with the rotations also given as quaternions (k, 4)."""
    out = weights @ poses
    out[3:6] = quaternion_to_rotvec(_quat_mean(quats, weights))
    return out


def _quat_mean(quats: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """Weighted quaternion mean (Markley et al. 2007): principal eigenvector of sum w q q^T."""
    m = (quats * weights[:, None]).T @ quats
    _, vecs = np.linalg.eigh(m)
    return vecs[:, -1]
