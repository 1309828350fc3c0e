"""Per-frame tracking pipeline on synthetic sequences (labels, crop, lookup, IK) and its figures."""
from __future__ import annotations

import dataclasses
import json
import math
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from colorglove_ros.core.camera import PinholeCamera
from colorglove_ros.core.errors import ColorGloveError
from colorglove_ros.core.evaluation.metrics import (
    LOCAL_WINDOW,
    contiguous_runs,
    jitter_runs_mm,
    latency_summary_ms,
    pose_accuracy,
)
from colorglove_ros.core.hand.handedness import (
    DEFAULT_HAND,
    check_hand,
    from_right_frame,
    mirror_points,
    mirrored_observer,
    to_right_frame,
)
from colorglove_ros.core.hand.model import NUM_DOFS, HandModel
from colorglove_ros.core.hand.observation_features import (
    empty_observation_record,
    write_observation,
)
from colorglove_ros.core.pipeline import (
    NODE_LIMITS,
    UNGATED,
    FramePipeline,
    Observer,
    StageLimits,
    TemporalPrior,
    Tracked,
    glove_seen,
    image_observer,
)
from colorglove_ros.core.segmentation.blobs import extract_blobs
from colorglove_ros.core.segmentation.crop import TinyCrop, crop_to_tiny
from colorglove_ros.core.tracking.config import TRACKER_MODES, IKConfig
from colorglove_ros.core.tracking.covariance_learning import TrainingFrame, training_frame
from colorglove_ros.core.tracking.line_constraints import glove_edge_image
from colorglove_ros.core.tracking.tracker import HandTracker, IKResult
from colorglove_ros.core.tracking.types import CameraObservation

__all__ = [
    'open_database_for_calibration',
    'LABEL_SOURCES', 'EVAL_SEED_BASE', 'TRAIN_SEED_BASE', 'SEED_SPAN', 'EvaluationError',
    'eval_seeds', 'train_seeds', 'observe_camera', 'truth_observer',
    'segmenter_observer', 'make_observer', 'TrackedSequence',
    'SequenceEvaluator', 'same_camera', 'jitter_runs_mm', 'contiguous_runs', 'summarize',
    'training_sequences', 'find_database', 'open_database', 'EvaluationSequence',
    'EVIDENCE_FIELDS', 'record_observation',
]

# The tracker's evidence per tracked frame (SequenceEvaluator with evidence=True): the
# lookup's nearest database image distance (tiny px), the share of the primary camera's glove
# blobs the fit explains, the mean reprojection error of its matched constraints (px), the
# number of constraints, and the share of the glove the fit shows that has no blob of its
# colour near it (the nodes' missing-glove measure, core.pipeline.glove_seen with NODE_LIMITS).
EVIDENCE_FIELDS = ('image_distance', 'explained_blob_share', 'reprojection_px', 'constraints',
                   'missing_glove_share')

def record_observation(record: dict[str, np.ndarray], i: int, seen: Any) -> None:
    """Frame ``i``'s primary observation (``FrameObservations``; nothing without a crop) into
    an observation record (``observation_features.empty_observation_record``)."""
    if seen.tiny is not None and seen.cameras:
        write_observation(record, i, seen.tiny.labels, seen.tiny.transform,
                          seen.cameras[0].blobs)


LABEL_SOURCES = ('truth', 'segmented')
# Sequence seeds (core.synthetic.sequences.generate_sequence): evaluation uses
# EVAL_SEED_BASE + k, training (learn_ik_covariances) TRAIN_SEED_BASE + k, k < SEED_SPAN:
# disjoint sets. Evaluation frames
# use the synthesiser's 'test' imaging conditions, training frames the 'train' ones.
EVAL_SEED_BASE = 0
TRAIN_SEED_BASE = 100_000
SEED_SPAN = 100_000


class EvaluationError(ColorGloveError):
    """Bad evaluation input: unknown label source, mismatched rigs, no database, no frames."""


