"""edge_tracker_node in one process: rendered bare-hand images in, pose or reason out."""
from __future__ import annotations

import contextlib
import math
from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np
import pytest
from geometry_msgs.msg import PoseStamped
from node_fixtures import Harness, header, params, running
from sensor_msgs.msg import JointState
from std_msgs.msg import String

from colorglove_ros.core.hand.model import DOF_NAMES
from colorglove_ros.core.synthetic.bare_hand import BareHandSequence
from colorglove_ros.core.synthetic.frames import default_camera
from colorglove_ros.ros.conversions import pose_to_joint_state_msg, pose_to_wrist_pose_msg
from colorglove_ros.ros.image import array_to_image
from colorglove_ros.ros.nodes.common import StartupError
from colorglove_ros.ros.nodes.edge_tracker_node import EdgeTrackerNode

pytestmark = [pytest.mark.dds, pytest.mark.usefixtures('isolated_ros_domain')]


@pytest.fixture(scope='module')
def sequence():
    seq = BareHandSequence(default_camera(), seed=5, num_frames=30, hold_frames=10)
    frames = {i: seq.render(i).image_rgb for i in (0, 20, 21)}
    yield seq, frames
    seq.close()


def _node(**overrides):
    values = {'calibration_file': 'config/calibration.yaml', 'init_hold_frames': 2, **overrides}
    return lambda ctx: EdgeTrackerNode(context=ctx, parameter_overrides=params(**values))


@dataclass
class _Outputs:
    """What edge_tracker_node publishes, collected as it arrives."""

    joints: list[JointState]
    wrists: list[PoseStamped]
    status: list[String]


@contextlib.contextmanager
def _tracker() -> Iterator[tuple[Harness, EdgeTrackerNode, _Outputs]]:
    """edge_tracker_node (defaults of :func:`_node`) running, with its outputs collected."""
    with running(_node()) as h:
        yield h, h.nodes[0], _Outputs(h.collect(JointState, 'hand/joint_states'),
                                      h.collect(PoseStamped, 'hand/wrist_pose'),
                                      h.collect(String, 'hand/tracking_status'))


def _position(msg: PoseStamped) -> np.ndarray:
    point = msg.pose.position
    return np.array([point.x, point.y, point.z])


def test_holds_then_publishes_the_pose_with_urdf_names(sequence) -> None:
    seq, frames = sequence
    with _tracker() as (h, node, out):
        joints, wrists, status = out.joints, out.wrists, out.status
        for k in range(2):
            msg = array_to_image(frames[0], 'rgb8', header(10 + k, 0, 'camera_optical_frame'))
            node.on_image(0, msg)
        assert h.spin_until(lambda: len(joints) >= 1 and len(status) >= 2, 10.0)
        assert status[0].data.startswith('no hand: waiting for the initialisation pose')
        assert status[1].data.startswith('tracking')
        names = list(joints[0].name)
        assert names == [n for n in names if n in set(names)] and len(names) >= 20
        assert not any(n in DOF_NAMES[:6] for n in names)
        assert np.linalg.norm(_position(wrists[0]) - seq.poses[0][0:3]) < 0.01
        # a given starting pose, then a moving frame
        node.on_init_wrist(pose_to_wrist_pose_msg(seq.poses[20], header(20)))
        node.on_init_joints(pose_to_joint_state_msg(seq.poses[20], header(20)))
        node.on_image(0, array_to_image(frames[21], 'rgb8', header(21)))
        assert h.spin_until(lambda: len(wrists) >= 2, 10.0)
        assert np.linalg.norm(_position(wrists[-1]) - seq.poses[21][0:3]) < 0.01


def test_blank_frames_give_reasons_not_poses(sequence) -> None:
    _, frames = sequence
    with _tracker() as (h, node, out):
        node.on_image(0, array_to_image(np.full_like(frames[0], 80), 'rgb8', header(1)))
        assert h.spin_until(lambda: len(out.status) >= 1, 10.0)
        h.settle(0.2)
        assert not out.joints and 'no hand' in out.status[0].data
        assert node.stats.frames == 1 and node.stats.frames_with_hand == 0   # diagnostics


def test_two_topics_without_calibration_refuse_to_start() -> None:
    with pytest.raises(StartupError):
        with running(_node(calibration_file='', image_topics=['a', 'b'])):
            pass
    with pytest.raises(StartupError):
        with running(_node(calibration_file='config/calibration_stereo.yaml')):
            pass


def test_camera_check_parameters_reach_the_tracker() -> None:
    with running(_node(calibration_file='config/calibration_stereo.yaml',
                       image_topics=['left/image_raw', 'right/image_raw'], camera_check=True,
                       max_camera_disagreement_mm=15.0)) as h:
        config = h.nodes[0].config
    assert config.camera_check and config.max_camera_disagreement_mm == 15.0


def test_silhouette_palm_parameter_reaches_the_tracker() -> None:
    with running(_node(silhouette_palm=False)) as h:
        assert not h.nodes[0].config.silhouette_palm
    with running(_node(silhouette_palm=True)) as h:
        assert h.nodes[0].config.silhouette_palm


