"""Tests for the cache of the tracker's output on scripted sequences."""
from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest
import yaml
from repo_paths import CONFIG_DIR
from small_databases import blob_database

from colorglove_ros.core.evaluation.scripted_hands import ScriptError
from colorglove_ros.core.evaluation.scripted_tracking import (
    TRACKED_FORMAT_VERSION,
    ScriptedTracker,
    settings_tag,
    tracking_settings,
    tracking_sources,
)
from colorglove_ros.core.evaluation.sequences import EVIDENCE_FIELDS
from colorglove_ros.core.hand.observation_features import empty_observation_record
from colorglove_ros.core.lookup.database import contents_tag, save_database
from colorglove_ros.core.pipeline import NODE_LIMITS, UNGATED


def _saved(tmp_path: Path, name: str, seed: int) -> Path:
    rng = np.random.default_rng(seed)
    tiny = np.zeros((4, 40, 40), np.uint8)
    for k in range(4):
        tiny[k, 5 + k:15 + k, 5:20] = 1 + k
    db = blob_database(tiny, rng.normal(size=(4, 26)), num_bits=8, num_pairs=20)
    return save_database(db, tmp_path / name)


IK, CAMERAS = CONFIG_DIR / 'ik.yaml', CONFIG_DIR / 'calibration.yaml'


def test_an_unreadable_database_manifest_is_a_script_error(tmp_path: Path) -> None:
    a = _saved(tmp_path, 'a', 0)
    manifest = json.loads((a / 'manifest.json').read_text())
    del manifest['arrays']['codes']
    (a / 'manifest.json').write_text(json.dumps(manifest))
    tracker = ScriptedTracker(a, IK, CAMERAS, tmp_path)
    with pytest.raises(ScriptError, match='manifest'):
        tracker._cache_path('spelling', 7, 3)
    missing = ScriptedTracker(tmp_path / 'missing', IK, CAMERAS, tmp_path)
    with pytest.raises(ScriptError):
        missing._cache_path('spelling', 7, 3)


def test_each_database_has_its_own_cache(tmp_path: Path) -> None:
    """Tracking with another database, or with the default database rebuilt, never reads the
    cache of the database before: every cache file is named by the database's contents."""
    truth = np.zeros((3, 26))
    first, rebuilt = _saved(tmp_path, 'a', 0), _saved(tmp_path, 'b', 1)
    before = ScriptedTracker(first, IK, CAMERAS, tmp_path)
    after = ScriptedTracker(rebuilt, IK, CAMERAS, tmp_path)
    path = before._cache_path('spelling', 7, 3)
    _write_cache(path, truth)
    assert before._load(path, truth) is not None
    tag = settings_tag(tracking_settings(IK, CAMERAS, 'segmented'))
    assert path.name == f'spelling_7_3_segmented_{contents_tag(first)}_{tag}.npz'
    other = after._cache_path('spelling', 7, 3)
    assert other != path and not other.exists()


def _edited_ik(tmp_path: Path, name: str, **changes: object) -> Path:
    data = yaml.safe_load(IK.read_text())
    data.update(changes)
    path = tmp_path / f'{name}.yaml'
    path.write_text(yaml.safe_dump(data))
    return path


