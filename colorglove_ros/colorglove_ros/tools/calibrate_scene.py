"""Calibrate the glove colours to your own scene and glove, with no hand-drawn masks.

Give a few seconds of the empty scene (``--empty``) and a few seconds with the gloved hand
moving and turning in it (``--glove``), from the camera in its place, each as a folder of
PNG/JPG frames or a rosbag2 folder (``colorglove_record_bag`` of the camera's image topic).
The tool learns the scene's colours as background, finds the glove's patches itself (seeded by
the glove's palette, under the scene's light), refits each glove colour, and writes the same
calibration file the nodes read (``--output``), a picture per checked frame (``--pictures``:
the frame, the glove pixels it learnt from, and the new labelling) and a table of what it
found. Then set ``calibration_file`` in config/color_calibration.yaml to the output file.
Walkthrough: docs/calibrate_your_scene.md.
"""
from __future__ import annotations

import time
from collections.abc import Iterator
from pathlib import Path

import cv2
import numpy as np

from colorglove_ros.core.frame_sources import IMAGE_SUFFIXES
from colorglove_ros.core.report import print_table, write_json
from colorglove_ros.core.segmentation.color_model import (
    ColorCalibration,
    load_calibration,
    read_calibration_config,
    save_calibration,
)
from colorglove_ros.core.segmentation.scene_calibration import (
    SceneCalibration,
    SceneCalibrationError,
    SceneCalibrationSettings,
    calibrate_scene,
    check_frames,
    label_image_rgb,
    scene_figures,
)
from colorglove_ros.core.segmentation.segmenter import GloveSegmenter
from colorglove_ros.tools._cli import run_tool, tool_parser

__all__ = ['DEFAULT_IMAGE_TOPIC', 'read_frames', 'check_pictures', 'main']

NAME = 'colorglove_calibrate_scene'
DEFAULT_IMAGE_TOPIC = '/camera/image_raw'   # what camera_node publishes
_BAG_FILES = ('metadata.yaml', '*.mcap', '*.db3')


# ----------------------------------------------------------------------------- input
def _is_bag(folder: Path) -> bool:
    return any(any(folder.glob(pattern)) for pattern in _BAG_FILES)


def _folder_frames(folder: Path) -> Iterator[np.ndarray]:
    files = sorted(p for p in folder.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES)
    if not files:
        raise SceneCalibrationError(
            f'{folder} holds no images ({", ".join(IMAGE_SUFFIXES)}) and is no rosbag2 folder')
    for path in files:
        bgr = cv2.imread(str(path), cv2.IMREAD_COLOR)
        if bgr is None:
            raise SceneCalibrationError(f'cannot read image {path}')
        yield cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB)


def _bag_frames(folder: Path, topic: str) -> Iterator[np.ndarray]:
    from rosbags.highlevel import AnyReader

    from colorglove_ros.ros.image_codec import (
        ImageEncodingError,
        compressed_image_to_rgb8,
        image_to_rgb8,
    )
    from colorglove_ros.ros.typestore import colorglove_typestore

    decoders = {'sensor_msgs/msg/Image': lambda m: image_to_rgb8(m, allow_mono=False),
                'sensor_msgs/msg/CompressedImage': compressed_image_to_rgb8}
    try:
        with AnyReader([folder], default_typestore=colorglove_typestore()) as reader:
            connections = [c for c in reader.connections if c.topic == topic]
            if not connections:
                images = sorted({c.topic for c in reader.connections if c.msgtype in decoders})
                raise SceneCalibrationError(
                    f'bag {folder} has no topic {topic}; its image topics: '
                    f'{", ".join(images) or "none"} (choose one with --image-topic)')
            if connections[0].msgtype not in decoders:
                raise SceneCalibrationError(
                    f'{topic} in {folder} is {connections[0].msgtype}, not an image')
            decode = decoders[connections[0].msgtype]
            for connection, _, raw in reader.messages(connections=connections):
                try:
                    yield decode(reader.deserialize(raw, connection.msgtype))
                except ImageEncodingError as exc:
                    raise SceneCalibrationError(f'{folder} {topic}: {exc}') from exc
    except SceneCalibrationError:
        raise
    except Exception as exc:   # rosbags' own reader errors (corrupt or unknown storage)
        raise SceneCalibrationError(f'cannot read bag {folder}: {exc}') from exc


