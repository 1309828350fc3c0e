"""The four node shells in one process (real DDS on loopback), and their start-up failures as
separate processes: inputs in, outputs checked against the core modules run directly."""
from __future__ import annotations

import copy
import shutil
import subprocess
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
import pytest
from colorglove_msgs.msg import HandObservation, HandPoseCandidates
from geometry_msgs.msg import PolygonStamped, PoseStamped
from message_samples import blob_tuples, set_blobs
from node_fixtures import (
    NodeAssets,
    background_rgb,
    glove_frame,
    hand_far_out_of_frame_rgb,
    header,
    ik_node,
    lookup_node,
    node_lookup,
    params,
    running,
    segmentation_node,
    start_node_process,
)
from rclpy.qos import qos_profile_sensor_data
from repo_paths import CONFIG_DIR
from sensor_msgs.msg import CameraInfo, Image, JointState
from std_msgs.msg import String
from visualization_msgs.msg import Marker, MarkerArray

from colorglove_ros.core.camera import load_calibration
from colorglove_ros.core.conventions import TINY_SIZE
from colorglove_ros.core.hand.model import DOF_NAMES, FINGER_DOF_NAMES
from colorglove_ros.core.segmentation.segmenter import load_segmenter
from colorglove_ros.ros.conversions import (
    blobs_from_observation_msg,
    crop_from_observation_msg,
    crop_prediction_from_msg,
    tiny_labels_from_observation_msg,
)
from colorglove_ros.ros.image import array_to_image
from colorglove_ros.ros.nodes.camera_node import CameraNode
from colorglove_ros.ros.nodes.common import StartupError
from colorglove_ros.ros.nodes.segmentation_node import DEBUG_PALETTE

# every test gets a ROS domain of its own on loopback (other runs on this machine share domain 0)
pytestmark = [pytest.mark.dds, pytest.mark.usefixtures('isolated_ros_domain')]

# good_rgb, good_observation and good_candidates: session fixtures of test/ros/conftest.py


# ------------------------------------------------------------------------ segmentation_node
def test_segmentation_node_rgb8_and_bgr8(node_assets: NodeAssets, good_rgb: np.ndarray) -> None:
    expected = load_segmenter(str(node_assets.color_config)).process(good_rgb)
    with running(segmentation_node(node_assets)) as h:
        out = h.collect(HandObservation, 'hand/observation')
        pub = h.publisher(Image, 'camera/image_raw')
        rgb_msg = h.exchange(pub, array_to_image(good_rgb, 'rgb8', header(100, 7, 'cam_rgb')),
                             out)
        bgr_msg = h.exchange(pub, array_to_image(np.ascontiguousarray(good_rgb[..., ::-1]),
                                                 'bgr8', header(101, 9, 'cam_bgr')), out)
    for msg, (sec, nanosec, frame) in ((rgb_msg, (100, 7, 'cam_rgb')),
                                       (bgr_msg, (101, 9, 'cam_bgr'))):
        assert msg.hand_found and msg.status == ''
        assert (msg.header.stamp.sec, msg.header.stamp.nanosec) == (sec, nanosec)
        assert msg.header.frame_id == frame
        assert (msg.image_width, msg.image_height) == (640, 480)
        tiny = tiny_labels_from_observation_msg(msg)
        assert tiny.shape == (TINY_SIZE, TINY_SIZE) and len(msg.tiny_labels) == 1600
        np.testing.assert_array_equal(tiny, expected.tiny_labels)
        blobs = blob_tuples(msg)
        colors = [b[0] for b in blobs]
        assert set(colors) <= set(range(1, 11)) and len(set(colors)) >= 8
        counts = [b[3] for b in blobs]
        assert counts == sorted(counts, reverse=True)
        assert all(0 <= x < 640 and 0 <= y < 480 for _, x, y, _ in blobs)
        assert msg.crop_scale == pytest.approx(expected.crop.scale)
        assert msg.crop_offset_x == pytest.approx(expected.crop.offset_x)
        assert msg.glove_pixel_count == expected.glove_pixel_count
    # the same pixels in either channel order give the same observation
    assert list(rgb_msg.tiny_labels) == list(bgr_msg.tiny_labels)
    assert blob_tuples(rgb_msg) == blob_tuples(bgr_msg)


