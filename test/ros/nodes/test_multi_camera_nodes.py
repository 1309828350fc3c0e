"""Two calibrated cameras through the node processes: a two-view synthetic bag
(``colorglove_make_bag --calibration config/calibration_stereo.yaml``) replayed into two
segmentation_nodes (one per camera), one lookup_node and an ik_node given the second camera's
observations in ``extra_observation_topics``. The same bag through the one-camera graph is
the baseline: with the second view the IK uses constraints from both cameras and the wrist
depth error against ground truth drops."""
from __future__ import annotations

import copy
import re
from pathlib import Path

import numpy as np
import pytest
from colorglove_msgs.msg import HandObservation, HandPoseCandidates
from node_fixtures import (
    SMALL_DATABASE_EXPLAINED_SHARE,
    NodeAssets,
    candidates_msg,
    header,
    ik_node,
    node_lookup,
    observation_msg,
    running,
)
from repo_paths import CONFIG_DIR
from std_msgs.msg import String

from colorglove_ros.core.camera import load_calibration
from colorglove_ros.core.hand.glove import default_hand
from colorglove_ros.core.segmentation.segmenter import load_segmenter
from colorglove_ros.core.synthetic import frames as synth
from colorglove_ros.core.synthetic.conditions import sample_conditions
from colorglove_ros.ros.launcher import NodeSpec
from colorglove_ros.ros.pipeline_run import PipelineRun, bag_feed, run_pipeline, summarize
from colorglove_ros.tools import make_bag

pytestmark = [pytest.mark.dds, pytest.mark.usefixtures('isolated_ros_domain')]

FRAMES = 30
SEED = 5                    # a held-out sequence seed
MONO = CONFIG_DIR / 'calibration.yaml'
STEREO = CONFIG_DIR / 'calibration_stereo.yaml'
RIG = load_calibration(STEREO).cameras
SECOND = RIG[1]
SECOND_IMAGE = f'/{SECOND.name}/camera/image_raw'
SECOND_OBSERVATION = f'/{SECOND.name}/hand/observation'
DEPTH_TARGET_2_CAMERAS_MM = 10.0


@pytest.fixture(scope='module')
def stereo_bag(tmp_path_factory: pytest.TempPathFactory) -> Path:
    bag = tmp_path_factory.mktemp('stereo') / 'bag'
    assert make_bag.main(['--seed', str(SEED), '--frames', str(FRAMES), '--output', str(bag),
                          '--calibration', str(STEREO)]) == 0
    return bag


@pytest.fixture(scope='module')
def stereo_messages(node_assets: NodeAssets) -> tuple[HandPoseCandidates, HandObservation]:
    """One instant seen by both cameras: the primary's candidates and the second camera's
    observation, as lookup_node and the second segmentation_node would send them."""
    rng = np.random.default_rng(SEED)
    q = synth.sample_pose(rng, RIG[0], out_of_frame_prob=0.0)
    views = synth.render_frames_multi(q, RIG, rng, sample_conditions(rng, 'test'))
    segmenter = load_segmenter(str(node_assets.color_config))
    primary = observation_msg(segmenter, views[0].image_rgb, header(300, 0, RIG[0].frame_id))
    return (candidates_msg(node_lookup(node_assets), primary, RIG[0]),
            observation_msg(segmenter, views[1].image_rgb, header(300, 0, SECOND.frame_id)))


def _second_camera_constraints(status: str) -> int:
    match = re.search(rf'{SECOND.name} (\d+)\)', status)
    assert match, status
    return int(match.group(1))


