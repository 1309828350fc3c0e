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
from colorglove_ros.ros.pipeline_run import _collect, bag_feed


def test_feed_keeps_what_the_player_printed(tmp_path: Path) -> None:
    feed = bag_feed(tmp_path / 'missing', paced=True)
    with pytest.raises(subprocess.CalledProcessError):
        feed()
    assert 'no bag at' in feed.output


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
