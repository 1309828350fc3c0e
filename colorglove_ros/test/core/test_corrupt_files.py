"""Every file a node reads at start-up, corrupted every way a user, a disk or an editor can:
each corrupt copy must be refused with a ColorGloveError that names the file (the node then
exits with that message instead of running with, or crashing on, a bad value)."""
from __future__ import annotations

import copy
import json
import math
import shutil
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml
from repo_paths import CONFIG_DIR

from colorglove_ros.core.camera import load_calibration
from colorglove_ros.core.errors import ColorGloveError
from colorglove_ros.core.lookup.database import MANIFEST_NAME, load_database, save_database
from colorglove_ros.core.lookup.database_build import assemble_database, read_database_config
from colorglove_ros.core.segmentation.calibration_fit import fit_color_calibration
from colorglove_ros.core.segmentation.color_model import save_calibration
from colorglove_ros.core.segmentation.segmenter import load_segmenter
from colorglove_ros.core.synthetic.blob_glove import render_blob_frame, sample_blob_conditions
from colorglove_ros.core.tracking.config import load_covariances, load_ik_config

Corruption = tuple[str, Callable[[Path], None]]
BAD_VALUES: dict[str, Any] = {'nan': math.nan, 'inf': math.inf, '-inf': -math.inf,
                              'text': 'garbage', 'null': None, 'mapping': {'a': 1},
                              'huge': 1e300}
BAD_BOOLEANS: dict[str, Any] = {'text': 'garbage', 'number': 2, 'null': None}


def _leaves(data: Any, path: tuple = ()) -> Iterator[tuple[tuple, Any]]:
    """(key path, value) of every number and boolean in a YAML document."""
    if isinstance(data, dict):
        for key, value in data.items():
            yield from _leaves(value, (*path, key))
    elif isinstance(data, list):
        for index, value in enumerate(data):
            yield from _leaves(value, (*path, index))
    elif isinstance(data, (bool, int, float)):
        yield path, data


def _with(data: Any, path: tuple, value: Any) -> Any:
    out = copy.deepcopy(data)
    node = out
    for key in path[:-1]:
        node = node[key]
    node[path[-1]] = value
    return out


def _write_yaml(data: Any) -> Callable[[Path], None]:
    return lambda file: file.write_text(yaml.safe_dump(data))


