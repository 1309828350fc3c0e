"""mouse_node in one process: hand pose messages in, cursor and buttons out."""
from __future__ import annotations

import math

import pytest
from geometry_msgs.msg import PointStamped
from node_fixtures import header, params, running
from sensor_msgs.msg import Joy
from std_msgs.msg import String

from colorglove_ros.core.hand.frame_evidence import edge_tracking_status
from colorglove_ros.core.hand.model import DOF_NAMES, HandModel
from colorglove_ros.core.tracking.mouse import MouseConfig, TablePlane, raw_mouse_values
from colorglove_ros.ros.conversions import pose_to_joint_state_msg, pose_to_wrist_pose_msg
from colorglove_ros.ros.nodes.common import StartupError
from colorglove_ros.ros.nodes.mouse_node import MouseNode

pytestmark = [pytest.mark.dds, pytest.mark.usefixtures('isolated_ros_domain')]


def _node(**overrides):
    values = {'smoothing_s': 0.0, **overrides}
    return lambda ctx: MouseNode(context=ctx, parameter_overrides=params(**values))


def test_cursor_and_thumb_button() -> None:
    model = HandModel()
    q = model.rest_pose()
    with running(_node()) as h:
        node = h.nodes[0]
        cursors = h.collect(PointStamped, 'mouse/cursor')
        joys = h.collect(Joy, 'mouse/buttons')
        for k, thumb_deg in enumerate([5.0, 40.0]):
            q[DOF_NAMES.index('thumb_cmc_abd')] = math.radians(thumb_deg)
            node.on_wrist(pose_to_wrist_pose_msg(q, header(5, k * 33_000_000)))
            node.on_joints(pose_to_joint_state_msg(q, header(5, k * 33_000_000)))
        assert h.spin_until(lambda: len(joys) >= 2 and len(cursors) >= 2, 10.0)
        assert list(joys[0].buttons) == [0, 0] and list(joys[1].buttons) == [1, 0]
        expected = raw_mouse_values(model, q, MouseConfig(
            plane=TablePlane.from_camera_tilt(45.0, 0.6)))
        c = cursors[-1].point
        assert abs(c.x - expected[0]) < 1e-6 and abs(c.y - expected[1]) < 1e-6
        assert cursors[-1].header.frame_id == 'table'


def test_a_press_waits_for_the_edge_trackers_evidence_when_asked() -> None:
    q = HandModel().rest_pose()
    thumb = DOF_NAMES.index('thumb_cmc_abd')
    # residuals 1 px, then the thumb abducted on a fit of 3 px (held back), then of 1 px
    script = [(5.0, 1.0)] * 3 + [(40.0, 3.0), (40.0, 1.0)]
    for ratio, expected in ((1.5, [0, 0, 0, 0, 1]), (0.0, [0, 0, 0, 1, 1])):
        with running(_node(press_max_residual_ratio=ratio)) as h:
            node = h.nodes[0]
            joys = h.collect(Joy, 'mouse/buttons')
            for k, (deg, residual) in enumerate(script):
                q[thumb] = math.radians(deg)
                node.on_wrist(pose_to_wrist_pose_msg(q, header(5, k * 33_000_000)))
                node.on_joints(pose_to_joint_state_msg(q, header(5, k * 33_000_000)))
                node.on_status(String(data=edge_tracking_status(
                    [('cam0', 10)], residual, 5.0, (5, k * 33_000_000))))
            assert h.spin_until(lambda joys=joys: len(joys) >= len(script), 10.0)
            assert [j.buttons[0] for j in joys] == expected


def test_unmatched_stamps_publish_nothing_and_bad_thresholds_refuse() -> None:
    q = HandModel().rest_pose()
    with running(_node()) as h:
        node = h.nodes[0]
        joys = h.collect(Joy, 'mouse/buttons')
        node.on_wrist(pose_to_wrist_pose_msg(q, header(1)))
        node.on_joints(pose_to_joint_state_msg(q, header(2)))
        h.settle(0.3)
        assert not joys
    with pytest.raises(StartupError):
        with running(_node(press_deg=[10.0, 10.0], release_deg=[20.0, 5.0])):
            pass
