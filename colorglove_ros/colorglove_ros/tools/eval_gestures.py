"""Evaluate gesture events (``core/hand/gestures.py``) on scripted synthetic pose sequences.

Each sequence is a script of episodes (``core/evaluation/scripted_hands.py``): the hand moves
(minimum jerk, 0.3-0.6 s) into a shape and holds it (0.6-1.5 s). A shape is one of the seven
gestures or a neutral shape that is none of them (relaxed hand, half fist, claw, two or three
fingers out, ...); the same gesture never follows itself. Gesture shapes come from the pose
collection (``GESTURE_SHAPES`` and ``LETTER_SHAPES``: fist, A, S, E, M, N, T, thumbs-up for
grab; point, L, G, Z for point; flat, spread, B, four, thumb tucked for the open hand) and,
for pinches of each finger, from poses solved so the thumb tip comes 4-9 % of the hand length
from that fingertip. Every episode adds 3 deg of Gaussian variation per finger DOF (how the
same gesture differs from one time to the next). The detector sees the poses through
``TrackingNoise`` (a model of the tracker's errors; the default mean absolute joint error is
7 deg, see that module), so this measures the gesture logic under tracking-like noise, not
the tracker on rendered images.

Scores: a ``start`` event of gesture g is a true positive when it falls inside an episode of
g (from the start of the move into it until 0.3 s after its hold ends) that no earlier event
matched; every other start of g is a false positive (a start during another gesture's episode
or a neutral shape, or a second start in one episode). Precision = true / all starts,
recall = matched episodes / episodes, per gesture and over all. Frame figures: the share of
hold frames (from 0.2 s into the hold) on which the held gesture is active, and on which any
other gesture is. Hold accuracy (with a classifier) separates the classifier from the
hysteresis, as ``colorglove_eval_spelling``'s does: each scripted hold is classified once by the
sum of its frames' class log-probabilities (``scripted_hands.classify_holds``), per gesture, and
the share of neutral holds classified as a gesture.

With ``--tracker`` the detector is given what ``gesture_node`` would be: the poses the
nodes publish (a frame lookup_node or ik_node refuses, e.g. a hand the image's border cuts,
reaches it as no hand; ``--ungated``: every output of the tracker, as before session 31).

With ``--tracker`` and ``--image-classifier FILE`` (``colorglove_train_hand_classifiers --what
gesture_images``; default none) the detector also reads each frame's observation (the tiny
label image and blobs the tracker got, recorded in the tracking cache) through that image
classifier, combined with the pose classifier (``--image-weight``, default the core's); the
noise model has no image.

Episodes in view: an episode whose true hand keypoints all project inside the image (the
tracker's primary camera, ``config/calibration.yaml``) on every frame of its hold. Recall is
also given over these alone (``recall_in_view``), a figure for what a camera can see; the
targets are judged on every episode.

Thresholds were tuned on seeds 0-4; the default report seeds 100-109 were not used for tuning.
"""
from __future__ import annotations

import dataclasses
from collections.abc import Sequence

import numpy as np
from scipy.optimize import least_squares

from colorglove_ros.core.camera import PinholeCamera, load_calibration
from colorglove_ros.core.evaluation.scripted_hands import (
    PoseSource,
    ScriptedSequence,
    Segment,
    TrackingNoise,
    classify_holds,
    evidence_seen,
    observation_seen,
    realised_joint_mae_deg,
    script_poses,
)
from colorglove_ros.core.evaluation.targets import target_row
from colorglove_ros.core.hand.frame_evidence import EvidenceGate
from colorglove_ros.core.hand.gestures import (
    DEFAULT_GESTURE_CLASSIFIER,
    DEFAULT_GESTURE_IMAGE_CLASSIFIER,
    GESTURE_FEATURES,
    GESTURE_NAMES,
    NO_GESTURE,
    PINCH_FINGERS,
    GestureConfig,
    GestureDetector,
    GestureError,
    GestureEvent,
    gesture_features,
)
from colorglove_ros.core.hand.model import DIP_PIP_RATIO, HandModel
from colorglove_ros.core.hand.pose_classifier import PoseClassifier, pose_features
from colorglove_ros.core.hand.poses import (
    GESTURE_SHAPES,
    LETTER_SHAPES,
    finger_limits,
    full_pose,
    sample_global_rotations,
)
from colorglove_ros.core.report import print_table
from colorglove_ros.paths import share_dir
from colorglove_ros.tools._cli import ScriptedSettings, run_scripted_evaluation

