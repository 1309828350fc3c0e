"""Building a pose database: low-dispersion sampling of finger configurations, rendering them
at many orientations like camera frames, assembling the entries (distance transforms, pixel
keys) and training their binary codes. The stored format is
:mod:`colorglove_ros.core.lookup.database`."""
from __future__ import annotations

import json
import time
from collections.abc import Callable
from dataclasses import dataclass, fields
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from colorglove_ros.core.conventions import (
    DEFAULT_GLOVE_SEED,
    DEFAULT_HAND_LENGTH_M,
    MODEL_HAND_LENGTH_RANGE_M,
    NUM_COLORS,
    NUM_PATCHES,
    TINY_SIZE,
)
from colorglove_ros.core.lookup.codes import BinaryEncoder, features_from_dts, train_ssc
from colorglove_ros.core.lookup.database import (
    MANIFEST_NAME,
    STANDARD_BUILD,
    DatabaseBuild,
    DatabaseError,
    PoseDatabase,
    load_database,
    manifest_entry,
    pixel_keys,
)
from colorglove_ros.core.lookup.distance import (
    QueryDistance,
    dequantize_dts,
    distance_transforms_batch,
    quantize_dts,
)
from colorglove_ros.core.segmentation.crop import TinyCrop, crop_signature
from colorglove_ros.core.validation import check_known_keys, check_number

if TYPE_CHECKING:
    from colorglove_ros.core.camera import PinholeCamera
    from colorglove_ros.core.hand.mesh import HandMesh
    from colorglove_ros.core.hand.model import HandModel

__all__ = [
    'read_database_config', 'BuildConfig', 'build_database', 'render_views', 'view_poses',
    'sample_configurations', 'farthest_point_sampling', 'nearest_neighbour_pairs',
    'train_encoder', 'encode_entries', 'assemble_database', 'retrain_codes',
    'SSC_SHORTLIST', 'SSC_HARD_NEGATIVES', 'DEFAULT_TRAINING_IMAGES',
]

SSC_SHORTLIST = 64
"""Images (nearest in PCA features) searched exactly for each anchor's nearest neighbour."""
DEFAULT_TRAINING_IMAGES = 50_000
"""Images the SSC nearest-neighbour training pairs are drawn from (``BuildConfig``)."""
SSC_HARD_NEGATIVES = 0.5
"""Fraction of the SSC negatives drawn from the far half of an anchor's shortlist (images
that look alike but are not close) instead of random pairs (its effect: docs/RESULTS.md,
Tuning notes)."""


# ------------------------------------------------------------------------------- configuration
_BUILD_LIMITS: dict[str, tuple[type, float, float]] = {
    # name: (int: [lowest, highest], or float: (lowest, highest])
    'entries': (int, 1, 10_000_000), 'orientations_per_config': (int, 1, 100_000),
    'collection_size': (int, 1, 10_000_000), 'collection_seed': (int, 0, 2**32 - 1),
    'seed': (int, 0, 2**32 - 1), 'image_size': (int, 16, 4096),
    'focal_px': (float, 0.0, 1e5), 'distance_m': (float, 0.0, 10.0),
    'num_bits': (int, 1, 4096), 'num_pairs': (int, 1, 10_000_000),
    'training_images': (int, 2, 10_000_000), 'hand_length_m': (float, *MODEL_HAND_LENGTH_RANGE_M),
    'glove_seed': (int, 0, 2**32 - 1), 'fps_vertices': (int, 1, 100_000),
    'batch': (int, 1, 100_000), 'visibility_tolerance_m': (float, 0.0, 0.1),
    'named_shape_configs': (int, 0, 10_000_000),
}
"""The range of every :class:`BuildConfig` number the build can run with."""
LOOKUP_SETTINGS: dict[str, tuple[int, int]] = {'num_candidates': (1, 100_000),
                                               'num_blend': (1, 300)}
