"""Where the lookup's pose prior loses accuracy: oracle, exact image NN, pipeline, blend."""
from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from colorglove_ros.core.camera import PinholeCamera
from colorglove_ros.core.errors import ColorGloveError
from colorglove_ros.core.evaluation.metrics import (
    fingertip_errors_mm,
    joint_angle_error_deg,
    translation_errors_mm,
)
from colorglove_ros.core.evaluation.sequences import EvaluationSequence
from colorglove_ros.core.hand.model import HandModel
from colorglove_ros.core.lookup.distance import QueryDistance
from colorglove_ros.core.lookup.search import PoseLookup

__all__ = ['DiagnosisError', 'QueryFrames', 'ESTIMATES', 'render_query_frames',
           'FullPoseIndex', 'diagnose', 'coverage']

ESTIMATES = {
    'oracle_fingers': "(a0) finger-nearest configuration (the database's pose distance, "
                      'global pose fixed), its entry nearest in rotation',
    'oracle_pose': '(a) pose-nearest entry: fingers and global rotation (wrist position '
                   'excluded)',
    'image_nn': '(b) exact image-distance NN over all entries (brute force)',
    'top1': '(c) pipeline top-1 (Hamming + re-rank)',
    'blended': '(d) blended pose the lookup returns',
}
"""Rows of the diagnosis table. Every entry is placed in the query's view the way the lookup
places its neighbours (``search.estimate_global_pose``)."""


class DiagnosisError(ColorGloveError):
    """No usable query frame, or a database without the metadata the oracle needs."""


@dataclass(frozen=True)
class QueryFrames:
    """Tiny crops of synthetic frames with their ground truth."""

    tiny: np.ndarray      # (Q, 40, 40) uint8 labels
    crop: np.ndarray      # (Q, 3) crop transform (scale, offset_x, offset_y)
    q_true: np.ndarray    # (Q, 26) true poses in the camera frame
    source: np.ndarray    # (Q, 2) (sequence seed, frame index)


def render_query_frames(seeds: Sequence[int], num_frames: int, step: int,
                        camera: PinholeCamera, observer: Callable[[Any, bool], tuple],
                        synthesizer: Any, split: str = 'test') -> QueryFrames:
    """Every ``step``-th frame of sequences ``seeds`` rendered as ``SequenceEvaluator.run``
    renders them (same poses, conditions and per-frame noise seeds), cropped by ``observer``
    (``evaluation.make_observer``); frames where no hand is found are left out."""
    tiny, crop, q_true, source = [], [], [], []
    for seed in seeds:
        sequence = EvaluationSequence.make(seed, num_frames, camera, synthesizer, split)
        poses = sequence.poses
        for i in range(0, num_frames, step):
            obs, tc = observer(sequence.render(i, (camera,))[0], True)
            if not obs.hand_found or tc is None or not np.any(tc.labels):
                continue
            t = tc.transform
            tiny.append(tc.labels)
            crop.append((t.scale, t.offset_x, t.offset_y))
            q_true.append(poses[i])
            source.append((seed, i))
    if not tiny:
        raise DiagnosisError('no query frame with a hand')
    return QueryFrames(np.array(tiny, np.uint8), np.array(crop), np.array(q_true),
                       np.array(source, np.int64))


