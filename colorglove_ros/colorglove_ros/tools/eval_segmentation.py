"""Evaluate colour classification, crop and patch centroids on held-out synthetic frames.

Frames come from ``core/synthetic/held_out.py``: the rendered glove under
``sample_conditions(rng, 'test')`` (other light levels, colour temperatures, noise, blur, JPEG
and unseen cluttered backgrounds than the 'train' frames the calibration was fitted on) or,
with ``--source blobs``, the 2-D stand-in glove of ``core/synthetic/blob_glove.py``.
Ground-truth crop = :func:`crop_to_tiny` on the true label image, so a perfect segmenter
scores IoU 1. Missed glove pixels are split by what they became
(background, another colour) and where they are (silhouette, colour border, interior), also
per imaging condition; stage times are given over all frames and over glove frames only.
The pixel figures judge the colour classification; ``pipeline_background_fp_rate`` judges the
label image the whole pipeline ends with (after the clean-up), and ``--clutter-near-hand``
lets glove-like distractors touch the hand, as in the tracking sequences.
"""
from __future__ import annotations

import time

import cv2
import numpy as np

from colorglove_ros.core.conventions import NUM_COLORS
from colorglove_ros.core.evaluation.machine_speed import machine_speed_after, machine_speed_before
from colorglove_ros.core.report import print_table, write_json
from colorglove_ros.core.segmentation.color_model import (
    ColorCalibrationError,
    read_calibration_config,
)
from colorglove_ros.core.segmentation.crop import CropTransform, crop_to_tiny
from colorglove_ros.core.segmentation.segmenter import (
    STAGES,
    GloveSegmenter,
    Observation,
    load_segmenter,
)
from colorglove_ros.core.synthetic.held_out import held_out_frames
from colorglove_ros.tools._cli import tool_error, tool_parser

__all__ = ['frame_metrics', 'evaluate', 'main']


# ----------------------------------------------------------------------------- evaluation
#: Condition bins of the accuracy breakdown: (name, condition key, bin edges, bin labels),
#: cut at the synthetic 'test' ranges (noise: read noise as a fraction of full scale).
CONDITION_BINS = (
    ('motion blur', 'blur_px', (1.0, 2.5), ('none', '1-2.5 px', '2.5-5 px')),
    ('JPEG', 'jpeg_quality', (1, 84), ('none', 'q 75-83', 'q 84-92')),
    ('light level', 'gain', (1.0,), ('dim (< 1)', 'bright (> 1)')),
    ('colour temperature', 'temperature_k', (6500.0,), ('warm (< 6500 K)', 'cool (> 6500 K)')),
    ('sensor noise', 'noise', (0.012, 0.016), ('low', 'mid', 'high')),
)


def condition_breakdown(per_frame: list[dict[str, float]],
                        conditions: list[dict[str, float]]) -> list[dict[str, object]]:
    """Mean glove-pixel accuracy and error split per imaging-condition bin (glove frames)."""
    rows: list[dict[str, object]] = []
    for name, key, edges, names in CONDITION_BINS:
        for b, label in enumerate(names):
            sel = [m for m, c in zip(per_frame, conditions, strict=True)
                   if key in c and np.isfinite(m['glove_acc'])
                   and int(np.searchsorted(edges, c[key], side='right')) == b]
            if sel:
                rows.append({'condition': name, 'bin': label, 'frames': len(sel),
                             **{k: float(np.mean([m[k] for m in sel])) for k in _SPLIT_KEYS}})
    return rows


def _window(t: CropTransform) -> tuple[float, float, float, float]:
    (cx, cy), h = t.center_xy, t.half_size
    return cx - h, cy - h, cx + h, cy + h


def _iou(a: CropTransform, b: CropTransform) -> float:
    ax0, ay0, ax1, ay1 = _window(a)
    bx0, by0, bx1, by1 = _window(b)
    iw = max(0.0, min(ax1, bx1) - max(ax0, bx0))
    ih = max(0.0, min(ay1, by1) - max(ay0, by0))
    inter = iw * ih
    return inter / ((ax1 - ax0) * (ay1 - ay0) + (bx1 - bx0) * (by1 - by0) - inter)


def _gt_blobs(labels: np.ndarray, min_pixels: int) -> list[tuple[int, float, float]]:
    out = []
    for c in range(1, NUM_COLORS + 1):
        m = (labels == c).astype(np.uint8)
        if not m.any():
            continue
        n, _, stats, cents = cv2.connectedComponentsWithStats(m, connectivity=8)
        for k in range(1, n):
            if stats[k, cv2.CC_STAT_AREA] >= min_pixels:
                out.append((c, float(cents[k, 0]), float(cents[k, 1])))
    return out


