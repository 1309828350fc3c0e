"""The real-scene ladder: the whole per-frame recipe (segmentation of rendered RGB frames, lookup,
IK with the nodes' gates) on synthetic sequences that look like a user's camera, one rung per
condition, so that each regression shows where it comes from.

A rung (:class:`SceneCondition`) names three things: the appearance of the frames
(``core.synthetic.conditions.scene_conditions``: clean, real photographs behind the hand,
sleeves, other cameras' colour processing, or all of them), the hand (the database's model, or
finger proportions varied +-10 % per digit with the hand length kept, the tracker either not
knowing them or given them as the user's hand calibration) and the motion (the desk motion of
``generate_sequence``, or ``border_crossing_sequence``: the hand entering and leaving across
every border). Every sequence ends with frames with no hand at all (the hand moved out of
view), and the border motion has more between its visits.

Each frame is classed from the renderer's ground truth: *fully visible* (all 21 hand keypoints
inside the image and no glove pixel on its border: the whole glove is in view), *no hand* (no
glove pixel in the image) or *partly visible*; the figures
(:func:`summarize_scene`) are those of the issue on real scenes. No rclpy import.
"""
from __future__ import annotations

import time
from collections import Counter
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from colorglove_ros.core.camera import PinholeCamera
from colorglove_ros.core.evaluation.metrics import fingertip_positions, translation_errors_mm
from colorglove_ros.core.evaluation.sequences import EvaluationError
from colorglove_ros.core.hand.model import NUM_DOFS, HandModel
from colorglove_ros.core.pipeline import (
    NODE_LIMITS,
    FramePipeline,
    NoHand,
    StageLimits,
    Tracked,
    primary_pixel_scale,
)
from colorglove_ros.core.segmentation.crop_prediction import (
    DEFAULT_PREDICTION_MAX_AGE_S,
    CropFeedback,
)

__all__ = [
    'SceneCondition', 'SCENE_LADDER', 'HAND_SHAPES', 'MOTIONS', 'FINGER_FACTOR_SPREAD',
    'NO_HAND_TAIL_FRACTION', 'OFF_POSE_MM', 'BORDER_DEPTH_MM', 'SceneRun', 'GateEvidence',
    'gate_evidence', 'STAGES', 'stage_poses', 'varied_finger_factors', 'fully_visible',
    'scene_poses', 'run_scene', 'summarize_scene', 'frame_records',
]

HAND_SHAPES = ('model', 'varied', 'varied_calibrated')
MOTIONS = ('desk', 'borders')
FINGER_FACTOR_SPREAD = 0.10       # per-digit length factors drawn from 1 +- this
NO_HAND_TAIL_FRACTION = 0.15      # share of each sequence's last frames without the hand
OFF_POSE_MM = 50.0                # a tracked frame this far off (mean fingertip) is wrong
BORDER_DEPTH_MM = 100.0           # depth error allowed on a hand cut by the image border
_AWAY = np.array([25.0, 0.0, 0.5])   # wrist position far out of every camera's view


@dataclass(frozen=True)
class SceneCondition:
    """One rung of the ladder: frame appearance, hand shape and motion."""

    name: str
    appearance: str
    hand: str = 'model'
    motion: str = 'desk'

    def __post_init__(self) -> None:
        if self.hand not in HAND_SHAPES or self.motion not in MOTIONS:
            raise EvaluationError(f'condition {self.name!r}: hand must be one of {HAND_SHAPES}'
                                  f' and motion one of {MOTIONS}')


SCENE_LADDER: tuple[SceneCondition, ...] = (
    SceneCondition('clean', 'clean'),
    SceneCondition('photos', 'photos'),
    SceneCondition('sleeve', 'sleeve'),
    SceneCondition('color_processing', 'color_processing'),
    SceneCondition('proportions', 'clean', hand='varied'),
    SceneCondition('proportions_calibrated', 'clean', hand='varied_calibrated'),
    SceneCondition('borders', 'clean', motion='borders'),
    SceneCondition('all', 'all', hand='varied_calibrated', motion='borders'),
)


