"""Matching database-entry constraints to measured blobs: the primary camera through the lookup
crop, the other cameras through the projected constraint vertices (one image shift, then
one-to-one per colour)."""
from __future__ import annotations

import math
from typing import Any

import numpy as np

from colorglove_ros.core.camera import PinholeCamera
from colorglove_ros.core.lookup.types import ProjectionConstraints
from colorglove_ros.core.segmentation.crop import tiny_to_full
from colorglove_ros.core.tracking.assignment import linear_sum_assignment
from colorglove_ros.core.tracking.types import Blobs, Correspondences, IKError, MeshLike

__all__ = ['match_by_color', 'match_primary', 'match_extra_camera', 'explained_blob_share']


def match_by_color(pred_xy: np.ndarray, pred_color: np.ndarray, blob_xy: np.ndarray,
                   blob_color: np.ndarray, gate_px: float) -> tuple[np.ndarray, np.ndarray]:
    """One-to-one matching of predicted points to blobs of the same colour (Hungarian on
    distance per colour); pairs farther than ``gate_px`` are dropped. Returns index arrays
    (into the predictions, into the blobs)."""
    pred_xy = np.asarray(pred_xy, float).reshape(-1, 2)
    blob_xy = np.asarray(blob_xy, float).reshape(-1, 2)
    empty = np.zeros(0, np.int64)
    if len(pred_xy) == 0 or len(blob_xy) == 0:
        return empty, empty
    d = np.linalg.norm(pred_xy[:, None, :] - blob_xy[None, :, :], axis=2)
    ok = (np.asarray(pred_color)[:, None] == np.asarray(blob_color)[None, :]) & (d <= gate_px)
    if not ok.any():
        return empty, empty
    # one assignment over all colours: forbidden pairs cost more than any allowed set
    big = (gate_px + 1.0) * (min(d.shape) + 1)
    r, c = linear_sum_assignment(np.where(ok, d, big))
    keep = ok[r, c]
    return r[keep].astype(np.int64), c[keep].astype(np.int64)


# A correspondence's target is its blob's undistorted centroid, computed the same way.
_SAME_PIXEL = 1e-6


def _usable(blobs: Blobs, min_pixels: float) -> np.ndarray:
    return np.flatnonzero(blobs.pixel_count >= min_pixels)


def match_primary(constraints: ProjectionConstraints, blobs: Blobs, crop: Any,
                  camera: PinholeCamera, mesh: MeshLike, gate_tiny_px: float = 8.0,
                  gate_min_px: float = 10.0, min_blob_pixels: float = 4,
                  max_blob_ratio: float = 0.0, min_kept: int = 3) -> Correspondences:
    """Match the entry's constraints (tiny-image centroids mapped to full-image pixels with
    the query's crop, ``full = offset + scale * tiny``) to same-colour blobs of the primary
    camera; targets are the undistorted blob centroids.

    With ``max_blob_ratio`` > 0 a pair whose blob holds more than that many times the
    pixels of its constraint's patch in the entry (tiny-image pixels times the crop scale
    squared) is dropped, as long as ``min_kept`` pairs remain (else every pair is kept):
    glove-coloured clutter joined to a patch inflates its blob and moves its centroid."""
    if crop is None:
        raise IKError('the primary observation needs the crop transform of the lookup query')
    if len(constraints) == 0 or len(blobs) == 0:
        return Correspondences.empty()
    scale = float(crop.scale)
    pred = tiny_to_full(constraints.tiny_xy, scale, float(crop.offset_x), float(crop.offset_y))
    keep = _usable(blobs, min_blob_pixels)
    gate = max(gate_min_px, gate_tiny_px * scale)
    k, m = match_by_color(pred, constraints.colors, blobs.centroid_px[keep],
                          blobs.color[keep], gate)
    m = keep[m]
    if max_blob_ratio > 0.0 and len(k):
        expected = np.maximum(np.asarray(constraints.pixel_counts, float)[k] * scale ** 2, 1.0)
        fits = blobs.pixel_count[m] <= max_blob_ratio * expected
        if int(fits.sum()) >= min_kept:
            k, m = k[fits], m[fits]
    return _make_corr(0, constraints, k, camera.undistort_pixels(blobs.centroid_px[m]), mesh)