_SPLIT_KEYS = ('glove_acc', 'miss_as_background', 'miss_as_other_colour', 'miss_silhouette',
               'miss_colour_border', 'miss_interior')


def frame_metrics(seg: GloveSegmenter, image: np.ndarray, truth: np.ndarray,
                  obs: Observation, min_blob_pixels: int = 30) -> dict[str, float]:
    """Pixel, crop and centroid figures of one frame (NaN where undefined)."""
    pred = seg.classify_full(image)
    g = truth > 0
    k3 = np.ones((3, 3), np.uint8)
    interior = (cv2.erode(truth, k3) == cv2.dilate(truth, k3)) & g
    silhouette = g & (cv2.erode(g.view(np.uint8), k3) == 0)   # a background 8-neighbour
    colour_border = g & ~interior & ~silhouette
    nan = float('nan')

    def acc(m: np.ndarray) -> float:
        return float(np.mean(pred[m] == truth[m])) if m.any() else nan

    def share(m: np.ndarray) -> float:
        return float(np.count_nonzero(m & (pred != truth)) / g.sum()) if g.any() else nan

    out = {
        'glove_acc': acc(g),
        'interior_acc': acc(interior),
        'silhouette_acc': acc(silhouette),
        'colour_border_acc': acc(colour_border),
        # errors as fractions of all glove pixels: where they are and what they became
        'miss_as_background': share(g & (pred == 0)),
        'miss_as_other_colour': share(g & (pred > 0)),
        'miss_silhouette': share(silhouette),
        'miss_colour_border': share(colour_border),
        'miss_interior': share(interior),
        'bg_fp_rate': float(np.mean(pred[~g] > 0)),
        'iou': nan, 'tiny_agree': nan, 'centroid_err_px': nan, 'blob_recall': nan,
    }
    gt = crop_to_tiny(truth, min_pixels=seg.min_glove_pixels)
    out['gt_hand'] = float(gt is not None)
    if gt is not None and obs.crop is not None:
        out['iou'] = _iou(gt.transform, obs.crop)
        out['tiny_agree'] = float(np.mean(gt.labels == obs.tiny_labels))
    if gt is not None:
        errs, found = [], 0
        gtb = _gt_blobs(truth, min_blob_pixels)
        for c, x, y in gtb:
            cand = [np.hypot(b.centroid_x - x, b.centroid_y - y) for b in obs.blobs
                    if b.color_label == c]
            if cand and min(cand) < 20.0:
                errs.append(min(cand))
                found += 1
        if gtb:
            out['blob_recall'] = found / len(gtb)
        if errs:
            out['centroid_err_px'] = float(np.mean(errs))
    return out


