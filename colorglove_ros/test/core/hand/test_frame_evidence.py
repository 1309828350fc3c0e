"""The tracker's evidence as the consumers read it (ik_node's status line) and the gate."""
from __future__ import annotations

import math

import numpy as np
import pytest

from colorglove_ros.core.hand.frame_evidence import (
    FOLLOWED_NOTE,
    EvidenceGate,
    EvidencePairer,
    FrameEvidence,
    FrameEvidenceError,
    edge_tracking_status,
    parse_edge_tracking_status,
    parse_tracking_status,
    tracking_status,
)


def test_status_line_round_trip() -> None:
    line = tracking_status(12, 'cam0 9, cam1 3', 2.14, 4.5)
    assert line == 'tracking: 12 constraints (cam0 9, cam1 3), reprojection 2.1 px, IK 4.5 ms'
    assert parse_tracking_status(line) == FrameEvidence(12.0, 2.1)
    unknown = parse_tracking_status(tracking_status(0, 'cam0 0', math.nan, 1.0))
    assert unknown is not None and unknown.constraints == 0 and math.isnan(unknown.reprojection_px)
    stamped = tracking_status(12, 'cam0 12', 2.14, 4.5, (100, 33333333))
    assert stamped == ('tracking: 12 constraints (cam0 12), reprojection 2.1 px, IK 4.5 ms, '
                       'frame 100.033333333')
    assert parse_tracking_status(stamped) == FrameEvidence(12.0, 2.1, (100, 33333333))
    followed = tracking_status(5, 'cam0 5', 1.04, 2.0, (100, 33333333), followed=True)
    assert followed == ('tracking: 5 constraints (cam0 5), reprojection 1.0 px, IK 2.0 ms, '
                        f'{FOLLOWED_NOTE}, frame 100.033333333')
    assert parse_tracking_status(followed) == FrameEvidence(5.0, 1.0, (100, 33333333))


def test_edge_tracker_status_line_carries_its_links_residual_and_stamp() -> None:
    line = edge_tracking_status([('cam0', 9), ('cam1', 12)], 1.234, 8.5, (100, 33333333))
    assert line == ('tracking: links found cam0 9, cam1 12, edge residual 1.23 px, 8.5 ms, '
                    'frame 100.033333333')
    assert parse_edge_tracking_status(line) == FrameEvidence(21.0, 1.23, (100, 33333333))
    assert parse_edge_tracking_status(edge_tracking_status([('cam0', 4)], 0.5, 1.0)) \
        == FrameEvidence(4.0, 0.5)
    # the glove gates read ik_node's lines only, the mouse the edge tracker's only
    assert parse_tracking_status(line) is None
    assert parse_edge_tracking_status(tracking_status(12, 'cam0 12', 2.1, 4.5)) is None
    assert parse_edge_tracking_status('no hand: lost') is None


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


def _line(constraints: float, stamp: tuple[int, int]) -> FrameEvidence:
    return FrameEvidence(constraints, 2.0, stamp)


def test_pairer_gives_each_frame_its_own_line_in_either_order() -> None:
    pairer: EvidencePairer[str] = EvidencePairer()
    # the line after its frame: the frame waits for it
    assert pairer.add_status(_line(15, (1, 0))) == []
    assert pairer.add_frame((1, 0), 'a') == [('a', _line(15, (1, 0)))]
    assert pairer.add_frame((2, 0), 'b') == []
    assert pairer.add_status(_line(6, (2, 0))) == [('b', _line(6, (2, 0)))]
    # the line before its frame
    assert pairer.add_status(_line(9, (3, 0))) == []
    assert pairer.add_frame((3, 0), 'c') == [('c', _line(9, (3, 0)))]


def test_pairer_lets_a_frame_whose_line_is_lost_go_without_evidence() -> None:
    pairer: EvidencePairer[str] = EvidencePairer()
    pairer.add_status(_line(15, (1, 0)))
    pairer.add_frame((1, 0), 'a')
    assert pairer.add_frame((2, 0), 'b') == []
    # a newer frame, or a newer frame's line, releases it
    assert pairer.add_frame((3, 0), 'c') == [('b', None)]
    assert pairer.add_status(_line(7, (4, 0))) == [('c', None)]
    assert pairer.add_frame((4, 0), 'd') == [('d', _line(7, (4, 0)))]
    assert pairer.add_frame((5, 0), 'e') == []
    assert pairer.flush() == [('e', None)] and pairer.flush() == []


def test_pairer_without_stamped_lines_pairs_the_next_line() -> None:
    """Lines without a stamp (another tracker, an older ik_node): a frame pairs with the line
    that follows it; let go by the next frame, it has the newest line's evidence."""
    pairer: EvidencePairer[str] = EvidencePairer()
    assert pairer.add_frame((1, 0), 'a') == []
    assert pairer.add_status(FrameEvidence(6.0, 2.0)) == [('a', FrameEvidence(6.0, 2.0))]
    assert pairer.add_frame((2, 0), 'b') == []
    assert pairer.add_frame((3, 0), 'c') == [('b', FrameEvidence(6.0, 2.0))]
    assert pairer.add_status(None) == [('c', None)]          # e.g. 'no hand: lost'
    assert pairer.add_frame((4, 0), 'd') == [] and pairer.flush() == [('d', None)]
