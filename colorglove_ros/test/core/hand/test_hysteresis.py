"""The shared hold-and-release hysteresis: hold times in seconds, thresholds, loss, release."""
from __future__ import annotations

import pytest

from colorglove_ros.core.hand.hysteresis import HoldConfig, HysteresisError, ScoreHysteresis

CONFIG = HoldConfig(smoothing=1.0, on_score=0.7, off_score=0.3, hold_on_s=0.1, hold_off_s=0.2)


def _feed(h: ScoreHysteresis, frames: list[tuple[float, float, float]]) -> list[tuple]:
    out = []
    for t, a, b in frames:
        out += [(x.name, x.state, round(x.stamp, 6)) for x in h.update({'a': a, 'b': b}, t)]
    return out


def test_start_needs_the_hold_time_and_end_the_release_time() -> None:
    h = ScoreHysteresis(('a', 'b'), CONFIG)
    frames = [(k * 0.05, 0.9, 0.0) for k in range(4)]          # a on from t = 0
    assert _feed(h, frames) == [('a', 'start', 0.1)]
    assert h.active == ('a',)
    # between the thresholds: stays on; one low frame resets nothing
    assert _feed(h, [(0.2, 0.5, 0.0), (0.25, 0.1, 0.0), (0.3, 0.8, 0.0)]) == []
    low = [(0.35 + k * 0.05, 0.1, 0.0) for k in range(6)]
    assert _feed(h, low) == [('a', 'end', 0.55)]
    assert h.active == ()


def test_smoothing_delays_the_crossing() -> None:
    h = ScoreHysteresis(('a', 'b'), HoldConfig(smoothing=0.5, on_score=0.7, off_score=0.3,
                                               hold_on_s=0.0, hold_off_s=0.0))
    # smoothed: 0, 0.5, 0.75 -> on at the third frame
    assert _feed(h, [(0.0, 0.0, 0.0), (0.1, 1.0, 0.0), (0.2, 1.0, 0.0)]) == [
        ('a', 'start', 0.2)]
    assert h.smoothed['a'] == pytest.approx(0.75)


def test_loss_and_release() -> None:
    h = ScoreHysteresis(('a', 'b'), CONFIG)
    _feed(h, [(k * 0.05, 0.9, 0.9) for k in range(4)])
    assert h.active == ('a', 'b')
    h.release('b')
    assert h.active == ('a',)
    # b, still high, must hold again before it starts anew
    assert _feed(h, [(0.2, 0.9, 0.9), (0.25, 0.9, 0.9)]) == []
    assert _feed(h, [(0.3, 0.9, 0.9)]) == [('b', 'start', 0.3)]
    lost = h.lose(0.4)
    assert [(x.name, x.state, x.score) for x in lost] == [('a', 'end', 0.0), ('b', 'end', 0.0)]
    assert h.active == () and h.smoothed == {}


def test_bad_settings_and_scores() -> None:
    with pytest.raises(HysteresisError):
        HoldConfig(on_score=0.3, off_score=0.5)
    with pytest.raises(HysteresisError):
        HoldConfig(hold_on_s=-1.0)
    with pytest.raises(HysteresisError):
        ScoreHysteresis(('a', 'a'))
    with pytest.raises(HysteresisError):
        ScoreHysteresis(('a', 'b')).update({'a': 1.0}, 0.0)