def test_each_ik_config_camera_and_label_source_has_its_own_cache(tmp_path: Path) -> None:
    """A cache made with one ``ik.yaml`` is never read with another that tracks differently
    (one IK setting changed, or the covariances of a covariance file), nor with another
    primary camera, label source or pipeline gates; the same settings written differently (no
    comments, other order) read the same cache."""
    from colorglove_ros.core.tracking.config import default_covariances, save_covariances

    truth = np.zeros((3, 26))
    db = _saved(tmp_path, 'a', 0)
    base = ScriptedTracker(db, IK, CAMERAS, tmp_path)
    path = base._cache_path('gestures', 7, 3)
    _write_cache(path, truth)
    same = ScriptedTracker(db, _edited_ik(tmp_path, 'same'), CAMERAS, tmp_path)
    assert same._cache_path('gestures', 7, 3) == path
    cov = default_covariances()
    cov_file = save_covariances(tmp_path / 'cov.yaml', cov)
    assert ScriptedTracker(db, _edited_ik(tmp_path, 'cov_same', covariance_file=str(cov_file)),
                           CAMERAS, tmp_path)._cache_path('gestures', 7, 3) == path
    save_covariances(tmp_path / 'cov2.yaml', type(cov)(cov.r_var_px2 * 4, cov.q_var, cov.p_var))
    camera = yaml.safe_load(CAMERAS.read_text())
    camera['cameras'][0]['fx'] = 500.0
    (tmp_path / 'cameras.yaml').write_text(yaml.safe_dump(camera))
    others = [ScriptedTracker(db, _edited_ik(tmp_path, 'iterations', max_iterations=4), CAMERAS,
                              tmp_path),
              ScriptedTracker(db, _edited_ik(tmp_path, 'blob_ratio', max_blob_ratio=3.0), CAMERAS,
                              tmp_path),
              ScriptedTracker(db, _edited_ik(tmp_path, 'cov', covariance_file=str(
                  tmp_path / 'cov2.yaml')), CAMERAS, tmp_path),
              ScriptedTracker(db, IK, tmp_path / 'cameras.yaml', tmp_path),
              ScriptedTracker(db, IK, CAMERAS, tmp_path, labels='truth'),
              ScriptedTracker(db, IK, CAMERAS, tmp_path, limits=UNGATED)]
    names = {other._cache_path('gestures', 7, 3) for other in others}
    assert path not in names and len(names) == len(others)
    assert all(other._load(other._cache_path('gestures', 7, 3), truth) is None
               for other in others)


def test_a_change_of_the_tracking_code_gives_another_cache(tmp_path: Path,
                                                          monkeypatch: pytest.MonkeyPatch) -> None:
    """The cache name holds a checksum of the tracking code: a changed statement in a module
    the tracking runs (the IK solver, the per-finger blend) gives another name whose cache is
    not there; a changed comment or docstring, or a change to a module the tracking does not
    import (the gesture detector), reads the same cache."""
    from colorglove_ros.core.evaluation import scripted_tracking

    copy = tmp_path / 'src'
    shutil.copytree(scripted_tracking.SOURCE_ROOT / 'colorglove_ros', copy / 'colorglove_ros',
                    ignore=shutil.ignore_patterns('__pycache__'))
    monkeypatch.setattr(scripted_tracking, 'SOURCE_ROOT', copy)
    db, truth = _saved(tmp_path, 'a', 0), np.zeros((3, 26))

    def cache() -> Path:
        return ScriptedTracker(db, IK, CAMERAS, tmp_path)._cache_path('gestures', 7, 3)

    def edit(module: str, old: str, new: str) -> str:
        path = copy / 'colorglove_ros' / module
        text = path.read_text()
        assert old in text
        path.write_text(text.replace(old, new, 1))
        return text

    first = cache()
    _write_cache(first, truth)
    solver = edit('core/tracking/solver.py', '\n\n', '\n\n# a comment\n\n')
    edit('core/tracking/solver.py', '"""', '"""Another docstring. ')
    edit('core/hand/gestures.py', '\n\n', '\n\n_NOT_TRACKING = 1\n\n')
    assert cache() == first
    (copy / 'colorglove_ros/core/tracking/solver.py').write_text(solver + '\n_CHANGED = 1\n')
    changed = cache()
    assert changed != first and ScriptedTracker(db, IK, CAMERAS, tmp_path)._load(
        changed, truth) is None
    (copy / 'colorglove_ros/core/tracking/solver.py').write_text(solver)
    assert cache() == first
    edit('core/lookup/finger_evidence.py', 'sigma_tiny_px: float = 1.0',
         'sigma_tiny_px: float = 1.5')
    assert cache() not in (first, changed)


