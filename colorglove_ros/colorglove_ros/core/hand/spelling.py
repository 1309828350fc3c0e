"""Finger-spelling: the 26 one-hand alphabet letters from the tracked pose, committed by holding.

Templates: each letter's finger DOFs are the pose collection's ``LETTER_SHAPES``; its
orientation is the direction the fingers point in the camera frame (the hand frame's ``-y``
axis), with the camera upright (image down = gravity): up for most letters, toward the image
right for G and H, tipped 45 deg toward the camera for P, and both for Q
(``LETTER_ROLL_PITCH``; within the tracker's orientation range, so P and Q are milder than
signed). The alphabet is static here: J and Z are their handshapes held still (their motion is
not modelled).

Classifier: a Gaussian likelihood per letter with a shared isotropic spread per feature group
(finger joints in radians over ``joint_sigma``, pointing direction over ``direction_sigma``),
its log smoothed over frames by an exponential moving average, and a softmax posterior.
Hold-to-commit: every frame votes for its most likely letter if its posterior is at least
``min_posterior``; a letter is emitted once it holds ``vote_share`` of the votes of the last
``hold_s`` seconds (noise may flip single frames without resetting the hold). The same letter
again (a double letter) needs a re-arm: another letter or no hand for ``release_s``, or the
wrist moving ``rearm_motion_m`` since the commit and the letter then held ``hold_s`` again
(double letters are signed with a small slide).
"""
from __future__ import annotations

from collections import Counter, deque
from dataclasses import dataclass

import numpy as np

from colorglove_ros.core.errors import ColorGloveError
from colorglove_ros.core.hand.model import NUM_DOFS, HandModel, rotvec_to_matrix
from colorglove_ros.core.hand.poses import LETTER_SHAPES
from colorglove_ros.core.validation import check_number

__all__ = [
    'LETTERS', 'THUMB_LETTERS', 'LETTER_ROLL_PITCH', 'SpellingError', 'SpellingConfig',
    'letter_rotation', 'pointing_direction', 'LetterClassifier', 'Speller',
]

LETTERS: tuple[str, ...] = tuple(sorted(LETTER_SHAPES))
THUMB_LETTERS: tuple[str, ...] = ('E', 'M', 'N', 'S', 'T')
# (roll about the camera z, then pitch toward the camera) of each letter's pointing direction,
# degrees; letters not listed point up
LETTER_ROLL_PITCH: dict[str, tuple[float, float]] = {
    'G': (90.0, 0.0), 'H': (90.0, 0.0), 'P': (0.0, 45.0), 'Q': (90.0, 45.0)}

assert len(LETTERS) == 26 and set(THUMB_LETTERS) <= set(LETTERS)
# (excluded lower, included upper) bound of every SpellingConfig setting
_SETTING_BOUNDS: dict[str, tuple[float, float | None]] = {
    'joint_sigma_deg': (0.0, None), 'direction_sigma': (0.0, None), 'smoothing': (0.0, 1.0),
    'min_posterior': (0.0, 1.0), 'hold_s': (0.0, None), 'vote_share': (0.5, 1.0),
    'release_s': (0.0, None), 'rearm_motion_m': (0.0, None)}


class SpellingError(ColorGloveError, ValueError):
    """Bad spelling settings or input."""


