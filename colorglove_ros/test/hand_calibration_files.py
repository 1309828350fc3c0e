"""Calibration files for the tests of the per-user hand: the shipped calibration with another
hand length and finger length factors."""
from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import yaml
from repo_paths import CONFIG_DIR

__all__ = ['UNEVEN_FACTORS', 'calibration_with_hand']

UNEVEN_FACTORS = (1.12, 0.9, 1.08, 0.85, 1.2)
"""Finger length factors (thumb..little) far from the nominal proportions, within range."""


def calibration_with_hand(folder: Path, finger_length_factors: Sequence[float] | object,
                          hand_length_m: float | None = None, name: str = 'calibration'
                          ) -> Path:
    """``config/calibration.yaml`` with ``finger_length_factors`` (written as given, so tests
    can write malformed values) and, if given, ``hand_length_m``, written in ``folder``."""
    data = yaml.safe_load((CONFIG_DIR / 'calibration.yaml').read_text())
    data['finger_length_factors'] = (list(finger_length_factors)
                                     if isinstance(finger_length_factors, tuple)
                                     else finger_length_factors)
    if hand_length_m is not None:
        data['hand_length_m'] = hand_length_m
    path = folder / f'{name}.yaml'
    path.write_text(yaml.safe_dump(data))
    return path
