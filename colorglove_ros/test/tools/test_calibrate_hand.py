"""colorglove_calibrate_hand: measured hand and digit lengths -> hand_length_m and
finger_length_factors in the calibration YAML (cameras and comments kept), refusals of
measurements that are not a hand's."""
from __future__ import annotations

import json
import re
import shutil
from pathlib import Path

import numpy as np
import pytest
from repo_paths import CONFIG_DIR

from colorglove_ros.core.camera import load_calibration
from colorglove_ros.core.hand.model import DIGITS, HandModel, calibrated_hand_model
from colorglove_ros.tools import calibrate_hand

HAND_MM = 184.0
FINGERS_MM = [66.0, 84.0, 99.0, 88.0, 79.0]     # long thumb, middle and little; short index


def _run(*args: str | Path) -> int:
    return calibrate_hand.main([str(a) for a in args])


def _measure(target: Path, *extra: str | Path, hand_mm: float = HAND_MM,
             fingers_mm: list[float] | None = None) -> int:
    fingers = FINGERS_MM if fingers_mm is None else fingers_mm
    return _run('--calibration', target, '--hand-length-mm', hand_mm, '--finger-mm',
                *fingers, *extra)


def test_new_file_holds_the_measured_hand_and_the_cameras(tmp_path: Path, capsys) -> None:
    target = tmp_path / 'user' / 'calibration.yaml'
    assert _measure(target, '--cameras-from', CONFIG_DIR / 'calibration_stereo.yaml',
                    '--json', tmp_path / 'hand.json') == 0
    out = capsys.readouterr().out
    calibration = load_calibration(target)
    stereo = load_calibration(CONFIG_DIR / 'calibration_stereo.yaml')
    assert [c.to_dict() for c in calibration.cameras] == [c.to_dict() for c in stereo.cameras]
    assert calibration.hand_length_m == HAND_MM / 1000.0
    model = calibrated_hand_model(calibration)
    # the model's digits are the measured ones (factors rounded to 1e-4)
    np.testing.assert_allclose(model.digit_lengths_m * 1000.0, FINGERS_MM, atol=0.02)
    rest = model.keypoints(model.rest_pose(centered=False))
    assert np.linalg.norm(rest[12] - rest[0]) == pytest.approx(HAND_MM / 1000.0, abs=1e-12)
    factors = np.array(calibration.finger_length_factors)
    # relative to the middle finger, each digit is as much longer than the model's as measured
    nominal = HandModel(HAND_MM / 1000.0).digit_lengths_m * 1000.0
    ratio = np.array(FINGERS_MM) / nominal
    np.testing.assert_allclose(factors / factors[2], ratio / ratio[2], rtol=2e-4)
    assert factors[0] > factors[2] > factors[1] and factors[4] > factors[2]
    figures = json.loads((tmp_path / 'hand.json').read_text())
    assert figures['written'] and figures['finger_length_factors'] == list(factors)
    assert [row['digit'] for row in figures['digits']] == list(DIGITS)
    for row, measured, expected in zip(figures['digits'], FINGERS_MM, nominal, strict=True):
        assert row['measured_mm'] == measured
        assert row['nominal_mm'] == pytest.approx(expected, rel=1e-12)
        assert row['model_mm'] == pytest.approx(measured, abs=0.02)
    assert figures['palm_scale'] == pytest.approx(
        model.scale / HandModel(HAND_MM / 1000.0).scale, rel=1e-12)
    assert figures['palm_scale'] < 1.0          # a long middle finger leaves less to the palm
    assert 'nominal_mm' in out and 'factor' in out and f'wrote {target}' in out