def test_segmentation_node_padded_rows_and_debug_image(node_assets: NodeAssets,
                                                       good_rgb: np.ndarray) -> None:
    """Rows padded to a larger ``step`` segment like packed rows; the debug image shows the
    glove colours where the segmenter found glove."""
    packed = array_to_image(good_rgb, 'rgb8')
    padded_rows = np.zeros((480, 1920 + 64), np.uint8)
    padded_rows[:, :1920] = good_rgb.reshape(480, 1920)
    padded = Image(header=header(120, 0, 'cam'), height=480, width=640, encoding='rgb8',
                   step=1920 + 64, data=padded_rows.tobytes())
    with running(segmentation_node(node_assets, publish_debug_image=True)) as h:
        out = h.collect(HandObservation, 'hand/observation')
        debug = h.collect(Image, 'hand/segmentation_debug')
        pub = h.publisher(Image, 'camera/image_raw')
        packed.header = header(119, 0, 'cam')
        first = h.exchange(pub, packed, out)
        second = h.exchange(pub, padded, out)
        assert h.spin_until(lambda: len(debug) >= 2, 5.0)
    assert first.hand_found and list(first.tiny_labels) == list(second.tiny_labels)
    assert blob_tuples(first) == blob_tuples(second)
    image = debug[1]
    assert (image.width, image.height, image.encoding) == (640, 480, 'rgb8')
    assert image.header.stamp.sec == 120 and image.header.frame_id == 'cam'
    pixels = np.frombuffer(bytes(image.data), np.uint8).reshape(480, 640, 3)
    glove = np.any(pixels > 0, axis=2)
    palette = {tuple(int(v) for v in c) for c in DEBUG_PALETTE[1:]}
    assert {tuple(int(v) for v in p) for p in pixels[glove][::50]} <= palette
    # the glove pixels the debug image shows cover at least the crop's glove pixels
    assert glove.sum() >= 0.8 * second.glove_pixel_count


def _bad_images(rgb: np.ndarray) -> dict[str, tuple[Image, str]]:
    mono = array_to_image(np.ascontiguousarray(rgb[..., 1]), 'mono8')
    empty = Image(encoding='rgb8', width=0, height=0, step=0)
    short = array_to_image(rgb, 'rgb8')
    short.data = bytes(short.data[:short.step * 100])          # 100 of 480 rows
    # a depth image sent to the colour input (yuv422 and Bayer images are decoded now)
    depth = Image(encoding='32FC1', width=640, height=480, step=2560, data=bytes(2560 * 480))
    return {'mono8': (mono, 'mono8'), 'empty': (empty, 'image_width must be >= 1'),
            'short': (short, 'image data holds'), 'depth': (depth, '32FC1')}


def test_segmentation_node_reports_bad_frames_and_keeps_going(node_assets: NodeAssets,
                                                              good_rgb: np.ndarray) -> None:
    with running(segmentation_node(node_assets)) as h:
        out = h.collect(HandObservation, 'hand/observation')
        pub = h.publisher(Image, 'camera/image_raw')
        for sec, (name, (bad, problem)) in enumerate(_bad_images(good_rgb).items()):
            bad.header = header(10 + 2 * sec, 0, 'bad')
            msg = h.exchange(pub, bad, out)
            assert not msg.hand_found, name
            assert msg.status.startswith('bad image') and problem in msg.status, msg.status
            assert msg.header.stamp.sec == 10 + 2 * sec and msg.header.frame_id == 'bad'
            assert len(msg.tiny_labels) == 0 and len(msg.blob_colors) == 0
            good = h.exchange(pub, array_to_image(good_rgb, 'rgb8', header(11 + 2 * sec)), out)
            assert good.hand_found and good.header.stamp.sec == 11 + 2 * sec, name


def test_segmentation_node_no_hand_and_hand_out_of_frame(node_assets: NodeAssets,
                                                         good_rgb: np.ndarray) -> None:
    frames = {'background': background_rgb(),
              'far_left': hand_far_out_of_frame_rgb(4),
              **{f'border_{s}': glove_frame(s, out_of_frame=True).image_rgb for s in (2, 5, 9)}}
    with running(segmentation_node(node_assets)) as h:
        out = h.collect(HandObservation, 'hand/observation')
        pub = h.publisher(Image, 'camera/image_raw')
        results = {name: h.exchange(pub, array_to_image(rgb, 'rgb8', header(50 + i)), out)
                   for i, (name, rgb) in enumerate(frames.items())}
        after = h.exchange(pub, array_to_image(good_rgb, 'rgb8', header(99)), out)
    background = results.pop('background')
    assert not background.hand_found and background.status == 'no_glove'
    assert len(background.tiny_labels) == 0
    for name, msg in results.items():
        if msg.hand_found:
            assert len(msg.tiny_labels) == 1600 and msg.status == '', name
        else:
            assert msg.status in ('out_of_frame', 'too_small', 'no_glove'), (name, msg.status)
            assert len(msg.tiny_labels) == 0, name
    # the hand 60 px left of the image is mostly outside: never a valid observation
    assert not results['far_left'].hand_found
    assert after.hand_found


