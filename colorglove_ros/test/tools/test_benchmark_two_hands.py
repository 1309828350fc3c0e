"""colorglove_benchmark_two_hands: each hand's rows from a two-topic probe record, and a short
run of two_hands_node over DDS fed a two-hand bag."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from colorglove_ros.ros.latency_probe import ProbeRecord
from colorglove_ros.tools import benchmark_two_hands


def test_rows_count_each_hand_on_its_own_topic() -> None:
    stamps = np.arange(5, dtype=np.int64) * 10**9
    record = ProbeRecord(stamps, stamps + 20_000_000, np.array([0, 1, 0, 0, 1]))
    rows = {row['hand']: row for row in benchmark_two_hands.hand_rows(record, ('right', 'left'),
                                                                        10, 30.0)}
    assert (rows['right']['joint_states'], rows['left']['joint_states']) == (3, 2)
    assert rows['right']['joint_states_per_s'] == pytest.approx(9.0)
    assert rows['left']['answered_fraction'] == pytest.approx(0.2)
    assert rows['right']['latency_p95_ms'] == pytest.approx(20.0)


def test_rows_judge_the_rate_on_frames_with_both_hands_visible() -> None:
    """A hand answered on every frame where both are visible gets the offered rate there,
    however many frames it could not be seen on; a stamp the player did not send is an
    error, not a frame."""
    stamps = np.arange(6, dtype=np.int64) * 10**9
    visible_at = {int(s): k < 4 for k, s in enumerate(stamps)}     # frames 0-3 visible
    record = ProbeRecord(stamps[:4], stamps[:4] + 10_000_000, np.array([0, 0, 0, 0]))
    right, left = benchmark_two_hands.hand_rows(record, ('right', 'left'), 6, 30.0, visible_at)
    assert right['frames_both_visible'] == 4
    assert right['answered_when_visible'] == pytest.approx(1.0)
    assert right['joint_states_per_s_when_visible'] == pytest.approx(30.0)
    assert right['joint_states_per_s'] == pytest.approx(20.0)        # 4 of 6 frames
    assert left['joint_states_per_s_when_visible'] == 0.0
    stray = ProbeRecord(np.array([7]), np.array([8]), np.array([1]))
    with pytest.raises(ValueError, match='left: 1 JointStates with a stamp the player'):
        benchmark_two_hands.hand_rows(stray, ('right', 'left'), 6, 30.0, visible_at)



def test_rows_count_the_start_up_misses_apart() -> None:
    """Frames missed during the node's start-up (the first startup_frames sent, in the order
    sent) are counted apart and left out of the share judged; the share over all visible
    frames stays beside it."""
    stamps = np.arange(8, dtype=np.int64) * 10**9
    visible_at = {int(s): k != 5 for k, s in enumerate(stamps)}     # frame 5 hidden
    answered = stamps[[2, 3, 4, 6]]                                  # 0, 1 and 7 missed
    record = ProbeRecord(answered, answered + 10_000_000, np.zeros(4, np.int64))
    right, _ = benchmark_two_hands.hand_rows(record, ('right', 'left'), 8, 30.0, visible_at,
                                             startup_frames=2)
    assert right['frames_both_visible'] == 7
    assert right['answered_when_visible'] == pytest.approx(4 / 7)
    assert right['startup_frames_missed'] == 2
    assert right['answered_when_visible_after_startup'] == pytest.approx(4 / 5)
    assert right['joint_states_per_s_when_visible_after_startup'] == pytest.approx(24.0)
    whole, _ = benchmark_two_hands.hand_rows(record, ('right', 'left'), 8, 30.0, visible_at)
    assert whole['startup_frames_missed'] == 0
    assert whole['answered_when_visible_after_startup'] == pytest.approx(4 / 7)

def test_node_gets_only_the_parameters_given() -> None:
    """The node's defaults stand unless the command names a setting (threads, OpenCV's
    threads: compared on an idle machine with --threads / --opencv-threads)."""
    from argparse import Namespace

    bare = Namespace(color_config=None, threads=None, opencv_threads=None)
    assert benchmark_two_hands.node_parameters(bare, Path('/db')) == {'database_path': '/db'}
    given = Namespace(color_config=Path('c.yaml'), threads=1, opencv_threads=-1)
    assert benchmark_two_hands.node_parameters(given, Path('/db')) == {
        'database_path': '/db', 'color_calibration_file': 'c.yaml', 'threads': 1,
        'opencv_threads': -1}


def test_visibility_file_of_another_sequence_is_refused(tmp_path: Path) -> None:
    from colorglove_ros.ros.bags import BagError

    bag = tmp_path / 'bag'
    benchmark_two_hands._write_visibility(bag, 5, [True, False])
    with pytest.raises(BagError, match='not of sequence 6 x 2 frames'):
        benchmark_two_hands.frame_visibility(bag, 6, 2)
    benchmark_two_hands.visibility_path(bag).write_text('{"format": 1}')
    with pytest.raises(BagError, match='not a visibility file'):
        benchmark_two_hands.frame_visibility(bag, 6, 2)


@pytest.mark.dds
@pytest.mark.slow
def test_short_run_over_dds(node_assets, tmp_path: Path, isolated_ros_domain: dict,
                            monkeypatch: pytest.MonkeyPatch) -> None:
    """The tool writes the bag once, runs the node over DDS and reports both hands."""
    import colorglove_ros.ros.pipeline_run as pipeline_run

    monkeypatch.setattr(pipeline_run, 'prepare_assets', lambda database: Path(database))
    output = tmp_path / 'two.json'
    # 5 Hz: no frame dropped however loaded the machine is
    argv = ['--frames', '6', '--rates', '5', '30', '--bag', str(tmp_path / 'bag'),
            '--database', str(node_assets.database), '--color-config',
            str(node_assets.color_config), '--domain-id',
            isolated_ros_domain['ROS_DOMAIN_ID'], '--json', str(output)]
    assert benchmark_two_hands.main(argv) == 0
    report = json.loads(output.read_text())
    assert [(row['offered_hz'], row['hand']) for row in report['dds']] == [
        (5.0, 'right'), (5.0, 'left'), (30.0, 'right'), (30.0, 'left')]
    # the node answered the bag: at least one hand got a pose, none more than once a frame
    assert sum(row['joint_states'] for row in report['dds'][:2]) >= 1
    assert all(0 <= row['joint_states'] <= 6 for row in report['dds'])
    # every JointState mapped to its frame through the player's stamp log
    assert all(row['frames_both_visible'] == report['dds'][0]['frames_both_visible']
               for row in report['dds'])
    assert (tmp_path / 'bag_visibility.json').is_file()
    assert [row['result'] in ('PASS', 'FAIL') for row in report['targets']] == [True, True]
    assert [row['when'] for row in report['machine_speed']] == ['before', 'after']