__all__ = ['SETTINGS', 'GESTURE_EXEMPLARS', 'NEUTRAL_SHAPES', 'pinch_shape',
           'gesture_script', 'segments_in_view', 'score_events', 'evaluate', 'main']

TARGET = 0.95
SETTINGS = ScriptedSettings(tuning_seeds=tuple(range(5)), default_seeds=tuple(range(100, 110)),
                            unit='episodes', default_count=60,
                            classifier=DEFAULT_GESTURE_CLASSIFIER, feature_set=GESTURE_FEATURES,
                            evidence_gate=GestureConfig().evidence,
                            image_classifier=DEFAULT_GESTURE_IMAGE_CLASSIFIER)
MATCH_GRACE_S = 0.3
HOLD_SETTLE_S = 0.2
VARIATION_DEG = 3.0
NEUTRAL_SHARE = 0.3

_SHAPES = {**GESTURE_SHAPES, **{f'letter_{k}': v for k, v in LETTER_SHAPES.items()}}
GESTURE_EXEMPLARS: dict[str, tuple[str, ...]] = {
    'grab': ('fist', 'letter_A', 'letter_S', 'letter_E', 'letter_M', 'letter_N', 'letter_T',
             'thumbs_up'),
    'point': ('point', 'letter_L', 'letter_G', 'letter_Z'),
    'open_hand': ('flat', 'spread', 'letter_B', 'four', 'thumb_tuck'),
}
# Neutral shapes are none of the gestures by the definitions (no thumb tip near a fingertip,
# no curl near a threshold). Shapes where the thumb rests on a fingertip (half fist, claw, the
# victory sign's thumb on the ring finger) are pinches by definition and are left out.
NEUTRAL_SHAPES: tuple[str, ...] = (
    'relaxed', 'tabletop', 'middle_curl', 'ring_curl', 'three', 'rock', 'call_me', 'gun',
    'letter_W', 'letter_K', 'letter_V', 'letter_H', 'letter_I', 'letter_R')
# the fingers other than the pinching one take one of these shapes' values
_PINCH_BACKGROUNDS = ('relaxed', 'flat', 'spread', 'tabletop')
_PINCH_OTHERS_MIN = 0.25      # other fingertips at least this far from the thumb tip
_PINCH_ATTEMPTS = 50


def pinch_shape(model: HandModel, rng: np.random.Generator, finger: str) -> np.ndarray:
    """Finger DOFs (20,) of a pinch of ``finger``: random curl of that finger, the others from
    a background shape, the thumb solved (within its limits) so its tip is 4-9 % of the hand
    length from that fingertip and at least 25 % from the other fingertips (redrawn until
    the solution meets both)."""
    for _ in range(_PINCH_ATTEMPTS):
        fingers, target = _solve_pinch(model, rng, finger)
        distance = gesture_features(model, full_pose(model, fingers)).pinch_distance
        f = PINCH_FINGERS.index(finger)
        if abs(distance[f] - target) < 0.01 and np.delete(distance, f).min() > _PINCH_OTHERS_MIN:
            return fingers
    raise RuntimeError(f'no pinch of the {finger} finger found in {_PINCH_ATTEMPTS} attempts')


def _solve_pinch(model: HandModel, rng: np.random.Generator, finger: str
                 ) -> tuple[np.ndarray, float]:
    lo, hi = finger_limits(model)
    f = PINCH_FINGERS.index(finger)
    fingers = GESTURE_SHAPES[_PINCH_BACKGROUNDS[rng.integers(len(_PINCH_BACKGROUNDS))]].copy()
    i = 4 + 4 * f
    target = rng.uniform(0.04, 0.09)
    start = np.concatenate([np.deg2rad([rng.uniform(10, 40), rng.uniform(25, 50),
                                        rng.uniform(10, 35), rng.uniform(10, 35)]),
                            np.deg2rad([rng.uniform(25, 55), rng.uniform(25, 60)])])

    def pose(x: np.ndarray) -> np.ndarray:
        out = fingers.copy()
        out[0:4] = x[0:4]
        out[i:i + 4] = [0.0, x[4], x[5], DIP_PIP_RATIO * x[5]]
        return full_pose(model, out)

    def residual(x: np.ndarray) -> np.ndarray:
        distance = gesture_features(model, pose(x)).pinch_distance[f]
        return np.concatenate([[distance - target], 0.02 * (x - start)])

    bounds = (np.concatenate([lo[0:4], [lo[i + 1], lo[i + 2]]]),
              np.concatenate([hi[0:4], [hi[i + 1], 0.8 * hi[i + 2]]]))
    solution = least_squares(residual, np.clip(start, *bounds), bounds=bounds, xtol=1e-6)
    return np.clip(pose(solution.x)[6:], lo, hi), target