class FullPoseIndex:
    """Exact pose distances from a true pose to every database entry: RMS distance (m) of a
    seeded mesh-vertex subset with the wrist at the origin, so both finger articulation and
    global rotation count and the wrist position does not. Vertices are skinned once per
    finger configuration; per query a 3x3 matrix per configuration gives every entry's
    distance under its own rotation."""

    def __init__(self, model: HandModel, mesh: Any, entry_fingers: np.ndarray,
                 config_index: np.ndarray, num_vertices: int = 300, seed: int = 0) -> None:
        rng = np.random.default_rng(seed)
        self.model, self.mesh = model, mesh
        self.subset = np.sort(rng.choice(mesh.num_vertices, min(num_vertices, mesh.num_vertices),
                                         replace=False))
        configs, first, self.entry_config = np.unique(np.asarray(config_index),
                                                      return_index=True, return_inverse=True)
        fingers = np.asarray(entry_fingers, np.float64)[first]
        self.vertices = self._skin(fingers)                  # (C, P, 3) hand frame
        self.sq_norms = np.einsum('cpi,cpi->c', self.vertices, self.vertices)

    def _skin(self, fingers: np.ndarray) -> np.ndarray:
        q = np.zeros((len(fingers), 26))
        q[:, 6:] = fingers
        return self.mesh.skin_batch(self.model, q)[:, self.subset].astype(np.float64)

    def finger_distances(self, fingers: np.ndarray) -> np.ndarray:
        """(C,) the database's pose distance (global pose fixed) to each configuration."""
        v = self._skin(np.asarray(fingers, np.float64)[None])[0]
        d2 = ((self.vertices - v) ** 2).sum(axis=(1, 2))
        return np.sqrt(d2 / len(self.subset))

    def pose_distances(self, q_true: np.ndarray, entry_rotvecs: np.ndarray) -> np.ndarray:
        """(N,) distances from ``q_true`` to every entry posed with rotations
        ``entry_rotvecs`` (N, 3)."""
        from scipy.spatial.transform import Rotation

        v = self._skin(np.asarray(q_true, np.float64)[None, 6:])[0]
        w = Rotation.from_rotvec(q_true[3:6]).apply(v)                       # (P, 3)
        m = np.einsum('cpi,pj->cij', self.vertices, w)                       # (C, 3, 3)
        r = Rotation.from_rotvec(entry_rotvecs).as_matrix()                      # (N, 3, 3)
        cross = np.einsum('nji,nij->n', r, m[self.entry_config])
        d2 = self.sq_norms[self.entry_config] + float((w * w).sum()) - 2.0 * cross
        return np.sqrt(np.maximum(d2, 0.0) / len(self.subset))


def _errors(model: HandModel, est: np.ndarray, truth: np.ndarray) -> dict[str, np.ndarray]:
    from scipy.spatial.transform import Rotation

    rot = (Rotation.from_rotvec(est[:, 3:6]) * Rotation.from_rotvec(truth[:, 3:6]).inv())
    plane, depth = translation_errors_mm(est, truth)
    return {'joint_mae_deg': joint_angle_error_deg(est, truth),
            'rotation_deg': np.degrees(rot.magnitude()),
            'fingertip_rel_wrist_mm': fingertip_errors_mm(model, est, truth,
                                                          relative_to_wrist=True),
            'fingertip_mm': fingertip_errors_mm(model, est, truth),
            'wrist_depth_mm': depth, 'wrist_plane_mm': plane}


def diagnose(lookup: PoseLookup, frames: QueryFrames, camera: PinholeCamera,
             index: FullPoseIndex, chunk: int = 25_000) -> list[dict[str, float]]:
    """One row per :data:`ESTIMATES` key: mean joint MAE (deg), global rotation error (deg),
    fingertip error with the wrist position removed and in full (mm), wrist depth and
    image-plane error (mm), the entry's image distance to the query (px) and its pose
    distance to the truth (mm, :class:`FullPoseIndex`; the blend has none), and how often
    the estimate's entry is the image NN."""
    db_poses = np.asarray(lookup.db.poses)
    n = len(db_poses)
    est = {k: [] for k in ESTIMATES}
    img_d = {k: [] for k in ESTIMATES}
    pose_d = {k: [] for k in ESTIMATES}
    same_nn = {k: [] for k in ESTIMATES}
    for i in range(len(frames.tiny)):
        crop = tuple(float(v) for v in frames.crop[i])
        truth = frames.q_true[i]
        res = lookup.lookup(frames.tiny[i], crop, camera)
        query = QueryDistance(frames.tiny[i])
        dist = np.concatenate([lookup.rerank(query, np.arange(s, min(n, s + chunk)))
                               for s in range(0, n, chunk)])
        placed = lookup.place(None, crop, camera)
        pd = index.pose_distances(truth, placed[:, 3:6])
        fd = index.finger_distances(truth[6:])
        fing = np.flatnonzero(index.entry_config == int(np.argmin(fd)))
        picks = {'oracle_fingers': int(fing[np.argmin(pd[fing])]),
                 'oracle_pose': int(np.argmin(pd)), 'image_nn': int(np.argmin(dist)),
                 'top1': int(res.indices[0])}
        nn = picks['image_nn']
        for key, e in picks.items():
            q = np.asarray(db_poses[e], np.float64).copy()
            q[0:6] = placed[e]
            est[key].append(q)
            img_d[key].append(float(dist[e]))
            pose_d[key].append(1e3 * float(pd[e]))
            same_nn[key].append(float(dist[e] <= dist[nn]))
        est['blended'].append(res.blended)
        same_nn['blended'].append(float(dist[res.indices[0]] <= dist[nn]))
    rows = []
    for key, text in ESTIMATES.items():
        err = _errors(index.model, np.array(est[key]), frames.q_true)
        row: dict[str, Any] = {'estimate': key, 'description': text}
        row.update({k: float(v.mean()) for k, v in err.items()})
        row['rotation_median_deg'] = float(np.median(err['rotation_deg']))
        row['image_distance_px'] = float(np.mean(img_d[key])) if img_d[key] else float('nan')
        row['pose_distance_mm'] = float(np.mean(pose_d[key])) if pose_d[key] else float('nan')
        row['is_image_nn'] = float(np.mean(same_nn[key]))
        rows.append(row)
    return rows