def read_frames(source: str | Path, *, image_topic: str = DEFAULT_IMAGE_TOPIC,
                max_frames: int = 40) -> list[np.ndarray]:
    """RGB frames of a folder of images (sorted by name) or of a rosbag2 folder's
    ``image_topic`` (``sensor_msgs/Image`` or ``CompressedImage``): every frame is read and
    checked, and between ``max_frames`` and twice as many, evenly spaced, are kept."""
    path = Path(source).expanduser()
    if not path.is_dir():
        raise SceneCalibrationError(
            f'{path} is not a folder: give a folder of PNG/JPG frames or a rosbag2 folder '
            '(from a video: ffmpeg -i VIDEO -vf fps=10 FOLDER/%04d.png)')
    frames = _bag_frames(path, image_topic) if _is_bag(path) else _folder_frames(path)
    kept: list[np.ndarray] = []
    step = 1
    size = None
    for index, frame in enumerate(frames):
        if size is None:
            size = frame.shape
        elif frame.shape != size:
            raise SceneCalibrationError(
                f'{path}: frame {index} is {frame.shape[1]}x{frame.shape[0]}, the first '
                f'{size[1]}x{size[0]}: all frames must come from one camera at one size')
        if index % step == 0:
            kept.append(frame)
            if len(kept) > 2 * max_frames:   # keep every other one: still evenly spaced
                kept, step = kept[::2], 2 * step
    if not kept:
        raise SceneCalibrationError(f'{path} holds no frames')
    check_frames(kept, str(path))
    return kept


# ----------------------------------------------------------------------------- pictures
def _caption(image: np.ndarray, text: str) -> np.ndarray:
    strip = np.full((22, image.shape[1], 3), 255, np.uint8)
    cv2.putText(strip, text, (4, 16), cv2.FONT_HERSHEY_SIMPLEX, 0.45, (0, 0, 0), 1,
                cv2.LINE_AA)
    return np.vstack([strip, image])


