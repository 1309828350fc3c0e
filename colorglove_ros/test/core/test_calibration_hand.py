"""The user's hand in the calibration file: optional ``finger_length_factors`` beside
``hand_length_m``, read, refused when malformed, and the one hand model every user of the
calibration builds (``calibrated_hand_model``, ``calibrated_hand``)."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yaml
from hand_calibration_files import UNEVEN_FACTORS, calibration_with_hand
from repo_paths import CONFIG_DIR

from colorglove_ros.core.camera import CalibrationError, load_calibration
from colorglove_ros.core.hand.glove import calibrated_hand, default_hand
from colorglove_ros.core.hand.model import NOMINAL_FINGER_LENGTH_FACTORS, calibrated_hand_model


def test_shipped_calibration_has_the_nominal_proportions() -> None:
    calibration = load_calibration(CONFIG_DIR / 'calibration.yaml')
    assert calibration.finger_length_factors == NOMINAL_FINGER_LENGTH_FACTORS
    model = calibrated_hand_model(calibration)
    assert model.finger_length_factors == NOMINAL_FINGER_LENGTH_FACTORS
    assert model.hand_length_m == calibration.hand_length_m


def test_factors_round_trip_into_the_hand_model(tmp_path: Path) -> None:
    path = calibration_with_hand(tmp_path, UNEVEN_FACTORS, hand_length_m=0.18)
    calibration = load_calibration(path)
    assert calibration.finger_length_factors == UNEVEN_FACTORS
    assert all(type(f) is float for f in calibration.finger_length_factors)
    assert calibration.hand_length_m == 0.18
    model = calibrated_hand_model(calibration)
    assert (model.hand_length_m, model.finger_length_factors) == (0.18, UNEVEN_FACTORS)
    triple = calibrated_hand(calibration, 0)
    assert triple is default_hand(0.18, 0, UNEVEN_FACTORS)
    assert triple[0].finger_length_factors == triple[1].finger_length_factors == UNEVEN_FACTORS
    assert np.array_equal(triple[2].face_patch, default_hand(0.18, 0)[2].face_patch)


def test_integer_factors_are_read(tmp_path: Path) -> None:
    path = calibration_with_hand(tmp_path, [1, 1, 1, 1, 1])
    assert load_calibration(path).finger_length_factors == NOMINAL_FINGER_LENGTH_FACTORS


@pytest.mark.parametrize('factors, message', [
    ([1.0, 1.0, 1.0, 1.0], 'must be a list of 5'),
    ([1.0] * 6, 'must be a list of 5'),
    ('1 1 1 1 1', 'must be a list of 5'),
    ({'thumb': 1.0}, 'must be a list of 5'),
    (None, 'must be a list of 5'),
    ([1.0, float('nan'), 1.0, 1.0, 1.0], 'the index factor nan is outside'),
    ([1.0, 1.0, float('inf'), 1.0, 1.0], 'the middle factor inf is outside'),
    ([1.0, 1.0, 1.0, 2.0, 1.0], 'the ring factor 2.0 is outside'),
    ([1.0, 1.0, 1.0, 1.0, 0.2], 'the little factor 0.2 is outside'),
    ([1.0, 1.0, 1.0, 1.0, 'long'], 'the little factor must be a number'),
    ([True, 1.0, 1.0, 1.0, 1.0], 'the thumb factor must be a number'),
])
def test_malformed_factors_are_refused(tmp_path: Path, factors, message: str) -> None:
    path = calibration_with_hand(tmp_path, factors)
    with pytest.raises(CalibrationError, match=f'{path}: finger_length_factors.*{message}'):
        load_calibration(path)


def test_a_misspelt_key_is_refused(tmp_path: Path) -> None:
    data = yaml.safe_load((CONFIG_DIR / 'calibration.yaml').read_text())
    data['finger_length_factor'] = [1.0] * 5
    path = tmp_path / 'misspelt.yaml'
    path.write_text(yaml.safe_dump(data))
    with pytest.raises(CalibrationError, match="unknown setting.*'finger_length_factor'"):
        load_calibration(path)
