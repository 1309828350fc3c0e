"""colorglove_eval_edges end to end on a short sequence: table, --json, silhouettes or not."""
from __future__ import annotations

import json
import math

import numpy as np
import pytest

from colorglove_ros.core.tracking.edge_fit import EdgeTrackerConfig
from colorglove_ros.tools.eval_edges import main


@pytest.mark.slow
def test_short_run_with_and_without_the_empty_scene(tmp_path) -> None:
    rows = {}
    for background in ('empty', 'none'):
        out = tmp_path / f'{background}.json'
        assert main(['--seeds', '1', '--frames', '40', '--speeds', '1', '--cameras', '2',
                     '--background', background, '--json', str(out)]) == 0
        data = json.loads(out.read_text())
        assert data['settings']['background'] == background
        (row,) = data['rows']
        assert row['frames'] == 40 and row['published'] > 10     # started from the hold
        assert row['finger_withheld'] + row['published'] <= 40
        rows[background] = row
    # the silhouettes take part in the fit: the estimates differ
    assert rows['empty']['fingertip_rel_wrist_mm'] != rows['none']['fingertip_rel_wrist_mm']


def test_tracker_options_reach_the_settings(tmp_path) -> None:
    out = tmp_path / 'options.json'
    assert main(['--seeds', '1', '--frames', '2', '--speeds', '1', '--cameras', '1',
                 '--finger-refit', '--silhouette-palm', '--max-finger-off-silhouette', '0.15',
                 '--json', str(out)]) == 0
    report = json.loads(out.read_text())
    settings = report['settings']
    assert settings['finger_refit'] and settings['silhouette_palm']
    assert settings['max_finger_off_silhouette'] == 0.15
    # the machine's speed on the fixed workloads before and after the timed tracking
    assert [row['when'] for row in report['machine_speed']] == ['before', 'after']
    assert all(row['python_loop_ms'] > 0 and row['numpy_sort_ms'] > 0
               for row in report['machine_speed'])


@pytest.mark.parametrize('flags, on', [([], True), (['--finger-refit', '--silhouette-palm'], True),
                                       (['--no-finger-refit', '--no-silhouette-palm'], False)])
def test_the_refits_and_the_palm_pull_are_on_unless_turned_off(tmp_path, flags: list[str],
                                                                on: bool) -> None:
    out = tmp_path / 'options.json'
    assert main(['--seeds', '1', '--frames', '2', '--speeds', '1', '--cameras', '1', *flags,
                 '--json', str(out)]) == 0
    settings = json.loads(out.read_text())['settings']
    assert settings['finger_refit'] is on and settings['silhouette_palm'] is on


def _recorded_configs(monkeypatch) -> list[EdgeTrackerConfig]:
    """The configs ``colorglove_eval_edges`` makes its trackers with, from now on."""
    from colorglove_ros.tools import eval_edges

    configs: list[EdgeTrackerConfig] = []
    tracker = eval_edges.EdgeTracker

    def recording(model, cameras, config=None, backgrounds=None):
        configs.append(config)
        return tracker(model, cameras, config, backgrounds)

    monkeypatch.setattr(eval_edges, 'EdgeTracker', recording)
    return configs


@pytest.mark.parametrize('flags, rounds, fault, camera', [
    ([], EdgeTrackerConfig.measurement_rounds, EdgeTrackerConfig.fault_round,
     EdgeTrackerConfig.min_camera_found_fraction),
    (['--measurement-rounds', '1', '--no-fault-round', '--min-camera-found-fraction', '0.25'],
     1, False, 0.25),
    (['--measurement-rounds', '3', '--fault-round', '--min-camera-found-fraction', '0.1'],
     3, True, 0.1)])
def test_the_measurement_rounds_and_fault_round_reach_the_tracker(
        tmp_path, monkeypatch, flags: list[str], rounds: int, fault: bool,
        camera: float) -> None:
    configs = _recorded_configs(monkeypatch)
    out = tmp_path / 'rounds.json'
    assert main(['--seeds', '1', '--frames', '2', '--speeds', '1', '--cameras', '1', *flags,
                 '--json', str(out)]) == 0
    report = json.loads(out.read_text())
    settings = report['settings']
    assert settings['measurement_rounds'] == rounds and settings['fault_round'] is fault
    assert settings['min_camera_found_fraction'] == camera
    assert [(c.measurement_rounds, c.fault_round, c.min_camera_found_fraction)
            for c in configs] == [(rounds, fault, camera)]
    row = report['rows'][0]
    assert isinstance(row['fault_rounds'], int) and row['fault_rounds'] >= 0
    assert 'thread_cpu_ms_mean' in row