def test_update_keeps_comments_and_cameras(tmp_path: Path, capsys) -> None:
    target = tmp_path / 'calibration.yaml'
    shutil.copy(CONFIG_DIR / 'calibration.yaml', target)
    before = target.read_text()
    assert _measure(target) == 0
    assert _measure(target, hand_mm=190.0, fingers_mm=[60, 88, 97, 91, 74]) == 0   # again
    after = target.read_text()
    comments = [line for line in before.splitlines() if line.lstrip().startswith('#')]
    assert all(line in after.splitlines() for line in comments)
    assert after.count('\nfinger_length_factors:') == 1 and after.count('\nhand_length_m:') == 1
    assert '# wrist crease to middle fingertip' in after       # the value's comment kept
    calibration = load_calibration(target)
    assert calibration.hand_length_m == 0.19
    original = load_calibration(CONFIG_DIR / 'calibration.yaml')
    assert calibration.cameras[0].to_dict() == original.cameras[0].to_dict()
    np.testing.assert_allclose(calibration.finger_length_factors, 1.0, atol=0.02)
    assert 'comments not kept' not in capsys.readouterr().out


def test_dry_run_writes_nothing(tmp_path: Path, capsys) -> None:
    target = tmp_path / 'calibration.yaml'
    shutil.copy(CONFIG_DIR / 'calibration.yaml', target)
    before = target.read_text()
    assert _measure(target, '--dry-run') == 0
    assert target.read_text() == before
    assert f'would write {target}' in capsys.readouterr().out


def test_camera_info_cameras_are_named_by_the_new_file(tmp_path: Path) -> None:
    info = tmp_path / 'camera_info.yaml'
    info.write_text('image_width: 640\nimage_height: 480\ncamera_name: cam\n'
                    'camera_matrix: {rows: 3, cols: 3, data: [600, 0, 320, 0, 600, 240, 0, 0, '
                    '1]}\ndistortion_model: plumb_bob\n'
                    'distortion_coefficients: {rows: 1, cols: 5, data: [0, 0, 0, 0, 0]}\n')
    target = tmp_path / 'calibration.yaml'
    assert _measure(target, '--cameras-from', info) == 0
    calibration = load_calibration(target)
    assert calibration.primary.fx == 600.0 and calibration.hand_length_m == HAND_MM / 1000.0
    # a camera_info file itself holds no hand: never overwritten
    before = info.read_text()
    assert _measure(info) == 1
    assert info.read_text() == before


@pytest.mark.parametrize('hand_mm, fingers_mm, message', [
    (50.0, FINGERS_MM, 'is not a human hand'),
    (400.0, FINGERS_MM, 'is not a human hand'),
    (HAND_MM, [66.0, 40.0, 99.0, 88.0, 79.0], 'the index .* allowed 0.7-1.3 times'),
    (HAND_MM, [66.0, 84.0, 99.0, 88.0, 150.0], 'the little .* allowed'),
    (HAND_MM, [66.0, 84.0, 190.0, 88.0, 79.0], 'middle finger .* must be shorter than the hand'),
    (HAND_MM, [66.0, 84.0, 99.0, -88.0, 79.0], 'needs 5 positive lengths'),
    (HAND_MM, [66.0, 84.0, float('nan'), 88.0, 79.0], 'needs 5 positive lengths'),
    (float('nan'), FINGERS_MM, 'is not a human hand'),
])
def test_nonsense_measurements_are_refused(tmp_path: Path, capsys, hand_mm: float,
                                           fingers_mm: list[float], message: str) -> None:
    target = tmp_path / 'calibration.yaml'
    assert _measure(target, hand_mm=hand_mm, fingers_mm=fingers_mm) == 1
    err = capsys.readouterr().err
    assert err.startswith('colorglove_calibrate_hand: error: ')
    assert re.search(message, err), err
    assert not target.exists()


def test_a_broken_calibration_is_refused_and_left_alone(tmp_path: Path, capsys) -> None:
    target = tmp_path / 'calibration.yaml'
    text = (CONFIG_DIR / 'calibration.yaml').read_text().replace('fx: 600.0', 'fx: -600.0')
    target.write_text(text)
    assert _measure(target) == 1
    assert 'fx must be positive' in capsys.readouterr().err
    assert target.read_text() == text


def test_wrong_number_of_digits_is_a_usage_error(tmp_path: Path) -> None:
    with pytest.raises(SystemExit) as exit_info:
        _run('--calibration', tmp_path / 'c.yaml', '--hand-length-mm', 184, '--finger-mm',
             66, 84, 99, 88)
    assert exit_info.value.code == 2
