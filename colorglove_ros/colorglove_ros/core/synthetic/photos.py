"""Real photographs for synthetic backgrounds: the versioned manifest ``config/photos.yaml``
(name, source, sha256, tags, train/test split of each photo), checked loading (cached), the
'photo' background albedo (seeded crop, zoom, flip, optional wood stain, plausible
reflectance) and the installer that ``scripts/fetch_photos.sh`` runs.

Sources: 'pip' photos ship with the pinned pip dependencies (found through the import path of
the module that holds them); 'deb' photos are copied from a Debian package into
``data/photos/<name>.jpg``. A missing or altered photo raises :class:`PhotoError` naming
:data:`FETCH_COMMAND`; nothing is downloaded at run time.
"""
from __future__ import annotations

import argparse
import hashlib
import importlib.util
import shutil
import sys
from collections.abc import Sequence
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import cv2
import numpy as np

from colorglove_ros.core.colorimetry import LUMINANCE_WEIGHTS, srgb_to_linear
from colorglove_ros.core.synthetic.conditions import SPLITS, SynthError
from colorglove_ros.core.validation import check_known_keys
from colorglove_ros.core.yaml_io import load_yaml_mapping
from colorglove_ros.paths import data_dir, share_dir

__all__ = [
    'PhotoError', 'PHOTO_FORMAT', 'PHOTO_FORMAT_VERSION', 'PHOTO_TAGS', 'SOURCE_KINDS',
    'FETCH_COMMAND', 'MAX_PHOTO_SIDE', 'PersonRegion', 'Photo', 'PhotoManifest',
    'default_manifest_path', 'default_photo_dir', 'load_photo_manifest', 'photo_file',
    'load_photo', 'photo_albedo', 'missing_photos', 'install_debian_photos', 'main',
]

PHOTO_FORMAT = 'colorglove_photos'
PHOTO_FORMAT_VERSION = 1
PHOTO_TAGS: tuple[str, ...] = ('wood', 'red', 'orange', 'yellow', 'green', 'blue', 'grey',
                               'dark', 'sky', 'skin', 'face')
SOURCE_KINDS: tuple[str, ...] = ('pip', 'deb')
FETCH_COMMAND = 'bash scripts/fetch_photos.sh'
MAX_PHOTO_SIDE = 1280        # photos are decoded and kept at most this long (pixels)
ZOOM_RANGE = (1.0, 2.5)      # crop zoom relative to the largest crop of the frame's aspect
ALBEDO_RANGE = (0.08, 0.35)  # mean linear reflectance a photo's scene is given
MAX_ALBEDO = 0.9             # brightest reflectance (the 99.5 % luminance percentile)
# linear albedos of wood stains (oak, teak, cherry, walnut) applied to 'wood' photos' grain
WOOD_STAINS = np.array([[0.42, 0.24, 0.11], [0.33, 0.15, 0.06], [0.30, 0.09, 0.045],
                        [0.13, 0.065, 0.03]])
WOOD_STAIN_PROBABILITY = 0.7

_MANIFEST_KEYS = ('format', 'version', 'debian_packages', 'photos')
_PHOTO_KEYS = ('name', 'source', 'sha256', 'license', 'tags', 'split', 'person')
_SOURCE_KEYS = ('kind', 'package', 'path')
_SRGB8_TO_LINEAR = srgb_to_linear(np.arange(256) / 255.0).astype(np.float32)


class PhotoError(SynthError):
    """A bad photo manifest, or a photo that is missing, altered or cannot be decoded."""


@dataclass(frozen=True)
class PersonRegion:
    """Where the person is in a photo (file pixels): head ellipse and torso outline."""

    head_ellipse: tuple[float, float, float, float]    # centre x, y, semi-axes x, y
    torso: tuple[tuple[float, float], ...]


@dataclass(frozen=True)
class Photo:
    """One manifest entry."""

    name: str
    kind: str                      # 'pip' or 'deb'
    package: str                   # pip distribution or Debian package
    path: str                      # inside the pip install tree / the package's files
    sha256: str
    tags: tuple[str, ...]
    split: str
    license: str = ''
    person: PersonRegion | None = None


