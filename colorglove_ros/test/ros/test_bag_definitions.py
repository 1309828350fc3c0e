"""Bags recorded with another definition of a message type than the installed one: found,
refused with the differing fields named, or converted field by field by name."""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from colorglove_msgs.msg import HandPoseCandidates
from message_samples import sample_candidates
from rclpy.serialization import deserialize_message, serialize_message
from rosbags.highlevel import AnyReader
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

from colorglove_ros.ros.bag_definitions import convert_message, definition_changes
from colorglove_ros.ros.typestore import colorglove_msg_files, colorglove_typestore, deserialize_cdr

CANDIDATES = 'colorglove_msgs/msg/HandPoseCandidates'
TOPIC = '/hand/pose_candidates'


def _old_store(indices_type: str = 'uint32'):
    """The installed type store with an 'older' HandPoseCandidates: no finger_std, a field
    the installed type has dropped, and candidate_indices of ``indices_type``."""
    store = get_typestore(Stores.ROS2_JAZZY)
    for path in colorglove_msg_files():
        text = path.read_text()
        if path.stem == 'HandPoseCandidates':
            text = '\n'.join(line.replace('uint32[] candidate_indices',
                                          f'{indices_type}[] candidate_indices')
                             for line in text.splitlines()
                             if not line.startswith('float64[] finger_std'))
            text += '\nfloat32[] retired_scores\n'
        store.register(get_types_from_msg(text, f'colorglove_msgs/msg/{path.stem}'))
    return store


def _old_message(store, seq: int):
    """sample_candidates(seq) as the old definition's message (its fields, finger_std gone)."""
    installed = colorglove_typestore()
    current = deserialize_cdr(serialize_message(sample_candidates(seq)), CANDIDATES, installed)
    values = {name: getattr(current, name) for name, _ in store.fielddefs[CANDIDATES][1]
              if name != 'retired_scores'}
    values['header'] = store.types['std_msgs/msg/Header'](
        stamp=store.types['builtin_interfaces/msg/Time'](sec=current.header.stamp.sec,
                                                         nanosec=current.header.stamp.nanosec),
        frame_id=current.header.frame_id)
    return store.types[CANDIDATES](**values, retired_scores=np.array([0.5], np.float32))


