"""Features of what the tracker saw in one frame, for a classifier of hand shapes that reads
the image evidence beside the fitted pose.

The observation is the primary camera's tiny label image (40 x 40, colour labels 1..10, 0
background; ``core/segmentation/crop.py``) and its glove blobs in the tiny image's pixel frame
(``core/evaluation/sequences.py`` ``record_observation``). Features (:func:`observation_features`),
all in the glove's own frame (centred on the tiny image's glove pixels, over their RMS radius),
so scale-free:

- a per-colour map: the share of each cell of a ``GRID`` x ``GRID`` grid over the tiny image
  held by each glove colour (10 x GRID x GRID);
- the ``BLOBS_PER_COLOR`` largest blobs of each colour: whether there is one, its share of the
  frame's blob pixels, and its centroid relative to the glove's centre (x, y).

The upright variant (:data:`OBSERVATION_UPRIGHT_FEATURES`) takes the view's in-plane angle
out: the glove-centred pixel and blob positions are turned by the fitted pose's in-plane angle
(:func:`image_angle`: the direction the fingers point, projected on the image) so the fingers
point along +x, and the colour map's grid spans :data:`UPRIGHT_EXTENT` RMS radii either side of
the glove's centre (cell shares of the glove's pixels). Gestures are held at any roll, which
moves the plain features more than the shape does.

Each glove colour is printed on two patches, so a colour's largest blobs name the patches that
show most; where the thumb's patches lie relative to the fingers' is what tells E, M, N, S and
T apart when the fitted pose puts the thumb elsewhere.
"""
from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from colorglove_ros.core.conventions import NUM_COLORS, TINY_SIZE
from colorglove_ros.core.errors import ColorGloveError
from colorglove_ros.core.geometry import rotvec_to_matrix

__all__ = ['GRID', 'BLOBS_PER_COLOR', 'OBSERVATION_FEATURES', 'OBSERVATION_UPRIGHT_FEATURES',
           'IMAGE_FEATURE_SETS', 'UPRIGHT_EXTENT', 'image_angle', 'feature_set_features',
           'RECORD_FIELDS',
           'MAX_RECORDED_BLOBS', 'ObservationError', 'empty_observation_record',
           'write_observation', 'observation_features', 'record_features', 'frame_features',
           'num_observation_features']

GRID = 5
BLOBS_PER_COLOR = 2
OBSERVATION_FEATURES = 'tiny_observation'   # the feature set's name in classifier files
# the same turned so the fitted pose's fingers point along the x axis (a pose is needed)
OBSERVATION_UPRIGHT_FEATURES = 'tiny_observation_upright'
IMAGE_FEATURE_SETS: tuple[str, ...] = (OBSERVATION_FEATURES, OBSERVATION_UPRIGHT_FEATURES)
UPRIGHT_EXTENT = 2.0     # the upright colour map's half side, in RMS radii of the glove
# the arrays of an observation record (:func:`empty_observation_record`), in the order
# :func:`observation_features` takes them
RECORD_FIELDS = ('tiny_labels', 'blob_color', 'blob_tiny_xy', 'blob_tiny_pixels')
# blobs a record keeps per frame (the largest; colour 0 pads the rows past a frame's blobs)
MAX_RECORDED_BLOBS = 40


class ObservationError(ColorGloveError, ValueError):
    """Observation arrays of inconsistent shapes."""


def empty_observation_record(n: int) -> dict[str, np.ndarray]:
    """The observation record of ``n`` frames with nothing seen: ``tiny_labels`` (n, 40, 40)
    uint8, ``blob_color`` (n, B) int, ``blob_tiny_xy`` (n, B, 2) and ``blob_tiny_pixels``
    (n, B) (the blob's pixel count in tiny-image pixels, i.e. over the crop scale squared)."""
    b = MAX_RECORDED_BLOBS
    return {'tiny_labels': np.zeros((n, TINY_SIZE, TINY_SIZE), np.uint8),
            'blob_color': np.zeros((n, b), np.int64),
            'blob_tiny_xy': np.full((n, b, 2), np.nan),
            'blob_tiny_pixels': np.zeros((n, b))}


def write_observation(record: dict[str, np.ndarray], i: int, tiny_labels: np.ndarray,
                      transform: Any, blobs: Any) -> None:
    """Frame ``i`` of ``record``: the tiny label image (40, 40), and the full image's blobs
    (``tracking.types.Blobs``) mapped into the tiny image by the crop ``transform``
    (``segmentation.crop.CropTransform``), the largest :data:`MAX_RECORDED_BLOBS`."""
    record['tiny_labels'][i] = np.asarray(tiny_labels, np.uint8)
    keep = np.argsort(-np.asarray(blobs.pixel_count), kind='stable')[:MAX_RECORDED_BLOBS]
    k = len(keep)
    record['blob_color'][i, :k] = blobs.color[keep]
    record['blob_tiny_xy'][i, :k] = transform.to_tiny(blobs.centroid_px[keep])
    record['blob_tiny_pixels'][i, :k] = blobs.pixel_count[keep] / float(transform.scale) ** 2


