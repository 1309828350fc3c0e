"""Finger-spelling: the 26 one-hand alphabet letters from the tracked pose, committed by holding.

Templates: each letter's finger DOFs are the pose collection's ``LETTER_SHAPES``; its
orientation is the direction the fingers point in the camera frame (the hand frame's ``-y``
axis), with the camera upright (image down = gravity): up for most letters, toward the image
right for G and H, tipped 45 deg toward the camera for P, and both for Q
(``LETTER_ROLL_PITCH``; within the tracker's orientation range, so P and Q are milder than
signed). The alphabet is static here: J and Z are their handshapes held still (their motion is
not modelled).

Classifier: a trained classifier (``core/hand/pose_classifier.py``, feature set
``hand_shape_direction``, classes the 26 letters; ``colorglove_train_hand_classifiers`` fits it
on synthetic training sequences seen through the tracking-noise model) gives each frame's
letter probabilities. Without one, the templates do: a Gaussian likelihood per letter with a
shared isotropic spread per feature group (finger joints in radians over ``joint_sigma_deg``,
pointing direction over ``direction_sigma``) and a softmax. An optional image classifier
(the same kind, on the frame's observation: ``core/hand/observation_features.py``) adds
``image_weight`` times its log-probabilities to the pose's, a product of the two
classifiers' probabilities (the image one's raised to the weight): the tiny image shows where
the thumb's patches lie when the fitted pose puts the thumb elsewhere.
Hold-to-commit: a letter is a hold, the hand still in one place (the wrist's speed over the last
``still_window_s`` below ``still_speed_m_s``). Each frame of the hold adds its per-letter
log-probabilities to the hold's sum, and once the hold has lasted ``commit_after_s`` the letter
of the largest sum is emitted, once per hold. Summing over the hold rather than deciding on one
frame keeps the move into a letter (whose passing shapes look like other letters) and a few
frames of a confusable letter (M, N, S, T) from deciding alone. A hold ends when the hand
moves (so a double letter, signed with a small slide, is two holds), when the hand is lost,
or when the hand shape turns into another letter in place: the letter probabilities also go
through the shared hold-and-release hysteresis (``core/hand/hysteresis.py``), and a letter
other than the committed one turning on there starts a new hold.
"""
from __future__ import annotations

from collections import deque
from dataclasses import dataclass, field

import numpy as np

from colorglove_ros.core.errors import ColorGloveError
from colorglove_ros.core.hand.hysteresis import HoldConfig, ScoreHysteresis
from colorglove_ros.core.hand.model import NUM_DOFS, HandModel, rotvec_to_matrix
from colorglove_ros.core.hand.observation_features import OBSERVATION_FEATURES
from colorglove_ros.core.hand.pose_classifier import (
    PoseClassifier,
    add_image_log_proba,
    pose_features,
)
from colorglove_ros.core.hand.poses import LETTER_SHAPES
from colorglove_ros.core.validation import check_number

__all__ = [
    'LETTERS', 'THUMB_LETTERS', 'LETTER_ROLL_PITCH', 'LETTER_FEATURES',
    'DEFAULT_LETTER_CLASSIFIER', 'TRAINED_LETTER_CLASSIFIER', 'LETTER_IMAGE_CLASSIFIER',
    'DEFAULT_LETTER_IMAGE_CLASSIFIER', 'SpellingError',
    'SpellingConfig',
    'letter_rotation', 'pointing_direction', 'LetterClassifier', 'Speller',
]

LETTERS: tuple[str, ...] = tuple(sorted(LETTER_SHAPES))
THUMB_LETTERS: tuple[str, ...] = ('E', 'M', 'N', 'S', 'T')
LETTER_FEATURES = 'hand_shape_direction'   # the classifier's feature set (pose_classifier.py)
# the trained classifier, relative to the package root (the nodes' and tools' default)
TRAINED_LETTER_CLASSIFIER = 'config/letter_classifier.npz'
DEFAULT_LETTER_CLASSIFIER = TRAINED_LETTER_CLASSIFIER
# the image evidence's letter classifier (colorglove_train_hand_classifiers --what
# letter_images): the spelling node's and eval_spelling --tracker's default ('': the pose alone)
LETTER_IMAGE_CLASSIFIER = 'config/letter_image_classifier.npz'
DEFAULT_LETTER_IMAGE_CLASSIFIER = LETTER_IMAGE_CLASSIFIER
# (roll about the camera z, then pitch toward the camera) of each letter's pointing direction,
# degrees; letters not listed point up
LETTER_ROLL_PITCH: dict[str, tuple[float, float]] = {
    'G': (90.0, 0.0), 'H': (90.0, 0.0), 'P': (0.0, 45.0), 'Q': (90.0, 45.0)}

