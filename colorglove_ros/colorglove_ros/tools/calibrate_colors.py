"""Fit the glove colour classifier from labelled frames and write the calibration file.

Labelled frames are PNG pairs in one folder: ``NAME.png`` (the RGB camera image) and
``NAME_mask.png`` (single-channel 8-bit labels: 0 background, 1..10 glove colour as in
``core/hand/glove.py``). ``--synthetic N`` first renders N 'train' frames with
``core/synthetic/frames.py``
and writes them as such pairs. The output file defaults to the ``calibration_file`` named in
``config/color_calibration.yaml``.
"""
from __future__ import annotations

from pathlib import Path

from colorglove_ros.core.conventions import NUM_COLORS
from colorglove_ros.core.hand.glove import GLOVE_COLOR_NAMES
from colorglove_ros.core.report import print_table, write_json
from colorglove_ros.core.segmentation.calibration_fit import (
    DEFAULT_LUT_BITS,
    DEFAULT_MAX_PIXELS_PER_CLASS,
    DEFAULT_PROCESSED_COLORS,
    DEFAULT_PROCESSED_COPIES,
    RESIDUAL_TEMPERATURES_K,
    SYNTHETIC_FRAMES_DIR,
    CalibrationFit,
    calibrate_frames,
    calibrate_synthetic,
    read_labelled_frames,
)
from colorglove_ros.core.segmentation.color_model import (
    ColorCalibrationError,
    read_calibration_config,
)
from colorglove_ros.tools._cli import tool_error, tool_parser

__all__ = ['main']


def training_accuracy_rows(fit: CalibrationFit) -> list[dict[str, object]]:
    """Self-check on the training frames (pixel-exact table lookup, no filtering): per class
    its training pixels, the share classified as that class, and its mixture components."""
    cal = fit.calibration
    rows = []
    for c in range(NUM_COLORS + 1):
        correct = total = 0
        for rgb, mask in fit.frames:
            m = mask == c
            total += int(m.sum())
            correct += int((cal.classify(rgb)[m] == c).sum())
        rows.append({'class': c, 'name': 'background' if c == 0 else GLOVE_COLOR_NAMES[c - 1],
                     'train_pixels': total, 'train_accuracy': correct / max(total, 1),
                     'components': len(cal.mixtures[c].weights)})
    return rows


def main(argv: list[str] | None = None) -> int:
    parser = tool_parser(__doc__.split('\n\n')[0])
    src = parser.add_mutually_exclusive_group(required=True)
    src.add_argument('--frames', type=Path, help='folder of NAME.png + NAME_mask.png pairs')
    src.add_argument('--synthetic', type=int, metavar='N',
                     help="render N synthetic 'train' frames, save them, calibrate from them")
    parser.add_argument('--config', default='config/color_calibration.yaml',
                        help='colour config YAML naming the calibration file')
    parser.add_argument('--output', type=Path, help='calibration .npz (default: from --config)')
    parser.add_argument('--frames-out', type=Path, default=SYNTHETIC_FRAMES_DIR,
                        help='where --synthetic writes its image/mask pairs')
    parser.add_argument('--seed', type=int, default=0, help='seed of rendering and fitting')
    parser.add_argument('--bits', type=int, default=DEFAULT_LUT_BITS,
                        help='LUT bits per RGB channel')
    parser.add_argument('--max-pixels', type=int, default=DEFAULT_MAX_PIXELS_PER_CLASS,
                        help='training pixels sampled per class')
    parser.add_argument('--light-temperatures', type=float, nargs=2, metavar=('LOW_K', 'HIGH_K'),
                        default=RESIDUAL_TEMPERATURES_K,
                        help='re-light the training pixels under black bodies of these colour '
                             'temperatures (default: calibration_fit.RESIDUAL_TEMPERATURES_K, '
                             "what the segmenter's per-frame light-colour correction leaves)")
    parser.add_argument('--processed-copies', type=int, default=DEFAULT_PROCESSED_COPIES,
                        metavar='N',
                        help="also train on N re-lit copies of the pixels seen through other "
                             "cameras' colour processing (white balance, saturation, gamma, "
                             'contrast; default: calibration_fit.DEFAULT_PROCESSED_COPIES)')
    parser.add_argument('--processed-colors', nargs='+', choices=(*GLOVE_COLOR_NAMES, 'all'),
                        metavar='COLOR', help='only these glove colours (and the background) '
                        "get the processed copies; 'all' for every colour (default: "
                        + ' '.join(GLOVE_COLOR_NAMES[c - 1] for c in DEFAULT_PROCESSED_COLORS)
                        + ')')
    args = parser.parse_args(argv)
    if args.processed_copies < 0:
        parser.error('--processed-copies needs N >= 0')
    if args.synthetic is not None and args.synthetic < 1:
        parser.error('--synthetic needs N >= 1')
    options = {'seed': args.seed, 'bits': args.bits, 'max_per_class': args.max_pixels,
               'augment_temperatures_k': tuple(args.light_temperatures),
               'augment_processed_copies': args.processed_copies,
               'augment_processed_colors': (
                   DEFAULT_PROCESSED_COLORS if args.processed_colors is None
                   else None if 'all' in args.processed_colors
                   else [GLOVE_COLOR_NAMES.index(name) + 1 for name in args.processed_colors])}
    try:
        output = args.output or read_calibration_config(args.config)['calibration_file']
        if args.synthetic is not None:
            fit = calibrate_synthetic(args.synthetic, output, args.frames_out, **options)
        else:
            fit = calibrate_frames(read_labelled_frames(args.frames), output, str(args.frames),
                                   **options)
    except ColorCalibrationError as exc:
        return tool_error('colorglove_calibrate_colors', exc)
    rows = training_accuracy_rows(fit)
    print_table(rows, title=f'colour calibration from {len(fit.frames)} frames -> {output}')
    print(f'fit + LUT ({1 << fit.calibration.bits}^3) time: {fit.fit_s:.1f} s')
    if args.json:
        write_json(args.json, {'output': str(output), 'frames': len(fit.frames),
                               'fit_s': fit.fit_s, 'classes': rows})
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
