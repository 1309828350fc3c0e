"""The tracker's evidence as the consumers read it (ik_node's status line) and the gate."""
from __future__ import annotations

import math

import numpy as np
import pytest

from colorglove_ros.core.hand.frame_evidence import (
    EvidenceGate,
    FrameEvidence,
    FrameEvidenceError,
    parse_tracking_status,
    tracking_status,
)


def test_status_line_round_trip() -> None:
    line = tracking_status(12, 'cam0 9, cam1 3', 2.14, 4.5)
    assert line == 'tracking: 12 constraints (cam0 9, cam1 3), reprojection 2.1 px, IK 4.5 ms'
    assert parse_tracking_status(line) == FrameEvidence(12.0, 2.1)
    unknown = parse_tracking_status(tracking_status(0, 'cam0 0', math.nan, 1.0))
    assert unknown is not None and unknown.constraints == 0 and math.isnan(unknown.reprojection_px)


@pytest.mark.parametrize('line', [
    'no hand: lost', 'tracking: links found cam0 12, edge residual 1.0 px, IK 3.0 ms',
    'tracking: cam0 pose', ''])
def test_other_status_lines_carry_no_evidence(line: str) -> None:
    assert parse_tracking_status(line) is None


def test_gate_is_off_by_default_and_weighs_known_values_only() -> None:
    assert not EvidenceGate().enabled
    assert not EvidenceGate().weak(FrameEvidence(0.0, 100.0))
    gate = EvidenceGate(max_reprojection_px=5.0, min_constraints=11)
    assert gate.enabled
    assert gate.weak(FrameEvidence(10.0, 1.0)) and gate.weak(FrameEvidence(15.0, 5.5))
    assert not gate.weak(FrameEvidence(11.0, 5.0))
    assert not gate.weak(FrameEvidence()) and not gate.weak(None)
    frames = FrameEvidence(np.array([10.0, 15.0, np.nan, 15.0]), np.array([1.0, 6.0, 9.0, 2.0]))
    np.testing.assert_array_equal(gate.weak(frames), [True, True, True, False])


@pytest.mark.parametrize('kwargs', [{'max_reprojection_px': 0.0}, {'min_constraints': -1.0},
                                    {'max_reprojection_px': math.nan}])
def test_bad_gate_settings(kwargs: dict) -> None:
    with pytest.raises(FrameEvidenceError):
        EvidenceGate(**kwargs)
