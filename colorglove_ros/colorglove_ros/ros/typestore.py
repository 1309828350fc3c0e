"""A rosbags type store that knows the Jazzy standard messages and this package's own."""
from __future__ import annotations

import importlib
from functools import cache
from pathlib import Path

from rosbags.typesys import Stores, get_types_from_msg, get_typestore
from rosbags.typesys.store import Typestore

__all__ = ['colorglove_typestore', 'colorglove_msg_files', 'deserialize_cdr', 'message_class']

_MSG_PACKAGE = 'colorglove_msgs'


def colorglove_msg_files() -> list[Path]:
    """The ``.msg`` files of colorglove_msgs (source checkout, else the installed share folder)."""
    source = Path(__file__).resolve().parents[3] / _MSG_PACKAGE / 'msg'
    if source.is_dir():
        return sorted(source.glob('*.msg'))
    from ament_index_python.packages import get_package_share_directory

    return sorted((Path(get_package_share_directory(_MSG_PACKAGE)) / 'msg').glob('*.msg'))


@cache
def colorglove_typestore() -> Typestore:
    """ROS 2 Jazzy types plus ``colorglove_msgs/msg/*`` parsed from their definitions."""
    store = get_typestore(Stores.ROS2_JAZZY)
    types = {}
    for path in colorglove_msg_files():
        types.update(get_types_from_msg(path.read_text(), f'{_MSG_PACKAGE}/msg/{path.stem}'))
    store.register(types)
    return store


def deserialize_cdr(data: bytes | memoryview, msgtype: str, store: Typestore | None = None):
    """Deserialize CDR bytes recorded from rclpy/Fast DDS into a rosbags message.

    Fast DDS pads some serialized messages with trailing zero bytes beyond the last field, which
    rosbags' ``deserialize_cdr`` rejects as a size mismatch; the fields themselves are read
    exactly as rosbags does, and only the trailing padding is tolerated.
    """
    store = store or colorglove_typestore()
    raw = memoryview(bytes(data))
    if len(raw) < 4 or bytes(raw[:2]) not in {b'\x00\x00', b'\x00\x01'}:
        raise ValueError(f'invalid or unsupported CDR encapsulation for {msgtype}')
    msgdef = store.get_msgdef(msgtype)
    func = msgdef.deserialize_cdr_le if raw[1] else msgdef.deserialize_cdr_be
    message, _ = func(raw[4:], 0, msgdef.cls, store)
    return message


def message_class(msgtype: str) -> type:
    """The rclpy message class of a type name such as ``sensor_msgs/msg/Image``."""
    package, _, name = msgtype.split('/')
    module = importlib.import_module(f'{package}.msg')
    return getattr(module, name)
