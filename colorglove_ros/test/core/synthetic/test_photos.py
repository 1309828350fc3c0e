"""Tests of the photo library (manifest, checked loading, installing) and 'photo' backgrounds.

The core tests use the photos the pip dependencies ship (scikit-learn's china and flower,
matplotlib's grace_hopper); those that need the Debian photos skip only when data/photos is
absent (``bash scripts/fetch_photos.sh``, run by setup.sh, installs them)."""
from __future__ import annotations

import hashlib
import os
import shutil
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest
import yaml
from repo_paths import CONFIG_DIR, REPO_DIR

from colorglove_ros.core.synthetic.backgrounds import background_light_field, make_background
from colorglove_ros.core.synthetic.conditions import BACKGROUND_SEED_SPLIT, SynthError
from colorglove_ros.core.synthetic.photos import (
    FETCH_COMMAND,
    MAX_PHOTO_SIDE,
    PhotoError,
    default_photo_dir,
    install_debian_photos,
    load_photo,
    load_photo_manifest,
    missing_photos,
    photo_albedo,
)

MANIFEST = CONFIG_DIR / 'photos.yaml'
PIP_TRAIN = ('china',)
PIP_TEST = ('flower', 'grace_hopper')
TRAIN_SEED, TEST_SEED = 12345, BACKGROUND_SEED_SPLIT + 12345


def _manifest_text(**photo_overrides: object) -> dict:
    """A one-photo manifest (a Debian photo) as a dict, with fields overridden."""
    photo = {'name': 'tile', 'sha256': '0' * 64, 'tags': ['wood'], 'split': 'test',
             'source': {'kind': 'deb', 'package': 'mate-backgrounds',
                        'path': 'usr/share/backgrounds/tile.jpg'}}
    photo.update(photo_overrides)
    return {'format': 'colorglove_photos', 'version': 1,
            'debian_packages': {'mate-backgrounds': '1.26.0-1'}, 'photos': [photo]}


def _write(tmp_path: Path, data: dict, name: str = 'photos.yaml') -> Path:
    path = tmp_path / name
    path.write_text(yaml.safe_dump(data))
    return path


def _jpeg_bytes(seed: int) -> bytes:
    rng = np.random.default_rng(seed)
    img = cv2.resize(rng.integers(0, 256, (12, 16, 3), dtype=np.uint8), (160, 120))
    ok, enc = cv2.imencode('.jpg', img)
    assert ok
    return enc.tobytes()


def test_shipped_manifest_has_disjoint_splits_covering_the_hard_surfaces() -> None:
    manifest = load_photo_manifest(MANIFEST)
    train, test = manifest.of_split('train'), manifest.of_split('test')
    assert len(train) >= 3 and len(test) >= 3
    assert not {p.name for p in train} & {p.name for p in test}
    assert not {p.sha256 for p in train} & {p.sha256 for p in test}
    assert {p.name for p in train} | {p.name for p in test} == {p.name for p in manifest.photos}
    test_tags = {t for p in test for t in p.tags}
    assert {'wood', 'skin', 'face', 'dark'} <= test_tags
    assert test_tags & {'red', 'orange'}
    # the people cut out as skin distractors are photos of people
    assert all('face' in p.tags for p in manifest.photos if p.person is not None)
    assert dict(manifest.debian_packages) == {'mate-backgrounds': '1.26.0-1'}


@pytest.mark.parametrize('change, message', [
    ({'format': 'something_else'}, 'not a colorglove_photos file'),
    ({'version': 2}, 'version 2'),
    ({'extra': 1}, 'unknown setting'),
    ({'photos': []}, 'non-empty list'),
    ({'debian_packages': {}}, 'not pinned'),
])
def test_bad_manifest_is_refused(tmp_path: Path, change: dict, message: str) -> None:
    data = {**_manifest_text(), **change}
    with pytest.raises(PhotoError, match=message):
        load_photo_manifest(_write(tmp_path, data))


@pytest.mark.parametrize('change, message', [
    ({'sha256': 'abc'}, 'sha256 must be 64'),
    ({'tags': ['wod']}, "unknown tag"),
    ({'tags': []}, 'tags must be a non-empty list'),
    ({'split': 'validation'}, 'split must be one of'),
    ({'colour': 'red'}, 'unknown setting'),
    ({'source': {'kind': 'ftp', 'package': 'x', 'path': 'a.jpg'}}, 'source kind'),
    ({'source': {'kind': 'deb', 'package': 'mate-backgrounds', 'path': '../a.jpg'}},
     'relative without'),
    ({'person': {'head_ellipse': [1, 2, 3]}}, 'head_ellipse'),
])
def test_bad_photo_entry_is_refused(tmp_path: Path, change: dict, message: str) -> None:
    with pytest.raises(PhotoError, match=message):
        load_photo_manifest(_write(tmp_path, _manifest_text(**change)))


def test_duplicate_names_and_missing_manifest_are_refused(tmp_path: Path) -> None:
    data = _manifest_text()
    data['photos'] = data['photos'] * 2
    with pytest.raises(PhotoError, match='duplicate photo name'):
        load_photo_manifest(_write(tmp_path, data))
    with pytest.raises(PhotoError, match='photo manifest not found'):
        load_photo_manifest(tmp_path / 'absent.yaml')
    assert issubclass(PhotoError, SynthError)