def eval_seeds(count: int, offset: int = 0) -> list[int]:
    """``count`` evaluation sequence seeds from ``offset`` (0, 1, ... by default). The
    reported figures use offset 0; IK settings are tuned on another offset (e.g. 1000), so
    the reported seeds are never the ones tuned on."""
    if not 0 < count <= SEED_SPAN or not 0 <= offset <= SEED_SPAN - count:
        raise EvaluationError(f'need 1..{SEED_SPAN} sequences inside [0, {SEED_SPAN}), got '
                              f'{count} from {offset}')
    return [EVAL_SEED_BASE + offset + k for k in range(count)]


def train_seeds(count: int) -> list[int]:
    """The first ``count`` training sequence seeds (100000, 100001, ...)."""
    if not 0 < count <= SEED_SPAN:
        raise EvaluationError(f'need 1..{SEED_SPAN} sequences, got {count}')
    return [TRAIN_SEED_BASE + k for k in range(count)]


@dataclass(frozen=True)
class EvaluationSequence:
    """One synthetic evaluation sequence: its true poses and imaging conditions (fixed per
    sequence, from its seed). Frame ``i`` renders with its own noise seed, so any subset of
    frames renders exactly as in the full run."""

    seed: int
    poses: np.ndarray           # (N, 26) true poses in the primary camera's frame
    conditions: Any             # core.synthetic.conditions imaging conditions
    synthesizer: Any

    @classmethod
    def make(cls, seed: int, num_frames: int, camera: PinholeCamera, synthesizer: Any,
             split: str = 'test', fps: float = 30.0) -> EvaluationSequence:
        """Sequence ``seed`` (``core.synthetic.sequences.generate_sequence``) with ``split``
        conditions. For a left-hand synthesiser it is the mirrored sequence: every pose and
        the light direction mirrored (``core.hand.handedness``), the background not."""
        from colorglove_ros.core.synthetic.conditions import sample_conditions
        from colorglove_ros.core.synthetic.sequences import generate_sequence

        poses = generate_sequence(seed, num_frames, fps, camera=camera, model=synthesizer.model)
        conditions = sample_conditions(np.random.default_rng([seed, 7]), split)
        hand = getattr(synthesizer, 'handedness', DEFAULT_HAND)
        if hand != DEFAULT_HAND:
            poses = from_right_frame(poses, hand)
            conditions = replace(conditions, light_dir=tuple(
                float(v) for v in mirror_points(np.asarray(conditions.light_dir, float))))
        return cls(seed, poses, conditions, synthesizer)

    def render(self, index: int, cameras: Sequence[PinholeCamera]) -> list[Any]:
        """Frame ``index`` as every camera sees it (primary first)."""
        from colorglove_ros.core.synthetic.frames import render_frames_multi

        rng = np.random.default_rng([self.seed, index, 11])
        return render_frames_multi(self.poses[index], cameras, rng, self.conditions,
                                   synthesizer=self.synthesizer)


# ---------------------------------------------------------------------------- observations
def observe_camera(labels: np.ndarray, primary: bool, min_blob_pixels: int = 4
                   ) -> tuple[CameraObservation, TinyCrop | None]:
    """A camera's observation from its label image: blobs, the glove mask (the edge image of
    the IK's optional line features), and for the primary camera the
    mean-shift crop (``crop_to_tiny``) whose transform the IK needs. Not found when the
    crop fails (primary) or no blob is large enough."""
    blobs = extract_blobs(labels, min_blob_pixels)
    tiny = crop_to_tiny(labels) if primary else None
    found = len(blobs) > 0 and (tiny is not None or not primary)
    return CameraObservation(found, blobs, tiny.transform if tiny is not None else None,
                             edge_image=glove_edge_image(labels)), tiny


def truth_observer(min_blob_pixels: int = 4) -> Observer:
    """Observations from the renderer's ground-truth labels (judges the IK and lookup
    apart from the colour segmentation)."""
    def observe(frame: Any, primary: bool) -> tuple[CameraObservation, TinyCrop | None]:
        return observe_camera(np.asarray(frame.labels, np.uint8), primary, min_blob_pixels)
    return observe


def segmenter_observer(segmenter: Any) -> Observer:
    """Observations from the colour segmentation of the rendered RGB image
    (``core.pipeline.observe_image``: ``GloveSegmenter.process`` and its checks)."""
    return image_observer(segmenter, lambda frame: frame.image_rgb)