def _view_rotations(anchor: np.ndarray, rotations: Any) -> Any:
    """Hand rotations (scipy ``Rotation``) relative to the viewing rays through the anchors
    (N, 3): R(d)^T R, R(d) the smallest rotation taking the optical axis to the ray d. Two
    hands with the same view rotation look alike up to an image shift (and a slight warp)."""
    from scipy.spatial.transform import Rotation

    d = anchor / np.linalg.norm(anchor, axis=1, keepdims=True)
    q = np.stack([-d[:, 1], d[:, 0], np.zeros(len(d)), 1.0 + d[:, 2]], axis=1)
    return Rotation.from_quat(q / np.linalg.norm(q, axis=1, keepdims=True)).inv() * rotations


def coverage(lookup: PoseLookup, frames: QueryFrames, camera: PinholeCamera,
             index: FullPoseIndex) -> dict[str, float]:
    """How well the database's samples cover the queries: the query's hand rotation relative
    to its viewing ray (what the image shows) against the entries', as roll/yaw/pitch
    (``poses.sample_global_rotations`` angles; 'inside' = within the entries' range of all
    three) and as the angle to the nearest entry's view rotation; finger configurations as
    the database's pose distance to the nearest one; and how far off the optical axis the
    queries are (deg)."""
    from scipy.spatial.transform import Rotation

    anchor = lookup.anchor_local if lookup.anchor_local is not None else np.zeros(3)
    truth = frames.q_true
    rot = Rotation.from_rotvec(truth[:, 3:6])
    centre = truth[:, 0:3] + rot.apply(anchor)
    ray = centre / np.linalg.norm(centre, axis=1, keepdims=True)
    view = _view_rotations(centre, rot)
    db = np.asarray(lookup.db.poses, np.float64)
    db_rot = Rotation.from_rotvec(db[:, 3:6])
    db_view = _view_rotations(db[:, 0:3] + db_rot.apply(anchor), db_rot)
    euler = view.as_euler('ZYX')
    db_euler = db_view.as_euler('ZYX')
    out: dict[str, float] = {'queries': len(truth),
                             'off_axis_deg_mean': float(np.degrees(np.arccos(ray[:, 2])).mean()),
                             'off_axis_deg_max': float(np.degrees(np.arccos(ray[:, 2])).max())}
    inside = np.ones(len(truth), bool)
    for k, name in enumerate(('roll', 'yaw', 'pitch')):
        inside &= (euler[:, k] >= db_euler[:, k].min()) & (euler[:, k] <= db_euler[:, k].max())
        out[f'{name}_query_deg_range'] = (f'{np.degrees(euler[:, k].min()):.0f}..'
                                          f'{np.degrees(euler[:, k].max()):.0f}')
        out[f'{name}_db_deg_range'] = (f'{np.degrees(db_euler[:, k].min()):.0f}..'
                                       f'{np.degrees(db_euler[:, k].max()):.0f}')
    out['view_rotation_inside_db_range'] = float(inside.mean())
    db_q = db_view.as_quat()
    nearest = [float(np.degrees(2.0 * np.arccos(min(1.0, np.abs(db_q @ q).max()))))
               for q in view.as_quat()]
    out['view_rotation_nn_deg_mean'] = float(np.mean(nearest))
    out['view_rotation_nn_deg_max'] = float(np.max(nearest))
    fing = [1e3 * float(index.finger_distances(q[6:]).min()) for q in truth]
    out['finger_nn_mm_mean'] = float(np.mean(fing))
    out['finger_nn_mm_max'] = float(np.max(fing))
    out['finger_configs'] = int(len(index.vertices))
    return out