def varied_finger_factors(seed: int) -> tuple[float, ...]:
    """Per-digit length factors (thumb..little) of sequence ``seed``'s hand, each drawn
    uniformly from 1 +- ``FINGER_FACTOR_SPREAD``, independently of the hand length."""
    rng = np.random.default_rng([seed, 31])
    return tuple(float(f) for f in 1.0 + rng.uniform(-FINGER_FACTOR_SPREAD,
                                                     FINGER_FACTOR_SPREAD, 5))


def scene_poses(condition: SceneCondition, seed: int, num_frames: int, camera: PinholeCamera,
                model: HandModel, fps: float = 30.0) -> np.ndarray:
    """(num_frames, 26) true poses of the rung's motion, the last
    ``NO_HAND_TAIL_FRACTION`` of them moved out of view (no hand in the frame)."""
    from colorglove_ros.core.synthetic.sequences import (
        border_crossing_sequence,
        generate_sequence,
    )

    if condition.motion == 'borders':
        poses, _ = border_crossing_sequence(seed, num_frames, fps, camera=camera, model=model)
    else:
        poses = generate_sequence(seed, num_frames, fps, camera=camera, model=model)
    tail = int(round(NO_HAND_TAIL_FRACTION * num_frames)) if num_frames >= 4 else 0
    if tail:
        poses[num_frames - tail:, 0:3] = _AWAY
    return poses


@dataclass(frozen=True)
class GateEvidence:
    """What one frame's gates saw: the outcome's reason ('' when tracked), the nearest
    database image's distance (tiny px; NaN without a lookup), and of the fit (NaN / 0 when
    none was made) the share of the glove blobs explained, the mean reprojection residual at
    the IK's reference focal length and the number of constraints."""

    reason: str
    image_distance: float
    explained_blob_share: float
    residual_px: float
    constraints: int


def gate_evidence(outcome: Tracked | NoHand, found: Any, tracker: Any) -> GateEvidence:
    """The :class:`GateEvidence` of one ``FramePipeline.process`` outcome, its lookup
    ``found`` (``FramePipeline.last_lookup``) and the ``tracker`` that fitted it."""
    result = outcome.result if isinstance(outcome, Tracked) else outcome.partial
    lookup = None if found is None else found.result
    if lookup is None and found is not None:     # refused by the lookup: its result
        lookup = getattr(found.outcome, 'partial', None)
    distances = np.asarray(getattr(lookup, 'distances', ()), float).reshape(-1)
    fitted = (getattr(result, 'q', None) is not None
              and hasattr(result, 'reprojection_error_px'))
    return GateEvidence(
        '' if isinstance(outcome, Tracked) else outcome.reason,
        float(distances[0]) if len(distances) else float('nan'),
        float(result.explained_blob_share) if fitted else float('nan'),
        float(result.reprojection_error_px) / primary_pixel_scale(tracker) if fitted
        else float('nan'),
        int(result.num_constraints) if fitted else 0)


STAGES = ('nearest', 'blend', 'prior', 'previous')
"""The poses of one frame's stages :func:`stage_poses` records: the nearest database entry
placed in the query's view, the lookup's blend, the IK prior q_b (the blend with its
translation refitted to the matched blobs) and the tracker's previous output."""


def stage_poses(outcome: Tracked | NoHand, found: Any, previous: np.ndarray | None
                ) -> dict[str, np.ndarray | None]:
    """The (26,) pose of every stage of :data:`STAGES` behind one ``FramePipeline.process``
    outcome (None where the stage made none): from its lookup ``found``
    (``FramePipeline.last_lookup``, also a refused one's result), the tracker's result (also a
    refused fit's) and ``previous``, the tracker's ``previous_pose`` before the frame."""
    lookup = None if found is None else found.result
    if lookup is None and found is not None:
        lookup = getattr(found.outcome, 'partial', None)
    result = outcome.result if isinstance(outcome, Tracked) else outcome.partial
    neighbours = np.asarray(getattr(lookup, 'poses', ()), float).reshape(-1, NUM_DOFS)

    def pose(value: Any) -> np.ndarray | None:
        return None if value is None else np.asarray(value, float).reshape(NUM_DOFS).copy()

    return {'nearest': neighbours[0].copy() if len(neighbours) else None,
            'blend': pose(getattr(lookup, 'blended', None)),
            'prior': pose(getattr(result, 'q_prior', None)),
            'previous': pose(previous)}


