"""Tests for the border pixels glove blobs share in a label image."""
from __future__ import annotations

import numpy as np
import pytest

from colorglove_ros.core.segmentation.blob_borders import BlobBorderError, blob_borders


def _image() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    labels = np.zeros((24, 24), np.uint8)
    labels[2:6, 2:6] = 1          # blob 0 touches blob 1 along a 4-pixel column
    labels[2:6, 6:9] = 2          # blob 1
    labels[10:14, 2:6] = 3        # blob 2: two background columns from blob 3
    labels[10:14, 8:10] = 1       # blob 3: same colour as blob 0, another component
    labels[18:20, 18:20] = 4      # blob 4: far from all
    colors = np.array([1, 2, 3, 1, 4])
    centroids = np.array([[3.5, 3.5], [7.0, 3.5], [3.5, 11.5], [8.5, 11.5], [18.5, 18.5]])
    return labels, colors, centroids


def test_touching_blobs_share_a_border_and_separate_ones_do_not() -> None:
    labels, colors, centroids = _image()
    one = blob_borders(labels, colors, centroids, reach=1)
    # across the column border: each of 4 rows pairs with its 3 (2 at the ends) neighbours
    assert one[0, 1] == one[1, 0] == 10
    assert one.sum() == 20 and np.all(np.diag(one) == 0)
    two = blob_borders(labels, colors, centroids, reach=2)
    assert two[0, 1] > one[0, 1] and two[2, 3] == 0      # a 2-pixel gap is 3 steps apart
    three = blob_borders(labels, colors, centroids, reach=3)
    assert three[2, 3] > 0 and three[0, 3] == 0 and three[4].sum() == 0


def test_a_blob_is_its_own_component_of_its_colour() -> None:
    """Two blobs of one colour are told apart by their centroids; a blob whose centroid matches
    no component of its colour has no border."""
    labels, colors, centroids = _image()
    moved = centroids.copy()
    moved[1] += 5.0
    out = blob_borders(labels, colors, moved, reach=1)
    assert out[0, 1] == 0 and out.sum() == 0
    assert blob_borders(labels, colors[:1], centroids[:1]).shape == (1, 1)
    assert blob_borders(np.zeros((5, 5), np.uint8), colors, centroids).sum() == 0


def test_bad_arguments_are_refused() -> None:
    labels, colors, centroids = _image()
    with pytest.raises(BlobBorderError):
        blob_borders(labels, colors, centroids[:2])
    with pytest.raises(BlobBorderError):
        blob_borders(labels, colors, centroids, reach=0)
