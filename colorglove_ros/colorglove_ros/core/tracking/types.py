"""Data types of the tracker: measured blobs, camera observations, the lookup prior (with the
entry's ``core.lookup.types.ProjectionConstraints``) and matched correspondences (numpy and
dataclasses only, light to import: the ROS message adapters use them)."""
from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from functools import cached_property
from typing import Any, Protocol

import numpy as np

from colorglove_ros.core.errors import ColorGloveError
from colorglove_ros.core.hand.model import NUM_DOFS
from colorglove_ros.core.lookup.types import ProjectionConstraints
from colorglove_ros.core.validation import as_rows

__all__ = [
    'IKError', 'Blobs', 'CameraObservation', 'PosePrior',
    'Correspondences', 'MeshLike', 'VertexTable',
]


class IKError(ColorGloveError):
    """Invalid input to the inverse kinematics (shapes, cameras, model mismatch)."""


@dataclass(frozen=True)
class Blobs:
    """Measured glove blobs of one camera image: colour (1..10), centroid in full-image
    pixels (x, y, as measured, i.e. still distorted) and pixel count."""

    color: np.ndarray
    centroid_px: np.ndarray
    pixel_count: np.ndarray

    def __post_init__(self) -> None:
        object.__setattr__(self, 'color', as_rows('color', self.color, np.int64, (), IKError))
        object.__setattr__(self, 'centroid_px',
                           as_rows('centroid', self.centroid_px, float, (2,), IKError))
        object.__setattr__(self, 'pixel_count',
                           as_rows('pixel_count', self.pixel_count, float, (), IKError))
        if not len(self.color) == len(self.centroid_px) == len(self.pixel_count):
            raise IKError('Blobs arrays must all have the same length')

    def __len__(self) -> int:
        return len(self.color)

    @classmethod
    def empty(cls) -> Blobs:
        """No blob."""
        return cls(np.zeros(0, np.int64), np.zeros((0, 2)), np.zeros(0))


@dataclass(frozen=True)
class CameraObservation:
    """What one camera saw in a frame: whether the glove was found, its blobs, and (for
    the primary camera) the crop transform tiny -> full image of the lookup query."""

    hand_found: bool
    blobs: Blobs = field(default_factory=Blobs.empty)
    crop: Any = None    # core.segmentation.crop.CropTransform (scale, offset_x, offset_y)
    cut_by_border: bool = False   # the glove reaches the image border (depth from the crop
    #                               size is unreliable)
    edge_image: Any = None   # (H, W) image the optional line features are measured on (the
    #                          glove mask), None without


@dataclass(frozen=True)
class PosePrior:
    """The lookup result the IK starts from: blended pose and the nearest entry's
    projection constraints."""

    q_blend: np.ndarray
    constraints: ProjectionConstraints
    finger_std: np.ndarray | None = None    # (20,) spread of the neighbours' fingers (rad)
    image_distance: float = math.nan        # the nearest entry's image distance (tiny px)

    @classmethod
    def from_lookup(cls, result: Any) -> PosePrior:
        """From a ``core.lookup.types.LookupResult`` (``blended`` and ``constraints`` with
        ``patch_ids, colors, vertices, tiny_xy, pixel_counts``; ``finger_std`` if any)."""
        try:
            c = result.constraints
            cons = c if isinstance(c, ProjectionConstraints) else ProjectionConstraints(
                c.patch_ids, c.colors, c.vertices, c.tiny_xy, c.pixel_counts)
            q_blend = np.asarray(result.blended, dtype=float)
        except AttributeError as exc:
            raise IKError(f'not a lookup result: {exc}') from exc
        if q_blend.shape != (NUM_DOFS,):
            raise IKError(f'blended pose must have shape (26,), got {q_blend.shape}')
        spread = getattr(result, 'finger_std', None)
        distances = np.asarray(getattr(result, 'distances', ()), dtype=float).reshape(-1)
        return cls(q_blend, cons, None if spread is None else np.asarray(spread, float),
                   float(distances[0]) if len(distances) else math.nan)