@dataclass(frozen=True)
class PhotoManifest:
    """The parsed ``config/photos.yaml``."""

    photos: tuple[Photo, ...]
    debian_packages: tuple[tuple[str, str], ...]    # (package, version)
    source: str

    def get(self, name: str) -> Photo:
        """The photo called ``name``."""
        for photo in self.photos:
            if photo.name == name:
                return photo
        raise PhotoError(f'{self.source}: no photo named {name!r} '
                         f'(known: {[p.name for p in self.photos]})')

    def of_split(self, split: str, names: Sequence[str] = ()) -> tuple[Photo, ...]:
        """The photos of ``split``, restricted to ``names`` when given (each must exist)."""
        if split not in SPLITS:
            raise PhotoError(f'split must be one of {SPLITS}, got {split!r}')
        wanted = {self.get(n).name for n in names}
        chosen = tuple(p for p in self.photos if p.split == split
                       and (not wanted or p.name in wanted))
        if not chosen:
            raise PhotoError(f'{self.source}: no {split!r} photo among {sorted(wanted) or "all"}')
        return chosen


def default_manifest_path() -> Path:
    """``config/photos.yaml`` of the package."""
    return share_dir() / 'config' / 'photos.yaml'


def default_photo_dir() -> Path:
    """``data/photos`` of the package, where the 'deb' photos are installed."""
    return data_dir() / 'photos'


def _text(where: str, value: object) -> str:
    if not isinstance(value, str) or not value.strip():
        raise PhotoError(f'{where} must be a non-empty string, got {value!r}')
    return value


def _person(where: str, data: object) -> PersonRegion:
    if not isinstance(data, dict):
        raise PhotoError(f'{where} must be a mapping with head_ellipse and torso')
    check_known_keys(where, data, ('head_ellipse', 'torso'), error=PhotoError)
    try:
        head = tuple(float(v) for v in data['head_ellipse'])
        torso = tuple((float(x), float(y)) for x, y in data['torso'])
    except (KeyError, TypeError, ValueError) as exc:
        raise PhotoError(f'{where}: needs head_ellipse [x, y, ax, ay] and torso [[x, y], ...]'
                         f' ({exc})') from exc
    if len(head) != 4 or head[2] <= 0 or head[3] <= 0 or len(torso) < 3:
        raise PhotoError(f'{where}: head_ellipse needs 4 values with positive semi-axes and '
                         'torso at least 3 points')
    return PersonRegion((head[0], head[1], head[2], head[3]), torso)


def _photo(where: str, entry: object, packages: dict[str, str]) -> Photo:
    if not isinstance(entry, dict):
        raise PhotoError(f'{where} must be a mapping')
    check_known_keys(where, entry, _PHOTO_KEYS, error=PhotoError)
    name = _text(f'{where}.name', entry.get('name'))
    where = f'{where} ({name})'
    source = entry.get('source')
    if not isinstance(source, dict):
        raise PhotoError(f'{where}: source must be a mapping with kind, package and path')
    check_known_keys(f'{where}.source', source, _SOURCE_KEYS, error=PhotoError)
    kind = source.get('kind')
    if kind not in SOURCE_KINDS:
        raise PhotoError(f'{where}: source kind must be one of {SOURCE_KINDS}, got {kind!r}')
    package = _text(f'{where}.source.package', source.get('package'))
    path = _text(f'{where}.source.path', source.get('path'))
    if kind == 'deb' and package not in packages:
        raise PhotoError(f'{where}: Debian package {package!r} is not pinned under '
                         'debian_packages')
    if Path(path).is_absolute() or '..' in Path(path).parts:
        raise PhotoError(f'{where}: source path must be relative without "..", got {path!r}')
    sha = entry.get('sha256')
    if not (isinstance(sha, str) and len(sha) == 64
            and all(c in '0123456789abcdef' for c in sha)):
        raise PhotoError(f'{where}: sha256 must be 64 lower-case hex digits, got {sha!r}')
    tags = entry.get('tags')
    if not isinstance(tags, list) or not tags:
        raise PhotoError(f'{where}: tags must be a non-empty list')
    unknown = sorted(str(t) for t in tags if t not in PHOTO_TAGS)
    if unknown:
        raise PhotoError(f'{where}: unknown tag(s) {unknown} (known: {list(PHOTO_TAGS)})')
    split = entry.get('split')
    if split not in SPLITS:
        raise PhotoError(f'{where}: split must be one of {SPLITS}, got {split!r}')
    person = _person(f'{where}.person', entry['person']) if 'person' in entry else None
    return Photo(name, kind, package, path, sha, tuple(tags), split,
                 str(entry.get('license', '')), person)


