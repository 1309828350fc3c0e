"""Tests for the cache of the tracker's output on scripted sequences."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from small_databases import blob_database

from colorglove_ros.core.evaluation.scripted_hands import ScriptError
from colorglove_ros.core.evaluation.scripted_tracking import ScriptedTracker
from colorglove_ros.core.lookup.database import contents_tag, save_database


def _saved(tmp_path: Path, name: str, seed: int) -> Path:
    rng = np.random.default_rng(seed)
    tiny = np.zeros((4, 40, 40), np.uint8)
    for k in range(4):
        tiny[k, 5 + k:15 + k, 5:20] = 1 + k
    db = blob_database(tiny, rng.normal(size=(4, 26)), num_bits=8, num_pairs=20)
    return save_database(db, tmp_path / name)


def test_an_unreadable_database_manifest_is_a_script_error(tmp_path: Path) -> None:
    a = _saved(tmp_path, 'a', 0)
    manifest = json.loads((a / 'manifest.json').read_text())
    del manifest['arrays']['codes']
    (a / 'manifest.json').write_text(json.dumps(manifest))
    tracker = ScriptedTracker(a, Path('ik.yaml'), Path('cal.yaml'), tmp_path)
    with pytest.raises(ScriptError, match='manifest'):
        tracker._cache_path('spelling', 7, 3)
    missing = ScriptedTracker(tmp_path / 'missing', Path('ik.yaml'), Path('cal.yaml'), tmp_path)
    with pytest.raises(ScriptError):
        missing._cache_path('spelling', 7, 3)


def test_each_database_has_its_own_cache(tmp_path: Path) -> None:
    """Tracking with another database, or with the default database rebuilt, never reads the
    cache of the database before: every cache file is named by the database's contents."""
    truth = np.zeros((3, 26))
    first, rebuilt = _saved(tmp_path, 'a', 0), _saved(tmp_path, 'b', 1)
    before = ScriptedTracker(first, Path('ik.yaml'), Path('cal.yaml'), tmp_path)
    after = ScriptedTracker(rebuilt, Path('ik.yaml'), Path('cal.yaml'), tmp_path)
    path = before._cache_path('spelling', 7, 3)
    np.savez_compressed(path, version=1, q_true=truth, q_est=truth + 1.0,
                        found=np.ones(3, bool))
    assert before._load(path, truth) is not None
    assert path.name == f'spelling_7_3_segmented_{contents_tag(first)}.npz'
    other = after._cache_path('spelling', 7, 3)
    assert other != path and not other.exists()