def _shape_bank(model: HandModel, rng: np.random.Generator, per_finger: int
                ) -> dict[str, list[np.ndarray]]:
    bank = {name: [_SHAPES[s] for s in shapes] for name, shapes in GESTURE_EXEMPLARS.items()}
    for finger in PINCH_FINGERS:
        bank[f'pinch_{finger}'] = [pinch_shape(model, rng, finger) for _ in range(per_finger)]
    bank[''] = [_SHAPES[s] for s in NEUTRAL_SHAPES]
    return bank


def gesture_script(model: HandModel, seed: int, episodes: int, pinch_exemplars: int = 6
                   ) -> list[Segment]:
    """A seeded script of ``episodes`` gesture or neutral episodes (module docstring)."""
    rng = np.random.default_rng(seed)
    lo, hi = finger_limits(model)
    bank = _shape_bank(model, rng, pinch_exemplars)
    segments, previous = [], None
    for _ in range(episodes):
        while True:
            label = '' if rng.uniform() < NEUTRAL_SHARE else \
                GESTURE_NAMES[rng.integers(len(GESTURE_NAMES))]
            if label != previous or label == '':
                break
        shapes = bank[label]
        fingers = shapes[rng.integers(len(shapes))] + \
            rng.normal(0.0, np.deg2rad(VARIATION_DEG), 20)
        position = np.array([rng.uniform(-0.15, 0.15), rng.uniform(-0.1, 0.15),
                             rng.uniform(0.4, 0.7)])
        segments.append(Segment(label=label, fingers=np.clip(fingers, lo, hi),
                                rotvec=sample_global_rotations(rng, 1)[0], position=position,
                                hold_s=float(rng.uniform(0.6, 1.5)),
                                move_s=float(rng.uniform(0.3, 0.6))))
        previous = label
    return segments


_COUNT_KEYS = ('episodes', 'detected', 'starts', 'true_starts', 'episodes_in_view',
               'detected_in_view')


def _episode_windows(truth: ScriptedSequence) -> list[tuple[str, float, float, int]]:
    """(gesture, start s, end s, segment index) of every gesture episode, grace included."""
    t = truth.times
    windows = []
    for k in np.unique(truth.segment):
        frames = np.flatnonzero(truth.segment == k)
        label = truth.label[frames[0]]
        if label:
            windows.append((label, float(t[frames[0]]), float(t[frames[-1]]) + MATCH_GRACE_S,
                            int(k)))
    return windows


def segments_in_view(model: HandModel, truth: ScriptedSequence, camera: PinholeCamera
                     ) -> set[int]:
    """The segments whose true hand keypoints all project inside ``camera``'s image (and
    in front of it) on every frame of their hold (module docstring)."""
    holding = np.flatnonzero(truth.holding)
    points = model.keypoints_batch(truth.poses[holding])          # (H, 21, 3)
    front = points[..., 2] > 1e-3
    uv = camera.project(np.where(front[..., None], points, 1.0))
    inside = front & (uv[..., 0] >= 0) & (uv[..., 0] <= camera.width - 1) \
        & (uv[..., 1] >= 0) & (uv[..., 1] <= camera.height - 1)
    frame_in_view = inside.all(axis=1)
    segments = truth.segment[holding]
    return {int(k) for k in np.unique(segments) if frame_in_view[segments == k].all()}


def score_events(truth: ScriptedSequence, events: Sequence[GestureEvent],
                 in_view: set[int] | None = None) -> dict[str, dict[str, int]]:
    """Per gesture: episodes, matched episodes, start events, true starts, and the episodes
    (and matched ones) among the segments ``in_view`` (None: every one; module doc)."""
    windows = _episode_windows(truth)
    matched = [False] * len(windows)
    counts = {g: dict.fromkeys(_COUNT_KEYS, 0) for g in GESTURE_NAMES}
    seen = [in_view is None or k in in_view for _, _, _, k in windows]
    for (label, _, _, _), visible in zip(windows, seen, strict=True):
        counts[label]['episodes'] += 1
        counts[label]['episodes_in_view'] += visible
    for event in events:
        if event.state != 'start':
            continue
        counts[event.name]['starts'] += 1
        for w, (label, t0, t1, _) in enumerate(windows):
            if label == event.name and t0 <= event.stamp <= t1 and not matched[w]:
                matched[w] = True
                counts[label]['detected'] += 1
                counts[label]['true_starts'] += 1
                counts[label]['detected_in_view'] += seen[w]
                break
    return counts


