"""SIGTERM and SIGHUP as ``SystemExit`` for tools that start processes, so their ``finally``
blocks stop what they started (the nodes run in sessions of their own and get no signal of the
tool's). Two refinements make that clean-up complete:

- a signal that arrives while a child process is being started is held until the start is
  recorded (:func:`deferred`): a ``SystemExit`` inside ``subprocess.Popen`` would leave a
  started child that no ``finally`` knows about;
- only the first signal exits; later ones are ignored, so a repeated SIGTERM cannot cut the
  clean-up itself short.
"""
from __future__ import annotations

import signal
import threading
from collections.abc import Iterator
from contextlib import contextmanager

__all__ = ['HANDLED_SIGNALS', 'deferred', 'exit_on_signals']

HANDLED_SIGNALS = (signal.SIGTERM, signal.SIGHUP)
_state: dict[str, object] = {'deferring': 0, 'pending': None, 'exiting': False}


def _on_signal(signum: int, _frame: object) -> None:
    if _state['exiting']:
        return
    if _state['deferring']:
        _state['pending'] = signum
        return
    _state['exiting'] = True
    raise SystemExit(128 + signum)


@contextmanager
def exit_on_signals() -> Iterator[None]:
    """Within this block SIGTERM and SIGHUP raise ``SystemExit`` (once) in the main thread;
    elsewhere (not the main thread) the block changes nothing."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    _state.update(deferring=0, pending=None, exiting=False)
    previous = {sig: signal.signal(sig, _on_signal) for sig in HANDLED_SIGNALS}
    try:
        yield
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)


@contextmanager
def deferred() -> Iterator[None]:
    """Hold a SIGTERM or SIGHUP that arrives in this block until its end (start a child
    process and record it inside the block)."""
    _state['deferring'] = int(_state['deferring']) + 1
    try:
        yield
    finally:
        _state['deferring'] = int(_state['deferring']) - 1
        signum = _state['pending']
        if not _state['deferring'] and signum is not None:
            _state['pending'] = None
            _on_signal(int(signum), None)