@lru_cache(maxsize=4)
def _load_manifest(path: str) -> PhotoManifest:
    data = load_yaml_mapping(path, PhotoError, 'photo manifest')
    if data.get('format') != PHOTO_FORMAT:
        raise PhotoError(f'{path} is not a {PHOTO_FORMAT} file '
                         f'(format: {data.get("format")!r})')
    if data.get('version') != PHOTO_FORMAT_VERSION:
        raise PhotoError(f'{path} has version {data.get("version")!r}, '
                         f'expected {PHOTO_FORMAT_VERSION}')
    check_known_keys(path, data, _MANIFEST_KEYS, error=PhotoError)
    packages = data.get('debian_packages', {})
    if not isinstance(packages, dict) or not all(
            isinstance(k, str) and isinstance(v, str) and v for k, v in packages.items()):
        raise PhotoError(f'{path}: debian_packages must map package names to versions')
    entries = data.get('photos')
    if not isinstance(entries, list) or not entries:
        raise PhotoError(f'{path}: photos must be a non-empty list')
    photos = tuple(_photo(f'{path}: photos[{i}]', e, packages) for i, e in enumerate(entries))
    names = [p.name for p in photos]
    duplicates = sorted({n for n in names if names.count(n) > 1})
    if duplicates:
        raise PhotoError(f'{path}: duplicate photo name(s) {duplicates}')
    return PhotoManifest(photos, tuple(sorted(packages.items())), path)


def load_photo_manifest(path: str | Path | None = None) -> PhotoManifest:
    """The manifest at ``path`` (default ``config/photos.yaml``), checked and cached; raise
    :class:`PhotoError` naming what is wrong."""
    return _load_manifest(str(default_manifest_path() if path is None else Path(path)))


def photo_file(photo: Photo, photo_dir: str | Path | None = None) -> Path:
    """Where ``photo`` is stored: in its pip package's install tree, or
    ``photo_dir/<name><suffix>`` (default ``data/photos``) for a Debian photo."""
    if photo.kind == 'deb':
        folder = default_photo_dir() if photo_dir is None else Path(photo_dir)
        return folder / f'{photo.name}{Path(photo.path).suffix.lower()}'
    module = Path(photo.path).parts[0]
    spec = importlib.util.find_spec(module)
    if spec is None or not spec.submodule_search_locations:
        raise PhotoError(f'photo {photo.name!r}: Python package {module!r} (pip: '
                         f'{photo.package}) is not installed: pip install -r requirements.txt')
    return Path(next(iter(spec.submodule_search_locations))).parent / photo.path


def _sha256(path: Path) -> str:
    digest = hashlib.sha256()
    with path.open('rb') as fh:
        while chunk := fh.read(1 << 20):
            digest.update(chunk)
    return digest.hexdigest()


def _how_to_get(photo: Photo) -> str:
    if photo.kind == 'deb':
        return f'run `{FETCH_COMMAND}` (copies it from the Debian package {photo.package})'
    return f'reinstall the pinned {photo.package} (pip install -r requirements.txt)'


def _checked_file(photo: Photo, photo_dir: str | Path | None) -> Path:
    path = photo_file(photo, photo_dir)
    if not path.is_file():
        raise PhotoError(f'photo {photo.name!r} not found at {path}: {_how_to_get(photo)}')
    actual = _sha256(path)
    if actual != photo.sha256:
        raise PhotoError(f'photo {photo.name!r} at {path} has sha256 {actual}, the manifest '
                         f'expects {photo.sha256}: {_how_to_get(photo)}')
    return path


