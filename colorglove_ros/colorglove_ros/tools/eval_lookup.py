"""Evaluate the pose lookup: code quality vs length, recall@300, NN distance vs size, timing.

With ``--diagnose`` it instead measures where the pose prior loses accuracy on frames of
synthetic test sequences (as colorglove_eval_ik renders them): the pose-nearest entry
(oracle), the exact image NN, the pipeline's top-1 and the blended pose, plus how well the
database's samples cover the queries' view rotations and finger configurations."""
from __future__ import annotations

import argparse
import dataclasses
import time
from pathlib import Path
from typing import Any

import numpy as np

from colorglove_ros.core.camera import PinholeCamera
from colorglove_ros.core.errors import ColorGloveError
from colorglove_ros.core.lookup.codes import (
    BinaryEncoder,
    features_from_dts,
    train_pca_itq,
    train_random_projections,
    train_ssc,
)
from colorglove_ros.core.lookup.database import DatabaseError, PoseDatabase, load_database
from colorglove_ros.core.lookup.database_build import (
    SSC_HARD_NEGATIVES,
    SSC_SHORTLIST,
    BuildConfig,
    nearest_neighbour_pairs,
    render_views,
)
from colorglove_ros.core.lookup.distance import QueryDistance, dequantize_dts
from colorglove_ros.core.lookup.search import PoseLookup, top_k_with_ties
from colorglove_ros.core.report import print_table, write_json
from colorglove_ros.tools._cli import tool_error, tool_parser
from colorglove_ros.tools.build_database import DEFAULT_CONFIG, load_build_config

__all__ = ['main']

LENGTHS = (32, 64, 96, 128, 192, 256)


def _build_config(db: PoseDatabase) -> BuildConfig:
    fields = {f.name for f in dataclasses.fields(BuildConfig)}
    return BuildConfig(**{k: v for k, v in db.meta.get('build', {}).items() if k in fields})