def test_missing_altered_or_broken_photo_names_the_fetch_command(tmp_path: Path) -> None:
    data = _jpeg_bytes(0)
    manifest = _write(tmp_path, _manifest_text(sha256=hashlib.sha256(data).hexdigest()))
    photo_dir = tmp_path / 'photos'
    with pytest.raises(PhotoError, match='not found') as missing:
        load_photo('tile', manifest_path=manifest, photo_dir=photo_dir)
    assert FETCH_COMMAND in str(missing.value)
    assert len(missing_photos(manifest, photo_dir)) == 1
    photo_dir.mkdir()
    (photo_dir / 'tile.jpg').write_bytes(data[:-10])
    with pytest.raises(PhotoError, match='has sha256') as altered:
        load_photo('tile', manifest_path=manifest, photo_dir=photo_dir)
    assert FETCH_COMMAND in str(altered.value)
    garbage = b'not a jpeg at all'
    broken = _write(tmp_path, _manifest_text(sha256=hashlib.sha256(garbage).hexdigest()),
                    'broken.yaml')
    (photo_dir / 'tile.jpg').write_bytes(garbage)
    with pytest.raises(PhotoError, match='cannot be decoded'):
        load_photo('tile', manifest_path=broken, photo_dir=photo_dir)
    (photo_dir / 'tile.jpg').write_bytes(data)
    rgb, factor = load_photo('tile', manifest_path=manifest, photo_dir=photo_dir)
    assert rgb.shape == (120, 160, 3) and rgb.dtype == np.uint8 and factor == 1.0
    assert missing_photos(manifest, photo_dir) == []


def test_install_copies_checked_photos_once(tmp_path: Path) -> None:
    data = _jpeg_bytes(1)
    manifest = _write(tmp_path, _manifest_text(sha256=hashlib.sha256(data).hexdigest()))
    root, photo_dir = tmp_path / 'root', tmp_path / 'photos'
    source = root / 'usr/share/backgrounds/tile.jpg'
    with pytest.raises(PhotoError, match='not in the extracted'):
        install_debian_photos(root, manifest, photo_dir)
    source.parent.mkdir(parents=True)
    source.write_bytes(data + b'tampered')
    with pytest.raises(PhotoError, match='another package version'):
        install_debian_photos(root, manifest, photo_dir)
    assert not (photo_dir / 'tile.jpg').exists()
    source.write_bytes(data)
    assert install_debian_photos(root, manifest, photo_dir) == ['tile']
    assert (photo_dir / 'tile.jpg').read_bytes() == data
    assert install_debian_photos(root, manifest, photo_dir) == []     # present and matching
    (photo_dir / 'tile.jpg').write_bytes(b'damaged')
    assert install_debian_photos(root, manifest, photo_dir) == ['tile']


def _build_deb(tmp_path: Path, photo: bytes) -> Path:
    """A minimal .deb holding ``photo`` at the manifest's path (dpkg-deb -b)."""
    root = tmp_path / 'package'
    shutil.rmtree(root, ignore_errors=True)
    (root / 'DEBIAN').mkdir(parents=True)
    (root / 'DEBIAN' / 'control').write_text(
        'Package: mate-backgrounds\nVersion: 1.26.0-1\nArchitecture: all\n'
        'Maintainer: test <test@example.org>\nDescription: test photos\n')
    (root / 'usr/share/backgrounds').mkdir(parents=True)
    (root / 'usr/share/backgrounds/tile.jpg').write_bytes(photo)
    deb = tmp_path / 'photos.deb'
    subprocess.run(['dpkg-deb', '--root-owner-group', '-b', str(root), str(deb)], check=True,
                   capture_output=True)
    return deb


@pytest.mark.skipif(shutil.which('dpkg-deb') is None, reason='dpkg-deb (Debian) not installed')
def test_fetch_script_installs_from_a_deb_once_and_fails_loudly(tmp_path: Path) -> None:
    data = _jpeg_bytes(2)
    manifest = _write(tmp_path, _manifest_text(sha256=hashlib.sha256(data).hexdigest()))
    photo_dir = tmp_path / 'photos'
    env = {**os.environ, 'COLORGLOVE_PHOTOS_DEB': str(_build_deb(tmp_path, data)),
           'COLORGLOVE_PHOTO_MANIFEST': str(manifest), 'COLORGLOVE_PHOTO_DIR': str(photo_dir),
           'PYTHON': sys.executable}
    script = ['bash', str(REPO_DIR / 'scripts' / 'fetch_photos.sh')]
    first = subprocess.run(script, env=env, capture_output=True, text=True, timeout=60)
    assert first.returncode == 0, first.stderr
    assert 'copied 1 photo(s): tile' in first.stdout
    assert (photo_dir / 'tile.jpg').read_bytes() == data
    # present and matching: nothing is fetched (the .deb is not even looked at)
    again = subprocess.run(script, env={**env, 'COLORGLOVE_PHOTOS_DEB': '/nonexistent.deb'},
                           capture_output=True, text=True, timeout=60)
    assert again.returncode == 0 and 'present and matching' in again.stdout
    # a package whose photo is not the manifest's: a non-zero exit and a clear message
    (photo_dir / 'tile.jpg').unlink()
    env['COLORGLOVE_PHOTOS_DEB'] = str(_build_deb(tmp_path, data + b'other'))
    wrong = subprocess.run(script, env=env, capture_output=True, text=True, timeout=60)
    assert wrong.returncode != 0
    assert 'another package version' in wrong.stderr and 'fetch_photos: error' in wrong.stderr
    assert not (photo_dir / 'tile.jpg').exists()