def _frame_counts(truth: ScriptedSequence, active: np.ndarray) -> dict[str, int]:
    """Hold frames (settled): gesture frames, of them with the gesture active, and frames with
    another gesture active."""
    settled = truth.holding.copy()
    for k in np.unique(truth.segment):
        frames = np.flatnonzero((truth.segment == k) & truth.holding)
        settled[frames[:int(round(HOLD_SETTLE_S * truth.fps))]] = False
    labels = truth.label
    gesture_frames = settled & (labels != '')
    held_active = np.array([active[i, GESTURE_NAMES.index(labels[i])] if gesture_frames[i]
                            else False for i in range(len(labels))])
    other = np.array([active[i].sum() - (held_active[i] if gesture_frames[i] else 0) > 0
                      for i in range(len(labels))]) & settled
    return {'gesture_frames': int(gesture_frames.sum()), 'held_active': int(held_active.sum()),
            'settled_frames': int(settled.sum()), 'other_active': int(other.sum())}


def run_sequence(model: HandModel, seed: int, episodes: int, source: PoseSource,
                 config: GestureConfig, classifier: PoseClassifier | None = None,
                 fps: float = 30.0, image_classifier: PoseClassifier | None = None,
                 camera: PinholeCamera | None = None
                 ) -> tuple[dict[str, dict[str, int]], dict[str, int], float,
                            list[tuple[str, str]]]:
    """Script, observe (noise model or tracker), detect: event counts, frame counts, the
    realised joint MAE, and with a classifier each whole hold classified (``classify_holds``:
    (scripted, classified) with :data:`NO_GESTURE` for the neutral shapes; empty without one).
    Frames the tracker lost reach the detector as 'no hand'; with the tracker, each frame comes
    with the evidence a node would have (``scripted_hands.evidence_seen``) for the config's
    evidence gate; with ``image_classifier`` each frame's observation (a source that records
    it: the tracker). With ``camera`` the counts also say which episodes are in its view
    (:func:`segments_in_view`)."""
    truth = script_poses(gesture_script(model, seed, episodes), fps)
    seen, found = source.observe('gestures', seed, truth, model)
    evidence = evidence_seen(source, 'gestures', seed, truth, model)
    detector = GestureDetector(model, config, classifier, image_classifier)
    observed = (None if image_classifier is None
                else observation_seen(source, 'gestures', seed, truth, model, GestureError,
                                      image_classifier.feature_set, seen))
    events: list[GestureEvent] = []
    active = np.zeros((len(seen), len(GESTURE_NAMES)), dtype=bool)
    for i, (q, ok, t) in enumerate(zip(seen, found, truth.times, strict=True)):
        events += detector.update(q if ok else None, float(t), evidence[i],
                                  None if observed is None else observed[i])
        for name in detector.active:
            active[i, GESTURE_NAMES.index(name)] = True
    holds: list[tuple[str, str]] = []
    if classifier is not None:
        log_p = np.full((len(seen), len(classifier.classes)), np.nan)
        if found.any():
            log_p[found] = detector.log_proba(
                pose_features(model, seen[found], classifier.feature_set),
                None if observed is None else observed[found])
        holds = classify_holds(truth, log_p, classifier.classes, NO_GESTURE)
    in_view = None if camera is None else segments_in_view(model, truth, camera)
    return (score_events(truth, events, in_view), _frame_counts(truth, active),
            realised_joint_mae_deg(truth.poses, seen, found), holds)


