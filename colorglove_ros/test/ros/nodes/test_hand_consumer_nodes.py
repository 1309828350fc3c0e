"""keypoints_node, gesture_node and spelling_node in one process over DDS on loopback: tracker
outputs in, their outputs checked against the core modules run directly."""
from __future__ import annotations

import time

import numpy as np
import pytest
from colorglove_msgs.msg import GestureEvent as GestureEventMsg
from geometry_msgs.msg import PoseArray, PoseStamped
from node_fixtures import header, params, running
from pose_samples import MODEL, hand_pose
from sensor_msgs.msg import JointState
from std_msgs.msg import String

from colorglove_ros.core.hand.frames import finger_joint_names
from colorglove_ros.core.hand.keypoints import hand_keypoints
from colorglove_ros.core.hand.poses import GESTURE_SHAPES, LETTER_SHAPES
from colorglove_ros.core.hand.spelling import letter_rotation
from colorglove_ros.ros.conversions import pose_to_joint_state_msg, pose_to_wrist_pose_msg
from colorglove_ros.ros.nodes.gesture_node import GestureNode
from colorglove_ros.ros.nodes.keypoints_node import KeypointsNode
from colorglove_ros.ros.nodes.spelling_node import SpellingNode

pytestmark = [pytest.mark.dds, pytest.mark.usefixtures('isolated_ros_domain')]

def _pose(fingers: np.ndarray, rotvec=(0.3, -0.2, 0.4)) -> np.ndarray:
    return hand_pose(fingers, np.array([0.05, 0.02, 0.5, *rotvec]))


