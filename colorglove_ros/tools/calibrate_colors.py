"""Fit the glove colour classifier from labelled frames and write the calibration file.

Labelled frames are PNG pairs in one folder: ``NAME.png`` (the RGB camera image) and
``NAME_mask.png`` (single-channel 8-bit labels: 0 background, 1..10 glove colour as in
``core/hand/glove.py``). ``--synthetic N`` first renders N 'train' frames with
``core/synthetic/frames.py``
and writes them as such pairs. The output file defaults to the ``calibration_file`` named in
``config/color_calibration.yaml``.
"""
from __future__ import annotations

import time
from pathlib import Path

import cv2
import numpy as np

from colorglove_ros.core.conventions import NUM_COLORS
from colorglove_ros.core.hand.glove import GLOVE_COLOR_NAMES
from colorglove_ros.core.report import print_table, write_json
from colorglove_ros.core.segmentation.calibration_fit import (
    RESIDUAL_TEMPERATURES_K,
    fit_color_calibration,
)
from colorglove_ros.core.segmentation.color_model import (
    ColorCalibrationError,
    read_calibration_config,
    save_calibration,
)
from colorglove_ros.tools._cli import tool_parser

__all__ = ['MASK_SUFFIX', 'read_labelled_frames', 'write_labelled_frames',
           'render_training_frames', 'main']

MASK_SUFFIX = '_mask'


def read_labelled_frames(folder: str | Path) -> list[tuple[np.ndarray, np.ndarray]]:
    """Read every ``NAME.png`` + ``NAME_mask.png`` pair in a folder (sorted by name)."""
    folder = Path(folder)
    if not folder.is_dir():
        raise ColorCalibrationError(f'frame folder not found: {folder}')
    frames = []
    for mask_path in sorted(folder.glob(f'*{MASK_SUFFIX}.png')):
        image_path = mask_path.with_name(mask_path.name[:-len(MASK_SUFFIX) - 4] + '.png')
        if not image_path.is_file():
            raise ColorCalibrationError(f'{mask_path} has no image {image_path.name}')
        bgr = cv2.imread(str(image_path), cv2.IMREAD_COLOR)
        mask = cv2.imread(str(mask_path), cv2.IMREAD_UNCHANGED)
        if bgr is None or mask is None:
            raise ColorCalibrationError(f'cannot read {image_path} or {mask_path}')
        if mask.ndim != 2 or mask.dtype != np.uint8:
            raise ColorCalibrationError(f'{mask_path} must be a single-channel 8-bit PNG')
        frames.append((np.ascontiguousarray(bgr[..., ::-1]), mask))
    return frames


def write_labelled_frames(folder: str | Path,
                          frames: list[tuple[np.ndarray, np.ndarray]]) -> list[Path]:
    """Write (image RGB, labels) pairs as ``frame_NNNN.png`` + ``frame_NNNN_mask.png``."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    paths = []
    for i, (rgb, mask) in enumerate(frames):
        p = folder / f'frame_{i:04d}.png'
        cv2.imwrite(str(p), np.ascontiguousarray(rgb[..., ::-1]))
        cv2.imwrite(str(folder / f'frame_{i:04d}{MASK_SUFFIX}.png'), mask.astype(np.uint8))
        paths.append(p)
    return paths


def render_training_frames(count: int, seed: int, split: str = 'train'
                           ) -> list[tuple[np.ndarray, np.ndarray]]:
    """Render ``count`` synthetic frames (hand fully in view) with ``core/synthetic/frames.py``."""
    from colorglove_ros.core.synthetic import frames as synth
    from colorglove_ros.core.synthetic.conditions import sample_conditions

    rng = np.random.default_rng(seed)
    camera = synth.default_camera()
    frames = []
    for _ in range(count):
        q = synth.sample_pose(rng, camera, out_of_frame_prob=0.0)
        frame = synth.render_frame(q, camera, rng, sample_conditions(rng, split))
        frames.append((frame.image_rgb, frame.labels))
    return frames


def main(argv: list[str] | None = None) -> int:
    parser = tool_parser(__doc__.split('\n\n')[0])
    src = parser.add_mutually_exclusive_group(required=True)
    src.add_argument('--frames', type=Path, help='folder of NAME.png + NAME_mask.png pairs')
    src.add_argument('--synthetic', type=int, metavar='N',
                     help="render N synthetic 'train' frames, save them, calibrate from them")
    parser.add_argument('--config', default='config/color_calibration.yaml',
                        help='colour config YAML naming the calibration file')
    parser.add_argument('--output', type=Path, help='calibration .npz (default: from --config)')
    parser.add_argument('--frames-out', type=Path, default=Path('data/color_calibration_frames'),
                        help='where --synthetic writes its image/mask pairs')
    parser.add_argument('--seed', type=int, default=0, help='seed of rendering and fitting')
    parser.add_argument('--bits', type=int, default=6, help='LUT bits per RGB channel')
    parser.add_argument('--max-pixels', type=int, default=5000,
                        help='training pixels sampled per class')
    parser.add_argument('--light-temperatures', type=float, nargs=2, metavar=('LOW_K', 'HIGH_K'),
                        default=RESIDUAL_TEMPERATURES_K,
                        help='re-light the training pixels under black bodies of these colour '
                             'temperatures (default: calibration_fit.RESIDUAL_TEMPERATURES_K, '
                             "what the segmenter's per-frame light-colour correction leaves)")
    args = parser.parse_args(argv)
    try:
        output = args.output or read_calibration_config(args.config)['calibration_file']
        if args.synthetic is not None:
            if args.synthetic < 1:
                parser.error('--synthetic needs N >= 1')
            frames = render_training_frames(args.synthetic, args.seed)
            write_labelled_frames(args.frames_out, frames)
            source = f'synthetic train frames, seed {args.seed} ({args.frames_out})'
        else:
            frames = read_labelled_frames(args.frames)
            source = str(args.frames)
        t0 = time.perf_counter()
        cal = fit_color_calibration(frames, num_colors=NUM_COLORS, bits=args.bits,
                                    max_per_class=args.max_pixels, seed=args.seed,
                                    augment_temperatures_k=tuple(args.light_temperatures),
                                    metadata={'source': source})
        fit_s = time.perf_counter() - t0
        save_calibration(cal, output)
    except ColorCalibrationError as exc:
        print(f'error: {exc}')
        return 1
    # Self-check on the training frames (pixel-exact table lookup, no filtering).
    rows = []
    for c in range(NUM_COLORS + 1):
        correct = total = 0
        for rgb, mask in frames:
            m = mask == c
            total += int(m.sum())
            correct += int((cal.classify(rgb)[m] == c).sum())
        rows.append({'class': c, 'name': 'background' if c == 0 else GLOVE_COLOR_NAMES[c - 1],
                     'train_pixels': total, 'train_accuracy': correct / max(total, 1),
                     'components': len(cal.mixtures[c].weights)})
    print_table(rows, title=f'colour calibration from {len(frames)} frames -> {output}')
    print(f'fit + LUT ({1 << cal.bits}^3) time: {fit_s:.1f} s')
    if args.json:
        write_json(args.json, {'output': str(output), 'frames': len(frames), 'fit_s': fit_s,
                               'classes': rows})
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
