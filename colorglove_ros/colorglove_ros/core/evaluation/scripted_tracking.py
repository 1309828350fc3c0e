"""The tracker itself on rendered scripted sequences: what the gesture and spelling evaluations
see when they run on the tracker's output instead of the noise model (cached per sequence)."""
from __future__ import annotations

import ast
import dataclasses
import hashlib
import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from colorglove_ros.core.evaluation.scripted_hands import ScriptedSequence, ScriptError
from colorglove_ros.core.evaluation.sequences import EVIDENCE_FIELDS
from colorglove_ros.core.file_checksums import crc32_of_file
from colorglove_ros.core.hand.model import HandModel
from colorglove_ros.core.hand.observation_features import empty_observation_record
from colorglove_ros.core.lookup.database import DatabaseError, contents_tag
from colorglove_ros.core.pipeline import NODE_LIMITS, StageLimits

__all__ = ['TRACKED_FORMAT_VERSION', 'TRACKER_MODE', 'TRACKING_MODULES', 'ScriptedTracker',
           'TrackedScript', 'tracking_settings', 'settings_tag', 'tracking_sources',
           'tracking_code_tag']

# 2: with the tracker's evidence per frame; 3: and the primary camera's observation per frame
TRACKED_FORMAT_VERSION = 3
_READABLE_VERSIONS = (2, 3)     # a version 2 cache serves everything but the observation
_OBSERVATION_KEYS = tuple(empty_observation_record(0))
TRACKER_MODE = 'ik_smooth'        # the mode ik_node runs (IK and smoothing on)
# fields that name where a setting came from, not what it is
_PROVENANCE_FIELDS = ('source', 'name', 'frame_id')
# this module (its tracking loop) and the modules the tracking of a scripted sequence runs
# (:meth:`ScriptedTracker._make_evaluator`); the cache key covers their code and that of every
# package module they import
TRACKING_MODULES = ('colorglove_ros.core.evaluation.scripted_tracking',
                    'colorglove_ros.core.evaluation.sequences', 'colorglove_ros.core.lookup.search',
                    'colorglove_ros.core.tracking.config', 'colorglove_ros.core.camera')
_PACKAGE = 'colorglove_ros'
# the folder holding the package folder, whose sources the code tag reads
SOURCE_ROOT = Path(__file__).resolve().parents[3]


def _plain(value: Any) -> Any:
    """``value`` as JSON data: dataclasses as mappings of their fields (but the provenance
    fields), arrays as lists; floats keep every digit."""
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return {f.name: _plain(getattr(value, f.name)) for f in dataclasses.fields(value)
                if f.name not in _PROVENANCE_FIELDS}
    if isinstance(value, dict):
        return {str(k): _plain(v) for k, v in sorted(value.items())}
    if isinstance(value, np.ndarray):
        return [_plain(v) for v in value.reshape(-1)]
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, Path):
        return str(value)
    return value


def tracking_settings(ik_config: Path, calibration: Path, labels: str,
                      limits: StageLimits = NODE_LIMITS) -> dict[str, Any]:
    """Everything that changes the tracked poses of a scripted sequence besides the database
    and the script: the tracking code (:func:`tracking_code_tag`), the parsed IK config
    (``load_ik_config``: its covariance file's values, not its path), the primary camera, the
    tracker mode, the label source, the pipeline's gates (``limits``) and, with
    ``labels='segmented'``, the segmenter's settings and a checksum of the colour calibration
    file (``'missing'`` when it is not there yet: the first tracking fits it)."""
    from colorglove_ros.core.camera import load_calibration
    from colorglove_ros.core.tracking.config import load_ik_config

    settings: dict[str, Any] = {
        'ik': _plain(load_ik_config(str(ik_config)).with_mode(TRACKER_MODE)),
        'camera': _plain(load_calibration(str(calibration)).cameras[0]),
        'mode': TRACKER_MODE, 'labels': labels, 'code': tracking_code_tag(),
        'limits': _plain(limits)}
    if labels == 'segmented':
        from colorglove_ros.core.segmentation.calibration_fit import DEFAULT_COLOR_CONFIG
        from colorglove_ros.core.segmentation.color_model import read_calibration_config

        color = read_calibration_config(DEFAULT_COLOR_CONFIG)
        path = Path(color['calibration_file'])
        settings['segmenter'] = _plain(color['segmenter'])
        settings['color_calibration'] = f'crc32 {crc32_of_file(path):08x}' \
            if path.is_file() else 'missing'
    return settings


