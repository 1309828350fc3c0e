"""Checks of large files, remembered between runs: the CRC-32 of a file, or any check over a
set of files (the database's contents), is not done again while every file's size, inode,
modification and status-change times (``st_ctime_ns`` cannot be set back by a user) are those
of its last successful check. The record is a small JSON stamp file beside the files
(``.crc32_verified.json``); where it cannot be written every start checks again."""
from __future__ import annotations

import json
import os
import zlib
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

__all__ = ['STAMP_NAME', 'crc32_of_file', 'crc32_matches', 'check_unless_passed']

STAMP_NAME = '.crc32_verified.json'
STAMP_VERSION = 1   # "checks" is an optional section; older readers keep "files"


def crc32_of_file(path: Path) -> int:
    """CRC-32 of a file's bytes (read in 16 MiB chunks)."""
    crc = 0
    with Path(path).open('rb') as fh:
        while chunk := fh.read(1 << 24):
            crc = zlib.crc32(chunk, crc)
    return crc


def _identity(stat: os.stat_result) -> list[int]:
    return [stat.st_size, stat.st_ino, stat.st_mtime_ns, stat.st_ctime_ns]


def _read_stamp(stamp: Path) -> dict[str, Any]:
    """The stamp's record ({'files': name -> identity + crc, 'checks': name -> identities}),
    empty when missing, unreadable or of another version."""
    try:
        data = json.loads(stamp.read_text())
    except (OSError, ValueError):
        data = None
    if not isinstance(data, dict) or data.get('version') != STAMP_VERSION:
        return {'files': {}, 'checks': {}}
    return {key: data[key] if isinstance(data.get(key), dict) else {}
            for key in ('files', 'checks')}


def _write_stamp(stamp: Path, record: dict[str, Any]) -> None:
    """Replace the stamp atomically; a read-only folder just means checking again next time."""
    temporary = stamp.with_name(f'{STAMP_NAME}.{os.getpid()}.tmp')
    try:
        temporary.write_text(json.dumps({'version': STAMP_VERSION, **record}))
        os.replace(temporary, stamp)
    except OSError:
        temporary.unlink(missing_ok=True)


def crc32_matches(path: str | Path, expected: object) -> bool:
    """Whether ``path``'s CRC-32 equals ``expected``: from the stamp file when the file is
    unchanged since it last matched, else computed (and, when it matches, recorded)."""
    path = Path(path)
    stamp = path.parent / STAMP_NAME
    identity = _identity(path.stat())
    record = _read_stamp(stamp)
    if isinstance(expected, int) and record['files'].get(path.name) == identity + [expected]:
        return True
    if crc32_of_file(path) != expected:
        return False
    record = _read_stamp(stamp)
    record['files'][path.name] = identity + [int(expected)]
    _write_stamp(stamp, record)
    return True


def check_unless_passed(files: Sequence[str | Path], name: str,
                        check: Callable[[], None]) -> bool:
    """Run ``check`` (which raises on failure) unless check ``name`` last passed on exactly
    these ``files`` (all in one folder) and none has changed since; record a pass. ``name``
    must change whenever what the check accepts changes. Returns whether ``check`` ran."""
    paths = [Path(file) for file in files]
    folder = paths[0].parent
    if any(path.parent != folder for path in paths):
        raise ValueError('check_unless_passed: the files must share one folder')
    identities = {path.name: _identity(path.stat()) for path in paths}
    stamp = folder / STAMP_NAME
    if _read_stamp(stamp)['checks'].get(name) == identities:
        return False
    check()
    record = _read_stamp(stamp)
    record['checks'][name] = identities
    _write_stamp(stamp, record)
    return True
