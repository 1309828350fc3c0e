"""hand_description_node in one process over DDS on loopback: the calibrated hand's URDF on
``robot_description``, latched as robot_state_publisher publishes it."""
from __future__ import annotations

from pathlib import Path

import pytest
from calibration_files import calibration_with_hand_length
from node_fixtures import params, running
from rclpy.parameter import Parameter
from rclpy.qos import (
    QoSDurabilityPolicy,
    QoSHistoryPolicy,
    QoSProfile,
    QoSReliabilityPolicy,
)
from repo_paths import CONFIG_DIR
from std_msgs.msg import String

from colorglove_ros.core.camera import load_calibration
from colorglove_ros.core.hand.model import calibrated_hand_model
from colorglove_ros.core.hand.urdf import calibrated_hand_urdf
from colorglove_ros.core.hand.urdf_variants import hand_urdf_string
from colorglove_ros.ros.nodes.common import StartupError
from colorglove_ros.ros.nodes.hand_description_node import HandDescriptionNode

pytestmark = [pytest.mark.dds, pytest.mark.usefixtures('isolated_ros_domain')]

# what RViz's RobotModel display and robot_state_publisher's own publisher use
LATCHED = QoSProfile(history=QoSHistoryPolicy.KEEP_LAST, depth=1,
                     reliability=QoSReliabilityPolicy.RELIABLE,
                     durability=QoSDurabilityPolicy.TRANSIENT_LOCAL)
VOLATILE = QoSProfile(history=QoSHistoryPolicy.KEEP_LAST, depth=1,
                      reliability=QoSReliabilityPolicy.RELIABLE,
                      durability=QoSDurabilityPolicy.VOLATILE)


def _node(**overrides):
    return lambda ctx: HandDescriptionNode(context=ctx, parameter_overrides=params(**overrides))


def test_late_subscriber_gets_the_calibrated_urdf(tmp_path: Path) -> None:
    calibration = calibration_with_hand_length(tmp_path, 0.17)
    expected = calibrated_hand_urdf(calibration, 'right_')
    with running(_node(calibration_file=str(calibration), frame_prefix='right_')) as h:
        node = h.nodes[0]
        h.settle(0.5)                      # published at start-up, before anyone subscribed
        latched = h.collect(String, 'robot_description', LATCHED)
        volatile = h.collect(String, 'robot_description', VOLATILE)
        assert h.spin_until(lambda: latched, 10.0), 'late transient-local subscriber got nothing'
        h.settle(0.5)
        info = h.probe.get_publishers_info_by_topic('/robot_description')
        own_qos = node.publisher.qos_profile
        parameter = node.get_parameter('robot_description').value
        refused = node.set_parameters([Parameter('robot_description', value='<robot/>')])
    assert [m.data for m in latched] == [expected]      # once, the calibrated hand
    assert volatile == []                               # it was sent before: latching did it
    assert 'name="right_palm"' in expected and 'hand length 0.17 m' in expected
    assert len(info) == 1
    assert info[0].qos_profile.durability == QoSDurabilityPolicy.TRANSIENT_LOCAL
    assert info[0].qos_profile.reliability == QoSReliabilityPolicy.RELIABLE
    # history and depth are not announced in discovery: the publisher's own profile
    assert (own_qos.history, own_qos.depth) == (QoSHistoryPolicy.KEEP_LAST, 1)
    assert parameter == expected
    assert not refused[0].successful                    # read-only


def test_robot_description_override_is_ignored() -> None:
    """A params file's '/**' value meant for robot_state_publisher does not replace it."""
    with running(_node(robot_description='<robot name="other"/>')) as h:
        value = h.nodes[0].get_parameter('robot_description').value
    assert value == calibrated_hand_urdf(CONFIG_DIR / 'calibration.yaml')   # the default file


@pytest.mark.parametrize('overrides, message', [
    ({'frame_prefix': '/right'}, 'frame prefix'),
    ({'frame_prefix': 'right hand'}, 'frame prefix'),
    ({'calibration_file': '/no/such/calibration.yaml'}, 'not found'),
    ({'hand': 'middle'}, 'hand must be one of'),
])
def test_bad_settings_stop_the_start(overrides: dict, message: str) -> None:
    with pytest.raises(StartupError, match=f'hand_description_node cannot start: .*{message}'):
        with running(_node(**overrides)):
            pass


def test_left_hand_description(tmp_path: Path) -> None:
    """hand:=left publishes the mirrored (left) hand's URDF with the left_ names."""
    calibration = calibration_with_hand_length(tmp_path, 0.18)
    with running(_node(calibration_file=str(calibration), frame_prefix='left_',
                       hand='left')) as h:
        value = h.nodes[0].get_parameter('robot_description').value
    model = calibrated_hand_model(load_calibration(calibration))
    assert value == hand_urdf_string('left', 'left_', model)
    assert value != calibrated_hand_urdf(calibration, 'left_')      # not the right hand renamed
    assert 'name="left_palm"' in value and 'name="left_index_pip_flex"' in value
