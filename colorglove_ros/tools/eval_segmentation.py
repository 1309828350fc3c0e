"""Evaluate colour classification, crop and patch centroids on held-out synthetic frames.

Frames come from ``core/synthetic/frames.py`` (``sample_conditions(rng, 'test')``: other light
levels,
colour temperatures, noise, blur, JPEG and unseen cluttered backgrounds than the 'train'
frames the calibration was fitted on) or, with ``--source blobs``, from a simple 2-D stand-in
glove (:func:`render_blob_frame`). Ground-truth crop = :func:`crop_to_tiny` on the true label
image, so a perfect segmenter scores IoU 1. Missed glove pixels are split by what they became
(background, another colour) and where they are (silhouette, colour border, interior), also
per imaging condition; stage times are given over all frames and over glove frames only.
The pixel figures judge the colour classification; ``pipeline_background_fp_rate`` judges the
label image the whole pipeline ends with (after the clean-up), and ``--clutter-near-hand``
lets glove-like distractors touch the hand, as in the tracking sequences.
"""
from __future__ import annotations

import argparse
import time
from dataclasses import dataclass, replace
from pathlib import Path

import cv2
import numpy as np

from colorglove_ros.core.hand.glove import GLOVE_PALETTE_RGB, NUM_COLORS
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

__all__ = ['BlobConditions', 'sample_blob_conditions', 'render_blob_frame', 'test_frames',
           'frame_metrics', 'evaluate', 'main']


@dataclass(frozen=True)
class BlobConditions:
    """Imaging conditions of one synthetic blob-glove frame."""

    light: float                 # overall light level multiplier
    white_balance: tuple[float, float, float]  # per-channel gains (colour temperature)
    noise_sigma: float           # sensor noise, 0..255 units
    clutter: int                 # number of coloured background rectangles
    glove_like_clutter: bool     # clutter may take (desaturated / shifted) glove colours
    hand_scale: float            # glove size in units of 100 px


def sample_blob_conditions(rng: np.random.Generator, split: str) -> BlobConditions:
    """Random conditions: 'train' is mild; 'test' has other light levels, colour temperatures,
    more noise and clutter with glove-like colours."""
    if split == 'train':
        light = float(rng.uniform(0.75, 1.15))
        wb = rng.uniform(0.92, 1.08, 3)
        return BlobConditions(light, (float(wb[0]), float(wb[1]), float(wb[2])),
                              float(rng.uniform(1.0, 3.0)), int(rng.integers(2, 8)), False,
                              float(rng.uniform(1.0, 1.8)))
    if split == 'test':
        light = float(rng.choice([rng.uniform(0.5, 0.75), rng.uniform(1.15, 1.35)]))
        temp = float(rng.uniform(-0.15, 0.15))  # warm (+) / cool (-)
        wb = np.array([1.0 + temp, 1.0, 1.0 - temp]) * rng.uniform(0.95, 1.05, 3)
        return BlobConditions(light, (float(wb[0]), float(wb[1]), float(wb[2])),
                              float(rng.uniform(2.0, 6.0)), int(rng.integers(5, 15)), True,
                              float(rng.uniform(0.8, 2.2)))
    raise ValueError(f"split must be 'train' or 'test', got {split!r}")


def _smooth_noise(rng: np.random.Generator, h: int, w: int, cells: int) -> np.ndarray:
    small = rng.uniform(0.0, 1.0, (cells, cells)).astype(np.float32)
    return cv2.resize(small, (w, h), interpolation=cv2.INTER_CUBIC)


def render_blob_frame(rng: np.random.Generator, cond: BlobConditions, width: int = 640,
                      height: int = 480) -> tuple[np.ndarray, np.ndarray]:
    """A stand-in glove (palm + five fingers cut into 20 coloured patches) on a textured,
    cluttered background -> (image (H, W, 3) uint8 RGB, labels (H, W) uint8)."""
    s = 100.0 * cond.hand_scale
    cx = rng.uniform(0.3, 0.7) * width
    cy = rng.uniform(0.35, 0.7) * height
    ang = rng.uniform(-0.6, 0.6)
    rot = np.array([[np.cos(ang), -np.sin(ang)], [np.sin(ang), np.cos(ang)]])
    colors = rng.integers(1, NUM_COLORS + 1, 20)
    labels = np.zeros((height, width), np.uint8)

    def pt(x: float, y: float) -> tuple[int, int]:
        p = rot @ np.array([x, y]) * s + [cx, cy]
        return int(round(p[0] * 16)), int(round(p[1] * 16))

    # Palm: 2x3 grid of patches (ids 0..5).
    k = 0
    for i in range(3):
        for j in range(2):
            x0, x1 = -0.45 + 0.45 * j, 0.45 * j
            y0, y1 = -0.3 + 0.3 * i, 0.3 * i - 0.0
            poly = np.array([pt(x0, y0), pt(x1, y0), pt(x1, y1), pt(x0, y1)], np.int32)
            cv2.fillConvexPoly(labels, poly, int(colors[k]), cv2.LINE_8, 4)
            k += 1
    # Fingers: thick segments; thumb 2 patches, others 3 (ids 6..19).
    bases = [(-0.55, 0.3, -2.3), (-0.38, -0.32, -1.7), (-0.12, -0.34, -1.57),
             (0.12, -0.32, -1.45), (0.36, -0.28, -1.3)]
    for f, (bx, by, a) in enumerate(bases):
        a += rng.uniform(-0.25, 0.25)
        nseg = 2 if f == 0 else 3
        seg = (0.42 if f else 0.25) * rng.uniform(0.8, 1.1) / nseg * 3 / 2
        thick = max(int(0.14 * s), 2)
        x, y = bx, by
        for _ in range(nseg):
            nx, ny = x + seg * np.cos(a), y + seg * np.sin(a)
            cv2.line(labels, pt(x, y), pt(nx, ny), int(colors[min(k, 19)]), thick, cv2.LINE_8, 4)
            x, y, k = nx, ny, k + 1
            a += rng.uniform(-0.2, 0.35)
    # Background: muted smooth texture plus clutter rectangles (muted random colours; in
    # 'test' also desaturated glove colours).
    base = rng.uniform(50, 190) + rng.normal(0, 10, 3)
    tex = _smooth_noise(rng, height, width, 6)[..., None] * rng.uniform(30, 70) * (
        1.0 + rng.normal(0, 0.1, 3))
    bg = np.clip(base + tex + rng.normal(0, 5, (height, width, 1)), 0, 255)
    for _ in range(cond.clutter):
        w, h = rng.integers(15, 140, 2)
        x0, y0 = rng.integers(0, width - w), rng.integers(0, height - h)
        if cond.glove_like_clutter and rng.uniform() < 0.5:
            c = GLOVE_PALETTE_RGB[rng.integers(NUM_COLORS)].astype(float)
        else:
            c = rng.uniform(0, 255, 3)
        gray = c.mean()
        c = gray + (c - gray) * rng.uniform(0.2, 0.5)
        bg[y0:y0 + h, x0:x0 + w] = np.clip(c, 0, 255)
    glove = GLOVE_PALETTE_RGB[np.maximum(labels, 1) - 1].astype(np.float64)
    shade = 0.7 + 0.3 * _smooth_noise(rng, height, width, 4)[..., None]
    img = np.where(labels[..., None] > 0, glove * shade, bg)
    img = cv2.GaussianBlur(img.astype(np.float32), (0, 0), 0.7)
    img = img * cond.light * np.array(cond.white_balance, np.float32)
    img = img + rng.normal(0.0, cond.noise_sigma, img.shape)
    return np.clip(np.round(img), 0, 255).astype(np.uint8), labels


