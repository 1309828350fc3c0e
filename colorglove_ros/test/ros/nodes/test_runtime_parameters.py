"""lookup_node's distance gate and ik_node's switches and gates change at run time, checked by
the core's own rules (an invalid value is refused with the reason and changes nothing);
start-up-only parameters stay read-only; topic lists are string arrays."""
from __future__ import annotations

import copy
from pathlib import Path

import pytest
from colorglove_msgs.msg import HandObservation, HandPoseCandidates
from node_fixtures import NodeAssets, header, ik_node, lookup_node, running
from rclpy.parameter import Parameter
from repo_paths import CONFIG_DIR
from sensor_msgs.msg import Image
from std_msgs.msg import String

from colorglove_ros.core.tracking.config import load_ik_config
from colorglove_ros.ros.nodes.common import StartupError

pytestmark = [pytest.mark.dds, pytest.mark.usefixtures('isolated_ros_domain')]


def _set(node, **values) -> object:
    return node.set_parameters_atomically([Parameter(k, value=v) for k, v in values.items()])


def test_lookup_distance_gate_is_used_from_the_next_observation(
        node_assets: NodeAssets, good_observation: HandObservation) -> None:
    with running(lookup_node(node_assets)) as h:
        node = h.nodes[0]
        out = h.collect(HandPoseCandidates, 'hand/pose_candidates')
        pub = h.publisher(HandObservation, 'hand/observation')
        assert h.exchange(pub, good_observation, out).hand_found
        assert _set(node, max_image_distance=0.0).successful
        refused = h.exchange(pub, good_observation, out)
        assert not refused.hand_found
        assert 'more than max_image_distance 0' in refused.status, refused.status
        result = _set(node, max_image_distance=-1.0)
        assert not result.successful and 'out of range' in result.reason
        assert node.limits.max_image_distance == 0.0
        read_only = _set(node, num_candidates=10)
        assert not read_only.successful and 'read-only' in read_only.reason


def test_ik_switches_and_gates_are_applied_to_the_tracker_and_checked_by_its_config(
        small_database_path: Path) -> None:
    file_config = load_ik_config(CONFIG_DIR / 'ik.yaml')
    with running(ik_node(small_database_path, publish_overlay=False)) as h:
        node = h.nodes[0]
        assert node.get_parameter('gate_tiny_px').value == file_config.gate_tiny_px
        assert _set(node, enable_smoothing=False, gate_tiny_px=4.0, outlier_px=0.0).successful
        config = node.tracker.config
        assert not config.enable_smoothing and config.gate_tiny_px == 4.0
        assert config.outlier_px == 0.0 and config.enable_ik
        # IKConfig's own rule refuses a negative gate; the batch changes nothing
        result = _set(node, enable_ik=False, gate_min_px=-1.0)
        assert not result.successful and 'gate_min_px must be >= 0' in result.reason
        assert node.tracker.config.enable_ik
        assert node.tracker.config.gate_min_px == file_config.gate_min_px
        wrong_type = _set(node, gate_tiny_px='wide')
        assert not wrong_type.successful
        read_only = _set(node, ik_config='config/other.yaml')
        assert not read_only.successful and 'read-only' in read_only.reason


def test_ik_evidence_gate_is_settable_at_run_time(small_database_path: Path) -> None:
    with running(ik_node(small_database_path, publish_overlay=False)) as h:
        node = h.nodes[0]
        assert _set(node, min_explained_blob_share=0.7, close_match_distance=1.5).successful
        assert node.limits.min_explained_blob_share == 0.7
        assert node.limits.close_match_distance == 1.5
        out_of_range = _set(node, min_explained_blob_share=1.5)
        assert not out_of_range.successful and node.limits.min_explained_blob_share == 0.7
        assert _set(node, max_missing_glove_share=0.3).successful
        assert node.limits.max_missing_glove_share == 0.3
        assert not _set(node, max_missing_glove_share=-0.1).successful
        assert _set(node, max_weak_match_residual_px=4.5).successful
        assert node.limits.max_weak_match_residual_px == 4.5
        assert node.limits.follow_cut_hands
        assert _set(node, follow_cut_hands=False).successful
        assert not node.limits.follow_cut_hands
        assert node.limits.max_weak_match_residual_px == 4.5    # the rest kept
        assert not _set(node, follow_cut_hands='sometimes').successful


def test_ik_gate_given_at_start_up_is_checked(small_database_path: Path) -> None:
    with running(ik_node(small_database_path, gate_tiny_px=6.5)) as h:
        assert h.nodes[0].tracker.config.gate_tiny_px == 6.5
    with pytest.raises(StartupError, match='outlier_px must be >= 0'):
        with running(ik_node(small_database_path, outlier_px=-2.0)):
            pass


def test_overlay_starts_and_stops_at_run_time(small_database_path: Path,
                                              good_candidates: HandPoseCandidates,
                                              good_rgb) -> None:
    from colorglove_ros.ros.image import array_to_image

    image = array_to_image(good_rgb, 'rgb8', good_candidates.header)
    with running(ik_node(small_database_path)) as h:
        node = h.nodes[0]
        overlay = h.collect(Image, 'hand/overlay')
        status = h.collect(String, 'hand/tracking_status')
        candidates_pub = h.publisher(HandPoseCandidates, 'hand/pose_candidates')
        assert h.probe.count_subscribers('camera/image_raw') == 0
        assert _set(node, publish_overlay=True).successful
        image_pub = h.publisher(Image, 'camera/image_raw')
        assert image_pub.get_subscription_count() == 1
        image_pub.publish(image)
        h.settle(0.3)
        h.exchange(candidates_pub, good_candidates, status)
        assert h.spin_until(lambda: len(overlay) == 1, 5.0)
        assert _set(node, publish_overlay=False).successful
        assert h.spin_until(lambda: image_pub.get_subscription_count() == 0, 5.0)
        later = copy.deepcopy(good_candidates)
        later.header = header(good_candidates.header.stamp.sec + 1, 0,
                              good_candidates.header.frame_id)
        h.exchange(candidates_pub, later, status)
        h.settle(0.3)
        assert len(overlay) == 1


def test_extra_observation_topics_is_a_string_array(small_database_path: Path) -> None:
    stereo = str(CONFIG_DIR / 'calibration_stereo.yaml')
    topics = ['/camera2/hand/observation']
    with running(ik_node(small_database_path, calibration_file=stereo,
                         extra_observation_topics=topics)) as h:
        node = h.nodes[0]
        assert node.get_parameter('extra_observation_topics').value == topics
        assert node.describe_parameter('extra_observation_topics').read_only
        assert h.probe.count_publishers('/camera2/hand/observation') == 0
        assert node.count_subscribers('/camera2/hand/observation') == 1
    with running(ik_node(small_database_path)) as h:     # one camera: an empty list
        assert h.nodes[0].get_parameter('extra_observation_topics').value == []
    with pytest.raises(StartupError, match='extra_observation_topics must be a list of topic'):
        with running(ik_node(small_database_path, calibration_file=stereo,
                             extra_observation_topics=topics[0])):
            pass