def check_pictures(fitted: SceneCalibration, start: ColorCalibration,
                   empty: list[np.ndarray], glove: list[np.ndarray],
                   segmenter_settings: dict) -> dict[str, np.ndarray]:
    """Pictures to check the calibration by eye (RGB): per checked glove frame the frame, the
    glove pixels the fit learnt from (over the dimmed frame) and the new calibration's
    labelling (the segmenter's full-frame labels); and one empty-scene frame labelled by the
    starting and the new calibration."""
    new = GloveSegmenter(fitted.calibration, **segmenter_settings)
    old = GloveSegmenter(start, **segmenter_settings)
    pictures = {}
    for index, found in fitted.found_labels.items():
        frame = glove[index]
        used = np.where(found[..., None] > 0, label_image_rgb(found), frame // 3)
        pictures[f'glove_{index:03d}.png'] = np.hstack([
            _caption(frame, f'glove frame {index}'),
            _caption(used, 'glove pixels learnt from'),
            _caption(label_image_rgb(new.classify_full(frame)), 'new labelling')])
    frame = empty[len(empty) // 2]
    pictures['empty_scene.png'] = np.hstack([
        _caption(frame, 'empty scene'),
        _caption(label_image_rgb(old.classify_full(frame)), 'starting calibration'),
        _caption(label_image_rgb(new.classify_full(frame)), 'new calibration')])
    return pictures


def _warnings(summary: dict) -> list[str]:
    """What the user should know about a fit that worked."""
    notes = []
    shared = ', '.join(summary['colours_shared_with_scene'])
    if shared:
        notes.append(f'the scene itself shows the glove\'s {shared}: those surfaces stay '
                     'glove-coloured (move them out of view if you can)')
    if not summary['glove_frames_with_foreground']:
        notes.append('no glove frame matched the empty scene outside the hand: did the camera '
                     'move, or its exposure change? The glove was found by colour alone')
    return notes


# ----------------------------------------------------------------------------- main
def main(argv: list[str] | None = None) -> int:
    parser = tool_parser(__doc__, raw_description=True)
    parser.add_argument('--empty', required=True, type=Path,
                        help='the empty scene: folder of frames or rosbag2 folder')
    parser.add_argument('--glove', required=True, type=Path,
                        help='the glove moving in the scene: folder of frames or rosbag2 folder')
    parser.add_argument('--output', required=True, type=Path, help='calibration .npz to write')
    parser.add_argument('--pictures', required=True, type=Path,
                        help='folder for the pictures to check the labelling')
    parser.add_argument('--start', type=Path,
                        help='starting calibration (default: the one --config names)')
    parser.add_argument('--config', default='config/color_calibration.yaml',
                        help='colour config YAML: the default starting calibration and the '
                             'segmenter settings')
    parser.add_argument('--image-topic', default=DEFAULT_IMAGE_TOPIC,
                        help='image topic of bag input')
    parser.add_argument('--max-frames', type=int, default=SceneCalibrationSettings.max_frames,
                        help='frames of each recording used, evenly spaced')
    parser.add_argument('--check-frames', type=int, default=4,
                        help='glove frames to draw pictures of')
    parser.add_argument('--seed', type=int, default=0, help='seed of the sampling and fits')
    args = parser.parse_args(argv)
    if args.max_frames < 1 or args.check_frames < 0:
        parser.error('--max-frames must be >= 1 and --check-frames >= 0')

    def body() -> int:
        started = time.perf_counter()
        config = read_calibration_config(args.config)
        start_path = args.start or config['calibration_file']
        start = load_calibration(start_path)
        settings = SceneCalibrationSettings(max_frames=args.max_frames)
        empty = read_frames(args.empty, image_topic=args.image_topic,
                            max_frames=args.max_frames)
        glove = read_frames(args.glove, image_topic=args.image_topic,
                            max_frames=args.max_frames)
        print(f'{len(empty)} empty-scene frames from {args.empty}, {len(glove)} glove frames '
              f'from {args.glove}; starting calibration {start_path}', flush=True)
        fitted = calibrate_scene(
            start, empty, glove, settings, seed=args.seed,
            segmenter_settings=config['segmenter'], picture_frames=args.check_frames,
            source=f'scene calibration: empty {args.empty}, glove {args.glove}, '
                   f'start {start_path}')
        output = save_calibration(fitted.calibration, args.output)
        print_table(fitted.classes, title=(
            'glove colours found (pixels learnt from; start_agrees / scene_agrees: share of '
            'them the starting calibration, at its light, / the new one labels so; '
            'scene_claim_before / _after: share of the colour the scene background takes, '
            'before / after down-weighting)'))
        before = scene_figures(start, empty, glove, config['segmenter'])
        after = scene_figures(fitted.calibration, empty, glove, config['segmenter'])
        rows = [{'figure': key, 'start': before[key], 'scene': after[key]} for key in before]
        print_table(rows, title=(
            'on the recorded frames, the starting and the new calibration: share of the empty '
            'scene labelled glove (full-frame labelling / the segmenter\'s final labels), share '
            'of empty and of glove frames with a hand found'))
        summary = fitted.summary
        print('light: gains to the starting calibration\'s light '
              f'{np.round(summary["light_gains"], 3).tolist()}; glove found in '
              f'{summary["glove_frames_with_glove"]} of {summary["glove_frames"]} glove frames; '
              f'scene components {summary["scene_components"]} kept '
              f'({summary["scene_components_downweighted"]} down-weighted, '
              f'{summary["scene_components_dropped"]} dropped)')
        for warning in _warnings(summary):
            print(f'note: {warning}')
        if 'scene_calibration' in start.metadata:
            print('note: the starting calibration was itself fitted to a scene; to calibrate '
                  'afresh, start from the generic one (--start data/color_calibration.npz)')
        args.pictures.mkdir(parents=True, exist_ok=True)
        written = []
        for name, picture in check_pictures(fitted, start, empty, glove,
                                            config['segmenter']).items():
            path = args.pictures / name
            if not cv2.imwrite(str(path), np.ascontiguousarray(picture[..., ::-1])):
                raise SceneCalibrationError(f'cannot write {path}')
            written.append(str(path))
        seconds = time.perf_counter() - started
        print(f'wrote {output} and {len(written)} pictures in {args.pictures} ({seconds:.1f} s)')
        print(f'check the pictures, then set in {config["config_path"]}:\n'
              f'  calibration_file: {output.resolve()}')
        if args.json:
            write_json(args.json, {
                'output': str(output), 'start': str(start_path), 'empty': str(args.empty),
                'glove': str(args.glove), 'classes': fitted.classes,
                'summary': fitted.summary, 'before': before, 'after': after,
                'pictures': written, 'seconds': seconds})
        return 0

    return run_tool(NAME, body)


if __name__ == '__main__':
    raise SystemExit(main())