@lru_cache(maxsize=32)
def _decoded(name: str, manifest_path: str | None, photo_dir: str | None
             ) -> tuple[np.ndarray, float]:
    photo = load_photo_manifest(manifest_path).get(name)
    path = _checked_file(photo, photo_dir)
    bgr = cv2.imdecode(np.fromfile(path, np.uint8), cv2.IMREAD_COLOR)
    if bgr is None:
        raise PhotoError(f'photo {photo.name!r} at {path} cannot be decoded: '
                         f'{_how_to_get(photo)}')
    h, w = bgr.shape[:2]
    factor = min(1.0, MAX_PHOTO_SIDE / max(h, w))
    if factor < 1.0:
        bgr = cv2.resize(bgr, (round(w * factor), round(h * factor)),
                         interpolation=cv2.INTER_AREA)
    rgb = np.ascontiguousarray(bgr[..., ::-1])
    rgb.setflags(write=False)
    return rgb, factor


def load_photo(name: str, *, manifest_path: str | Path | None = None,
               photo_dir: str | Path | None = None) -> tuple[np.ndarray, float]:
    """Photo ``name`` as read-only (H, W, 3) uint8 sRGB, at most ``MAX_PHOTO_SIDE`` long, and
    the factor from file pixels to these pixels; checked against its sha256 and cached.
    Raise :class:`PhotoError` (naming how to get it) when it is missing, altered or broken."""
    return _decoded(name, None if manifest_path is None else str(manifest_path),
                    None if photo_dir is None else str(photo_dir))


def photo_albedo(rng: np.random.Generator, split: str, width: int, height: int,
                 names: Sequence[str] = ()) -> tuple[np.ndarray, Photo]:
    """(height, width, 3) float32 linear albedo of a real scene, and the photo it came from:
    a photo of ``split`` (among ``names`` when given) drawn from ``rng``, cropped to the
    frame's aspect at a zoom of ``ZOOM_RANGE``, flipped left-right half the time, the grain
    of a 'wood' photo stained with a ``WOOD_STAINS`` colour (``WOOD_STAIN_PROBABILITY``), and
    scaled to a mean reflectance in ``ALBEDO_RANGE`` with highlights at most ``MAX_ALBEDO``."""
    choices = load_photo_manifest().of_split(split, names)
    photo = choices[int(rng.integers(len(choices)))]
    rgb, _ = load_photo(photo.name)
    ph, pw = rgb.shape[:2]
    aspect = width / height
    full_w, full_h = (pw, pw / aspect) if pw / ph <= aspect else (ph * aspect, ph)
    zoom = rng.uniform(*ZOOM_RANGE)
    cw, ch = full_w / zoom, full_h / zoom
    x0, y0 = rng.uniform(0.0, pw - cw), rng.uniform(0.0, ph - ch)
    # output pixel centre (u, v) samples photo point (x0 + (u + 0.5) sx - 0.5, ...)
    sx, sy = cw / width, ch / height
    flip = rng.uniform() < 0.5
    ax = -sx if flip else sx
    bx = x0 + (cw - 0.5 * sx if flip else 0.5 * sx) - 0.5
    affine = np.array([[ax, 0.0, bx], [0.0, sy, y0 + 0.5 * sy - 0.5]])
    if sx > 1.2:   # shrinking: pre-filter so the crop does not alias
        rgb = cv2.GaussianBlur(rgb, (0, 0), 0.5 * float(np.sqrt(sx * sx - 1.0)))
    crop = cv2.warpAffine(rgb, affine, (width, height), flags=cv2.INTER_LINEAR
                          | cv2.WARP_INVERSE_MAP, borderMode=cv2.BORDER_REFLECT)
    linear = _SRGB8_TO_LINEAR[crop]
    luma = linear @ LUMINANCE_WEIGHTS.astype(np.float32)
    if 'wood' in photo.tags and rng.uniform() < WOOD_STAIN_PROBABILITY:
        stain = WOOD_STAINS[int(rng.integers(len(WOOD_STAINS)))] * rng.uniform(0.8, 1.2, 3)
        linear = (luma / max(float(luma.mean()), 1e-6))[..., None] * stain.astype(np.float32)
        luma = linear @ LUMINANCE_WEIGHTS.astype(np.float32)
    target = rng.uniform(*ALBEDO_RANGE)
    scale = min(target / max(float(luma.mean()), 1e-6),
                MAX_ALBEDO / max(float(np.percentile(luma, 99.5)), 1e-6))
    return np.clip(linear * scale, 0.0, MAX_ALBEDO).astype(np.float32), photo