@dataclass
class SceneRun:
    """One sequence of one rung: truth, outputs and per-frame classes."""

    condition: str
    seed: int
    q_true: np.ndarray                  # (N, 26)
    q_est: np.ndarray                   # (N, 26), NaN where no pose was published
    tracked: np.ndarray                 # (N,) bool: a pose was published
    fully_visible: np.ndarray           # (N,) bool
    no_hand: np.ndarray                 # (N,) bool
    segmentation_ms: np.ndarray         # (N,) primary camera's segmentation wall time
    reasons: Counter                    # 'no hand' reasons on frames with a visible hand
    true_model: HandModel
    tracker_model: HandModel
    evidence: tuple[GateEvidence, ...] = ()   # per frame, :func:`gate_evidence`
    # per stage of STAGES, (N, 26) poses (NaN where the stage made none): :func:`stage_poses`
    stages: dict[str, np.ndarray] = field(default_factory=dict)


def fully_visible(labels: np.ndarray, keypoints_uv: np.ndarray) -> bool:
    """Whether the whole glove is in view: every hand keypoint (``keypoints_uv``, (K, 2)
    pixels) inside the truth label image ``labels`` and no glove pixel on its outermost rows
    or columns (there, part of the glove may be outside)."""
    h, w = labels.shape
    uv = np.asarray(keypoints_uv, float)
    inside = bool(np.all((uv[:, 0] >= 0) & (uv[:, 0] <= w - 1) & (uv[:, 1] >= 0)
                         & (uv[:, 1] <= h - 1)))
    on_border = bool(labels[0].any() or labels[-1].any() or labels[:, 0].any()
                     or labels[:, -1].any())
    return inside and bool(labels.any()) and not on_border


def run_scene(condition: SceneCondition, seed: int, num_frames: int, *, lookup: Any,
              camera: PinholeCamera, observer_factory: Callable[[CropFeedback], Any],
              tracker_factory: Callable[[Any], Any], hand_factory: Callable[[Any], Any],
              limits: StageLimits = NODE_LIMITS, fps: float = 30.0, split: str = 'test',
              prediction_max_age_s: float = DEFAULT_PREDICTION_MAX_AGE_S,
              progress: Callable[[int], None] | None = None) -> SceneRun:
    """Render and track one sequence of a rung.

    ``hand_factory(finger_factors or None)`` gives the (model, mesh, glove) of a hand with
    the database's hand length and glove; ``tracker_factory(hand)`` a fresh tracker for
    that hand; ``observer_factory(feedback)`` a fresh observer (``core.pipeline.image_observer``
    of a new segmenter: nothing carries over between sequences) reading the crop predictions
    of ``feedback``, which the pipeline feeds from each tracked frame (``CropFeedback`` with
    ``prediction_max_age_s``; 0 turns the feedback off), as the nodes do."""
    from colorglove_ros.core.synthetic.conditions import scene_conditions
    from colorglove_ros.core.synthetic.frames import Synthesizer

    factors = varied_finger_factors(seed) if condition.hand != 'model' else None
    true_hand = hand_factory(factors)
    tracker_hand = true_hand if condition.hand != 'varied' else hand_factory(None)
    synth = Synthesizer(hand=true_hand)
    try:
        poses = scene_poses(condition, seed, num_frames, camera, true_hand[0], fps)
        rng = np.random.default_rng([seed, 7, SCENE_LADDER.index(condition)
                                     if condition in SCENE_LADDER else 99])
        look = replace(scene_conditions(condition.appearance, rng, split),
                       distractors_avoid_hand=False)
        tracker = tracker_factory(tracker_hand)
        feedback = CropFeedback(prediction_max_age_s)
        observe = observer_factory(feedback)
        timed_ms: list[float] = []

        def timed(view: Any, primary: bool) -> Any:
            started = time.perf_counter()
            out = observe(view, primary)
            if primary:
                timed_ms.append(1e3 * (time.perf_counter() - started))
            return out

        pipeline = FramePipeline(timed, lookup, camera, limits=limits, feedback=feedback)
        n = len(poses)
        q_est = np.full((n, poses.shape[1]), np.nan)
        tracked = np.zeros(n, bool)
        fully = np.zeros(n, bool)
        empty = np.zeros(n, bool)
        reasons: Counter = Counter()
        evidence: list[GateEvidence] = []
        stages = {name: np.full((n, poses.shape[1]), np.nan) for name in STAGES}
        for i in range(n):
            frame = synth.render_frame(poses[i], camera, np.random.default_rng([seed, i, 11]),
                                       look)
            fully[i] = fully_visible(frame.labels,
                                     camera.project(true_hand[0].keypoints(poses[i])))
            empty[i] = not np.any(frame.labels)
            previous = getattr(tracker, 'previous_pose', None)
            outcome = pipeline.process(tracker, [frame.image_rgb], i / fps)
            evidence.append(gate_evidence(outcome, pipeline.last_lookup, tracker))
            for name, q in stage_poses(outcome, pipeline.last_lookup, previous).items():
                if q is not None:
                    stages[name][i] = q
            if isinstance(outcome, Tracked):
                tracked[i] = True
                q_est[i] = outcome.result.q
            elif not empty[i]:
                reasons[outcome.reason.split(':')[0]] += 1
            if progress is not None:
                progress(i)
        return SceneRun(condition.name, seed, poses, q_est, tracked, fully, empty,
                        np.array(timed_ms), reasons, true_hand[0], tracker_hand[0],
                        tuple(evidence), stages)
    finally:
        synth.release()