# ------------------------------------------------------------------------------ lookup_node
def test_lookup_node_candidates(node_assets: NodeAssets, good_observation: HandObservation) -> None:
    lookup = node_lookup(node_assets)
    camera = load_calibration(CONFIG_DIR / 'calibration.yaml').primary
    # the node blends each finger from the observation's blobs (finger_evidence: true)
    expected = lookup.lookup(tiny_labels_from_observation_msg(good_observation),
                             crop_from_observation_msg(good_observation), camera,
                             blobs_from_observation_msg(good_observation))
    with running(lookup_node(node_assets)) as h:
        out = h.collect(HandPoseCandidates, 'hand/pose_candidates')
        pub = h.publisher(HandObservation, 'hand/observation')
        msg = h.exchange(pub, good_observation, out)
        # the database's files were read into the page cache in the background
        reader = h.nodes[0].page_cache_reader
        reader.join(10.0)
        assert reader.daemon and not reader.is_alive()
    assert msg.hand_found and msg.status == ''
    assert (msg.header.stamp.sec, msg.header.stamp.nanosec) == (200, 500)
    assert msg.header.frame_id == 'camera_optical_frame'
    assert list(msg.dof_names) == list(DOF_NAMES) and len(msg.dof_names) == 26
    assert len(msg.candidate_indices) == 10
    distances = list(msg.candidate_distances)
    assert len(distances) == 10 and distances == sorted(distances)
    assert sum(msg.candidate_weights) == pytest.approx(1.0, abs=1e-9)
    assert len(msg.candidate_weights) == 10 and len(msg.candidate_poses) == 10 * 26
    np.testing.assert_allclose(np.reshape(msg.candidate_poses, (10, 26)), expected.poses,
                               atol=1e-12)
    assert list(msg.candidate_indices) == [int(i) for i in expected.indices]
    np.testing.assert_allclose(msg.blended_pose, expected.blended, atol=1e-9)
    assert len(msg.blended_pose) == 26
    np.testing.assert_allclose(msg.finger_std, expected.finger_std, atol=1e-12)
    assert len(msg.finger_std) == 20
    count = len(msg.constraint_patch_ids)
    assert count > 0 and len(msg.constraint_tiny_xy) == 2 * count
    assert all(len(getattr(msg, f'constraint_{name}')) == count
               for name in ('colors', 'vertices', 'pixel_counts'))
    assert all(1 <= c <= 10 for c in msg.constraint_colors)
    assert all(0 <= p < 20 for p in msg.constraint_patch_ids)
    assert list(msg.observation.tiny_labels) == list(good_observation.tiny_labels)
    assert msg.observation.crop_scale == good_observation.crop_scale
    assert blob_tuples(msg.observation) == blob_tuples(good_observation)
    assert msg.lookup_time_ms > 0.0


@pytest.mark.parametrize('threads', [1, 2])
def test_lookup_node_search_threads(node_assets: NodeAssets, good_observation: HandObservation,
                                    threads: int) -> None:
    """search_threads 1 runs the scan and re-rank in the callback (no worker thread), 2 with
    a worker; the candidates are the same."""
    lookup = node_lookup(node_assets)
    camera = load_calibration(CONFIG_DIR / 'calibration.yaml').primary
    expected = lookup.lookup(tiny_labels_from_observation_msg(good_observation),
                             crop_from_observation_msg(good_observation), camera,
                             blobs_from_observation_msg(good_observation))
    with running(lookup_node(node_assets, search_threads=threads)) as h:
        assert (h.nodes[0].lookup._pool is None) == (threads == 1)
        out = h.collect(HandPoseCandidates, 'hand/pose_candidates')
        msg = h.exchange(h.publisher(HandObservation, 'hand/observation'), good_observation, out)
    assert list(msg.candidate_indices) == [int(i) for i in expected.indices]
    assert list(msg.candidate_distances) == [float(d) for d in expected.distances]


