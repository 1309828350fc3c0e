"""Remove the Fast DDS shared-memory segments of participants that no longer exist.

Each Fast DDS participant maps a segment ``/dev/shm/fastrtps_<id>`` (32 MiB with
``config/fastdds_profile.xml``) and holds an exclusive ``flock`` on ``fastrtps_<id>_el`` while
it lives. A process killed with SIGKILL cannot unlink them, and Fast DDS only reclaims them
much later, so repeated crashes pile up memory. A segment whose lock file nobody holds (and
that is older than a few seconds, so a participant being created right now is never touched)
is stale: removing it is what ``fastdds shm clean`` does. Listening-port segments
(``fastrtps_port<N>``) are shared and repaired by Fast DDS itself and are left alone.
"""
from __future__ import annotations

import fcntl
import os
import time
from pathlib import Path

__all__ = ['SHM_FOLDER', 'stale_fastdds_segments', 'clean_stale_fastdds_segments']

SHM_FOLDER = Path('/dev/shm')
MIN_AGE_S = 3.0


def _lock_is_free(lock: Path) -> bool:
    """Whether no process holds ``lock`` (an exclusive, non-blocking flock succeeds)."""
    try:
        fd = os.open(lock, os.O_RDONLY)
    except OSError:
        return False
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError:
        return False
    else:
        fcntl.flock(fd, fcntl.LOCK_UN)
        return True
    finally:
        os.close(fd)


def stale_fastdds_segments(folder: Path = SHM_FOLDER, min_age_s: float = MIN_AGE_S
                           ) -> list[Path]:
    """Participant segments (and their lock files) whose owner is gone."""
    if not folder.is_dir():
        return []
    now = time.time()
    stale = []
    for lock in sorted(folder.glob('fastrtps_*_el')):
        if lock.name.startswith('fastrtps_port'):
            continue
        try:
            age = now - lock.stat().st_mtime
        except OSError:
            continue
        if age >= min_age_s and _lock_is_free(lock):
            segment = lock.with_name(lock.name[:-len('_el')])
            stale += [p for p in (segment, lock) if p.exists()]
    return stale


def clean_stale_fastdds_segments(folder: Path = SHM_FOLDER, min_age_s: float = MIN_AGE_S
                                 ) -> tuple[int, int]:
    """Remove stale participant segments; return (files removed, bytes freed)."""
    removed = freed = 0
    for path in stale_fastdds_segments(folder, min_age_s):
        try:
            size = path.stat().st_size
            path.unlink()
        except OSError:
            continue
        removed += 1
        freed += size
    return removed, freed