def _held_out_queries(db: PoseDatabase, count: int, seed: int
                      ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Render ``count`` views of collection configurations not in the database."""
    from colorglove_ros.core.hand.poses import pose_collection, sample_global_rotations

    cfg = _build_config(db)
    collection = pose_collection(cfg.collection_seed, cfg.collection_size,
                                 pinch_shapes=cfg.pinch_shapes)
    free = np.setdiff1d(np.arange(len(collection)), np.unique(np.asarray(db.config_index)))
    rng = np.random.default_rng(seed)
    pick = rng.choice(free, size=count, replace=count > len(free))
    rot = sample_global_rotations(rng, count)
    q, tiny, crop, ok = render_views(cfg, collection[pick], rot)
    return q[ok], tiny[ok], crop[ok], collection[pick][ok]


def _exact_distances(lookup: PoseLookup, tiny: np.ndarray, chunk: int = 20_000) -> np.ndarray:
    """(Q, N) exact image distances from each query to every database entry."""
    n = len(lookup.db)
    out = np.empty((len(tiny), n), np.float32)
    for i, t in enumerate(tiny):
        qd = QueryDistance(t)
        for s in range(0, n, chunk):
            out[i, s:s + chunk] = lookup.rerank(qd, np.arange(s, min(n, s + chunk)))
    return out


def _db_bits(encoder: BinaryEncoder, db: PoseDatabase, chunk: int = 8192) -> np.ndarray:
    n = len(db)
    out = np.empty((n, encoder.num_bits), bool)
    for s in range(0, n, chunk):
        out[s:s + chunk] = encoder.bits_from_dts(dequantize_dts(db.dts[s:s + chunk]))
    return out


def _ranks(db_bits: np.ndarray, q_bits: np.ndarray, nn: np.ndarray, lengths: list[int],
           k: int) -> dict[int, tuple[np.ndarray, np.ndarray]]:
    """Rank of the true NN (1 = first; ties share the mean rank) and whether it is among
    the top-k candidates (ties at the cut kept), for each prefix length."""
    out = {b: (np.empty(len(q_bits)), np.empty(len(q_bits), bool)) for b in lengths}
    for i in range(len(q_bits)):
        cum = np.cumsum(db_bits != q_bits[i], axis=1, dtype=np.uint16)
        for b in lengths:
            ham = cum[:, b - 1]
            h = ham[nn[i]]
            less = int(np.count_nonzero(ham < h))
            ties = int(np.count_nonzero(ham == h)) - 1
            out[b][0][i] = 1 + less + 0.5 * ties
            out[b][1][i] = nn[i] in set(top_k_with_ties(ham, k).tolist())
    return out


def _code_study(db: PoseDatabase, q_dts: np.ndarray, nn: np.ndarray, k: int, seed: int,
                pairs_count: int, max_bits: int) -> tuple[list[dict], dict]:
    rows: list[dict] = []
    curves: dict[str, dict] = {}
    lengths = [b for b in LENGTHS if b <= max_bits]
    db_bits = _db_bits(db.encoder, db)
    q_bits = db.encoder.bits_from_dts(q_dts)
    own = [b for b in lengths if b <= db.num_bits]
    res = _ranks(db_bits, q_bits, nn, own, k)
    curves['database_ssc'] = {b: res[b] for b in own}
    if pairs_count > 0:
        rng = np.random.default_rng(seed)
        sub = np.sort(rng.choice(len(db), size=min(len(db), 20_000), replace=False))
        sub_tiny, sub_dts = np.asarray(db.tiny[sub]), np.asarray(db.dts[sub])
        t0 = time.perf_counter()
        pairs, similar = nearest_neighbour_pairs(
            sub_tiny, sub_dts, pairs_count, seed=seed + 1, shortlist=SSC_SHORTLIST,
            exclude=np.asarray(db.config_index)[sub], hard_negatives=SSC_HARD_NEGATIVES)
        feats = features_from_dts(dequantize_dts(sub_dts))
        encoders = {
            'ssc': train_ssc(feats, pairs, similar, num_bits=max_bits, seed=seed + 1),
            'random_proj': train_random_projections(feats, max_bits, seed=seed + 1),
            'pca_itq': train_pca_itq(feats[: min(len(feats), 10_000)], max_bits, seed=seed + 1),
        }
        print(f'[eval] trained comparison codes in {time.perf_counter() - t0:.1f} s', flush=True)
        for name, enc in encoders.items():
            res = _ranks(_db_bits(enc, db), enc.bits_from_dts(q_dts), nn, lengths, k)
            curves[name] = res
    for name, res in curves.items():
        for b, (rank, hit) in res.items():
            rows.append({'code': name, 'bits': b, 'mean_rank': float(rank.mean()),
                         'median_rank': float(np.median(rank)), 'std_rank': float(rank.std()),
                         f'recall@{k}': float(hit.mean())})
    return rows, curves


def _size_study(db: PoseDatabase, dist: np.ndarray, q_fingers: np.ndarray) -> list[dict]:
    """NN distance (pose and image metric) of held-out queries vs database size, using
    prefixes of the farthest-point order (entries are stored in that order)."""
    from colorglove_ros.core.hand.glove import default_hand
    from colorglove_ros.core.hand.poses import pose_collection, pose_features

    cfg = _build_config(db)
    model, mesh, _ = default_hand(cfg.hand_length_m, seed=cfg.glove_seed)
    collection = pose_collection(cfg.collection_seed, cfg.collection_size,
                                 pinch_shapes=cfg.pinch_shapes)
    cfg_idx = np.asarray(db.config_index)
    fq = pose_features(mesh, model, q_fingers).astype(np.float64)
    n = len(db)
    sizes = sorted({max(1, n // 64), max(1, n // 16), max(1, n // 4), n})
    rows = []
    for size in sizes:
        configs = np.unique(cfg_idx[:size])
        fd = pose_features(mesh, model, collection[configs]).astype(np.float64)
        d2 = (fq ** 2).sum(1)[:, None] - 2 * fq @ fd.T + (fd ** 2).sum(1)[None]
        pose_nn = np.sqrt(np.maximum(d2.min(axis=1), 0.0))
        img_nn = dist[:, :size].min(axis=1)
        rows.append({'entries': size, 'configs': len(configs),
                     'pose_nn_mm_mean': 1e3 * float(pose_nn.mean()),
                     'pose_nn_mm_median': 1e3 * float(np.median(pose_nn)),
                     'image_nn_px_mean': float(img_nn.mean()),
                     'image_nn_px_median': float(np.median(img_nn))})
    return rows


def _pose_errors(q_true: np.ndarray, q_est: np.ndarray) -> dict[str, float]:
    """Mean wrist-translation (mm), global-rotation (deg) and finger-DOF RMS (deg) errors."""
    from scipy.spatial.transform import Rotation

    trans = 1e3 * np.linalg.norm(q_est[:, :3] - q_true[:, :3], axis=1)
    rot = (Rotation.from_rotvec(q_est[:, 3:6]) * Rotation.from_rotvec(q_true[:, 3:6]).inv())
    fing = np.sqrt(np.mean((q_est[:, 6:] - q_true[:, 6:]) ** 2, axis=1))
    return {'translation_mm': float(trans.mean()), 'depth_mm': float(
        1e3 * np.abs(q_est[:, 2] - q_true[:, 2]).mean()),
        'rotation_deg': float(np.rad2deg(rot.magnitude()).mean()),
        'fingers_rms_deg': float(np.rad2deg(fing).mean())}


def _tiny_blobs(tiny: np.ndarray, crop: np.ndarray) -> Any:
    """Blobs of a tiny label image in full-image pixels of the crop (scale, x0, y0), as the
    segmentation reports them for the per-finger blend."""
    from colorglove_ros.core.segmentation.blobs import extract_blobs
    from colorglove_ros.core.tracking.types import Blobs

    b = extract_blobs(tiny, min_pixels=1)
    scale, x0, y0 = (float(v) for v in crop)
    return Blobs(b.color, b.centroid_px * scale + (x0, y0), b.pixel_count * scale ** 2)


def _timing(lookup: PoseLookup, tiny: np.ndarray, crop: np.ndarray, nn: np.ndarray,
            camera: PinholeCamera, repeats: int, q_true: np.ndarray
            ) -> tuple[dict, float, list[dict]]:
    times: dict[str, list[float]] = {}
    found = 0
    nearest, blended, finger_blended = [], [], []
    blobs = [_tiny_blobs(tiny[i], crop[i]) for i in range(len(tiny))]
    for rep in range(repeats):
        for i in range(len(tiny)):
            res = lookup.lookup(tiny[i], crop[i], camera)
            for key, val in res.timings_ms.items():
                times.setdefault(key, []).append(val)
            found += int(res.indices[0] == nn[i])
            # fingers blended from blobs (core.lookup.finger_evidence), as lookup_node does; the
            # blobs here come from the tiny labels, the node's from the full image
            res_f = lookup.lookup(tiny[i], crop[i], camera, blobs[i])
            times.setdefault('total_with_finger_blend_ms', []).append(
                res_f.timings_ms['total_ms'])
            if rep == 0:
                nearest.append(res.poses[0])
                blended.append(res.blended)
                finger_blended.append(res_f.blended)
    errors = [{'estimate': 'nearest', **_pose_errors(q_true, np.asarray(nearest))},
              {'estimate': 'blended', **_pose_errors(q_true, np.asarray(blended))},
              {'estimate': 'per-finger blend', **_pose_errors(q_true,
                                                                np.asarray(finger_blended))}]
    row = {}
    for key, vals in times.items():
        v = np.asarray(vals)
        row[f'{key}_mean'] = float(v.mean())
        row[f'{key}_p95'] = float(np.percentile(v, 95))
    return row, found / (repeats * len(tiny)), errors


def _plots(curves: dict, size_rows: list[dict], out_dir: Path, k: int) -> list[str]:
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    out_dir.mkdir(parents=True, exist_ok=True)
    files = []
    fig, ax = plt.subplots(figsize=(6, 4))
    for name, res in curves.items():
        bits = sorted(res)
        ax.plot(bits, [res[b][0].mean() for b in bits], 'o-', label=name)
    ax.set_yscale('log')
    ax.set_xlabel('code length (bits)')
    ax.set_ylabel('mean rank of true NN')
    ax.axhline(16, color='grey', ls=':', label='paper, 192 bits')
    ax.legend()
    ax.set_title('Rank of the true nearest neighbour vs code length (fig. 9)')
    fig.tight_layout()
    files.append(str(out_dir / 'rank_vs_bits.png'))
    fig.savefig(files[-1], dpi=100)
    plt.close(fig)
    fig, ax1 = plt.subplots(figsize=(6, 4))
    sizes = [r['entries'] for r in size_rows]
    ax1.plot(sizes, [r['pose_nn_mm_mean'] for r in size_rows], 'o-', color='C0')
    ax1.set_xscale('log')
    ax1.set_yscale('log')
    ax1.set_xlabel('database entries')
    ax1.set_ylabel('pose NN distance (mm RMS)', color='C0')
    ax2 = ax1.twinx()
    ax2.plot(sizes, [r['image_nn_px_mean'] for r in size_rows], 's-', color='C1')
    ax2.set_yscale('log')
    ax2.set_ylabel('image NN distance (px)', color='C1')
    ax1.set_title('NN distance vs database size (fig. 8)')
    fig.tight_layout()
    files.append(str(out_dir / 'nn_vs_size.png'))
    fig.savefig(files[-1], dpi=100)
    plt.close(fig)
    return files


def _diagnose(args: argparse.Namespace, db: PoseDatabase, lookup: PoseLookup, path: Path
              ) -> int:
    """The (a)-(d) table and the coverage table on synthetic test-sequence frames."""
    from colorglove_ros.core.camera import load_calibration
    from colorglove_ros.core.evaluation.diagnosis import (
        FullPoseIndex,
        coverage,
        diagnose,
        render_query_frames,
    )
    from colorglove_ros.core.evaluation.sequences import make_observer
    from colorglove_ros.core.synthetic.frames import Synthesizer
    from colorglove_ros.paths import share_dir

    cfg = _build_config(db)
    try:
        camera = load_calibration(args.calibration or share_dir() / 'config' /
                                  'calibration.yaml').cameras[0]
        observer = make_observer(args.labels)
    except ColorGloveError as exc:
        return tool_error('colorglove_eval_lookup', exc)
    synth = Synthesizer(cfg.hand_length_m, cfg.glove_seed)
    try:
        t0 = time.perf_counter()
        frames = render_query_frames(args.seeds, args.frames, args.step, camera, observer,
                                     synth)
    finally:
        synth.release()
    print(f'[eval] {len(frames.tiny)} query frames (seeds {args.seeds}, every {args.step}th '
          f'of {args.frames}, labels={args.labels}) in {time.perf_counter() - t0:.1f} s',
          flush=True)
    index = FullPoseIndex(synth.model, synth.mesh, np.asarray(db.poses)[:, 6:],
                          np.asarray(db.config_index))
    t1 = time.perf_counter()
    rows = diagnose(lookup, frames, camera, index)
    print(f'[eval] diagnosis in {time.perf_counter() - t1:.1f} s', flush=True)
    shown = ['estimate', 'joint_mae_deg', 'rotation_deg', 'rotation_median_deg',
             'fingertip_rel_wrist_mm', 'fingertip_mm', 'wrist_depth_mm', 'wrist_plane_mm',
             'image_distance_px', 'pose_distance_mm', 'is_image_nn']
    print_table([{k: r[k] for k in shown} for r in rows],
                f'where the prior loses accuracy ({len(frames.tiny)} frames, {len(db)} entries, '
                f'{lookup.num_blend} blended)')
    for r in rows:
        print(f'  {r["estimate"]}: {r["description"]}')
    cov = coverage(lookup, frames, camera, index)
    print_table([cov], 'coverage of the queries by the database samples')
    if args.json:
        write_json(args.json, {'database': str(path), 'seeds': list(args.seeds),
                               'frames': args.frames, 'step': args.step, 'labels': args.labels,
                               'num_candidates': lookup.num_candidates,
                               'num_blend': lookup.num_blend, 'diagnosis': rows,
                               'coverage': cov})
    return 0


def main(argv: list[str] | None = None) -> int:
    """Command-line entry point."""
    parser = tool_parser(__doc__)
    parser.add_argument('--database', help='database directory (default from config)')
    parser.add_argument('--config', default=str(DEFAULT_CONFIG))
    parser.add_argument('--queries', type=int, default=200, help='held-out query renders')
    parser.add_argument('--seed', type=int, default=1)
    parser.add_argument('--pairs', type=int, default=10_000,
                        help='training pairs for the comparison codes (0: skip them)')
    parser.add_argument('--max-bits', type=int, default=256)
    parser.add_argument('--timing-repeats', type=int, default=3)
    parser.add_argument('--plots', default='data/eval_lookup', help='directory for PNG plots')
    diag = parser.add_argument_group('diagnosis (--diagnose)')
    diag.add_argument('--diagnose', action='store_true', help='only the oracle / image NN / '
                      'top-1 / blend table and the coverage table')
    diag.add_argument('--seeds', type=int, nargs='+', default=[0, 1],
                      help='synthetic test sequences (colorglove_eval_ik uses 0..S-1)')
    diag.add_argument('--frames', type=int, default=150, help='frames per sequence')
    diag.add_argument('--step', type=int, default=3, help='use every step-th frame')
    diag.add_argument('--labels', choices=('truth', 'segmented'), default='segmented')
    diag.add_argument('--calibration', help='camera calibration YAML (default '
                      'config/calibration.yaml)')
    args = parser.parse_args(argv)
    _, default_path, lookup_cfg = load_build_config(args.config)
    path = Path(args.database) if args.database else default_path
    try:
        t0 = time.perf_counter()
        db = load_database(path)
        load_s = time.perf_counter() - t0
    except DatabaseError as exc:
        return tool_error('colorglove_eval_lookup', exc)
    k = int(lookup_cfg.get('num_candidates', 300))
    lookup = PoseLookup(db, num_candidates=k, num_blend=int(lookup_cfg.get('num_blend', 10)))
    if args.diagnose:
        return _diagnose(args, db, lookup, path)
    print(f'[eval] {len(db)} entries loaded in {load_s:.1f} s; rendering {args.queries} '
          'held-out queries', flush=True)
    q_true, q_tiny, q_crop, q_fingers = _held_out_queries(db, args.queries, args.seed)
    t1 = time.perf_counter()
    dist = _exact_distances(lookup, q_tiny)
    nn = np.argmin(dist, axis=1)
    print(f'[eval] exact NN of {len(q_tiny)} queries in {time.perf_counter() - t1:.1f} s',
          flush=True)
    q_dts = np.stack([QueryDistance(t).dts for t in q_tiny])
    code_rows, curves = _code_study(db, q_dts, nn, k, args.seed, args.pairs, args.max_bits)
    print_table(code_rows, f'rank of the true NN under Hamming ({len(q_tiny)} held-out queries)')
    size_rows = _size_study(db, dist, q_fingers)
    print_table(size_rows, 'NN distance vs database size (farthest-point prefixes)')
    cfg = _build_config(db)
    rc = cfg.render_camera()
    camera = PinholeCamera(rc['width'], rc['height'], rc['fx'], rc['fy'], rc['cx'], rc['cy'])
    timing, found, errors = _timing(lookup, q_tiny, q_crop, nn, camera, args.timing_repeats,
                                    q_true)
    mem = {'entries': len(db), 'database_MB': db.nbytes / 1e6,
           'codes_MB': db.codes.nbytes / 1e6, 'dts_MB': db.dts.nbytes / 1e6,
           'pixel_keys_MB': db.pixel_keys.nbytes / 1e6,
           'lookup_buffers_MB': lookup.buffer_bytes / 1e6}
    timing_row = {'entries': len(db), 'bits': db.num_bits,
                  'lookup_finds_true_nn': found, **timing}
    print_table([timing_row], 'lookup time per query (ms)')
    print_table([mem], 'memory')
    print_table(errors, 'pose error of the lookup on held-out renders (same camera)')
    plots = _plots(curves, size_rows, Path(args.plots), k)
    print(f'plots: {", ".join(plots)}')
    if args.json:
        write_json(args.json, {'database': str(path), 'queries': int(len(q_tiny)),
                               'codes': code_rows, 'size': size_rows, 'timing': timing_row,
                               'memory': mem, 'pose_errors': errors, 'plots': plots})
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