def evaluate(seeds: Sequence[int], episodes: int = 60, source: PoseSource | None = None,
             classifier: PoseClassifier | None = None, config: GestureConfig | None = None,
             evidence: EvidenceGate | None = None,
             image_classifier: PoseClassifier | None = None,
             image_weight: float | None = None, camera: PinholeCamera | None = None) -> dict:
    """Precision and recall per gesture over the sequences of ``seeds``, as seen through
    ``source`` (default: the built-in ``TrackingNoise``), scored by ``classifier`` (None: the
    rules) and, given, ``image_classifier`` on each frame's observation (weighted by
    ``image_weight``, default the config's); ``evidence`` replaces the config's evidence
    gate. Recall is also given over the episodes in ``camera``'s view (default: the primary
    camera of the source's calibration, else of ``config/calibration.yaml``)."""
    model = HandModel()
    source = TrackingNoise() if source is None else source
    if camera is None:
        calibration = getattr(source, 'calibration', share_dir() / 'config' / 'calibration.yaml')
        camera = load_calibration(str(calibration)).cameras[0]
    config = GestureConfig() if config is None else config
    if evidence is not None:
        config = dataclasses.replace(config, evidence=evidence)
    if image_weight is not None:
        config = dataclasses.replace(config, image_weight=image_weight)
    totals = {g: dict.fromkeys(_COUNT_KEYS, 0) for g in GESTURE_NAMES}
    frames = {'gesture_frames': 0, 'held_active': 0, 'settled_frames': 0, 'other_active': 0}
    maes = []
    holds: list[tuple[str, str]] = []
    for seed in seeds:
        counts, frame_counts, mae, seq_holds = run_sequence(
            model, seed, episodes, source, config, classifier, image_classifier=image_classifier,
            camera=camera)
        holds += seq_holds
        for g in GESTURE_NAMES:
            for key in totals[g]:
                totals[g][key] += counts[g][key]
        for key in frames:
            frames[key] += frame_counts[key]
        maes.append(mae)
    rows = []
    for g in (*GESTURE_NAMES, 'all'):
        c = totals[g] if g != 'all' else {k: sum(totals[x][k] for x in GESTURE_NAMES)
                                          for k in totals[GESTURE_NAMES[0]]}
        held = [p for p in holds if p[0] == g or (g == 'all' and p[0] != NO_GESTURE)]
        rows.append({'gesture': g, 'episodes': c['episodes'], 'starts': c['starts'],
                     'precision': c['true_starts'] / c['starts'] if c['starts'] else float('nan'),
                     'recall': c['detected'] / c['episodes'] if c['episodes'] else float('nan'),
                     'episodes_in_view': c['episodes_in_view'],
                     'recall_in_view': c['detected_in_view'] / c['episodes_in_view']
                     if c['episodes_in_view'] else float('nan'),
                     'hold_accuracy': sum(a == b for a, b in held) / len(held) if held
                     else float('nan')})
    neutral = [b for a, b in holds if a == NO_GESTURE]
    return {'rows': rows, 'frames': {
        **frames,
        'held_gesture_active_share': frames['held_active'] / max(frames['gesture_frames'], 1),
        'other_gesture_active_share': frames['other_active'] / max(frames['settled_frames'], 1)},
        'joint_mae_deg_realised': float(np.nanmean(maes)),
        'neutral_holds_as_gesture': sum(b not in (NO_GESTURE, '-') for b in neutral) /
        len(neutral) if neutral else float('nan')}


def main(argv: list[str] | None = None) -> int:
    """Entry point of ``colorglove_eval_gestures``."""
    run = run_scripted_evaluation(argv, __doc__, SETTINGS, evaluate)
    result = run.result
    print_table(result['rows'], run.title('Gesture events'))
    frames = result['frames']
    print_table([{'held gesture active (settled hold frames)':
                  frames['held_gesture_active_share'],
                  'another gesture active': frames['other_gesture_active_share'],
                  'neutral holds classified as a gesture': result['neutral_holds_as_gesture']}],
                'Frames (hold accuracy and the last column: each whole hold classified, the '
                'classifier alone, hold known; NaN with the rules)')
    overall = result['rows'][-1]
    worst_p = min(r['precision'] for r in result['rows'])
    worst_r = min(r['recall'] for r in result['rows'])
    targets = [target_row('precision >= 95 % (every gesture)', worst_p, TARGET, '>='),
               target_row('recall >= 95 % (every gesture)', worst_r, TARGET, '>=')]
    print_table(targets, 'Targets (lowest gesture; overall precision '
                f'{overall["precision"]:.3f}, recall {overall["recall"]:.3f}; recall on the '
                f'{overall["episodes_in_view"]} of {overall["episodes"]} episodes in view '
                f'{overall["recall_in_view"]:.3f}, not judged)')
    return run.finish(targets)

if __name__ == '__main__':
    raise SystemExit(main())
