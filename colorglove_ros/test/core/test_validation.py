"""Boundary checks (core/validation.py), the calibration and colour-config files refused at
start-up with a message naming the file and the problem, and the remembered database CRCs."""
from __future__ import annotations

import math
import os
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
import yaml
from repo_paths import PKG_DIR

from colorglove_ros.core.camera import CalibrationError, load_calibration
from colorglove_ros.core.file_checksums import (
    STAMP_NAME,
    check_unless_passed,
    crc32_matches,
    crc32_of_file,
)
from colorglove_ros.core.segmentation.segmenter import SegmentationConfigError, load_segmenter
from colorglove_ros.core.validation import (
    InvalidConfigError,
    InvalidInputError,
    InvalidObservationError,
    InvalidPriorError,
    check_array,
    check_number,
    validate_crop,
    validate_database_arrays,
    validate_hand_depth,
    validate_observation,
    validate_prior,
    validate_segmenter_settings,
)


# ------------------------------------------------------------------------ helper family
@pytest.mark.parametrize('value, bounds, message', [
    (math.nan, {}, 'finite'), (math.inf, {}, 'finite'), ('3', {}, 'number'),
    (True, {}, 'number'), (4, {'odd': True, 'integer': True}, 'odd'),
    (2.5, {'integer': True}, 'integer'), (0.0, {'low': 0.0, 'low_open': True}, 'positive'),
    (11, {'high': 10}, '<= 10'),
])
def test_check_number_names_field_and_value(value, bounds, message) -> None:
    with pytest.raises(InvalidInputError, match=f'speed.*{message}'):
        check_number('speed', value, **bounds)
    assert check_number('speed', 3, integer=True, odd=True, low=1, high=5) == 3


def test_check_array_shape_kind_finite_range_length() -> None:
    with pytest.raises(InvalidInputError, match=r'xy must have shape \(N, 2\)'):
        check_array('xy', np.zeros((3, 3)), shape=(None, 2))
    with pytest.raises(InvalidInputError, match='xy must be finite, got nan at index'):
        check_array('xy', [[0.0, np.nan]], shape=(None, 2))
    with pytest.raises(InvalidInputError, match='dtype kind'):
        check_array('ids', [0.5], kind='iu')
    with pytest.raises(InvalidInputError, match='at most 4'):
        check_array('ids', list(range(5)), max_length=4)
    assert check_array('xy', [], shape=(None, 2)).shape == (0, 2)


# ------------------------------------------------------------------------ observations
def _observation(**changes) -> dict:
    tiny = np.zeros(1600, np.int64)
    tiny[700:760] = 3
    fields = dict(image_width=640, image_height=480, tiny_labels=tiny, crop=(2.0, 280.0, 200.0),
                  blob_color=np.array([3, 4]), blob_centroid_px=np.array([[300.0, 240.0],
                                                                          [310.0, 250.0]]),
                  blob_pixel_count=np.array([120, 80]), glove_pixel_count=200)
    fields.update(changes)
    return fields


@pytest.mark.parametrize('changes, message', [
    ({'crop': (1e155, 0.0, 0.0)}, 'crop_scale'), ({'crop': (math.nan, 0.0, 0.0)}, 'crop_scale'),
    ({'crop': (1e-250, 0.0, 0.0)}, 'crop_scale'), ({'crop': (2.0, 1e9, 0.0)}, 'crop_offset_x'),
    ({'blob_color': np.array([0, 4])}, 'color_label'),
    ({'blob_color': np.array([11, 4])}, 'color_label'),
    ({'blob_centroid_px': np.array([[np.nan, 1.0], [1.0, 1.0]])}, 'centroid'),
    ({'blob_centroid_px': np.array([[1.0, 600.0], [1.0, 1.0]])}, 'outside'),
    ({'blob_pixel_count': np.array([0, 5])}, 'pixel_count'),
    ({'blob_pixel_count': np.array([4e9, 5])}, 'pixel_count'),
    ({'blob_color': np.ones(50_000, int), 'blob_centroid_px': np.ones((50_000, 2)),
      'blob_pixel_count': np.ones(50_000)}, '50000 rows'),
    ({'image_width': 0}, 'image_width'), ({'tiny_labels': np.zeros(1600, int)}, 'no glove'),
    ({'tiny_labels': np.full(1600, 11)}, 'tiny_labels'), ({'tiny_labels': [1] * 5}, 'shape'),
    ({'glove_pixel_count': 4_000_000_000}, 'glove_pixel_count'),
])
def test_validate_observation_refuses(changes, message) -> None:
    with pytest.raises(InvalidObservationError, match=message):
        validate_observation(**_observation(**changes))
    assert validate_observation(**_observation()).shape == (40, 40)


