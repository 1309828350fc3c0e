"""colorglove_single_process: segmentation, lookup and IK node classes in one process on one
executor track a bag replayed into them like the separate processes do."""
from __future__ import annotations

from pathlib import Path

import pytest
from node_fixtures import SMALL_DATABASE_GATES, NodeAssets, assert_run_tracked, paced_bag_feed

from colorglove_ros.core.hand.glove import default_hand
from colorglove_ros.ros.pipeline_run import node_specs, run_pipeline, summarize
from colorglove_ros.tools import make_bag

pytestmark = [pytest.mark.dds, pytest.mark.slow, pytest.mark.usefixtures('isolated_ros_domain')]

FRAMES = 20
SEED = 5                    # a held-out sequence seed


def test_node_specs_of_one_process(tmp_path: Path) -> None:
    params = tmp_path / 'params.yaml'
    (spec,) = node_specs(params, with_camera=False, single_process=True)
    assert spec.executable == 'colorglove_single_process' and spec.name == ''
    assert spec.arguments == ['--no-camera'] and spec.parameters == [params]
    assert [s.name for s in node_specs(params, with_camera=True)] == \
        ['camera', 'segmentation', 'lookup', 'ik']


def test_one_process_tracks_a_bag(node_assets: NodeAssets, tmp_path: Path) -> None:
    bag = tmp_path / 'bag'
    assert make_bag.main(['--seed', str(SEED), '--frames', str(FRAMES), '--output',
                          str(bag)]) == 0
    parameters = {
        'segmentation': {'color_calibration_file': str(node_assets.color_config)},
        'lookup': {'database_path': str(node_assets.database)},
        'ik': {'publish_overlay': False, 'database_path': str(node_assets.database),
               **SMALL_DATABASE_GATES},
    }
    run = run_pipeline(parameters, FRAMES, feed=paced_bag_feed(bag), timeout_s=300.0,
                       single_process=True)
    figures = summarize(run, default_hand()[0])
    assert_run_tracked(run, figures, FRAMES)
