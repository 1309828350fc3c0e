"""Messages recorded with another definition of their type than the one installed.

A bag stores each topic's message definition and its type hash (RIHS01). A bag recorded before
a message of this package changed (a field added, renamed or retyped) holds bytes laid out for
the old definition; published as they are, every subscriber would decode them with the new
layout and read nonsense. :func:`definition_changes` finds such topics (comparing the recorded
hash with the installed definition's) and says which fields differ; :func:`convert_message`
rebuilds a message decoded with the recorded definition as the installed type, field by field
by name (fields the installed type lacks are dropped, new fields get their defaults; a value
the installed field cannot hold exactly is a :class:`DefinitionConversionError`). A field this
package moved is carried over rather than dropped: ``HandObservation``'s ``PatchBlob[] blobs``
(before session 27) fills its parallel blob arrays (:data:`MOVED_FIELDS`)."""
from __future__ import annotations

from dataclasses import dataclass, fields, is_dataclass
from typing import Any

import numpy as np
from rosbags.interfaces import MessageDefinitionFormat, Nodetype
from rosbags.typesys.store import Typestore

__all__ = ['DefinitionChange', 'DefinitionConversionError', 'MOVED_FIELDS', 'convert_message',
           'definition_changes']

_OBSERVATION = 'colorglove_msgs/msg/HandObservation'

_BASE, _NAME, _ARRAY, _SEQUENCE = Nodetype.BASE, Nodetype.NAME, Nodetype.ARRAY, Nodetype.SEQUENCE
# (rosbags reads and writes a scalar ``byte`` as signed)
_NUMPY_TYPES = {'bool': np.bool_, 'byte': np.int8, 'char': np.uint8, 'int8': np.int8,
                'uint8': np.uint8, 'int16': np.int16, 'uint16': np.uint16,
                'int32': np.int32, 'uint32': np.uint32, 'int64': np.int64,
                'uint64': np.uint64, 'float32': np.float32, 'float64': np.float64}


class DefinitionConversionError(ValueError):
    """A recorded value the installed definition of its field cannot hold (named by its dotted
    field path)."""


@dataclass(frozen=True)
class DefinitionChange:
    """How a topic's recorded message definition differs from the installed one."""

    topic: str
    msgtype: str
    dropped: tuple[str, ...]     # recorded fields the installed type lacks (dotted paths)
    added: tuple[str, ...]       # installed fields the recording lacks (get their defaults)
    retyped: tuple[str, ...]     # fields of both whose type differs
    convertible: bool = True     # False: the bag does not hold the definition it was recorded with

    def describe(self) -> str:
        """One line for the user."""
        if not self.convertible:
            return (f'{self.topic}: recorded with another definition of {self.msgtype} than '
                    'the installed one (its type hash differs), and the bag does not hold that '
                    'definition, so its messages cannot be converted')
        moves = _moved_in(self)
        moved = [f'{old} -> {", ".join(new)}' for old, new in moves]
        # a moved field and its elements are converted, neither dropped nor at defaults
        dropped = [path for path in self.dropped
                   if not any(path == old or path.startswith(f'{old}[]') for old, _ in moves)]
        added = [path for path in self.added if not any(path in new for _, new in moves)]
        parts = [f'{name} {", ".join(items)}' for name, items in
                 (('dropped:', dropped), ('new, at defaults:', added),
                  ('retyped:', self.retyped), ('converted:', moved)) if items]
        return (f'{self.topic}: recorded with another definition of {self.msgtype} than the '
                f'installed one ({"; ".join(parts) or "same field names, other layout"})')


def _blobs_as_arrays(present: dict[str, Any], values: dict[str, Any], path: str) -> None:
    """A ``HandObservation`` recorded with ``PatchBlob[] blobs``: its blobs into the
    installed parallel arrays (colour, (x, y), pixel count), each value kept exactly."""
    blobs = present['blobs']
    values['blob_colors'] = _exact_numbers([b.color_label for b in blobs], np.uint8,
                                           f'{path}blobs[].color_label')
    values['blob_centroids'] = _exact_numbers(
        [value for b in blobs for value in (b.x, b.y)], np.float64, f'{path}blobs[].x/y')
    values['blob_pixel_counts'] = _exact_numbers([b.pixel_count for b in blobs], np.uint32,
                                                 f'{path}blobs[].pixel_count')


# (type, recorded field, installed fields it fills, conversion(recorded fields, installed
# values, dotted prefix)): fields this package moved, converted instead of dropped
MOVED_FIELDS = ((_OBSERVATION, 'blobs', ('blob_colors', 'blob_centroids', 'blob_pixel_counts'),
                 _blobs_as_arrays),)


def _moved_in(change: DefinitionChange) -> list[tuple[str, tuple[str, ...]]]:
    """(recorded path, installed paths) of the :data:`MOVED_FIELDS` a change converts."""
    out = []
    for path in change.dropped:
        for _, old, new, _ in MOVED_FIELDS:
            prefix = path[:-len(old)]
            if path.endswith(old) and (not prefix or prefix.endswith('.')) and all(
                    f'{prefix}{name}' in change.added for name in new):
                out.append((path, tuple(f'{prefix}{name}' for name in new)))
    return out


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
            out[path] = f'{spec[0]}<={spec[1]}' if spec[1] else spec[0]
    return out