def test_validate_crop_accepts_the_segmenters_range() -> None:
    validate_crop(0.5, -10.0, -10.0, 640, 480)
    validate_crop(30.0, -600.0, -500.0, 640, 480)


# ------------------------------------------------------------------------ priors
def _prior(**changes) -> dict:
    fields = dict(blended_pose=np.r_[0.0, 0.0, 0.5, np.zeros(23)],
                  candidate_poses=[np.r_[0.0, 0.0, 0.5, np.zeros(23)]],
                  candidate_weights=np.ones(1), candidate_distances=np.ones(1),
                  constraints=(np.array([3]), np.array([2]), np.array([10]),
                               np.array([[20.0, 20.0]]), np.array([12])),
                  num_vertices=100)
    fields.update(changes)
    return fields


@pytest.mark.parametrize('changes, message', [
    ({'blended_pose': np.full(26, np.nan)}, 'blended_pose'),
    ({'blended_pose': np.zeros(5)}, 'blended_pose'),
    ({'candidate_poses': []}, 'no candidates'),
    ({'candidate_weights': np.array([np.nan])}, 'candidate_weights'),
    ({'constraints': (np.array([], int),) * 3 + (np.zeros((0, 2)), np.array([], int))},
     'no projection constraints'),
    ({'constraints': (np.array([25]), np.array([2]), np.array([10]), np.array([[1.0, 1.0]]),
                      np.array([1]))}, 'constraint_patch_ids'),
    ({'constraints': (np.array([3]), np.array([2]), np.array([100]), np.array([[1.0, 1.0]]),
                      np.array([1]))}, 'constraint_vertices'),
    ({'finger_std': -np.ones(20)}, 'finger_std'),
])
def test_validate_prior_refuses(changes, message) -> None:
    with pytest.raises(InvalidPriorError, match=message):
        validate_prior(**_prior(**changes))
    assert validate_prior(**_prior()).shape == (26,)


def test_validate_hand_depth() -> None:
    validate_hand_depth(np.array([[0.0, 0.0, 0.4], [0.05, 0.0, 0.5]]))
    for z in (0.001, -0.3, 50.0):
        with pytest.raises(InvalidPriorError, match='hand depth'):
            validate_hand_depth(np.array([[0.0, 0.0, 0.4], [0.0, 0.0, z]]))


# ------------------------------------------------------------------------ corrupt files
CALIBRATION_CASES = {
    'fx_nan': ('fx', math.nan, 'fx must be finite'), 'fx_inf': ('fx', math.inf, 'fx must be'),
    'cx_nan': ('cx', math.nan, 'cx must be finite'), 'fx_zero': ('fx', 0.0, 'fx must be positive'),
    'fy_negative': ('fy', -600.0, 'fy must be positive'), 'width_zero': ('width', 0, 'width'),
    'width_text': ('width', 'wide', 'width must be a number'),
    'distortion_nan': ('distortion', [0.1, math.nan, 0.0, 0.0, 0.0], 'distortion must be finite'),
    'distortion_length': ('distortion', [0.1, 0.0], 'distortion needs 5'),
    'rotation_length': ('rotation_vector', [0.0, 0.0], 'rotation_vector must have shape'),
    'translation_inf': ('translation', [0.0, math.inf, 0.0], 'translation must be finite'),
    'missing_fx': ('fx', None, 'missing camera field'),
}


