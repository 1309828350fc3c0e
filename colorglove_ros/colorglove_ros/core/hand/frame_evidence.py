"""How well the tracked pose explains its frame, as the consumers of the pose see it.

``ik_node`` ends every tracked frame with a status line (:func:`tracking_status`): the number
of constraints the IK matched to observed glove blobs, their mean reprojection error at the
output pose and the frame's stamp. The gesture and spelling cores read it back
(:func:`parse_tracking_status`); an :class:`EvidencePairer` gives each pose the status line of
its own frame (same stamp; the line and the pose travel on different topics, in either
order), and an :class:`EvidenceGate` sets aside the frames whose pose the image explains
poorly: such a frame neither starts nor ends anything (it is skipped, not a lost hand), so a
whole hold the tracker misreads with few or badly fitting constraints starts no gesture,
while a good hold with a few weak frames is not cut. Frames without evidence (another
tracker's status, a line lost, or none) always count. ``edge_tracker_node``'s line
(:func:`edge_tracking_status`: the links found and the edge residual, on another scale than
the glove IK's reprojection) is read by :func:`parse_edge_tracking_status` only (the mouse).
No rclpy import.
"""
from __future__ import annotations

import math
import re
from collections import OrderedDict
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Generic, TypeVar

import numpy as np

from colorglove_ros.core.errors import ColorGloveError
from colorglove_ros.core.validation import check_number

__all__ = ['FrameEvidenceError', 'FrameEvidence', 'EvidenceGate', 'EvidencePairer',
           'Stamp', 'FOLLOWED_NOTE', 'tracking_status', 'parse_tracking_status',
           'edge_tracking_status', 'parse_edge_tracking_status']

Stamp = tuple[int, int]          # a frame's header stamp (sec, nanosec)
Frame = TypeVar('Frame')


class FrameEvidenceError(ColorGloveError, ValueError):
    """Bad evidence-gate settings."""


@dataclass(frozen=True)
class FrameEvidence:
    """One tracked frame's evidence: matched constraints and their mean reprojection error
    (px; NaN when unknown), and the stamp of the frame it is of (None: unknown). The first two
    may also be arrays of frames (the evaluations)."""

    constraints: float | np.ndarray = math.nan
    reprojection_px: float | np.ndarray = math.nan
    stamp: Stamp | None = None


@dataclass(frozen=True)
class EvidenceGate:
    """A frame is weak when its reprojection error is above ``max_reprojection_px`` or it
    matched fewer than ``min_constraints`` constraints; unknown values never make a frame
    weak. The defaults let every frame through (off)."""

    max_reprojection_px: float = math.inf
    min_constraints: float = 0.0

    def __post_init__(self) -> None:
        if self.max_reprojection_px != math.inf:       # inf: no reprojection gate
            check_number('max_reprojection_px', self.max_reprojection_px, low=0.0,
                         low_open=True, error=FrameEvidenceError)
        check_number('min_constraints', self.min_constraints, low=0.0,
                     error=FrameEvidenceError)

    @property
    def enabled(self) -> bool:
        """Whether any frame can be weak."""
        return self.max_reprojection_px < math.inf or self.min_constraints > 0.0

    def weak(self, evidence: FrameEvidence | None) -> bool | np.ndarray:
        """Whether the frame (or each frame, for array fields) is weak; None is not."""
        if evidence is None:
            return False
        with np.errstate(invalid='ignore'):
            out = (np.greater(evidence.reprojection_px, self.max_reprojection_px)
                   | np.less(evidence.constraints, self.min_constraints))
        return bool(out) if np.ndim(out) == 0 else out


_STATUS = re.compile(r'^tracking: (\d+) constraints\b.*?, reprojection (\S+) px\b')
_STAMP = re.compile(r', frame (\d+)\.(\d{9})$')


#: What a tracked frame's status line adds when the tracker followed a hand the image's
#: border cuts from its last pose (``core.pipeline.StageLimits.follow_cut_hands``).
FOLLOWED_NOTE = 'followed from the last pose (hand cut by the image border)'


def tracking_status(constraints: int, per_camera: str, reprojection_px: float,
                    ik_ms: float, stamp: Stamp | None = None, followed: bool = False) -> str:
    """ik_node's status line of a tracked frame (``per_camera``: e.g. ``'cam0 12, cam1 4'``;
    ``followed``: :data:`FOLLOWED_NOTE` added), ending with the frame's header stamp
    (``frame <sec>.<nanosec>``) when given."""
    note = f', {FOLLOWED_NOTE}' if followed else ''
    return _stamped(f'tracking: {constraints} constraints ({per_camera}), reprojection '
                    f'{reprojection_px:.1f} px, IK {ik_ms:.1f} ms{note}', stamp)


