"""SIGTERM / SIGHUP as SystemExit for tools: held while a child is being started, and once
only (a second signal during the clean-up is ignored)."""
from __future__ import annotations

import os
import signal

import pytest

from colorglove_ros import signal_exit


def test_signal_exits_at_once_outside_a_start() -> None:
    with pytest.raises(SystemExit) as exited, signal_exit.exit_on_signals():
        os.kill(os.getpid(), signal.SIGTERM)
        for _ in range(1000):         # the handler runs between bytecodes
            pass
    assert exited.value.code == 128 + signal.SIGTERM


def test_signal_during_a_start_waits_for_its_end() -> None:
    reached = []
    with pytest.raises(SystemExit), signal_exit.exit_on_signals():
        with signal_exit.deferred():
            os.kill(os.getpid(), signal.SIGHUP)
            for _ in range(1000):
                pass
            reached.append('recorded')       # the start completes and is recorded
        reached.append('after')              # not reached: the held signal exits here
    assert reached == ['recorded']


def test_second_signal_does_not_cut_the_clean_up() -> None:
    cleaned = []
    with pytest.raises(SystemExit), signal_exit.exit_on_signals():
        try:
            os.kill(os.getpid(), signal.SIGTERM)
            for _ in range(1000):
                pass
        finally:
            os.kill(os.getpid(), signal.SIGTERM)
            for _ in range(1000):
                pass
            cleaned.append('stopped')
    assert cleaned == ['stopped']
    assert signal.getsignal(signal.SIGTERM) is not signal_exit._on_signal   # restored
