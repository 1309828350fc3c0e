"""Fixtures of the segmentation tests: a blob-glove calibration and a clean blob glove cut-out
(``segmentation_samples``), made once per module."""
from __future__ import annotations

import numpy as np
import pytest
from segmentation_samples import blob_glove_calibration, blob_glove_cutout

from colorglove_ros.core.segmentation.color_model import ColorCalibration


@pytest.fixture(scope='module')
def blob_calibration() -> ColorCalibration:
    return blob_glove_calibration()


@pytest.fixture(scope='module')
def blob_glove() -> tuple[np.ndarray, np.ndarray]:
    return blob_glove_cutout()
