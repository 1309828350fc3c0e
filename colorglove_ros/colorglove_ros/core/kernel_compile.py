"""Compiling numba kernels ahead of the first frame, for the compiled inner loops of the IK
(``core.tracking.ik_kernel``), the segmenter (``core.segmentation.segmentation_kernel``), the
lookup (``core.lookup.lookup_kernel``) and the edge tracker (``core.tracking.edge_kernel``):
each kernel for its one signature (or loaded from numba's on-disk cache), then no other, so
no frame pays for a compilation and an argument of another type or layout raises. Imports no
numba itself."""
from __future__ import annotations

import time
from collections.abc import Mapping
from typing import Any

__all__ = ['compile_signatures']

_DONE: set[int] = set()   # the signature tables compiled in this process, by id


def compile_signatures(signatures: Mapping[Any, Any]) -> float:
    """Compile each numba dispatcher of ``signatures`` for its signature unless it has one,
    then disable compiling it; returns the seconds it took. Once per table and process: a
    later call returns 0 at once (a set lookup, not the dispatchers' signatures, which cost
    tens of microseconds to list), so a caller may ask before every use."""
    if id(signatures) in _DONE:
        return 0.0
    started = time.perf_counter()
    for kernel, signature in signatures.items():
        if not kernel.signatures:
            kernel.compile(signature)
            kernel.disable_compile()
    _DONE.add(id(signatures))
    return time.perf_counter() - started
