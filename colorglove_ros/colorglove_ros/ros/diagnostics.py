"""Health of a pipeline node as ``diagnostic_msgs/DiagnosticArray``: per-frame outcomes counted
(frames, frames with a hand, refusals per kind, latency of the frame's stamp), summarised once
a period into a level (OK / WARN / ERROR) and a message, as ROS's diagnostic_updater does
(status name ``'<node name>: <what>'``, a hardware_id, published on ``/diagnostics``). No rclpy
import: the nodes feed it, so the counting and the levels are unit-testable in one process."""
from __future__ import annotations

import math
from collections import Counter
from collections.abc import Mapping
from dataclasses import dataclass, field

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue

__all__ = ['DIAGNOSTICS_TOPIC', 'DIAGNOSTICS_PERIOD_S', 'OK', 'WARN', 'ERROR', 'FrameStats',
           'Summary', 'refusal_kind', 'upstream', 'status_msg', 'diagnostic_array']

DIAGNOSTICS_TOPIC = '/diagnostics'
"""Where diagnostic_updater publishes (absolute: one topic for the whole graph)."""
DIAGNOSTICS_PERIOD_S = 1.0
"""Seconds between two reports (diagnostic_updater's default period)."""
OK, WARN, ERROR = DiagnosticStatus.OK, DiagnosticStatus.WARN, DiagnosticStatus.ERROR


def refusal_kind(reason: str) -> str:
    """The kind of a 'no hand' reason: its text before the first ':' (``'camera: image
    1280x960 but ...'`` -> ``'camera'``, ``'lost'`` -> ``'lost'``)."""
    return reason.split(':', 1)[0].strip() or 'unknown'


def upstream(reason: str) -> str:
    """The reason of a frame an earlier stage already found no hand in (kind 'upstream')."""
    return f'upstream: {reason or "no hand"}'


@dataclass(frozen=True)
class Summary:
    """One period's report: level, message and the key/value pairs (all as text)."""

    level: bytes
    message: str
    values: dict[str, str] = field(default_factory=dict)


class FrameStats:
    """Per-frame outcomes of one node: call :meth:`hand` or :meth:`no_hand` once per frame,
    :meth:`summary` once per period (which starts the next period).

    Failures beside a frame's output (:meth:`fault`: the output went out, some work after it
    failed) are counted per :func:`refusal_kind` too and make the period WARN.

    Refusals are counted per :func:`refusal_kind` since start-up; kinds in ``counted_elsewhere``
    are read from that counter instead (e.g. ``{'camera': FrameCamera.refused}``, which counts
    its refusals per kind itself) and reported as ``'<kind>: <sub-kind>'``. ``what`` names the
    outputs in the messages (``'hand'``, ``'image'``).
    """

    def __init__(self, counted_elsewhere: Mapping[str, Mapping[str, int]] | None = None,
                 what: str = 'hand') -> None:
        self.counted_elsewhere = dict(counted_elsewhere or {})
        self.what = what
        self.frames = 0
        self.frames_with_hand = 0
        self.refused: Counter[str] = Counter()
        self.faults: Counter[str] = Counter()
        self.last_fault = ''
        self._period_faults = 0
        self.last_reason = ''
        self.last_was_error = False
        self.last_values: dict[str, str] = {}
        self._period_frames = 0
        self._period_errors = 0
        self._period_latency_s: list[float] = []

    def _frame(self, latency_s: float | None) -> None:
        self.frames += 1
        self._period_frames += 1
        if latency_s is not None and math.isfinite(latency_s):
            self._period_latency_s.append(latency_s)

    def hand(self, latency_s: float | None = None, **values: object) -> None:
        """A frame with an output (``latency_s``: now minus the frame's stamp; ``values``:
        figures of this frame shown until the next one, e.g. constraint counts)."""
        self._frame(latency_s)
        self.frames_with_hand += 1
        self.last_reason, self.last_was_error = '', False
        self.last_values = {key: str(value) for key, value in values.items()}

    def no_hand(self, reason: str, error: bool = False, latency_s: float | None = None) -> None:
        """A frame without an output and why; ``error``: the frame or a stage failed (bad
        input, refused fit) rather than no hand being seen."""
        self._frame(latency_s)
        kind = refusal_kind(reason)
        if kind not in self.counted_elsewhere:
            self.refused[kind] += 1
        self.last_reason, self.last_was_error = reason, bool(error)
        self._period_errors += bool(error)
        self.last_values = {}

    def fault(self, reason: str) -> None:
        """A failure beside the frame's output (counted once more, the frame itself as it
        was counted), e.g. the segmenter's background learning after the observation went
        out."""
        self.faults[refusal_kind(reason)] += 1
        self.last_fault = reason
        self._period_faults += 1

    def refusals(self) -> dict[str, int]:
        """Frames refused since start-up per kind (other counters' kinds as
        ``'<kind>: <sub-kind>'``)."""
        counts = dict(self.refused)
        for kind, counter in self.counted_elsewhere.items():
            counts.update({f'{kind}: {sub}': int(n) for sub, n in counter.items() if n})
        return counts

    def summary(self, period_s: float) -> Summary:
        """The report of the period of ``period_s`` seconds that ends now; starts the next.

        ERROR: every frame of the period failed (bad input, a stage failing, a refused fit);
        WARN: no frame in the period, some failed, the newest frame had no hand (hand lost),
        or some work beside the outputs failed (:meth:`fault`); OK otherwise."""
        frames, errors, latency = self._period_frames, self._period_errors, \
            self._period_latency_s
        faults, self._period_faults = self._period_faults, 0
        self._period_frames, self._period_errors, self._period_latency_s = 0, 0, []
        rate = frames / period_s if period_s > 0 else 0.0
        values = {'rate (Hz)': f'{rate:.1f}', 'frames': str(self.frames),
                  f'frames with {self.what}': str(self.frames_with_hand)}
        if latency:
            values['latency mean (ms)'] = f'{1e3 * sum(latency) / len(latency):.1f}'
            values['latency max (ms)'] = f'{1e3 * max(latency):.1f}'
        values.update({f'refused: {kind}': str(n) for kind, n in
                       sorted(self.refusals().items())})
        values.update({f'fault: {kind}': str(n) for kind, n in sorted(self.faults.items())})
        values.update(self.last_values)
        if frames == 0:
            level, message = WARN, f'no frames in the last {period_s:g} s'
        elif errors == frames:
            level, message = ERROR, f'frames refused: {self.last_reason}'
        elif self.last_reason:
            level = WARN
            message = (f'frame refused: {self.last_reason}' if self.last_was_error
                       else f'{self.what} lost: {self.last_reason}')
        elif errors:
            level, message = WARN, f'{errors} of {frames} frames refused, {rate:.1f} Hz'
        elif faults:
            level, message = WARN, f'{faults} fault(s) beside the outputs: {self.last_fault}'
        else:
            level, message = OK, f'{rate:.1f} Hz'
        return Summary(level, message, values)


def status_msg(summary: Summary, name: str, hardware_id: str) -> DiagnosticStatus:
    """A ``DiagnosticStatus`` of ``summary`` (``name``: ``'<node name>: <what>'``)."""
    return DiagnosticStatus(level=summary.level, name=name, message=summary.message,
                            hardware_id=hardware_id,
                            values=[KeyValue(key=key, value=value)
                                    for key, value in summary.values.items()])


def diagnostic_array(header, statuses: list[DiagnosticStatus]) -> DiagnosticArray:
    """A ``DiagnosticArray`` of ``statuses`` with ``header`` (stamp: now)."""
    return DiagnosticArray(header=header, status=statuses)