def test_ik_node_waits_for_the_second_view_of_a_frame(
        stereo_messages: tuple[HandPoseCandidates, HandObservation],
        small_database_path: Path) -> None:
    """Candidates that arrive before the second camera's observation of the same stamp wait
    for it; an observation whose frame_id is not the calibrated one is ignored."""
    candidates, second = stereo_messages
    wrong_frame = copy.deepcopy(second)
    wrong_frame.header = header(301, 0, RIG[0].frame_id)
    late = copy.deepcopy(candidates)
    late.header = header(301, 0, RIG[0].frame_id)
    with running(ik_node(small_database_path, calibration_file=str(STEREO), publish_overlay=False,
                         extra_observation_topics=[SECOND_OBSERVATION],
                         extra_observation_wait_s=0.5)) as h:
        status = h.collect(String, 'hand/tracking_status')
        candidates_pub = h.publisher(HandPoseCandidates, 'hand/pose_candidates')
        second_pub = h.publisher(HandObservation, SECOND_OBSERVATION)
        candidates_pub.publish(candidates)
        h.settle(0.1)
        assert not status, 'tracked before the second view arrived or the wait ran out'
        second_pub.publish(second)
        assert h.spin_until(lambda: status, 5.0)
        second_pub.publish(wrong_frame)
        h.settle(0.1)
        h.exchange(candidates_pub, late, status, timeout=5.0)
    assert status[0].data.startswith('tracking:'), status[0].data
    assert _second_camera_constraints(status[0].data) > 0
    assert _second_camera_constraints(status[1].data) == 0


def _run(assets: NodeAssets, bag: Path, two_cameras: bool) -> PipelineRun:
    segmentation = {'color_calibration_file': str(assets.color_config)}
    parameters = {
        'segmentation': segmentation,
        'lookup': {'database_path': str(assets.database)},
        # a loaded 2-core machine runs six processes here: give the second view time to arrive
        'ik': {'publish_overlay': False, 'database_path': str(assets.database),
               'calibration_file': str(STEREO if two_cameras else MONO),
               **({'extra_observation_topics': [SECOND_OBSERVATION]} if two_cameras else {}),
               'extra_observation_wait_s': 0.3,
               'min_explained_blob_share': SMALL_DATABASE_EXPLAINED_SHARE},
    }
    extra_nodes, extra_inputs = [], {}
    if two_cameras:
        parameters['segmentation2'] = segmentation
        extra_nodes = [NodeSpec('segmentation_node', 'segmentation2', remappings={
            'camera/image_raw': SECOND_IMAGE, 'hand/observation': SECOND_OBSERVATION,
            'camera/camera_info': f'/{SECOND.name}/camera/camera_info',
            'hand/segmentation_debug': f'/{SECOND.name}/hand/segmentation_debug'})]
        extra_inputs = {SECOND_IMAGE: 'segmentation2'}
    return run_pipeline(parameters, FRAMES, feed=bag_feed(bag, paced=True), timeout_s=300.0,
                        extra_nodes=extra_nodes, extra_inputs=extra_inputs)


def _constraints_per_camera(statuses: list[str]) -> np.ndarray:
    """(tracked frames, 2) constraint counts from ik_node's status lines."""
    pattern = re.compile(rf'\(camera (\d+), {SECOND.name} (\d+)\)')
    counts = [pattern.search(line) for line in statuses if line.startswith('tracking:')]
    assert all(counts), statuses[:3]
    return np.array([[int(m.group(1)), int(m.group(2))] for m in counts]).reshape(-1, 2)


def test_second_camera_lowers_depth_error(node_assets: NodeAssets, stereo_bag: Path) -> None:
    model = default_hand()[0]
    mono = _run(node_assets, stereo_bag, two_cameras=False)
    stereo = _run(node_assets, stereo_bag, two_cameras=True)
    one, two = summarize(mono, model), summarize(stereo, model)
    print({'1 camera': one, '2 cameras': two})
    for run, figures in ((mono, one), (stereo, two)):
        assert not run.timed_out
        assert run.segmented == FRAMES, 'segmentation_node missed camera frames'
        assert figures['tracked_fraction'] >= 0.9, figures
        assert figures['frames_with_truth'] >= 0.9 * FRAMES
    assert all('camera2' not in line for line in mono.statuses)
    counts = _constraints_per_camera(stereo.statuses)
    assert len(counts) >= 0.9 * FRAMES
    # the second camera's observations reach the IK for (nearly) every frame
    assert np.mean(counts[:, 1] > 0) >= 0.9, counts
    assert np.mean(counts[:, 0] > 0) >= 0.9, counts
    assert two['wrist_depth_mm'] < one['wrist_depth_mm'], (one, two)
    assert two['wrist_depth_mm'] < DEPTH_TARGET_2_CAMERAS_MM, two
