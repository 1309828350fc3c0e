"""Gesture events from the tracked pose: pinches, grab, point, open hand, with hysteresis.

Every frame each gesture gets a score in [0, 1]. With a trained classifier
(``core/hand/pose_classifier.py``, feature set ``hand_shape``, classes the gestures and
:data:`NO_GESTURE`; ``colorglove_train_hand_classifiers`` fits it on synthetic training
sequences) the score is the gesture's class probability. Without one, it comes from rules on
the pose's finger geometry (scale-free: distances are divided by the hand length), made of
logistic ramps around thresholds:

* ``pinch_<finger>`` (index, middle, ring, little): the thumb tip is near that fingertip,
  that fingertip is the nearest one to the thumb tip, and the finger is not folded into the
  palm (a fist brings the fingertips near the thumb without a pinch);
* ``grab``: all four fingers curled;
* ``point``: the index extended, the middle, ring and little fingers curled;
* ``open_hand``: all four fingers extended and no pinch.

A finger's curl is its MCP + PIP + DIP flexion over the sum of their upper limits (0 straight,
1 fully bent). The scores go through the shared hold-and-release hysteresis
(``core/hand/hysteresis.py``: smoothing, on / off thresholds and hold times); a hand lost
for ``lose_after_s`` (frames with no pose: no hand seen, or a pose the tracker refused) ends
every active gesture at once; a shorter loss decides nothing, so a gesture held through a
few refused frames is neither ended nor started again. The confidence of an event is the
gesture's smoothed score on the frame that decided it (for a loss: 0).

An optional image classifier (the same kind, feature set ``tiny_observation`` or its upright
variant ``tiny_observation_upright``, on the frame's observation:
``core/hand/observation_features.py``; the caller computes the features, the upright ones with
the frame's fitted global rotation) adds ``image_weight`` times its
log-probabilities to the pose classifier's, renormalised over the classes: a product of the
two classifiers' probabilities (the image one's raised to the weight), which reads where the
fingertips' patches lie when the fitted pose puts them elsewhere. A frame without an
observation is scored from its pose alone.

A classifier's probabilities are bounded by the pose's geometry (:class:`ShapeGate`,
``GestureConfig.shape``): a pinch's score is multiplied by the logistic ramp of its
thumb-to-fingertip distance falling below ``max_pinch_distance``, and grab's and point's by
the ramp of the curl rising above ``min_curl`` of the least curled of the fingers they hold
curled (grab: all four; point: middle, ring and little); the ramps' widths are the rules'
``pinch_width`` and ``curl_width``. A pose whose thumb tip is far from every fingertip is no
pinch, nor one with a straight finger a grab, whatever else the classifier reads in it.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, fields

import numpy as np

from colorglove_ros.core.errors import ColorGloveError
from colorglove_ros.core.hand.frame_evidence import EvidenceGate, FrameEvidence
from colorglove_ros.core.hand.hysteresis import HoldConfig, ScoreHysteresis
from colorglove_ros.core.hand.keypoints import FINGERTIP_INDICES, hand_keypoints
from colorglove_ros.core.hand.model import DOF_NAMES, HandModel
from colorglove_ros.core.hand.observation_features import IMAGE_FEATURE_SETS
from colorglove_ros.core.hand.pose_classifier import (
    PoseClassifier,
    add_image_log_proba,
    pose_features,
)
from colorglove_ros.core.validation import check_number

__all__ = [
    'GESTURE_NAMES', 'PINCH_FINGERS', 'EVENT_STATES', 'NO_GESTURE', 'GESTURE_FEATURES',
    'DEFAULT_GESTURE_CLASSIFIER', 'GESTURE_IMAGE_CLASSIFIER', 'GESTURE_UPRIGHT_IMAGE_CLASSIFIER',
    'DEFAULT_GESTURE_IMAGE_CLASSIFIER',
    'GestureError', 'ShapeGate', 'GestureConfig',
    'GestureFeatures', 'GestureEvent', 'gesture_features', 'gesture_scores',
    'shape_gate_factors',
    'GestureDetector', 'format_event', 'parse_event',
]

PINCH_FINGERS: tuple[str, ...] = ('index', 'middle', 'ring', 'little')
GESTURE_NAMES: tuple[str, ...] = (
    *(f'pinch_{f}' for f in PINCH_FINGERS), 'grab', 'point', 'open_hand')
EVENT_STATES: tuple[str, ...] = ('start', 'end')
NO_GESTURE = 'none'               # the classifier's class for a hand doing none of them
GESTURE_FEATURES = 'hand_shape'   # the classifier's feature set (pose_classifier.py)
# the trained classifier, relative to the package root (the nodes' and tools' default)
DEFAULT_GESTURE_CLASSIFIER = 'config/gesture_classifier.npz'
# the image evidence's gesture classifier (colorglove_train_hand_classifiers --what
# gesture_images)
GESTURE_IMAGE_CLASSIFIER = 'config/gesture_image_classifier.npz'
# the same of the upright features (``--image-features tiny_observation_upright``)
GESTURE_UPRIGHT_IMAGE_CLASSIFIER = 'config/gesture_upright_image_classifier.npz'
# gesture_node's and eval_gestures --tracker's image classifier ('': the pose alone)
DEFAULT_GESTURE_IMAGE_CLASSIFIER = ''
_CURL_DOFS = np.array([[DOF_NAMES.index(f'{f}_{j}') for j in ('mcp_flex', 'pip_flex', 'dip_flex')]
                       for f in PINCH_FINGERS])


class GestureError(ColorGloveError, ValueError):
    """Bad gesture settings, pose or event text."""


@dataclass(frozen=True)
class ShapeGate:
    """Geometric bounds on a classifier's gesture scores (module docstring): the largest
    thumb-to-fingertip distance of a pinch (hand lengths; ``inf``: no bound) and the least
    curl of every finger a grab or a point holds curled (0: no bound). The defaults bound
    nothing (off)."""

    max_pinch_distance: float = math.inf
    min_curl: float = 0.0

    def __post_init__(self) -> None:
        if self.max_pinch_distance != math.inf:
            check_number('max_pinch_distance', self.max_pinch_distance, low=0.0,
                         low_open=True, error=GestureError)
        check_number('min_curl', self.min_curl, low=0.0, high=1.0,
                     error=GestureError)

    @property
    def enabled(self) -> bool:
        """Whether it bounds any score."""
        return self.max_pinch_distance < math.inf or self.min_curl > 0.0


@dataclass(frozen=True)
class GestureConfig:
    """Rule thresholds (pinch distances as a fraction of the hand length, curls in [0, 1]) and
    the width of each logistic ramp, used without a classifier; the hysteresis (``hold``);
    how long the hand must be lost before the active gestures end (``lose_after_s``; 0: at
    the first frame without a pose); the gate that skips frames of weak tracker evidence
    (``evidence``: frames whose pose matched fewer than 11 constraints; ``EvidenceGate()``
    turns it off); the image
    classifier's weight (``image_weight``, with one); the geometric bounds on a classifier's
    scores (``shape``: pinches within 0.275 hand lengths, a grab's and a point's curled fingers
    above 0.55; ``ShapeGate()`` turns them off)."""

    pinch_distance: float = 0.21
    pinch_width: float = 0.025
    pinch_margin_width: float = 0.03
    pinch_max_curl: float = 0.72
    curled: float = 0.55
    extended: float = 0.18
    curl_width: float = 0.04
    hold: HoldConfig = field(default_factory=lambda: HoldConfig(
        smoothing=0.25, on_score=0.75, off_score=0.3, hold_on_s=0.1, hold_off_s=0.1))
    lose_after_s: float = 0.3
    evidence: EvidenceGate = field(default_factory=lambda: EvidenceGate(min_constraints=11.0))
    image_weight: float = 0.25
    shape: ShapeGate = field(default_factory=lambda: ShapeGate(max_pinch_distance=0.275,
                                                               min_curl=0.55))

    def __post_init__(self) -> None:
        check_number('image_weight', self.image_weight, low=0.0, error=GestureError)
        check_number('lose_after_s', self.lose_after_s, low=0.0, error=GestureError)
        for f in fields(self):
            if f.name not in ('hold', 'evidence', 'image_weight', 'shape', 'lose_after_s'):
                check_number(f.name, getattr(self, f.name), low=0.0, low_open=True,
                             error=GestureError)
        if self.extended >= self.curled:
            raise GestureError(f'extended ({self.extended}) must be below curled '
                               f'({self.curled})')


@dataclass(frozen=True)
class GestureFeatures:
    """``pinch_distance`` (4,): thumb tip to the index..little fingertips over the hand
    length; ``curl`` (4,): index..little curl in [0, 1]."""

    pinch_distance: np.ndarray
    curl: np.ndarray


@dataclass(frozen=True)
class GestureEvent:
    """A gesture started or ended at ``stamp`` (seconds) with ``confidence`` in [0, 1]."""

    name: str
    state: str
    confidence: float
    stamp: float = 0.0


def _sigmoid(x: np.ndarray | float) -> np.ndarray:
    return 1.0 / (1.0 + np.exp(-np.asarray(x, dtype=float)))


def gesture_features(model: HandModel, q: np.ndarray) -> GestureFeatures:
    """Pinch distances and finger curls of a 26-DOF pose (wrist frame, so the global pose does
    not matter)."""
    tips = hand_keypoints(model, q, 'wrist').positions[list(FINGERTIP_INDICES)]
    distance = np.linalg.norm(tips[1:] - tips[0], axis=1) / model.hand_length_m
    q = np.asarray(q, dtype=float)
    curl = q[_CURL_DOFS].sum(axis=1) / model.upper_limits[_CURL_DOFS].sum(axis=1)
    return GestureFeatures(pinch_distance=distance, curl=np.clip(curl, 0.0, 1.0))


def gesture_scores(features: GestureFeatures, config: GestureConfig | None = None
                   ) -> dict[str, float]:
    """Score in [0, 1] of every gesture in ``GESTURE_NAMES`` (see the module docstring)."""
    c = GestureConfig() if config is None else config
    d, curl = features.pinch_distance, features.curl
    near = _sigmoid((c.pinch_distance - d) / c.pinch_width)
    others = np.array([np.min(np.delete(d, i)) for i in range(len(d))])
    nearest = _sigmoid((others - d) / c.pinch_margin_width)
    not_folded = _sigmoid((c.pinch_max_curl - curl) / c.curl_width)
    pinch = near * nearest * not_folded
    is_curled = _sigmoid((curl - c.curled) / c.curl_width)
    is_extended = _sigmoid((c.extended - curl) / c.curl_width)
    scores = {f'pinch_{f}': float(s) for f, s in zip(PINCH_FINGERS, pinch, strict=True)}
    scores['grab'] = float(is_curled.min())
    scores['point'] = float(min(is_extended[0], is_curled[1:].min()))
    scores['open_hand'] = float(min(is_extended.min(), 1.0 - pinch.max()))
    return scores


def shape_gate_factors(features: GestureFeatures, config: GestureConfig | None = None
                       ) -> dict[str, float]:
    """The factor in [0, 1] the config's :class:`ShapeGate` multiplies each gesture's
    classifier score by (1 for every gesture it does not bound; module docstring)."""
    c = GestureConfig() if config is None else config
    gate = c.shape
    out = dict.fromkeys(GESTURE_NAMES, 1.0)
    if gate.max_pinch_distance < math.inf:
        near = _sigmoid((gate.max_pinch_distance - features.pinch_distance) / c.pinch_width)
        out.update({f'pinch_{f}': float(v) for f, v in zip(PINCH_FINGERS, near, strict=True)})
    if gate.min_curl > 0.0:
        for name, curled in (('grab', features.curl), ('point', features.curl[1:])):
            out[name] = float(_sigmoid((curled.min() - gate.min_curl) / c.curl_width))
    return out


@dataclass
class GestureDetector:
    """Turns per-frame scores into start / end events with hysteresis (one per hand); scores
    from ``classifier`` when given, else from the rules; with an ``image_classifier`` (which
    needs ``classifier``) combined with the frame's observation (module docstring)."""

    model: HandModel
    config: GestureConfig = field(default_factory=GestureConfig)
    classifier: PoseClassifier | None = None
    image_classifier: PoseClassifier | None = None

    def __post_init__(self) -> None:
        expected = {*GESTURE_NAMES, NO_GESTURE}
        for clf, features in ((self.classifier, (GESTURE_FEATURES,)),
                              (self.image_classifier, IMAGE_FEATURE_SETS)):
            if clf is not None and (set(clf.classes) != expected or
                                    clf.feature_set not in features):
                raise GestureError(f'a gesture classifier must classify {features!r} '
                                   f'features into {sorted(expected)}, got '
                                   f'{clf.feature_set!r} {clf.classes}')
        if self.image_classifier is not None and self.classifier is None:
            raise GestureError('an image classifier is combined with a pose classifier: '
                               'give one (the rules have no probabilities)')
        self._hysteresis = ScoreHysteresis(GESTURE_NAMES, self.config.hold)
        self._lost_since: float | None = None     # stamp of the first frame of a loss

    @property
    def active(self) -> tuple[str, ...]:
        """The gestures currently on."""
        return self._hysteresis.active

    @property
    def scores(self) -> dict[str, float]:
        """The smoothed score of every gesture after the last frame (empty before one)."""
        return dict(self._hysteresis.smoothed)

    def reset(self) -> None:
        """Forget the history without events (:meth:`update` with None ends the active ones)."""
        self._hysteresis.reset()
        self._lost_since = None

    def log_proba(self, features: np.ndarray, observations: np.ndarray | None = None
                  ) -> np.ndarray:
        """(N, C) class log-probabilities (the classifier's classes) of N frames' pose
        features (``hand_shape``) and, with an image classifier, their observation features
        (N, F; None: the pose alone), renormalised."""
        if self.classifier is None:
            raise GestureError('class probabilities need a classifier')
        log_p = np.atleast_2d(self.classifier.log_proba(features))
        if self.image_classifier is None or observations is None:
            return log_p
        log_p = add_image_log_proba(log_p, self.classifier.classes, self.image_classifier,
                                    observations, self.config.image_weight)
        top = log_p.max(axis=1, keepdims=True)
        return log_p - top - np.log(np.exp(log_p - top).sum(axis=1, keepdims=True))

    def frame_scores(self, q: np.ndarray, observation: np.ndarray | None = None
                     ) -> dict[str, float]:
        """One frame's raw score of every gesture (``observation``: its observation
        features, read with an image classifier); a classifier's bounded by the config's
        shape gate."""
        if self.classifier is None:
            return gesture_scores(gesture_features(self.model, q), self.config)
        p = np.exp(self.log_proba(pose_features(self.model, q, GESTURE_FEATURES),
                                  None if observation is None else np.asarray(observation))[0])
        scores = {c: float(v) for c, v in zip(self.classifier.classes, p, strict=True)
                  if c != NO_GESTURE}
        if self.config.shape.enabled:
            factors = shape_gate_factors(gesture_features(self.model, q), self.config)
            scores = {g: s * factors[g] for g, s in scores.items()}
        return scores

    def update(self, q: np.ndarray | None, stamp: float = 0.0,
               evidence: FrameEvidence | None = None,
               observation: np.ndarray | None = None) -> list[GestureEvent]:
        """Feed one frame's pose (None: no hand), the tracker's evidence for it (None:
        unknown) and its observation features (None: none; read with an image classifier);
        returns the events it decided. A frame the config's evidence gate finds weak is
        skipped: it decides nothing; so is a frame without a pose until the hand has been lost
        for ``lose_after_s``, when the active gestures end."""
        if q is not None and self.config.evidence.weak(evidence):
            return []
        if q is None:
            if self._lost_since is None:
                self._lost_since = stamp
            if stamp - self._lost_since < self.config.lose_after_s - 1e-9:
                return []
            changes = self._hysteresis.lose(stamp)
        else:
            self._lost_since = None
            q = np.asarray(q, dtype=float)
            if not np.all(np.isfinite(q)):
                raise GestureError('pose must be finite')
            changes = self._hysteresis.update(self.frame_scores(q, observation), stamp)
        return [GestureEvent(t.name, t.state, t.score, t.stamp) for t in changes]


def format_event(event: GestureEvent) -> str:
    """``name:state:confidence`` with the confidence to two decimals, e.g.
    ``pinch_index:start:0.93``."""
    return f'{event.name}:{event.state}:{event.confidence:.2f}'


def parse_event(text: str, stamp: float = 0.0) -> GestureEvent:
    """The inverse of :func:`format_event`."""
    parts = text.split(':')
    if len(parts) != 3 or parts[0] not in GESTURE_NAMES or parts[1] not in EVENT_STATES:
        raise GestureError(f'not a gesture event: {text!r}')
    try:
        confidence = float(parts[2])
    except ValueError as exc:
        raise GestureError(f'bad confidence in {text!r}') from exc
    if not 0.0 <= confidence <= 1.0:
        raise GestureError(f'confidence out of [0, 1] in {text!r}')
    return GestureEvent(parts[0], parts[1], confidence, stamp)