"""The ``database.lookup`` settings of ``config/database.yaml`` and their ranges."""


@dataclass(frozen=True)
class BuildConfig:
    """Parameters of :func:`build_database` (``config/database.yaml`` holds the defaults).

    ``named_shape_configs``: how many of the finger configurations are first picked among the
    pose collection's named shapes and their noisy copies (finger-spelling letters and
    gestures, :func:`sample_configurations`); 0: all picked over the whole collection.
    ``pinch_shapes``: the collection's named shapes include ``poses.PINCH_SHAPES`` (the thumb
    on the middle, ring or little fingertip; off: the collection without them)."""

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
    glove_seed: int = DEFAULT_GLOVE_SEED
    fps_vertices: int = 300
    batch: int = 256
    visibility_tolerance_m: float = 0.004
    named_shape_configs: int = 0
    pinch_shapes: bool = False

    def __post_init__(self) -> None:
        if not isinstance(self.pinch_shapes, bool):
            raise DatabaseError(f'pinch_shapes must be true or false, got {self.pinch_shapes!r}')
        for name, (kind, low, high) in _BUILD_LIMITS.items():
            value = check_number(name, getattr(self, name), low=low, high=high,
                                 low_open=kind is float, integer=kind is int,
                                 error=DatabaseError)
            object.__setattr__(self, name, value)

    def render_camera(self) -> dict[str, float]:
        """Intrinsics of the square database render camera."""
        c = 0.5 * (self.image_size - 1)
        return {'width': self.image_size, 'height': self.image_size, 'fx': self.focal_px,
                'fy': self.focal_px, 'cx': c, 'cy': c}


def read_database_config(path: str | Path) -> tuple[BuildConfig, Path, dict[str, Any]]:
    """Build parameters, the database folder (resolved like every configured path, see
    :func:`colorglove_ros.paths.resolve_path`) and lookup settings of ``config/database.yaml``;
    :class:`DatabaseError` if the file is missing or malformed."""
    from colorglove_ros.core.yaml_io import load_yaml_mapping
    from colorglove_ros.paths import resolve_path

    document = load_yaml_mapping(resolve_path(path), DatabaseError, 'database config')
    data = document.get('database')
    check_known_keys(f'database config {path}', document, ('database',), error=DatabaseError)
    if not isinstance(data, dict) or not isinstance(data.get('path'), str) or not data['path']:
        raise DatabaseError(f'database config {path} has no database.path')
    check_known_keys(f'database config {path}: database', data, ('path', 'build', 'lookup'),
                     error=DatabaseError)
    lookup = data.get('lookup') or {}
    if not isinstance(lookup, dict):
        raise DatabaseError(f'database config {path}: database.lookup must be a mapping')
    check_known_keys(f'database config {path}: database.lookup', lookup, LOOKUP_SETTINGS,
                     error=DatabaseError)
    for name, value in lookup.items():
        check_number(f'database config {path}: database.lookup.{name}', value,
                     low=LOOKUP_SETTINGS[name][0], high=LOOKUP_SETTINGS[name][1], integer=True,
                     error=DatabaseError)
    known = {f.name for f in fields(BuildConfig)}
    build = data.get('build') or {}
    if not isinstance(build, dict):
        raise DatabaseError(f'database config {path}: database.build must be a mapping')
    check_known_keys(f'database config {path}: database.build', build, known,
                     error=DatabaseError)
    try:
        config = BuildConfig(**build)
    except (TypeError, DatabaseError) as exc:
        raise DatabaseError(f'database config {path}: bad build settings: {exc}') from exc
    return config, resolve_path(data['path']), dict(lookup)


