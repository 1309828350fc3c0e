"""The glove pipeline nodes take camera 0's intrinsics from its CameraInfo (use_camera_info):
a frame at another resolution with a matching CameraInfo is tracked at the same depth, and a
frame whose size or frame_id does not match its CameraInfo (or, without CameraInfo, the
calibration) is refused with 'no hand: camera: ...', never tracked with the wrong camera."""
from __future__ import annotations

import copy
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from colorglove_msgs.msg import HandObservation, HandPoseCandidates
from geometry_msgs.msg import PoseStamped
from node_fixtures import (
    NodeAssets,
    header,
    ik_node,
    lookup_node,
    running,
    segmentation_node,
)
from rclpy.qos import QoSProfile, qos_profile_sensor_data
from repo_paths import CONFIG_DIR
from sensor_msgs.msg import CameraInfo, Image, JointState
from std_msgs.msg import String

from colorglove_ros.core.camera import PinholeCamera, load_calibration
from colorglove_ros.ros.conversions import camera_to_camera_info_msg
from colorglove_ros.ros.image import array_to_image

pytestmark = [pytest.mark.dds, pytest.mark.usefixtures('isolated_ros_domain')]

CAMERA = load_calibration(CONFIG_DIR / 'calibration.yaml').primary


def _scaled(camera: PinholeCamera, factor: int) -> PinholeCamera:
    """``camera`` for images ``factor`` times as large (pixel-repeated)."""
    return replace(camera, width=camera.width * factor, height=camera.height * factor,
                   fx=camera.fx * factor, fy=camera.fy * factor,
                   cx=camera.cx * factor, cy=camera.cy * factor)


def _upscaled(rgb: np.ndarray, factor: int) -> np.ndarray:
    return np.ascontiguousarray(np.repeat(np.repeat(rgb, factor, axis=0), factor, axis=1))


def _pipeline(assets: NodeAssets, database: Path, use_camera_info: bool = True) -> list:
    return [segmentation_node(assets, use_camera_info=use_camera_info),
            lookup_node(assets, use_camera_info=use_camera_info),
            ik_node(database, use_camera_info=use_camera_info, publish_overlay=False)]


def _run_frame(assets: NodeAssets, database: Path, rgb: np.ndarray,
               info: PinholeCamera | None, frame_id: str = CAMERA.frame_id,
               use_camera_info: bool = True, info_qos: QoSProfile | int = 10):
    """Send ``info`` (as CameraInfo with ``info_qos``, unless None) then one image through
    segmentation -> lookup -> IK; return (status line, joint states, wrist poses, lookup
    candidates, the nodes)."""
    with running(*_pipeline(assets, database, use_camera_info)) as h:
        status = h.collect(String, 'hand/tracking_status')
        joints = h.collect(JointState, 'hand/joint_states')
        wrist = h.collect(PoseStamped, 'hand/wrist_pose')
        candidates = h.collect(HandPoseCandidates, 'hand/pose_candidates')
        image_pub = h.publisher(Image, 'camera/image_raw')
        if info is not None:
            info_pub = h.probe.create_publisher(CameraInfo, 'camera/camera_info', info_qos)
            assert h.spin_until(lambda: info_pub.get_subscription_count() >= 3, 10.0)
            info_pub.publish(camera_to_camera_info_msg(info, header(50, 0, info.frame_id)))
            h.settle(0.3)
        assert h.spin_until(lambda: h.probe.count_subscribers('hand/pose_candidates') >= 1,
                            10.0)
        line = h.exchange(image_pub, array_to_image(rgb, 'rgb8', header(51, 0, frame_id)),
                          status, timeout=30.0)
        h.settle(0.3)
        return line.data, list(joints), list(wrist), list(candidates), h.nodes


def test_same_hand_at_twice_the_resolution_is_tracked_at_the_same_depth(
        node_assets: NodeAssets, small_database_path: Path, good_rgb: np.ndarray) -> None:
    status_640, _, wrist_640, lookup_640, _ = _run_frame(node_assets, small_database_path,
                                                         good_rgb, CAMERA)
    status_1280, joints, wrist_1280, lookup_1280, nodes = _run_frame(
        node_assets, small_database_path, _upscaled(good_rgb, 2), _scaled(CAMERA, 2))
    assert status_640.startswith('tracking:'), status_640
    assert status_1280.startswith('tracking:'), status_1280
    assert len(joints) == 1 and len(wrist_640) == len(wrist_1280) == 1
    # the IK ran with the CameraInfo's camera, not the calibration's 640x480 one
    assert nodes[2].tracker.cameras[0].width == 1280
    # the lookup's depth (crop size and focal length): the calibration's 640x480 intrinsics
    # would put the doubled image's hand at about half the depth
    z_lookup_640, z_lookup_1280 = lookup_640[0].blended_pose[2], lookup_1280[0].blended_pose[2]
    assert 0.2 < z_lookup_640 < 1.0
    assert abs(z_lookup_1280 - z_lookup_640) < 0.005, (z_lookup_640, z_lookup_1280)
    # the IK's wrist: same scale, not the same value (its pixel-unit settings, r_std_px,
    # outlier_px and the gates, and the blobs the segmenter keeps depend on the resolution)
    z_640, z_1280 = wrist_640[0].pose.position.z, wrist_1280[0].pose.position.z
    assert 0.8 < z_1280 / z_640 < 1.25, (z_640, z_1280)


