"""Shared inputs of the scene-calibration tests, made once per test session: a quick starting
calibration, rendered scenes, the shipped segmenter settings and fast scene-calibration
settings."""
from __future__ import annotations

from functools import lru_cache
from pathlib import Path
from typing import Any

from repo_paths import CONFIG_DIR

from colorglove_ros.core.segmentation.calibration_fit import (
    fit_color_calibration,
    render_training_frames,
)
from colorglove_ros.core.segmentation.color_model import (
    ColorCalibration,
    read_calibration_config,
    save_calibration,
)
from colorglove_ros.core.segmentation.scene_calibration import SceneCalibrationSettings
from colorglove_ros.tools.eval_scene_calibration import Scene, render_scene

__all__ = ['FAST_SCENE_SETTINGS', 'WARM_SCENE', 'start_calibration', 'start_calibration_file',
           'scene', 'segmenter_settings']

#: Fewer pixels per fit than the defaults: the same steps, in a few seconds.
FAST_SCENE_SETTINGS = SceneCalibrationSettings(max_pixels_per_class=1500, max_scene_pixels=8000)
#: A tuning scene of eval_scene_calibration (not a reported one): 3500 K light at 0.66 gain,
#: an office wall and desk with wood, brick, skin-like and near-black surfaces behind the hand.
WARM_SCENE = 8


@lru_cache(maxsize=1)
def start_calibration() -> ColorCalibration:
    """A quick colour calibration fitted on 8 rendered 'train' frames (5200-7200 K light)."""
    return fit_color_calibration(render_training_frames(8, 0), seed=0, max_per_class=1500,
                                 bits=5, augment_copies=1, background_components=6)


def start_calibration_file(folder: Path) -> Path:
    """:func:`start_calibration` saved in ``folder``."""
    return save_calibration(start_calibration(), folder / 'start_calibration.npz')


@lru_cache(maxsize=2)
def scene(seed: int = WARM_SCENE) -> Scene:
    """Scene ``seed`` of eval_scene_calibration at 320x240 (shared: never modify it)."""
    return render_scene(seed)


@lru_cache(maxsize=1)
def segmenter_settings() -> dict[str, Any]:
    """The segmenter settings of the shipped config/color_calibration.yaml."""
    return read_calibration_config(CONFIG_DIR / 'color_calibration.yaml')['segmenter']
