"""CRC-32 checks of large files, remembered between runs: a file whose size, inode,
modification and status-change times (``st_ctime_ns`` cannot be set back by a user) are those
of its last successful check is not read again. The record is a small JSON stamp file beside
the files (``.crc32_verified.json``); where it cannot be written every start reads again."""
from __future__ import annotations

import json
import os
import zlib
from pathlib import Path

__all__ = ['STAMP_NAME', 'crc32_of_file', 'crc32_matches']

STAMP_NAME = '.crc32_verified.json'
STAMP_VERSION = 1


def crc32_of_file(path: Path) -> int:
    """CRC-32 of a file's bytes (read in 16 MiB chunks)."""
    crc = 0
    with Path(path).open('rb') as fh:
        while chunk := fh.read(1 << 24):
            crc = zlib.crc32(chunk, crc)
    return crc


def _identity(stat: os.stat_result, crc: int) -> list[int]:
    return [stat.st_size, stat.st_ino, stat.st_mtime_ns, stat.st_ctime_ns, int(crc)]


def _read_stamps(stamp: Path) -> dict[str, list[int]]:
    try:
        data = json.loads(stamp.read_text())
    except (OSError, ValueError):
        return {}
    if not isinstance(data, dict) or data.get('version') != STAMP_VERSION:
        return {}
    files = data.get('files')
    return files if isinstance(files, dict) else {}


def crc32_matches(path: str | Path, expected: object) -> bool:
    """Whether ``path``'s CRC-32 equals ``expected``: from the stamp file when the file is
    unchanged since it last matched, else computed (and, when it matches, recorded)."""
    path = Path(path)
    stamp = path.parent / STAMP_NAME
    stat = path.stat()
    stamps = _read_stamps(stamp)
    if isinstance(expected, int) and stamps.get(path.name) == _identity(stat, expected):
        return True
    if crc32_of_file(path) != expected:
        return False
    stamps[path.name] = _identity(stat, int(expected))
    temporary = stamp.with_name(f'{STAMP_NAME}.{os.getpid()}.tmp')
    try:
        temporary.write_text(json.dumps({'version': STAMP_VERSION, 'files': stamps}))
        os.replace(temporary, stamp)
    except OSError:
        temporary.unlink(missing_ok=True)   # read-only folder: verified again next start
    return True