def test_camera_info_from_a_sensor_data_driver_is_used(
        node_assets: NodeAssets, small_database_path: Path, good_rgb: np.ndarray) -> None:
    """A driver publishing CameraInfo best effort (sensor-data QoS) reaches all three nodes:
    a reliable reader would never connect to it."""
    status, joints, _, _, nodes = _run_frame(node_assets, small_database_path,
                                             _upscaled(good_rgb, 2), _scaled(CAMERA, 2),
                                             info_qos=qos_profile_sensor_data)
    assert status.startswith('tracking:'), status
    assert len(joints) == 1 and nodes[2].tracker.cameras[0].width == 1280


@pytest.mark.parametrize('size_factor, frame_id, reason', [
    (2, CAMERA.frame_id, 'camera: image 1280x960 but CameraInfo says 640x480'),
    (1, 'another_camera', "camera: frame_id 'another_camera' != CameraInfo frame_id"),
], ids=['size', 'frame_id'])
def test_frame_not_matching_its_camera_info_is_refused(
        node_assets: NodeAssets, small_database_path: Path, good_rgb: np.ndarray,
        size_factor: int, frame_id: str, reason: str) -> None:
    status, joints, wrist, _, nodes = _run_frame(node_assets, small_database_path,
                                                 _upscaled(good_rgb, size_factor), CAMERA,
                                                 frame_id=frame_id)
    assert status.startswith(f'no hand: {reason}'), status
    assert joints == [] and wrist == []
    kind = 'size' if size_factor != 1 else 'frame_id'
    assert nodes[0].frame_camera.refused == {kind: 1}


def test_without_camera_info_a_frame_of_another_size_is_refused(
        node_assets: NodeAssets, small_database_path: Path, good_rgb: np.ndarray) -> None:
    status, joints, wrist, _, nodes = _run_frame(node_assets, small_database_path,
                                                 _upscaled(good_rgb, 2), None,
                                                 use_camera_info=False)
    assert status == 'no hand: camera: image 1280x960 but calibration says 640x480', status
    assert joints == [] and wrist == []
    assert nodes[0].frame_camera.refused == {'size': 1}


def test_lookup_and_ik_check_the_observation_against_their_camera_info(
        node_assets: NodeAssets, small_database_path: Path,
        good_observation: HandObservation, good_candidates: HandPoseCandidates) -> None:
    """An observation (or candidates) from a 1280x960 image while the CameraInfo says
    640x480 is refused by lookup_node and ik_node themselves; before any CameraInfo they
    wait for one."""
    big = copy.deepcopy(good_observation)
    big.image_width, big.image_height = 1280, 960
    big_candidates = copy.deepcopy(good_candidates)
    big_candidates.observation = big
    with running(lookup_node(node_assets, use_camera_info=True),
                 ik_node(small_database_path, use_camera_info=True,
                         publish_overlay=False)) as h:
        candidates = h.collect(HandPoseCandidates, 'hand/pose_candidates')
        status = h.collect(String, 'hand/tracking_status')
        joints = h.collect(JointState, 'hand/joint_states')
        observation_pub = h.publisher(HandObservation, 'hand/observation')
        candidates_pub = h.probe.create_publisher(HandPoseCandidates, 'hand/pose_candidates',
                                                  10)
        assert h.spin_until(lambda: candidates_pub.get_subscription_count() >= 2, 10.0)
        waiting = h.exchange(observation_pub, good_observation, candidates)
        info_pub = h.probe.create_publisher(CameraInfo, 'camera/camera_info', 10)
        assert h.spin_until(lambda: info_pub.get_subscription_count() >= 2, 10.0)
        info_pub.publish(camera_to_camera_info_msg(CAMERA, header(50, 0, CAMERA.frame_id)))
        h.settle(0.3)
        refused = h.exchange(observation_pub, big, candidates)
        h.settle(0.5)          # ik_node answers the lookup's refusals first
        ik_refused = h.exchange(candidates_pub, big_candidates, status)
        ik_tracked = h.exchange(candidates_pub, good_candidates, status)
        h.settle(0.3)
        lookup_refusals = dict(h.nodes[0].frame_camera.refused)
        ik_refusals = dict(h.nodes[1].frame_camera.refused)
    assert not waiting.hand_found and waiting.status == 'camera: waiting for CameraInfo'
    assert not refused.hand_found
    assert refused.status == 'camera: image 1280x960 but CameraInfo says 640x480'
    assert lookup_refusals == {'waiting for CameraInfo': 1, 'size': 1}
    assert ik_refused.data == 'no hand: camera: image 1280x960 but CameraInfo says 640x480'
    assert ik_tracked.data.startswith('tracking:'), ik_tracked.data
    assert ik_refusals == {'size': 1}
    assert [m.header.stamp.nanosec for m in joints] == [500]


