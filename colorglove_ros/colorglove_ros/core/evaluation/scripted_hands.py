"""Scripted hand-pose sequences with a tracking-noise model, for the gesture and spelling
evaluations (no rendering: these test what consumes the tracked pose, not the tracker).

A script is a list of segments: move from the previous segment's pose to this one with a
minimum-jerk profile (fingers and wrist position) and a slerp (wrist orientation), then hold
it. ``TrackingNoise`` then stands in for the tracker's errors: it is a MODEL, not errors
measured frame by frame. Each finger DOF gets zero-mean Gaussian noise whose mean absolute
value is ``joint_mae_deg`` (default: the order of the tracker's mean joint-angle error, see
the README's measured results), split
into a slowly varying part (an AR(1) process with ``correlation_s``; the tracker's errors
come mostly from the lookup's bias, which persists over frames) and white per-frame jitter;
each axis of the wrist orientation (a small rotation applied on the camera side) gets
the same kind of noise with mean absolute value ``rotation_mae_deg``. Noisy joints are clipped
into the model's limits, as the IK's are, with the scale set so the error after clipping
has the stated mean.
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation, Slerp

from colorglove_ros.core.errors import ColorGloveError
from colorglove_ros.core.hand.model import NUM_DOFS, NUM_FINGER_DOFS, HandModel
from colorglove_ros.core.synthetic.sequences import min_jerk

__all__ = ['ScriptError', 'Segment', 'ScriptedSequence', 'TrackingNoise', 'script_poses',
           'ar1_noise']


class ScriptError(ColorGloveError, ValueError):
    """A bad script or noise setting."""


@dataclass(frozen=True)
class Segment:
    """Move to ``fingers`` (20,), wrist ``rotvec`` (3,) and ``position`` (3,) in ``move_s``
    seconds, then hold for ``hold_s``; ``label`` names what is held (e.g. a gesture or a
    letter; '' for nothing in particular)."""

    label: str
    fingers: np.ndarray
    rotvec: np.ndarray
    position: np.ndarray
    hold_s: float
    move_s: float


@dataclass(frozen=True)
class ScriptedSequence:
    """Ground truth of a script: ``poses`` (N, 26), and per frame the segment index, its
    label, and whether the frame is in the segment's hold (else in the move to it)."""

    poses: np.ndarray
    segment: np.ndarray
    label: np.ndarray
    holding: np.ndarray
    fps: float

    @property
    def times(self) -> np.ndarray:
        """Frame times in seconds."""
        return np.arange(len(self.poses)) / self.fps


def script_poses(segments: Sequence[Segment], fps: float = 30.0) -> ScriptedSequence:
    """Sample a script at ``fps``; the first segment's move starts from its own pose."""
    if not segments or fps <= 0:
        raise ScriptError('need at least one segment and fps > 0')
    poses, seg_index, holding = [], [], []
    prev = segments[0]
    for k, seg in enumerate(segments):
        if seg.hold_s < 0 or seg.move_s < 0:
            raise ScriptError(f'segment {k}: negative duration')
        n_move, n_hold = int(round(seg.move_s * fps)), int(round(seg.hold_s * fps))
        s = min_jerk((np.arange(n_move) + 1.0) / max(n_move, 1))
        slerp = Slerp([0.0, 1.0], Rotation.from_rotvec(np.stack([prev.rotvec, seg.rotvec])))
        move = np.empty((n_move, NUM_DOFS))
        move[:, 0:3] = prev.position + s[:, None] * (seg.position - prev.position)
        move[:, 3:6] = slerp(s).as_rotvec() if n_move else np.zeros((0, 3))
        move[:, 6:] = prev.fingers + s[:, None] * (seg.fingers - prev.fingers)
        hold = np.tile(np.concatenate([seg.position, seg.rotvec, seg.fingers]), (n_hold, 1))
        poses += [move, hold]
        seg_index += [k] * (n_move + n_hold)
        holding += [False] * n_move + [True] * n_hold
        prev = seg
    seg_index_arr = np.asarray(seg_index, dtype=np.int64)
    labels = np.array([s.label for s in segments], dtype=object)
    return ScriptedSequence(poses=np.concatenate(poses), segment=seg_index_arr,
                            label=labels[seg_index_arr], holding=np.asarray(holding), fps=fps)


def ar1_noise(rng: np.random.Generator, shape: tuple[int, int], fps: float,
              correlation_s: float) -> np.ndarray:
    """Stationary unit-variance AR(1) noise (frames, channels) with the given correlation
    time (0: white)."""
    if correlation_s <= 0:
        return rng.normal(0.0, 1.0, shape)
    a = float(np.exp(-1.0 / (fps * correlation_s)))
    e = rng.normal(0.0, 1.0, shape)
    out = np.empty(shape)
    out[0] = e[0]
    b = np.sqrt(1.0 - a * a)
    for t in range(1, shape[0]):
        out[t] = a * out[t - 1] + b * e[t]
    return out


@dataclass(frozen=True)
class TrackingNoise:
    """Tracking-error model (see the module docstring); ``slow_share`` is the slow part's
    share of the variance."""

    joint_mae_deg: float = 7.0
    rotation_mae_deg: float = 5.0
    slow_share: float = 0.8
    correlation_s: float = 0.4

    def __post_init__(self) -> None:
        if self.joint_mae_deg < 0 or self.rotation_mae_deg < 0 or \
                not 0.0 <= self.slow_share <= 1.0 or self.correlation_s < 0:
            raise ScriptError(f'bad tracking noise settings {self}')

    def _unit(self, rng: np.random.Generator, shape: tuple[int, int], fps: float
              ) -> np.ndarray:
        """Unit-variance noise: the slow AR(1) part plus the white part."""
        slow = ar1_noise(rng, shape, fps, self.correlation_s)
        fast = rng.normal(0.0, 1.0, shape)
        return np.sqrt(self.slow_share) * slow + np.sqrt(1.0 - self.slow_share) * fast

    def apply(self, rng: np.random.Generator, poses: np.ndarray, fps: float,
              model: HandModel) -> np.ndarray:
        """Noisy copies (N, 26) of true poses (N, 26). Finger joints are clipped into the
        limits, and the noise scale is set so the mean absolute finger error AFTER clipping
        is ``joint_mae_deg`` (clipping alone would shrink it near the limits)."""
        poses = np.asarray(poses, dtype=float)
        n = len(poses)
        out = poses.copy()
        unit = self._unit(rng, (n, NUM_FINGER_DOFS), fps)
        lo, hi = model.lower_limits[6:], model.upper_limits[6:]
        target = np.deg2rad(self.joint_mae_deg)
        scale = target * np.sqrt(np.pi / 2.0)        # Gaussian: MAE = sigma sqrt(2 / pi)
        for _ in range(8):
            fingers = np.clip(poses[:, 6:] + scale * unit, lo, hi)
            realised = float(np.abs(fingers - poses[:, 6:]).mean())
            if target == 0.0 or realised == 0.0:
                break
            scale *= target / realised
        out[:, 6:] = np.clip(poses[:, 6:] + scale * unit, lo, hi)
        sigma = np.deg2rad(self.rotation_mae_deg) * np.sqrt(np.pi / 2.0)
        turn = sigma * self._unit(rng, (n, 3), fps)
        out[:, 3:6] = (Rotation.from_rotvec(turn) * Rotation.from_rotvec(poses[:, 3:6])
                       ).as_rotvec()
        return out
