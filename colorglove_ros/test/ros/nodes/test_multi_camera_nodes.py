"""Two calibrated cameras through the node processes: a two-view synthetic bag
(``colorglove_make_bag --calibration config/calibration_stereo.yaml``) replayed into two
segmentation_nodes (one per camera), one lookup_node and an ik_node given the second camera's
observations in ``extra_observation_topics``. The same bag through the one-camera graph is
the baseline: with the second view the IK uses constraints from both cameras and the wrist
depth error against ground truth drops."""
from __future__ import annotations

import copy
import re
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from colorglove_msgs.msg import HandObservation, HandPoseCandidates
from geometry_msgs.msg import PoseStamped
from message_samples import blob_tuples, set_blobs
from node_fixtures import (
    SMALL_DATABASE_GATES,
    NodeAssets,
    assert_run_tracked,
    candidates_msg,
    header,
    ik_node,
    node_lookup,
    observation_msg,
    paced_bag_feed,
    running,
)
from repo_paths import CONFIG_DIR
from sensor_msgs.msg import CameraInfo
from std_msgs.msg import String

from colorglove_ros.core.camera import PinholeCamera, load_calibration
from colorglove_ros.core.hand.glove import default_hand
from colorglove_ros.core.segmentation.segmenter import load_segmenter
from colorglove_ros.core.synthetic import frames as synth
from colorglove_ros.core.synthetic.conditions import sample_conditions
from colorglove_ros.ros.conversions import camera_to_camera_info_msg
from colorglove_ros.ros.launcher import NodeSpec
from colorglove_ros.ros.nodes.ik_node import IKNode
from colorglove_ros.ros.pipeline_run import PipelineRun, run_pipeline, summarize
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


def _upscaled_camera(camera: PinholeCamera, k: int = 2) -> PinholeCamera:
    """``camera`` for its images resized k times (pixel centres: x' = k x + (k - 1) / 2)."""
    shift = 0.5 * (k - 1)
    return replace(camera, width=camera.width * k, height=camera.height * k,
                   fx=camera.fx * k, fy=camera.fy * k, cx=camera.cx * k + shift,
                   cy=camera.cy * k + shift)


def _upscaled_observation(msg: HandObservation, k: int = 2) -> HandObservation:
    """What the segmentation reports of the k times resized image."""
    shift = 0.5 * (k - 1)
    big = copy.deepcopy(msg)
    big.image_width, big.image_height = msg.image_width * k, msg.image_height * k
    big.crop_scale = msg.crop_scale * k
    big.crop_offset_x, big.crop_offset_y = (msg.crop_offset_x * k + shift,
                                            msg.crop_offset_y * k + shift)
    set_blobs(big, [(color, x * k + shift, y * k + shift, count * k * k)
                    for color, x, y, count in blob_tuples(msg)])
    big.glove_pixel_count = msg.glove_pixel_count * k * k
    return big


def _track_stereo_frame(database: Path, candidates: HandPoseCandidates,
                        second: HandObservation, second_info: PinholeCamera | None
                        ) -> tuple[str, float, IKNode]:
    """One stereo frame through ik_node: with ``second_info`` every camera's intrinsics come
    from its CameraInfo (camera 0's: the calibration's, camera2's: ``second_info`` on
    /camera2/camera/camera_info), else from the calibration. Returns the status line, the
    wrist depth and the node."""
    use_info = second_info is not None
    with running(ik_node(database, calibration_file=str(STEREO), publish_overlay=False,
                         use_camera_info=use_info, extra_observation_topics=[SECOND_OBSERVATION],
                         extra_observation_wait_s=0.5)) as h:
        status = h.collect(String, 'hand/tracking_status')
        wrist = h.collect(PoseStamped, 'hand/wrist_pose')
        if use_info:
            for topic, camera in (('camera/camera_info', RIG[0]),
                                  (f'/{SECOND.name}/camera/camera_info', second_info)):
                h.publisher(CameraInfo, topic).publish(
                    camera_to_camera_info_msg(camera, header(50, 0, camera.frame_id)))
            h.settle(0.3)
        second_pub = h.publisher(HandObservation, SECOND_OBSERVATION)
        candidates_pub = h.publisher(HandPoseCandidates, 'hand/pose_candidates')
        second_pub.publish(second)
        h.settle(0.2)
        line = h.exchange(candidates_pub, candidates, status, timeout=10.0)
        h.settle(0.2)
        return line.data, wrist[0].pose.position.z if wrist else float('nan'), h.nodes[0]


def test_extra_camera_intrinsics_come_from_its_camera_info(
        stereo_messages: tuple[HandPoseCandidates, HandObservation],
        small_database_path: Path) -> None:
    """With use_camera_info, camera2's intrinsics come from /camera2/camera/camera_info (its
    extrinsics from the calibration): its view at twice the calibrated resolution is used and
    gives the pose its calibrated view gives; a view that does not match its CameraInfo is
    ignored and counted."""
    candidates, second = stereo_messages
    calibrated, z_calibrated, _ = _track_stereo_frame(small_database_path, candidates, second,
                                                      None)
    big = _upscaled_camera(SECOND)
    from_info, z_info, node = _track_stereo_frame(small_database_path, candidates,
                                                  _upscaled_observation(second), big)
    assert calibrated.startswith('tracking:') and from_info.startswith('tracking:'), \
        (calibrated, from_info)
    assert _second_camera_constraints(from_info) == _second_camera_constraints(calibrated) > 0
    assert abs(z_info - z_calibrated) < 1e-3, (z_calibrated, z_info)
    used = node.tracker.cameras[1]
    assert (used.width, used.fx, used.name) == (1280, big.fx, SECOND.name)
    np.testing.assert_allclose(used.translation, SECOND.translation)
    np.testing.assert_allclose(used.rotation, SECOND.rotation)
    # the calibrated 640x480 view no longer matches camera2's CameraInfo
    ignored, _, node = _track_stereo_frame(small_database_path, candidates, second, big)
    assert _second_camera_constraints(ignored) == 0, ignored
    assert node.extra_frame_cameras[0].refused == {'size': 1}


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
               **SMALL_DATABASE_GATES},
    }
    extra_nodes, extra_inputs = [], {}
    if two_cameras:
        parameters['segmentation2'] = segmentation
        extra_nodes = [NodeSpec('segmentation_node', 'segmentation2', remappings={
            'camera/image_raw': SECOND_IMAGE, 'hand/observation': SECOND_OBSERVATION,
            'camera/camera_info': f'/{SECOND.name}/camera/camera_info',
            'hand/segmentation_debug': f'/{SECOND.name}/hand/segmentation_debug'})]
        extra_inputs = {SECOND_IMAGE: 'segmentation2'}
    return run_pipeline(parameters, FRAMES, feed=paced_bag_feed(bag), timeout_s=300.0,
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
        assert_run_tracked(run, figures, FRAMES)
    assert all('camera2' not in line for line in mono.statuses)
    counts = _constraints_per_camera(stereo.statuses)
    assert len(counts) >= 0.9 * FRAMES
    # the second camera's observations reach the IK for (nearly) every frame
    assert np.mean(counts[:, 1] > 0) >= 0.9, counts
    assert np.mean(counts[:, 0] > 0) >= 0.9, counts
    assert two['wrist_depth_mm'] < one['wrist_depth_mm'], (one, two)
    assert two['wrist_depth_mm'] < DEPTH_TARGET_2_CAMERAS_MM, two
