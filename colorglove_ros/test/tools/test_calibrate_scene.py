"""colorglove_calibrate_scene: folders or bags of frames in; the calibration file, pictures to
check and the figures out; bad input refused with one clear line and exit code 1."""
from __future__ import annotations

import json
import re
from pathlib import Path
from types import SimpleNamespace

import cv2
import numpy as np
import pytest
from repo_paths import CONFIG_DIR
from scene_samples import scene, segmenter_settings, start_calibration_file

from colorglove_ros.core.camera import PinholeCamera
from colorglove_ros.core.segmentation.color_model import load_calibration
from colorglove_ros.core.segmentation.scene_calibration import SceneCalibrationError
from colorglove_ros.core.segmentation.segmenter import GloveSegmenter
from colorglove_ros.ros.bags import write_sequence_bag
from colorglove_ros.tools import calibrate_scene
from colorglove_ros.tools.calibrate_scene import read_frames

CONFIG = str(CONFIG_DIR / 'color_calibration.yaml')


def _write_pngs(folder: Path, frames: list[np.ndarray]) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    for i, frame in enumerate(frames):
        cv2.imwrite(str(folder / f'{i:04d}.png'), np.ascontiguousarray(frame[..., ::-1]))
    return folder


@pytest.fixture(scope='module')
def recordings(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    folder = tmp_path_factory.mktemp('scene_recordings')
    frames = scene()
    return {'empty': _write_pngs(folder / 'empty', frames.empty),
            'glove': _write_pngs(folder / 'glove', frames.glove),
            'start': start_calibration_file(folder)}


def _run(recordings: dict[str, Path], out: Path, **change: str) -> int:
    args = {'--empty': str(recordings['empty']), '--glove': str(recordings['glove']),
            '--output': str(out / 'scene.npz'), '--pictures': str(out / 'pictures'),
            '--start': str(recordings['start']), '--config': CONFIG, **change}
    return calibrate_scene.main([part for item in args.items() for part in item])


def test_tool_writes_the_calibration_pictures_and_figures(
        recordings: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    assert _run(recordings, tmp_path, **{'--json': str(tmp_path / 'figures.json'),
                                         '--check-frames': '2'}) == 0
    printed = capsys.readouterr().out
    assert 'glove colours found' in printed
    assert f'calibration_file: {(tmp_path / "scene.npz").resolve()}' in printed
    calibration = load_calibration(tmp_path / 'scene.npz')
    segmenter = GloveSegmenter(calibration, **segmenter_settings())
    held = scene().held_glove
    assert sum(segmenter.process(frame).hand_found for frame in held) >= len(held) - 1
    pictures = sorted(p.name for p in (tmp_path / 'pictures').glob('*.png'))
    assert pictures == ['empty_scene.png', 'glove_000.png', 'glove_007.png']
    picture = cv2.imread(str(tmp_path / 'pictures' / 'glove_007.png'))
    assert picture.shape[1] == 3 * 320 and picture.shape[0] > 240
    figures = json.loads((tmp_path / 'figures.json').read_text())
    assert [row['name'] for row in figures['classes']][:3] == ['red', 'green', 'blue']
    assert all(row['status'] == 'refitted' for row in figures['classes'])
    assert figures['after']['empty_labelled_glove'] < 0.2 * figures['before'][
        'empty_labelled_glove']
    assert figures['after']['glove_hand_found'] >= 7 / 8
    assert figures['pictures'] == [str(tmp_path / 'pictures' / name) for name in
                                   ('glove_000.png', 'glove_007.png', 'empty_scene.png')]


def _empty_folder(root: Path, recordings: dict[str, Path]) -> dict[str, str]:
    (root / 'nothing').mkdir()
    return {'--empty': str(root / 'nothing')}


def _unreadable_image(root: Path, recordings: dict[str, Path]) -> dict[str, str]:
    folder = _write_pngs(root / 'glove', [cv2.imread(str(p))[..., ::-1]
                                          for p in sorted(recordings['glove'].glob('*.png'))])
    (folder / '0003.png').write_bytes(b'not a png at all')
    return {'--glove': str(folder)}


def _mixed_sizes(root: Path, recordings: dict[str, Path]) -> dict[str, str]:
    frames = scene().glove
    return {'--glove': str(_write_pngs(root / 'glove', [*frames[:3], frames[3][:200]]))}


def _a_file(root: Path, recordings: dict[str, Path]) -> dict[str, str]:
    return {'--empty': str(next(recordings['empty'].glob('*.png')))}


def _no_glove(root: Path, recordings: dict[str, Path]) -> dict[str, str]:
    return {'--glove': str(_write_pngs(root / 'glove', scene().held_empty))}


def _no_start(root: Path, recordings: dict[str, Path]) -> dict[str, str]:
    return {'--start': str(root / 'missing.npz')}


@pytest.mark.parametrize('bad_input, message', [
    (_empty_folder, 'holds no images'),
    (_unreadable_image, 'cannot read image .*0003.png'),
    (_mixed_sizes, 'frame 3 is 320x200, the first 320x240: all frames must come from one '
                   'camera'),
    (_a_file, 'is not a folder: give a folder of PNG/JPG frames or a rosbag2 folder'),
    (_no_glove, 'no glove found in any of the 3 glove frames'),
    (_no_start, 'colour calibration file not found'),
])
def test_bad_input_is_one_clear_line_and_exit_code_1(
        recordings: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture,
        bad_input, message: str) -> None:
    assert _run(recordings, tmp_path / 'out', **bad_input(tmp_path, recordings)) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith('colorglove_calibrate_scene: error: ')
    assert re.search(message, err[0])
    assert not (tmp_path / 'out' / 'scene.npz').exists()


def test_bag_frames_are_read_from_the_image_topic(tmp_path: Path) -> None:
    frames = scene().empty
    camera = PinholeCamera(320, 240, 300.0, 300.0, 159.5, 119.5)
    write_sequence_bag(tmp_path / 'bag', [
        SimpleNamespace(image_rgb=f, pose=np.zeros(26), keypoints_3d=np.zeros((21, 3)))
        for f in frames], camera)
    read = read_frames(tmp_path / 'bag')
    assert len(read) == len(frames)
    for got, want in zip(read, frames, strict=True):
        np.testing.assert_array_equal(got, want)
    with pytest.raises(SceneCalibrationError, match='no topic /usb_cam/image_raw; its image '
                                                    'topics: /camera/image_raw'):
        read_frames(tmp_path / 'bag', image_topic='/usb_cam/image_raw')


def test_long_recordings_keep_evenly_spaced_frames(tmp_path: Path) -> None:
    frames = [np.full((4, 6, 3), i, np.uint8) for i in range(25)]
    read = read_frames(_write_pngs(tmp_path / 'many', frames), max_frames=4)
    values = [int(frame[0, 0, 0]) for frame in read]
    assert 4 <= len(values) <= 8
    assert values == list(range(0, 25, values[1]))