def test_lookup_node_passes_no_hand_through(node_assets: NodeAssets) -> None:
    no_hand = HandObservation(header=header(300, 1, 'cam'), hand_found=False,
                              status='out_of_frame', image_width=640, image_height=480)
    bad_size = HandObservation(header=header(301, 0, 'cam'), hand_found=True, image_width=640,
                               image_height=480, tiny_labels=[1] * 100, crop_scale=3.0)
    with running(lookup_node(node_assets)) as h:
        out = h.collect(HandPoseCandidates, 'hand/pose_candidates')
        pub = h.publisher(HandObservation, 'hand/observation')
        msg = h.exchange(pub, no_hand, out)
        bad = h.exchange(pub, bad_size, out)
    assert not msg.hand_found and msg.status == 'out_of_frame'
    assert msg.header.stamp.sec == 300 and msg.header.frame_id == 'cam'
    assert len(msg.candidate_indices) == 0 and len(msg.blended_pose) == 0
    assert msg.observation.status == 'out_of_frame'
    assert not bad.hand_found and 'tiny_labels must have shape (1600)' in bad.status, bad.status


def test_lookup_node_rejects_non_finite_crop(node_assets: NodeAssets,
                                             good_observation: HandObservation) -> None:
    bad = copy.deepcopy(good_observation)
    bad.crop_offset_x = float('inf')
    with running(lookup_node(node_assets)) as h:
        out = h.collect(HandPoseCandidates, 'hand/pose_candidates')
        pub = h.publisher(HandObservation, 'hand/observation')
        msg = h.exchange(pub, bad, out)
    assert not msg.hand_found and msg.status.startswith('lookup:'), msg.status
    assert len(msg.blended_pose) == 0 and len(msg.candidate_indices) == 0


# ------------------------------------------------------------------------------ ik_node
def test_ik_node_outputs(good_candidates: HandPoseCandidates, good_rgb: np.ndarray,
                        small_database_path: Path) -> None:
    no_hand = HandPoseCandidates(header=header(200, 600_000_000, 'camera_optical_frame'),
                                 hand_found=False, status='no_glove',
                                 dof_names=list(DOF_NAMES))
    with running(ik_node(small_database_path, publish_overlay=True)) as h:
        joints = h.collect(JointState, 'hand/joint_states')
        wrist = h.collect(PoseStamped, 'hand/wrist_pose')
        markers = h.collect(MarkerArray, 'hand/markers')
        status = h.collect(String, 'hand/tracking_status')
        overlay = h.collect(Image, 'hand/overlay')
        predictions = h.collect(PolygonStamped, 'hand/crop_prediction')
        image_pub = h.publisher(Image, 'camera/image_raw')
        image_pub.publish(array_to_image(good_rgb, 'rgb8', good_candidates.header))
        h.settle(0.3)
        pub = h.publisher(HandPoseCandidates, 'hand/pose_candidates')
        first = h.exchange(pub, good_candidates, status)
        assert h.spin_until(lambda: joints and wrist and markers and overlay and predictions,
                            10.0), (len(joints), len(wrist), len(markers), len(overlay))
        lost = h.exchange(pub, no_hand, status)
        assert h.spin_until(lambda: len(markers) >= 2, 5.0)
        h.settle(0.5)
    assert first.data.startswith('tracking:'), first.data
    joint_state = joints[0]
    assert list(joint_state.name) == list(FINGER_DOF_NAMES) and len(joint_state.name) == 20
    assert np.all(np.isfinite(joint_state.position)) and len(joint_state.position) == 20
    # the tracked frame's crop prediction (only for it): near the crop the glove was found in
    assert len(predictions) == 1 and predictions[0].header.frame_id == 'camera_optical_frame'
    predicted = crop_prediction_from_msg(predictions[0], (640, 480))
    crop = crop_from_observation_msg(good_candidates.observation)
    assert predicted.stamp == pytest.approx(200.0000005)
    assert 0.5 < predicted.half_size / crop.half_size < 2.0
    assert np.hypot(*np.subtract(predicted.center_xy, crop.center_xy)) < crop.half_size
    for msg in (joint_state, wrist[0], markers[0], overlay[0], predictions[0]):
        stamp = msg.markers[0].header.stamp if isinstance(msg, MarkerArray) else msg.header.stamp
        assert (stamp.sec, stamp.nanosec) == (200, 500)
    assert wrist[0].header.frame_id == 'camera_optical_frame'
    position = wrist[0].pose.position
    assert 0.2 < position.z < 1.0               # in front of the camera, near the sampled depth
    q = wrist[0].pose.orientation
    assert q.x ** 2 + q.y ** 2 + q.z ** 2 + q.w ** 2 == pytest.approx(1.0)
    kinds = sorted(m.type for m in markers[0].markers)
    assert kinds == sorted([Marker.LINE_LIST, Marker.SPHERE_LIST])
    assert all(len(m.points) > 0 for m in markers[0].markers)
    assert (overlay[0].width, overlay[0].height, overlay[0].encoding) == (640, 480, 'rgb8')
    # hand lost: a status, the markers cleared, and no joint state or wrist pose
    assert lost.data == 'no hand: no_glove'
    assert markers[1].markers[0].action == Marker.DELETEALL
    assert len(joints) == 1 and len(wrist) == 1



