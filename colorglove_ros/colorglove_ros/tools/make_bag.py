"""Write a synthetic test sequence (camera images + hand ground truth) as an MCAP rosbag2; with a
several-camera calibration, every camera's view of each frame."""
from __future__ import annotations

import time
from pathlib import Path

from tqdm import tqdm

from colorglove_ros.core.camera import CalibrationError, load_calibration
from colorglove_ros.core.conventions import DEFAULT_HAND_LENGTH_M
from colorglove_ros.core.report import print_table, write_json
from colorglove_ros.core.synthetic.conditions import SPLITS, SynthError
from colorglove_ros.core.synthetic.frames import default_camera
from colorglove_ros.ros.bags import bag_size_bytes, write_synthetic_bag
from colorglove_ros.ros.image_codec import RGB8_ENCODERS
from colorglove_ros.tools._cli import tool_parser


def main(argv: list[str] | None = None) -> int:
    """Render ``--frames`` frames of sequence ``--seed`` and write them to ``--output``."""
    parser = tool_parser(__doc__)
    parser.add_argument('--seed', type=int, default=1, help='sequence seed (motion + conditions)')
    parser.add_argument('--frames', type=int, default=300, help='number of frames')
    parser.add_argument('--fps', type=float, default=30.0, help='frame rate of the stamps')
    parser.add_argument('--output', '-o', required=True, help='bag directory to create')
    parser.add_argument('--calibration', default=None,
                        help='calibration YAML; every camera listed is rendered (extra cameras '
                             'on /NAME/camera/...); default one camera, 640x480, f = 600')
    parser.add_argument('--split', choices=SPLITS, default='test',
                        help="conditions range: 'test' (held out) or 'train'")
    parser.add_argument('--encoding', choices=sorted(RGB8_ENCODERS), default='rgb8',
                        help='image encoding, as a camera driver sends it (e.g. yuv422_yuy2: '
                             "usb_cam's yuyv mode)")
    parser.add_argument('--hand-length', type=float, default=None,
                        help='hand length in metres (default: from the calibration, or '
                             f'{DEFAULT_HAND_LENGTH_M})')
    args = parser.parse_args(argv)
    output = Path(args.output)
    if output.exists():
        parser.error(f'{output} exists; choose a new bag directory')
    try:
        if args.calibration:
            calib = load_calibration(args.calibration)
            cameras, hand_length = calib.cameras, calib.hand_length_m
        else:
            cameras, hand_length = (default_camera(),), DEFAULT_HAND_LENGTH_M
    except CalibrationError as exc:
        parser.error(str(exc))
    if args.hand_length is not None:
        hand_length = args.hand_length
    if args.frames < 1:
        parser.error('--frames must be >= 1')
    t0 = time.perf_counter()
    try:
        bag = write_synthetic_bag(output, cameras, seed=args.seed, num_frames=args.frames,
                                  fps=args.fps, hand_length_m=hand_length, split=args.split,
                                  encoding=args.encoding,
                                  progress=lambda it: tqdm(it, desc='frames', unit='frame'))
    except SynthError as exc:
        parser.error(str(exc))
    elapsed = time.perf_counter() - t0
    size = bag_size_bytes(output)
    written, c = bag.frames, bag.conditions
    row = {'bag': str(output), 'frames': written, 'cameras': len(cameras),
           'size_MB': size / 1e6, 'seconds': elapsed,
           'frames_per_s': written / elapsed, 'split': args.split,
           'background': c.background_kind, 'gain': c.gain,
           'temperature_K': c.color_temperature_k}
    print_table([row], title=f'make_bag seed {args.seed}')
    if args.json:
        write_json(args.json, {'summary': row, 'conditions': vars(c)})
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