def definition_changes(connections: list[Any], recorded: Typestore, installed: Typestore
                       ) -> list[DefinitionChange]:
    """The topics of ``connections`` (rosbags connections) recorded with another definition
    of their type than the installed one. ``recorded``: the reader's type store, built from the
    definitions the bag holds. With the definition in the bag its hash is compared (and the
    change can be converted); without it, the recorded RIHS01 type hash (not convertible).
    Types the installed store does not know, and recordings with neither, are not judged."""
    changes = []
    for connection in connections:
        msgtype = connection.msgtype
        if msgtype not in installed.fielddefs:
            continue
        installed_hash = installed.hash_rihs01(msgtype)
        msgdef = getattr(connection, 'msgdef', None)
        held = msgdef is not None and msgdef.format != MessageDefinitionFormat.NONE
        if held:
            if recorded.hash_rihs01(msgtype) == installed_hash:
                continue
        else:
            digest = getattr(connection, 'digest', '') or ''
            if not digest.startswith('RIHS01_') or digest == installed_hash:
                continue
            changes.append(DefinitionChange(connection.topic, msgtype, (), (), (), False))
            continue
        old = _field_types(recorded, msgtype)
        new = _field_types(installed, msgtype)
        changes.append(DefinitionChange(
            connection.topic, msgtype,
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
    size = count if kind == _ARRAY else 0
    if inner_kind == _BASE and inner_spec[0] in _NUMPY_TYPES:
        return np.zeros(size, _NUMPY_TYPES[inner_spec[0]])
    return [_default(store, inner_kind, inner_spec) for _ in range(size)]


def _exact_numbers(value: Any, dtype: type, path: str) -> np.ndarray:
    """``value`` (number or array) as ``dtype``, refused unless every value is kept exactly."""
    source = np.asarray(value)
    if source.dtype.kind not in 'biuf':
        raise DefinitionConversionError(f'{path}: recorded {source.dtype} values cannot become '
                                        f'{np.dtype(dtype).name}')
    with np.errstate(all='ignore'):
        converted = source.astype(dtype)
        kept = np.array_equal(converted.astype(np.float64), source.astype(np.float64),
                              equal_nan=np.dtype(dtype).kind == 'f')
    if not kept:
        raise DefinitionConversionError(f'{path}: recorded values do not fit '
                                        f'{np.dtype(dtype).name}')
    return converted


def _bounded(size: int, bound: int, path: str) -> None:
    if bound and size > bound:
        raise DefinitionConversionError(f'{path}: {size} recorded, at most {bound} installed')


def _convert(value: Any, store: Typestore, kind: int, spec: Any, path: str) -> Any:
    if kind == _BASE:
        if spec[0] in ('string', 'wstring'):
            if not isinstance(value, str):
                raise DefinitionConversionError(f'{path}: a recorded {type(value).__name__} '
                                                'cannot become a string')
            _bounded(len(value), spec[1], path)
            return value
        if not np.isscalar(value) or isinstance(value, str):
            raise DefinitionConversionError(f'{path}: a recorded {type(value).__name__} cannot '
                                            f'become a {spec[0]}')
        return _exact_numbers(value, _NUMPY_TYPES[spec[0]], path).item()
    if kind == _NAME:
        if not is_dataclass(value):
            raise DefinitionConversionError(f'{path}: a recorded {type(value).__name__} cannot '
                                            f'become a {spec}')
        return convert_message(value, spec, store, f'{path}.')
    (inner_kind, inner_spec), count = spec
    if isinstance(value, (str, bytes)) or not hasattr(value, '__len__'):
        raise DefinitionConversionError(f'{path}: a recorded {type(value).__name__} cannot '
                                        'become an array')
    if kind == _ARRAY and len(value) != count:
        raise DefinitionConversionError(f'{path}: a fixed array of {count} recorded with '
                                        f'{len(value)} values')
    if kind == _SEQUENCE:
        _bounded(len(value), count, path)
    if inner_kind == _BASE and inner_spec[0] in _NUMPY_TYPES:
        return _exact_numbers(value, _NUMPY_TYPES[inner_spec[0]], f'{path}[]')
    return [_convert(item, store, inner_kind, inner_spec, f'{path}[{k}]')
            for k, item in enumerate(value)]


def convert_message(message: Any, msgtype: str, store: Typestore, prefix: str = '') -> Any:
    """``message`` (decoded with any definition of ``msgtype``; None for all defaults) as an
    instance of ``store``'s definition: fields matched by name, recursively (``prefix``: the
    dotted path of ``message`` in its parent, for errors). A value the installed field cannot
    hold exactly is a :class:`DefinitionConversionError` naming the field."""
    present = ({f.name: getattr(message, f.name) for f in fields(message)}
               if is_dataclass(message) else {})
    values = {}
    for name, (kind, spec) in store.fielddefs[msgtype][1]:
        values[name] = (_convert(present[name], store, kind, spec, f'{prefix}{name}')
                        if name in present else _default(store, kind, spec))
    installed = {name for name, _ in store.fielddefs[msgtype][1]}
    for kind, old, new, move in MOVED_FIELDS:
        if (kind == msgtype and old in present and old not in installed
                and set(new) <= installed and not set(new) & set(present)):
            move(present, values, prefix)
    return store.types[msgtype](**values)
