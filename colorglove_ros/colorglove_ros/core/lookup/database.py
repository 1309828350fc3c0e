"""Versioned storage of a pose database: the entry arrays (:class:`PoseDatabase`), a folder of
.npy files with a ``manifest.json`` of shapes, dtypes and CRC-32 checksums, and its checks on
load. Building a database (sampling, rendering, code training) is
:mod:`colorglove_ros.core.lookup.database_build`; loading one imports neither the renderer nor
scikit-learn."""
from __future__ import annotations

import json
import mmap
import os
import threading
import zlib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from colorglove_ros.core.conventions import (
    DEFAULT_GLOVE_SEED,
    DEFAULT_HAND_LENGTH_M,
    MODEL_HAND_LENGTH_RANGE_M,
    NUM_COLORS,
    NUM_PATCHES,
    TINY_SIZE,
)
from colorglove_ros.core.errors import ColorGloveError
from colorglove_ros.core.file_checksums import check_unless_passed, crc32_matches, crc32_of_file
from colorglove_ros.core.lookup.codes import BinaryEncoder, encoder_from_arrays
from colorglove_ros.core.lookup.distance import DT_SCALE
from colorglove_ros.core.segmentation.crop import crop_signature
from colorglove_ros.core.validation import validate_database_arrays

__all__ = [
    'DATABASE_VERSION', 'MANIFEST_NAME', 'ENTRY_ARRAYS', 'DatabaseError', 'PoseDatabase',
    'DatabaseBuild', 'contents_tag', 'pixel_keys', 'manifest_entry', 'save_database',
    'load_database', 'read_database_build', 'check_hand_length', 'STANDARD_BUILD',
    'read_into_page_cache', 'start_reading_into_page_cache', 'map_into_process',
]

DATABASE_VERSION = 1
MANIFEST_NAME = 'manifest.json'
"""The file of a database folder that describes (and checksums) every array file."""
_PAD_KEY = NUM_COLORS * TINY_SIZE * TINY_SIZE   # pixel_keys padding: reads a zero

ENTRY_ARRAYS: dict[str, tuple[str, tuple]] = {
    'poses': ('float32', ('N', 26)),
    'tiny': ('uint8', ('N', TINY_SIZE, TINY_SIZE)),
    'dts': ('uint8', ('N', NUM_COLORS, TINY_SIZE, TINY_SIZE)),
    'pixel_keys': ('uint16', ('N', 'K')),
    'pixel_counts': ('uint16', ('N',)),
    'crop': ('float64', ('N', 3)),
    'codes': ('uint64', ('W', 'N')),
    'config_index': ('int32', ('N',)),
    'patch_xy': ('float32', ('N', NUM_PATCHES, 2)),
    'patch_pixels': ('float32', ('N', NUM_PATCHES)),
    'patch_vertex': ('int32', ('N', NUM_PATCHES)),
    'patch_color': ('uint8', (NUM_PATCHES,)),
}
"""Entry arrays of a database: name -> (dtype, shape with 'N' for the entry count, 'W' code
words, 'K' max glove pixels)."""


CONTENTS_CHECK = 'database contents v1'
"""Name of the remembered contents check (``validate_database_arrays``); change it when what
that check accepts changes, so every database is checked again."""


class DatabaseError(ColorGloveError):
    """A database directory is missing, corrupt, truncated, inconsistent or of another version."""


