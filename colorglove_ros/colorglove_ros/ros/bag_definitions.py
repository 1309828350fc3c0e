"""Messages recorded with another definition of their type than the one installed.

A bag stores each topic's message definition and its type hash (RIHS01). A bag recorded before
a message of this package changed (a field added, renamed or retyped) holds bytes laid out for
the old definition; published as they are, every subscriber would decode them with the new
layout and read nonsense. :func:`definition_changes` finds such topics (comparing the recorded
hash with the installed definition's) and says which fields differ; :func:`convert_message`
rebuilds a message decoded with the recorded definition as the installed type, field by field
by name (fields the installed type lacks are dropped, new fields get their defaults)."""
from __future__ import annotations

from dataclasses import dataclass, fields, is_dataclass
from typing import Any

import numpy as np
from rosbags.interfaces import Nodetype
from rosbags.typesys.store import Typestore

__all__ = ['DefinitionChange', 'convert_message', 'definition_changes']

_BASE, _NAME, _ARRAY, _SEQUENCE = Nodetype.BASE, Nodetype.NAME, Nodetype.ARRAY, Nodetype.SEQUENCE
_NUMPY_TYPES = {'bool': np.bool_, 'byte': np.uint8, 'char': np.uint8, 'int8': np.int8,
                'uint8': np.uint8, 'int16': np.int16, 'uint16': np.uint16,
                'int32': np.int32, 'uint32': np.uint32, 'int64': np.int64,
                'uint64': np.uint64, 'float32': np.float32, 'float64': np.float64}


@dataclass(frozen=True)
class DefinitionChange:
    """How a topic's recorded message definition differs from the installed one."""

    topic: str
    msgtype: str
    dropped: tuple[str, ...]     # recorded fields the installed type lacks (dotted paths)
    added: tuple[str, ...]       # installed fields the recording lacks (get their defaults)
    retyped: tuple[str, ...]     # fields of both whose type differs

    def describe(self) -> str:
        """One line for the user."""
        parts = [f'{name} {", ".join(items)}' for name, items in
                 (('dropped:', self.dropped), ('new, at defaults:', self.added),
                  ('retyped:', self.retyped)) if items]
        return (f'{self.topic}: recorded with another definition of {self.msgtype} than the '
                f'installed one ({"; ".join(parts) or "same field names, other layout"})')


def _field_types(store: Typestore, msgtype: str, prefix: str = '') -> dict[str, str]:
    """Dotted field path -> a type string, for every field of ``msgtype``, nested included."""
    out: dict[str, str] = {}
    for name, (kind, spec) in store.fielddefs[msgtype][1]:
        path = f'{prefix}{name}'
        if kind == _NAME:
            out[path] = spec
            out.update(_field_types(store, spec, f'{path}.'))
        elif kind in (_ARRAY, _SEQUENCE):
            (inner_kind, inner_spec), count = spec
            element = inner_spec if inner_kind == _NAME else inner_spec[0]
            out[path] = f'{element}[{count if kind == _ARRAY else ""}]'
            if inner_kind == _NAME:
                out.update(_field_types(store, inner_spec, f'{path}[].'))
        else:
            out[path] = spec[0]
    return out


def definition_changes(connections: list[Any], recorded: Typestore, installed: Typestore
                       ) -> list[DefinitionChange]:
    """The topics of ``connections`` (rosbags connections with ``digest``) whose recorded
    type hash differs from the installed definition's (``recorded``: the reader's type store,
    built from the bag's own definitions). Types the installed store does not know, and
    recordings without a RIHS01 hash (older distributions), are not judged here."""
    changes = []
    for connection in connections:
        digest = getattr(connection, 'digest', '') or ''
        if not digest.startswith('RIHS01_') or connection.msgtype not in installed.fielddefs:
            continue
        if digest == installed.hash_rihs01(connection.msgtype):
            continue
        old = _field_types(recorded, connection.msgtype)
        new = _field_types(installed, connection.msgtype)
        changes.append(DefinitionChange(
            connection.topic, connection.msgtype,
            tuple(path for path in old if path not in new),
            tuple(path for path in new if path not in old),
            tuple(path for path in old if path in new and old[path] != new[path])))
    return changes


def _default(store: Typestore, kind: int, spec: Any) -> Any:
    if kind == _BASE:
        return '' if spec[0] in ('string', 'wstring') else _NUMPY_TYPES[spec[0]](0).item()
    if kind == _NAME:
        return convert_message(None, spec, store)
    (inner_kind, inner_spec), count = spec
    if inner_kind == _BASE and inner_spec[0] in _NUMPY_TYPES:
        return np.zeros(count if kind == _ARRAY else 0, _NUMPY_TYPES[inner_spec[0]])
    return [_default(store, inner_kind, inner_spec) for _ in range(count if kind == _ARRAY
                                                                     else 0)]


def _convert(value: Any, store: Typestore, kind: int, spec: Any) -> Any:
    if kind == _BASE:
        if spec[0] in ('string', 'wstring'):
            return str(value)
        return _NUMPY_TYPES[spec[0]](value).item()
    if kind == _NAME:
        return convert_message(value, spec, store)
    (inner_kind, inner_spec), count = spec
    if inner_kind == _BASE and inner_spec[0] in _NUMPY_TYPES:
        array = np.asarray(value).astype(_NUMPY_TYPES[inner_spec[0]])
        if kind == _ARRAY and array.size != count:
            raise ValueError(f'a fixed array of {count} recorded with {array.size} values')
        return array
    return [_convert(item, store, inner_kind, inner_spec) for item in value]


def convert_message(message: Any, msgtype: str, store: Typestore) -> Any:
    """``message`` (decoded with any definition of ``msgtype``; None for all defaults) as an
    instance of ``store``'s definition: fields matched by name, recursively."""
    present = ({f.name: getattr(message, f.name) for f in fields(message)}
               if is_dataclass(message) else {})
    values = {}
    for name, (kind, spec) in store.fielddefs[msgtype][1]:
        values[name] = (_convert(present[name], store, kind, spec) if name in present
                        else _default(store, kind, spec))
    return store.types[msgtype](**values)
