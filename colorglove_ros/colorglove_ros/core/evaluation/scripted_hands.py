"""Scripted hand-pose sequences with a tracking-noise model, for the gesture and spelling
evaluations (no rendering: these test what consumes the tracked pose, not the tracker).

A script is a list of segments: move from the previous segment's pose to this one with a
minimum-jerk profile (fingers and wrist position) and a slerp (wrist orientation), then hold
it. ``TrackingNoise`` then stands in for the tracker's errors: it is a MODEL, not errors
measured frame by frame. Each finger DOF gets a constant bias ``joint_bias_deg`` (none when
empty) plus Gaussian noise, its scale relative to the others set by ``joint_weights`` (equal
when empty), scaled so that the mean absolute error over all finger DOFs is
``joint_mae_deg``; the noise is split into a slowly varying part (an AR(1) process with
``correlation_s``; the tracker's errors come mostly from the lookup's bias, which persists
over frames) and white per-frame jitter; each axis of the wrist orientation (a small rotation
applied on the camera side) gets the same kind of noise with mean absolute value
``rotation_mae_deg``. Noisy joints are clipped into the model's limits, as the IK's are, with
the scale set so the error after clipping has the stated mean.

:func:`fit_tracking_noise` fits these settings to the tracker's measured errors (the tracker
run on rendered scripted sequences, ``core/evaluation/scripted_tracking.py``), and
:func:`save_tracking_noise` / :func:`load_tracking_noise` keep them in a versioned YAML file
(``config/tracking_noise.yaml``). What the model cannot hold: the tracker's errors depend on
the pose (a bias per hand shape), which is why the evaluations can also run on the tracker's
own output.
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Protocol

import numpy as np
from scipy.spatial.transform import Rotation, Slerp

from colorglove_ros.core.errors import ColorGloveError
from colorglove_ros.core.hand.frame_evidence import FrameEvidence
from colorglove_ros.core.hand.model import NUM_DOFS, NUM_FINGER_DOFS, HandModel
from colorglove_ros.core.hand.observation_features import (
    OBSERVATION_FEATURES,
    feature_set_features,
)
from colorglove_ros.core.synthetic.sequences import min_jerk
from colorglove_ros.core.yaml_io import load_yaml_mapping

__all__ = ['ScriptError', 'Segment', 'ScriptedSequence', 'TrackingNoise', 'script_poses',
           'observation_seen',
           'ar1_noise', 'PoseSource', 'fit_tracking_noise', 'save_tracking_noise',
           'load_tracking_noise', 'classify_holds', 'evidence_seen',
           'NOISE_FORMAT', 'NOISE_FORMAT_VERSION', 'NOISE_SEED_OFFSET', 'realised_joint_mae_deg']

NOISE_FORMAT = 'colorglove_tracking_noise'
NOISE_FORMAT_VERSION = 1
_MAX_FIT_LAG_S = 1.0      # autocorrelation lags the correlation time is fitted on
NOISE_SEED_OFFSET = 7919  # a sequence's noise is drawn with seed (sequence seed + this)


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


class PoseSource(Protocol):
    """What the gesture and spelling evaluations see of a scripted sequence: the noise model
    (:class:`TrackingNoise`) or the tracker (``scripted_tracking.ScriptedTracker``)."""

    def observe(self, name: str, seed: int, truth: ScriptedSequence, model: HandModel
                ) -> tuple[np.ndarray, np.ndarray]:
        """Observed poses (N, 26) and found flags (N,) of sequence ``name`` / ``seed``."""
        ...


def evidence_seen(source: PoseSource, name: str, seed: int, truth: ScriptedSequence,
                  model: HandModel) -> list[FrameEvidence | None]:
    """The tracker's evidence a consumer node pairs with each frame of sequence ``name`` /
    ``seed``: the frame's own status line (``frame_evidence.EvidencePairer``, by stamp); None
    for a lost frame and for a source that records no evidence (the noise model)."""
    record = getattr(source, 'evidence', None)
    n = len(truth.poses)
    if record is None:
        return [None] * n
    ev = record(name, seed, truth, model)
    return [FrameEvidence(float(c), float(r)) if np.isfinite(c) else None
            for c, r in zip(ev['constraints'], ev['reprojection_px'], strict=True)]



def observation_seen(source: PoseSource, name: str, seed: int, truth: ScriptedSequence,
                     model: HandModel, error: type[Exception] = ScriptError,
                     feature_set: str = OBSERVATION_FEATURES, seen: np.ndarray | None = None
                     ) -> np.ndarray:
    """The observation features (N, F; ``core.hand.observation_features``, of ``feature_set``)
    of every frame of sequence ``name`` / ``seed`` as ``source`` saw it, for an image
    classifier; the upright set turns each frame by the global rotation of its ``seen`` pose
    (N, 26; a frame without a finite one is turned as for a zero rotation vector: the detector
    reads such a frame as no hand and never scores its features). A
    source that records no observation (the noise model) is refused with ``error``."""
    record = getattr(source, 'observation', None)
    if record is None:
        raise error("an image classifier needs the frames' observation: run on the "
                          'tracker (--tracker)')
    rotvec = None
    if seen is not None:
        rotvec = np.asarray(seen, dtype=float)[:, 3:6].copy()
        rotvec[~np.all(np.isfinite(rotvec), axis=1)] = 0.0
    return feature_set_features(record(name, seed, truth, model), feature_set, rotvec)

@dataclass(frozen=True)
class TrackingNoise:
    """Tracking-error model (see the module docstring); ``slow_share`` is the slow part's
    share of the variance."""

    joint_mae_deg: float = 7.0
    rotation_mae_deg: float = 5.0
    slow_share: float = 0.8
    correlation_s: float = 0.4
    joint_weights: tuple[float, ...] = ()
    joint_bias_deg: tuple[float, ...] = ()

    def __post_init__(self) -> None:
        weights = np.asarray(self.joint_weights, dtype=float)
        bias = np.asarray(self.joint_bias_deg, dtype=float)
        if self.joint_mae_deg < 0 or self.rotation_mae_deg < 0 or \
                not 0.0 <= self.slow_share <= 1.0 or self.correlation_s < 0 or \
                weights.size not in (0, NUM_FINGER_DOFS) or np.any(~(weights >= 0)) or \
                bias.size not in (0, NUM_FINGER_DOFS) or not np.all(np.isfinite(bias)):
            raise ScriptError(f'bad tracking noise settings {self}')
        object.__setattr__(self, 'joint_weights', tuple(float(w) for w in weights))
        object.__setattr__(self, 'joint_bias_deg', tuple(float(b) for b in bias))

    def with_joint_mae(self, joint_mae_deg: float) -> TrackingNoise:
        """The same model at another overall finger-joint error (the bias scaled alike)."""
        ratio = joint_mae_deg / self.joint_mae_deg if self.joint_mae_deg > 0 else 0.0
        return TrackingNoise(joint_mae_deg, self.rotation_mae_deg, self.slow_share,
                             self.correlation_s, self.joint_weights,
                             tuple(ratio * b for b in self.joint_bias_deg))

    def observe(self, name: str, seed: int, truth: ScriptedSequence, model: HandModel
                ) -> tuple[np.ndarray, np.ndarray]:
        """What the consumers see of sequence ``seed`` (``name`` is unused here; the same
        interface as ``ScriptedTracker.observe``): noisy poses (N, 26), all found."""
        noisy = self.apply(np.random.default_rng(seed + NOISE_SEED_OFFSET), truth.poses,
                           truth.fps, model)
        return noisy, np.ones(len(noisy), dtype=bool)

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
        if self.joint_weights:
            unit = unit * np.asarray(self.joint_weights)
        bias = np.deg2rad(np.asarray(self.joint_bias_deg)) if self.joint_bias_deg else 0.0
        lo, hi = model.lower_limits[6:], model.upper_limits[6:]
        target = np.deg2rad(self.joint_mae_deg)
        scale = target * np.sqrt(np.pi / 2.0)        # Gaussian: MAE = sigma sqrt(2 / pi)
        for _ in range(12):
            fingers = np.clip(poses[:, 6:] + bias + scale * unit, lo, hi)
            realised = float(np.abs(fingers - poses[:, 6:]).mean())
            if target == 0.0 or realised == 0.0:
                break
            scale *= target / realised
        out[:, 6:] = np.clip(poses[:, 6:] + bias + scale * unit, lo, hi)
        sigma = np.deg2rad(self.rotation_mae_deg) * np.sqrt(np.pi / 2.0)
        turn = sigma * self._unit(rng, (n, 3), fps)
        out[:, 3:6] = (Rotation.from_rotvec(turn) * Rotation.from_rotvec(poses[:, 3:6])
                       ).as_rotvec()
        return out


def _runs(found: np.ndarray) -> list[slice]:
    """Slices of the runs of consecutive True frames."""
    edges = np.flatnonzero(np.diff(np.concatenate([[0], found.astype(np.int8), [0]])))
    return [slice(a, b) for a, b in zip(edges[0::2], edges[1::2], strict=True)]


def fit_tracking_noise(true_poses: Sequence[np.ndarray], tracked_poses: Sequence[np.ndarray],
                       found: Sequence[np.ndarray], fps: float) -> TrackingNoise:
    """Noise settings fitted to a tracker's errors over sequences (true and tracked poses
    (N, 26), found (N,)): the finger DOFs' overall mean absolute error and each DOF's share
    (``joint_weights``, the DOF's RMS error over the mean RMS), the wrist orientation's mean
    absolute error per axis, each finger DOF's mean error (``joint_bias_deg``; the RMS is
    about it), and from the errors' autocorrelation over runs of tracked frames
    (lags up to 1 s, fitted as ``slow_share * exp(-lag / correlation_s)``) the slow part."""
    from scipy.spatial.transform import Rotation

    fingers, turns, runs = [], [], []
    for q_true, q_est, ok in zip(true_poses, tracked_poses, found, strict=True):
        ok = np.asarray(ok, dtype=bool)
        error = np.asarray(q_est, dtype=float)[:, 6:] - np.asarray(q_true, dtype=float)[:, 6:]
        for run in _runs(ok):
            fingers.append(error[run])
            runs.append(error[run])
        turn = Rotation.from_rotvec(np.asarray(q_est)[ok, 3:6]) * \
            Rotation.from_rotvec(np.asarray(q_true)[ok, 3:6]).inv()
        turns.append(turn.as_rotvec())
    if not fingers:
        raise ScriptError('no tracked frame to fit the noise to')
    errors = np.concatenate(fingers)
    bias = errors.mean(axis=0)
    rms = np.sqrt(np.mean((errors - bias) ** 2, axis=0))
    lags = np.arange(1, max(2, int(round(_MAX_FIT_LAG_S * fps))) + 1)
    runs = [r - bias for r in runs]
    power = float(np.mean((errors - bias) ** 2))
    rho = []
    for lag in lags:
        pairs = [(r[:-lag] * r[lag:]).ravel() for r in runs if len(r) > lag]
        rho.append(float(np.mean(np.concatenate(pairs))) / power if pairs else np.nan)
    rho_arr = np.asarray(rho)
    usable = np.isfinite(rho_arr) & (rho_arr > 0.02)
    if usable.sum() >= 2:
        slope, intercept = np.polyfit(lags[usable], np.log(rho_arr[usable]), 1)
        slow_share = float(np.clip(np.exp(intercept), 0.0, 1.0))
        correlation_s = float(-1.0 / (slope * fps)) if slope < 0 else float(lags[-1] / fps)
    else:
        slow_share, correlation_s = 0.0, 0.0
    return TrackingNoise(joint_mae_deg=float(np.degrees(np.abs(errors).mean())),
                         rotation_mae_deg=float(np.degrees(np.abs(np.concatenate(turns)).mean())),
                         slow_share=slow_share, correlation_s=correlation_s,
                         joint_weights=tuple(rms / rms.mean()),
                         joint_bias_deg=tuple(np.degrees(bias)))


def save_tracking_noise(path: str | Path, noise: TrackingNoise, source: str) -> Path:
    """Write the settings as versioned YAML; ``source`` says what they were fitted to."""
    import yaml

    path = Path(path)
    data = {'format': NOISE_FORMAT, 'version': NOISE_FORMAT_VERSION, 'source': source,
            **{k: (list(v) if isinstance(v, tuple) else v) for k, v in asdict(noise).items()}}
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return path


def load_tracking_noise(path: str | Path) -> TrackingNoise:
    """Settings written by :func:`save_tracking_noise`; ``ScriptError`` for another format,
    version or bad settings."""
    data = load_yaml_mapping(path, ScriptError, 'tracking noise file')
    if data.get('format') != NOISE_FORMAT or data.get('version') != NOISE_FORMAT_VERSION:
        raise ScriptError(f'{path} is not a {NOISE_FORMAT} file of version '
                          f'{NOISE_FORMAT_VERSION} (format {data.get("format")!r}, version '
                          f'{data.get("version")!r})')
    keys = ('joint_mae_deg', 'rotation_mae_deg', 'slow_share', 'correlation_s', 'joint_weights',
            'joint_bias_deg')
    missing = [k for k in keys if k not in data]
    if missing:
        raise ScriptError(f'{path} lacks {", ".join(missing)}')
    try:
        return TrackingNoise(float(data['joint_mae_deg']), float(data['rotation_mae_deg']),
                             float(data['slow_share']), float(data['correlation_s']),
                             tuple(float(w) for w in data['joint_weights']),
                             tuple(float(b) for b in data['joint_bias_deg']))
    except (TypeError, ValueError) as exc:
        raise ScriptError(f'{path}: bad tracking noise settings: {exc}') from exc


def realised_joint_mae_deg(truth: np.ndarray, seen: np.ndarray, found: np.ndarray) -> float:
    """Mean absolute finger-joint error (deg) of the poses the consumers saw, found frames."""
    found = np.asarray(found, dtype=bool)
    if not found.any():
        return float('nan')
    return float(np.degrees(np.abs(seen[found, 6:] - truth[found, 6:])).mean())


def classify_holds(truth: ScriptedSequence, log_likelihoods: np.ndarray,
                   classes: Sequence[str], unlabelled: str = '') -> list[tuple[str, str]]:
    """(scripted, classified or '-') per scripted segment: the class of ``classes`` with the
    largest sum of the per-frame log-likelihoods (N, len(classes); NaN rows for lost frames)
    over the segment's hold frames (the classifier alone, knowing when the hold starts and
    ends); a segment labelled '' is reported as ``unlabelled``."""
    log_likelihoods = np.asarray(log_likelihoods, dtype=float)
    if log_likelihoods.shape != (len(truth.poses), len(classes)):
        raise ScriptError(f'log-likelihoods must be ({len(truth.poses)}, {len(classes)}), '
                          f'got {log_likelihoods.shape}')
    pairs = []
    for k in np.unique(truth.segment):
        frames = np.flatnonzero((truth.segment == k) & truth.holding)
        seen = log_likelihoods[frames]
        seen = seen[np.all(np.isfinite(seen), axis=1)]
        label = truth.label[np.flatnonzero(truth.segment == k)[0]] or unlabelled
        pairs.append((label, classes[int(np.argmax(seen.sum(axis=0)))] if len(seen) else '-'))
    return pairs
