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
pointing direction over ``direction_sigma``) and a softmax.
Hold-to-commit: the letter probabilities go through the shared hold-and-release hysteresis
(``core/hand/hysteresis.py``); a letter is emitted when it turns on (its smoothed probability
held at or above ``on_score`` for ``hold_on_s``). The same letter again (a double letter) needs
a re-arm: the letter turning off (another letter or no hand), or the wrist moving
``rearm_motion_m`` since the commit, after which the letter must be held anew (double letters
are signed with a small slide).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from colorglove_ros.core.errors import ColorGloveError
from colorglove_ros.core.hand.hysteresis import HoldConfig, ScoreHysteresis
from colorglove_ros.core.hand.model import NUM_DOFS, HandModel, rotvec_to_matrix
from colorglove_ros.core.hand.pose_classifier import PoseClassifier, pose_features
from colorglove_ros.core.hand.poses import LETTER_SHAPES
from colorglove_ros.core.validation import check_number

__all__ = [
    'LETTERS', 'THUMB_LETTERS', 'LETTER_ROLL_PITCH', 'LETTER_FEATURES',
    'DEFAULT_LETTER_CLASSIFIER', 'TRAINED_LETTER_CLASSIFIER', 'SpellingError',
    'SpellingConfig',
    'letter_rotation', 'pointing_direction', 'LetterClassifier', 'Speller',
]

LETTERS: tuple[str, ...] = tuple(sorted(LETTER_SHAPES))
THUMB_LETTERS: tuple[str, ...] = ('E', 'M', 'N', 'S', 'T')
LETTER_FEATURES = 'hand_shape_direction'   # the classifier's feature set (pose_classifier.py)
# the trained classifier, relative to the package root (the nodes' and tools' default)
TRAINED_LETTER_CLASSIFIER = 'config/letter_classifier.npz'
DEFAULT_LETTER_CLASSIFIER = TRAINED_LETTER_CLASSIFIER
# (roll about the camera z, then pitch toward the camera) of each letter's pointing direction,
# degrees; letters not listed point up
LETTER_ROLL_PITCH: dict[str, tuple[float, float]] = {
    'G': (90.0, 0.0), 'H': (90.0, 0.0), 'P': (0.0, 45.0), 'Q': (90.0, 45.0)}

assert len(LETTERS) == 26 and set(THUMB_LETTERS) <= set(LETTERS)
# (excluded lower, included upper) bound of the template settings
_SETTING_BOUNDS: dict[str, tuple[float, float | None]] = {
    'joint_sigma_deg': (0.0, None), 'direction_sigma': (0.0, None),
    'rearm_motion_m': (0.0, None)}


class SpellingError(ColorGloveError, ValueError):
    """Bad spelling settings or input."""


@dataclass(frozen=True)
class SpellingConfig:
    """Template spreads (without a classifier), hold-to-commit (``hold``) and re-arm motion."""

    joint_sigma_deg: float = 12.0
    direction_sigma: float = 0.3
    hold: HoldConfig = field(default_factory=lambda: HoldConfig(
        smoothing=0.25, on_score=0.4, off_score=0.2, hold_on_s=0.3, hold_off_s=0.15))
    rearm_motion_m: float = 0.03

    def __post_init__(self) -> None:
        for name, (low, high) in _SETTING_BOUNDS.items():
            check_number(name, getattr(self, name), low=low, low_open=True, high=high,
                         error=SpellingError)


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
    ``classifier`` when given, else the templates (module docstring)."""

    def __init__(self, config: SpellingConfig | None = None, model: HandModel | None = None,
                 classifier: PoseClassifier | None = None) -> None:
        self.config = SpellingConfig() if config is None else config
        self.model = HandModel() if model is None else model
        if classifier is not None and (classifier.feature_set != LETTER_FEATURES or
                                       set(classifier.classes) != set(LETTERS)):
            raise SpellingError(f'a letter classifier must classify {LETTER_FEATURES!r} '
                                f'features into the 26 letters, got {classifier.feature_set!r} '
                                f'{classifier.classes}')
        self.classifier = classifier
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

    def log_likelihoods(self, q: np.ndarray) -> np.ndarray:
        """(26,) log-probability of each letter in ``LETTERS`` order (the templates': up to a
        constant)."""
        q = np.asarray(q, dtype=float)
        if q.shape != (NUM_DOFS,):
            raise SpellingError(f'pose must be 26 finite values, got shape {q.shape}')
        return self.log_likelihoods_batch(q[None])[0]

    def log_likelihoods_batch(self, poses: np.ndarray) -> np.ndarray:
        """(N, 26) :meth:`log_likelihoods` of poses (N, 26)."""
        poses = np.asarray(poses, dtype=float)
        if poses.ndim != 2 or poses.shape[1] != NUM_DOFS or not np.all(np.isfinite(poses)):
            raise SpellingError(f'poses must be finite (N, 26), got shape {poses.shape}')
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
    """Hold-to-commit letter stream from tracked poses (one per hand)."""

    def __init__(self, config: SpellingConfig | None = None, model: HandModel | None = None,
                 classifier: PoseClassifier | None = None) -> None:
        self.config = SpellingConfig() if config is None else config
        self.classifier = LetterClassifier(self.config, model, classifier)
        self._hysteresis = ScoreHysteresis(LETTERS, self.config.hold)
        self.reset()

    def reset(self) -> None:
        """Forget the history (the next letter can be the last committed one)."""
        self._hysteresis.reset()
        self._committed_at: np.ndarray | None = None
        self.posterior: np.ndarray | None = None

    @property
    def current(self) -> tuple[str | None, float]:
        """The most likely letter now and its smoothed probability (None, 0 before any
        frame)."""
        if self.posterior is None:
            return None, 0.0
        i = int(np.argmax(self.posterior))
        return LETTERS[i], float(self.posterior[i])

    def update(self, q: np.ndarray | None, stamp: float) -> str | None:
        """Feed one frame (None: no hand); returns the letter committed on it, if any."""
        if q is None:
            self.reset()
            return None
        q = np.asarray(q, dtype=float)
        p = _softmax(self.classifier.log_likelihoods(q))
        wrist = q[0:3]
        for letter in self._hysteresis.active:
            if self._committed_at is not None and \
                    np.linalg.norm(wrist - self._committed_at) >= self.config.rearm_motion_m:
                self._hysteresis.release(letter)      # a double letter: held anew here
        changes = self._hysteresis.update(dict(zip(LETTERS, p, strict=True)), stamp)
        smoothed = self._hysteresis.smoothed
        self.posterior = np.array([smoothed[k] for k in LETTERS])
        started = [t.name for t in changes if t.state == 'start']
        if not started:
            return None
        self._committed_at = wrist.copy()
        return started[0]