@dataclass(frozen=True)
class DatabaseBuild:
    """The hand a database was rendered with, recorded in its manifest (``meta.build``): the
    one source of the glove seed and hand length every other stage must use."""

    hand_length_m: float
    glove_seed: int

    @classmethod
    def from_meta(cls, meta: dict[str, Any], where: str) -> DatabaseBuild:
        """The build record of a manifest's ``meta``; :class:`DatabaseError` naming ``where``
        when it is missing or malformed."""
        build = meta.get('build') if isinstance(meta, dict) else None
        if not isinstance(build, dict) or 'hand_length_m' not in build \
                or 'glove_seed' not in build:
            raise DatabaseError(f'{where}: the manifest does not record the hand length and glove '
                                'seed the database was built for (meta.build.hand_length_m, '
                                'glove_seed); rebuild it with colorglove_build_database')
        length, seed = build['hand_length_m'], build['glove_seed']
        if isinstance(length, bool) or not isinstance(length, (int, float)) \
                or not MODEL_HAND_LENGTH_RANGE_M[0] <= float(length) \
                <= MODEL_HAND_LENGTH_RANGE_M[1]:
            raise DatabaseError(f'{where}: meta.build.hand_length_m {length!r} is not a hand '
                                'length in metres')
        if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
            raise DatabaseError(f'{where}: meta.build.glove_seed {seed!r} is not a seed')
        return cls(float(length), int(seed))


STANDARD_BUILD = DatabaseBuild(DEFAULT_HAND_LENGTH_M, DEFAULT_GLOVE_SEED)
"""The standard hand and glove (what ``default_hand()`` makes)."""


@dataclass
class PoseDatabase:
    """All entries of a pose database (arrays may be read-only memory maps).

    ``poses`` (N, 26) float32 rendered pose (camera frame of ``render_camera``);
    ``tiny`` (N, 40, 40) uint8 label images; ``dts`` (N, 10, 40, 40) uint8 distance
    transforms quantised with DT_SCALE; ``pixel_keys`` (N, K) uint16 glove pixels as
    ``(label - 1) * 1600 + y * 40 + x`` padded with 16000; ``pixel_counts`` (N,);
    ``crop`` (N, 3) float64 crop transform (scale, offset_x, offset_y) of the render;
    ``codes`` (W, N) uint64 packed codes, one contiguous row per 64-bit word;
    ``config_index`` (N,) row of the pose collection each entry's fingers come from;
    ``patch_xy`` (N, 20, 2) patch centroids in tiny-image pixels (NaN if not visible);
    ``patch_pixels`` (N, 20) visible patch area in tiny-image pixels;
    ``patch_vertex`` (N, 20) mesh vertex nearest each centroid among the visible vertices
    of that patch (-1 if none); ``patch_color`` (20,) colour label of each patch."""

    poses: np.ndarray
    tiny: np.ndarray
    dts: np.ndarray
    pixel_keys: np.ndarray
    pixel_counts: np.ndarray
    crop: np.ndarray
    codes: np.ndarray
    config_index: np.ndarray
    patch_xy: np.ndarray
    patch_pixels: np.ndarray
    patch_vertex: np.ndarray
    patch_color: np.ndarray
    encoder: BinaryEncoder
    render_camera: dict[str, Any]
    meta: dict[str, Any] = field(default_factory=dict)

    def __len__(self) -> int:
        return len(self.poses)

    @property
    def num_bits(self) -> int:
        """Code length in bits."""
        return self.encoder.num_bits

    @property
    def nbytes(self) -> int:
        """Total bytes of the entry arrays."""
        return sum(int(getattr(self, name).nbytes) for name in ENTRY_ARRAYS)

    @property
    def build(self) -> DatabaseBuild:
        """The hand this database was built for (from its manifest)."""
        return DatabaseBuild.from_meta(self.meta, 'pose database')

    def check(self) -> None:
        """Raise :class:`DatabaseError` unless all arrays agree in shape and dtype."""
        n = len(self.poses)
        words = (self.encoder.num_bits + 63) // 64
        sizes = {'N': n, 'W': words, 'K': self.pixel_keys.shape[1] if self.pixel_keys.ndim == 2
                 else -1}
        for name, (dtype, shape) in ENTRY_ARRAYS.items():
            arr = getattr(self, name)
            want = tuple(sizes[s] if isinstance(s, str) else s for s in shape)
            if arr.dtype != np.dtype(dtype) or arr.shape != want:
                raise DatabaseError(f'array {name!r} is {arr.dtype}{arr.shape}, '
                                    f'expected {dtype}{want}')


