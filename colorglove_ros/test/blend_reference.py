"""The lookup blend as numpy wrote it: the per-finger scores before the compiled nearest-blob
search, and, before their compiled loops (issue 19, twenty-third pass), the per-finger weighted
moments and blend, the Gaussian weights of the image distances, the projection constraints'
patch sources, the wrists' placement on the query's rays and ``PoseLookup.blend`` made of them.
References for the compiled versions, which must give the same bits."""
from __future__ import annotations

import numpy as np

from colorglove_ros.core.lookup.blend import blend_poses_with_quaternions
from colorglove_ros.core.segmentation.crop import tiny_to_full

__all__ = ['blend_weights_reference', 'finger_scores_reference', 'weighted_fingers_reference',
           'finger_blend_reference', 'constraints_reference', 'place_wrists_reference',
           'blend_reference']



def blend_weights_reference(distances: np.ndarray) -> np.ndarray:
    """``blend.blend_weights`` in numpy: exp(-(d / mean d)^2) over its sum, equal weights
    when the mean is not positive."""
    d = np.asarray(distances, np.float64)
    sigma = float(d.mean())
    if sigma <= 0.0:
        return np.full(len(d), 1.0 / len(d))
    w = np.exp(-(d / sigma) ** 2)
    return w / w.sum()

def finger_scores_reference(patch_xy, patch_pixels, patch_digit, patch_color, blob_color, blob_xy,
                            blob_pixels, config) -> np.ndarray:
    """finger_evidence.finger_scores as it was in numpy (the reference of the compiled search
    for each patch's nearest same-colour blob and of the compiled residuals and means)."""
    cap = float(config.cap_tiny_px)
    xy = np.asarray(patch_xy, np.float64)
    k, p = xy.shape[:2]
    digit = np.asarray(patch_digit)
    residual = np.full((k, p), cap)
    bcol = np.asarray(blob_color).reshape(-1)
    if len(bcol):
        bxy = np.asarray(blob_xy, np.float64).reshape(-1, 2)
        same = np.asarray(patch_color)[:, None] == bcol[None, :]
        slots = max(1, int(same.sum(axis=1).max()))
        blob = np.argsort(~same, axis=1, kind='stable')[:, :slots]
        dx = xy[:, :, 0, None] - bxy[blob, 0]
        dy = xy[:, :, 1, None] - bxy[blob, 1]
        dist = np.where(np.take_along_axis(same, blob, axis=1)[None],
                        np.sqrt(dx * dx + dy * dy), np.inf)
        nearest = np.argmin(dist, axis=2)
        d = np.take_along_axis(dist, nearest[..., None], axis=2)[..., 0]
        area = np.asarray(blob_pixels, np.float64).reshape(-1)[blob[np.arange(p), nearest]]
        area_term = np.abs(np.log((np.asarray(patch_pixels, np.float64) + 1.0) / (area + 1.0)))
        with np.errstate(invalid='ignore'):
            residual = np.minimum(cap, d + config.area_weight * area_term)
        residual[~np.isfinite(residual)] = cap
    member = digit[:, None, :] == np.arange(5)[None, :, None]
    count = member.sum(axis=2)
    total = np.where(member, residual[:, None, :], 0.0).sum(axis=2)
    return np.where(count > 0, total / np.maximum(count, 1), cap)


def weighted_fingers_reference(poses: np.ndarray, weights: np.ndarray
                               ) -> tuple[np.ndarray, np.ndarray]:
    """Weighted means (20,) and standard deviations (20,) of the finger DOFs of (K, 26)
    ``poses`` with (K, 5) or (K,) weights, by ``np.einsum``."""
    poses = np.asarray(poses, np.float64)
    w = np.asarray(weights, np.float64)
    w = np.repeat(w[:, None], 5, axis=1) if w.ndim == 1 else w
    fingers = poses[:, 6:].reshape(len(poses), 5, 4)
    mean = np.einsum('kg,kgd->gd', w, fingers)
    var = np.einsum('kg,kgd->gd', w, (fingers - mean) ** 2)
    return mean.reshape(-1), np.sqrt(var).reshape(-1)


