"""The user's finger proportions (``finger_length_factors`` of the calibration file) in the
nodes that build the hand from it: ik_node's tracker, the hand consumers
(``common.hand_model_from_calibration``) and hand_description_node's URDF."""
from __future__ import annotations

from pathlib import Path

import pytest
from hand_calibration_files import UNEVEN_FACTORS, calibration_with_hand
from node_fixtures import ik_node, params, running
from rclpy.qos import QoSDurabilityPolicy, QoSHistoryPolicy, QoSProfile, QoSReliabilityPolicy
from std_msgs.msg import String

from colorglove_ros.core.hand.glove import default_hand
from colorglove_ros.core.hand.urdf import calibrated_hand_urdf, urdf_string
from colorglove_ros.core.lookup.database import read_database_build
from colorglove_ros.ros.nodes.common import StartupError
from colorglove_ros.ros.nodes.hand_description_node import HandDescriptionNode
from colorglove_ros.ros.nodes.keypoints_node import KeypointsNode

pytestmark = [pytest.mark.dds, pytest.mark.usefixtures('isolated_ros_domain')]

LATCHED = QoSProfile(history=QoSHistoryPolicy.KEEP_LAST, depth=1,
                     reliability=QoSReliabilityPolicy.RELIABLE,
                     durability=QoSDurabilityPolicy.TRANSIENT_LOCAL)


def test_ik_node_tracks_with_the_calibrated_fingers(tmp_path: Path,
                                                    small_database_path: Path) -> None:
    build = read_database_build(str(small_database_path))
    calibration = calibration_with_hand(tmp_path, UNEVEN_FACTORS, build.hand_length_m)
    with running(ik_node(small_database_path, calibration_file=str(calibration))) as h:
        tracker = h.nodes[0].tracker
    assert tracker.model.finger_length_factors == UNEVEN_FACTORS
    assert tracker.mesh.finger_length_factors == UNEVEN_FACTORS
    # the database's glove (its seed) on the stretched mesh of the same topology
    model, mesh, glove = default_hand(build.hand_length_m, build.glove_seed, UNEVEN_FACTORS)
    assert tracker.model is model and tracker.mesh is mesh
    assert h.nodes[0].num_vertices == default_hand(build.hand_length_m)[1].num_vertices


def test_hand_consumers_use_the_calibrated_fingers(tmp_path: Path) -> None:
    calibration = calibration_with_hand(tmp_path, UNEVEN_FACTORS, 0.18)
    with running(lambda ctx: KeypointsNode(context=ctx, parameter_overrides=params(
            calibration_file=str(calibration)))) as h:
        model = h.nodes[0].model
    assert (model.hand_length_m, model.finger_length_factors) == (0.18, UNEVEN_FACTORS)


def test_hand_consumer_refuses_bad_factors(tmp_path: Path) -> None:
    calibration = calibration_with_hand(tmp_path, [1.0, 1.0, 9.0, 1.0, 1.0])
    with pytest.raises(StartupError, match='keypoints_node cannot start: .*middle factor 9.0'):
        with running(lambda ctx: KeypointsNode(context=ctx, parameter_overrides=params(
                calibration_file=str(calibration)))):
            pass


def test_hand_description_publishes_the_calibrated_fingers(tmp_path: Path) -> None:
    calibration = calibration_with_hand(tmp_path, UNEVEN_FACTORS, 0.18)
    expected = calibrated_hand_urdf(calibration, 'right_')
    with running(lambda ctx: HandDescriptionNode(context=ctx, parameter_overrides=params(
            calibration_file=str(calibration), frame_prefix='right_'))) as h:
        latched = h.collect(String, 'robot_description', LATCHED)
        assert h.spin_until(lambda: latched, 10.0)
    assert [m.data for m in latched] == [expected]
    assert 'finger length factors' in expected
    assert expected != calibrated_hand_urdf(calibration_with_hand(tmp_path, [1.0] * 5, 0.18,
                                                                  'plain'), 'right_')
    assert calibrated_hand_urdf(calibration_with_hand(tmp_path, [1.0] * 5, 0.18, 'plain')) \
        == urdf_string(default_hand(0.18)[0])