def _module_file(module: str, root: Path) -> Path | None:
    """The source file of package module ``module`` under ``root`` (None: not one)."""
    base = root.joinpath(*module.split('.'))
    for path in (base.with_suffix('.py'), base / '__init__.py'):
        if path.is_file():
            return path
    return None


def _imports(path: Path, module: str) -> set[str]:
    """The package modules the source ``path`` of ``module`` imports anywhere in it (inside
    functions too), with the packages they sit in; ``from a import b`` names both ``a`` and
    ``a.b`` (``b`` may be a module)."""
    package = module if path.name == '__init__.py' else module.rpartition('.')[0]
    names = set()
    for node in ast.walk(ast.parse(path.read_text(), filename=str(path))):
        if isinstance(node, ast.Import):
            names.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ''
            if node.level:
                parent = package.rsplit('.', node.level - 1)[0] if node.level > 1 else package
                base = f'{parent}.{base}' if base else parent
            names.add(base)
            names.update(f'{base}.{alias.name}' for alias in node.names)
    return {m for name in names if name.split('.')[0] == _PACKAGE for m in _with_packages(name)}


def _with_packages(module: str) -> list[str]:
    """``module`` and the packages it sits in (importing it runs their ``__init__``)."""
    parts = module.split('.')
    return ['.'.join(parts[:k]) for k in range(1, len(parts) + 1)]


def tracking_sources(modules: tuple[str, ...] = TRACKING_MODULES,
                     root: Path | None = None) -> list[Path]:
    """The source files of ``modules`` and of every package module they import, at any depth
    (read, not imported), under ``root`` (default :data:`SOURCE_ROOT`), sorted."""
    root = SOURCE_ROOT if root is None else Path(root)
    seen: dict[str, Path] = {}
    todo = [m for name in modules for m in _with_packages(name)]
    while todo:
        module = todo.pop()
        if module in seen:
            continue
        path = _module_file(module, root)
        if path is None:
            continue
        seen[module] = path
        todo.extend(_imports(path, module) - seen.keys())
    return sorted(set(seen.values()))


def _code_of(path: Path) -> str:
    """The code of a source file without its comments, layout and docstrings (its syntax
    tree)."""
    tree = ast.parse(path.read_text(), filename=str(path))
    for node in ast.walk(tree):
        body = getattr(node, 'body', None)
        if isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef)) \
                and body and isinstance(body[0], ast.Expr) and \
                isinstance(body[0].value, ast.Constant) and isinstance(body[0].value.value, str):
            node.body = body[1:] or [ast.Pass()]
    return ast.dump(tree)


def tracking_code_tag(root: Path | None = None) -> str:
    """A checksum of the tracking code (:func:`tracking_sources` under ``root``): each file's
    path and syntax tree, so a changed statement changes it and a changed comment, docstring
    or layout does not."""
    root = SOURCE_ROOT if root is None else Path(root)
    digest = hashlib.sha1()
    for path in tracking_sources(root=root):
        digest.update(path.relative_to(root).as_posix().encode() + b'\0')
        digest.update(_code_of(path).encode() + b'\0')
    return 'sha1 ' + digest.hexdigest()[:16]


def settings_tag(settings: dict[str, Any]) -> str:
    """A short name of :func:`tracking_settings` for cache file names (equal settings, equal
    name)."""
    text = json.dumps(settings, sort_keys=True, allow_nan=True)
    return 'ik' + hashlib.sha1(text.encode()).hexdigest()[:10]


@dataclass(frozen=True)
class TrackedScript:
    """One scripted sequence tracked: poses (N, 26; NaN where not found), found flags (N,),
    the tracker's evidence per frame (``sequences.EVIDENCE_FIELDS``) and the primary camera's
    observation per frame (``observation_features.empty_observation_record``: the tiny label
    image and the blobs in its frame)."""

    q_est: np.ndarray
    found: np.ndarray
    evidence: dict[str, np.ndarray]
    observation: dict[str, np.ndarray]