def finger_blend_reference(poses: np.ndarray, scores: np.ndarray, sigma: float, cap: float
                           ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``finger_evidence.finger_blend`` in numpy: weights exp(-(score / sigma)^2), each column
    over its sum (equal where the sum is not positive)."""
    scores = np.asarray(scores, np.float64)
    s = scores / sigma
    w = np.exp(-s * s)
    total = w.sum(axis=0)
    w = np.where(total > 0, w / np.where(total > 0, total, 1.0), 1.0 / max(len(scores), 1))
    mean, spread = weighted_fingers_reference(poses, w)
    return mean, spread, scores.min(axis=0) < cap


def constraints_reference(patch_vertex: np.ndarray, patch_digit: np.ndarray,
                          patch_xy: np.ndarray, patch_pixels: np.ndarray,
                          patch_color: np.ndarray, entry: int,
                          crop: tuple[float, float, float],
                          finger_entries: np.ndarray | None = None
                          ) -> tuple[np.ndarray, ...]:
    """``PoseLookup._constraints``' arrays (patch ids, colours, vertices, tiny and full-image
    centroids, areas) in numpy: the nearest entry's visible patches, digit g's from
    ``finger_entries[g]`` where that is another entry."""
    source = np.where(patch_vertex[entry] >= 0, entry, -1)
    if finger_entries is not None:
        entries = np.asarray(finger_entries, np.int64)
        digits = patch_digit[np.append(entries, entry)]
        for g, e in enumerate(entries):
            if e != entry:
                source[(digits[-1] == g) & (source == entry)] = -1
                source[digits[g] == g] = e
    vis = np.flatnonzero(source >= 0)
    src = source[vis]
    tiny_xy = patch_xy[src, vis].astype(np.float64)
    return (vis.astype(np.int64), patch_color[vis].astype(np.int64),
            patch_vertex[src, vis].astype(np.int64), tiny_xy,
            patch_pixels[src, vis].astype(np.float64), tiny_to_full(tiny_xy, *crop))


def place_wrists_reference(terms: np.ndarray, render_camera: dict,
                           query_crop: tuple[float, float, float], camera: object
                           ) -> np.ndarray:
    """``search._place_wrists`` in numpy: each entry's anchor pixel mapped with the query
    crop, undistorted, back-projected, at its range scaled by apparent size, less the anchor's
    offset from the wrist."""
    rc = render_camera
    sq, oqx, oqy = query_crop
    full = terms[:, 0:2] * sq
    full += (oqx, oqy)
    if np.any(camera.distortion):
        full = camera.undistort_pixels(full)
    out = np.empty((len(terms), 3))
    out[:, 0] = (full[:, 0] - camera.cx) / camera.fx
    out[:, 1] = (full[:, 1] - camera.cy) / camera.fy
    out[:, 2] = 1.0
    r = terms[:, 2] * ((camera.fx + camera.fy) / (rc['fx'] + rc['fy']) / sq)
    out *= (r / np.sqrt(out[:, 0] ** 2 + out[:, 1] ** 2 + 1.0))[:, None]
    out -= terms[:, 7:10]
    return out


def blend_reference(lookup: object, found: object, camera: object, blobs: object = None
                    ) -> dict[str, np.ndarray | None]:
    """``PoseLookup.blend``'s arrays (indices, distances, weights, poses, blended, finger_std
    and the constraints' six arrays) as numpy made them, from ``lookup``'s tables."""
    a, config = lookup._a, lookup.finger_evidence
    cand, dist, crop = found.candidates, found.distances, found.crop
    wide = min(max(lookup.num_blend, config.num_neighbours if blobs is not None else 0),
               len(cand))
    near = np.argpartition(dist, wide - 1)[:wide] if wide < len(cand) else np.arange(len(cand))
    near = near[np.lexsort((cand[near], dist[near]))]
    k = min(lookup.num_blend, len(cand))
    idx, d = cand[near[:k]], dist[near[:k]]
    weights = blend_weights_reference(d)
    poses = a['poses'][idx].astype(np.float64)
    terms = lookup._place_table[idx]
    poses[:, 0:3] = place_wrists_reference(terms, lookup.db.render_camera, crop, camera)
    blended = blend_poses_with_quaternions(poses, terms[:, 3:7], weights)
    finger_std = finger_entries = None
    if blobs is not None:
        color = np.asarray(blobs.color).reshape(-1)
        xy = np.asarray(blobs.centroid_px, np.float64).reshape(-1, 2)
        pixels = np.asarray(blobs.pixel_count, np.float64).reshape(-1)
        usable = np.isfinite(xy).all(axis=1) & np.isfinite(pixels) & (pixels > 0)
        if usable.any():
            entries = cand[near]
            scale, ox, oy = crop
            scores = finger_scores_reference(
                a['patch_xy'][entries], a['patch_pixels'][entries],
                lookup._patch_digit[entries], a['patch_color'], color[usable],
                (xy[usable] - (ox, oy)) / scale, pixels[usable] / scale ** 2, config)
            fingers, finger_std, seen = finger_blend_reference(
                a['poses'][entries], scores, config.sigma_tiny_px, config.cap_tiny_px)
            finger_entries = entries[np.argmin(scores, axis=0)]
            dofs = np.repeat(seen, 4)
            blended[6:] = np.where(dofs, fingers, blended[6:])
            if not seen.all():
                finger_std = np.where(dofs, finger_std,
                                      weighted_fingers_reference(poses, weights)[1])
            finger_entries = np.where(seen, finger_entries, idx[0])
    names = ('patch_ids', 'colors', 'vertices', 'tiny_xy', 'pixel_counts', 'full_xy')
    constraints = constraints_reference(a['patch_vertex'], lookup._patch_digit, a['patch_xy'],
                                        a['patch_pixels'], a['patch_color'], int(idx[0]), crop,
                                        finger_entries)
    return {'indices': idx, 'distances': d, 'weights': weights, 'poses': poses,
            'blended': blended, 'finger_std': finger_std,
            **{f'constraints.{n}': v for n, v in zip(names, constraints, strict=True)}}