@pytest.mark.parametrize('case', sorted(CALIBRATION_CASES))
def test_corrupt_calibration_refused_naming_file_and_problem(case: str, tmp_path: Path) -> None:
    key, value, message = CALIBRATION_CASES[case]
    data = yaml.safe_load((PKG_DIR / 'config' / 'calibration.yaml').read_text())
    if value is None:
        del data['cameras'][0][key]
    else:
        data['cameras'][0][key] = value
    path = tmp_path / f'{case}.yaml'
    path.write_text(yaml.safe_dump(data))
    with pytest.raises(CalibrationError, match=message) as info:
        load_calibration(path)
    assert str(path) in str(info.value)


def test_calibration_hand_length_nan_refused(tmp_path: Path) -> None:
    data = yaml.safe_load((PKG_DIR / 'config' / 'calibration.yaml').read_text())
    data['hand_length_m'] = math.nan
    path = tmp_path / 'hand.yaml'
    path.write_text(yaml.safe_dump(data))
    with pytest.raises(CalibrationError, match=f'{path}: hand_length_m must be finite'):
        load_calibration(path)


SEGMENTER_CASES = {
    'median_even': ('median_size', 4, 'median_size must be odd'),
    'roi_margin_inf': ('roi_margin', math.inf, 'roi_margin must be finite'),
    'sigma_color_nan': ('bilateral_sigma_color', math.nan, 'bilateral_sigma_color must be finite'),
    'sigma_space_zero': ('bilateral_sigma_space', 0.0, 'bilateral_sigma_space must be > 0'),
    'coarse_zero': ('coarse_factor', 0, 'coarse_factor must be >= 1'),
    'inside_fraction': ('min_inside_fraction', 2.0, 'min_inside_fraction must be <= 1'),
    'border_distances_empty': ('border_distances', [], 'border_distances must be a non-empty'),
    'unknown_key': ('no_such_key', 1, "unknown setting 'no_such_key'"),
    'max_roi_text': ('max_roi_cells', 'many', 'max_roi_cells must be a number'),
}


@pytest.mark.parametrize('case', sorted(SEGMENTER_CASES))
def test_corrupt_colour_config_refused_at_start_up(case: str, tmp_path: Path) -> None:
    key, value, message = SEGMENTER_CASES[case]
    path = tmp_path / f'{case}.yaml'
    path.write_text(yaml.safe_dump({'calibration_file': str(tmp_path / 'never_read.npz'),
                                    'segmenter': {key: value}}))
    with pytest.raises(SegmentationConfigError, match=message) as info:
        load_segmenter(str(path))
    assert str(path) in str(info.value)
    with pytest.raises(InvalidConfigError):
        validate_segmenter_settings({key: value}, str(path))


def _database(**changes) -> SimpleNamespace:
    fields = dict(poses=np.zeros((4, 26), np.float32), crop=np.tile([1.0, 0.0, 0.0], (4, 1)),
                  patch_color=np.arange(20, dtype=np.uint8) % 10 + 1,
                  patch_vertex=np.full((4, 20), 5, np.int32),
                  patch_pixels=np.ones((4, 20), np.float32),
                  pixel_keys=np.zeros((4, 8), np.uint16), tiny=np.zeros((4, 40, 40), np.uint8),
                  render_camera={'fx': 150.0, 'fy': 150.0, 'cx': 63.5, 'cy': 63.5})
    fields.update(changes)
    return SimpleNamespace(**fields)


@pytest.mark.parametrize('changes, message', [
    ({'patch_vertex': np.full((4, 20), 5000, np.int32)}, 'patch_vertex must be <= 2891'),
    ({'patch_vertex': np.full((4, 20), -7, np.int32)}, 'patch_vertex must be >= -1'),
    ({'poses': np.full((4, 26), np.nan, np.float32)}, 'poses must be finite'),
    ({'crop': np.zeros((4, 3))}, 'crop scale must be > 0'),
    ({'patch_color': np.full(20, 11, np.uint8)}, 'patch_color must be <= 10'),
    ({'pixel_keys': np.full((4, 8), 60000, np.uint16)}, 'pixel_keys must be <='),
    ({'tiny': np.full((4, 40, 40), 12, np.uint8)}, 'tiny must be <= 10'),
    ({'render_camera': {'fx': math.nan}}, 'render_camera fx must be finite'),
])
def test_corrupt_database_contents_refused(changes, message) -> None:
    with pytest.raises(InvalidInputError, match=f'db_folder: {message}'):
        validate_database_arrays(_database(**changes), 'db_folder', num_vertices=2892)
    validate_database_arrays(_database(), 'db_folder', num_vertices=2892)