def test_the_node_refits_fingers_and_pulls_the_palm_by_default() -> None:
    with running(_node()) as h:
        assert h.nodes[0].config.finger_refit and h.nodes[0].config.silhouette_palm
    with running(_node(finger_refit=False)) as h:
        assert not h.nodes[0].config.finger_refit


def test_the_measurement_rounds_and_fault_round_parameters_reach_the_tracker() -> None:
    with running(_node(measurement_rounds=3, fault_round=False)) as h:
        config = h.nodes[0].config
        assert config.measurement_rounds == 3 and not config.fault_round
    with running(_node(measurement_rounds=1, fault_round=True)) as h:
        config = h.nodes[0].config
        assert config.measurement_rounds == 1 and config.fault_round


def test_the_finger_refit_and_round_gate_parameters_reach_the_tracker() -> None:
    with running(_node(finger_refit_dofs='digit', finger_refit_abduction='spread',
                       finger_refit_spread_deg=5.0, round_min_move_px=4.0)) as h:
        config = h.nodes[0].config
    assert (config.finger_refit_dofs, config.finger_refit_abduction,
            config.finger_refit_spread_deg, config.round_min_move_px) \
        == ('digit', 'spread', 5.0, 4.0)
    with pytest.raises(StartupError, match='finger_refit_dofs'):
        with running(_node(finger_refit_dofs='wrist')):
            pass


def test_the_node_defaults_are_the_tracker_defaults() -> None:
    """The node's parameters default to EdgeTrackerConfig's (one home for each default)."""
    from colorglove_ros.core.tracking.edge_fit import EdgeTrackerConfig

    with running(_node()) as h:
        config = h.nodes[0].config
    defaults = EdgeTrackerConfig()
    for name in ('finger_refit', 'silhouette_palm', 'measurement_rounds', 'fault_round',
                 'finger_refit_dofs', 'finger_refit_abduction', 'finger_refit_spread_deg',
                 'round_min_move_px', 'max_finger_off_silhouette',
                 'max_finger_unexplained', 'max_unexplained', 'silhouette_weight',
                 'retry_dofs', 'retry_step_deg', 'retry_max_wrist_move_m',
                 'retry_rest_margin_px'):
        assert getattr(config, name) == getattr(defaults, name), name


def test_retry_parameters_reach_the_tracker() -> None:
    with running(_node(retry_dofs=['thumb_cmc_abd'], retry_step_deg=15.0)) as h:
        config = h.nodes[0].config
    assert config.retry_dofs == ('thumb_cmc_abd',) and config.retry_step_deg == 15.0


def test_the_retry_guards_reach_the_tracker_and_0_is_a_rest_margin() -> None:
    with running(_node(retry_max_wrist_move_m=0.005, retry_rest_margin_px=0.0)) as h:
        config = h.nodes[0].config
    assert config.retry_max_wrist_move_m == 0.005 and config.retry_rest_margin_px == 0.0
    with running(_node(retry_max_wrist_move_m=0.0, retry_rest_margin_px=-1.0)) as h:
        config = h.nodes[0].config
    assert config.retry_max_wrist_move_m == math.inf and config.retry_rest_margin_px == math.inf


def test_max_finger_off_silhouette_parameter_reaches_the_tracker() -> None:
    with running(_node(max_finger_off_silhouette=0.3)) as h:
        assert h.nodes[0].config.max_finger_off_silhouette == 0.3


def test_background_images_give_the_tracker_silhouettes(tmp_path, sequence) -> None:
    import cv2

    seq, frames = sequence
    empty = seq.render_empty_views([default_camera()])[0]
    path = tmp_path / 'empty.png'
    cv2.imwrite(str(path), empty[..., ::-1])
    with running(_node(background_images=[str(path)], silhouette_weight=0.3,
                       max_unexplained=0.2, silhouette_threshold=25.0)) as h:
        tracker = h.nodes[0].tracker
        assert tracker.config.silhouette_weight == 0.3 and tracker.config.max_unexplained == 0.2
        (background,) = tracker.backgrounds
        assert background.config.threshold == 25.0
        assert np.abs(background.mean.astype(float) - cv2.resize(
            empty, background.mean.shape[1::-1], interpolation=cv2.INTER_AREA)).max() < 1.0
        silhouette = background.silhouette(frames[20])
        assert silhouette.area_px > 3000
    with pytest.raises(StartupError):
        with running(_node(background_images=[str(path), str(path)])):
            pass
    with pytest.raises(StartupError):
        with running(_node(background_images=[str(tmp_path / 'missing.png')])):
            pass


@pytest.mark.parametrize('threads', [None, 2])
def test_the_node_runs_opencv_in_the_calling_thread_by_default(threads) -> None:
    """``opencv_threads`` (default ``OPENCV_THREADS``, as the glove nodes) reaches the process."""
    import cv2

    from colorglove_ros.core.opencv_threads import OPENCV_THREADS

    before = cv2.getNumThreads()
    try:
        cv2.setNumThreads(3)
        overrides = {} if threads is None else {'opencv_threads': threads}
        with running(_node(**overrides)) as h:
            assert h.nodes[0].get_parameter('opencv_threads').value == (threads or OPENCV_THREADS)
            assert cv2.getNumThreads() == (threads or OPENCV_THREADS)
    finally:
        cv2.setNumThreads(before)