# ------------------------------------------------------------------------------- sampling
def farthest_point_sampling(points: np.ndarray, count: int, seed: int = 0,
                            chunk: int = 8192, initial: np.ndarray | None = None
                            ) -> tuple[np.ndarray, np.ndarray]:
    """Low-dispersion subset by greedy farthest-point sampling under Euclidean distance.

    ``points`` (M, D): the first index is drawn with ``seed`` (or the picks start with the
    distinct indices ``initial``), then each next index is the argmax over candidates of the
    minimum distance to the chosen set. Returns the chosen indices (count,) and the covering
    radius after each pick (count,) (the dispersion)."""
    pts = np.ascontiguousarray(points, dtype=np.float32)
    m = len(pts)
    if not 0 < count <= m:
        raise DatabaseError(f'cannot pick {count} of {m} points')
    start = np.zeros(0, np.intp) if initial is None else np.asarray(initial, np.intp).ravel()
    if len(start) > count or len(np.unique(start)) != len(start) or \
            np.any((start < 0) | (start >= m)):
        raise DatabaseError(f'initial picks must be at most {count} distinct indices < {m}')
    rng = np.random.default_rng(seed)
    chosen = np.empty(count, np.intp)
    radius = np.empty(count, np.float64)
    chosen[:len(start)] = start
    if not len(start):
        chosen[0] = int(rng.integers(m))
    sq_norm = np.einsum('ij,ij->i', pts, pts)
    min_d2 = np.full(m, np.inf, np.float32)
    for i in range(count):
        c = chosen[i]
        for s in range(0, m, chunk):
            blk = pts[s:s + chunk]
            d2 = sq_norm[s:s + chunk] - 2.0 * (blk @ pts[c]) + sq_norm[c]
            np.minimum(min_d2[s:s + chunk], np.maximum(d2, 0.0), out=min_d2[s:s + chunk])
        if len(start) <= i + 1 < count:
            chosen[i + 1] = int(np.argmax(min_d2))
        radius[i] = float(np.sqrt(min_d2.max()))
    return chosen, radius