# ----------------------------------------------------------------------------- installing
def missing_photos(manifest_path: str | Path | None = None,
                   photo_dir: str | Path | None = None) -> list[str]:
    """Messages for each manifest photo that is missing or does not match its sha256."""
    problems = []
    for photo in load_photo_manifest(manifest_path).photos:
        try:
            _checked_file(photo, photo_dir)
        except PhotoError as exc:
            problems.append(str(exc))
    return problems


def install_debian_photos(extracted_root: str | Path, manifest_path: str | Path | None = None,
                          photo_dir: str | Path | None = None) -> list[str]:
    """Copy each 'deb' photo from ``extracted_root`` (a ``dpkg-deb -x`` tree) into
    ``photo_dir`` unless already there and matching; each file is checked against its sha256
    before it is copied. Return the names copied; raise :class:`PhotoError` on a mismatch."""
    manifest = load_photo_manifest(manifest_path)
    root = Path(extracted_root)
    copied = []
    for photo in manifest.photos:
        if photo.kind != 'deb':
            continue
        target = photo_file(photo, photo_dir)
        if target.is_file() and _sha256(target) == photo.sha256:
            continue
        source = root / photo.path
        if not source.is_file():
            raise PhotoError(f'photo {photo.name!r}: {photo.path} is not in the extracted '
                             f'{photo.package} package at {root}')
        actual = _sha256(source)
        if actual != photo.sha256:
            raise PhotoError(f'photo {photo.name!r}: {photo.package}\'s {photo.path} has '
                             f'sha256 {actual}, the manifest expects {photo.sha256} (another '
                             'package version?)')
        target.parent.mkdir(parents=True, exist_ok=True)
        temporary = target.with_name(f'.{target.name}.tmp')
        shutil.copyfile(source, temporary)
        temporary.replace(target)
        copied.append(photo.name)
    return copied


def main(argv: Sequence[str] | None = None) -> int:
    """``python -m colorglove_ros.core.synthetic.photos``: the steps of fetch_photos.sh."""
    parser = argparse.ArgumentParser(description='Check and install the photo library.')
    parser.add_argument('--manifest', help='photo manifest (default config/photos.yaml)')
    parser.add_argument('--photo-dir', help='where Debian photos go (default data/photos)')
    sub = parser.add_subparsers(dest='command', required=True)
    sub.add_parser('debian-packages', help='print package=version of each Debian source')
    sub.add_parser('check', help='exit 1 listing missing or altered photos')
    install = sub.add_parser('install', help='copy Debian photos from a dpkg-deb -x tree')
    install.add_argument('root')
    args = parser.parse_args(argv)
    try:
        if args.command == 'debian-packages':
            for package, version in load_photo_manifest(args.manifest).debian_packages:
                print(f'{package}={version}')
            return 0
        if args.command == 'install':
            copied = install_debian_photos(args.root, args.manifest, args.photo_dir)
            print(f'copied {len(copied)} photo(s): {", ".join(copied) or "none needed"}')
        problems = missing_photos(args.manifest, args.photo_dir)
        for problem in problems:
            print(problem, file=sys.stderr)
        if not problems:
            print(f'all {len(load_photo_manifest(args.manifest).photos)} photos present and '
                  'matching their sha256')
        return 1 if problems else 0
    except PhotoError as exc:
        print(f'error: {exc}', file=sys.stderr)
        return 1


if __name__ == '__main__':
    sys.exit(main())
