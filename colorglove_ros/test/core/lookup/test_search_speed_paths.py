"""Tests for the fast lookup paths: query encoder, grouped re-rank, threads."""
from __future__ import annotations

import numpy as np
import pytest
from label_samples import random_blob_images
from small_databases import blob_database, poses_on_axis

from colorglove_ros.core.camera import PinholeCamera
from colorglove_ros.core.lookup.codes import (
    QueryEncoder,
    hamming_naive,
    pack_codes,
    train_random_projections,
)
from colorglove_ros.core.lookup.distance import QueryDistance, distance_transforms_batch
from colorglove_ros.core.lookup.search import PoseLookup, SearchError, top_k_with_ties


def _blobs(seed: int, n: int) -> np.ndarray:
    # 1 to 6 discs of radius 2 to 9: very different glove-pixel counts
    return random_blob_images(np.random.default_rng(seed), n, blobs=(1, 7), radius=(2, 10))


def _db(n: int = 240):
    rng = np.random.default_rng(1)
    tiny = _blobs(3, n)
    tiny[5] = 0
    tiny[5, 10:12, 10:12] = 4                          # a 4-pixel entry
    return blob_database(tiny, poses_on_axis(rng.normal(0.0, 0.5, (n, 3))), num_bits=96,
                         num_pairs=400)


def test_query_encoder_equals_full_feature_path() -> None:
    db = _db()
    qe = QueryEncoder(db.encoder)
    imgs = _blobs(9, 30)
    dts = distance_transforms_batch(imgs)
    want = db.encoder.bits_from_dts(dts)
    for i in range(len(imgs)):
        np.testing.assert_array_equal(qe.bits(dts[i]), want[i])
        np.testing.assert_array_equal(qe.encode(dts[i]), pack_codes(want[i:i + 1])[0])
    # stored database codes are the same function of the (quantised) transforms
    lookup = PoseLookup(db)
    ham = lookup.hamming(imgs[0])
    np.testing.assert_array_equal(qe.encode(dts[0]).shape, (2,))
    assert ham.dtype == np.uint8 and ham.max() <= 96
    # projection codes use the generic path
    rp = train_random_projections(np.random.default_rng(0).normal(size=(50, 4000)), 70)
    dense = QueryEncoder(rp)
    np.testing.assert_array_equal(dense.bits(dts[3]), rp.bits_from_dts(dts[3:4])[0])


def test_grouped_rerank_matches_reference_distance() -> None:
    db = _db()
    lookup = PoseLookup(db)
    for q in (_blobs(11, 1)[0], np.asarray(db.tiny[5]), np.asarray(db.tiny[17])):
        qd = QueryDistance(q)
        cand = top_k_with_ties(lookup.hamming(q), 120)
        ref = qd.to_many(np.asarray(db.tiny[cand]), np.asarray(db.dts[cand]))
        for groups in (1, 3, 4, 500):
            lookup._rerank_groups = groups
            np.testing.assert_allclose(lookup.rerank(qd, cand), ref, atol=2e-4)
    assert lookup.rerank(QueryDistance(db.tiny[5]), np.array([5]))[0] == 0.0


def test_top_k_uint8_binary_search_matches_sort() -> None:
    rng = np.random.default_rng(4)
    for k in (1, 7, 50, 299, 300):
        vals = rng.integers(0, 193, 1000).astype(np.uint8)
        got = top_k_with_ties(vals, k)
        cut = np.sort(vals)[k - 1]
        np.testing.assert_array_equal(got, np.flatnonzero(vals <= cut))
        np.testing.assert_array_equal(got, top_k_with_ties(vals.astype(np.uint16), k))
        np.testing.assert_array_equal(got, top_k_with_ties(vals.astype(np.int64), k))


def test_threaded_lookup_equals_single_thread() -> None:
    """The worker thread (the re-rank's query -> candidate gather) changes no result."""
    db = _db()
    one = PoseLookup(db, num_candidates=40, threads=1)
    two = PoseLookup(db, num_candidates=40, threads=2)
    assert two._pool is not None
    cam = PinholeCamera(128, 128, 150.0, 150.0, 63.5, 63.5)
    for q in (_blobs(21, 1)[0], np.asarray(db.tiny[9])):
        np.testing.assert_array_equal(one.hamming(q), two.hamming(q))
        np.testing.assert_array_equal(one.hamming(q), hamming_naive(
            np.ascontiguousarray(np.asarray(db.codes).T), db.encoder.encode(q[None])[0]))
        a, b = one.lookup(q, (1.5, 10.0, 12.0), cam), two.lookup(q, (1.5, 10.0, 12.0), cam)
        np.testing.assert_array_equal(a.indices, b.indices)
        np.testing.assert_array_equal(a.distances, b.distances)
        np.testing.assert_array_equal(a.blended, b.blended)
    with pytest.raises(SearchError):
        PoseLookup(db, threads=3)
    assert PoseLookup(db)._pool is None                    # one thread by default


def test_buffer_bytes_counts_tables() -> None:
    db = _db()
    lookup = PoseLookup(db, num_candidates=40)
    before = lookup.buffer_bytes
    # Hamming output, the scan's selection and the place table
    assert before >= len(db) * (1 + 8 + 10 * 8)
    lookup.lookup(np.asarray(db.tiny[9]), (1.0, 0.0, 0.0),
                  PinholeCamera(128, 128, 150.0, 150.0, 63.5, 63.5))
    assert lookup.buffer_bytes == before                   # no re-rank buffers kept