assert len(LETTERS) == 26 and set(THUMB_LETTERS) <= set(LETTERS)
# (excluded lower, included upper) bound of the template settings
_SETTING_BOUNDS: dict[str, tuple[float, float | None]] = {
    'joint_sigma_deg': (0.0, None), 'direction_sigma': (0.0, None),
    'still_speed_m_s': (0.0, None), 'still_window_s': (0.0, None),
    'commit_after_s': (0.0, None)}


class SpellingError(ColorGloveError, ValueError):
    """Bad spelling settings or input."""


@dataclass(frozen=True)
class SpellingConfig:
    """Template spreads (without a classifier); what a hold is (the wrist slower than
    ``still_speed_m_s`` over ``still_window_s``) and how long it lasts before its letter is
    committed (``commit_after_s``); the hysteresis (``hold``) that tells a change of letter in
    place; the image classifier's weight (``image_weight``, with one)."""

    joint_sigma_deg: float = 12.0
    direction_sigma: float = 0.3
    hold: HoldConfig = field(default_factory=lambda: HoldConfig(
        smoothing=0.25, on_score=0.4, off_score=0.2, hold_on_s=0.3, hold_off_s=0.15))
    still_speed_m_s: float = 0.08
    still_window_s: float = 0.3
    commit_after_s: float = 0.2
    image_weight: float = 1.0

    def __post_init__(self) -> None:
        for name, (low, high) in _SETTING_BOUNDS.items():
            check_number(name, getattr(self, name), low=low, low_open=True, high=high,
                         error=SpellingError)
        check_number('image_weight', self.image_weight, low=0.0, error=SpellingError)


def letter_rotation(letter: str) -> np.ndarray:
    """Canonical wrist rotation vector (3,) of a letter: the palm toward the camera, turned by
    the letter's roll and pitch (``LETTER_ROLL_PITCH``)."""
    from scipy.spatial.transform import Rotation

    roll, pitch = LETTER_ROLL_PITCH.get(letter, (0.0, 0.0))
    return Rotation.from_euler('ZX', [roll, pitch], degrees=True).as_rotvec()


def pointing_direction(q: np.ndarray) -> np.ndarray:
    """Unit direction (3,) the fingers point in the camera frame (the hand frame's -y axis)."""
    return -rotvec_to_matrix(np.asarray(q, dtype=float)[3:6])[:, 1]


class LetterClassifier:
    """Per-frame log-probabilities of the 26 letters from a 26-DOF pose: the trained
    ``classifier`` when given, else the templates (module docstring); with an
    ``image_classifier`` (feature set ``tiny_observation``) plus ``config.image_weight`` times
    its log-probabilities of the frame's observation features."""

    def __init__(self, config: SpellingConfig | None = None, model: HandModel | None = None,
                 classifier: PoseClassifier | None = None,
                 image_classifier: PoseClassifier | None = None) -> None:
        self.config = SpellingConfig() if config is None else config
        self.model = HandModel() if model is None else model
        for clf, features in ((classifier, LETTER_FEATURES),
                              (image_classifier, OBSERVATION_FEATURES)):
            if clf is not None and (clf.feature_set != features or
                                    set(clf.classes) != set(LETTERS)):
                raise SpellingError(f'a letter classifier must classify {features!r} '
                                    f'features into the 26 letters, got {clf.feature_set!r} '
                                    f'{clf.classes}')
        self.classifier = classifier
        self.image_classifier = image_classifier
        if classifier is not None:
            self._order = np.array([classifier.classes.index(k) for k in LETTERS])
        lo, hi = self.model.lower_limits[6:], self.model.upper_limits[6:]
        self._joints = np.stack([np.clip(LETTER_SHAPES[k], lo, hi) for k in LETTERS])
        rest = np.zeros(NUM_DOFS)
        directions = []
        for k in LETTERS:
            rest[3:6] = letter_rotation(k)
            directions.append(pointing_direction(rest))
        self._directions = np.stack(directions)

    def log_likelihoods(self, q: np.ndarray, observation: np.ndarray | None = None
                        ) -> np.ndarray:
        """(26,) log-probability of each letter in ``LETTERS`` order (the templates': up to a
        constant); ``observation``: the frame's observation features (F,), used with an
        image classifier (a frame without one is classified from its pose alone)."""
        q = np.asarray(q, dtype=float)
        if q.shape != (NUM_DOFS,):
            raise SpellingError(f'pose must be 26 finite values, got shape {q.shape}')
        return self.log_likelihoods_batch(
            q[None], None if observation is None else np.asarray(observation)[None])[0]

    def log_likelihoods_batch(self, poses: np.ndarray, observations: np.ndarray | None = None
                              ) -> np.ndarray:
        """(N, 26) :meth:`log_likelihoods` of poses (N, 26) and their frames' observation
        features (N, F; without them, with an image classifier too, the pose's part alone)."""
        poses = np.asarray(poses, dtype=float)
        if poses.ndim != 2 or poses.shape[1] != NUM_DOFS or not np.all(np.isfinite(poses)):
            raise SpellingError(f'poses must be finite (N, 26), got shape {poses.shape}')
        out = self._pose_log_likelihoods(poses)
        if self.image_classifier is None or observations is None:
            return out
        if len(observations) != len(poses):
            raise SpellingError(f'{len(poses)} poses but {len(observations)} observations')
        return add_image_log_proba(out, LETTERS, self.image_classifier, observations,
                                   self.config.image_weight)

    def _pose_log_likelihoods(self, poses: np.ndarray) -> np.ndarray:
        """(N, 26) the pose classifier's (or the templates') part."""
        if self.classifier is not None:
            features = pose_features(self.model, poses, self.classifier.feature_set)
            return np.atleast_2d(self.classifier.log_proba(features))[:, self._order]
        c = self.config
        joint = np.sum((poses[:, None, 6:] - self._joints) ** 2, axis=2) \
            / np.deg2rad(c.joint_sigma_deg) ** 2
        pointing = np.stack([pointing_direction(q) for q in poses])
        direction = np.sum((pointing[:, None] - self._directions) ** 2, axis=2) \
            / c.direction_sigma ** 2
        return -0.5 * (joint + direction)