def summarize_scene(runs: Sequence[SceneRun]) -> dict[str, Any]:
    """The rung's figures over its sequences: fully visible frames tracked (share), no-hand
    frames with a pose (share and count), tracked frames more than ``OFF_POSE_MM`` off (mean
    fingertip error, absolute), fingertip error relative to the wrist and absolute (mean and
    median over tracked fully visible frames, mm), the largest wrist depth error of a pose
    published for a partly visible hand and how many exceed ``BORDER_DEPTH_MM``, the
    segmentation's median time and the commonest 'no hand' reasons on frames with a hand."""
    if not runs:
        raise EvaluationError('no sequence to summarise')
    visible = np.concatenate([r.fully_visible for r in runs])
    empty = np.concatenate([r.no_hand for r in runs])
    tracked = np.concatenate([r.tracked for r in runs])
    abs_err, rel_err, depth_err, partial = [], [], [], []
    for r in runs:
        sel = r.tracked & ~r.no_hand
        if not sel.any():
            continue
        est, truth = r.q_est[sel], r.q_true[sel]
        tips_est = fingertip_positions(r.tracker_model, est)
        tips_true = fingertip_positions(r.true_model, truth)
        abs_err.append(1e3 * np.linalg.norm(tips_est - tips_true, axis=2).mean(axis=1))
        rel_err.append(1e3 * np.linalg.norm((tips_est - est[:, None, 0:3])
                                            - (tips_true - truth[:, None, 0:3]),
                                            axis=2).mean(axis=1))
        depth_err.append(translation_errors_mm(est, truth)[1])
        partial.append(~r.fully_visible[sel])
    out: dict[str, Any] = {
        'frames': int(len(visible)), 'fully_visible_frames': int(visible.sum()),
        'no_hand_frames': int(empty.sum()),
        'visible_tracked': float(tracked[visible].mean()) if visible.any() else float('nan'),
        'no_hand_with_pose': float(tracked[empty].mean()) if empty.any() else float('nan'),
        'no_hand_with_pose_count': int(tracked[empty].sum()),
    }
    nan = float('nan')
    if abs_err:
        a, rel = np.concatenate(abs_err), np.concatenate(rel_err)
        d, part = np.concatenate(depth_err), np.concatenate(partial)
        vis = ~part
        out.update({
            'tracked_frames': int(len(a)),
            'off_50mm': float((a > OFF_POSE_MM).mean()),
            'fingertip_rel_wrist_mm': float(rel[vis].mean()) if vis.any() else nan,
            'fingertip_rel_wrist_median_mm': float(np.median(rel[vis])) if vis.any() else nan,
            'fingertip_mm': float(a[vis].mean()) if vis.any() else nan,
            'fingertip_median_mm': float(np.median(a[vis])) if vis.any() else nan,
            'partial_tracked_frames': int(part.sum()),
            'partial_depth_max_mm': float(d[part].max()) if part.any() else 0.0,
            'partial_depth_over_100mm': int((d[part] > BORDER_DEPTH_MM).sum()),
        })
    else:
        out.update({'tracked_frames': 0, 'off_50mm': nan, 'fingertip_rel_wrist_mm': nan,
                    'fingertip_rel_wrist_median_mm': nan, 'fingertip_mm': nan,
                    'fingertip_median_mm': nan, 'partial_tracked_frames': 0,
                    'partial_depth_max_mm': 0.0, 'partial_depth_over_100mm': 0})
    seg = np.concatenate([r.segmentation_ms for r in runs])
    out['segmentation_ms_median'] = float(np.median(seg)) if len(seg) else nan
    reasons: Counter = Counter()
    for r in runs:
        reasons.update(r.reasons)
    out['no_hand_reasons'] = dict(reasons.most_common(4))
    return out