def make_observer(labels: str, color_config: str | Path | None = None,
                  min_blob_pixels: int = 4) -> Observer:
    """'truth' (renderer labels) or 'segmented' (``core.segmentation.segmenter.load_segmenter`` on
    ``color_config``; raises the segmentation's error when its calibration file is missing).
    Without ``color_config``: the package's ``config/color_calibration.yaml``, whose calibration
    is fitted on rendered frames first if it is missing, as the demo does."""
    if labels == 'truth':
        return truth_observer(min_blob_pixels)
    if labels == 'segmented':
        from colorglove_ros.core.segmentation.calibration_fit import prepared_color_config
        from colorglove_ros.core.segmentation.segmenter import load_segmenter

        path = prepared_color_config(color_config)
        return segmenter_observer(load_segmenter(str(path)))
    raise EvaluationError(f'unknown label source {labels!r}, expected one of {LABEL_SOURCES}')


@dataclass
class TrackedSequence:
    """One tracker's outputs over one sequence, with the ground truth (primary frame)."""

    seed: int
    rig: str
    mode: str
    q_true: np.ndarray                       # (N, 26)
    q_est: np.ndarray                        # (N, 26), NaN rows where not found
    found: np.ndarray                        # (N,) bool
    reprojection_px: np.ndarray              # (N,) NaN when no constraint
    ik_ms: np.ndarray                        # (N,) tracker wall time (matching + IK)
    ik_cpu_ms: np.ndarray                    # (N,) the same as thread CPU time
    lookup_ms: np.ndarray                    # (N,) shared lookup time
    iterations: np.ndarray                   # (N,)
    constraints: np.ndarray                  # (N,)
    results: list[IKResult | None] = field(default_factory=list)
    hand: str = DEFAULT_HAND                 # whose poses q_true and q_est are
    # the tracker's evidence per frame (:data:`EVIDENCE_FIELDS`; NaN where not found), kept
    # when the evaluator was made with ``evidence=True``
    evidence: dict[str, np.ndarray] = field(default_factory=dict)
    # the primary camera's observation per frame (:func:`empty_observation_record`), kept when
    # the evaluator was made with ``observation=True``
    observation: dict[str, np.ndarray] = field(default_factory=dict)


def same_camera(a: PinholeCamera, b: PinholeCamera) -> bool:
    """Same image size, intrinsics, distortion and extrinsics."""
    return (a.width == b.width and a.height == b.height
            and np.allclose([a.fx, a.fy, a.cx, a.cy], [b.fx, b.fy, b.cx, b.cy])
            and np.allclose(a.distortion, b.distortion) and np.allclose(a.rotation, b.rotation)
            and np.allclose(a.translation, b.translation))


