"""Data types of a lookup result (numpy and dataclasses only, light to import: the ROS message
adapters use them)."""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from colorglove_ros.core.validation import InvalidPriorError, as_rows

__all__ = ['ProjectionConstraints', 'LookupResult', 'Neighbours']


@dataclass(frozen=True)
class ProjectionConstraints:
    """Projection constraints of a database entry's visible patches, what the lookup hands
    the inverse kinematics: per patch its id, glove colour, the mesh vertex nearest its
    centroid, the centroid in the entry's tiny image and its area.

    ``full_xy`` is the same centroid mapped into the query's full image with the query's
    crop transform (set by the lookup; None where the constraints came without it, e.g. from
    a message: the tracker maps ``tiny_xy`` itself). Arrays are converted on construction;
    :class:`~colorglove_ros.core.validation.InvalidPriorError` if shapes or lengths differ."""

    patch_ids: np.ndarray     # (M,) int64 patch 0..19
    colors: np.ndarray        # (M,) int64 glove colour label 1..10
    vertices: np.ndarray      # (M,) int64 mesh vertex nearest the patch centroid
    tiny_xy: np.ndarray       # (M, 2) float, centroid in tiny-image pixels (x, y)
    pixel_counts: np.ndarray  # (M,) float, patch area in tiny-image pixels
    full_xy: np.ndarray | None = None   # (M, 2) float, centroid in full-image pixels

    def __post_init__(self) -> None:
        def rows(name: str, dtype: type, tail: tuple[int, ...] = ()) -> None:
            object.__setattr__(self, name, as_rows(name, getattr(self, name), dtype, tail,
                                                   InvalidPriorError))

        rows('patch_ids', np.int64)
        rows('colors', np.int64)
        rows('vertices', np.int64)
        rows('tiny_xy', float, (2,))
        rows('pixel_counts', float)
        arrays = [self.colors, self.vertices, self.tiny_xy, self.pixel_counts]
        if self.full_xy is not None:
            rows('full_xy', float, (2,))
            arrays.append(self.full_xy)
        if not all(len(a) == len(self.patch_ids) for a in arrays):
            raise InvalidPriorError('ProjectionConstraints arrays must all have the same length')

    def __len__(self) -> int:
        return len(self.patch_ids)


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
    # were blended per finger from the observed blobs (core.lookup.finger_evidence); else None
    finger_std: np.ndarray | None = None


@dataclass(frozen=True)
class Neighbours:
    """The re-ranked candidates of one query, before their poses are blended
    (``PoseLookup.search``; ``PoseLookup.blend`` makes the :class:`LookupResult`): database
    entries and their exact image distances (px), the query's crop (scale, offset_x,
    offset_y) and the search's timings."""

    candidates: np.ndarray      # (n,) database entries re-ranked (top by Hamming, ties kept)
    distances: np.ndarray       # (n,) their image distances (px), in the same order
    crop: tuple[float, float, float]
    timings_ms: dict[str, float] = field(default_factory=dict)

    @property
    def nearest(self) -> float:
        """The nearest candidate's image distance (the result's ``distances[0]``; inf when
        there is none)."""
        return float(self.distances.min()) if len(self.distances) else float('inf')