def test_the_tracking_sources_are_the_modules_the_tracking_imports(tmp_path: Path) -> None:
    """The code checksum reads every package module the tracking imports at any depth
    (function-level and relative imports too, and the packages' ``__init__``), and no other."""
    from colorglove_ros.core.evaluation.scripted_tracking import SOURCE_ROOT

    names = {p.relative_to(SOURCE_ROOT / 'colorglove_ros').as_posix() for p in tracking_sources()}
    assert {'__init__.py', 'core/evaluation/scripted_tracking.py', 'core/tracking/solver.py',
            'core/tracking/tracker.py',
            'core/lookup/__init__.py', 'core/lookup/finger_evidence.py', 'core/pipeline.py',
            'core/segmentation/segmenter.py', 'core/synthetic/render.py'} <= names
    assert not any(n in ('core/hand/gestures.py', 'core/hand/spelling.py') or
                   n.startswith(('tools/', 'ros/')) for n in names)
    package = tmp_path / 'colorglove_ros'
    (package / 'sub').mkdir(parents=True)
    for name, text in {'__init__.py': '', 'sub/__init__.py': '',
                       'sub/a.py': 'from . import b\nfrom ..c import X\n',
                       'sub/b.py': 'def f():\n    import colorglove_ros.d\n',
                       'c.py': 'import numpy\nX = 1\n', 'd.py': '', 'e.py': ''}.items():
        (package / name).write_text(text)
    found = tracking_sources(('colorglove_ros.sub.a',), root=tmp_path)
    assert [p.relative_to(package).as_posix() for p in found] == [
        '__init__.py', 'c.py', 'd.py', 'sub/__init__.py', 'sub/a.py', 'sub/b.py']


def _write_cache(path: Path, truth: np.ndarray, version: int = TRACKED_FORMAT_VERSION,
                 evidence: bool = True) -> None:
    fields = {f'evidence_{k}': np.arange(len(truth), dtype=float) for k in EVIDENCE_FIELDS} \
        if evidence else {}
    if version >= 3:
        seen = empty_observation_record(len(truth))
        seen['tiny_labels'][:, 3, 4] = 5
        fields.update({f'observation_{k}': v for k, v in seen.items()})
    np.savez_compressed(path, version=version, q_true=truth, q_est=truth + 1.0,
                        found=np.ones(len(truth), bool), **fields)


def test_the_cache_holds_the_trackers_evidence_per_frame(tmp_path: Path) -> None:
    """The cache gives back the tracker's evidence with the poses; a cache written before the
    evidence was recorded (format 1) is not read (the sequence is tracked anew)."""
    truth = np.zeros((3, 26))
    tracker = ScriptedTracker(_saved(tmp_path, 'a', 0), IK, CAMERAS,
                              tmp_path)
    path = tracker._cache_path('gestures', 7, 3)
    _write_cache(path, truth)
    loaded = tracker._load(path, truth)
    assert loaded is not None and set(loaded.evidence) == set(EVIDENCE_FIELDS)
    np.testing.assert_array_equal(loaded.evidence['image_distance'], [0.0, 1.0, 2.0])
    _write_cache(path, truth, version=1, evidence=False)
    assert tracker._load(path, truth) is None


def test_the_cache_holds_the_observation_and_reads_an_evidence_only_cache(tmp_path: Path) -> None:
    """A format 3 cache gives back the primary camera's observation per frame (tiny label
    image, blobs); a format 2 cache (evidence, no observation) still serves the poses and the
    evidence, but not a caller that needs the observation (tracked anew)."""
    truth = np.zeros((3, 26))
    tracker = ScriptedTracker(_saved(tmp_path, 'a', 0), IK, CAMERAS,
                              tmp_path)
    path = tracker._cache_path('spelling', 7, 3)
    _write_cache(path, truth)
    loaded = tracker._load(path, truth, observation=True)
    assert loaded is not None
    assert set(loaded.observation) == set(empty_observation_record(0))
    assert loaded.observation['tiny_labels'].shape == (3, 40, 40)
    assert loaded.observation['tiny_labels'][2, 3, 4] == 5
    _write_cache(path, truth, version=2)
    old = tracker._load(path, truth)
    assert old is not None and old.observation == {}
    np.testing.assert_array_equal(old.q_est, truth + 1.0)
    assert tracker._load(path, truth, observation=True) is None


