"""How well the tracked pose explains its frame, as the consumers of the pose see it.

``ik_node`` ends every tracked frame with a status line (:func:`tracking_status`): the number
of constraints the IK matched to observed glove blobs and their mean reprojection error at the
output pose. The gesture and spelling cores read it back (:func:`parse_tracking_status`) and
an :class:`EvidenceGate` sets aside the frames whose pose the image explains poorly: such a
frame neither starts nor ends anything (it is skipped, not a lost hand), so a whole hold the
tracker misreads with few or badly fitting constraints starts no gesture, while a good hold
with a few weak frames is not cut. Frames without evidence (another tracker's status, or
none) always count. No rclpy import.
"""
from __future__ import annotations

import math
import re
from dataclasses import dataclass

import numpy as np

from colorglove_ros.core.errors import ColorGloveError
from colorglove_ros.core.validation import check_number

__all__ = ['FrameEvidenceError', 'FrameEvidence', 'EvidenceGate', 'tracking_status',
           'parse_tracking_status']


class FrameEvidenceError(ColorGloveError, ValueError):
    """Bad evidence-gate settings."""


@dataclass(frozen=True)
class FrameEvidence:
    """One tracked frame's evidence: matched constraints and their mean reprojection error
    (px; NaN when unknown). Fields may also be arrays of frames (the evaluations)."""

    constraints: float | np.ndarray = math.nan
    reprojection_px: float | np.ndarray = math.nan


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


def tracking_status(constraints: int, per_camera: str, reprojection_px: float,
                    ik_ms: float) -> str:
    """ik_node's status line of a tracked frame (``per_camera``: e.g. ``'cam0 12, cam1 4'``)."""
    return (f'tracking: {constraints} constraints ({per_camera}), reprojection '
            f'{reprojection_px:.1f} px, IK {ik_ms:.1f} ms')


def parse_tracking_status(text: str) -> FrameEvidence | None:
    """The evidence in a :func:`tracking_status` line; None for any other line."""
    match = _STATUS.match(text)
    if match is None:
        return None
    try:
        reprojection = float(match.group(2))
    except ValueError:
        reprojection = math.nan
    return FrameEvidence(float(match.group(1)), reprojection)
