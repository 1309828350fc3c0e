"""Pose database of rendered tiny images: low-dispersion sampling, building, versioned storage."""
from __future__ import annotations

import json
import time
import zlib
from collections.abc import Callable
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Any

import numpy as np
from sklearn.utils.extmath import randomized_svd

from colorglove_ros.core.conventions import (
    DEFAULT_HAND_LENGTH_M,
    NUM_COLORS,
    NUM_PATCHES,
    TINY_SIZE,
)
from colorglove_ros.core.errors import ColorGloveError
from colorglove_ros.core.file_checksums import crc32_matches
from colorglove_ros.core.lookup.codes import (
    BinaryEncoder,
    encoder_from_arrays,
    features_from_dts,
    train_ssc,
)
from colorglove_ros.core.lookup.distance import (
    DT_SCALE,
    QueryDistance,
    dequantize_dts,
    distance_transforms_batch,
    quantize_dts,
)
from colorglove_ros.core.segmentation.crop import crop_signature
from colorglove_ros.core.validation import validate_database_arrays

__all__ = [
    'read_database_config',
    'DATABASE_VERSION', 'DatabaseError', 'PoseDatabase', 'pixel_keys',
    'save_database', 'load_database', 'farthest_point_sampling', 'nearest_neighbour_pairs',
    'train_encoder', 'assemble_database', 'BuildConfig', 'build_database', 'render_views',
    'retrain_codes', 'SSC_SHORTLIST', 'SSC_HARD_NEGATIVES', 'DEFAULT_TRAINING_IMAGES',
]

DATABASE_VERSION = 1
SSC_SHORTLIST = 64
"""Images (nearest in PCA features) searched exactly for each anchor's nearest neighbour."""
DEFAULT_TRAINING_IMAGES = 50_000
"""Images the SSC nearest-neighbour training pairs are drawn from (``BuildConfig``)."""
SSC_HARD_NEGATIVES = 0.5
"""Fraction of the SSC negatives drawn from the far half of an anchor's shortlist (images
that look alike but are not close) instead of random pairs (its effect: docs/RESULTS.md,
Tuning notes)."""
_PAD_KEY = NUM_COLORS * TINY_SIZE * TINY_SIZE   # pixel_keys padding: reads a zero
_MANIFEST = 'manifest.json'

