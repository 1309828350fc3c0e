"""Damaged bag files: a clear BagError naming the bag (reading) or a one-line error and an
exit code (colorglove_play_bag), never a traceback; what was played before the damage stays
played."""
from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest
from rclpy.serialization import serialize_message
from rosbags.rosbag2 import StoragePlugin, Writer
from sensor_msgs.msg import JointState

from colorglove_ros.ros.bags import BagError, bag_messages, open_bag_reader, read_sequence_bag
from colorglove_ros.ros.typestore import colorglove_typestore


def _joint_state_bag(path: Path, count: int = 400, size: int = 20) -> Path:
    with Writer(path, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        connection = writer.add_connection('/hand/ground_truth/joint_states',
                                           'sensor_msgs/msg/JointState',
                                           typestore=colorglove_typestore())
        for index in range(count):
            message = JointState(name=[f'joint_{k}' for k in range(20)],
                                 position=[float(index)] * size)
            message.header.stamp.sec = index
            writer.write(connection, 10**9 + index * 10**7, serialize_message(message))
    return path


def _mcap(path: Path) -> Path:
    return next(path.glob('*.mcap'))


def test_truncated_bag_is_a_bag_error(tmp_path: Path) -> None:
    bag = _joint_state_bag(tmp_path / 'bag')
    data = _mcap(bag).read_bytes()
    _mcap(bag).write_bytes(data[:len(data) // 2])
    with pytest.raises(BagError, match=f'cannot read the bag {bag}'):
        open_bag_reader(bag)
    with pytest.raises(BagError, match='cannot read the bag'):
        list(read_sequence_bag(bag))


def test_unreadable_metadata_is_a_bag_error(tmp_path: Path) -> None:
    bag = _joint_state_bag(tmp_path / 'bag')
    (bag / 'metadata.yaml').write_text('rosbag2_bagfile_information: [\n')
    with pytest.raises(BagError, match='metadata.yaml'):
        open_bag_reader(bag)
    (bag / 'metadata.yaml').unlink()
    with pytest.raises(BagError, match='metadata'):
        open_bag_reader(bag)


def _damage_middle(bag: Path) -> None:
    data = bytearray(_mcap(bag).read_bytes())
    for i in range(len(data) // 3, 2 * len(data) // 3):
        data[i] = 0xAB
    _mcap(bag).write_bytes(bytes(data))


def test_damaged_messages_end_the_reading_with_a_bag_error(tmp_path: Path) -> None:
    bag = _joint_state_bag(tmp_path / 'bag')
    _damage_middle(bag)
    reader = open_bag_reader(bag)
    try:
        with pytest.raises(BagError, match='any further'):
            for _ in bag_messages(reader, reader.connections, bag):
                pass
    finally:
        reader.close()


def _damage_last_chunk_header(bag: Path) -> None:
    """Overwrite the record header of the bag's last chunk (the ones before stay readable)."""
    from mcap.reader import make_reader

    with _mcap(bag).open('rb') as stream:
        start = make_reader(stream).get_summary().chunk_indexes[-1].chunk_start_offset
    data = bytearray(_mcap(bag).read_bytes())
    data[start:start + 40] = b'\xab' * 40
    _mcap(bag).write_bytes(bytes(data))


@pytest.mark.dds
def test_player_keeps_what_it_played_before_the_damage(tmp_path: Path,
                                                       isolated_ros_domain: dict) -> None:
    bag = _joint_state_bag(tmp_path / 'bag', count=200, size=2000)   # several chunks
    _damage_last_chunk_header(bag)
    result = subprocess.run([sys.executable, '-m', 'colorglove_ros.tools.play_bag', str(bag),
                             '--rate', '0', '--settle', '0', '--linger', '0'],
                            env=isolated_ros_domain, capture_output=True, text=True, timeout=60)
    assert result.returncode == 1, result.stderr
    published = int(re.search(r'\((\d+) messages published before\)', result.stderr).group(1))
    assert 0 < published < 200
    assert 'Traceback' not in result.stderr


@pytest.mark.dds
def test_player_says_why_it_cannot_play(tmp_path: Path, isolated_ros_domain: dict) -> None:
    truncated = _joint_state_bag(tmp_path / 'truncated')
    data = _mcap(truncated).read_bytes()
    _mcap(truncated).write_bytes(data[:len(data) // 2])
    damaged = _joint_state_bag(tmp_path / 'damaged')
    _damage_middle(damaged)
    for bag, code in ((truncated, 2), (damaged, 1)):
        result = subprocess.run([sys.executable, '-m', 'colorglove_ros.tools.play_bag',
                                 str(bag), '--rate', '0', '--settle', '0', '--linger', '0'],
                                env=isolated_ros_domain, capture_output=True, text=True,
                                timeout=60)
        assert result.returncode == code, result.stderr
        assert f'cannot read the bag {bag}' in result.stderr
        assert 'Traceback' not in result.stderr