def frame_features(tiny_labels: np.ndarray, transform: Any, blobs: Any) -> np.ndarray:
    """(F,) features of one frame's observation (as :func:`write_observation` takes it)."""
    record = empty_observation_record(1)
    write_observation(record, 0, tiny_labels, transform, blobs)
    return record_features(record)[0]


def num_observation_features() -> int:
    """The length F of one frame's features."""
    return NUM_COLORS * GRID * GRID + NUM_COLORS * BLOBS_PER_COLOR * 4


def _colour_maps(tiny: np.ndarray) -> np.ndarray:
    """(N, 10 * GRID * GRID) share of each grid cell held by each colour."""
    n, h, w = tiny.shape
    cells = GRID * GRID
    rows = np.minimum(np.arange(h) * GRID // h, GRID - 1)
    cols = np.minimum(np.arange(w) * GRID // w, GRID - 1)
    cell = (rows[:, None] * GRID + cols[None, :]).ravel()
    cell_size = np.bincount(cell, minlength=cells).astype(float)
    labels = tiny.reshape(n, -1).astype(np.int64)
    # one count of (frame, colour, cell) triples; labels outside 1..NUM_COLORS count nowhere
    glove = (labels >= 1) & (labels <= NUM_COLORS)
    frame = np.broadcast_to(np.arange(n)[:, None], labels.shape)
    slot = ((frame * NUM_COLORS + labels - 1) * cells + cell[None, :])[glove]
    out = np.bincount(slot, minlength=n * NUM_COLORS * cells).astype(float)
    return (out.reshape(n, NUM_COLORS, cells) / cell_size).reshape(n, -1)


def _glove_frame(tiny: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Centre (N, 2) (x, y) and RMS radius (N,) of each tiny image's glove pixels (the image's
    centre and a quarter of its side where there is none)."""
    n, h, w = tiny.shape
    ys, xs = np.mgrid[0:h, 0:w]
    mask = (tiny > 0).reshape(n, -1).astype(float)
    count = mask.sum(axis=1)
    safe = np.maximum(count, 1.0)
    cx = mask @ xs.ravel() / safe
    cy = mask @ ys.ravel() / safe
    r2 = (mask * ((xs.ravel()[None] - cx[:, None]) ** 2 + (ys.ravel()[None] - cy[:, None]) ** 2)
          ).sum(axis=1) / safe
    radius = np.sqrt(r2)
    empty = (count == 0) | (radius < 1e-6)
    cx[empty], cy[empty] = 0.5 * (w - 1), 0.5 * (h - 1)
    radius[empty] = 0.25 * w
    return np.stack([cx, cy], axis=1), radius


def _blob_features(color: np.ndarray, xy: np.ndarray, pixels: np.ndarray, centre: np.ndarray,
                   radius: np.ndarray) -> np.ndarray:
    """(N, 10 * BLOBS_PER_COLOR * 4) per colour's largest blobs: seen, pixel share, x, y."""
    n = len(color)
    total = np.maximum(np.where(color > 0, pixels, 0.0).sum(axis=1), 1e-9)
    out = np.zeros((n, NUM_COLORS, BLOBS_PER_COLOR, 4))
    for i in range(n):
        for k in range(1, NUM_COLORS + 1):
            mine = np.flatnonzero(color[i] == k)
            mine = mine[np.argsort(-pixels[i, mine], kind='stable')][:BLOBS_PER_COLOR]
            for j, b in enumerate(mine):
                rel = (xy[i, b] - centre[i]) / radius[i]
                out[i, k - 1, j] = (1.0, pixels[i, b] / total[i], rel[0], rel[1])
    return out.reshape(n, -1)


def _upright_colour_maps(tiny: np.ndarray, centre: np.ndarray, radius: np.ndarray,
                         angle: np.ndarray) -> np.ndarray:
    """(N, 10 * GRID * GRID) share of the glove pixels each colour holds in each cell of a
    grid over the glove's upright frame (``UPRIGHT_EXTENT`` RMS radii either side of the
    centre; pixels beyond count in the border cells)."""
    n, h, w = tiny.shape
    cells = GRID * GRID
    ys, xs = np.mgrid[0:h, 0:w]
    labels = tiny.reshape(n, -1).astype(np.int64)
    glove = (labels >= 1) & (labels <= NUM_COLORS)
    rel = np.stack([xs.ravel()[None] - centre[:, :1], ys.ravel()[None] - centre[:, 1:]], -1) \
        / radius[:, None, None]
    up = _rotate(rel, -angle)
    index = np.clip(np.floor((up + UPRIGHT_EXTENT) / (2 * UPRIGHT_EXTENT) * GRID), 0,
                    GRID - 1).astype(np.int64)
    cell = index[..., 1] * GRID + index[..., 0]
    frame = np.broadcast_to(np.arange(n)[:, None], labels.shape)
    slot = ((frame * NUM_COLORS + labels - 1) * cells + cell)[glove]
    out = np.bincount(slot, minlength=n * NUM_COLORS * cells).astype(float)
    total = np.maximum(glove.sum(axis=1), 1).astype(float)
    return (out.reshape(n, NUM_COLORS * cells) / total[:, None])


def _rotate(xy: np.ndarray, angle: np.ndarray) -> np.ndarray:
    """Points (N, ..., 2) turned by ``angle`` (N,) radians (x towards y)."""
    c = np.cos(angle).reshape(-1, *([1] * (xy.ndim - 2)))
    s = np.sin(angle).reshape(-1, *([1] * (xy.ndim - 2)))
    return np.stack([c * xy[..., 0] - s * xy[..., 1], s * xy[..., 0] + c * xy[..., 1]], -1)


def observation_features(tiny_labels: np.ndarray, blob_color: np.ndarray,
                         blob_tiny_xy: np.ndarray, blob_tiny_pixels: np.ndarray,
                         angle: np.ndarray | None = None) -> np.ndarray:
    """(N, F) features (module docstring) of N frames' observations: tiny label images
    (N, 40, 40), blob colours (N, B; 0 pads), centroids in tiny pixels (N, B, 2) and pixel
    counts (N, B); with ``angle`` (N,), each frame's fingers' direction in the image
    (:func:`image_angle`), upright features (:data:`OBSERVATION_UPRIGHT_FEATURES`)."""
    tiny = np.asarray(tiny_labels)
    color = np.asarray(blob_color, dtype=np.int64)
    xy = np.asarray(blob_tiny_xy, dtype=float)
    pixels = np.asarray(blob_tiny_pixels, dtype=float)
    n = len(tiny)
    if tiny.ndim != 3 or color.shape[0] != n or xy.shape != (*color.shape, 2) or \
            pixels.shape != color.shape:
        raise ObservationError(f'inconsistent observation arrays: tiny {tiny.shape}, blobs '
                               f'{color.shape} / {xy.shape} / {pixels.shape}')
    centre, radius = _glove_frame(tiny)
    xy = np.where(np.isfinite(xy), xy, 0.0)
    if angle is None:
        return np.concatenate([_colour_maps(tiny),
                               _blob_features(color, xy, pixels, centre, radius)], axis=1)
    angle = np.asarray(angle, dtype=float).reshape(-1)
    if angle.shape != (n,) or not np.all(np.isfinite(angle)):
        raise ObservationError(f'need one finite angle per frame ({n}), got {angle.shape}')
    blobs = _blob_features(color, xy, pixels, centre, radius).reshape(n, NUM_COLORS,
                                                                       BLOBS_PER_COLOR, 4)
    blobs[..., 2:] = _rotate(blobs[..., 2:].reshape(n, -1, 2), -angle).reshape(
        n, NUM_COLORS, BLOBS_PER_COLOR, 2)
    return np.concatenate([_upright_colour_maps(tiny, centre, radius, angle),
                           blobs.reshape(n, -1)], axis=1)


def image_angle(rotvec: np.ndarray) -> np.ndarray:
    """(N,) angle (rad, from the image's x axis towards its y axis) of the direction the
    fingers point (the hand frame's -y axis) projected on the image plane, for hands of
    global rotation vectors (N, 3) in the camera frame."""
    d = -rotvec_to_matrix(np.atleast_2d(np.asarray(rotvec, dtype=float)))[:, :, 1]
    return np.arctan2(d[:, 1], d[:, 0])


def record_features(record: Mapping[str, np.ndarray], angle: np.ndarray | None = None
                    ) -> np.ndarray:
    """(N, F) :func:`observation_features` of an observation record's frames (upright with
    ``angle``)."""
    missing = [k for k in RECORD_FIELDS if k not in record]
    if missing:
        raise ObservationError(f'the observation record lacks {", ".join(missing)}')
    return observation_features(*(record[k] for k in RECORD_FIELDS), angle=angle)


def feature_set_features(record: Mapping[str, np.ndarray], feature_set: str,
                         rotvec: np.ndarray | None = None) -> np.ndarray:
    """(N, F) features of ``feature_set`` (:data:`IMAGE_FEATURE_SETS`) of a record's frames;
    the upright set needs each frame's fitted global rotation vector ``rotvec`` (N, 3)."""
    if feature_set == OBSERVATION_FEATURES:
        return record_features(record)
    if feature_set != OBSERVATION_UPRIGHT_FEATURES:
        raise ObservationError(f'unknown image feature set {feature_set!r}, expected one of '
                               f'{IMAGE_FEATURE_SETS}')
    if rotvec is None:
        raise ObservationError(f'{feature_set!r} features need the fitted global rotations')
    return record_features(record, image_angle(rotvec))
