"""Data types of a lookup result (numpy and dataclasses only, light to import: the ROS message
adapters use them)."""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

__all__ = ['ProjectionConstraints', 'LookupResult']


@dataclass(frozen=True)
class ProjectionConstraints:
    """Visible patches of the nearest database entry, for inverse kinematics.

    ``tiny_xy`` are patch centroids in tiny-image pixels and ``full_xy`` the same points
    mapped into the query's full image with the query's crop transform."""

    patch_ids: np.ndarray     # (M,) int
    colors: np.ndarray        # (M,) uint8 glove colour label 1..10
    vertices: np.ndarray      # (M,) int mesh vertex nearest the patch centroid
    tiny_xy: np.ndarray       # (M, 2) float
    full_xy: np.ndarray       # (M, 2) float
    pixel_counts: np.ndarray  # (M,) float, patch area in tiny-image pixels


@dataclass(frozen=True)
class LookupResult:
    """Outcome of one lookup. The neighbour arrays are sorted by image distance."""

    indices: np.ndarray         # (k,) database entries blended
    distances: np.ndarray       # (k,) image distances (px)
    weights: np.ndarray         # (k,) normalised blend weights
    poses: np.ndarray           # (k, 26) neighbour poses, wrist moved to the query
    #                             (estimate_global_pose)
    blended: np.ndarray         # (26,) blended pose q_b
    constraints: ProjectionConstraints
    num_candidates: int         # entries re-ranked (top by Hamming, ties kept)
    timings_ms: dict[str, float] = field(default_factory=dict)
    # (20,) weighted spread (rad) of each finger DOF over the neighbours when the fingers
    # were blended per finger from the observed blobs (core.finger_evidence); else None
    finger_std: np.ndarray | None = None