def test_the_thread_cpu_is_averaged_over_the_published_frames() -> None:
    from colorglove_ros.core.hand.model import HandModel
    from colorglove_ros.tools.eval_edges import sequence_figures

    truth = np.zeros((3, 26))
    fig = sequence_figures(HandModel(), truth, [truth[0], None, truth[2]], [5.0, 7.0], [False] * 3,
                           [9.0, 11.0], [4.0, 6.0])
    assert fig['cpu_ms_mean'] == 10.0 and fig['thread_cpu_ms_mean'] == 5.0
    empty = sequence_figures(HandModel(), truth, [None] * 3, [], [False] * 3)
    assert math.isnan(empty['thread_cpu_ms_mean'])


_DEFAULTS = EdgeTrackerConfig()
_REFIT_NAMES = ('finger_refit_dofs', 'finger_refit_abduction', 'finger_refit_spread_deg',
                'round_min_move_px')


@pytest.mark.parametrize('flags, expected', [
    ([], tuple(getattr(_DEFAULTS, n) for n in _REFIT_NAMES)),
    (['--finger-refit-dofs', 'digit', '--finger-refit-abduction', 'spread',
      '--finger-refit-spread-deg', '5', '--round-min-move-px', '4'], ('digit', 'spread', 5.0, 4.0)),
    (['--finger-refit-dofs', 'flexion', '--finger-refit-abduction', 'kept',
      '--round-min-move-px', '0'],
     ('flexion', 'kept', _DEFAULTS.finger_refit_spread_deg, 0.0))])
def test_the_finger_refit_settings_and_the_round_gate_reach_the_tracker(
        tmp_path, monkeypatch, flags: list[str], expected: tuple) -> None:
    configs = _recorded_configs(monkeypatch)
    out = tmp_path / 'refit.json'
    assert main(['--seeds', '1', '--frames', '2', '--speeds', '1', '--cameras', '1', *flags,
                 '--json', str(out)]) == 0
    settings = json.loads(out.read_text())['settings']
    assert tuple(settings[n] for n in _REFIT_NAMES) == expected
    assert [tuple(getattr(c, n) for n in _REFIT_NAMES) for c in configs] == [expected]


def test_an_unknown_finger_refit_mode_is_refused() -> None:
    with pytest.raises(SystemExit):
        main(['--seeds', '1', '--frames', '2', '--finger-refit-dofs', 'wrist'])


@pytest.mark.parametrize('flags, threads', [([], 1), (['--opencv-threads', '2'], 2)])
def test_the_tool_runs_opencv_as_the_node_does(tmp_path, flags: list[str], threads: int) -> None:
    """OpenCV's threads default to the nodes' ``opencv_threads`` (``OPENCV_THREADS``), so the
    process CPU the tool reports is what edge_tracker_node would take; the JSON says which."""
    import cv2

    from colorglove_ros.core.opencv_threads import OPENCV_THREADS

    assert OPENCV_THREADS == 1
    before = cv2.getNumThreads()
    try:
        cv2.setNumThreads(3)
        out = tmp_path / 'threads.json'
        assert main(['--seeds', '1', '--frames', '2', '--speeds', '1', '--cameras', '1', *flags,
                     '--json', str(out)]) == 0
        assert cv2.getNumThreads() == threads
        assert json.loads(out.read_text())['settings']['opencv_threads'] == threads
    finally:
        cv2.setNumThreads(before)


@pytest.mark.parametrize('value', ['65', '-2', 'two'])
def test_an_opencv_thread_count_outside_the_nodes_range_is_refused(value: str) -> None:
    with pytest.raises(SystemExit):
        main(['--seeds', '1', '--frames', '2', '--opencv-threads', value])