def parse_tracking_status(text: str) -> FrameEvidence | None:
    """The evidence in a :func:`tracking_status` line; None for any other line."""
    match = _STATUS.match(text)
    if match is None:
        return None
    return _evidence(float(match.group(1)), match.group(2), text)


def _stamped(line: str, stamp: Stamp | None) -> str:
    """A status ``line`` ending with the frame's header stamp (``frame <sec>.<nanosec>``)
    when given."""
    return line if stamp is None else f'{line}, frame {stamp[0]}.{stamp[1]:09d}'


def _evidence(constraints: float, residual_text: str, text: str) -> FrameEvidence:
    """The evidence of a status line ``text`` whose residual reads ``residual_text`` (NaN
    when it is no number) and whose stamp, if any, ends it (:func:`_stamped`)."""
    try:
        residual = float(residual_text)
    except ValueError:
        residual = math.nan
    stamp = _STAMP.search(text)
    return FrameEvidence(constraints, residual,
                         None if stamp is None else (int(stamp.group(1)), int(stamp.group(2))))


_EDGE_STATUS = re.compile(r'^tracking: links found (.*?), edge residual (\S+) px\b')
_EDGE_CAMERA = re.compile(r'\S+ (\d+)$')


def edge_tracking_status(links_found: Sequence[tuple[str, int]], residual_px: float,
                         time_ms: float, stamp: Stamp | None = None) -> str:
    """edge_tracker_node's status line of a tracked frame: the links found per camera
    (name, count), the fit's edge residual and time, and the frame's header stamp (``frame
    <sec>.<nanosec>``) when given."""
    per_camera = ', '.join(f'{name} {n}' for name, n in links_found)
    return _stamped(f'tracking: links found {per_camera}, edge residual {residual_px:.2f} px, '
                    f'{time_ms:.1f} ms', stamp)


def parse_edge_tracking_status(text: str) -> FrameEvidence | None:
    """The evidence in an :func:`edge_tracking_status` line (constraints: the links found
    over the cameras; reprojection: the edge residual); None for any other line."""
    match = _EDGE_STATUS.match(text)
    if match is None:
        return None
    counts = [_EDGE_CAMERA.search(part.strip()) for part in match.group(1).split(',')]
    return _evidence(float(sum(int(c.group(1)) for c in counts if c is not None)),
                     match.group(2), text)


class EvidencePairer(Generic[Frame]):
    """Gives each tracked frame the evidence of its own status line.

    :meth:`add_frame` and :meth:`add_status` return the frames now ready, oldest first, each
    with its evidence. A frame whose line (same stamp) is already in goes at once; otherwise
    it waits for the next status line: its own (same stamp), or a line without a stamp
    (another tracker's, an older ik_node's, ``no hand``), which ik_node publishes after the
    frame's pose, pairs with it; a newer frame or a newer frame's line lets it go without
    evidence (its line was lost). While no stamped line has been seen, a frame let go so
    has the newest line's evidence instead. ``keep`` lines wait for their frame at most."""

    def __init__(self, keep: int = 32) -> None:
        self.keep = keep
        self._lines: OrderedDict[Stamp, FrameEvidence] = OrderedDict()
        self._waiting: tuple[Stamp, Frame] | None = None
        self._stamped = False
        self._newest: FrameEvidence | None = None

    def add_frame(self, stamp: Stamp, frame: Frame
                  ) -> list[tuple[Frame, FrameEvidence | None]]:
        """A tracked frame of header stamp ``stamp``."""
        ready = self.flush()
        for old in [s for s in self._lines if s < stamp]:
            del self._lines[old]
        if stamp in self._lines:
            ready.append((frame, self._lines.pop(stamp)))
        else:
            self._waiting = (stamp, frame)
        return ready

    def add_status(self, evidence: FrameEvidence | None
                   ) -> list[tuple[Frame, FrameEvidence | None]]:
        """A status line's evidence (``parse_tracking_status``; None for other lines)."""
        if evidence is None or evidence.stamp is None:
            self._newest = evidence
            return self._release(evidence)
        self._stamped = True
        if self._waiting is not None and self._waiting[0] == evidence.stamp:
            return self._release(evidence)
        ready = self.flush() if self._waiting is not None and \
            self._waiting[0] < evidence.stamp else []
        self._lines[evidence.stamp] = evidence
        while len(self._lines) > self.keep:
            self._lines.popitem(last=False)
        return ready

    def flush(self) -> list[tuple[Frame, FrameEvidence | None]]:
        """The waiting frame, if any, without its line."""
        return self._release(None if self._stamped else self._newest)

    def _release(self, evidence: FrameEvidence | None
                 ) -> list[tuple[Frame, FrameEvidence | None]]:
        if self._waiting is None:
            return []
        frame = self._waiting[1]
        self._waiting = None
        return [(frame, evidence)]
