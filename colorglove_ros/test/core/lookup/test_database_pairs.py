"""Tests for the SSC training pairs: true neighbours, hard negatives, excluded groups."""
from __future__ import annotations

import numpy as np
import pytest
from label_samples import random_blob_images

from colorglove_ros.core.lookup.database import DatabaseError
from colorglove_ros.core.lookup.database_build import nearest_neighbour_pairs, train_encoder
from colorglove_ros.core.lookup.distance import (
    distance_transforms_batch,
    image_distance,
    quantize_dts,
)


def _images(n: int = 90) -> np.ndarray:
    return random_blob_images(np.random.default_rng(7), n, blobs=4)


def test_hard_negatives_are_farther_than_the_neighbour() -> None:
    tiny = _images()
    dts = quantize_dts(distance_transforms_batch(tiny))
    groups = np.arange(len(tiny)) // 3
    pairs, similar = nearest_neighbour_pairs(tiny, dts, 80, seed=0, shortlist=20,
                                             exclude=groups, hard_negatives=0.5)
    assert len(pairs) == 80 and similar.sum() == 40
    pos, hard = pairs[:40], pairs[40:60]
    assert np.all(groups[pos[:, 0]] != groups[pos[:, 1]])
    np.testing.assert_array_equal(hard[:, 0], pos[:20, 0])     # same anchors
    for (a, p), (_, h) in zip(pos[:20], hard, strict=True):
        assert image_distance(tiny[a], tiny[h]) > image_distance(tiny[a], tiny[p])
        # the positive is the anchor's nearest image outside its group (within 0.125 px)
        others = [j for j in range(len(tiny)) if groups[j] != groups[a]]
        best = min(image_distance(tiny[a], tiny[j]) for j in others)
        assert image_distance(tiny[a], tiny[p]) <= best + 0.25
    assert not similar[40:].any()
    with pytest.raises(DatabaseError):
        nearest_neighbour_pairs(tiny, dts, 80, hard_negatives=1.5)


def test_train_encoder_with_hard_negatives_is_seeded() -> None:
    tiny = _images(60)
    dts = quantize_dts(distance_transforms_batch(tiny))
    a = train_encoder(tiny, dts, num_bits=16, num_pairs=100, seed=3, hard_negatives=0.5)
    b = train_encoder(tiny, dts, num_bits=16, num_pairs=100, seed=3, hard_negatives=0.5)
    np.testing.assert_array_equal(a.dims, b.dims)
    np.testing.assert_array_equal(a.thresholds, b.thresholds)
