"""Accuracy, jitter and latency figures of tracked poses against ground truth (shared by the
IK evaluation, the end-to-end demo and the benchmark), and the centred local average that
jitter and the IK covariance learning measure deviations from."""
from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from colorglove_ros.core.errors import ColorGloveError
from colorglove_ros.core.hand.model import KEYPOINT_NAMES, HandModel
from colorglove_ros.core.validation import check_number

__all__ = [
    'FINGERTIP_INDICES', 'fingertip_positions', 'LOCAL_WINDOW', 'MetricsError',
    'joint_angle_error_deg',
    'fingertip_errors_mm', 'fingertip_error_split_mm', 'translation_errors_mm',
    'local_average', 'deviation_from_local_average', 'dof_jitter', 'jitter_mm',
    'contiguous_runs', 'jitter_runs_mm', 'latency_summary_ms', 'pose_accuracy',
]

FINGERTIP_INDICES = np.array([i for i, name in enumerate(KEYPOINT_NAMES) if name.endswith('_tip')])
#: frames in the centred local average (the papers' 5-frame jitter window)
LOCAL_WINDOW = 5


class MetricsError(ColorGloveError, ValueError):
    """A sequence too short or of the wrong shape for a figure, or an unusable window."""


def joint_angle_error_deg(estimated: np.ndarray, truth: np.ndarray) -> np.ndarray:
    """Per-frame mean absolute error of the 20 finger joint angles, degrees: (N,)."""
    diff = np.asarray(estimated)[:, 6:26] - np.asarray(truth)[:, 6:26]
    return np.degrees(np.abs(diff)).mean(axis=1)


def fingertip_positions(model: HandModel, poses: np.ndarray) -> np.ndarray:
    """(N, 5, 3) fingertip positions of poses (N, 26)."""
    return np.stack([model.keypoints(q)[FINGERTIP_INDICES] for q in np.asarray(poses)])


def fingertip_errors_mm(model: HandModel, estimated: np.ndarray, truth: np.ndarray,
                        relative_to_wrist: bool = False) -> np.ndarray:
    """Per-frame mean 3-D fingertip error, mm: (N,). With ``relative_to_wrist`` the
    fingertips are taken relative to each pose's wrist position, which removes the wrist
    translation error only: the wrist rotation error stays in (see
    :func:`fingertip_error_split_mm` for the articulation alone)."""
    est, gt = fingertip_positions(model, estimated), fingertip_positions(model, truth)
    if relative_to_wrist:
        est = est - np.asarray(estimated)[:, None, 0:3]
        gt = gt - np.asarray(truth)[:, None, 0:3]
    return 1000.0 * np.linalg.norm(est - gt, axis=2).mean(axis=1)


def fingertip_error_split_mm(model: HandModel, estimated: np.ndarray,
                             truth: np.ndarray) -> dict[str, np.ndarray]:
    """Per-frame mean fingertip errors, mm, (N,) each, split by cause:
    ``hand_frame``: in the hand frame (wrist translation and rotation of both poses removed),
    i.e. finger articulation only; ``rotation_only``: the true pose with the estimated wrist
    rotation, i.e. what the rotation error alone costs."""
    est, gt = np.array(estimated, float), np.array(truth, float)
    rot = gt.copy()
    rot[:, 3:6] = est[:, 3:6]
    est[:, 0:6] = 0.0
    local = gt.copy()
    local[:, 0:6] = 0.0
    return {'hand_frame': fingertip_errors_mm(model, est, local),
            'rotation_only': fingertip_errors_mm(model, rot, gt)}