# ----------------------------------------------------------------------------- evaluation
def test_frames(source: str, count: int, seed: int, empty: int = 0,
                clutter_near_hand: bool = False
                ) -> list[tuple[np.ndarray, np.ndarray, dict[str, float]]]:
    """``count`` held-out 'test' frames with ground truth labels, plus ``empty`` frames with
    no glove (hand moved out of view): (image, labels, imaging conditions) each. With
    ``clutter_near_hand`` ('synth' only) the glove-like background distractors may lie next to
    or behind the hand, as in the tracking sequences, instead of away from it."""
    rng = np.random.default_rng(seed)
    frames: list[tuple[np.ndarray, np.ndarray, dict[str, float]]] = []
    if source == 'blobs':
        if clutter_near_hand:
            raise ValueError("clutter_near_hand needs source 'synth'")
        for i in range(count + empty):
            cond = sample_blob_conditions(rng, 'test')
            img, lab = render_blob_frame(rng, cond)
            if i >= count:
                img, lab = render_blob_frame(rng, sample_blob_conditions(rng, 'test'))
                keep = lab == 0
                img = np.where(keep[..., None], img, np.uint8(90))
                lab = np.zeros_like(lab)
            frames.append((img, lab, {'gain': cond.light, 'noise': cond.noise_sigma / 255.0}))
        return frames
    if source != 'synth':
        raise ValueError(f"source must be 'synth' or 'blobs', got {source!r}")
    from colorglove_ros.core.synthetic import frames as synth

    camera = synth.default_camera()
    for i in range(count + empty):
        q = synth.sample_pose(rng, camera)
        if i >= count:
            q[0] += 10.0  # far outside the field of view: background only
        cond = synth.sample_conditions(rng, 'test')
        if clutter_near_hand:
            cond = replace(cond, distractors_avoid_hand=False)
        f = synth.render_frame(q, camera, rng, cond)
        frames.append((f.image_rgb, f.labels, {
            'blur_px': cond.blur_px, 'jpeg_quality': cond.jpeg_quality, 'gain': cond.gain,
            'temperature_k': cond.color_temperature_k, 'noise': cond.noise_sigma}))
    return frames


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
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--config', default='config/color_calibration.yaml',
                        help='colour config YAML (calibration file + segmenter settings)')
    parser.add_argument('--source', choices=('synth', 'blobs'), default='synth')
    parser.add_argument('--frames', type=int, default=40, help='test frames with a glove')
    parser.add_argument('--empty', type=int, default=5, help='extra frames with no glove')
    parser.add_argument('--seed', type=int, default=12345, help='seed of the test frames')
    parser.add_argument('--repeats', type=int, default=3, help='timed runs per frame')
    parser.add_argument('--clutter-near-hand', action='store_true',
                        help="glove-like distractors may touch or sit behind the hand ('synth')")
    parser.add_argument('--json', type=Path, help='also write the figures as JSON')
    args = parser.parse_args(argv)
    try:
        seg = load_segmenter(args.config)
        cal_path = read_calibration_config(args.config)['calibration_file']
    except ColorCalibrationError as exc:
        print(f'error: {exc}')
        return 1
    try:
        frames = test_frames(args.source, args.frames, args.seed, args.empty,
                             args.clutter_near_hand)
    except ValueError as exc:
        print(f'error: {exc}')
        return 1
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
    load = ' '.join(Path('/proc/loadavg').read_text().split()[:3]) \
        if Path('/proc/loadavg').is_file() else 'n/a'
    print(f'evaluation took {time.perf_counter() - t0:.1f} s; load average {load}')
    if args.json:
        write_json(args.json, {'source': args.source, 'seed': args.seed,
                               'clutter_near_hand': args.clutter_near_hand,
                               'calibration': str(cal_path), 'load_average': load, **result})
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