@dataclass(frozen=True)
class SpellingConfig:
    """Classifier spreads and hold-to-commit timing."""

    joint_sigma_deg: float = 12.0
    direction_sigma: float = 0.3
    smoothing: float = 0.6           # EMA weight of the newest frame's log-likelihoods
    min_posterior: float = 0.35
    hold_s: float = 0.5
    vote_share: float = 0.7
    release_s: float = 0.15
    rearm_motion_m: float = 0.03

    def __post_init__(self) -> None:
        for name, (low, high) in _SETTING_BOUNDS.items():
            check_number(name, getattr(self, name), low=low, low_open=True, high=high,
                         error=SpellingError)
        if self.min_posterior == 1.0:
            raise SpellingError('min_posterior must be < 1, got 1.0')


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
    """Per-frame log-likelihoods of the 26 letters from a 26-DOF pose."""

    def __init__(self, config: SpellingConfig | None = None,
                 model: HandModel | None = None) -> None:
        self.config = SpellingConfig() if config is None else config
        model = HandModel() if model is None else model
        lo, hi = model.lower_limits[6:], model.upper_limits[6:]
        self._joints = np.stack([np.clip(LETTER_SHAPES[k], lo, hi) for k in LETTERS])
        rest = np.zeros(NUM_DOFS)
        directions = []
        for k in LETTERS:
            rest[3:6] = letter_rotation(k)
            directions.append(pointing_direction(rest))
        self._directions = np.stack(directions)

    def log_likelihoods(self, q: np.ndarray) -> np.ndarray:
        """(26,) log-likelihood of each letter in ``LETTERS`` order (up to a constant)."""
        q = np.asarray(q, dtype=float)
        if q.shape != (NUM_DOFS,) or not np.all(np.isfinite(q)):
            raise SpellingError(f'pose must be 26 finite values, got shape {q.shape}')
        c = self.config
        joint = np.sum((q[6:] - self._joints) ** 2, axis=1) / np.deg2rad(c.joint_sigma_deg) ** 2
        direction = np.sum((pointing_direction(q) - self._directions) ** 2, axis=1) \
            / c.direction_sigma ** 2
        return -0.5 * (joint + direction)


def _softmax(x: np.ndarray) -> np.ndarray:
    e = np.exp(x - x.max())
    return e / e.sum()


class Speller:
    """Hold-to-commit letter stream from tracked poses (one per hand)."""

    def __init__(self, config: SpellingConfig | None = None,
                 model: HandModel | None = None) -> None:
        self.config = SpellingConfig() if config is None else config
        self.classifier = LetterClassifier(self.config, model)
        self.reset()

    def reset(self) -> None:
        """Forget the history (the next letter can be the last committed one)."""
        self._smoothed: np.ndarray | None = None
        self._votes: deque[tuple[float, str | None]] = deque()
        self._committed: str | None = None
        self._committed_at: np.ndarray | None = None
        self._away_since: float | None = None
        self._armed = True
        self.posterior: np.ndarray | None = None

    @property
    def current(self) -> tuple[str | None, float]:
        """The most likely letter now and its posterior (None, 0 before any frame)."""
        if self.posterior is None:
            return None, 0.0
        i = int(np.argmax(self.posterior))
        return LETTERS[i], float(self.posterior[i])

    def update(self, q: np.ndarray | None, stamp: float) -> str | None:
        """Feed one frame (None: no hand); returns the letter committed on it, if any."""
        c = self.config
        if q is None:
            self.reset()
            return None
        log_l = self.classifier.log_likelihoods(q)
        self._smoothed = log_l if self._smoothed is None else \
            c.smoothing * log_l + (1.0 - c.smoothing) * self._smoothed
        self.posterior = _softmax(self._smoothed)
        letter, p = self.current
        if p < c.min_posterior:
            letter = None
        self._votes.append((stamp, letter))
        self._update_arming(letter, np.asarray(q, dtype=float)[0:3], stamp)
        winner = self._vote_winner(stamp)
        if winner is None or (winner == self._committed and not self._armed):
            return None
        self._committed, self._committed_at = winner, np.asarray(q, dtype=float)[0:3].copy()
        self._armed, self._away_since = False, None
        self._votes.clear()
        return winner

    def _vote_winner(self, stamp: float) -> str | None:
        """The letter holding ``vote_share`` of the frames of the last ``hold_s`` seconds,
        once the votes span that long."""
        c = self.config
        while self._votes and self._votes[0][0] < stamp - c.hold_s:
            self._votes.popleft()
        if not self._votes or stamp - self._votes[0][0] < c.hold_s - 1e-6:
            return None
        counts = Counter(letter for _, letter in self._votes if letter is not None)
        if not counts:
            return None
        letter, n = counts.most_common(1)[0]
        return letter if n >= c.vote_share * len(self._votes) else None

    def _update_arming(self, letter: str | None, wrist: np.ndarray, stamp: float) -> None:
        if self._armed or self._committed is None:
            return
        c = self.config
        if letter != self._committed:
            self._away_since = stamp if self._away_since is None else self._away_since
            if stamp - self._away_since >= c.release_s:
                self._armed = True
        else:
            self._away_since = None
        if self._committed_at is not None and \
                np.linalg.norm(wrist - self._committed_at) >= c.rearm_motion_m:
            # a double letter: the same letter held anew at the new place
            self._armed = True
            self._votes.clear()