class SequenceEvaluator:
    """Renders seeded synthetic sequences once with every camera of the largest rig and runs
    the per-frame recipe (``core.pipeline.FramePipeline``): the observations, the lookup once
    per frame on the primary camera, and one :class:`HandTracker` per (rig, mode), optionally
    with the lookup's neighbours reweighted by that tracker's previous output (``temporal``).
    With ``finger_evidence`` (default) the lookup also gets the primary camera's blobs and
    blends each finger by its own patch evidence (``core.lookup.finger_evidence``). ``limits``
    are the pipeline's gates (default ``UNGATED``: every output of the tracker counts). Every
    rig must be a prefix of the largest one (same primary camera), so all rows of a table see
    identical frames and lookups.

    ``hand`` 'left': the mirrored sequences rendered with the left glove, tracked by the
    right-hand lookup and trackers on the mirrored query (``handedness.mirrored_observer``;
    one camera) and the poses mirrored back."""

    def __init__(self, lookup: Any, rigs: Mapping[str, Sequence[PinholeCamera]],
                 modes: Sequence[str] = TRACKER_MODES, ik_config: IKConfig | None = None,
                 observer: Observer | None = None, synthesizer: Any = None,
                 fps: float = 30.0, keep_results: bool = False,
                 temporal: TemporalPrior | None = None, finger_evidence: bool = True,
                 limits: StageLimits = UNGATED, hand: str = DEFAULT_HAND,
                 evidence: bool = False, observation: bool = False) -> None:
        from colorglove_ros.core.synthetic.frames import Synthesizer

        self.hand = check_hand(hand)
        self.evidence = bool(evidence)
        self.observation = bool(observation)

        if not rigs:
            raise EvaluationError('need at least one camera rig')
        for m in modes:
            if m not in TRACKER_MODES:
                raise EvaluationError(f'unknown mode {m!r}, expected one of {TRACKER_MODES}')
        self.rigs = {name: tuple(cams) for name, cams in rigs.items()}
        self.cameras = max(self.rigs.values(), key=len)
        for name, cams in self.rigs.items():
            if not cams or not all(same_camera(a, b) for a, b in zip(cams, self.cameras,
                                                                      strict=False)):
                raise EvaluationError(f'rig {name!r} is not a prefix of the largest rig '
                                      '(the lookup runs once on a shared primary camera)')
        self.modes = tuple(modes)
        self.config = ik_config or IKConfig()
        if synthesizer is None:      # the hand and glove the lookup's database was built with
            build = lookup.db.build
            synthesizer = Synthesizer(build.hand_length_m, build.glove_seed,
                                      handedness=self.hand)
        if getattr(synthesizer, 'handedness', DEFAULT_HAND) != self.hand:
            raise EvaluationError(f'the synthesiser renders a {synthesizer.handedness} hand, '
                                  f'the evaluation is of a {self.hand} hand')
        self.synth = synthesizer
        self.fps = float(fps)
        self.keep_results = keep_results
        if temporal is not None and finger_evidence:
            # reweight_by_previous re-blends every DOF with one weight per neighbour
            raise EvaluationError('temporal reweighting re-blends the fingers with one weight '
                                  'per neighbour: use it without the per-finger blend')
        observer = observer or truth_observer(self.config.min_blob_pixels)
        if self.hand != DEFAULT_HAND:
            if len(self.cameras) != 1:
                raise EvaluationError('a left hand is evaluated with one camera (its mirrored '
                                      'query is defined for one camera)')
            observer = mirrored_observer(observer, self.cameras[0].cx)
        self.pipeline = FramePipeline(observer,
                                      lookup, self.cameras[0], limits=limits,
                                      finger_evidence=finger_evidence, temporal=temporal)
        self.trackers = {(r, m): HandTracker(self.synth.model, self.synth.mesh, cams,
                                             self.config.with_mode(m), glove=self.synth.glove)
                         for r, cams in self.rigs.items() for m in self.modes}

    @property
    def model(self) -> HandModel:
        """The hand model of the synthesiser (and the trackers)."""
        return self.synth.model

    def run(self, seed: int, num_frames: int, split: str = 'test',
            progress: Callable[[int], None] | None = None, poses: np.ndarray | None = None
            ) -> dict[tuple[str, str], TrackedSequence]:
        """Track sequence ``seed`` (``generate_sequence``, or the given true ``poses`` (N, 26)
        in the primary camera's frame, e.g. a scripted sequence; conditions from ``split``,
        fixed per sequence; noise per frame) with every (rig, mode)."""
        if num_frames < 1:
            raise EvaluationError(f'need at least one frame, got {num_frames}')
        sequence = EvaluationSequence.make(seed, num_frames, self.cameras[0], self.synth,
                                           split, self.fps)
        if poses is not None:
            sequence = dataclasses.replace(sequence, poses=np.asarray(poses, dtype=float))
        Q = sequence.poses
        n = len(Q)
        out = {key: TrackedSequence(seed, key[0], key[1], Q.copy(),
                                    np.full((n, NUM_DOFS), np.nan), np.zeros(n, bool),
                                    np.full(n, np.nan), np.full(n, np.nan),
                                    np.full(n, np.nan), np.zeros(n),
                                    np.zeros(n, np.int64), np.zeros(n, np.int64),
                                    hand=self.hand)
               for key in self.trackers}
        if self.evidence:
            for ts in out.values():
                ts.evidence = {k: np.full(n, np.nan) for k in EVIDENCE_FIELDS}
        if self.observation:
            for ts in out.values():
                ts.observation = empty_observation_record(n)
        for tr in self.trackers.values():
            tr.reset()
        for i in range(n):
            seen = self.pipeline.observe(sequence.render(i, self.cameras))
            found = self.pipeline.look_up(seen)
            if self.observation:
                for ts in out.values():
                    record_observation(ts.observation, i, seen)
            for key, tracker in self.trackers.items():
                c0 = time.thread_time()
                outcome = self.pipeline.track(tracker, found, seen, i / self.fps)
                cpu_ms = 1e3 * (time.thread_time() - c0)
                ts = out[key]
                ts.lookup_ms[i] = found.time_ms
                tracked = isinstance(outcome, Tracked)
                res = outcome.result if tracked else outcome.partial
                if self.keep_results:
                    ts.results.append(res)
                if tracked:
                    ts.found[i] = True
                    ts.q_est[i] = from_right_frame(res.q, self.hand)
                    ts.reprojection_px[i] = res.reprojection_error_px
                    ts.ik_ms[i] = res.time_ms
                    ts.ik_cpu_ms[i] = cpu_ms
                    ts.iterations[i] = res.iterations
                    ts.constraints[i] = res.num_constraints
                    if self.evidence:
                        self._record_evidence(ts.evidence, i, tracker, res, found, seen)
            if progress is not None:
                progress(i)
        return out

    @staticmethod
    def _record_evidence(evidence: dict[str, np.ndarray], i: int, tracker: HandTracker,
                         res: IKResult, found: Any, seen: Any) -> None:
        """Frame ``i``'s :data:`EVIDENCE_FIELDS` of the tracked result ``res``."""
        lookup = found.result
        if lookup is not None and len(lookup.distances):
            evidence['image_distance'][i] = float(lookup.distances[0])
        evidence['explained_blob_share'][i] = res.explained_blob_share
        evidence['reprojection_px'][i] = res.reprojection_error_px
        evidence['constraints'][i] = res.num_constraints
        glove = glove_seen(tracker, res.q, seen.cameras[0], NODE_LIMITS)
        if glove is not None:
            evidence['missing_glove_share'][i] = glove.missing_share

    def close(self) -> None:
        """Free the renderer's GL contexts."""
        self.synth.release()