def translation_errors_mm(estimated: np.ndarray,
                          truth: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Wrist translation error split into image-plane (perpendicular to the viewing ray through
    the true wrist) and depth (along it), mm: two (N,) arrays."""
    est, gt = np.asarray(estimated)[:, 0:3], np.asarray(truth)[:, 0:3]
    ray = gt / np.linalg.norm(gt, axis=1, keepdims=True)
    diff = est - gt
    depth = np.abs(np.sum(diff * ray, axis=1))
    plane = np.linalg.norm(diff - np.sum(diff * ray, axis=1, keepdims=True) * ray, axis=1)
    return 1000.0 * plane, 1000.0 * depth


def local_average(values: np.ndarray, window: int = LOCAL_WINDOW) -> np.ndarray:
    """Centred moving average along the first axis of a sequence (N, ...):
    ``1/w sum_{j in S} x_{i+j}``, S = {-w//2..w//2}, ``w = window`` odd, each row the sum of
    its own window divided once by ``w`` (no running sums, so no error that grows with N);
    rows whose window leaves the sequence are NaN."""
    x = np.asarray(values, dtype=float)
    if x.ndim < 1:
        raise MetricsError(f'values must be a sequence (N, ...), got shape {x.shape}')
    window = int(check_number('window', window, low=1, integer=True, odd=True,
                              error=MetricsError))
    out = np.full_like(x, np.nan)
    inner = len(x) - window + 1
    if inner > 0:
        half = window // 2
        out[half:half + inner] = sum(x[j:j + inner] for j in range(window)) / window
    return out


def deviation_from_local_average(values: np.ndarray,
                                 window: int = LOCAL_WINDOW) -> np.ndarray:
    """``x_i - local_average_i`` (NaN where the window is incomplete)."""
    x = np.asarray(values, dtype=float)
    return x - local_average(x, window)


def dof_jitter(poses: np.ndarray, window: int = LOCAL_WINDOW) -> np.ndarray:
    """Per-DOF jitter of a pose sequence (N, D): the mean absolute deviation from the local
    average over the frames with a complete window, (D,)."""
    q = np.asarray(poses, dtype=float)
    if q.ndim != 2:
        raise MetricsError(f'poses must be (N, D), got shape {q.shape}')
    dev = deviation_from_local_average(q, window)
    valid = ~np.isnan(dev).any(axis=1)
    if not valid.any():
        raise MetricsError(f'jitter needs at least {window} frames, got {len(q)}')
    return np.abs(dev[valid]).mean(axis=0)


def jitter_mm(model: HandModel, poses: np.ndarray, window: int = LOCAL_WINDOW) -> float:
    """Mean distance of fingertips from their ``window``-frame local average, mm (the paper's
    jitter measure). NaN for sequences shorter than the window."""
    poses = np.asarray(poses)
    if len(poses) < window:
        return float('nan')
    half = window // 2
    dev = deviation_from_local_average(fingertip_positions(model, poses), window)
    return float(1000.0 * np.linalg.norm(dev[half:len(poses) - half], axis=2).mean())


def contiguous_runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """(start, stop) of the runs of True in a boolean mask."""
    m = np.concatenate([[False], np.asarray(mask, bool), [False]])
    d = np.diff(m.astype(np.int8))
    return list(zip(np.flatnonzero(d == 1).tolist(), np.flatnonzero(d == -1).tolist(),
                    strict=True))


def jitter_runs_mm(model: HandModel, poses: np.ndarray, valid: np.ndarray,
                   window: int = LOCAL_WINDOW) -> float:
    """``metrics.jitter_mm`` over each run of consecutive valid frames (>= ``window``),
    averaged weighted by the frames each run contributes; NaN if no run is long enough."""
    total, weight = 0.0, 0
    for a, b in contiguous_runs(valid):
        if b - a >= window:
            total += jitter_mm(model, poses[a:b], window) * (b - a - 2 * (window // 2))
            weight += b - a - 2 * (window // 2)
    return total / weight if weight else math.nan


def latency_summary_ms(latencies_s: Sequence[float]) -> dict[str, float]:
    """Mean, p50, p95 and max of latencies given in seconds, as milliseconds."""
    values = 1000.0 * np.asarray(latencies_s, dtype=float)
    if values.size == 0:
        return {'mean': float('nan'), 'p50': float('nan'), 'p95': float('nan'),
                'max': float('nan')}
    return {'mean': float(values.mean()), 'p50': float(np.percentile(values, 50)),
            'p95': float(np.percentile(values, 95)), 'max': float(values.max())}


def pose_accuracy(model: HandModel, estimated: np.ndarray, truth: np.ndarray) -> dict[str, float]:
    """Mean accuracy figures of an estimated pose sequence against ground truth."""
    estimated, truth = np.atleast_2d(estimated), np.atleast_2d(truth)
    plane, depth = translation_errors_mm(estimated, truth)
    split = fingertip_error_split_mm(model, estimated, truth)
    return {
        'joint_mae_deg': float(joint_angle_error_deg(estimated, truth).mean()),
        'fingertip_mm': float(fingertip_errors_mm(model, estimated, truth).mean()),
        'fingertip_rel_wrist_mm': float(
            fingertip_errors_mm(model, estimated, truth, relative_to_wrist=True).mean()),
        'fingertip_hand_frame_mm': float(split['hand_frame'].mean()),
        'fingertip_rotation_only_mm': float(split['rotation_only'].mean()),
        'wrist_plane_mm': float(plane.mean()),
        'wrist_depth_mm': float(depth.mean()),
        'jitter_mm': jitter_mm(model, estimated),
        'jitter_truth_mm': jitter_mm(model, truth),
    }
