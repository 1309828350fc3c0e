"""Temporal lookup prior: reweight the lookup's neighbours by their distance to the last pose."""
from __future__ import annotations

import dataclasses
import math

import numpy as np

from colorglove_ros.core.errors import ColorGloveError
from colorglove_ros.core.geometry import rotvec_to_matrix
from colorglove_ros.core.hand.model import NUM_DOFS
from colorglove_ros.core.lookup.blend import blend_poses
from colorglove_ros.core.lookup.types import LookupResult

__all__ = ['TemporalPriorError', 'pose_distances_rad', 'reweight_by_previous']


class TemporalPriorError(ColorGloveError):
    """Bad temporal-prior input (pose shape, tau, rotation weight)."""


def pose_distances_rad(poses: np.ndarray, q_ref: np.ndarray,
                       rotation_weight: float = 1.0) -> np.ndarray:
    """Distances (k,) of poses (k, 26) to ``q_ref`` (26,):
    sqrt(|finger DOFs - ref|^2 + rotation_weight * angle^2), with ``angle`` the geodesic
    angle (rad, in [0, pi]) between the wrist rotations; the wrist translation is ignored
    (the lookup places every neighbour's wrist from the same image)."""
    poses = np.asarray(poses, np.float64)
    q_ref = np.asarray(q_ref, np.float64)
    if poses.ndim != 2 or poses.shape[1] != NUM_DOFS or q_ref.shape != (NUM_DOFS,):
        raise TemporalPriorError(f'need poses (k, {NUM_DOFS}) and a reference ({NUM_DOFS},), '
                                 f'got {poses.shape} and {q_ref.shape}')
    fingers = ((poses[:, 6:] - q_ref[6:]) ** 2).sum(axis=1)
    # |R_i - R_ref|_F = 2 sqrt(2) sin(angle / 2): well conditioned at 0 and pi alike
    chord = np.linalg.norm(rotvec_to_matrix(poses[:, 3:6]) - rotvec_to_matrix(q_ref[3:6]),
                           axis=(1, 2))
    angle = 2.0 * np.arcsin(np.clip(chord / (2.0 * math.sqrt(2.0)), 0.0, 1.0))
    return np.sqrt(fingers + rotation_weight * angle ** 2)


def reweight_by_previous(result: LookupResult, q_prev: np.ndarray | None, tau_rad: float,
                         rotation_weight: float = 1.0) -> LookupResult:
    """A copy of ``result`` whose blend weights are the image weights times
    exp(-d_i^2 / tau^2), d_i = :func:`pose_distances_rad` of neighbour i to the previous
    output pose ``q_prev``, and whose blended pose is :func:`blend.blend_poses` of the
    neighbours with those weights. ``result`` itself when ``q_prev`` is None (no previous
    frame: first frame, or the tracker was reset). Neighbour order, distances and projection
    constraints (of the nearest image) are kept."""
    if not tau_rad > 0.0 or not math.isfinite(tau_rad):
        raise TemporalPriorError(f'tau must be a positive finite angle (rad), got {tau_rad}')
    if not rotation_weight >= 0.0 or not math.isfinite(rotation_weight):
        raise TemporalPriorError(f'rotation weight must be >= 0, got {rotation_weight}')
    if q_prev is None:
        return result
    d = pose_distances_rad(result.poses, q_prev, rotation_weight)
    with np.errstate(divide='ignore'):
        log_w = np.log(np.asarray(result.weights, np.float64)) - (d / tau_rad) ** 2
    if not np.isfinite(log_w).any():
        raise TemporalPriorError('the lookup result has no positive image weight')
    w = np.exp(log_w - log_w.max())     # in log space: far neighbours do not underflow all
    w /= w.sum()
    return dataclasses.replace(result, weights=w, blended=blend_poses(result.poses, w))