def _frame(k: int, frame_id: str = 'cam_a'):
    return header(100 + k // 30, int((k % 30) * 1e9 / 30), frame_id)


def test_keypoints_node_publishes_both_frames() -> None:
    q = _pose(GESTURE_SHAPES['relaxed'])
    with running(lambda ctx: KeypointsNode(context=ctx, parameter_overrides=params(
            hand_frame='right_palm'))) as h:
        camera = h.collect(PoseArray, 'hand/keypoints')
        wrist = h.collect(PoseArray, 'hand/keypoints_wrist')
        joints_pub = h.publisher(JointState, 'hand/joint_states')
        wrist_pub = h.publisher(PoseStamped, 'hand/wrist_pose')
        joints_pub.publish(pose_to_joint_state_msg(q, _frame(3)))
        h.settle(0.3)
        assert camera == []                       # half a frame: nothing yet
        wrist_pub.publish(pose_to_wrist_pose_msg(q, _frame(3)))
        assert h.spin_until(lambda: camera and wrist, 10.0)
    expected_camera = hand_keypoints(MODEL, q, 'camera').positions
    expected_wrist = hand_keypoints(MODEL, q, 'wrist').positions
    for msg, expected, frame in ((camera[0], expected_camera, 'cam_a'),
                                 (wrist[0], expected_wrist, 'right_palm')):
        assert msg.header.frame_id == frame
        assert (msg.header.stamp.sec, msg.header.stamp.nanosec) == (100, int(3e9 / 30))
        got = np.array([[p.position.x, p.position.y, p.position.z] for p in msg.poses])
        np.testing.assert_allclose(got, expected, atol=1e-9)
        norms = [np.linalg.norm([p.orientation.x, p.orientation.y, p.orientation.z,
                                 p.orientation.w]) for p in msg.poses]
        np.testing.assert_allclose(norms, 1.0, atol=1e-9)


def test_gesture_node_events_and_loss() -> None:
    with running(lambda ctx: GestureNode(context=ctx, parameter_overrides=params(
            frame_prefix='left_', hand='left', lose_after_s=0.5))) as h:
        events = h.collect(String, 'hand/gesture_events')
        messages = h.collect(GestureEventMsg, 'hand/gestures')
        joints_pub = h.publisher(JointState, 'hand/joint_states')
        status_pub = h.publisher(String, 'hand/tracking_status')
        for k in range(10):
            joints_pub.publish(pose_to_joint_state_msg(_pose(GESTURE_SHAPES['flat']), _frame(k),
                                                       finger_joint_names('left_')))
        assert h.spin_until(lambda: len(events) >= 1 and len(messages) >= 1, 10.0)
        # a loss shorter than lose_after_s (0.5 s here) ends nothing; a longer one does
        for _ in range(3):
            status_pub.publish(String(data='no hand: lost'))
            h.settle(0.05)
        h.settle(0.3)
        assert len(events) == 1
        for k in range(10, 13):       # the hand back: the loss starts anew
            joints_pub.publish(pose_to_joint_state_msg(_pose(GESTURE_SHAPES['flat']), _frame(k),
                                                       finger_joint_names('left_')))
        h.settle(0.3)
        lost_at = time.monotonic()
        while len(events) < 2 and time.monotonic() - lost_at < 10.0:
            status_pub.publish(String(data='no hand: lost'))
            h.settle(0.05)
        assert len(events) >= 2 and h.spin_until(lambda: len(messages) >= 2, 5.0)
        assert time.monotonic() - lost_at >= 0.45
    name, state, confidence = events[0].data.split(':')
    assert (name, state) == ('open_hand', 'start') and float(confidence) >= 0.7
    assert events[1].data == 'open_hand:end:0.00'
    start, end = messages[0], messages[1]
    assert (start.hand, start.gesture, start.event) == ('left', GestureEventMsg.OPEN_HAND,
                                                        GestureEventMsg.START)
    assert start.header.frame_id == 'left_palm'
    assert start.confidence == pytest.approx(float(confidence), abs=0.005)
    # the start was decided on one of the published frames, and carries its stamp
    assert start.header.stamp.sec == 100 and start.header.stamp.nanosec in {
        int(k * 1e9 / 30) for k in range(10)}
    assert (end.gesture, end.event, end.confidence) == ('open_hand', GestureEventMsg.END, 0.0)


def test_gesture_node_text_events_can_be_turned_off() -> None:
    with running(lambda ctx: GestureNode(context=ctx, parameter_overrides=params(
            publish_text_events=False))) as h:
        events = h.collect(String, 'hand/gesture_events')
        messages = h.collect(GestureEventMsg, 'hand/gestures')
        joints_pub = h.publisher(JointState, 'hand/joint_states')
        for k in range(10):
            joints_pub.publish(pose_to_joint_state_msg(_pose(GESTURE_SHAPES['fist']), _frame(k)))
        assert h.spin_until(lambda: len(messages) >= 1, 10.0)
        h.settle(0.3)
    assert messages[0].gesture == 'grab' and messages[0].hand == 'right'
    assert events == []


def test_gesture_node_skips_frames_of_weak_tracking_evidence() -> None:
    """With evidence_min_constraints set, frames after a status line with fewer constraints
    start nothing; after a status line with enough they do."""
    from colorglove_ros.core.hand.frame_evidence import tracking_status

    with running(lambda ctx: GestureNode(context=ctx, parameter_overrides=params(
            evidence_min_constraints=11.0))) as h:
        events = h.collect(String, 'hand/gesture_events')
        joints_pub = h.publisher(JointState, 'hand/joint_states')
        status_pub = h.publisher(String, 'hand/tracking_status')
        status_pub.publish(String(data=tracking_status(6, 'cam0 6', 2.0, 3.0)))
        h.settle(0.3)
        for k in range(10):
            joints_pub.publish(pose_to_joint_state_msg(_pose(GESTURE_SHAPES['fist']), _frame(k)))
        h.settle(0.5)
        assert events == []
        status_pub.publish(String(data=tracking_status(15, 'cam0 15', 2.0, 3.0)))
        h.settle(0.3)
        for k in range(10, 20):
            joints_pub.publish(pose_to_joint_state_msg(_pose(GESTURE_SHAPES['fist']), _frame(k)))
        assert h.spin_until(lambda: len(events) >= 1, 10.0)
    assert events[0].data.startswith('grab:start')


def test_gesture_node_gates_each_frame_on_its_own_status_line() -> None:
    """ik_node publishes a frame's status line after its JointState: each frame is gated by
    its own line (same stamp), not by the newest line the node has (the previous frame's).
    Frames 0-11 have weak lines, frames 12-23 strong ones: the start comes on the frame the
    core detector, given each frame's own evidence, starts it on."""
    from colorglove_ros.core.hand.frame_evidence import EvidenceGate, FrameEvidence, tracking_status
    from colorglove_ros.core.hand.gestures import (
        DEFAULT_GESTURE_CLASSIFIER,
        GESTURE_FEATURES,
        GestureConfig,
        GestureDetector,
    )
    from colorglove_ros.core.hand.pose_classifier import load_pose_classifier
    from colorglove_ros.paths import share_dir

    q = _pose(GESTURE_SHAPES['fist'])
    constraints = [6 if k < 12 else 15 for k in range(24)]
    detector = GestureDetector(MODEL, GestureConfig(evidence=EvidenceGate(min_constraints=11.0)),
                               load_pose_classifier(share_dir() / DEFAULT_GESTURE_CLASSIFIER,
                                                    GESTURE_FEATURES))
    expected = next(k for k, n in enumerate(constraints) if detector.update(
        q, 100 + k / 30, FrameEvidence(float(n), 2.0)))
    with running(lambda ctx: GestureNode(context=ctx, parameter_overrides=params(
            evidence_min_constraints=11.0))) as h:
        messages = h.collect(GestureEventMsg, 'hand/gestures')
        joints_pub = h.publisher(JointState, 'hand/joint_states')
        status_pub = h.publisher(String, 'hand/tracking_status')
        h.settle(0.3)
        for k, n in enumerate(constraints):
            stamp = _frame(k).stamp
            joints_pub.publish(pose_to_joint_state_msg(q, _frame(k)))
            h.settle(0.05)
            status_pub.publish(String(data=tracking_status(
                n, f'cam0 {n}', 2.0, 3.0, (stamp.sec, stamp.nanosec))))
            h.settle(0.05)
        assert h.spin_until(lambda: len(messages) >= 1, 10.0)
    start = messages[0]
    assert (start.gesture, start.event) == ('grab', GestureEventMsg.START)
    assert (start.header.stamp.sec, start.header.stamp.nanosec) == \
        (_frame(expected).stamp.sec, _frame(expected).stamp.nanosec), expected


def test_spelling_node_commits_held_letters() -> None:
    with running(lambda ctx: SpellingNode(context=ctx)) as h:
        letters = h.collect(String, 'hand/spelled_letters')
        text = h.collect(String, 'hand/spelled_text')
        joints_pub = h.publisher(JointState, 'hand/joint_states')
        wrist_pub = h.publisher(PoseStamped, 'hand/wrist_pose')
        k = 0
        for letter in 'GO':
            q = _pose(LETTER_SHAPES[letter], letter_rotation(letter))
            for _ in range(30):
                joints_pub.publish(pose_to_joint_state_msg(q, _frame(k)))
                wrist_pub.publish(pose_to_wrist_pose_msg(q, _frame(k)))
                h.settle(0.005)
                k += 1
        assert h.spin_until(lambda: len(text) >= 2, 10.0)
    assert [m.data for m in letters] == ['G', 'O']
    assert text[-1].data == 'GO'


def _observation(k: int, tiny: np.ndarray) -> object:
    """Frame ``k``'s HandObservation of a found hand with the tiny label image ``tiny``."""
    from array import array

    from colorglove_msgs.msg import HandObservation

    return HandObservation(
        header=_frame(k), hand_found=True, image_width=640, image_height=480,
        tiny_labels=array('B', tiny.tobytes()), crop_scale=4.0, crop_offset_x=100.0,
        crop_offset_y=80.0, blob_colors=array('B', [1]), blob_centroids=array('d', [220.0, 180.0]),
        blob_pixel_counts=array('I', [1024]))


def test_spelling_node_reads_each_poses_own_observation_with_an_image_classifier(tmp_path
                                                                                 ) -> None:
    """With an image_classifier_file the node subscribes to hand/observation and gives each
    pose the observation of its stamp: G poses whose tiny images an image classifier reads as
    S (weighted far above the pose) commit S; the node without one ('') commits G."""
    from colorglove_msgs.msg import HandObservation

    from colorglove_ros.core.hand.observation_features import (
        OBSERVATION_FEATURES,
        num_observation_features,
    )
    from colorglove_ros.core.hand.pose_classifier import (
        save_pose_classifier,
        train_pose_classifier,
    )
    from colorglove_ros.core.hand.spelling import LETTERS

    rng = np.random.default_rng(0)
    x = rng.normal(0.0, 0.05, (26 * 20, num_observation_features()))
    y = np.repeat(np.array(LETTERS), 20)
    for k, letter in enumerate(LETTERS):
        x[y == letter, k] += 1.0             # letter k: colour 1 fills grid cell k
    path = save_pose_classifier(tmp_path / 'image.npz', train_pose_classifier(
        x, y, OBSERVATION_FEATURES, kind='lda'))
    tiny = np.zeros((40, 40), np.uint8)
    cell = LETTERS.index('S')
    tiny[8 * (cell // 5):8 * (cell // 5) + 8, 8 * (cell % 5):8 * (cell % 5) + 8] = 1
    q = _pose(LETTER_SHAPES['G'], letter_rotation('G'))
    got = {}
    for name, overrides in (('image', params(image_classifier_file=str(path),
                                             image_weight=20.0)),
                            ('pose', params(image_classifier_file=''))):
        with running(lambda ctx, o=overrides: SpellingNode(context=ctx,
                                                           parameter_overrides=o)) as h:
            letters = h.collect(String, 'hand/spelled_letters')
            observation_pub = h.publisher(HandObservation, 'hand/observation')
            joints_pub = h.publisher(JointState, 'hand/joint_states')
            wrist_pub = h.publisher(PoseStamped, 'hand/wrist_pose')
            h.settle(0.3)
            for k in range(30):
                observation_pub.publish(_observation(k, tiny))
                h.settle(0.005)
                joints_pub.publish(pose_to_joint_state_msg(q, _frame(k)))
                wrist_pub.publish(pose_to_wrist_pose_msg(q, _frame(k)))
                h.settle(0.005)
            assert h.spin_until(lambda seen=letters: len(seen) >= 1, 10.0)
            got[name] = [m.data for m in letters]
    assert got == {'image': ['S'], 'pose': ['G']}


def test_gesture_node_reads_each_poses_own_observation_with_an_image_classifier(tmp_path
                                                                                ) -> None:
    """With an image_classifier_file the gesture node subscribes to hand/observation and
    gives each pose the observation of its stamp: pointing poses whose tiny images an image
    classifier reads as an open hand (weighted far above the pose) start the open hand; the
    node without one ('', the default) starts the point. (Not a pinch read into an open hand:
    the core's shape gate refuses a pinch whose thumb tip is far from the fingertip.)"""
    from colorglove_msgs.msg import HandObservation

    from colorglove_ros.core.hand.gestures import GESTURE_NAMES, NO_GESTURE
    from colorglove_ros.core.hand.observation_features import (
        OBSERVATION_FEATURES,
        num_observation_features,
    )
    from colorglove_ros.core.hand.pose_classifier import (
        save_pose_classifier,
        train_pose_classifier,
    )

    classes = (*GESTURE_NAMES, NO_GESTURE)
    rng = np.random.default_rng(0)
    x = rng.normal(0.0, 0.05, (len(classes) * 20, num_observation_features()))
    y = np.repeat(np.array(classes), 20)
    for k, c in enumerate(classes):
        x[y == c, k] += 1.0                 # class k: colour 1 fills grid cell k
    path = save_pose_classifier(tmp_path / 'image.npz', train_pose_classifier(
        x, y, OBSERVATION_FEATURES, kind='lda'))
    tiny = np.zeros((40, 40), np.uint8)
    cell = classes.index('open_hand')
    tiny[8 * (cell // 5):8 * (cell // 5) + 8, 8 * (cell % 5):8 * (cell % 5) + 8] = 1
    q = _pose(GESTURE_SHAPES['point'])
    got = {}
    for name, overrides in (('image', params(image_classifier_file=str(path),
                                             image_weight=20.0)),
                            ('pose', params())):
        with running(lambda ctx, o=overrides: GestureNode(context=ctx,
                                                          parameter_overrides=o)) as h:
            events = h.collect(String, 'hand/gesture_events')
            observation_pub = h.publisher(HandObservation, 'hand/observation')
            joints_pub = h.publisher(JointState, 'hand/joint_states')
            h.settle(0.3)
            for k in range(15):
                observation_pub.publish(_observation(k, tiny))
                h.settle(0.005)
                joints_pub.publish(pose_to_joint_state_msg(q, _frame(k)))
                h.settle(0.005)
            assert h.spin_until(lambda seen=events: len(seen) >= 1, 10.0)
            got[name] = events[0].data.split(':')[:2]
    assert got == {'image': ['open_hand', 'start'], 'pose': ['point', 'start']}
