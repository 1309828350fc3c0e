"""Calibration files for the tests: the shipped one with another hand length."""
from __future__ import annotations

from pathlib import Path

import yaml
from repo_paths import CONFIG_DIR

__all__ = ['calibration_with_hand_length']


def calibration_with_hand_length(folder: Path, hand_length_m: float) -> Path:
    """``config/calibration.yaml`` with ``hand_length_m`` changed, written in ``folder``."""
    data = yaml.safe_load((CONFIG_DIR / 'calibration.yaml').read_text())
    assert 'hand_length_m' in data
    data['hand_length_m'] = hand_length_m
    path = folder / f'calibration_{hand_length_m}.yaml'
    path.write_text(yaml.safe_dump(data))
    return path