def explained_blob_share(corr: Correspondences, blobs: Blobs, camera: PinholeCamera,
                         min_blob_pixels: float = 4) -> float:
    """The share of the primary camera's blobs (those large enough to be matched) that a
    correspondence of camera 0 targets: how much of what the segmenter found the fitted hand
    explains. Glove-coloured clutter inside the hand's crop leaves many blobs unexplained.
    NaN without a usable blob."""
    keep = _usable(blobs, min_blob_pixels)
    if len(keep) == 0:
        return math.nan
    targets = np.asarray(corr.target_px, float)[np.asarray(corr.camera) == 0]
    if len(targets) == 0:
        return 0.0
    centroids = camera.undistort_pixels(blobs.centroid_px[keep])
    gap = np.linalg.norm(centroids[:, None, :] - targets[None, :, :], axis=2).min(axis=1)
    return float(np.mean(gap <= _SAME_PIXEL))


def _make_corr(cam: int, constraints: ProjectionConstraints, k: np.ndarray, target: np.ndarray,
               mesh: MeshLike) -> Correspondences:
    v = constraints.vertices[k]
    nv = len(mesh.vertex_link)
    if np.any((v < 0) | (v >= nv)):
        raise IKError(f'constraint vertex index out of range [0, {nv})')
    return Correspondences(np.full(len(k), cam, np.int64),
                           np.asarray(mesh.vertex_link, np.int64)[v],
                           np.asarray(mesh.local_vertices, float)[v],
                           np.asarray(target, float).reshape(-1, 2),
                           constraints.patch_ids[k].copy(), v.copy())


def match_extra_camera(cam_index: int, camera: PinholeCamera, constraints: ProjectionConstraints,
                       predicted_world: np.ndarray, blobs: Blobs, mesh: MeshLike,
                       gate_px: float = 30.0, shift_max_px: float = 150.0,
                       inlier_px: float = 15.0, min_blob_pixels: float = 4,
                       min_depth_m: float = 0.05,
                       normals_world: np.ndarray | None = None) -> Correspondences:
    """Match constraints to same-colour blobs of a camera with no lookup: project the
    constraint vertices (``predicted_world``, (K, 3) in the primary frame, at the current
    pose), find the common image shift with most same-colour inliers (absorbs the weak
    depth of the pose), then Hungarian-match inside ``gate_px``. With ``normals_world``
    (K, 3), vertices whose surface faces away from this camera are skipped."""
    if len(constraints) == 0 or len(blobs) == 0:
        return Correspondences.empty()
    pc = camera.world_to_camera(predicted_world)
    front = pc[:, 2] > min_depth_m
    if normals_world is not None:
        center = -camera.rotation.T @ camera.translation
        front &= np.einsum('ni,ni->n', normals_world, center - predicted_world) > 0.0
    pred = np.full((len(pc), 2), np.nan)
    pred[front] = camera.project(pc[front])
    margin = gate_px
    inside = front & (pred[:, 0] > -margin) & (pred[:, 0] < camera.width + margin) \
        & (pred[:, 1] > -margin) & (pred[:, 1] < camera.height + margin)
    ks = np.flatnonzero(inside)
    keep = _usable(blobs, min_blob_pixels)
    if len(ks) == 0 or len(keep) == 0:
        return Correspondences.empty()
    bxy = camera.undistort_pixels(blobs.centroid_px[keep])
    bcol = blobs.color[keep]
    kcol = constraints.colors[ks]
    # same-colour (constraint, blob) pairs, grouped by constraint (row-major order)
    pair_k, pair_m = np.nonzero(kcol[:, None] == bcol[None, :])
    diff = bxy[pair_m] - pred[ks[pair_k]]                  # (P, 2)
    shift = np.zeros(2)
    hyp = diff[np.linalg.norm(diff, axis=1) <= shift_max_px]
    if len(hyp):
        # per hypothesis, distance of every shifted prediction to its nearest same-colour
        # blob (constraints without one never count)
        pair_dist = np.linalg.norm(diff[None] - hyp[:, None, :], axis=2)     # (H, P)
        first = np.flatnonzero(np.diff(pair_k, prepend=-1))
        dist = np.minimum.reduceat(pair_dist, first, axis=1)                 # (H, K with pairs)
        inl = dist <= inlier_px
        score = inl.sum(axis=1) - 1e-3 * np.where(inl, dist, 0.0).sum(axis=1) / inlier_px
        best = int(np.argmax(score))
        if inl[best].sum() >= 2:
            # refine: mean residual of the inliers to their nearest same-colour blob
            nearest = np.lexsort((pair_dist[best], pair_k))[first]
            rows = np.flatnonzero(inl[best])
            shift = hyp[best] + (diff[nearest[rows]] - hyp[best]).mean(axis=0)
    k, m = match_by_color(pred[ks] + shift, kcol, bxy, bcol, gate_px)
    return _make_corr(cam_index, constraints, ks[k], bxy[m], mesh)