def test_pip_photos_load_checked_and_cached() -> None:
    for name in PIP_TRAIN + PIP_TEST:
        rgb, factor = load_photo(name)
        assert rgb.ndim == 3 and max(rgb.shape[:2]) <= MAX_PHOTO_SIDE and factor == 1.0
        assert not rgb.flags.writeable
        assert load_photo(name)[0] is rgb
        assert 40 < rgb.mean() < 200


def test_photo_background_is_deterministic_per_seed_and_differs_across_seeds() -> None:
    a = make_background('photo', TRAIN_SEED, 160, 120, photos=PIP_TRAIN)
    np.testing.assert_array_equal(a, make_background('photo', TRAIN_SEED, 160, 120,
                                                     photos=PIP_TRAIN))
    b = make_background('photo', TRAIN_SEED + 1, 160, 120, photos=PIP_TRAIN)
    assert a.shape == (120, 160, 3) and a.dtype == np.float32
    assert np.abs(a - b).mean() > 0.02
    assert 0.0 <= a.min() and a.max() <= 1.0
    luma = a @ np.array([0.2126, 0.7152, 0.0722])
    assert 0.04 < luma.mean() < 0.45           # a plausible reflectance, not a bright print
    assert background_light_field('photo', TRAIN_SEED, 160, 120, photos=PIP_TRAIN).shape == (
        120, 160, 1)
    # test seeds choose among the test photos, and the choice follows the seed
    chosen = {photo_albedo(np.random.default_rng(s), 'test', 64, 48, PIP_TEST)[1].name
              for s in range(12)}
    assert chosen == set(PIP_TEST)


def test_photo_background_keeps_to_its_seeds_split() -> None:
    with pytest.raises(PhotoError, match="no 'train' photo"):
        make_background('photo', TRAIN_SEED, 64, 48, photos=PIP_TEST)
    with pytest.raises(PhotoError, match="no 'test' photo"):
        make_background('photo', TEST_SEED, 64, 48, photos=PIP_TRAIN)
    with pytest.raises(PhotoError, match='no photo named'):
        make_background('photo', TEST_SEED, 64, 48, photos=('mona_lisa',))


def test_photo_background_looks_like_its_photo() -> None:
    """The background is a crop of the photo: its luminance correlates with the photo's
    crop drawn from the same seed far better than with another seed's crop."""
    def luma(img: np.ndarray) -> np.ndarray:
        return np.log(img @ np.array([0.2126, 0.7152, 0.0722]) + 1e-3).ravel()

    bg = make_background('photo', TEST_SEED, 320, 240, photos=('grace_hopper',),
                         glove_distractors=False)
    same, _ = photo_albedo(np.random.default_rng(TEST_SEED), 'test', 320, 240,
                           ('grace_hopper',))
    other, _ = photo_albedo(np.random.default_rng(TEST_SEED + 5), 'test', 320, 240,
                            ('grace_hopper',))
    assert np.corrcoef(luma(bg), luma(same))[0, 1] > 0.95
    assert np.corrcoef(luma(bg), luma(other))[0, 1] < 0.8


def test_wood_is_stained_to_warm_colours_sometimes() -> None:
    """The wood photo's grain is kept; a stain makes it warm (red > green > blue)."""
    if not default_photo_dir().is_dir():
        pytest.skip(f'Debian photos not installed in {default_photo_dir()}: run '
                    f'`{FETCH_COMMAND}`')
    means = [photo_albedo(np.random.default_rng(s), 'test', 160, 120, ('wood',))[0]
             .mean(axis=(0, 1)) for s in range(12)]
    warm = [m for m in means if m[0] > 1.5 * m[2] and m[0] > m[1] > m[2]]
    assert 3 <= len(warm) < len(means)


def test_every_manifest_photo_is_installed_and_usable() -> None:
    if not default_photo_dir().is_dir():
        pytest.skip(f'Debian photos not installed in {default_photo_dir()}: run '
                    f'`{FETCH_COMMAND}`')
    assert missing_photos() == []
    manifest = load_photo_manifest()
    for photo in manifest.photos:
        rgb, _ = load_photo(photo.name)
        assert max(rgb.shape[:2]) <= MAX_PHOTO_SIDE and rgb.std() > 10
    for seed in (TRAIN_SEED, TEST_SEED):
        img = make_background('photo', seed, 160, 120, skin_distractors=True)
        assert img.shape == (120, 160, 3) and np.isfinite(img).all()
