"""Learning the IK covariances R, Q, P from training sequences about 5-frame local averages
(``core.evaluation.metrics.local_average``)."""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from colorglove_ros.core.camera import PinholeCamera
from colorglove_ros.core.errors import ColorGloveError
from colorglove_ros.core.evaluation.metrics import LOCAL_WINDOW, local_average
from colorglove_ros.core.geometry import align_rotation_vector
from colorglove_ros.core.hand.model import NUM_DOFS, HandModel
from colorglove_ros.core.tracking.config import IKCovariances
from colorglove_ros.core.tracking.kinematics import FastKinematics
from colorglove_ros.core.tracking.projection import per_point_cameras, project_correspondences
from colorglove_ros.core.tracking.tracker import IKResult
from colorglove_ros.core.tracking.types import Correspondences

__all__ = [
    'IKTrainingError', 'TrainingFrame', 'CovarianceFloors', 'estimate_r', 'learn_covariances',
    'training_frame',
]


class IKTrainingError(ColorGloveError):
    """Training data too short, of the wrong shape, or without usable constraints."""


@dataclass(frozen=True)
class TrainingFrame:
    """One frame of a training sequence: the blended lookup pose, the matched constraints
    (``core.tracking.types.Correspondences`` over all cameras), and the ground-truth pose (synthetic
    data) or else the tracker's estimate (the paper's setting, no ground truth)."""

    q_blend: np.ndarray
    correspondences: Correspondences
    q_true: np.ndarray | None = None
    q_estimate: np.ndarray | None = None


def training_frame(result: IKResult, q_true: np.ndarray | None = None) -> TrainingFrame:
    """A training frame from a tracker output (run the tracker over a training sequence,
    e.g. in 'ik' mode): its IK prior, its matched constraints and its estimate."""
    if not result.found or result.q is None or result.correspondences is None:
        raise IKTrainingError('a training frame needs a tracker result with a hand')
    prior = result.q_prior if result.q_prior is not None else result.q_blend
    return TrainingFrame(np.asarray(prior, float), result.correspondences,
                         None if q_true is None else np.asarray(q_true, float), result.q)


@dataclass(frozen=True)
class CovarianceFloors:
    """Smallest standard deviations kept (a DOF that never moved in training must not get
    an infinite weight)."""

    r_px: float = 0.5
    translation_m: float = 0.002
    rotation_rad: float = 0.01
    fingers_rad: float = 0.01

    def pose_var(self) -> np.ndarray:
        """(26,) variance floors."""
        std = np.concatenate([[self.translation_m] * 3, [self.rotation_rad] * 3,
                              [self.fingers_rad] * 20])
        return std**2


def estimate_r(residuals_px: np.ndarray) -> np.ndarray:
    """Mean square of projection residuals c - f(q_ref) per pixel axis (2,) px^2."""
    r = np.asarray(residuals_px, dtype=float)
    if r.ndim != 2 or r.shape[1] != 2 or len(r) == 0:
        raise IKTrainingError(f'residuals must be (M, 2) with M > 0, got {r.shape}')
    return (r**2).mean(axis=0)


def _rot_aligned(q: np.ndarray, ref: np.ndarray) -> np.ndarray:
    out = q.copy()
    for i in range(len(q)):
        out[i, 3:6] = align_rotation_vector(q[i, 3:6], ref[i, 3:6])
    return out


def learn_covariances(sequences: Sequence[Sequence[TrainingFrame]], model: HandModel,
                      cameras: Sequence[PinholeCamera], window: int = LOCAL_WINDOW,
                      floors: CovarianceFloors | None = None,
                      reference_focal_px: float | None = None
                      ) -> tuple[IKCovariances, dict[str, Any]]:
    """Learn diagonal R, Q, P (Wang-Popovic 5.3-5.4). The reference pose of a frame is its
    ground truth when every frame of the sequence has one, else the ``window``-frame local
    average of the tracker's estimates (the paper's "covariances about a local average"):
    R from the constraint residuals at the reference, Q from blended minus reference,
    P from the previous frame about the current local average. Variances are floored.
    Residuals are measured in pixels of a camera of focal length ``reference_focal_px``
    (``IKConfig.reference_focal_px``; None: each camera's own pixels).
    Returns the covariances and counts (frames, residuals, sequences used)."""
    floors = floors or CovarianceFloors()
    kin = FastKinematics(model)
    residuals: list[np.ndarray] = []
    q_devs: list[np.ndarray] = []
    p_devs: list[np.ndarray] = []
    n_frames = 0
    n_truth = 0
    for s, seq in enumerate(sequences):
        if len(seq) < window:
            raise IKTrainingError(f'sequence {s} has {len(seq)} frames, needs >= {window}')
        blend = np.stack([np.asarray(f.q_blend, float).reshape(NUM_DOFS) for f in seq])
        if all(f.q_true is not None for f in seq):
            ref = np.stack([np.asarray(f.q_true, float).reshape(NUM_DOFS) for f in seq])
            traj = ref
            n_truth += 1
        elif all(f.q_estimate is not None for f in seq):
            est = np.stack([np.asarray(f.q_estimate, float).reshape(NUM_DOFS) for f in seq])
            ref = local_average(est, window)
            traj = est
        else:
            raise IKTrainingError(f'sequence {s}: every frame needs q_true, or every frame '
                                  'needs q_estimate')
        ok = ~np.isnan(ref).any(axis=1)
        for i in np.flatnonzero(ok):
            corr = seq[i].correspondences
            if len(corr):
                pix, _, _ = project_correspondences(kin, cameras, corr, ref[i])
                scale = per_point_cameras(cameras, corr).axis_scale(reference_focal_px)
                residuals.append((corr.target_px - pix) / scale)
        q_devs.append(_rot_aligned(blend[ok], ref[ok]) - ref[ok])
        p_devs.append(_p_deviations(traj, window))
        n_frames += int(ok.sum())
    if not residuals:
        raise IKTrainingError('no correspondences in the training frames: R cannot be learned')
    res = np.concatenate(residuals)
    r_var = np.maximum(estimate_r(res), floors.r_px**2)
    q_var = np.maximum((np.concatenate(q_devs) ** 2).mean(axis=0), floors.pose_var())
    p_var = np.maximum((np.concatenate(p_devs) ** 2).mean(axis=0), floors.pose_var())
    stats = {'sequences': len(sequences), 'with_ground_truth': n_truth, 'frames': n_frames,
             'residuals': len(res), 'window': window}
    return IKCovariances(r_var, q_var, p_var, source='learned'), stats


def _p_deviations(traj: np.ndarray, window: int) -> np.ndarray:
    """Rows ``q_{i-1} - local_average_i`` of a trajectory (incomplete windows dropped)."""
    avg = local_average(traj, window)
    prev, cur = traj[:-1], avg[1:]
    ok = ~(np.isnan(prev).any(axis=1) | np.isnan(cur).any(axis=1))
    return _rot_aligned(prev[ok], cur[ok]) - cur[ok]
