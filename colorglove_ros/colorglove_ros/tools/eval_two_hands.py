"""Two hands at once on synthetic sequences: a right glove moving as evaluation sequence S and a
left glove as the mirrored sequence S + 50000 (core.synthetic.sequences.generate_sequence; the
two move independently, so they cross and occlude each other), rendered in one frame with the
colour segmentation, through core.hands.TwoHandPipeline (regions, mirrored and unmirrored
lookups, handedness from the evidence and continuity, one tracker per hand).

Per hand: tracked share of the frames where both hands are fully visible (their keypoint boxes,
grown by 15 %, inside the image and apart), handedness correct on tracked frames (the region a
hand's pose came from is mostly that hand's glove in the renderer's ground truth), identity
swaps (a hand's output taken from the other hand's glove after being right), fingertip error,
and the layer's time per frame. Seeds O..O+S-1: the reported figures use O = 0; the settings
(core.hands.HandsSettings) were set by hand on seed 1000.
"""
from __future__ import annotations

import time

import numpy as np

from colorglove_ros.core.camera import load_calibration
from colorglove_ros.core.errors import ColorGloveError
from colorglove_ros.core.evaluation.metrics import pose_accuracy
from colorglove_ros.core.evaluation.sequences import eval_seeds, open_database
from colorglove_ros.core.evaluation.targets import target_row
from colorglove_ros.core.hand.handedness import HANDS, from_right_frame, to_right_frame
from colorglove_ros.core.hands import TwoHandPipeline
from colorglove_ros.core.lookup.database import DatabaseBuild, check_hand_length
from colorglove_ros.core.pipeline import Tracked
from colorglove_ros.core.report import print_table, write_json
from colorglove_ros.core.tracking.config import load_ik_config
from colorglove_ros.paths import data_dir, share_dir
from colorglove_ros.tools._cli import sequence_tool_parser, tool_error

__all__ = ['main', 'LEFT_SEED_OFFSET', 'both_visible']

LEFT_SEED_OFFSET = 50_000


def both_visible(kp2: dict[str, np.ndarray], width: int, height: int,
                 grow: float = 0.15) -> bool:
    """Both hands fully in view and apart: their 2-D keypoint boxes grown by ``grow`` lie
    inside the image and do not overlap."""
    boxes = []
    for pts in kp2.values():
        lo, hi = pts.min(0), pts.max(0)
        pad = grow * (hi - lo)
        lo, hi = lo - pad, hi + pad
        if lo[0] < 0 or lo[1] < 0 or hi[0] > width - 1 or hi[1] > height - 1:
            return False
        boxes.append((lo, hi))
    (a0, a1), (b0, b1) = boxes
    return bool(np.any(a1 < b0) or np.any(b1 < a0))