def _tf_message_type() -> type:
    from tf2_msgs.msg import TFMessage
    return TFMessage


@pytest.mark.parametrize('function, message_type, topic, publisher', [
    # segmentation_node subscribes to crop predictions only while it uses them (its default:
    # not)
    ('tracked_crop', lambda: PolygonStamped, 'hand/crop_prediction', 'crop_prediction_pub'),
    # the camera -> palm transform, for RViz or a tf listener
    ('wrist_pose_to_tf_msg', _tf_message_type, '/tf', 'tf_pub'),
])
def test_ik_node_builds_an_output_only_for_a_subscriber(
        function: str, message_type, topic: str, publisher: str,
        good_candidates: HandPoseCandidates, small_database_path: Path,
        monkeypatch: pytest.MonkeyPatch) -> None:
    """No subscriber to the output: tracked frames are published without computing it; once
    someone subscribes, each tracked frame gets one."""
    from colorglove_ros.ros.nodes import ik_node as ik_node_module

    computed = []
    real = getattr(ik_node_module, function)

    def counting(*args, **kwargs):
        computed.append(True)
        return real(*args, **kwargs)

    monkeypatch.setattr(ik_node_module, function, counting)
    with running(ik_node(small_database_path)) as h:
        status = h.collect(String, 'hand/tracking_status')
        pub = h.publisher(HandPoseCandidates, 'hand/pose_candidates')
        assert h.exchange(pub, good_candidates, status).data.startswith('tracking:')
        assert computed == []
        outputs = h.collect(message_type(), topic)
        output_pub = getattr(h.nodes[0], publisher)
        assert h.spin_until(lambda: output_pub.get_subscription_count() == 1, 5.0)
        later = copy.deepcopy(good_candidates)
        later.header.stamp.nanosec += 33_000_000
        assert h.exchange(pub, later, status).data.startswith('tracking:')
        assert h.spin_until(lambda: outputs, 5.0)
    assert len(computed) == 1 and len(outputs) == 1


def test_ik_node_frame_prefix_names_joints_and_tf_child(good_candidates: HandPoseCandidates,
                                                        small_database_path: Path) -> None:
    """ik_node with frame_prefix 'right_' publishes 'right_...' joints and the camera ->
    right_palm transform; a consumer node with the same prefix reads those joint states."""
    from geometry_msgs.msg import PoseArray
    from tf2_msgs.msg import TFMessage

    from colorglove_ros.core.hand.frames import finger_joint_names
    from colorglove_ros.ros.nodes.keypoints_node import KeypointsNode

    keypoints = lambda ctx: KeypointsNode(context=ctx, parameter_overrides=params(  # noqa: E731
        frame_prefix='right_'))
    with running(ik_node(small_database_path, frame_prefix='right_'), keypoints) as h:
        joints = h.collect(JointState, 'hand/joint_states')
        tf = h.collect(TFMessage, '/tf')
        in_hand = h.collect(PoseArray, 'hand/keypoints_wrist')
        status = h.collect(String, 'hand/tracking_status')
        pub = h.publisher(HandPoseCandidates, 'hand/pose_candidates')
        first = h.exchange(pub, good_candidates, status)
        assert h.spin_until(lambda: joints and tf and in_hand, 10.0), \
            (len(joints), len(tf), len(in_hand))
    assert first.data.startswith('tracking:'), first.data
    assert list(joints[0].name) == finger_joint_names('right_')
    assert all(name.startswith('right_') for name in joints[0].name)
    transform = tf[0].transforms[0]
    assert transform.child_frame_id == 'right_palm'
    assert transform.header.frame_id == 'camera_optical_frame'
    # the consumer found every prefixed joint (a plain-name reader would miss them all)
    assert in_hand[0].header.frame_id == 'right_palm' and len(in_hand[0].poses) == 21


@dataclass
class _IKAnswers:
    """What ik_node did with a bad candidates message followed by a good one."""

    bad_status: str
    good_status: str
    joints: list[JointState]
    overlays: list[Image]
    camera_subscribers: int


