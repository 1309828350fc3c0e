"""two_hands_node in one process over DDS on loopback: a frame with a left and a right glove in,
each hand's joint states (prefixed names), wrist pose and status out under hand/<hand>/; a frame
of the wrong size gives both hands a 'no hand' status and no pose."""
from __future__ import annotations

import numpy as np
import pytest
from geometry_msgs.msg import PoseStamped
from node_fixtures import header, params, running
from sensor_msgs.msg import Image, JointState
from std_msgs.msg import String

from colorglove_ros.core.hand.frames import finger_joint_names
from colorglove_ros.core.hand.handedness import HANDS
from colorglove_ros.core.synthetic.conditions import sample_conditions
from colorglove_ros.core.synthetic.frames import Synthesizer, default_camera
from colorglove_ros.core.synthetic.sequences import two_hand_sequences
from colorglove_ros.ros.image import array_to_image
from colorglove_ros.ros.nodes.two_hands_node import TwoHandsNode, hand_topic

pytestmark = [pytest.mark.dds, pytest.mark.usefixtures('isolated_ros_domain')]


def _two_hand_frame() -> tuple[np.ndarray, dict[str, np.ndarray]]:
    camera = default_camera()
    synth = Synthesizer()
    try:
        poses = {h: q[0] for h, q in two_hand_sequences(3, 1, camera=camera,
                                                         model=synth.model).items()}
        frame, _ = synth.render_hands([(poses[h], h) for h in HANDS], camera,
                                      np.random.default_rng(5),
                                      sample_conditions(np.random.default_rng(5), 'test'))
    finally:
        synth.release()
    return frame.image_rgb, poses


@pytest.mark.parametrize('threads', [2, 1])
def test_two_hands_node_publishes_each_hand_under_its_namespace(node_assets, threads) -> None:
    rgb, truth = _two_hand_frame()
    with running(lambda ctx: TwoHandsNode(context=ctx, parameter_overrides=params(
            color_calibration_file=str(node_assets.color_config),
            database_path=str(node_assets.database), threads=threads))) as h:
        assert h.nodes[0].pipeline.parallel == (threads == 2)
        h.nodes[0].page_cache_reader.join(10.0)        # the database read into the page cache
        assert not h.nodes[0].page_cache_reader.is_alive()
        joints = {hand: h.collect(JointState, hand_topic(hand, 'joint_states')) for hand in HANDS}
        wrists = {hand: h.collect(PoseStamped, hand_topic(hand, 'wrist_pose')) for hand in HANDS}
        status = {hand: h.collect(String, hand_topic(hand, 'tracking_status')) for hand in HANDS}
        pub = h.publisher(Image, 'camera/image_raw')
        pub.publish(array_to_image(rgb, 'rgb8', header(7, 5)))
        assert h.spin_until(lambda: all(status.values()), 60.0)
        h.settle(0.3)
        tracked = [hand for hand in HANDS if status[hand][0].data.startswith('tracking')]
        for hand in HANDS:       # a pose, or no pose and the reason: never both, never neither
            assert len(status[hand]) == 1
            assert len(joints[hand]) == len(wrists[hand]) == (hand in tracked), \
                status[hand][0].data
        for hand in tracked:
            msg, wrist = joints[hand][0], wrists[hand][0]
            assert list(msg.name) == finger_joint_names(f'{hand}_')
            assert (msg.header.stamp.sec, msg.header.stamp.nanosec) == (7, 5)
            # each pose is its own hand's: the wrist nearer its own hand's than the other's
            p = np.array([wrist.pose.position.x, wrist.pose.position.y, wrist.pose.position.z])
            other = 'left' if hand == 'right' else 'right'
            assert np.linalg.norm(p - truth[hand][:3]) < np.linalg.norm(p - truth[other][:3])
        for hand in HANDS:
            if hand not in tracked:
                assert status[hand][0].data.startswith('no hand: ')
        # a frame of another size: both hands say why, neither gets a pose
        pub.publish(array_to_image(rgb[:240, :320].copy(), 'rgb8', header(8)))
        assert h.spin_until(lambda: all(len(s) == 2 for s in status.values()), 20.0)
        h.settle(0.3)
        for hand in HANDS:
            assert status[hand][1].data.startswith('no hand: camera: image 320x240')
            assert len(joints[hand]) == (hand in tracked)


def test_two_hands_node_reads_frames_serialized_and_runs_opencv_in_its_own_threads(
        node_assets) -> None:
    """Frames come serialized (the pixels read in place, no Python message): one of another
    size gives both hands its reason, bytes that are no image are logged and answered with
    nothing; OpenCV runs in the calling threads (``opencv_threads``, as the one-hand nodes)."""
    import cv2
    from rclpy.serialization import serialize_message

    from colorglove_ros.ros.nodes.common import OPENCV_THREADS

    rgb, _ = _two_hand_frame()
    before = cv2.getNumThreads()
    try:
        cv2.setNumThreads(2)
        with running(lambda ctx: TwoHandsNode(context=ctx, parameter_overrides=params(
                color_calibration_file=str(node_assets.color_config),
                database_path=str(node_assets.database)))) as h:
            node = h.nodes[0]
            assert node.get_parameter('opencv_threads').value == OPENCV_THREADS
            assert cv2.getNumThreads() == OPENCV_THREADS
            status = {hand: h.collect(String, hand_topic(hand, 'tracking_status'))
                      for hand in HANDS}
            h.settle(0.3)
            node.on_serialized_image(b'\x00\x07 not an image')
            node.on_serialized_image(serialize_message(
                array_to_image(rgb[:240, :320].copy(), 'rgb8', header(8))))
            assert h.spin_until(lambda: all(status.values()), 20.0)
            h.settle(0.3)
            for hand in HANDS:
                assert [s.data for s in status[hand]] == [
                    'no hand: camera: image 320x240, calibrated 640x480']
    finally:
        cv2.setNumThreads(before)
