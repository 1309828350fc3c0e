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
    d = np.asarray(distances, np.float64)
    sigma = float(d.mean())
    if sigma <= 0.0:
        return np.full(len(d), 1.0 / len(d))
    w = np.exp(-(d / sigma) ** 2)
    return w / w.sum()


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