# ---------------------------------------------------------------------------- figures
def summarize(model: HandModel, runs: Sequence[TrackedSequence]) -> dict[str, float]:
    """Figures of one (rig, mode) over sequences: ``metrics.pose_accuracy`` on the tracked
    frames (joint MAE deg, fingertip / wrist image-plane / depth error mm), jitter as the
    fingertips' mean distance from their 5-frame local average over runs of tracked frames
    (and the same for the true motion), mean reprojection error of the matched constraints
    (px), the fingertip error split (``metrics.fingertip_error_split_mm``: in the hand frame,
    and from the wrist rotation alone), tracker time per frame (wall and thread CPU, mean and
    p95 ms) and the tracked fraction. A left hand's figures are those of its mirror image
    (the right model at the mirrored poses): mirroring keeps every distance and angle."""
    if not runs:
        raise EvaluationError('no sequence to summarise')
    runs = [replace(r, q_est=to_right_frame(r.q_est, r.hand),
                    q_true=to_right_frame(r.q_true, r.hand), hand=DEFAULT_HAND) for r in runs]
    est = np.concatenate([r.q_est[r.found] for r in runs])
    truth = np.concatenate([r.q_true[r.found] for r in runs])
    frames = int(sum(len(r.found) for r in runs))
    tracked = len(est)
    out: dict[str, float] = {'frames': frames, 'tracked_fraction': tracked / max(frames, 1)}
    if tracked == 0:
        return out
    acc = pose_accuracy(model, est, truth)
    for key in ('joint_mae_deg', 'fingertip_mm', 'fingertip_rel_wrist_mm',
                'fingertip_hand_frame_mm', 'fingertip_rotation_only_mm', 'wrist_plane_mm',
                'wrist_depth_mm'):
        out[key] = acc[key]
    jit, jit_true, w = 0.0, 0.0, 0
    for r in runs:
        j = jitter_runs_mm(model, r.q_est, r.found)
        if math.isfinite(j):
            n = int(r.found.sum())
            jit += j * n
            jit_true += jitter_runs_mm(model, r.q_true, r.found) * n
            w += n
    out['jitter_mm'] = jit / w if w else math.nan
    out['jitter_truth_mm'] = jit_true / w if w else math.nan
    rep = np.concatenate([r.reprojection_px[r.found] for r in runs])
    out['reprojection_px'] = float(np.nanmean(rep)) if np.isfinite(rep).any() else math.nan
    ik = latency_summary_ms(1e-3 * np.concatenate([r.ik_ms[r.found] for r in runs]))
    out['ik_ms_mean'] = ik['mean']
    out['ik_ms_p95'] = ik['p95']
    cpu = latency_summary_ms(1e-3 * np.concatenate([r.ik_cpu_ms[r.found] for r in runs]))
    out['ik_cpu_ms_mean'] = cpu['mean']
    out['ik_cpu_ms_p95'] = cpu['p95']
    lk = np.concatenate([r.lookup_ms[r.found] for r in runs])
    out['lookup_ms_mean'] = float(lk.mean())
    out['iterations_mean'] = float(np.concatenate([r.iterations[r.found] for r in runs]).mean())
    out['constraints_mean'] = float(
        np.concatenate([r.constraints[r.found] for r in runs]).mean())
    return out