def test_camera_info_is_taken_when_a_frame_needs_it_not_when_it_arrives(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """A spinning node runs no callback for CameraInfo (every message read by the executor
    costs it a wake-up): the subscription is the node's but outside the executor's wait set,
    and a frame asking for its camera takes the newest of those that came (one deep, like
    every input of the pipeline); the node's destruction ends the subscription."""
    import time

    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.node import Node

    from colorglove_ros.ros.frame_camera import FrameCamera
    from colorglove_ros.ros.nodes.common import CAMERA_INFO_TOPIC, declare_frame_camera

    widths = []
    keep = FrameCamera.set_camera_info
    monkeypatch.setattr(FrameCamera, 'set_camera_info',
                        lambda self, msg: (widths.append(msg.width), keep(self, msg)))
    context = rclpy.Context()
    rclpy.init(context=context)
    try:
        reader = Node('reader', context=context)
        frame_camera = declare_frame_camera(reader, CAMERA)
        assert [s.topic_name for s in reader.subscriptions] == ['/' + CAMERA_INFO_TOPIC]
        executor = SingleThreadedExecutor(context=context)
        subscription = next(iter(reader.subscriptions))
        # out of the wait set, and nothing of it in: a QoS event handler waiting there would
        # wake the executor on every unread CameraInfo (a busy loop)
        assert not executor.can_execute(subscription)
        assert not any(executor.can_execute(h) for h in subscription.event_handlers)
        assert not any(executor.can_execute(w) for w in reader.waitables
                       if w.callback_group is subscription.callback_group)
        writer = Node('writer', context=context)
        publisher = writer.create_publisher(CameraInfo, CAMERA_INFO_TOPIC, 10)
        deadline = time.monotonic() + 10.0
        while publisher.get_subscription_count() < 1 and time.monotonic() < deadline:
            time.sleep(0.05)
        executor.add_node(reader)
        stamp = header(1, frame_id=CAMERA.frame_id)

        def frame() -> object:
            return frame_camera.camera_for(CAMERA.width, CAMERA.height, CAMERA.frame_id)

        assert frame().reason == 'camera: waiting for CameraInfo'
        burst = [replace(CAMERA, width=CAMERA.width + k) for k in range(5)]
        for camera in burst:
            publisher.publish(camera_to_camera_info_msg(camera, stamp))
        time.sleep(1.0)
        deadline = time.monotonic() + 2.0
        while time.monotonic() < deadline:
            executor.spin_once(timeout_sec=0.1)
        assert widths == []                      # the executor never read it
        assert frame_camera.camera_info_camera is None
        assert frame().reason == (f'camera: image {CAMERA.width}x{CAMERA.height} but '
                                f'CameraInfo says {burst[-1].width}x{CAMERA.height}')
        assert widths == [burst[-1].width]       # the newest only
        publisher.publish(camera_to_camera_info_msg(CAMERA, stamp))
        time.sleep(0.5)
        assert frame() == frame_camera.camera_info_camera
        assert frame_camera.camera_info_camera.width == CAMERA.width
        assert frame_camera.refused == {'waiting for CameraInfo': 1, 'size': 1}
        executor.shutdown()
        reader.destroy_node()
        deadline = time.monotonic() + 5.0
        while publisher.get_subscription_count() > 0 and time.monotonic() < deadline:
            time.sleep(0.05)
        assert publisher.get_subscription_count() == 0
        assert frame_camera.take_camera_info() is None   # destroyed: nothing, no error
        writer.destroy_node()
    finally:
        rclpy.try_shutdown(context=context)