@dataclass(frozen=True)
class Correspondences:
    """Matched constraints over all cameras: camera index, the constrained point, the
    undistorted target pixel, patch id and the database's constraint vertex.

    The constrained point of row k is the weighted mean of S link-fixed points
    (``link[k, s]``, ``local[k, s]`` in that link's frame, ``weight[k, s]`` summing to 1):
    one vertex (S = 1), or the visible part of a glove patch spread over several links
    (:class:`PatchSurface`). 1-D ``link`` and (K, 3) ``local`` mean S = 1."""

    camera: np.ndarray
    link: np.ndarray
    local: np.ndarray
    target_px: np.ndarray
    patch_id: np.ndarray
    vertex: np.ndarray
    weight: np.ndarray | None = None

    def __post_init__(self) -> None:
        link = np.asarray(self.link, np.int64)
        local = np.asarray(self.local, float)
        if link.ndim == 1:
            link, local = link[:, None], local.reshape(-1, 1, 3)
        weight = (np.ones(link.shape) if self.weight is None
                  else np.asarray(self.weight, float))
        if local.shape != (*link.shape, 3) or weight.shape != link.shape \
                or len(link) != len(self.camera):
            raise IKError(f'correspondence points: link {link.shape}, local {local.shape}, '
                          f'weight {weight.shape} for {len(self.camera)} rows')
        object.__setattr__(self, 'link', link)
        object.__setattr__(self, 'local', local)
        object.__setattr__(self, 'weight', weight)

    def __len__(self) -> int:
        return len(self.camera)

    @classmethod
    def empty(cls) -> Correspondences:
        """No correspondence."""
        z = np.zeros(0, np.int64)
        return cls(z, z, np.zeros((0, 3)), np.zeros((0, 2)), z, z)

    @classmethod
    def concat(cls, items: Sequence[Correspondences]) -> Correspondences:
        """Join several sets (e.g. one per camera); point lists are padded with zero weights
        to the longest."""
        items = [c for c in items if len(c)]
        if not items:
            return cls.empty()
        s = max(c.link.shape[1] for c in items)
        k = sum(len(c) for c in items)
        link, local, weight = np.zeros((k, s), np.int64), np.zeros((k, s, 3)), np.zeros((k, s))
        row = 0
        for c in items:
            n, m = c.link.shape
            link[row:row + n, :m], local[row:row + n, :m] = c.link, c.local
            weight[row:row + n, :m] = c.weight
            row += n
        cat = {key: np.concatenate([getattr(c, key) for c in items])
               for key in ('camera', 'target_px', 'patch_id', 'vertex')}
        return cls(cat['camera'], link, local, cat['target_px'], cat['patch_id'], cat['vertex'],
                   weight)

    def select(self, mask: np.ndarray) -> Correspondences:
        """The subset picked by a boolean mask or index array."""
        return Correspondences(self.camera[mask], self.link[mask], self.local[mask],
                               self.target_px[mask], self.patch_id[mask], self.vertex[mask],
                               self.weight[mask])

    @cached_property
    def point_mix(self) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
        """The points of non-zero weight (links (M,), link-frame points (M, 3)) and the
        (K, M) matrix averaging them into the rows (None when every row is one point)."""
        if self.link.shape[1] == 1:
            return self.link[:, 0], self.local[:, 0], None
        rows, cols = np.nonzero(self.weight)
        mix = np.zeros((len(self), len(rows)))
        mix[rows, np.arange(len(rows))] = self.weight[rows, cols]
        return self.link[rows, cols], self.local[rows, cols], mix

    @cached_property
    def point_slots(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """C-contiguous links (K, S), link-frame points (K, S, 3) and weights (K, S) of the
        rows' points as :attr:`point_mix` mixes them (weights of one when S = 1), for the
        compiled projection (``ik_kernel.projected_rows``)."""
        weight = np.ones(self.link.shape) if self.link.shape[1] == 1 else self.weight
        return (np.ascontiguousarray(self.link), np.ascontiguousarray(self.local),
                np.ascontiguousarray(weight))

    def same_as(self, other: Correspondences) -> bool:
        """True if both hold the same (camera, patch, target) triples in the same order."""
        return (len(self) == len(other) and np.array_equal(self.camera, other.camera)
                and np.array_equal(self.patch_id, other.patch_id)
                and np.array_equal(self.target_px, other.target_px))

    def counts(self, num_cameras: int) -> tuple[int, ...]:
        """Number of correspondences per camera."""
        return tuple(int(v) for v in np.bincount(self.camera, minlength=num_cameras))


class MeshLike(Protocol):
    """What the tracker needs from ``core.hand.mesh.HandMesh``."""

    vertex_link: np.ndarray
    local_vertices: np.ndarray


@dataclass(frozen=True)
class VertexTable:
    """Minimal :class:`MeshLike`: link index and link-frame position per vertex."""

    vertex_link: np.ndarray
    local_vertices: np.ndarray
