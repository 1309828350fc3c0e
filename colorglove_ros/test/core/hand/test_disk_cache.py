"""The on-disk cache of the hand mesh and glove arrays: identical to a fresh build, keyed by
the source files, rebuilt when its file is damaged."""
from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from colorglove_ros.core.hand import disk_cache
from colorglove_ros.core.hand.disk_cache import cached_arrays


def test_cached_arrays_round_trip_and_key(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv(disk_cache.CACHE_DIR_VARIABLE, str(tmp_path / 'cache'))
    source = tmp_path / 'source.py'
    source.write_text('a = 1\n')
    builds = []

    def build() -> dict[str, np.ndarray]:
        builds.append(1)
        return {'x': np.arange(5, dtype=np.int32), 'y': np.eye(2)}

    first = cached_arrays('thing', [source], build)
    second = cached_arrays('thing', [source], build)
    assert len(builds) == 1
    for key in first:
        assert np.array_equal(first[key], second[key]) and first[key].dtype == second[key].dtype
    source.write_text('a = 2\n')               # the code changed: built afresh
    cached_arrays('thing', [source], build)
    assert len(builds) == 2
    for path in (tmp_path / 'cache').glob('thing-*.npz'):
        path.write_bytes(b'not a zip file')    # damaged: rebuilt, not an error
    assert np.array_equal(cached_arrays('thing', [source], build)['x'], np.arange(5))
    assert len(builds) == 3


def test_default_hand_from_cache_equals_a_fresh_build(tmp_path: Path) -> None:
    """In fresh processes: the cached mesh and glove are the built ones, and a process that
    finds them cached imports neither trimesh nor scipy."""
    code = (
        'import sys, numpy as np\n'
        'from colorglove_ros.core.hand.glove import default_hand, make_glove\n'
        'from colorglove_ros.core.hand.mesh import _build_arrays\n'
        'model, mesh, glove = default_hand(0.19)\n'
        'print("heavy", "trimesh" in sys.modules or "scipy" in sys.modules)\n'
        'built = _build_arrays(0.19)\n'
        'assert all(np.array_equal(built[k], getattr(mesh, k)) for k in built)\n'
        'fresh = make_glove(mesh, seed=0, model=model)\n'
        'assert np.array_equal(fresh.face_patch, glove.face_patch)\n'
        'assert np.array_equal(fresh.patch_color, glove.patch_color)\n')
    env = {**os.environ, disk_cache.CACHE_DIR_VARIABLE: str(tmp_path)}
    runs = [subprocess.run([sys.executable, '-c', code], env=env, capture_output=True,
                           text=True, timeout=120) for _ in range(2)]
    for run in runs:
        assert run.returncode == 0, run.stderr
    assert 'heavy True' in runs[0].stdout       # first run builds with trimesh and scipy
    assert 'heavy False' in runs[1].stdout      # second run loads the cache


def test_segmentation_node_imports_neither_trimesh_nor_scipy() -> None:
    """Importing the node loads none of the heavy modules: numba (which loads scipy) comes
    with the segmenter's compiled kernels when the node builds its segmenter
    (``crop.compiled_kernels``), not with the import."""
    code = ('import sys, colorglove_ros.ros.nodes.segmentation_node\n'
            'print(sorted(m for m in ("trimesh", "scipy", "sklearn", "numba")'
            ' if m in sys.modules))')
    run = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True,
                         timeout=120)
    assert run.returncode == 0, run.stderr
    assert run.stdout.strip() == '[]'