def _file_level(original: bytes, truncate: bool = True) -> list[Corruption]:
    """Corruptions of any file regardless of its contents (a truncated YAML file is often
    valid YAML with fewer settings, so YAML files are cut by their own cases instead)."""
    cases: list[Corruption] = [
        ('missing', lambda file: file.unlink()),
        ('empty', lambda file: file.write_bytes(b'')),
        ('binary garbage', lambda file: file.write_bytes(bytes(range(256)) * 4)),
        ('a folder', lambda file: (file.unlink(), file.mkdir())),
    ]
    if truncate:
        cases.append(('truncated', lambda file: file.write_bytes(original[:len(original) // 2])))
    return cases


def yaml_corruptions(source: Path, optional_keys: tuple[str, ...] = (),
                     informative_keys: tuple[str, ...] = ()) -> list[Corruption]:
    """File-level corruptions plus, for every number or boolean in the file (outside the
    ``informative_keys`` no code reads), each bad value; a top-level list, an unknown key and,
    for each required top-level key, its removal."""
    data = yaml.safe_load(source.read_text())
    cases = _file_level(source.read_bytes(), truncate=False)
    cases.append(('top-level list', _write_yaml([data])))
    cases.append(('unknown key', _write_yaml({**data, 'no_such_setting': 1})))
    for key in data:
        if key not in optional_keys + informative_keys:
            cases.append((f'without {key}', _write_yaml({k: v for k, v in data.items()
                                                         if k != key})))
    for path, value in _leaves({k: v for k, v in data.items() if k not in informative_keys}):
        bad = BAD_BOOLEANS if isinstance(value, bool) else BAD_VALUES
        for name, replacement in bad.items():
            where = '.'.join(str(p) for p in path)
            cases.append((f'{where} = {name}', _write_yaml(_with(data, path, replacement))))
    return cases


def _refusals(source: Path, cases: list[Corruption], load: Callable[[Path], Any],
              folder: Path) -> list[str]:
    """Apply each corruption to a copy of ``source`` and load it; the cases not refused with a
    ColorGloveError naming the file (or that raised anything else)."""
    failures = []
    for index, (name, corrupt) in enumerate(cases):
        file = folder / f'{index:03d}' / source.name
        file.parent.mkdir(parents=True)
        if source.is_dir():
            shutil.copytree(source, file)
        else:
            shutil.copyfile(source, file)
        corrupt(file)
        try:
            load(file)
        except ColorGloveError as exc:
            if str(file.parent) not in str(exc):
                failures.append(f'{name}: message does not name the file: {exc}')
        except Exception as exc:   # noqa: BLE001 - what the test looks for
            failures.append(f'{name}: {type(exc).__name__}: {exc}')
        else:
            failures.append(f'{name}: accepted')
    return failures


@pytest.fixture(scope='module')
def colour_calibration_file(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A small valid colour calibration (.npz) fitted on blob-glove frames."""
    rng = np.random.default_rng(3)
    frames = [render_blob_frame(rng, sample_blob_conditions(rng, 'train'), 320, 240)
              for _ in range(8)]
    calibration = fit_color_calibration(frames, seed=0, max_per_class=1500, bits=5,
                                        augment_copies=1, background_components=6)
    return save_calibration(calibration, tmp_path_factory.mktemp('colour') / 'cal.npz')


@pytest.fixture(scope='module')
def database_folder(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A small valid pose database folder."""
    rng = np.random.default_rng(5)
    tiny = rng.integers(0, 11, (40, 40, 40)).astype(np.uint8)
    poses = np.zeros((40, 26), np.float32)
    poses[:, 2] = 0.5
    db = assemble_database(tiny, poses, np.tile([1.0, 0.0, 0.0], (40, 1)),
                           {'width': 128, 'height': 128, 'fx': 150.0, 'fy': 150.0, 'cx': 63.5,
                            'cy': 63.5}, num_bits=32, num_pairs=100, seed=0)
    return save_database(db, tmp_path_factory.mktemp('database') / 'db')


def test_corrupt_camera_calibrations_refused(tmp_path: Path) -> None:
    for name in ('calibration.yaml', 'calibration_stereo.yaml'):
        source = CONFIG_DIR / name
        cases = yaml_corruptions(source, optional_keys=('hand_length_m', 'version'))
        failures = _refusals(source, cases, load_calibration, tmp_path / name)
        assert not failures, f'{len(failures)} of {len(cases)} corrupt {name} accepted:\n' + \
            '\n'.join(failures)


def test_corrupt_ik_configs_refused(tmp_path: Path) -> None:
    optional = tuple(yaml.safe_load((CONFIG_DIR / 'ik.yaml').read_text()))
    cases = yaml_corruptions(CONFIG_DIR / 'ik.yaml', optional_keys=optional)
    failures = _refusals(CONFIG_DIR / 'ik.yaml', cases, load_ik_config, tmp_path / 'ik')
    covariance_cases = yaml_corruptions(CONFIG_DIR / 'ik_covariances.yaml',
                                       informative_keys=('provenance',))
    failures += _refusals(CONFIG_DIR / 'ik_covariances.yaml', covariance_cases,
                          load_covariances, tmp_path / 'cov')
    assert not failures, f'{len(failures)} corrupt IK files accepted:\n' + '\n'.join(failures)


def test_corrupt_colour_configs_refused(tmp_path: Path, colour_calibration_file: Path) -> None:
    data = yaml.safe_load((CONFIG_DIR / 'color_calibration.yaml').read_text())
    data['calibration_file'] = str(colour_calibration_file)
    source = tmp_path / 'color_calibration.yaml'
    source.write_text(yaml.safe_dump(data))
    load_segmenter(str(source))                                # the uncorrupted copy loads
    cases = yaml_corruptions(source, optional_keys=('segmenter',))
    failures = _refusals(source, cases, lambda file: load_segmenter(str(file)),
                         tmp_path / 'yaml')
    npz_cases = _file_level(colour_calibration_file.read_bytes())
    npz_cases += [('one array missing', lambda file: _drop_npz_array(file, 'thresholds')),
                  ('lookup table cut', lambda file: _replace_npz_array(file, 'lut',
                                                                       np.zeros(7, np.uint8)))]
    failures += _refusals(colour_calibration_file, npz_cases,
                          lambda file: load_segmenter(str(_config_naming(file, data))),
                          tmp_path / 'npz')
    assert not failures, f'{len(failures)} corrupt colour files accepted:\n' + '\n'.join(failures)


def _config_naming(calibration: Path, data: dict[str, Any]) -> Path:
    config = calibration.parent / 'color_calibration.yaml'
    config.write_text(yaml.safe_dump({**data, 'calibration_file': str(calibration)}))
    return config


def _npz_arrays(file: Path) -> dict[str, np.ndarray]:
    with np.load(file, allow_pickle=False) as z:
        return {k: z[k] for k in z.files}


def _drop_npz_array(file: Path, name: str) -> None:
    arrays = _npz_arrays(file)
    del arrays[name]
    with file.open('wb') as fh:
        np.savez_compressed(fh, **arrays)


def _replace_npz_array(file: Path, name: str, value: np.ndarray) -> None:
    arrays = _npz_arrays(file)
    arrays[name] = value
    with file.open('wb') as fh:
        np.savez_compressed(fh, **arrays)


def test_corrupt_database_configs_refused(tmp_path: Path) -> None:
    source = CONFIG_DIR / 'database.yaml'
    cases = yaml_corruptions(source)
    failures = _refusals(source, cases, read_database_config, tmp_path)
    assert not failures, f'{len(failures)} corrupt database.yaml accepted:\n' + \
        '\n'.join(failures)


def _edit_manifest(change: Callable[[dict[str, Any]], None]) -> Callable[[Path], None]:
    def corrupt(folder: Path) -> None:
        manifest = json.loads((folder / MANIFEST_NAME).read_text())
        change(manifest)
        (folder / MANIFEST_NAME).write_text(json.dumps(manifest))
    return corrupt


def _array_file(folder: Path, name: str) -> Path:
    manifest = json.loads((folder / MANIFEST_NAME).read_text())
    return folder / manifest['arrays'][name]['file']


def database_corruptions(folder: Path) -> list[Corruption]:
    """Corruptions of a database folder: its manifest, its build record and its arrays."""
    manifest = json.loads((folder / MANIFEST_NAME).read_text())
    cases: list[Corruption] = [
        ('folder missing', lambda f: shutil.rmtree(f)),
        ('manifest missing', lambda f: (f / MANIFEST_NAME).unlink()),
        ('manifest empty', lambda f: (f / MANIFEST_NAME).write_text('')),
        ('manifest garbage', lambda f: (f / MANIFEST_NAME).write_bytes(bytes(range(256)))),
        ('manifest truncated', lambda f: (f / MANIFEST_NAME).write_text(
            (f / MANIFEST_NAME).read_text()[:200])),
        ('manifest a list', lambda f: (f / MANIFEST_NAME).write_text('[]')),
        ('other version', _edit_manifest(lambda m: m.update(version=99))),
        ('other format', _edit_manifest(lambda m: m.update(format='something'))),
        ('other dt_scale', _edit_manifest(lambda m: m.update(dt_scale=3))),
        ('entry count', _edit_manifest(lambda m: m.update(num_entries=41))),
        ('no build record', _edit_manifest(lambda m: m['meta'].pop('build'))),
        ('hand length nan', _edit_manifest(
            lambda m: m['meta']['build'].update(hand_length_m=math.nan))),
        ('hand length text', _edit_manifest(
            lambda m: m['meta']['build'].update(hand_length_m='long'))),
        ('glove seed negative', _edit_manifest(
            lambda m: m['meta']['build'].update(glove_seed=-4))),
        ('encoder kind', _edit_manifest(lambda m: m.update(encoder_kind='nonsense'))),
        ('render camera fx nan', _edit_manifest(
            lambda m: m['render_camera'].update(fx=math.nan))),
        ('arrays not a mapping', _edit_manifest(lambda m: m.update(arrays=[]))),
    ]
    for name in manifest['arrays']:
        cases += [
            (f'{name} missing', lambda f, n=name: _array_file(f, n).unlink()),
            (f'{name} truncated', lambda f, n=name: _array_file(f, n).write_bytes(
                _array_file(f, n).read_bytes()[:-8])),
            (f'{name} bytes flipped', lambda f, n=name: _flip_last_byte(_array_file(f, n))),
            (f'{name} left out of the manifest', _edit_manifest(
                lambda m, n=name: m['arrays'].pop(n))),
            (f'{name} shape in the manifest', _edit_manifest(
                lambda m, n=name: m['arrays'][n].update(shape=[1]))),
        ]
    return cases


def _flip_last_byte(file: Path) -> None:
    data = bytearray(file.read_bytes())
    data[-1] ^= 0xFF
    file.write_bytes(bytes(data))


def test_corrupt_databases_refused(tmp_path: Path, database_folder: Path) -> None:
    load_database(database_folder)                           # the uncorrupted copy loads
    cases = database_corruptions(database_folder)
    failures = _refusals(database_folder, cases, load_database, tmp_path)
    assert not failures, f'{len(failures)} of {len(cases)} corrupt databases accepted:\n' + \
        '\n'.join(failures)
