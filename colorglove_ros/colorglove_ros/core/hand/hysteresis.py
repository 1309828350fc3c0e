"""Hold and release with hysteresis: which of a set of per-frame scores is on, over time.

Shared by the gesture events (``gestures.py``) and the finger-spelling's hold-to-commit
(``spelling.py``). Each frame's scores (one per name, in [0, 1]) are smoothed by an
exponential moving average (weight ``smoothing`` on the newest frame). A name turns on
(``start``) once its smoothed score has stayed at or above ``on_score`` for ``hold_on_s``
seconds, and off (``end``) once it has stayed below ``off_score`` for ``hold_off_s`` seconds;
a lost hand turns every name off at once. Durations are measured between frame stamps, so
the behaviour does not depend on the frame rate (``hold_on_s = 0``: the first frame over the
threshold decides).
"""
from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, fields

from colorglove_ros.core.errors import ColorGloveError
from colorglove_ros.core.validation import check_number

__all__ = ['HysteresisError', 'HoldConfig', 'Transition', 'ScoreHysteresis']


class HysteresisError(ColorGloveError, ValueError):
    """Bad hold settings or scores."""


@dataclass(frozen=True)
class HoldConfig:
    """Smoothing weight of the newest frame, the two thresholds and the two hold times."""

    smoothing: float = 0.3
    on_score: float = 0.7
    off_score: float = 0.3
    hold_on_s: float = 0.05
    hold_off_s: float = 0.15

    def __post_init__(self) -> None:
        for f in fields(self):
            low_open = f.name not in ('hold_on_s', 'hold_off_s')
            high = None if f.name.endswith('_s') else 1.0
            check_number(f.name, getattr(self, f.name), low=0.0, low_open=low_open, high=high,
                         error=HysteresisError)
        if not self.off_score < self.on_score < 1.0:
            raise HysteresisError(f'need 0 < off_score < on_score < 1, got {self.off_score}, '
                                  f'{self.on_score}')


@dataclass(frozen=True)
class Transition:
    """``name`` turned on (``state`` 'start') or off ('end') at ``stamp`` with smoothed
    ``score`` (0 for a lost hand)."""

    name: str
    state: str
    score: float
    stamp: float


class ScoreHysteresis:
    """Per-name on/off state from per-frame scores (module docstring)."""

    def __init__(self, names: Sequence[str], config: HoldConfig | None = None) -> None:
        if not names or len(set(names)) != len(names):
            raise HysteresisError(f'need distinct names, got {list(names)}')
        self.names = tuple(names)
        self.config = HoldConfig() if config is None else config
        self.reset()

    def reset(self) -> None:
        """Forget everything, without transitions."""
        self.smoothed: dict[str, float] = {}
        self._on: dict[str, bool] = dict.fromkeys(self.names, False)
        self._since: dict[str, float | None] = dict.fromkeys(self.names)

    @property
    def active(self) -> tuple[str, ...]:
        """The names on now."""
        return tuple(n for n in self.names if self._on[n])

    def update(self, scores: Mapping[str, float], stamp: float) -> list[Transition]:
        """Feed one frame's scores (every name); returns the transitions it decided."""
        missing = set(self.names) - set(scores)
        if missing:
            raise HysteresisError(f'scores lack {sorted(missing)}')
        c = self.config
        a = c.smoothing
        self.smoothed = {n: float(scores[n]) if n not in self.smoothed
                         else a * float(scores[n]) + (1.0 - a) * self.smoothed[n]
                         for n in self.names}
        out = []
        for n in self.names:
            s, on = self.smoothed[n], self._on[n]
            crossing = s < c.off_score if on else s >= c.on_score
            if not crossing:
                self._since[n] = None
                continue
            since = self._since[n] = stamp if self._since[n] is None else self._since[n]
            if stamp - since >= (c.hold_off_s if on else c.hold_on_s) - 1e-9:
                self._on[n], self._since[n] = not on, None
                out.append(Transition(n, 'end' if on else 'start', s, stamp))
        return out

    def lose(self, stamp: float) -> list[Transition]:
        """The hand is gone: every active name ends (score 0) and the history is forgotten."""
        out = [Transition(n, 'end', 0.0, stamp) for n in self.active]
        self.reset()
        return out

    def release(self, name: str) -> None:
        """Turn ``name`` off without a transition (it must then hold again to start)."""
        self._on[name], self._since[name] = False, None