@dataclass
class ScriptedTracker:
    """Renders a scripted sequence's true poses (the glove, test-split imaging conditions from
    the seed, the primary camera of ``calibration``), runs the per-frame recipe (segmentation
    with ``labels='segmented'``, lookup, IK with smoothing) and returns the tracked poses and
    the found flags. A frame counts as found when the nodes would publish its pose: the
    pipeline's gates are ``limits`` (default ``NODE_LIMITS``, lookup_node's and ik_node's:
    what a consumer node such as gesture_node is given; ``UNGATED``: every output of the
    tracker). Results are cached in ``cache_dir`` as ``<name>_<seed>_<frames>_<labels>
    _<database tag>_<settings tag>.npz`` (versioned, with the true poses, so a changed script
    is tracked anew; the database tag is its ``contents_tag`` and the settings tag
    :func:`settings_tag` of :func:`tracking_settings`, so a rebuilt or another database, another
    ``ik.yaml``, camera, colour calibration, gates or tracking code never reads a cache of
    other tracking)."""

    database: Path
    ik_config: Path
    calibration: Path
    cache_dir: Path
    labels: str = 'segmented'
    limits: StageLimits = NODE_LIMITS

    def __post_init__(self) -> None:
        self._evaluator: Any = None
        self.frames_tracked = 0       # frames run through the tracker (not from the cache)
        self._settings_tag: str | None = None

    def _cache_path(self, name: str, seed: int, frames: int) -> Path:
        try:
            tag = contents_tag(self.database)
        except DatabaseError as exc:
            raise ScriptError(f'{self.database}: no readable pose database manifest: {exc}') \
                from exc
        if self._settings_tag is None:      # read once, as the evaluator reads them once
            self._settings_tag = settings_tag(tracking_settings(self.ik_config, self.calibration,
                                                                self.labels, self.limits))
        return Path(self.cache_dir) / \
            f'{name}_{seed}_{frames}_{self.labels}_{tag}_{self._settings_tag}.npz'

    def _load(self, path: Path, truth: np.ndarray, observation: bool = False
              ) -> TrackedScript | None:
        """The cached tracking of ``truth``; None when there is none, it is of other poses or
        of an unreadable version, or (``observation``) it holds no observation (a version 2
        cache, read with an empty observation otherwise)."""
        try:
            with np.load(path) as data:
                version = int(data['version'])
                if version not in _READABLE_VERSIONS or \
                        (observation and version < TRACKED_FORMAT_VERSION) or \
                        data['q_true'].shape != truth.shape or \
                        not np.allclose(data['q_true'], truth, atol=1e-9):
                    return None
                seen = {k: data[f'observation_{k}'] for k in _OBSERVATION_KEYS} \
                    if version >= TRACKED_FORMAT_VERSION else {}
                return TrackedScript(data['q_est'], data['found'].astype(bool),
                                     {k: data[f'evidence_{k}'] for k in EVIDENCE_FIELDS}, seen)
        except (OSError, KeyError, ValueError):
            return None

    def _make_evaluator(self) -> Any:
        from colorglove_ros.core.camera import load_calibration
        from colorglove_ros.core.evaluation.sequences import (
            SequenceEvaluator,
            make_observer,
            open_database,
        )
        from colorglove_ros.core.lookup.search import PoseLookup
        from colorglove_ros.core.tracking.config import load_ik_config

        _, db = open_database(self.database, self.database)
        config = load_ik_config(str(self.ik_config))
        cameras = load_calibration(str(self.calibration)).cameras
        return SequenceEvaluator(PoseLookup(db), {'1 camera': cameras[:1]}, [TRACKER_MODE],
                                 config, make_observer(self.labels, None,
                                                       config.min_blob_pixels),
                                 limits=self.limits, evidence=True, observation=True)

    def observe(self, name: str, seed: int, truth: ScriptedSequence, model: HandModel
                ) -> tuple[np.ndarray, np.ndarray]:
        """Tracked poses (N, 26; NaN where not found) and found flags (N,) of sequence
        ``name`` / ``seed`` with true poses ``truth`` (``model`` must be the database's hand)."""
        tracked = self.track(name, seed, truth, model)
        return tracked.q_est, tracked.found

    def evidence(self, name: str, seed: int, truth: ScriptedSequence, model: HandModel
                 ) -> dict[str, np.ndarray]:
        """The tracker's evidence per frame (``sequences.EVIDENCE_FIELDS``, NaN where not
        found) of the sequence :meth:`observe` tracks."""
        return self.track(name, seed, truth, model).evidence

    def observation(self, name: str, seed: int, truth: ScriptedSequence, model: HandModel
                    ) -> dict[str, np.ndarray]:
        """The primary camera's observation per frame
        (``observation_features.empty_observation_record``) of the sequence :meth:`observe`
        tracks."""
        return self.track(name, seed, truth, model, observation=True).observation

    def track(self, name: str, seed: int, truth: ScriptedSequence, model: HandModel,
              observation: bool = False) -> TrackedScript:
        """The sequence tracked (from the cache when it holds it; with ``observation`` only
        from a cache that holds the observation, else tracked anew)."""
        path = self._cache_path(name, seed, len(truth.poses))
        cached = self._load(path, truth.poses, observation)
        if cached is not None:
            return cached
        if self._evaluator is None:
            self._evaluator = self._make_evaluator()
        if not np.isclose(self._evaluator.model.hand_length_m, model.hand_length_m):
            raise ScriptError('the scripted hand is not the pose database\'s hand')
        run = self._evaluator.run(seed, len(truth.poses), poses=truth.poses,
                                  )[('1 camera', TRACKER_MODE)]
        self.frames_tracked += len(truth.poses)
        path.parent.mkdir(parents=True, exist_ok=True)
        np.savez_compressed(path, version=TRACKED_FORMAT_VERSION, q_true=truth.poses,
                            q_est=run.q_est, found=run.found,
                            **{f'evidence_{k}': v for k, v in run.evidence.items()},
                            **{f'observation_{k}': v for k, v in run.observation.items()})
        return TrackedScript(run.q_est, run.found, run.evidence, run.observation)

    def hold_observations(self, name: str, seed: int, truth: ScriptedSequence, every: int = 5
                          ) -> tuple[np.ndarray, dict[str, np.ndarray]]:
        """Every ``every``-th frame of each hold of sequence ``name`` / ``seed`` rendered as
        :meth:`track` renders it and seen through the segmentation alone (no lookup, no IK;
        training data for a classifier of the observation): the frame indices and their
        observation record (``observation_features.empty_observation_record``). Cached beside the
        tracking (``<name>_holds<every>_...``)."""
        import dataclasses

        from colorglove_ros.core.evaluation.sequences import (
            EvaluationSequence,
            record_observation,
        )

        if every < 1:
            raise ScriptError(f'every must be at least 1, got {every}')
        frames = np.concatenate([np.flatnonzero((truth.segment == k) & truth.holding)[::every]
                                 for k in np.unique(truth.segment)]).astype(np.int64)
        path = self._cache_path(f'{name}_holds{every}', seed, len(truth.poses))
        try:
            with np.load(path) as data:
                if int(data['version']) == TRACKED_FORMAT_VERSION and \
                        np.array_equal(data['frames'], frames) and \
                        np.allclose(data['q_true'], truth.poses[frames], atol=1e-9):
                    return frames, {k: data[f'observation_{k}'] for k in _OBSERVATION_KEYS}
        except (OSError, KeyError, ValueError):
            pass
        if self._evaluator is None:
            self._evaluator = self._make_evaluator()
        ev = self._evaluator
        sequence = EvaluationSequence.make(seed, len(truth.poses), ev.cameras[0], ev.synth)
        sequence = dataclasses.replace(sequence, poses=np.asarray(truth.poses, dtype=float))
        record = empty_observation_record(len(frames))
        for j, i in enumerate(frames):
            record_observation(record, j, ev.pipeline.observe(sequence.render(int(i),
                                                                              ev.cameras)))
        path.parent.mkdir(parents=True, exist_ok=True)
        np.savez_compressed(path, version=TRACKED_FORMAT_VERSION, frames=frames,
                            q_true=truth.poses[frames],
                            **{f'observation_{k}': v for k, v in record.items()})
        return frames, record

    def close(self) -> None:
        """Free the renderer."""
        if self._evaluator is not None:
            self._evaluator.close()
            self._evaluator = None