def frame_records(run: SceneRun) -> list[dict[str, Any]]:
    """One record per frame of ``run``: its class (fully visible / partly visible / no hand),
    whether a pose was published, :class:`GateEvidence`, and for a published pose on a
    frame with a hand the fingertip errors per digit (thumb..little, absolute, mm), their mean
    (the figure ``OFF_POSE_MM`` is judged on) and the wrist depth error (estimate minus truth,
    mm): the frame-by-frame view behind :func:`summarize_scene`. On a frame with a hand, every
    stage of :data:`STAGES` that made a pose adds its mean fingertip error and wrist depth
    error against the same truth (``<stage>_mm``, ``<stage>_depth_mm``): which stage was
    already wrong."""
    records = []
    for i in range(len(run.q_true)):
        kind = ('no hand' if run.no_hand[i] else
                'fully visible' if run.fully_visible[i] else 'partly visible')
        rec: dict[str, Any] = {'condition': run.condition, 'seed': run.seed, 'frame': i,
                               'class': kind, 'tracked': bool(run.tracked[i])}
        if i < len(run.evidence):
            e = run.evidence[i]
            rec.update({'reason': e.reason, 'image_distance': e.image_distance,
                        'explained_blob_share': e.explained_blob_share,
                        'residual_px': e.residual_px, 'constraints': e.constraints})
        if run.tracked[i] and not run.no_hand[i]:
            tips = _fingertip_errors_mm(run, run.q_est[i], i)
            rec.update({'fingertip_mm': [float(t) for t in tips],
                        'fingertip_mean_mm': float(tips.mean()),
                        'depth_error_mm': float(1e3 * (run.q_est[i, 2] - run.q_true[i, 2]))})
        if not run.no_hand[i]:
            for name, poses in run.stages.items():
                if np.all(np.isfinite(poses[i])):
                    rec.update(_pose_errors(run, poses[i], i, name))
        records.append(rec)
    return records


def _fingertip_errors_mm(run: SceneRun, q: np.ndarray, i: int) -> np.ndarray:
    """Per-digit fingertip errors (5,), mm, of pose ``q`` (of ``run``'s tracker's hand)
    against frame ``i``'s truth (of the true hand)."""
    return 1e3 * np.linalg.norm(fingertip_positions(run.tracker_model, q[None])[0]
                                - fingertip_positions(run.true_model, run.q_true[i:i + 1])[0],
                                axis=1)


def _pose_errors(run: SceneRun, q: np.ndarray, i: int, name: str) -> dict[str, float]:
    """Mean fingertip error (mm) and wrist depth error (estimate minus truth, mm) of pose
    ``q`` (of ``run``'s tracker's hand) against frame ``i``'s truth, keyed by ``name``."""
    return {f'{name}_mm': float(_fingertip_errors_mm(run, q, i).mean()),
            f'{name}_depth_mm': float(1e3 * (q[2] - run.q_true[i, 2]))}
