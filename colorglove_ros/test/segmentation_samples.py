"""Quick colour calibrations for the segmentation tests: the fast fitting settings, fitted on
blob-glove frames or on rendered frames of the printed glove."""
from __future__ import annotations

from typing import Any

import numpy as np

from colorglove_ros.core.segmentation.calibration_fit import (
    fit_color_calibration,
    render_training_frames,
)
from colorglove_ros.core.segmentation.color_model import ColorCalibration
from colorglove_ros.core.synthetic.blob_glove import render_blob_frame, sample_blob_conditions

FAST_FIT: dict[str, Any] = dict(max_per_class=1500, bits=5, augment_copies=1,
                                background_components=6)
"""Fitting settings that keep a test's calibration to about a second."""


def blob_glove_calibration() -> ColorCalibration:
    """A calibration fitted with :data:`FAST_FIT` on 8 blob-glove training frames (seed 11)."""
    rng = np.random.default_rng(11)
    train = [render_blob_frame(rng, sample_blob_conditions(rng, 'train')) for _ in range(8)]
    return fit_color_calibration(train, seed=0, **FAST_FIT)


def printed_glove_calibration() -> ColorCalibration:
    """A calibration fitted with :data:`FAST_FIT` on 8 rendered frames of the printed glove."""
    return fit_color_calibration(render_training_frames(8, 0), seed=0, **FAST_FIT)