def _bad_then_good(database: Path, bad: HandPoseCandidates, good: HandPoseCandidates,
                   **overrides) -> _IKAnswers:
    """Send ``bad`` then ``good`` to an ik_node (database ``database``) with the parameters
    ``overrides``."""
    with running(ik_node(database, **overrides)) as h:
        status = h.collect(String, 'hand/tracking_status')
        joints = h.collect(JointState, 'hand/joint_states')
        overlays = h.collect(Image, 'hand/overlay')
        pub = h.publisher(HandPoseCandidates, 'hand/pose_candidates')
        bad_status = h.exchange(pub, bad, status).data
        good_status = h.exchange(pub, good, status).data
        h.settle(0.2)
        camera_subscribers = h.probe.count_subscribers('/camera/image_raw')
    return _IKAnswers(bad_status, good_status, joints, overlays, camera_subscribers)


def test_ik_node_survives_malformed_candidates(good_candidates: HandPoseCandidates,
                                               small_database_path: Path) -> None:
    """A candidates message with hand_found and wrong DOF names is reported, not fatal."""
    wrong_names = HandPoseCandidates()
    wrong_names.header = header(200, 400_000_000, 'camera_optical_frame')
    wrong_names.hand_found = True
    wrong_names.observation = good_candidates.observation
    wrong_names.dof_names = ['a', 'b']
    wrong_names.blended_pose = [0.0, 0.0]
    # defaults: no overlay, so no camera image subscription
    answers = _bad_then_good(small_database_path, wrong_names, good_candidates)
    assert answers.bad_status.startswith('no hand')
    assert answers.good_status.startswith('tracking:')
    assert not answers.overlays and answers.camera_subscribers == 0


def _with_clutter_blobs(good: HandPoseCandidates, nearest_distance: float
                        ) -> HandPoseCandidates:
    """``good`` after a far lookup, with three times as many glove-coloured blobs in a row
    along the image's top edge (clutter no fitted hand explains)."""
    msg = copy.deepcopy(good)
    msg.header = header(200, 400_000_000, 'camera_optical_frame')
    msg.candidate_distances[0] = nearest_distance
    seen = msg.observation
    count = 3 * len(seen.blob_colors)
    set_blobs(seen, blob_tuples(seen) + [(1 + k % 10, 10.0 + 9.0 * k, 5.0, 40)
                                         for k in range(count)])
    seen.glove_pixel_count += 40 * count
    return msg


def test_ik_node_refuses_weak_evidence(good_candidates: HandPoseCandidates,
                                       small_database_path: Path) -> None:
    """After a lookup that was not a close match, a fit that leaves most of the observed glove
    blobs unexplained is 'no hand: weak evidence', with no JointState; the same clutter after
    a close match, or the far match without the clutter, is tracked."""
    gate = {'min_explained_blob_share': 0.5, 'close_match_distance': 2.0}
    cluttered = _with_clutter_blobs(good_candidates, nearest_distance=3.0)
    answers = _bad_then_good(small_database_path, cluttered, good_candidates, **gate)
    assert answers.bad_status.startswith('no hand: weak evidence'), answers.bad_status
    assert answers.good_status.startswith('tracking:')
    assert [m.header.stamp.nanosec for m in answers.joints] == [500]
    close = _with_clutter_blobs(good_candidates, nearest_distance=1.0)
    answers = _bad_then_good(small_database_path, close, good_candidates, **gate)
    assert answers.bad_status.startswith('tracking:'), answers.bad_status


def _short_pose(msg: HandPoseCandidates) -> None:
    msg.blended_pose = [0.0] * 5


def _vertex_out_of_range(msg: HandPoseCandidates) -> None:
    msg.constraint_vertices = [1_000_000] * len(msg.constraint_vertices)


def _nan_pose(msg: HandPoseCandidates) -> None:
    msg.blended_pose = [float('nan')] * 26


@pytest.mark.parametrize('spoil', [_short_pose, _vertex_out_of_range, _nan_pose],
                         ids=['short_pose', 'vertex_out_of_range', 'nan_pose'])
def test_ik_node_survives_bad_candidates(spoil, good_candidates: HandPoseCandidates,
                                         small_database_path: Path) -> None:
    """A hand_found candidates message the tracker cannot use is reported as 'no hand' and the
    node goes on with the next frame."""
    bad = copy.deepcopy(good_candidates)
    bad.header = header(200, 400_000_000, 'camera_optical_frame')
    spoil(bad)
    answers = _bad_then_good(small_database_path, bad, good_candidates, publish_overlay=False)
    assert answers.bad_status.startswith('no hand'), answers.bad_status
    assert answers.good_status.startswith('tracking:')
    assert [m.header.stamp.nanosec for m in answers.joints] == [500]