def test_the_consumers_get_the_poses_the_nodes_publish(small_database_path: Path,
                                                      tmp_path: Path) -> None:
    """By default a scripted sequence is tracked through the nodes' gates (NODE_LIMITS): a
    hand the image's border cuts is no hand, as ik_node refuses it, while UNGATED tracks
    every frame; a hand in view is tracked either way."""
    from repo_paths import CONFIG_DIR

    from colorglove_ros.core.camera import load_calibration
    from colorglove_ros.core.evaluation.scripted_hands import ScriptedSequence
    from colorglove_ros.core.hand.model import HandModel

    model = HandModel()
    camera = load_calibration(str(CONFIG_DIR / 'calibration.yaml')).cameras[0]
    fingers = np.zeros(20)
    q_in = np.concatenate([[0.0, 0.0, 0.45], [0.0, 0.0, 0.0], fingers])
    # far to the left at the same depth: the fingers leave the image, the palm stays in it
    q_cut = q_in.copy()
    q_cut[0] = -(camera.cx / camera.fx) * 0.45 - 0.02
    uv = camera.project(model.keypoints(q_cut))
    assert (uv[:, 0] < 0).any() and (uv[:, 0] >= 0).any()
    poses = np.stack([q_in] * 3 + [q_cut] * 3)
    truth = ScriptedSequence(poses, np.array([0, 0, 0, 1, 1, 1]), np.array([''] * 6),
                             np.ones(6, bool), 30.0)
    found = {}
    for name, limits in (('nodes', NODE_LIMITS), ('ungated', UNGATED)):
        tracker = ScriptedTracker(small_database_path, CONFIG_DIR / 'ik.yaml',
                                  CONFIG_DIR / 'calibration.yaml', tmp_path / name,
                                  labels='truth', limits=limits)
        try:
            found[name] = tracker.track('gates', 1, truth, model).found
        finally:
            if tracker._evaluator is not None:
                tracker._evaluator.close()
    assert found['ungated'][3:].all() and not found['nodes'][3:].any(), found
    assert found['nodes'][:3].any() and found['ungated'][:3].any(), found


def test_hold_frames_are_rendered_through_the_segmentation_and_cached(
        small_database_path: Path, tmp_path: Path) -> None:
    """hold_observations renders every ``every``-th frame of each hold (renderer labels here)
    and records its tiny image and blobs; a second call reads the cache without rendering."""
    from repo_paths import CONFIG_DIR

    from colorglove_ros.core.evaluation.scripted_hands import script_poses
    from colorglove_ros.core.hand.model import HandModel
    from colorglove_ros.tools.eval_spelling import spelling_script

    segments = spelling_script(HandModel(), 1200, 1)[0][:2]
    truth = script_poses(segments)
    tracker = ScriptedTracker(small_database_path, CONFIG_DIR / 'ik.yaml',
                              CONFIG_DIR / 'calibration.yaml', tmp_path, labels='truth')
    try:
        frames, record = tracker.hold_observations('spelling', 1200, truth, every=12)
        expected = np.concatenate([np.flatnonzero((truth.segment == k) & truth.holding)[::12]
                                   for k in (0, 1)])
        np.testing.assert_array_equal(frames, expected)
        assert record['tiny_labels'].shape == (len(frames), 40, 40)
        assert all(record['tiny_labels'][j].any() for j in range(len(frames)))
        assert (record['blob_color'] > 0).sum(axis=1).min() >= 3
        tracker._evaluator.close()
        tracker._evaluator = object()       # a second render would fail: it must not run
        again_frames, again = tracker.hold_observations('spelling', 1200, truth, every=12)
        np.testing.assert_array_equal(again_frames, frames)
        np.testing.assert_array_equal(again['tiny_labels'], record['tiny_labels'])
    finally:
        tracker._evaluator = None