# ------------------------------------------------------------------------ remembered CRCs
def test_crc32_remembered_until_the_file_changes(tmp_path: Path) -> None:
    file = tmp_path / 'poses.npy'
    file.write_bytes(b'x' * 1000)
    crc = crc32_of_file(file)
    assert not crc32_matches(file, crc + 1) and not (tmp_path / STAMP_NAME).exists()
    assert crc32_matches(file, crc) and (tmp_path / STAMP_NAME).is_file()
    assert crc32_matches(file, crc)                              # from the stamp
    # same size and modification time, other bytes: the status-change time gives it away
    stat = file.stat()
    file.write_bytes(b'y' * 1000)
    os.utime(file, ns=(stat.st_atime_ns, stat.st_mtime_ns))
    assert not crc32_matches(file, crc)


def test_a_passed_check_is_remembered_until_a_file_changes(tmp_path: Path) -> None:
    """The database's contents check runs once per unchanged set of files; a failing check
    is never remembered; a changed file, another check name or another file set runs it again,
    and the CRC records kept in the same stamp survive."""
    files = [tmp_path / 'a.npy', tmp_path / 'b.npy']
    for file in files:
        file.write_bytes(b'x' * 100)
    crc = crc32_of_file(files[0])
    assert crc32_matches(files[0], crc)
    runs: list[str] = []

    def passing() -> None:
        runs.append('pass')

    def failing() -> None:
        runs.append('fail')
        raise InvalidInputError('bad contents')

    with pytest.raises(InvalidInputError):
        check_unless_passed(files, 'contents v1', failing)
    with pytest.raises(InvalidInputError):
        check_unless_passed(files, 'contents v1', failing)      # a failure is not remembered
    assert check_unless_passed(files, 'contents v1', passing)
    assert not check_unless_passed(files, 'contents v1', passing)      # remembered
    assert check_unless_passed(files, 'contents v2', passing)          # another check
    assert check_unless_passed(files[:1], 'contents v1', passing)      # another file set
    stat = files[1].stat()
    files[1].write_bytes(b'y' * 100)
    os.utime(files[1], ns=(stat.st_atime_ns, stat.st_mtime_ns))
    with pytest.raises(InvalidInputError):
        check_unless_passed(files, 'contents v1', failing)      # changed: checked again
    assert runs == ['fail', 'fail', 'pass', 'pass', 'pass', 'fail']
    assert crc32_matches(files[0], crc)
    with pytest.raises(ValueError, match='one folder'):
        check_unless_passed([files[0], tmp_path.parent / 'c.npy'], 'x', passing)


@pytest.mark.parametrize('bad, shown', [(np.nan, 'nan'), (np.inf, 'inf'), (-np.inf, '-inf')])
@pytest.mark.parametrize('bounds', [{}, {'low': -1.0}, {'high': 1.0}, {'low': -1.0, 'high': 1.0}])
def test_check_array_names_the_first_non_finite_value_whatever_the_bounds(bad, shown,
                                                                          bounds) -> None:
    values = np.zeros((3, 2))
    values[2, 1], values[1, 0] = bad, 0.5
    with pytest.raises(InvalidInputError,
                       match=rf'xy must be finite, got {shown} at index \(2, 1\)'):
        check_array('xy', values, shape=(None, 2), **bounds)
    # not asked to be finite: a NaN passes the bounds (it compares false), as before
    if bad != bad:
        assert check_array('xy', values, finite=False, **bounds) is values


def test_check_array_finite_check_scans_the_extremes_only(monkeypatch) -> None:
    """A finite float array is known finite from its extremes (a NaN or infinity would be
    one): no elementwise mask is built."""
    seen = []
    original = np.isfinite
    monkeypatch.setattr(np, 'isfinite', lambda x, *a, **k: seen.append(np.ndim(x)) or
                        original(x, *a, **k))
    out = check_array('xy', np.linspace(0.0, 1.0, 40).reshape(20, 2), shape=(None, 2),
                      low=0.0, high=1.0)
    assert out.shape == (20, 2) and seen and max(seen) == 0