# ------------------------------------------------------------------------------ camera_node
def test_camera_node_image_folder(tmp_path: Path) -> None:
    rng = np.random.default_rng(0)
    images = [rng.integers(0, 256, (480, 640, 3), dtype=np.uint8) for _ in range(3)]
    for i, rgb in enumerate(images):
        cv2.imwrite(str(tmp_path / f'frame_{i}.png'), np.ascontiguousarray(rgb[..., ::-1]))
    (tmp_path / 'notes.txt').write_text('not an image')
    with running(lambda ctx: CameraNode(context=ctx, parameter_overrides=params(
            source=str(tmp_path), rate_hz=20.0, loop=True))) as h:
        frames = h.collect(Image, 'camera/image_raw', qos_profile_sensor_data)
        infos = h.collect(CameraInfo, 'camera/camera_info', qos_profile_sensor_data)
        assert h.spin_until(lambda: len(frames) >= 6 and len(infos) >= 6, 20.0)
    seen = []
    info_by_stamp = {(m.header.stamp.sec, m.header.stamp.nanosec): m for m in infos}
    for image in frames:
        assert (image.encoding, image.width, image.height, image.step) == ('rgb8', 640, 480,
                                                                           1920)
        pixels = np.frombuffer(bytes(image.data), np.uint8).reshape(480, 640, 3)
        matches = [i for i, rgb in enumerate(images) if np.array_equal(pixels, rgb)]
        assert len(matches) == 1, 'a published frame equals none of the folder images'
        seen.append(matches[0])
        assert image.header.frame_id == 'camera_optical_frame'
        info = info_by_stamp.get((image.header.stamp.sec, image.header.stamp.nanosec))
        if info is not None:
            assert info.header.frame_id == image.header.frame_id
    assert set(seen) == {0, 1, 2}
    # consecutive frames follow the folder's sorted order, looping (losses aside)
    steps = [(b - a) % 3 for a, b in zip(seen, seen[1:], strict=False)]
    assert steps.count(1) >= len(steps) - 1
    assert len(info_by_stamp) >= 6
    for info in infos:
        assert (info.width, info.height) == (640, 480)
        np.testing.assert_allclose(info.k, [600.0, 0.0, 319.5, 0.0, 600.0, 239.5, 0, 0, 1])
        assert info.distortion_model == 'plumb_bob' and list(info.d) == [0.0] * 5
        assert info.header.frame_id == 'camera_optical_frame'
    matched = sum((f.header.stamp.sec, f.header.stamp.nanosec) in info_by_stamp for f in frames)
    assert matched >= len(frames) - 1


def test_camera_node_refuses_frames_of_another_size(tmp_path: Path) -> None:
    """Frames whose size differs from the calibration are not published (an error is logged
    per second instead); the node keeps running."""
    cv2.imwrite(str(tmp_path / 'small.png'), np.zeros((240, 320, 3), np.uint8))
    with running(lambda ctx: CameraNode(context=ctx, parameter_overrides=params(
            source=str(tmp_path), rate_hz=20.0, loop=True))) as h:
        frames = h.collect(Image, 'camera/image_raw', qos_profile_sensor_data)
        h.settle(1.5)
        node = h.nodes[0]
        assert node.published == 0 and not frames
        assert not node.timer.is_canceled()


def test_camera_node_publishes_the_calibrated_camera_it_is(tmp_path: Path) -> None:
    """camera_index picks the camera of a several-camera calibration: its frame_id and
    intrinsics are published; an index outside the calibration, or the synthetic source
    for a camera other than 0, cannot start."""
    stereo = CONFIG_DIR / 'calibration_stereo.yaml'
    second = load_calibration(stereo).cameras[1]
    cv2.imwrite(str(tmp_path / 'frame.png'), np.zeros((480, 640, 3), np.uint8))
    with running(lambda ctx: CameraNode(context=ctx, parameter_overrides=params(
            source=str(tmp_path), calibration_file=str(stereo), camera_index=1,
            rate_hz=20.0))) as h:
        infos = h.collect(CameraInfo, 'camera/camera_info', qos_profile_sensor_data)
        assert h.spin_until(lambda: infos, 10.0)
    assert infos[0].header.frame_id == second.frame_id == 'camera2_optical_frame'
    np.testing.assert_allclose(infos[0].k, second.K.ravel())
    for index, source, message in ((2, str(tmp_path), 'lists 2 camera'),
                                   (1, 'synthetic', 'renders camera 0 only')):
        with pytest.raises(StartupError, match=message), running(
                lambda ctx, i=index, src=source: CameraNode(
                    context=ctx, parameter_overrides=params(
                        source=src, calibration_file=str(stereo), camera_index=i))):
            pass