def pixel_keys(tiny: np.ndarray, width: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Glove pixels of (N, 40, 40) label images as padded key rows (N, K) uint16 and counts."""
    n = len(tiny)
    flat = tiny.reshape(n, -1)
    counts = np.count_nonzero(flat, axis=1)
    k = int(counts.max()) if width is None and n else (width or 0)
    keys = np.full((n, max(k, 1)), _PAD_KEY, np.uint16)
    for i in range(n):
        pix = np.flatnonzero(flat[i])
        keys[i, :len(pix)] = (flat[i, pix].astype(np.int64) - 1) * flat.shape[1] + pix
    return keys, counts.astype(np.uint16)


# ------------------------------------------------------------------------------- storage
def manifest_entry(file: Path, arr: np.ndarray) -> dict[str, Any]:
    """The manifest record of an array file just written from ``arr``: file name, dtype,
    shape, size in bytes and CRC-32."""
    return {'file': file.name, 'dtype': str(arr.dtype), 'shape': list(arr.shape),
            'bytes': file.stat().st_size, 'crc32': crc32_of_file(file)}


def save_database(db: PoseDatabase, path: str | Path) -> Path:
    """Write ``db`` as a directory of .npy files plus ``manifest.json`` (written last)."""
    db.check()
    path = Path(path)
    path.mkdir(parents=True, exist_ok=True)
    (path / MANIFEST_NAME).unlink(missing_ok=True)
    arrays = {name: getattr(db, name) for name in ENTRY_ARRAYS}
    arrays.update(db.encoder.to_arrays())
    entries = {}
    for name, arr in arrays.items():
        file = path / f'{name}.npy'
        np.save(file, np.ascontiguousarray(arr), allow_pickle=False)
        entries[name] = manifest_entry(file, arr)
    manifest = {
        'format': 'colorglove_pose_database', 'version': DATABASE_VERSION,
        'num_entries': len(db), 'num_bits': db.num_bits, 'encoder_kind': db.encoder.kind,
        'encoder_info': db.encoder.info, 'dt_scale': DT_SCALE,
        'render_camera': db.render_camera, 'meta': db.meta, 'arrays': entries,
    }
    (path / MANIFEST_NAME).write_text(json.dumps(manifest, indent=2) + '\n')
    return path


def _read_manifest(path: Path) -> dict[str, Any]:
    """The checked manifest of the database folder ``path`` (format, version, dt_scale, build
    record); :class:`DatabaseError` naming the file otherwise."""
    mpath = path / MANIFEST_NAME
    if not path.is_dir():
        raise DatabaseError(f'pose database not found: {path} (build it with '
                            'python -m colorglove_ros.tools.build_database)')
    try:
        manifest = json.loads(mpath.read_text())
    except FileNotFoundError as exc:
        raise DatabaseError(f'{mpath} missing: incomplete or not a pose database') from exc
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise DatabaseError(f'{mpath} is corrupt: {exc}') from exc
    if not isinstance(manifest, dict) or manifest.get('format') != 'colorglove_pose_database':
        raise DatabaseError(f'{mpath} is not a pose database manifest')
    if manifest.get('version') != DATABASE_VERSION:
        raise DatabaseError(f'{path}: database version {manifest.get("version")!r}, this code '
                            f'reads version {DATABASE_VERSION}; rebuild the database')
    if manifest.get('dt_scale') != DT_SCALE:
        raise DatabaseError(f'{path}: dt_scale {manifest.get("dt_scale")} != {DT_SCALE}')
    DatabaseBuild.from_meta(manifest.get('meta', {}), str(mpath))
    return manifest


def contents_tag(path: str | Path) -> str:
    """A short name of the contents of the database at ``path`` (the checksums of its poses and
    codes in its manifest), for the file names of caches computed with it: a rebuilt or another
    database gets another name. :class:`DatabaseError` when the manifest does not list them."""
    path = Path(path)
    arrays = _read_manifest(path).get('arrays')
    try:
        key = f"{arrays['poses']['crc32']}:{arrays['codes']['crc32']}"
    except (KeyError, TypeError) as exc:
        raise DatabaseError(f'{path / MANIFEST_NAME} does not list the poses and codes '
                            f'checksums ({exc!r}): an incomplete manifest') from exc
    return f'db{zlib.crc32(key.encode()):08x}'


def read_database_build(path: str | Path) -> DatabaseBuild:
    """The hand the database at ``path`` was built for, read from its manifest alone (cheap:
    no array is opened), for stages that need the glove and hand but not the entries."""
    path = Path(path)
    return DatabaseBuild.from_meta(_read_manifest(path)['meta'], str(path / MANIFEST_NAME))


def check_hand_length(build: DatabaseBuild, hand_length_m: float, calibration: str,
                      database: str) -> None:
    """:class:`DatabaseError` unless the calibration's hand length is the database's: the
    lookup's depth and the IK's hand model both come from it."""
    if abs(float(hand_length_m) - build.hand_length_m) > 1e-6:
        raise DatabaseError(
            f'{calibration}: hand_length_m {hand_length_m} but the pose database {database} was '
            f'built for a {build.hand_length_m} m hand; rebuild the database with '
            f'hand_length_m: {hand_length_m} in config/database.yaml or fix the calibration')


def read_into_page_cache(path: str | Path, chunk_bytes: int = 1 << 24) -> int:
    """Read every array file of the database folder ``path`` once, start to end, and return
    the bytes read. The arrays are memory-mapped and the re-rank reads rows of the largest at
    random; from a cold page cache (after a boot) each such row is a disk read on the first
    lookups, while one sequential pass puts the files in the cache. The kernel's own read-ahead
    advice (``posix_fadvise`` WILLNEED) reads only a little of a large file, so the files are
    read here. Meant for a background thread: :func:`start_reading_into_page_cache`."""
    path = Path(path)
    listed = _read_manifest(path).get('arrays', {})
    buffer = bytearray(chunk_bytes)
    total = 0
    for info in listed.values():
        with open(path / str(info.get('file', '')), 'rb', buffering=0) as file:
            while count := file.readinto(buffer):
                total += count
    return total


def map_into_process(database: PoseDatabase) -> int:
    """Read one byte of every page of ``database``'s memory-mapped arrays through their
    mappings and return the pages read. A page in the page cache but not yet mapped into
    this process costs a (minor) page fault on its first read, and the re-rank reads rows of
    the largest arrays at random: in a fresh process the lookups meet tens of such faults each
    until most rows have been read once. Arrays that are not memory maps are left alone."""
    pages = 0
    for name in ENTRY_ARRAYS:
        arr = getattr(database, name)
        if not isinstance(arr, np.memmap) or not arr.flags.c_contiguous or not arr.size:
            continue
        data = np.asarray(arr).reshape(-1).view(np.uint8)[::mmap.PAGESIZE]
        data.sum(dtype=np.uint64)      # (the read maps the page; the sum is not used)
        pages += len(data)
    return pages


def _read_at_lowest_priority(path: Path, database: PoseDatabase | None) -> None:
    """:func:`map_into_process` of ``database`` (if any), then :func:`read_into_page_cache`,
    on a thread lowered to nice 19 (Linux threads have their own priority; elsewhere it
    reads at the process's)."""
    try:
        os.setpriority(os.PRIO_PROCESS, threading.get_native_id(), 19)
    except (AttributeError, OSError):
        pass
    if database is not None:
        map_into_process(database)
    read_into_page_cache(path)


def start_reading_into_page_cache(path: str | Path, database: PoseDatabase | None = None
                                  ) -> threading.Thread:
    """:func:`read_into_page_cache` of ``path`` on a daemon thread at the lowest CPU priority,
    started (a node calls it once its database is loaded, so its first lookups after a cold
    start do not wait for the disk, while the reading yields the CPU to the node's work; an
    error reading is reported by the thread, the lookups are unaffected). With ``database``
    (the one loaded from ``path``) its arrays' pages are first mapped into the process
    (:func:`map_into_process`), so that the first lookups do not each take the page faults."""
    thread = threading.Thread(target=_read_at_lowest_priority, args=(Path(path), database),
                              name='database page cache', daemon=True)
    thread.start()
    return thread


def load_database(path: str | Path, verify: bool = True) -> PoseDatabase:
    """Open a database directory with memory-mapped arrays.

    Raises :class:`DatabaseError` when the directory or manifest is missing, the version
    differs, a file is missing, truncated, of the wrong shape/dtype, or (with ``verify``)
    its CRC-32 does not match the manifest."""
    path = Path(path)
    manifest = _read_manifest(path)
    arrays: dict[str, np.ndarray] = {}
    listed = manifest.get('arrays')
    if not isinstance(listed, dict) or not all(isinstance(i, dict) for i in listed.values()):
        raise DatabaseError(f'{path / MANIFEST_NAME}: arrays must map names to file entries')
    for name, info in listed.items():
        file = path / str(info.get('file', ''))
        if not file.is_file():
            raise DatabaseError(f'{path}: array file {file.name!r} missing')
        size = file.stat().st_size
        if size != info.get('bytes'):
            raise DatabaseError(f'{file}: {size} bytes, manifest says {info.get("bytes")} '
                                '(truncated or modified)')
        if verify and not crc32_matches(file, info.get('crc32')):   # cached when unchanged
            raise DatabaseError(f'{file}: checksum mismatch (corrupt)')
        try:
            arr = np.load(file, mmap_mode='r', allow_pickle=False)
        except (ValueError, OSError) as exc:
            raise DatabaseError(f'{file}: unreadable .npy: {exc}') from exc
        if str(arr.dtype) != info.get('dtype') or list(arr.shape) != info.get('shape'):
            raise DatabaseError(f'{file}: {arr.dtype}{arr.shape} does not match the manifest')
        arrays[name] = arr
    missing = [name for name in ENTRY_ARRAYS if name not in arrays]
    if missing:
        raise DatabaseError(f'{path}: manifest lacks arrays {missing}')
    try:
        encoder = encoder_from_arrays(str(manifest.get('encoder_kind')), arrays)
    except Exception as exc:
        raise DatabaseError(f'{path}: bad encoder: {exc}') from exc
    db = PoseDatabase(**{name: arrays[name] for name in ENTRY_ARRAYS}, encoder=encoder,
                      render_camera=dict(manifest.get('render_camera', {})),
                      meta=dict(manifest.get('meta', {})))
    if len(db) != manifest.get('num_entries'):
        raise DatabaseError(f'{path}: {len(db)} entries, manifest says '
                            f'{manifest.get("num_entries")}')
    built_crop = db.meta.get('crop')
    if built_crop is not None and built_crop != crop_signature():
        raise DatabaseError(f'{path}: built with crop {built_crop}, this code crops with '
                            f'{crop_signature()}; rebuild the database')
    db.check()
    # patch vertices must be vertices of the standard hand mesh the lookup and the IK use
    from colorglove_ros.core.hand.mesh import build_hand_mesh
    from colorglove_ros.core.hand.model import HandModel

    num_vertices = build_hand_mesh(HandModel(db.build.hand_length_m)).num_vertices
    # reading every entry takes seconds: done once, then again only when a file changes
    files = [path / MANIFEST_NAME] + [path / str(info['file']) for info in listed.values()]
    check_unless_passed(files, f'{CONTENTS_CHECK} {num_vertices} vertices',
                        lambda: validate_database_arrays(db, str(path), num_vertices,
                                                         error=DatabaseError))
    return db
