"""How much of what the segmenter found a fit explains (``matching.explained_blob_share``)."""
from __future__ import annotations

import math

import numpy as np
import pytest

from colorglove_ros.core.camera import PinholeCamera
from colorglove_ros.core.tracking.matching import explained_blob_share
from colorglove_ros.core.tracking.types import Blobs, Correspondences

CAMERA = PinholeCamera(fx=500.0, fy=500.0, cx=320.0, cy=240.0, width=640, height=480,
                       distortion=np.array([-0.2, 0.05, 0.0, 0.0, 0.0]))


def _corr(targets: np.ndarray, camera: int = 0) -> Correspondences:
    n = len(targets)
    return Correspondences(np.full(n, camera), np.zeros(n, np.int64), np.zeros((n, 3)),
                           targets, np.arange(n), np.arange(n))


def test_share_of_usable_blobs_a_correspondence_targets() -> None:
    centroids = np.array([[100.0, 100.0], [200.0, 150.0], [300.0, 260.0], [500.0, 400.0],
                          [50.0, 20.0]])
    blobs = Blobs(np.array([1, 2, 3, 4, 5]), centroids, np.array([40.0, 40, 40, 40, 2]))
    # targets are the undistorted centroids of the blobs they matched (as match_primary makes)
    matched = _corr(CAMERA.undistort_pixels(centroids[[0, 2]]))
    # the 2-pixel blob is too small to be matched, so it does not count either way
    assert explained_blob_share(matched, blobs, CAMERA, min_blob_pixels=4) == pytest.approx(0.5)
    assert explained_blob_share(matched, blobs, CAMERA, min_blob_pixels=1) == pytest.approx(0.4)
    # a distorted (raw) centroid is not its blob's target
    assert explained_blob_share(_corr(centroids[[0, 2]]), blobs, CAMERA) == 0.0
    # another camera's correspondences explain nothing of the primary camera's blobs
    other = _corr(CAMERA.undistort_pixels(centroids[[0, 2]]), camera=1)
    assert explained_blob_share(other, blobs, CAMERA) == 0.0
    assert math.isnan(explained_blob_share(matched, Blobs.empty(), CAMERA))