def _softmax(x: np.ndarray) -> np.ndarray:
    e = np.exp(x - x.max())
    return e / e.sum()


class Speller:
    """Hold-to-commit letter stream from tracked poses (one per hand; module docstring)."""

    def __init__(self, config: SpellingConfig | None = None, model: HandModel | None = None,
                 classifier: PoseClassifier | None = None,
                 image_classifier: PoseClassifier | None = None) -> None:
        self.config = SpellingConfig() if config is None else config
        self.classifier = LetterClassifier(self.config, model, classifier, image_classifier)
        self._hysteresis = ScoreHysteresis(LETTERS, self.config.hold)
        self.reset()

    def reset(self) -> None:
        """Forget the history (the next letter can be the last committed one)."""
        self._hysteresis.reset()
        self._wrists: deque[tuple[float, np.ndarray]] = deque()
        self._end_hold()
        self.posterior: np.ndarray | None = None

    def _end_hold(self) -> None:
        self._hold_sum: np.ndarray | None = None    # summed log-probabilities of the hold
        self._hold_start = 0.0
        self._committed: str | None = None          # the hold's letter, once committed

    @property
    def current(self) -> tuple[str | None, float]:
        """The most likely letter now and its smoothed probability (None, 0 before any
        frame)."""
        if self.posterior is None:
            return None, 0.0
        i = int(np.argmax(self.posterior))
        return LETTERS[i], float(self.posterior[i])

    def _moving(self, wrist: np.ndarray, stamp: float) -> bool:
        """Whether the wrist moved at ``still_speed_m_s`` or faster over the last
        ``still_window_s`` (a frame's own first stamp: not moving)."""
        self._wrists.append((stamp, wrist))
        while stamp - self._wrists[0][0] > self.config.still_window_s + 1e-9:
            self._wrists.popleft()
        since, start = self._wrists[0]
        return stamp - since > 1e-9 and \
            np.linalg.norm(wrist - start) >= self.config.still_speed_m_s * (stamp - since)

    def update(self, q: np.ndarray | None, stamp: float,
               observation: np.ndarray | None = None) -> str | None:
        """Feed one frame (None: no hand; ``observation``: its observation features, used
        with an image classifier); returns the letter committed on it, if any."""
        if q is None:
            self.reset()
            return None
        q = np.asarray(q, dtype=float)
        log_p = self.classifier.log_likelihoods(q, observation)
        changes = self._hysteresis.update(dict(zip(LETTERS, _softmax(log_p), strict=True)),
                                          stamp)
        smoothed = self._hysteresis.smoothed
        self.posterior = np.array([smoothed[k] for k in LETTERS])
        if self._moving(q[0:3].copy(), stamp):
            self._end_hold()
            return None
        if self._committed is not None and \
                any(t.state == 'start' and t.name != self._committed for t in changes):
            self._end_hold()                           # another letter, signed in place
        if self._hold_sum is None:
            self._hold_sum, self._hold_start = log_p.copy(), stamp
        else:
            self._hold_sum += log_p
        if self._committed is not None or \
                stamp - self._hold_start < self.config.commit_after_s - 1e-9:
            return None
        self._committed = LETTERS[int(np.argmax(self._hold_sum))]
        return self._committed
