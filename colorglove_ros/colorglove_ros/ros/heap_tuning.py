"""Keep freed camera-frame buffers in the process's heap instead of returning them to the
kernel: :func:`keep_freed_buffers`, called by every node process before it starts.

A node taking 640x480 images allocates and frees several buffers of about a megabyte per
frame (the taken message, its Python bytes, decoded arrays). glibc's malloc serves blocks that
large with a fresh ``mmap`` and trims the top of its heap once more than twice that much is
free, so each frame's buffers come back as new pages: a page fault for every page of them, every
frame, paid in the kernel on the image's path (figures: docs/RESULTS.md, Speed (issue 19),
"Session 32"). Raising the mmap threshold above a frame's size and the trim threshold above a
few frames' worth keeps the pages mapped between frames; the heap then holds on to at most
``TRIM_THRESHOLD_BYTES`` of free memory beyond the process's peak use.

Only glibc has these settings; elsewhere nothing changes. A process whose environment already
sets glibc's malloc variables (``MALLOC_MMAP_THRESHOLD_``, ``MALLOC_TRIM_THRESHOLD_`` or malloc
tunables in ``GLIBC_TUNABLES``) keeps its own choice."""
from __future__ import annotations

import ctypes
import os
import platform
from collections.abc import Mapping
from dataclasses import dataclass

__all__ = ['MMAP_THRESHOLD_BYTES', 'TRIM_THRESHOLD_BYTES', 'HeapTuning', 'keep_freed_buffers']

#: Blocks below this size come from the heap (glibc's largest allowed value on 64-bit; a
#: 3840x2160 rgb8 frame is 24.9 MB).
MMAP_THRESHOLD_BYTES = 32 * 1024 * 1024
#: Free memory at the heap's top kept mapped (twice the mmap threshold, as glibc's own rule).
TRIM_THRESHOLD_BYTES = 2 * MMAP_THRESHOLD_BYTES

# mallopt parameters, <malloc.h>
_M_TRIM_THRESHOLD = -1
_M_MMAP_THRESHOLD = -3

_ENVIRONMENT_SETTINGS = ('MALLOC_MMAP_THRESHOLD_', 'MALLOC_TRIM_THRESHOLD_')


@dataclass(frozen=True)
class HeapTuning:
    """What :func:`keep_freed_buffers` did: whether it set the thresholds, and a sentence."""

    applied: bool
    note: str


def _environment_choice(environ: Mapping[str, str]) -> str | None:
    """The environment variable that already sets glibc's malloc thresholds, or None."""
    for name in _ENVIRONMENT_SETTINGS:
        if name in environ:
            return name
    if 'glibc.malloc.' in environ.get('GLIBC_TUNABLES', ''):
        return 'GLIBC_TUNABLES'
    return None


def keep_freed_buffers(environ: Mapping[str, str] | None = None) -> HeapTuning:
    """Set glibc malloc's mmap and trim thresholds for this process (module docstring) unless
    the environment (default ``os.environ``) already sets them or the C library is not glibc;
    say what was done."""
    environ = os.environ if environ is None else environ
    chosen = _environment_choice(environ)
    if chosen is not None:
        return HeapTuning(False, f'malloc thresholds left to the environment ({chosen})')
    if platform.libc_ver()[0] != 'glibc':
        return HeapTuning(False, 'malloc thresholds unchanged: the C library is not glibc')
    mallopt = ctypes.CDLL(None).mallopt
    mallopt.argtypes = (ctypes.c_int, ctypes.c_int)
    mallopt.restype = ctypes.c_int
    # mallopt returns 1 on success
    if not (mallopt(_M_MMAP_THRESHOLD, MMAP_THRESHOLD_BYTES)
            and mallopt(_M_TRIM_THRESHOLD, TRIM_THRESHOLD_BYTES)):
        return HeapTuning(False, 'malloc thresholds unchanged: glibc refused them')
    return HeapTuning(True, f'malloc keeps freed blocks below {MMAP_THRESHOLD_BYTES >> 20} MiB '
                            f'in the heap')
