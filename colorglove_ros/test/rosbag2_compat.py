"""What Jazzy's rosbag2 (MCAP storage plugin and metadata.yaml reader) needs from a bag, checked
with Foxglove's independent MCAP/ROS 2 decoder (``mcap``, ``mcap-ros2-support``) instead of
rosbags, which wrote the bags. The rules follow rosbag2 (Jazzy, metadata version 9):
``rosbag2_storage/yaml.hpp`` (BagMetadata / TopicMetadata decode), ``rosbag2_storage/qos.cpp``
(QoS as a YAML sequence of mappings with policies as strings) and
``rosbag2_storage_mcap/mcap_storage.cpp`` (channels: ``cdr`` messages, ``ros2msg`` schemas,
``offered_qos_profiles`` channel metadata, a ``rosbag2`` metadata record)."""
from __future__ import annotations

import re
from pathlib import Path

import yaml
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory

__all__ = ['check_jazzy_bag']

# rmw_qos_*_policy_from_str accepts exactly these (plus 'unknown', which rosbag2 records for
# the history of discovered publishers)
_POLICIES = {
    'history': {'system_default', 'keep_last', 'keep_all', 'unknown'},
    'reliability': {'system_default', 'reliable', 'best_effort', 'best_available', 'unknown'},
    'durability': {'system_default', 'transient_local', 'volatile', 'best_available', 'unknown'},
    'liveliness': {'system_default', 'automatic', 'manual_by_topic', 'best_available',
                   'unknown'},
}
_DURATIONS = ('deadline', 'lifespan', 'liveliness_lease_duration')
_TOPIC_KEYS = {'name', 'type', 'serialization_format', 'offered_qos_profiles',
               'type_description_hash'}
_BAG_KEYS = {'version', 'storage_identifier', 'duration', 'starting_time', 'message_count',
             'topics_with_message_count', 'compression_format', 'compression_mode',
             'relative_file_paths', 'files', 'custom_data', 'ros_distro'}


def _check_qos_list(profiles: object, where: str) -> None:
    assert isinstance(profiles, list), f'{where}: offered_qos_profiles must be a YAML sequence'
    for qos in profiles:
        keys = set(_POLICIES) | set(_DURATIONS) | {'depth', 'avoid_ros_namespace_conventions'}
        assert set(qos) == keys, f'{where}: QoS keys {sorted(qos)}'
        for policy, allowed in _POLICIES.items():
            assert qos[policy] in allowed, f'{where}: {policy} {qos[policy]!r}'
        for name in _DURATIONS:
            assert set(qos[name]) == {'sec', 'nsec'} and all(
                isinstance(v, int) and v >= 0 for v in qos[name].values()), (where, qos[name])
        assert isinstance(qos['depth'], int) and qos['depth'] >= 0
        assert isinstance(qos['avoid_ros_namespace_conventions'], bool)


def _check_metadata(info: dict, where: str) -> dict[str, dict]:
    assert _BAG_KEYS <= set(info), f'{where}: missing {sorted(_BAG_KEYS - set(info))}'
    assert info['version'] == 9 and info['storage_identifier'] == 'mcap'
    assert info['compression_format'] == '' and info['compression_mode'] == ''
    assert info['custom_data'] is None or isinstance(info['custom_data'], dict)
    assert isinstance(info['duration']['nanoseconds'], int)
    assert isinstance(info['starting_time']['nanoseconds_since_epoch'], int)
    topics = {}
    for entry in info['topics_with_message_count']:
        topic = entry['topic_metadata']
        assert set(topic) == _TOPIC_KEYS, f'{where}: topic keys {sorted(topic)}'
        assert topic['serialization_format'] == 'cdr'
        assert re.fullmatch(r'[A-Za-z]\w*/msg/[A-Z]\w*', topic['type']), topic['type']
        assert re.fullmatch(r'RIHS01_[0-9a-f]{64}', topic['type_description_hash'])
        _check_qos_list(topic['offered_qos_profiles'], f'{where} {topic["name"]}')
        topics[topic['name']] = {**topic, 'message_count': entry['message_count']}
    assert sum(t['message_count'] for t in topics.values()) == info['message_count']
    return topics


def check_jazzy_bag(bag: Path) -> dict[str, list]:
    """Assert ``bag`` (a rosbag2 folder holding one MCAP file) meets what Jazzy's rosbag2 reads;
    decode every message with mcap_ros2 and return the decoded messages per topic."""
    info = yaml.safe_load((bag / 'metadata.yaml').read_text())['rosbag2_bagfile_information']
    topics = _check_metadata(info, 'metadata.yaml')
    assert [f['path'] for f in info['files']] == info['relative_file_paths']
    assert len(info['relative_file_paths']) == 1
    decoded: dict[str, list] = {name: [] for name in topics}
    with open(bag / info['relative_file_paths'][0], 'rb') as stream:
        reader = make_reader(stream, decoder_factories=[DecoderFactory()])
        assert reader.get_header().profile == 'ros2'
        summary = reader.get_summary()
        records = [m for m in reader.iter_metadata() if m.name == 'rosbag2']
        assert len(records) == 1, 'the rosbag2 storage plugin reads the metadata record'
        embedded = yaml.safe_load(records[0].metadata['serialized_metadata'])
        assert _check_metadata(embedded, 'MCAP rosbag2 record') == topics
        for channel in summary.channels.values():
            schema = summary.schemas[channel.schema_id]
            assert channel.message_encoding == 'cdr' and schema.encoding == 'ros2msg'
            assert schema.name == topics[channel.topic]['type']
            _check_qos_list(yaml.safe_load(channel.metadata['offered_qos_profiles']),
                            f'channel {channel.topic}')
        for _, channel, _, message in reader.iter_decoded_messages(log_time_order=False):
            decoded[channel.topic].append(message)
        assert summary.statistics.message_count == info['message_count']
    for name, topic in topics.items():
        assert len(decoded[name]) == topic['message_count'], name
    return decoded
