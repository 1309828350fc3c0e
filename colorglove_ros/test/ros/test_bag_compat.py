"""Bags written here are what a native Jazzy ``ros2 bag play`` reads: a bag from
``colorglove_make_bag`` and one from ``colorglove_record_bag`` checked against rosbag2's metadata
schema and decoded message by message with Foxglove's mcap_ros2 (an implementation independent
of rosbags, which wrote them). ``ros2 bag play`` itself is not installable here (see README)."""
from __future__ import annotations

import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import yaml
from repo_paths import CONFIG_DIR
from rosbag2_compat import check_jazzy_bag

from colorglove_ros.core.hand.model import FINGER_DOF_NAMES
from colorglove_ros.ros.bags import (
    TOPIC_CAMERA_INFO,
    TOPIC_IMAGE,
    TOPIC_JOINTS,
    TOPIC_TF,
    TOPIC_TF_STATIC,
    read_sequence_bag,
)
from colorglove_ros.tools import make_bag

FRAMES = 3


@pytest.fixture(scope='module')
def stereo_bag(tmp_path_factory: pytest.TempPathFactory) -> Path:
    bag = tmp_path_factory.mktemp('compat') / 'stereo'
    assert make_bag.main(['--seed', '2', '--frames', str(FRAMES), '--output', str(bag),
                          '--calibration', str(CONFIG_DIR / 'calibration_stereo.yaml')
                          ]) == 0
    return bag


def test_make_bag_output_decodes_with_mcap_ros2(stereo_bag: Path) -> None:
    decoded = check_jazzy_bag(stereo_bag)
    static = decoded.pop(TOPIC_TF_STATIC)
    assert all(len(messages) == FRAMES for messages in decoded.values()), \
        {topic: len(messages) for topic, messages in decoded.items()}
    # 5 primary topics, /tf, the second camera's image and info; /tf_static once
    assert len(decoded) == 8
    assert [t.child_frame_id for t in static[0].transforms] == ['camera2_optical_frame']
    assert decoded[TOPIC_TF][0].transforms[0].child_frame_id == 'palm'
    # the independent decoder reads the same pixels and values as rosbags
    frames = list(read_sequence_bag(stereo_bag))
    for image, info, joints, frame in zip(decoded[TOPIC_IMAGE], decoded[TOPIC_CAMERA_INFO],
                                          decoded[TOPIC_JOINTS], frames, strict=True):
        assert (image.encoding, image.width, image.height) == ('rgb8', 640, 480)
        pixels = np.frombuffer(bytes(image.data), np.uint8).reshape(480, 640, 3)
        np.testing.assert_array_equal(pixels, frame.image_rgb)
        assert info.distortion_model == 'plumb_bob' and len(info.d) == 5
        assert list(joints.name) == list(FINGER_DOF_NAMES)
        np.testing.assert_array_equal(joints.position, frame.joint_positions)
        assert image.header.stamp.sec * 10**9 + image.header.stamp.nanosec == frame.stamp_ns
    second = decoded['/camera2/camera/image_raw'][0]
    assert second.header.frame_id == 'camera2_optical_frame'


@pytest.mark.dds
def test_recorded_bag_decodes_with_mcap_ros2(stereo_bag: Path, tmp_path: Path,
                                             isolated_ros_domain: dict) -> None:
    """Replay the make_bag bag and record it back: the recorded bag (with the publishers'
    offered QoS) is also readable by Jazzy's rosbag2."""
    topics = [TOPIC_IMAGE, TOPIC_CAMERA_INFO, TOPIC_JOINTS]
    recorder = subprocess.Popen(
        [sys.executable, '-m', 'colorglove_ros.tools.record_bag', str(tmp_path / 'recorded'),
         '--topics', *topics, '--duration', '60'],
        env=isolated_ros_domain, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    time.sleep(1.0)
    player = subprocess.run(
        [sys.executable, '-m', 'colorglove_ros.tools.play_bag', str(stereo_bag), '--rate', '0.5',
         '--wait-subscribers', '10'],
        env=isolated_ros_domain, capture_output=True, text=True, timeout=60)
    assert player.returncode == 0, player.stderr
    time.sleep(0.5)
    recorder.send_signal(signal.SIGINT)
    output = recorder.communicate(timeout=30)[0]
    assert recorder.returncode == 0, output
    decoded = check_jazzy_bag(tmp_path / 'recorded')
    assert set(decoded) == set(topics)
    # the recorder subscribes once a topic appears, so the first frame may predate it
    assert all(len(messages) >= FRAMES - 1 for messages in decoded.values()), output
    assert decoded[TOPIC_IMAGE][-1].encoding == 'rgb8'
    info = yaml.safe_load((tmp_path / 'recorded' / 'metadata.yaml').read_text())
    offered = [entry['topic_metadata']['offered_qos_profiles']
               for entry in info['rosbag2_bagfile_information']['topics_with_message_count']]
    assert all(len(profiles) == 1 and profiles[0]['reliability'] == 'reliable'
               for profiles in offered), offered