def main(argv: list[str] | None = None) -> int:
    """Command-line entry point."""
    parser = sequence_tool_parser(__doc__, 'evaluation sequences (seeds O..O+S-1)')
    parser.add_argument('--seed-offset', type=int, default=0, help='first sequence seed O')
    args = parser.parse_args(argv)
    from colorglove_ros.core.lookup.search import PoseLookup
    from colorglove_ros.core.segmentation.segmenter import load_segmenter
    from colorglove_ros.core.synthetic.conditions import sample_conditions
    from colorglove_ros.core.synthetic.frames import Synthesizer
    from colorglove_ros.core.synthetic.sequences import generate_sequence
    from colorglove_ros.core.tracking.tracker import HandTracker

    t0 = time.perf_counter()
    try:
        db_path, db = open_database(args.database, data_dir())
        config = load_ik_config(args.ik_config)
        mono = load_calibration(args.calibration)
        build = DatabaseBuild.from_meta(db.meta, str(db_path))
        check_hand_length(build, mono.hand_length_m, str(args.calibration), str(db_path))
        segmenter = load_segmenter(str(args.color_config or share_dir() / 'config' /
                                       'color_calibration.yaml'))
        seeds = eval_seeds(args.sequences, args.seed_offset)
    except ColorGloveError as exc:
        return tool_error('colorglove_eval_two_hands', exc)
    camera = mono.cameras[0]
    synth = Synthesizer(build.hand_length_m, build.glove_seed)
    lookup = PoseLookup(db)
    stats = {h: {'both': 0, 'tracked_both': 0, 'tracked': 0, 'correct': 0, 'swaps': 0,
                 'est': [], 'true': []} for h in HANDS}
    frame_ms = []
    for seed in seeds:
        poses = {'right': generate_sequence(seed, args.frames, args.fps, camera=camera,
                                            model=synth.model),
                 'left': from_right_frame(generate_sequence(
                     seed + LEFT_SEED_OFFSET, args.frames, args.fps, camera=camera,
                     model=synth.model), 'left')}
        conditions = sample_conditions(np.random.default_rng([seed, 7]), 'test')
        trackers = {h: HandTracker(synth.model, synth.mesh, [camera], config.with_mode(
            'ik_smooth'), glove=synth.glove) for h in HANDS}
        pipeline = TwoHandPipeline(segmenter, lookup, camera, trackers)
        was_correct = {h: None for h in HANDS}
        ts = time.perf_counter()
        for i in range(args.frames):
            frame, which = synth.render_hands([(poses[h][i], h) for h in HANDS], camera,
                                              np.random.default_rng([seed, i, 11]), conditions)
            c0 = time.perf_counter()
            outcomes = pipeline.process(frame.image_rgb, i / args.fps)
            frame_ms.append(1e3 * (time.perf_counter() - c0))
            kp2 = {h: camera.project(synth.keypoints(poses[h][i], h)) for h in HANDS}
            visible = both_visible(kp2, camera.width, camera.height)
            for k, h in enumerate(HANDS):
                st = stats[h]
                out = outcomes[h]
                st['both'] += visible
                if not isinstance(out.outcome, Tracked):
                    continue
                x0, y0, x1, y1 = out.region.box
                inside = which[y0:y1, x0:x1]
                counts = np.bincount(inside[inside > 0], minlength=3)
                correct = bool(counts[k + 1] > counts[2 - k])
                st['tracked'] += 1
                st['tracked_both'] += visible
                st['correct'] += correct
                if was_correct[h] is True and not correct:
                    st['swaps'] += 1
                was_correct[h] = correct
                if correct:
                    st['est'].append(to_right_frame(out.q, h))
                    st['true'].append(to_right_frame(poses[h][i], h))
        print(f'[eval_two_hands] sequence {seed}: {args.frames} frames in '
              f'{time.perf_counter() - ts:.1f} s', flush=True)
    synth.release()
    rows = []
    for h in HANDS:
        st = stats[h]
        acc = pose_accuracy(synth.model, np.array(st['est']), np.array(st['true'])) \
            if st['est'] else {}
        rows.append({'hand': h, 'frames_both_visible': st['both'],
                     'tracked_when_both_visible': st['tracked_both'] / max(st['both'], 1),
                     'tracked_frames': st['tracked'],
                     'handedness_correct': st['correct'] / max(st['tracked'], 1),
                     'identity_swaps': st['swaps'],
                     'fingertip_mm': acc.get('fingertip_mm', float('nan')),
                     'fingertip_rel_wrist_mm': acc.get('fingertip_rel_wrist_mm', float('nan'))})
    print_table(rows, f'Two hands: {len(seeds)} sequences x {args.frames} frames (right seeds '
                f'{seeds[0]}..{seeds[-1]}, left: mirrored seeds + {LEFT_SEED_OFFSET}), '
                f'segmented, 1 camera, IK + smoothing, database {db_path} ({len(db)} entries)')
    ms = np.array(frame_ms)
    print(f'two-hand layer time per frame (both hands, one thread): mean {ms.mean():.1f} ms, '
          f'p95 {np.percentile(ms, 95):.1f} ms')
    targets = []
    for r in rows:
        targets += [target_row(f'{r["hand"]}: tracked when both fully visible',
                               r['tracked_when_both_visible'], 0.95, '>='),
                    target_row(f'{r["hand"]}: identity swaps', r['identity_swaps'], 0, '<='),
                    target_row(f'{r["hand"]}: handedness correct on tracked frames',
                               r['handedness_correct'], 0.99, '>=')]
    print_table(targets, 'Targets (measured, not asserted; the fingertip target compares with '
                'the one-hand figures of colorglove_eval_left_glove on the same seeds)')
    if args.json:
        write_json(args.json, {'settings': {
            'database': str(db_path), 'seeds': seeds, 'left_seed_offset': LEFT_SEED_OFFSET,
            'frames_per_sequence': args.frames, 'fps': args.fps,
            'frame_ms_mean': float(ms.mean()), 'frame_ms_p95': float(np.percentile(ms, 95)),
            'wall_s': time.perf_counter() - t0}, 'rows': rows, 'targets': targets})
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