def _write_old_bag(path: Path, indices_type: str = 'uint32', first_index: int = 0) -> None:
    store = _old_store(indices_type)
    with Writer(path, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        connection = writer.add_connection(TOPIC, CANDIDATES, typestore=store)
        for seq in range(3):
            message = _old_message(store, seq)
            if indices_type != 'uint32':
                message.candidate_indices = np.asarray(message.candidate_indices,
                                                       np.int64).astype(indices_type)
                message.candidate_indices[0] = first_index
            writer.write(connection, 1_000 + seq,
                         bytes(store.serialize_cdr(message, CANDIDATES)))


def test_changed_definition_is_found_with_its_fields(tmp_path: Path) -> None:
    _write_old_bag(tmp_path / 'old')
    with AnyReader([tmp_path / 'old'], default_typestore=colorglove_typestore()) as reader:
        changes = definition_changes(reader.connections, reader.typestore,
                                     colorglove_typestore())
    assert len(changes) == 1
    change = changes[0]
    assert (change.topic, change.dropped, change.added) == (TOPIC, ('retired_scores',),
                                                            ('finger_std',))
    assert 'retired_scores' in change.describe() and 'finger_std' in change.describe()


def test_same_definition_is_no_change(tmp_path: Path) -> None:
    store = colorglove_typestore()
    with Writer(tmp_path / 'new', version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        connection = writer.add_connection(TOPIC, CANDIDATES, typestore=store)
        writer.write(connection, 1, serialize_message(sample_candidates(0)))
    with AnyReader([tmp_path / 'new'], default_typestore=store) as reader:
        assert definition_changes(reader.connections, reader.typestore, store) == []


def test_converted_message_keeps_every_common_field() -> None:
    store = _old_store()
    old = _old_message(store, 4)
    installed = colorglove_typestore()
    converted = convert_message(old, CANDIDATES, installed)
    message = deserialize_message(bytes(installed.serialize_cdr(converted, CANDIDATES)),
                                  HandPoseCandidates)
    expected = sample_candidates(4)
    assert message.header.stamp == expected.header.stamp
    assert message.header.frame_id == expected.header.frame_id
    assert list(message.dof_names) == list(expected.dof_names)
    np.testing.assert_array_equal(message.candidate_poses, expected.candidate_poses)
    np.testing.assert_array_equal(message.constraint_colors, expected.constraint_colors)
    assert len(message.finger_std) == 0          # new field: its default


def test_player_refuses_an_old_bag_naming_the_fields(tmp_path: Path,
                                                     isolated_ros_domain: dict) -> None:
    _write_old_bag(tmp_path / 'old')
    result = subprocess.run([sys.executable, '-m', 'colorglove_ros.tools.play_bag',
                             str(tmp_path / 'old'), '--rate', '0', '--linger', '0'],
                            env=isolated_ros_domain, capture_output=True, text=True, timeout=60)
    assert result.returncode == 2, result.stderr
    assert 'retired_scores' in result.stderr and '--convert-definitions' in result.stderr
    assert 'Traceback' not in result.stderr


@pytest.mark.dds
def test_player_converts_an_old_bag_when_asked(tmp_path: Path) -> None:
    import rclpy

    from colorglove_ros.tools.play_bag import BagPlayer

    _write_old_bag(tmp_path / 'old')
    context = rclpy.Context()
    rclpy.init(context=context)
    try:
        player = BagPlayer(tmp_path / 'old', convert_definitions=True, context=context)
        published = [deserialize_message(player.installed_bytes(connection.topic, raw),
                                         HandPoseCandidates)
                     for connection, _, raw in player.reader.messages()]
        player.close()
        player.destroy_node()
    finally:
        rclpy.try_shutdown(context=context)
    assert [m.header.stamp for m in published] == [sample_candidates(s).header.stamp
                                                   for s in range(3)]
    np.testing.assert_array_equal(published[2].candidate_weights,
                                  sample_candidates(2).candidate_weights)


def _play(bag: Path, env: dict, *options: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, '-m', 'colorglove_ros.tools.play_bag', str(bag),
                           '--rate', '0', '--settle', '0', '--linger', '0', *options],
                          env=env, capture_output=True, text=True, timeout=60)


@pytest.mark.dds
def test_player_plays_an_old_bag_converted(tmp_path: Path, isolated_ros_domain: dict) -> None:
    _write_old_bag(tmp_path / 'old')
    result = _play(tmp_path / 'old', isolated_ros_domain, '--convert-definitions')
    assert result.returncode == 0, result.stderr
    assert 'converting /hand/pose_candidates' in result.stderr
    assert 'published 3 messages' in result.stdout


def test_retyped_values_that_fit_are_converted(tmp_path: Path) -> None:
    _write_old_bag(tmp_path / 'old', indices_type='int64', first_index=7)
    with AnyReader([tmp_path / 'old'], default_typestore=colorglove_typestore()) as reader:
        (change,) = definition_changes(reader.connections, reader.typestore,
                                       colorglove_typestore())
        assert change.retyped == ('candidate_indices',)
        _, _, raw = next(reader.messages())
        old = reader.deserialize(raw, CANDIDATES)
    converted = convert_message(old, CANDIDATES, colorglove_typestore())
    assert converted.candidate_indices.dtype == np.uint32
    assert converted.candidate_indices[0] == 7


@pytest.mark.dds
def test_player_refuses_values_the_installed_field_cannot_hold(
        tmp_path: Path, isolated_ros_domain: dict) -> None:
    """A recorded int64 -1 cannot become the installed uint32: refused before playing."""
    _write_old_bag(tmp_path / 'old', indices_type='int64', first_index=-1)
    result = _play(tmp_path / 'old', isolated_ros_domain, '--convert-definitions')
    assert result.returncode == 2, result.stderr
    assert 'candidate_indices' in result.stderr and 'do not fit uint32' in result.stderr
    assert 'Traceback' not in result.stderr


@pytest.mark.parametrize(('fields', 'value', 'message'), [
    ('int32 x', 2.7, 'do not fit int32'),
    ('string[2] x', ['a', 'b', 'c'], 'fixed array of 2 recorded with 3'),
    ('float64 x', 'text', 'cannot become a float64'),
    ('string<=3 x', 'toolong', 'at most 3'),
])
def test_conversion_refuses_what_the_field_cannot_hold(fields: str, value, message: str
                                                       ) -> None:
    from colorglove_ros.ros.bag_definitions import DefinitionConversionError

    store = get_typestore(Stores.ROS2_JAZZY)
    store.register(get_types_from_msg(fields, 'test_msgs/msg/One'))
    recorded = SimpleNamespace(x=value)
    with pytest.raises(DefinitionConversionError, match=message):
        convert_message(_as_dataclass(recorded), 'test_msgs/msg/One', store)


def test_signed_byte_values_convert() -> None:
    store = get_typestore(Stores.ROS2_JAZZY)
    store.register(get_types_from_msg('byte b', 'test_msgs/msg/Byte'))
    converted = convert_message(_as_dataclass(SimpleNamespace(b=-56)), 'test_msgs/msg/Byte',
                                store)
    assert converted.b == -56
    store.serialize_cdr(converted, 'test_msgs/msg/Byte')


def _as_dataclass(values: SimpleNamespace):
    """A recorded message with the fields of ``values`` (what the reader decodes)."""
    from dataclasses import make_dataclass

    names = list(vars(values))
    return make_dataclass('Recorded', names)(**vars(values))


OBSERVATION = 'colorglove_msgs/msg/HandObservation'
# HandObservation's blobs before session 27: a list of PatchBlob messages
_PATCH_BLOB = """uint8 color_label
float64 x
float64 y
uint32 pixel_count
"""
_NEW_BLOB_FIELDS = ('uint8[] blob_colors', 'float64[] blob_centroids',
                    'uint32[] blob_pixel_counts')


def _patch_blob_store():
    """The installed type store with HandObservation's blobs as ``PatchBlob[] blobs``."""
    store = get_typestore(Stores.ROS2_JAZZY)
    store.register(get_types_from_msg(_PATCH_BLOB, 'colorglove_msgs/msg/PatchBlob'))
    for path in colorglove_msg_files():
        text = path.read_text()
        if path.stem == 'HandObservation':
            lines = [line for line in text.splitlines()
                     if not line.startswith(_NEW_BLOB_FIELDS)]
            text = '\n'.join(lines) + '\nPatchBlob[] blobs\n'
        store.register(get_types_from_msg(text, f'colorglove_msgs/msg/{path.stem}'))
    return store


def _blob_values(seq: int) -> list[tuple[int, float, float, int]]:
    rng = np.random.default_rng(seq)
    return [(int(rng.integers(1, 11)), float(rng.uniform(0, 640)), float(rng.uniform(0, 480)),
             int(rng.integers(1, 4_000_000_000))) for _ in range(int(rng.integers(0, 25)))]


def _patch_blob_candidates(store, seq: int):
    """sample_candidates(seq) in the PatchBlob store, its observation's blobs
    :func:`_blob_values` as PatchBlob messages."""
    installed = colorglove_typestore()
    current = deserialize_cdr(serialize_message(sample_candidates(seq)), CANDIDATES, installed)
    blob = store.types['colorglove_msgs/msg/PatchBlob']
    observation = current.observation
    old_observation = store.types[OBSERVATION](**{
        name: getattr(observation, name) for name, _ in store.fielddefs[OBSERVATION][1]
        if name != 'blobs'}, blobs=[blob(color_label=c, x=x, y=y, pixel_count=n)
                                    for c, x, y, n in _blob_values(seq)])
    old_observation.header = _header(store, observation.header)
    values = {name: getattr(current, name) for name, _ in store.fielddefs[CANDIDATES][1]}
    values['observation'] = old_observation
    values['header'] = _header(store, current.header)
    return store.types[CANDIDATES](**values)


def _header(store, header):
    """``header`` as ``store``'s std_msgs/Header."""
    return store.types['std_msgs/msg/Header'](
        stamp=store.types['builtin_interfaces/msg/Time'](sec=header.stamp.sec,
                                                         nanosec=header.stamp.nanosec),
        frame_id=header.frame_id)


def test_patch_blob_bags_convert_their_blobs_into_the_parallel_arrays(tmp_path: Path) -> None:
    """A bag recorded before the blobs became parallel arrays: the change names the blobs as
    converted, and every blob's colour, centroid and pixel count reaches the installed arrays
    exactly, in order (nested in the candidates and on an observation topic)."""
    store = _patch_blob_store()
    with Writer(tmp_path / 'old', version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        candidates = writer.add_connection(TOPIC, CANDIDATES, typestore=store)
        observations = writer.add_connection('/hand/observation', OBSERVATION, typestore=store)
        for seq in range(4):
            message = _patch_blob_candidates(store, seq)
            writer.write(candidates, 1_000 + seq,
                         bytes(store.serialize_cdr(message, CANDIDATES)))
            writer.write(observations, 1_000 + seq,
                         bytes(store.serialize_cdr(message.observation, OBSERVATION)))
    installed = colorglove_typestore()
    with AnyReader([tmp_path / 'old'], default_typestore=installed) as reader:
        changes = {c.topic: c for c in definition_changes(reader.connections, reader.typestore,
                                                          installed)}
        assert 'converted: observation.blobs -> observation.blob_colors, ' \
            'observation.blob_centroids, observation.blob_pixel_counts' \
            in changes[TOPIC].describe()
        assert 'converted: blobs -> blob_colors' in changes['/hand/observation'].describe()
        assert 'dropped' not in changes[TOPIC].describe()       # the blobs are carried over
        assert 'at defaults' not in changes['/hand/observation'].describe()
        recorded = [(c.topic, reader.deserialize(raw, c.msgtype))
                    for c, _, raw in reader.messages()]
    from colorglove_msgs.msg import HandObservation

    seen = 0
    for k, (topic, old) in enumerate(recorded):
        kind, cls = ((CANDIDATES, HandPoseCandidates) if topic == TOPIC
                     else (OBSERVATION, HandObservation))
        converted = convert_message(old, kind, installed)
        message = deserialize_message(bytes(installed.serialize_cdr(converted, kind)), cls)
        observation = message.observation if topic == TOPIC else message
        blobs = _blob_values(k // 2)
        assert list(observation.blob_colors) == [b[0] for b in blobs]
        assert list(observation.blob_centroids) == [v for b in blobs for v in b[1:3]]
        assert list(observation.blob_pixel_counts) == [b[3] for b in blobs]
        assert observation.crop_scale == sample_candidates(k // 2).observation.crop_scale
        seen += len(blobs)
    assert seen > 0