# ------------------------------------------------------------------------ start-up failures
def test_nodes_exit_with_code_1_on_bad_startup(tmp_path: Path, node_assets: NodeAssets,
                                               isolated_ros_domain: dict) -> None:
    """Each node process given a bad device, file, database or config prints why and exits 1.
    The processes run side by side (each takes seconds to import on a loaded machine)."""
    corrupt = tmp_path / 'corrupt_db'
    shutil.copytree(node_assets.database, corrupt)
    (corrupt / 'manifest.json').write_text('{not json')
    missing_db = tmp_path / 'no_database_here'
    missing_ik = tmp_path / 'no_ik.yaml'
    missing_cal = tmp_path / 'no_colors.yaml'
    cases = {
        'lookup, no database': ('lookup_node', {'database_path': missing_db},
                                ['lookup_node cannot start', str(missing_db)]),
        'lookup, corrupt manifest': ('lookup_node', {'database_path': corrupt},
                                     ['lookup_node cannot start', 'manifest']),
        'ik, no config': ('ik_node', {'ik_config': missing_ik},
                          ['ik_node cannot start', 'IK config file not found', str(missing_ik)]),
        'camera, no device': ('camera_node', {'source': '/dev/video99'},
                              ['camera_node cannot start', '/dev/video99 does not exist']),
        'camera, no file': ('camera_node', {'source': tmp_path / 'missing.mp4'},
                            ['camera_node cannot start', 'is neither', 'missing.mp4']),
        'segmentation, no colour config': (
            'segmentation_node', {'color_calibration_file': missing_cal},
            ['segmentation_node cannot start', str(missing_cal)]),
    }
    processes = {name: start_node_process(executable, {k: str(v) for k, v in values.items()},
                                          isolated_ros_domain)
                 for name, (executable, values, _) in cases.items()}
    problems = []
    for name, process in processes.items():
        try:
            output, _ = process.communicate(timeout=90)
        except subprocess.TimeoutExpired:
            process.kill()
            output, _ = process.communicate()
            problems.append(f'{name}: still running after 90 s')
            continue
        missing = [text for text in cases[name][2] if text not in output]
        if process.returncode != 1 or missing:
            problems.append(f'{name}: exit code {process.returncode}, missing {missing} in '
                            f'{output!r}')
        elif '[FATAL]' not in output:
            problems.append(f'{name}: no [FATAL] line in {output!r}')
    assert not problems, '\n'.join(problems)


# ------------------------------------------------------------------------ parameters
def test_start_up_parameters_are_read_only(node_assets: NodeAssets) -> None:
    """A parameter read only at start-up is declared read-only: ROS refuses a run-time change
    with its standard reason instead of accepting a value the node would never use."""
    from rclpy.parameter import Parameter

    with running(segmentation_node(node_assets)) as h:
        node = h.nodes[0]
        descriptor = node.describe_parameter('color_calibration_file')
        assert descriptor.read_only
        result = node.set_parameters([Parameter('color_calibration_file',
                                                value='config/other.yaml')])[0]
        assert not result.successful and 'read-only' in result.reason
        assert node.get_parameter('color_calibration_file').value == str(node_assets.color_config)


def test_ik_node_follows_a_tracked_hand_the_border_cuts(good_candidates: HandPoseCandidates,
                                                       small_database_path: Path) -> None:
    """A tracked hand whose next observation the border cuts, and which the lookup refused
    (no candidates), is followed from its last pose and says so; with follow_cut_hands off
    the frame is the lookup's 'no hand', as before."""
    from colorglove_ros.core.hand.frame_evidence import FOLLOWED_NOTE

    cut = copy.deepcopy(good_candidates)
    cut.header.stamp.nanosec += 33_000_000
    cut.observation.header.stamp = cut.header.stamp
    cut.hand_found = False
    cut.status = 'lookup: nearest database image too far'
    cut.observation.cut_by_border = True
    for follow, expected in ((True, 'tracking:'), (False, f'no hand: {cut.status}')):
        with running(ik_node(small_database_path, follow_cut_hands=follow)) as h:
            status = h.collect(String, 'hand/tracking_status')
            joints = h.collect(JointState, 'hand/joint_states')
            pub = h.publisher(HandPoseCandidates, 'hand/pose_candidates')
            assert h.exchange(pub, good_candidates, status).data.startswith('tracking:')
            answer = h.exchange(pub, cut, status).data
            h.settle(0.2)
        assert answer.startswith(expected), answer
        assert (FOLLOWED_NOTE in answer) == follow
        assert len(joints) == (2 if follow else 1)