def sample_configurations(config: BuildConfig, count: int, model: HandModel, mesh: HandMesh,
                          rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``count`` low-dispersion finger configurations of the pose collection: greedy
    farthest-point sampling under the RMS distance of a seeded subset of
    ``config.fps_vertices`` mesh vertices. The first ``config.named_shape_configs`` picks are
    made among the named shapes and their noisy copies only (a denser cover of the letters and
    gestures), the rest over the whole collection from there. Returns the collection (M, 20),
    the chosen rows (count,) and the covering radius after each pick (count,) (m)."""
    from colorglove_ros.core.hand.poses import (
        named_neighbourhood_rows,
        pose_collection,
        skin_fingers,
    )

    collection = pose_collection(config.collection_seed, max(config.collection_size, count),
                                 model, config.pinch_shapes)
    subset = np.sort(rng.choice(mesh.num_vertices, size=min(config.fps_vertices,
                                                            mesh.num_vertices), replace=False))
    feats = np.concatenate([
        skin_fingers(mesh, model, collection[s:s + 2048])[:, subset].reshape(
            -1, 3 * len(subset)) for s in range(0, len(collection), 2048)])
    feats /= np.sqrt(len(subset))                        # Euclidean = RMS vertex distance
    named = min(config.named_shape_configs, count)
    initial = None
    if named:
        rows = named_neighbourhood_rows(len(collection), config.pinch_shapes)
        if named > rows:
            raise DatabaseError(f'named_shape_configs {named} is more than the '
                                f'{rows} named-shape rows of the pose collection')
        initial, _ = farthest_point_sampling(feats[:rows], named, seed=config.seed)
    chosen, radius = farthest_point_sampling(feats, count, seed=config.seed, initial=initial)
    return collection, chosen, radius


# ------------------------------------------------------------------------------- codes
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
    from sklearn.utils.extmath import randomized_svd  # heavy: only when training codes

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


def encode_entries(encoder: BinaryEncoder, dts: np.ndarray, chunk: int = 4096) -> np.ndarray:
    """Codes of quantised distance transforms (N, 10, 40, 40) as the database stores them:
    (W, N) uint64, one contiguous row per 64-bit word."""
    n = len(dts)
    codes = np.empty((n, (encoder.num_bits + 63) // 64), np.uint64)
    for s in range(0, n, chunk):
        codes[s:s + chunk] = encoder.encode_dts(dequantize_dts(dts[s:s + chunk]))
    return np.ascontiguousarray(codes.T)


# ------------------------------------------------------------------------------- assembling
def assemble_database(tiny: np.ndarray, poses: np.ndarray, crop: np.ndarray,
                      render_camera: dict[str, Any], *, config_index: np.ndarray | None = None,
                      patch_xy: np.ndarray | None = None, patch_pixels: np.ndarray | None = None,
                      patch_vertex: np.ndarray | None = None,
                      patch_color: np.ndarray | None = None,
                      encoder: BinaryEncoder | None = None, num_bits: int = 192,
                      num_pairs: int = 10_000, seed: int = 0,
                      meta: dict[str, Any] | None = None,
                      build: DatabaseBuild = STANDARD_BUILD,
                      progress: Callable[[str], None] | None = None,
                      max_training_images: int = DEFAULT_TRAINING_IMAGES) -> PoseDatabase:
    """Make a :class:`PoseDatabase` from rendered entries: distance transforms, pixel keys,
    codes (training an SSC encoder on the entries when ``encoder`` is None). Missing patch
    arrays are filled with 'not visible'. ``build`` is the hand the entries were rendered with
    (recorded as ``meta.build`` unless ``meta`` has a build record already)."""
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
    codes = encode_entries(encoder, dts)
    nan_xy = np.full((n, NUM_PATCHES, 2), np.nan, np.float32)
    db = PoseDatabase(
        poses=np.asarray(poses, np.float32), tiny=tiny, dts=dts, pixel_keys=keys,
        pixel_counts=counts, crop=np.asarray(crop, np.float64),
        codes=codes,
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
    db.meta.setdefault('build', {'hand_length_m': build.hand_length_m,
                                 'glove_seed': build.glove_seed})
    db.check()
    return db


# ------------------------------------------------------------------------------- rendering
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


def _render_camera(config: BuildConfig) -> PinholeCamera:
    from colorglove_ros.core.camera import PinholeCamera

    cam = config.render_camera()
    return PinholeCamera(cam['width'], cam['height'], cam['fx'], cam['fy'], cam['cx'], cam['cy'])


def _hand_centre(mesh: HandMesh, model: HandModel) -> np.ndarray:
    """Mean of the rest-pose mesh vertices in the hand frame (the point put on the axis)."""
    return mesh.skin_batch(model, np.zeros((1, 26)))[0].mean(axis=0)


def view_poses(distance_m: float, centre: np.ndarray, rotvecs: np.ndarray,
               fingers: np.ndarray) -> np.ndarray:
    """(M, 26) poses of finger configurations (M, 20) at orientations (M, 3) with the hand
    point ``centre`` (hand frame) on the optical axis at ``distance_m``."""
    from colorglove_ros.core.geometry import rotvec_to_matrix

    R = np.stack([rotvec_to_matrix(r) for r in rotvecs])
    Q = np.zeros((len(rotvecs), 26))
    Q[:, 0:3] = np.array([0.0, 0.0, distance_m]) - R @ centre
    Q[:, 3:6] = rotvecs
    Q[:, 6:] = fingers
    return Q


def _crop_render(labels: np.ndarray) -> TinyCrop | None:
    """``crop_to_tiny`` of one rendered label image; None when it is rejected or empty."""
    from colorglove_ros.core.segmentation.crop import crop_to_tiny

    tc = crop_to_tiny(labels)
    return None if tc is None or not tc.labels.any() else tc


def render_views(config: BuildConfig, fingers: np.ndarray, rotvecs: np.ndarray
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Render finger configurations (M, 20) at orientations (M, 3) exactly like the database
    entries (same camera, distance, crop). Returns poses (M, 26), tiny images (M, 40, 40),
    crops (M, 3) and a (M,) bool ``ok`` (False where crop_to_tiny rejected the render)."""
    from colorglove_ros.core.hand.glove import default_hand
    from colorglove_ros.core.synthetic.mesh_images import patch_ids_to_labels
    from colorglove_ros.core.synthetic.render import Renderer

    model, mesh, glove = default_hand(config.hand_length_m, seed=config.glove_seed)
    fingers = np.atleast_2d(np.asarray(fingers, np.float64))
    rotvecs = np.atleast_2d(np.asarray(rotvecs, np.float64))
    m = len(fingers)
    Q = view_poses(config.distance_m, _hand_centre(mesh, model), rotvecs, fingers)
    camera = _render_camera(config)
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
                tc = _crop_render(lab)
                if tc is not None:
                    tiny[s + j] = tc.labels
                    crop[s + j] = (tc.transform.scale, tc.transform.offset_x,
                                   tc.transform.offset_y)
                    ok[s + j] = True
    finally:
        renderer.release()
    return Q, tiny, crop, ok


# ------------------------------------------------------------------------------- building
def build_database(config: BuildConfig,
                   progress: Callable[[str], None] | None = None,
                   bar: Callable[..., Any] | None = None) -> PoseDatabase:
    """Render a database: low-dispersion finger configurations of the pose collection
    (:func:`sample_configurations`), each rendered at ``orientations_per_config``
    orientations with the hand's centre on the optical axis at ``distance_m``
    (:func:`view_poses`), cropped with ``crop_to_tiny`` like camera frames.

    ``bar`` wraps an iterable with a progress bar (e.g. ``tqdm``)."""
    from colorglove_ros.core.hand.glove import default_hand
    from colorglove_ros.core.hand.poses import sample_global_rotations
    from colorglove_ros.core.synthetic.mesh_images import patch_centroids, patch_ids_to_labels
    from colorglove_ros.core.synthetic.render import Renderer

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
    say(f'farthest-point sampling {n_configs} of '
        f'{max(config.collection_size, n_configs)} configurations')
    collection, chosen, radius = sample_configurations(config, n_configs, model, mesh, rng)
    timings['sampling_s'] = time.perf_counter() - t0
    # --- global poses: hand centre on the optical axis at distance_m
    n_render = n_configs * config.orientations_per_config
    config_of = np.repeat(np.arange(n_configs), config.orientations_per_config)
    rotvecs = sample_global_rotations(rng, n_render)
    centre = _hand_centre(mesh, model)
    cam = config.render_camera()
    camera = _render_camera(config)
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
            Q = view_poses(config.distance_m, centre, rv,
                           collection[chosen[config_of[s:s + config.batch]]])
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
                tc = _crop_render(labels[j])
                if tc is None:
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
    codes = encode_entries(encoder, db.dts)
    manifest = json.loads((path / MANIFEST_NAME).read_text())
    del db                                   # release the memory maps before rewriting files
    (path / MANIFEST_NAME).unlink()
    for name in [k for k in manifest['arrays'] if k.startswith('encoder_')]:
        (path / manifest['arrays'].pop(name)['file']).unlink(missing_ok=True)
    arrays = {'codes': codes, **encoder.to_arrays()}
    for name, arr in arrays.items():
        file = path / f'{name}.npy'
        tmp = path / f'.{name}.npy.tmp'
        with tmp.open('wb') as fh:           # new inode: readers holding a memory map of the
            np.save(fh, arr, allow_pickle=False)   # old file keep valid (old) data, no SIGBUS
        tmp.replace(file)
        manifest['arrays'][name] = manifest_entry(file, arr)
    manifest.update({'num_bits': encoder.num_bits, 'encoder_kind': encoder.kind,
                     'encoder_info': encoder.info})
    (path / MANIFEST_NAME).write_text(json.dumps(manifest, indent=2) + '\n')
    return encoder
