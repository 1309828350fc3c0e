"""pipeline_run's diagnostics of a run that lost frames: the bag player's output is kept, and a
run names the camera frames that got no observation."""
from __future__ import annotations

import subprocess
import threading
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from colorglove_ros.ros.latency_probe import ProbeRecord
from colorglove_ros.ros.pipeline_run import (
    PipelineRun,
    _collect,
    _cpu_since,
    bag_feed,
    summarize,
)


def test_feed_keeps_what_the_player_printed(tmp_path: Path) -> None:
    feed = bag_feed(tmp_path / 'missing', paced=True)
    with pytest.raises(subprocess.CalledProcessError):
        feed()
    assert 'no bag at' in feed.output
    # the player's CPU time, for the benchmark's per-process figures: a started Python process
    assert 0.0 < feed.cpu_s < 60.0


def test_cpu_per_offered_frame_of_each_process() -> None:
    empty = np.zeros(0, np.int64)
    run = PipelineRun(frames_expected=200, frames=200, segmented=0, tracked=0, duration_s=1.0,
                      latencies_s=[], estimated=np.zeros((0, 26)), truth=np.zeros((0, 26)),
                      segmentation_ms=[], lookup_ms=[], probe=ProbeRecord(empty, empty),
                      cpu_s={'segmentation': 1.0, 'monitor': 0.5})
    figures = summarize(run, None)
    assert figures['cpu_ms_per_frame_segmentation'] == pytest.approx(5.0)
    assert figures['cpu_ms_per_frame_monitor'] == pytest.approx(2.5)


def test_cpu_used_between_two_readings() -> None:
    assert _cpu_since({'a': 1.0, 'b': 2.0, 'gone': 1.0}, {'a': 1.5, 'b': 2.0, 'new': 9.0}) \
        == {'a': 0.5, 'b': 0.0}


def test_run_names_the_frames_without_an_observation() -> None:
    frames = {(1, 0): 0.0, (1, 5): 0.1, (2, 0): 0.2}
    monitor = SimpleNamespace(
        lock=threading.Lock(), joints={}, wrists={}, truth_joints={}, truth_wrists={},
        frame_times=frames, observation_times={(1, 0): 0.0, (2, 0): 0.2},
        segmentation_ms={}, lookup_ms={}, overlays=[], statuses=[], camera_refusals=[])
    empty = np.zeros(0, np.int64)
    run = _collect(monitor, 1.0, 3, ProbeRecord(empty, empty))
    assert (run.frames, run.segmented, run.unsegmented) == (3, 2, [(1, 5)])
    assert '2 of 3 camera frames segmented; without an observation: [(1, 5)]' \
        in run.missed_frames()


def test_a_paced_feed_passes_its_pace_timeout_to_the_player(tmp_path: Path) -> None:
    command = bag_feed(tmp_path, paced=True, pace_timeout_s=7.5).command
    assert command[command.index('--pace-timeout') + 1] == '7.5'
    assert '--pace-timeout' not in bag_feed(tmp_path, paced=True).command
    assert '--pace-timeout' not in bag_feed(tmp_path, pace_timeout_s=7.5).command


@pytest.mark.dds
@pytest.mark.usefixtures('isolated_ros_domain')
def test_a_probe_that_dies_during_the_run_leaves_a_run_that_says_so(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """The latency probe killed (and reaped) while the feed plays: the run ends normally with
    no latency, NaN probe CPU and the probe's fate in ``probe_error`` (it raised OSError from
    the CPU reading before)."""
    from colorglove_ros.ros import pipeline_run

    probes: list = []

    class Probe(pipeline_run.LatencyProbe):
        def start(self, ready_timeout_s: float = 30.0) -> None:
            super().start(ready_timeout_s)
            probes.append(self)

    class NoNodes:           # the launcher's place: no tracker nodes
        def __init__(self, specs: list) -> None:
            pass

        def start(self) -> None:
            pass

        def stop(self) -> None:
            pass

        def cpu_seconds(self) -> dict[str, float]:
            return {}

    def feed() -> None:
        probes[0].process.kill()
        probes[0].process.wait()

    monkeypatch.setattr(pipeline_run, 'LatencyProbe', Probe)
    monkeypatch.setattr(pipeline_run, 'Launcher', NoNodes)
    monkeypatch.setattr(pipeline_run, '_wait_for_graph', lambda *args: None)
    run = pipeline_run.run_pipeline({}, 0, feed=feed, timeout_s=10.0)
    assert 'was killed by signal 9 before the run ended' in run.probe_error
    assert np.isnan(run.cpu_s['probe'])
    assert run.latencies_s == [] and len(run.probe.stamp_ns) == 0
    assert np.isnan(summarize(run, None)['latency_p95_ms'])
