"""The diagnostics' counting and levels (``ros.diagnostics``), without rclpy: refusals per kind
(other counters' kinds read from them), rate and latency per period, OK / WARN / ERROR."""
from __future__ import annotations

from collections import Counter

import pytest

from colorglove_ros.ros.diagnostics import (
    ERROR,
    OK,
    WARN,
    FrameStats,
    diagnostic_array,
    refusal_kind,
    status_msg,
    upstream,
)


@pytest.mark.parametrize('reason, kind', [
    ('camera: image 1280x960 but CameraInfo says 640x480', 'camera'),
    ('bad image: empty image (0x0)', 'bad image'), ('lost', 'lost'),
    (upstream('no_glove'), 'upstream'), ('', 'unknown')])
def test_refusal_kind_is_the_text_before_the_first_colon(reason: str, kind: str) -> None:
    assert refusal_kind(reason) == kind


def test_counts_rate_latency_and_refusals_per_kind() -> None:
    camera_refused: Counter[str] = Counter()
    stats = FrameStats({'camera': camera_refused})
    stats.hand(0.010)
    stats.hand(0.030, constraints=14)
    stats.no_hand('bad image: truncated', error=True, latency_s=0.002)
    camera_refused['size'] += 1                       # counted by FrameCamera itself ...
    stats.no_hand('camera: image 1280x960 but ...', error=True)   # ... so not again here
    stats.hand(0.020, constraints=12)
    summary = stats.summary(2.0)
    assert summary.level == WARN and summary.message == '2 of 5 frames refused, 2.5 Hz'
    assert summary.values == {
        'rate (Hz)': '2.5', 'frames': '5', 'frames with hand': '3',
        'latency mean (ms)': '15.5', 'latency max (ms)': '30.0',
        'refused: bad image': '1', 'refused: camera: size': '1', 'constraints': '12'}
    # the next period starts empty; the counts since start-up stay
    stats.hand(0.001)
    later = stats.summary(1.0)
    assert later.level == OK and later.message == '1.0 Hz'
    assert later.values['frames'] == '6' and later.values['refused: bad image'] == '1'


def test_levels() -> None:
    stats = FrameStats()
    assert stats.summary(1.0).level == WARN             # nothing received
    assert stats.summary(1.0).message == 'no frames in the last 1 s'
    stats.no_hand('bad image: empty', error=True)
    stats.no_hand('bad image: empty', error=True)
    error = stats.summary(1.0)
    assert error.level == ERROR and error.message == 'frames refused: bad image: empty'
    stats.hand()
    stats.no_hand('lost')
    lost = stats.summary(1.0)
    assert lost.level == WARN and lost.message == 'hand lost: lost'
    assert stats.refused == {'bad image': 2, 'lost': 1}


def test_messages_as_diagnostic_updater_publishes_them() -> None:
    from std_msgs.msg import Header

    stats = FrameStats()
    stats.hand(0.005, constraints=3)
    status = status_msg(stats.summary(1.0), 'ik: tracking', 'camera_optical_frame')
    array = diagnostic_array(Header(frame_id=''), [status])
    assert array.status[0].level == OK and array.status[0].name == 'ik: tracking'
    assert array.status[0].hardware_id == 'camera_optical_frame'
    assert {kv.key: kv.value for kv in array.status[0].values}['constraints'] == '3'


def test_a_fault_beside_the_outputs_is_counted_and_warns() -> None:
    """Work after an output that failed (the output itself went out): counted per kind since
    start-up, the period WARN with the reason; the next period without one is OK again."""
    stats = FrameStats()
    stats.hand(0.010)
    stats.fault("background learning: RuntimeError('disk full')")
    stats.hand(0.012)
    summary = stats.summary(1.0)
    assert summary.level == WARN
    assert summary.message == ("1 fault(s) beside the outputs: background learning: "
                               "RuntimeError('disk full')")
    assert summary.values['fault: background learning'] == '1'
    assert stats.frames == 2 and stats.frames_with_hand == 2 and not stats.refusals()
    stats.hand(0.011)
    later = stats.summary(1.0)
    assert later.level == OK and later.values['fault: background learning'] == '1'
