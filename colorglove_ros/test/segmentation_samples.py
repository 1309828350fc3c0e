"""Quick colour calibrations for the segmentation tests: the fast fitting settings, fitted on
blob-glove frames or on rendered frames of the printed glove."""
from __future__ import annotations

from typing import Any

import cv2
import numpy as np

from colorglove_ros.core.segmentation.calibration_fit import (
    fit_color_calibration,
    render_training_frames,
)
from colorglove_ros.core.segmentation.color_model import ColorCalibration
from colorglove_ros.core.synthetic.blob_glove import (
    BlobConditions,
    render_blob_frame,
    sample_blob_conditions,
)

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


GREY = 110
"""The background grey of :func:`paste_gloves` frames."""
LEFT, RIGHT = (150, 240), (470, 240)
"""Glove centres (x, y) in a 640x480 frame."""


def blob_glove_cutout() -> tuple[np.ndarray, np.ndarray]:
    """A clean blob glove's pixels and mask, cut to its bounding box."""
    rng = np.random.default_rng(3)
    image, labels = render_blob_frame(rng, BlobConditions(1.0, (1.0, 1.0, 1.0), 1.0, 0, False,
                                                          1.0))
    ys, xs = np.nonzero(labels)
    box = np.s_[ys.min():ys.max() + 1, xs.min():xs.max() + 1]
    return image[box], labels[box] > 0


def paste_gloves(glove: tuple[np.ndarray, np.ndarray], *placed: tuple[tuple[int, int], float]
                 ) -> np.ndarray:
    """A :data:`GREY` 640x480 frame with the ``glove`` cut-out (:func:`blob_glove_cutout`)
    pasted centred at each (centre, scale)."""
    frame = np.full((480, 640, 3), GREY, np.uint8)
    pixels, mask = glove
    for (cx, cy), scale in placed:
        size = (round(pixels.shape[1] * scale), round(pixels.shape[0] * scale))
        p = cv2.resize(pixels, size, interpolation=cv2.INTER_NEAREST)
        m = cv2.resize(mask.view(np.uint8), size, interpolation=cv2.INTER_NEAREST) > 0
        y0, x0 = cy - size[1] // 2, cx - size[0] // 2
        frame[y0:y0 + size[1], x0:x0 + size[0]][m] = p[m]
    return frame