# name -> (dtype, shape with 'N' for the entry count, 'W' code words, 'K' max glove pixels)
_ARRAYS: dict[str, tuple[str, tuple]] = {
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


def read_database_config(path: str | Path) -> tuple[BuildConfig, Path, dict[str, Any]]:
    """Build parameters, the database folder (resolved like every configured path, see
    :func:`colorglove_ros.paths.resolve_path`) and lookup settings of ``config/database.yaml``;
    :class:`DatabaseError` if the file is missing or malformed."""
    from colorglove_ros.core.yaml_io import load_yaml_mapping
    from colorglove_ros.paths import resolve_path

    data = load_yaml_mapping(resolve_path(path), DatabaseError, 'database config').get('database')
    if not isinstance(data, dict) or 'path' not in data:
        raise DatabaseError(f'database config {path} has no database.path')
    known = {f.name for f in fields(BuildConfig)}
    build = {k: v for k, v in (data.get('build') or {}).items() if k in known}
    try:
        config = BuildConfig(**build)
    except TypeError as exc:
        raise DatabaseError(f'database config {path}: bad build settings: {exc}') from exc
    return config, resolve_path(str(data['path'])), dict(data.get('lookup') or {})


class DatabaseError(ColorGloveError):
    """A database directory is missing, corrupt, truncated, inconsistent or of another version."""


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
        return sum(int(getattr(self, name).nbytes) for name in _ARRAYS)

    def check(self) -> None:
        """Raise :class:`DatabaseError` unless all arrays agree in shape and dtype."""
        n = len(self.poses)
        words = (self.encoder.num_bits + 63) // 64
        sizes = {'N': n, 'W': words, 'K': self.pixel_keys.shape[1] if self.pixel_keys.ndim == 2
                 else -1}
        for name, (dtype, shape) in _ARRAYS.items():
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
def _crc32(path: Path) -> int:
    crc = 0
    with path.open('rb') as fh:
        while chunk := fh.read(1 << 24):
            crc = zlib.crc32(chunk, crc)
    return crc


def save_database(db: PoseDatabase, path: str | Path) -> Path:
    """Write ``db`` as a directory of .npy files plus ``manifest.json`` (written last)."""
    db.check()
    path = Path(path)
    path.mkdir(parents=True, exist_ok=True)
    (path / _MANIFEST).unlink(missing_ok=True)
    arrays = {name: getattr(db, name) for name in _ARRAYS}
    arrays.update(db.encoder.to_arrays())
    entries = {}
    for name, arr in arrays.items():
        file = path / f'{name}.npy'
        np.save(file, np.ascontiguousarray(arr), allow_pickle=False)
        entries[name] = {'file': file.name, 'dtype': str(arr.dtype), 'shape': list(arr.shape),
                         'bytes': file.stat().st_size, 'crc32': _crc32(file)}
    manifest = {
        'format': 'colorglove_pose_database', 'version': DATABASE_VERSION,
        'num_entries': len(db), 'num_bits': db.num_bits, 'encoder_kind': db.encoder.kind,
        'encoder_info': db.encoder.info, 'dt_scale': DT_SCALE,
        'render_camera': db.render_camera, 'meta': db.meta, 'arrays': entries,
    }
    (path / _MANIFEST).write_text(json.dumps(manifest, indent=2) + '\n')
    return path


def load_database(path: str | Path, verify: bool = True) -> PoseDatabase:
    """Open a database directory with memory-mapped arrays.

    Raises :class:`DatabaseError` when the directory or manifest is missing, the version
    differs, a file is missing, truncated, of the wrong shape/dtype, or (with ``verify``)
    its CRC-32 does not match the manifest."""
    path = Path(path)
    mpath = path / _MANIFEST
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
    arrays: dict[str, np.ndarray] = {}
    for name, info in manifest.get('arrays', {}).items():
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
    missing = [name for name in _ARRAYS if name not in arrays]
    if missing:
        raise DatabaseError(f'{path}: manifest lacks arrays {missing}')
    try:
        encoder = encoder_from_arrays(str(manifest.get('encoder_kind')), arrays)
    except Exception as exc:
        raise DatabaseError(f'{path}: bad encoder: {exc}') from exc
    db = PoseDatabase(**{name: arrays[name] for name in _ARRAYS}, encoder=encoder,
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

    length = float(db.meta.get('build', {}).get('hand_length_m', DEFAULT_HAND_LENGTH_M))
    validate_database_arrays(db, str(path), build_hand_mesh(HandModel(length)).num_vertices,
                             error=DatabaseError)
    return db


# ------------------------------------------------------------------------------- sampling
def farthest_point_sampling(points: np.ndarray, count: int, seed: int = 0,
                            chunk: int = 8192) -> tuple[np.ndarray, np.ndarray]:
    """Low-dispersion subset by greedy farthest-point sampling under Euclidean distance.

    ``points`` (M, D): the first index is drawn with ``seed``, then each next index is the
    argmax over candidates of the minimum distance to the chosen set. Returns the chosen
    indices (count,) and the covering radius after each pick (count,) (the dispersion)."""
    pts = np.ascontiguousarray(points, dtype=np.float32)
    m = len(pts)
    if not 0 < count <= m:
        raise DatabaseError(f'cannot pick {count} of {m} points')
    rng = np.random.default_rng(seed)
    chosen = np.empty(count, np.intp)
    radius = np.empty(count, np.float64)
    chosen[0] = int(rng.integers(m))
    sq_norm = np.einsum('ij,ij->i', pts, pts)
    min_d2 = np.full(m, np.inf, np.float32)
    for i in range(count):
        c = chosen[i]
        for s in range(0, m, chunk):
            blk = pts[s:s + chunk]
            d2 = sq_norm[s:s + chunk] - 2.0 * (blk @ pts[c]) + sq_norm[c]
            np.minimum(min_d2[s:s + chunk], np.maximum(d2, 0.0), out=min_d2[s:s + chunk])
        if i + 1 < count:
            chosen[i + 1] = int(np.argmax(min_d2))
        radius[i] = float(np.sqrt(min_d2.max()))
    return chosen, radius


def nearest_neighbour_pairs(tiny: np.ndarray, dts: np.ndarray, num_pairs: int, seed: int = 0,
                            shortlist: int = 32, exclude: np.ndarray | None = None,
                            hard_negatives: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """Training pairs for the codes: half positives (an anchor and its nearest neighbour
    under the image distance among the other images), half negatives (random pairs).

    ``tiny`` (M, 40, 40) labels, ``dts`` (M, 10, 40, 40) quantised distance transforms. The
    neighbour is searched exactly among a shortlist of the ``shortlist`` nearest images in
    Euclidean distance of 64 PCA components of the features. ``exclude`` (M,) group ids:
    images sharing an anchor's group are not its neighbours (None: only itself).
    ``hard_negatives`` (0..1) is the fraction of negatives that are hard: an anchor paired
    with a random image from the far half (by exact distance) of its shortlist, i.e. an image
    that looks alike in the PCA features but is not close; the rest are random pairs.
    Returns pairs (P, 2) and similar flags (P,)."""
    if not 0.0 <= hard_negatives <= 1.0:
        raise DatabaseError(f'hard_negatives must be in [0, 1], got {hard_negatives}')
    m = len(tiny)
    if m < 3:
        raise DatabaseError('need at least 3 images to form training pairs')
    rng = np.random.default_rng(seed)
    n_pos = num_pairs // 2
    feats = np.sqrt(features_from_dts(dequantize_dts(dts))).astype(np.float32)
    feats -= feats.mean(axis=0)
    sample = feats[rng.choice(m, size=min(m, 4000), replace=False)]
    _, _, vt = randomized_svd(sample, n_components=min(64, *sample.shape), n_iter=3,
                              random_state=int(rng.integers(2**31)))
    z = feats @ vt.T
    zn = np.einsum('ij,ij->i', z, z)
    anchors = rng.choice(m, size=n_pos, replace=n_pos > m)
    groups = np.arange(m) if exclude is None else np.asarray(exclude)
    pos = np.empty((n_pos, 2), np.intp)
    n_neg = num_pairs - n_pos
    n_hard = min(n_pos, int(round(hard_negatives * n_neg)))
    hard = np.empty((n_hard, 2), np.intp)
    k = min(shortlist + 1, m)
    for s in range(0, n_pos, 512):
        a = anchors[s:s + 512]
        d2 = zn[a, None] - 2.0 * z[a] @ z.T + zn[None, :]
        d2[groups[a][:, None] == groups[None, :]] = np.inf
        short = np.argpartition(d2, k - 1, axis=1)[:, :k]
        for j, anchor in enumerate(a):
            cand = short[j][np.isfinite(d2[j, short[j]])]
            qd = QueryDistance(tiny[anchor], dequantize_dts(dts[anchor]))
            dist = qd.to_many(tiny[cand], dts[cand])
            order = np.argsort(dist, kind='stable')
            pos[s + j] = (anchor, cand[order[0]])
            if s + j < n_hard:
                far = order[max(1, len(order) // 2):]
                hard[s + j] = (anchor, cand[far[int(rng.integers(len(far)))]])
    neg = rng.integers(0, m, size=(n_neg - n_hard, 2))
    neg[:, 1] = np.where(neg[:, 0] == neg[:, 1], (neg[:, 1] + 1) % m, neg[:, 1])
    neg = np.concatenate([hard, neg])
    pairs = np.concatenate([pos, neg])
    similar = np.concatenate([np.ones(n_pos, bool), np.zeros(len(neg), bool)])
    return pairs, similar


def train_encoder(tiny: np.ndarray, dts: np.ndarray, num_bits: int = 192,
                  num_pairs: int = 10_000, seed: int = 0,
                  max_images: int = DEFAULT_TRAINING_IMAGES,
                  exclude: np.ndarray | None = None, shortlist: int = SSC_SHORTLIST,
                  hard_negatives: float = SSC_HARD_NEGATIVES) -> BinaryEncoder:
    """Learn SSC codes on (a seeded subset of at most ``max_images`` of) the images
    (pairs from :func:`nearest_neighbour_pairs`). ``exclude`` (M,) group ids, e.g. the
    finger configuration of each entry: a neighbour is never from the anchor's own group,
    like a query from an unseen configuration."""
    rng = np.random.default_rng(seed)
    m = len(tiny)
    subset = np.sort(rng.choice(m, size=min(m, max_images), replace=False))
    sub_tiny, sub_dts = np.asarray(tiny[subset]), np.asarray(dts[subset])
    groups = None if exclude is None else np.asarray(exclude)[subset]
    pairs, similar = nearest_neighbour_pairs(sub_tiny, sub_dts, num_pairs, seed=seed,
                                             shortlist=shortlist, exclude=groups,
                                             hard_negatives=hard_negatives)
    feats = features_from_dts(dequantize_dts(sub_dts))
    enc = train_ssc(feats, pairs, similar, num_bits=num_bits, seed=seed)
    enc.info.update({'training_images': int(len(subset))})
    return enc


def assemble_database(tiny: np.ndarray, poses: np.ndarray, crop: np.ndarray,
                      render_camera: dict[str, Any], *, config_index: np.ndarray | None = None,
                      patch_xy: np.ndarray | None = None, patch_pixels: np.ndarray | None = None,
                      patch_vertex: np.ndarray | None = None,
                      patch_color: np.ndarray | None = None,
                      encoder: BinaryEncoder | None = None, num_bits: int = 192,
                      num_pairs: int = 10_000, seed: int = 0,
                      meta: dict[str, Any] | None = None,
                      progress: Callable[[str], None] | None = None,
                      max_training_images: int = DEFAULT_TRAINING_IMAGES) -> PoseDatabase:
    """Make a :class:`PoseDatabase` from rendered entries: distance transforms, pixel keys,
    codes (training an SSC encoder on the entries when ``encoder`` is None). Missing patch
    arrays are filled with 'not visible'."""
    tiny = np.ascontiguousarray(tiny, np.uint8)
    n = len(tiny)
    say = progress or (lambda _msg: None)
    say('distance transforms')
    dts = np.empty((n, NUM_COLORS, TINY_SIZE, TINY_SIZE), np.uint8)
    for s in range(0, n, 2048):
        dts[s:s + 2048] = quantize_dts(distance_transforms_batch(tiny[s:s + 2048]))
    keys, counts = pixel_keys(tiny)
    if encoder is None:
        say('training codes')
        encoder = train_encoder(tiny, dts, num_bits=num_bits, num_pairs=num_pairs, seed=seed,
                                max_images=max_training_images, exclude=config_index)
    say('encoding')
    codes = np.empty((n, (encoder.num_bits + 63) // 64), np.uint64)
    for s in range(0, n, 4096):
        codes[s:s + 4096] = encoder.encode_dts(dequantize_dts(dts[s:s + 4096]))
    nan_xy = np.full((n, NUM_PATCHES, 2), np.nan, np.float32)
    db = PoseDatabase(
        poses=np.asarray(poses, np.float32), tiny=tiny, dts=dts, pixel_keys=keys,
        pixel_counts=counts, crop=np.asarray(crop, np.float64),
        codes=np.ascontiguousarray(codes.T),
        config_index=(np.arange(n, dtype=np.int32) if config_index is None
                      else np.asarray(config_index, np.int32)),
        patch_xy=nan_xy if patch_xy is None else np.asarray(patch_xy, np.float32),
        patch_pixels=(np.zeros((n, NUM_PATCHES), np.float32) if patch_pixels is None
                      else np.asarray(patch_pixels, np.float32)),
        patch_vertex=(np.full((n, NUM_PATCHES), -1, np.int32) if patch_vertex is None
                      else np.asarray(patch_vertex, np.int32)),
        patch_color=(np.zeros(NUM_PATCHES, np.uint8) if patch_color is None
                     else np.asarray(patch_color, np.uint8)),
        encoder=encoder, render_camera=dict(render_camera), meta=dict(meta or {}))
    db.check()
    return db


# ------------------------------------------------------------------------------- building
@dataclass(frozen=True)
class BuildConfig:
    """Parameters of :func:`build_database` (``config/database.yaml`` holds the defaults)."""

    entries: int = 100_000
    orientations_per_config: int = 50
    collection_size: int = 18_000
    collection_seed: int = 0
    seed: int = 0
    image_size: int = 128
    focal_px: float = 150.0
    distance_m: float = 0.5
    num_bits: int = 192
    num_pairs: int = 10_000
    training_images: int = DEFAULT_TRAINING_IMAGES
    hand_length_m: float = DEFAULT_HAND_LENGTH_M
    glove_seed: int = 0
    fps_vertices: int = 300
    batch: int = 256
    visibility_tolerance_m: float = 0.004

    def render_camera(self) -> dict[str, float]:
        """Intrinsics of the square database render camera."""
        c = 0.5 * (self.image_size - 1)
        return {'width': self.image_size, 'height': self.image_size, 'fx': self.focal_px,
                'fy': self.focal_px, 'cx': c, 'cy': c}


def _patch_vertices(faces: np.ndarray, face_patch: np.ndarray) -> list[np.ndarray]:
    return [np.unique(faces[face_patch == p]) for p in range(NUM_PATCHES)]


def _nearest_visible_vertices(verts: np.ndarray, depth: np.ndarray, centroids: np.ndarray,
                              patch_verts: list[np.ndarray], cam: dict[str, float],
                              tol: float) -> np.ndarray:
    """(B, 20) index of the visible vertex of each patch nearest (in the image) to the patch
    centroid (full-image pixels); -1 where the patch is not visible."""
    b, h, w = depth.shape
    z = verts[..., 2]
    u = cam['fx'] * verts[..., 0] / z + cam['cx']
    v = cam['fy'] * verts[..., 1] / z + cam['cy']
    iu = np.clip(np.rint(u).astype(np.intp), 0, w - 1)
    iv = np.clip(np.rint(v).astype(np.intp), 0, h - 1)
    zbuf = depth[np.arange(b)[:, None], iv, iu]
    visible = (zbuf > 0) & (z <= zbuf + tol)
    out = np.full((b, NUM_PATCHES), -1, np.int32)
    for p, pv in enumerate(patch_verts):
        if len(pv) == 0:
            continue
        d2 = (u[:, pv] - centroids[:, p, None, 0]) ** 2 + (v[:, pv] - centroids[:, p, None, 1]) ** 2
        d2 = np.where(visible[:, pv] & np.isfinite(d2), d2, np.inf)
        best = np.argmin(d2, axis=1)
        ok = np.isfinite(d2[np.arange(b), best])
        out[ok, p] = pv[best[ok]]
    return out


def build_database(config: BuildConfig,
                   progress: Callable[[str], None] | None = None,
                   bar: Callable[..., Any] | None = None) -> PoseDatabase:
    """Render a database: greedy farthest-point finger configurations from the pose
    collection (pose distance = RMS mesh-vertex distance over a seeded vertex subset), each
    rendered at ``orientations_per_config`` orientations with the hand's centre on the
    optical axis at ``distance_m``, cropped with ``crop_to_tiny`` like camera frames.

    ``bar`` wraps an iterable with a progress bar (e.g. ``tqdm``)."""
    from colorglove_ros.core.camera import PinholeCamera
    from colorglove_ros.core.geometry import rotvec_to_matrix
    from colorglove_ros.core.hand.glove import default_hand
    from colorglove_ros.core.hand.poses import (
        pose_collection,
        sample_global_rotations,
        skin_fingers,
    )
    from colorglove_ros.core.segmentation.crop import crop_to_tiny
    from colorglove_ros.core.synthetic.render import Renderer, patch_centroids, patch_ids_to_labels

    say = progress or (lambda _msg: None)
    wrap = bar or (lambda it, **_kw: it)
    if config.entries < 2 or config.orientations_per_config < 1:
        raise DatabaseError('need at least 2 entries and 1 orientation per configuration')
    timings: dict[str, float] = {}
    t0 = time.perf_counter()
    model, mesh, glove = default_hand(config.hand_length_m, seed=config.glove_seed)
    rng = np.random.default_rng(config.seed)
    # --- low-dispersion finger configurations
    spare = max(8, config.entries // 50)                 # renders that crop_to_tiny may reject
    n_configs = -(-(config.entries + spare) // config.orientations_per_config)
    collection = pose_collection(config.collection_seed, max(config.collection_size, n_configs),
                                 model)
    subset = np.sort(rng.choice(mesh.num_vertices, size=min(config.fps_vertices,
                                                            mesh.num_vertices), replace=False))
    feats = np.concatenate([
        skin_fingers(mesh, model, collection[s:s + 2048])[:, subset].reshape(
            -1, 3 * len(subset)) for s in range(0, len(collection), 2048)])
    feats /= np.sqrt(len(subset))                        # Euclidean = RMS vertex distance
    say(f'farthest-point sampling {n_configs} of {len(collection)} configurations')
    chosen, radius = farthest_point_sampling(feats, n_configs, seed=config.seed)
    del feats
    timings['sampling_s'] = time.perf_counter() - t0
    # --- global poses: hand centre on the optical axis at distance_m
    n_render = n_configs * config.orientations_per_config
    config_of = np.repeat(np.arange(n_configs), config.orientations_per_config)
    rotvecs = sample_global_rotations(rng, n_render)
    rest = mesh.skin_batch(model, np.zeros((1, 26)))[0]
    centre = rest.mean(axis=0)
    cam = config.render_camera()
    camera = PinholeCamera(cam['width'], cam['height'], cam['fx'], cam['fy'], cam['cx'], cam['cy'])
    renderer = Renderer(config.image_size, config.image_size, max_batch=config.batch)
    patch_verts = _patch_vertices(mesh.faces, glove.face_patch)
    n = config.entries
    poses = np.empty((n, 26), np.float32)
    tiny = np.empty((n, TINY_SIZE, TINY_SIZE), np.uint8)
    crop = np.empty((n, 3), np.float64)
    cfg_idx = np.empty(n, np.int32)
    patch_xy = np.full((n, NUM_PATCHES, 2), np.nan, np.float32)
    patch_pixels = np.zeros((n, NUM_PATCHES), np.float32)
    patch_vertex = np.full((n, NUM_PATCHES), -1, np.int32)
    filled, rejected = 0, 0
    t1 = time.perf_counter()
    try:
        for s in wrap(range(0, n_render, config.batch), desc='render', unit='batch'):
            if filled >= n:
                break
            rv = rotvecs[s:s + config.batch]
            R = np.stack([rotvec_to_matrix(r) for r in rv])
            Q = np.zeros((len(rv), 26))
            Q[:, 0:3] = np.array([0.0, 0.0, config.distance_m]) - R @ centre
            Q[:, 3:6] = rv
            Q[:, 6:] = collection[chosen[config_of[s:s + config.batch]]]
            verts = mesh.skin_batch(model, Q)
            ids, depth = renderer.render_patch_ids_depth(verts, mesh.faces, glove.face_patch,
                                                         camera)
            labels = patch_ids_to_labels(ids, glove.patch_color)
            cen, cnt = patch_centroids(ids, NUM_PATCHES)
            vert_idx = _nearest_visible_vertices(verts, depth, cen, patch_verts, cam,
                                                 config.visibility_tolerance_m)
            for j in range(len(rv)):
                if filled >= n:
                    break
                tc = crop_to_tiny(labels[j])
                if tc is None or not tc.labels.any():
                    rejected += 1
                    continue
                tr = tc.transform
                poses[filled] = Q[j]
                tiny[filled] = tc.labels
                crop[filled] = (tr.scale, tr.offset_x, tr.offset_y)
                cfg_idx[filled] = chosen[config_of[s + j]]
                vis = (cnt[j] > 0) & (vert_idx[j] >= 0)
                patch_xy[filled, vis] = tr.to_tiny(cen[j, vis])
                patch_pixels[filled, vis] = cnt[j, vis] / tr.scale ** 2
                patch_vertex[filled, vis] = vert_idx[j, vis]
                filled += 1
    finally:
        renderer.release()
    if filled < n:
        raise DatabaseError(f'only {filled} of {n} renders could be cropped ({rejected} rejected)')
    timings['render_s'] = time.perf_counter() - t1
    t2 = time.perf_counter()
    meta = {
        'build': {k: getattr(config, k) for k in config.__dataclass_fields__},
        'num_configs': int(n_configs), 'rejected_renders': int(rejected),
        'dispersion_m': float(radius[-1]), 'hand_centre_local': centre.tolist(),
        'chosen_configs': int(len(np.unique(cfg_idx))),
        'crop': crop_signature(),
    }
    db = assemble_database(tiny, poses, crop, cam, config_index=cfg_idx, patch_xy=patch_xy,
                           patch_pixels=patch_pixels, patch_vertex=patch_vertex,
                           patch_color=glove.patch_color, num_bits=config.num_bits,
                           num_pairs=config.num_pairs, seed=config.seed, meta=meta,
                           progress=say, max_training_images=config.training_images)
    timings['assemble_s'] = time.perf_counter() - t2
    timings['total_s'] = time.perf_counter() - t0
    db.meta['timings'] = timings
    return db


def render_views(config: BuildConfig, fingers: np.ndarray, rotvecs: np.ndarray
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Render finger configurations (M, 20) at orientations (M, 3) exactly like the database
    entries (same camera, distance, crop). Returns poses (M, 26), tiny images (M, 40, 40),
    crops (M, 3) and a (M,) bool ``ok`` (False where crop_to_tiny rejected the render)."""
    from colorglove_ros.core.camera import PinholeCamera
    from colorglove_ros.core.geometry import rotvec_to_matrix
    from colorglove_ros.core.hand.glove import default_hand
    from colorglove_ros.core.segmentation.crop import crop_to_tiny
    from colorglove_ros.core.synthetic.render import Renderer, patch_ids_to_labels

    model, mesh, glove = default_hand(config.hand_length_m, seed=config.glove_seed)
    fingers = np.atleast_2d(np.asarray(fingers, np.float64))
    rotvecs = np.atleast_2d(np.asarray(rotvecs, np.float64))
    m = len(fingers)
    centre = mesh.skin_batch(model, np.zeros((1, 26)))[0].mean(axis=0)
    R = np.stack([rotvec_to_matrix(r) for r in rotvecs])
    Q = np.zeros((m, 26))
    Q[:, 0:3] = np.array([0.0, 0.0, config.distance_m]) - R @ centre
    Q[:, 3:6] = rotvecs
    Q[:, 6:] = fingers
    cam = config.render_camera()
    camera = PinholeCamera(cam['width'], cam['height'], cam['fx'], cam['fy'], cam['cx'], cam['cy'])
    tiny = np.zeros((m, TINY_SIZE, TINY_SIZE), np.uint8)
    crop = np.zeros((m, 3))
    ok = np.zeros(m, bool)
    renderer = Renderer(config.image_size, config.image_size, max_batch=config.batch)
    try:
        for s in range(0, m, config.batch):
            verts = mesh.skin_batch(model, Q[s:s + config.batch])
            ids = renderer.render_patch_ids(verts, mesh.faces, glove.face_patch, camera)
            labels = patch_ids_to_labels(ids, glove.patch_color)
            for j, lab in enumerate(labels):
                tc = crop_to_tiny(lab)
                if tc is not None and tc.labels.any():
                    tiny[s + j] = tc.labels
                    crop[s + j] = (tc.transform.scale, tc.transform.offset_x,
                                   tc.transform.offset_y)
                    ok[s + j] = True
    finally:
        renderer.release()
    return Q, tiny, crop, ok


def retrain_codes(path: str | Path, num_bits: int = 192, num_pairs: int = 10_000,
                  seed: int = 0, max_images: int = DEFAULT_TRAINING_IMAGES
                  ) -> BinaryEncoder:
    """Learn a new SSC encoder on an existing database's images and rewrite its codes,
    encoder arrays and manifest in place (the rendered entries are kept)."""
    path = Path(path)
    db = load_database(path)
    encoder = train_encoder(db.tiny, db.dts, num_bits=num_bits, num_pairs=num_pairs,
                            seed=seed, max_images=max_images,
                            exclude=np.asarray(db.config_index))
    n = len(db)
    codes = np.empty((n, (encoder.num_bits + 63) // 64), np.uint64)
    for s in range(0, n, 4096):
        codes[s:s + 4096] = encoder.encode_dts(dequantize_dts(db.dts[s:s + 4096]))
    manifest = json.loads((path / _MANIFEST).read_text())
    del db                                   # release the memory maps before rewriting files
    (path / _MANIFEST).unlink()
    for name in [k for k in manifest['arrays'] if k.startswith('encoder_')]:
        (path / manifest['arrays'].pop(name)['file']).unlink(missing_ok=True)
    arrays = {'codes': np.ascontiguousarray(codes.T), **encoder.to_arrays()}
    for name, arr in arrays.items():
        file = path / f'{name}.npy'
        tmp = path / f'.{name}.npy.tmp'
        with tmp.open('wb') as fh:           # new inode: readers holding a memory map of the
            np.save(fh, arr, allow_pickle=False)   # old file keep valid (old) data, no SIGBUS
        tmp.replace(file)
        manifest['arrays'][name] = {'file': file.name, 'dtype': str(arr.dtype),
                                    'shape': list(arr.shape), 'bytes': file.stat().st_size,
                                    'crc32': _crc32(file)}
    manifest.update({'num_bits': encoder.num_bits, 'encoder_kind': encoder.kind,
                     'encoder_info': encoder.info})
    (path / _MANIFEST).write_text(json.dumps(manifest, indent=2) + '\n')
    return encoder
