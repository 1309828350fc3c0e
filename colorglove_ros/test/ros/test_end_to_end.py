"""End to end: a synthetic bag replayed through segmentation_node, lookup_node and ik_node as
separate processes over DDS; at least 95% of the frames give a JointState and the error against
the bag's ground truth is within the IK issue's one-camera targets, on the figures
colorglove_eval_ik judges (there on seeds 0-1 with the 100,000-entry database, here on one
held-out bag with a 20,000-entry one): fingertip error relative to the wrist position < 15 mm
and wrist depth error < 25 mm (on average). The absolute fingertip error, which includes the
depth error, is held to a regression bound (FINGERTIP_BOUND_MM).

The assets are real and built here: the colour calibration from 12 rendered training frames,
a pose database of E2E_DATABASE_ENTRIES entries (default 20,000; a few minutes on 2 cores) with
the settings of config/database.yaml, and a 60-frame bag of a held-out sequence."""
from __future__ import annotations

import dataclasses
import os
from pathlib import Path

import pytest
from node_fixtures import paced_bag_feed, synthetic_color_config

from colorglove_ros.core.hand.glove import default_hand
from colorglove_ros.core.lookup.database import save_database
from colorglove_ros.core.lookup.database_build import build_database
from colorglove_ros.ros.pipeline_run import run_pipeline, summarize
from colorglove_ros.tools import build_database as build_database_tool
from colorglove_ros.tools import make_bag

pytestmark = pytest.mark.dds

E2E_FRAMES = 60
E2E_SEED = 5          # a held-out sequence seed (the database and calibration use others)
DATABASE_ENTRIES = int(os.environ.get('E2E_DATABASE_ENTRIES', '20000'))
FINGERTIP_BOUND_MM = 30.0              # regression bound; measured 23.7 mm with 20,000 entries
FINGERTIP_REL_WRIST_TARGET_MM = 15.0   # the IK target; measured 13.7 mm
DEPTH_TARGET_MM = 25.0                 # the IK target; measured 17.1 mm


@pytest.fixture(scope='module')
def assets(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    folder = tmp_path_factory.mktemp('e2e')
    _, color_config = synthetic_color_config(folder, 12)
    config, _, _ = build_database_tool.load_build_config()
    config = dataclasses.replace(config, entries=DATABASE_ENTRIES,
                                 orientations_per_config=min(config.orientations_per_config,
                                                             max(DATABASE_ENTRIES // 200, 10)))
    database = Path(save_database(build_database(config), folder / 'database'))
    bag = folder / 'bag'
    assert make_bag.main(['--seed', str(E2E_SEED), '--frames', str(E2E_FRAMES),
                          '--output', str(bag), '--split', 'test']) == 0
    return {'color_config': color_config, 'database': database, 'bag': bag}


def test_bag_through_the_pipeline(assets: dict[str, Path], isolated_ros_domain: dict) -> None:
    parameters = {
        'segmentation': {'color_calibration_file': str(assets['color_config'])},
        'lookup': {'database_path': str(assets['database'])},
        'ik': {'publish_overlay': False, 'database_path': str(assets['database'])},
    }
    run = run_pipeline(parameters, expected_frames=E2E_FRAMES,
                       feed=paced_bag_feed(assets['bag']), timeout_s=300.0)
    figures = summarize(run, default_hand()[0])
    print(figures)
    assert not run.timed_out
    assert run.segmented == E2E_FRAMES, \
        f'segmentation_node missed camera frames: {run.missed_frames()}'
    assert figures['tracked_fraction'] >= 0.95, figures
    assert figures['frames_with_truth'] >= 0.95 * E2E_FRAMES
    assert figures['fingertip_mm'] < FINGERTIP_BOUND_MM, figures
    assert figures['fingertip_rel_wrist_mm'] < FINGERTIP_REL_WRIST_TARGET_MM, figures
    assert figures['wrist_depth_mm'] < DEPTH_TARGET_MM, figures
    assert figures['jitter_mm'] < 10.0, figures
    assert 0 < figures['latency_p50_ms'] < 2000.0