def evaluate(seg: GloveSegmenter,
             frames: list[tuple[np.ndarray, np.ndarray, dict[str, float]]],
             repeats: int = 3) -> dict[str, object]:
    """Run the segmenter on every (image, labels, conditions) frame (timed ``repeats``
    times) and gather the figures. Times are given over all 640x480 frames and over those
    with a glove in the ground truth (frames without one exit early)."""
    per_frame = []
    timings: dict[str, list[float]] = {k: [] for k in (*STAGES, 'total')}
    glove_timings: dict[str, list[float]] = {k: [] for k in timings}
    detect = {'tp': 0, 'fn': 0, 'fp': 0, 'tn': 0}
    for image, truth, _ in frames:
        seg.lose_track()   # independent frames: nothing to follow from the last one
        obs = seg.process(image, keep_labels=True)
        for _ in range(repeats):
            o = seg.process(image)
            if image.shape[:2] == (480, 640):
                for k in timings:
                    timings[k].append(o.timings_ms.get(k, 0.0))
                    if truth.any():
                        glove_timings[k].append(o.timings_ms.get(k, 0.0))
        m = frame_metrics(seg, image, truth, obs)
        # background the whole pipeline (after the clean-up) calls glove; none if it found none
        output = obs.label_image if obs.label_image is not None else np.zeros_like(truth)
        m['pipeline_bg_fp_rate'] = float(np.mean(output[truth == 0] > 0))
        gt_found = m['gt_hand'] > 0
        # a ground-truth hand counts only if its crop is mostly inside the image, like ours
        if gt_found:
            gt = crop_to_tiny(truth, min_pixels=seg.min_glove_pixels)
            (cx, cy), hh = gt.transform.center_xy, gt.transform.half_size
            h, w = truth.shape
            inside = (max(0.0, min(cx + hh, w - 0.5) - max(cx - hh, -0.5))
                      * max(0.0, min(cy + hh, h - 0.5) - max(cy - hh, -0.5))) / (2 * hh) ** 2
            gt_found = inside >= seg.min_inside_fraction
        key = ('tp' if obs.hand_found else 'fn') if gt_found else (
            'fp' if obs.hand_found else 'tn')
        detect[key] += 1
        m['status'] = obs.status
        per_frame.append(m)

    def agg(name: str, fn=np.nanmean) -> float:
        vals = np.array([f[name] for f in per_frame], dtype=float)
        return float(fn(vals)) if np.isfinite(vals).any() else float('nan')

    summary = {
        'frames': len(frames),
        'glove_pixel_accuracy': agg('glove_acc'),
        'interior_pixel_accuracy': agg('interior_acc'),
        'silhouette_pixel_accuracy': agg('silhouette_acc'),
        'colour_border_pixel_accuracy': agg('colour_border_acc'),
        **{k: agg(k) for k in _SPLIT_KEYS[1:]},
        'background_fp_rate': agg('bg_fp_rate'),
        'pipeline_background_fp_rate': agg('pipeline_bg_fp_rate'),
        'crop_iou_mean': agg('iou'),
        'crop_iou_median': agg('iou', np.nanmedian),
        'tiny_label_agreement': agg('tiny_agree'),
        'centroid_error_px_mean': agg('centroid_err_px'),
        'centroid_error_px_median': agg('centroid_err_px', np.nanmedian),
        'blob_recall': agg('blob_recall'),
        'hand_detect_tp': detect['tp'], 'hand_detect_fn': detect['fn'],
        'hand_detect_fp': detect['fp'], 'hand_detect_tn': detect['tn'],
    }
    def pct(v: list[float], q: float) -> float:
        return float(np.percentile(v, q)) if v else float('nan')

    timing_rows = [{'stage': k, 'median_ms': pct(v, 50), 'p90_ms': pct(v, 90),
                    'glove_median_ms': pct(glove_timings[k], 50),
                    'glove_p90_ms': pct(glove_timings[k], 90)} for k, v in timings.items()]
    return {'summary': summary, 'timings': timing_rows,
            'conditions': condition_breakdown(per_frame, [f[2] for f in frames]),
            'per_frame': per_frame}


def main(argv: list[str] | None = None) -> int:
    parser = tool_parser(__doc__.split('\n\n')[0])
    parser.add_argument('--config', default='config/color_calibration.yaml',
                        help='colour config YAML (calibration file + segmenter settings)')
    parser.add_argument('--source', choices=('synth', 'blobs'), default='synth')
    parser.add_argument('--frames', type=int, default=40, help='test frames with a glove')
    parser.add_argument('--empty', type=int, default=5, help='extra frames with no glove')
    parser.add_argument('--seed', type=int, default=12345, help='seed of the test frames')
    parser.add_argument('--repeats', type=int, default=3, help='timed runs per frame')
    parser.add_argument('--clutter-near-hand', action='store_true',
                        help="glove-like distractors may touch or sit behind the hand ('synth')")
    args = parser.parse_args(argv)
    try:
        seg = load_segmenter(args.config)
        cal_path = read_calibration_config(args.config)['calibration_file']
    except ColorCalibrationError as exc:
        return tool_error('colorglove_eval_segmentation', exc)
    try:
        frames = held_out_frames(args.source, args.frames, args.seed, args.empty,
                             args.clutter_near_hand)
    except ValueError as exc:
        return tool_error('colorglove_eval_segmentation', exc)
    machine = machine_speed_before()
    t0 = time.perf_counter()
    result = evaluate(seg, frames, args.repeats)
    summary = result['summary']
    print_table([{'metric': k, 'value': v} for k, v in summary.items()],
                title=f'segmentation on {len(frames)} held-out {args.source} frames '
                      f'(calibration {cal_path})')
    print_table(result['conditions'], title='glove frames by imaging condition: accuracy and '
                'misses (fractions of glove pixels)')
    print_table(result['timings'], title='time per 640x480 frame by stage (ms): all frames, '
                'and glove frames only')
    print(f'evaluation took {time.perf_counter() - t0:.1f} s')
    machine_speed_after(machine)
    if args.json:
        write_json(args.json, {'source': args.source, 'seed': args.seed,
                               'clutter_near_hand': args.clutter_near_hand,
                               'calibration': str(cal_path), 'machine_speed': machine, **result})
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
