"""Arrays derived deterministically from the package's own code (the hand mesh, the glove
pattern), kept on disk so a (re)started node loads them instead of rebuilding them with
trimesh and scipy. The cache key holds a hash of the source files the arrays come from, so any
change to that code builds them afresh."""
from __future__ import annotations

import hashlib
import os
import tempfile
import zipfile
from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np

__all__ = ['CACHE_DIR_VARIABLE', 'cache_dir', 'cached_arrays']

CACHE_DIR_VARIABLE = 'COLORGLOVE_CACHE_DIR'   # set to an empty string to disable the cache
CACHE_FORMAT = 1


def cache_dir() -> Path | None:
    """``$COLORGLOVE_CACHE_DIR``, else ``$XDG_CACHE_HOME/colorglove_ros`` (``~/.cache``);
    None when disabled."""
    configured = os.environ.get(CACHE_DIR_VARIABLE)
    if configured is not None:
        return Path(configured).expanduser() if configured else None
    base = os.environ.get('XDG_CACHE_HOME') or Path.home() / '.cache'
    return Path(base) / 'colorglove_ros'


def _source_hash(sources: Sequence[Path]) -> str:
    digest = hashlib.sha1(f'format {CACHE_FORMAT}'.encode())
    for path in sources:
        digest.update(Path(path).read_bytes())
    return digest.hexdigest()[:16]


def cached_arrays(name: str, sources: Sequence[Path],
                  build: Callable[[], dict[str, np.ndarray]]) -> dict[str, np.ndarray]:
    """The arrays ``build()`` returns, read from the cache file of ``name`` and the hash of
    ``sources`` when present, else built and written there (atomically). An unreadable or
    incomplete file is rebuilt; an unwritable cache folder only costs the rebuild."""
    folder = cache_dir()
    if folder is None:
        return build()
    path = folder / f'{name}-{_source_hash(sources)}.npz'
    try:
        with np.load(path, allow_pickle=False) as data:
            return {key: data[key] for key in data.files}
    except (OSError, ValueError, KeyError, zipfile.BadZipFile):
        pass
    arrays = build()
    try:
        folder.mkdir(parents=True, exist_ok=True)
        with tempfile.NamedTemporaryFile(dir=folder, suffix='.npz', delete=False) as tmp:
            np.savez(tmp, **arrays)
        os.replace(tmp.name, path)
    except OSError:
        pass
    return arrays