def training_sequences(run: TrackedSequence, with_truth: bool = False,
                       window: int = LOCAL_WINDOW) -> list[list[TrainingFrame]]:
    """Training frames (``covariance_learning.training_frame``) of a run made with
    ``keep_results=True``, split into runs of consecutive tracked frames of at least
    ``window`` frames; with ``with_truth`` each frame carries its ground-truth pose."""
    if len(run.results) != len(run.found):
        raise EvaluationError('the run kept no tracker results (use keep_results=True)')
    out = []
    for a, b in contiguous_runs(run.found):
        if b - a >= window:
            out.append([training_frame(run.results[i], run.q_true[i] if with_truth else None)
                        for i in range(a, b)])
    return out


def find_database(root: str | Path) -> Path | None:
    """The pose database directory with the most entries directly under ``root`` (or
    ``root`` itself), by the ``num_entries`` of its manifest; None if there is none."""
    root = Path(root)
    best: tuple[int, Path] | None = None
    for cand in [root, *sorted(p for p in root.glob('*') if p.is_dir())] if root.is_dir() else []:
        manifest = cand / 'manifest.json'
        if not manifest.is_file():
            continue
        try:
            data = json.loads(manifest.read_text())
        except (OSError, json.JSONDecodeError):
            continue
        if isinstance(data, dict) and data.get('format') == 'colorglove_pose_database':
            n = int(data.get('num_entries', 0))
            if best is None or n > best[0]:
                best = (n, cand)
    return None if best is None else best[1]


def open_database(path: str | Path | None, root: str | Path) -> tuple[Path, Any]:
    """The pose database at ``path``, or else the largest under ``root`` (see
    :func:`find_database`), loaded; :class:`EvaluationError` if there is none."""
    from colorglove_ros.core.lookup.database import load_database

    db_path = Path(path) if path else find_database(root)
    if db_path is None:
        raise EvaluationError(f'no pose database under {root}: build one with '
                              'colorglove_build_database')
    return db_path, load_database(db_path)


def open_database_for_calibration(path: str | Path | None, root: str | Path,
                                  calibration_file: str | Path) -> tuple[Path, Any, Any]:
    """:func:`open_database` and the camera calibration at ``calibration_file``: (database
    path, database, calibration); :class:`DatabaseError` when they disagree on the hand
    length."""
    from colorglove_ros.core.camera import load_calibration
    from colorglove_ros.core.lookup.database import DatabaseBuild, check_hand_length

    db_path, db = open_database(path, root)
    calibration = load_calibration(calibration_file)
    build = DatabaseBuild.from_meta(db.meta, str(db_path))
    check_hand_length(build, calibration.hand_length_m, str(calibration_file), str(db_path))
    return db_path, db, calibration
