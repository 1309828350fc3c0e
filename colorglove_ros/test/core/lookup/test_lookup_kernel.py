"""The lookup's compiled kernels (core.lookup.lookup_kernel) against the numpy code they
replaced: the same Hamming distances, candidates and re-rank distances, bit for bit."""
from __future__ import annotations

import numpy as np
import pytest
from blend_reference import finger_scores_reference
from label_samples import random_blob_images
from small_databases import blob_database, poses_on_axis

from colorglove_ros.core.lookup import lookup_kernel
from colorglove_ros.core.lookup.codes import hamming_distances
from colorglove_ros.core.lookup.distance import ABSENT_PENALTY, DT_SCALE, QueryDistance
from colorglove_ros.core.lookup.search import PoseLookup, top_k_with_ties


@pytest.fixture(scope='module', autouse=True)
def _compiled() -> None:
    lookup_kernel.compile_kernels()


def _numpy_hamming(columns: np.ndarray, query: np.ndarray) -> np.ndarray:
    n = columns.shape[1]
    out = np.empty(n, np.uint8)
    return hamming_distances(columns, query, out, np.empty(n, np.uint64), np.empty(n, np.uint8))


@pytest.mark.parametrize('bits', [1, 64, 96, 192, 255])
def test_hamming_histogram_equals_numpy_scan(bits: int) -> None:
    rng = np.random.default_rng(bits)
    words = (bits + 63) // 64
    for n in (0, 1, 7, 1000, 40001):
        columns = rng.integers(0, 2**64, (words, n), dtype=np.uint64, endpoint=False)
        if bits % 64:
            columns[-1] &= np.uint64((1 << (bits % 64)) - 1)        # unused high bits zero
        query = columns[:, 0].copy() if n else np.zeros(words, np.uint64)
        out = np.empty(n, np.uint8)
        hist = np.full(64 * words + 1, 7, np.int64)               # stale counts are replaced
        lookup_kernel.hamming_histogram(columns, query, out, hist)
        np.testing.assert_array_equal(out, _numpy_hamming(columns, query))
        np.testing.assert_array_equal(hist, np.bincount(out, minlength=len(hist)))
        for cut in (0, 3, bits // 2, bits):
            dest = np.empty(n, np.intp)
            m = lookup_kernel.at_most(out, cut, dest)
            np.testing.assert_array_equal(dest[:m], np.flatnonzero(out <= cut))


def _db(n: int = 300):
    rng = np.random.default_rng(1)
    tiny = random_blob_images(np.random.default_rng(3), n, blobs=(1, 7), radius=(2, 10))
    return blob_database(tiny, poses_on_axis(rng.normal(0.0, 0.5, (n, 3))), num_bits=32,
                         num_pairs=400)


def test_lookup_candidates_equal_top_k_with_ties() -> None:
    """32-bit codes on 300 entries: many ties at the cut, all kept as top_k_with_ties does."""
    db = _db()
    queries = random_blob_images(np.random.default_rng(8), 12, blobs=(1, 7), radius=(2, 10))
    for k in (1, 5, 40, 299, 300, 301):
        lookup = PoseLookup(db, num_candidates=k, threads=1)
        for q in queries:
            qd = QueryDistance(q)
            want = top_k_with_ties(lookup.hamming(q), k)
            got = lookup._candidates(qd.dts)
            np.testing.assert_array_equal(got, want)
            assert got.dtype == np.intp


def _numpy_rerank(lookup: PoseLookup, query: QueryDistance, indices: np.ndarray) -> np.ndarray:
    """The re-rank as numpy computed it before the kernels (one thread)."""
    idx = np.asarray(indices, np.intp)
    nq = query.num_pixels
    keys_db = np.asarray(lookup.db.pixel_keys)
    dts = np.asarray(lookup.db.dts).reshape(-1)
    row = lookup._row
    counts = np.asarray(lookup.db.pixel_counts, np.float64)[idx]
    table = np.zeros(row + 1, np.float32)
    table[:-1] = query.dts.reshape(-1)
    cand_sum = np.empty(len(idx), np.float64)
    order = np.argsort(counts, kind='stable')
    groups = min(lookup._rerank_groups, max(1, len(idx)))
    bounds = (len(idx) * np.arange(groups + 1)) // groups
    for g in range(groups):
        grp = order[bounds[g]:bounds[g + 1]]
        if len(grp) == 0:
            continue
        width = max(1, int(counts[grp[-1]]))
        keys = keys_db[idx[grp], :width].astype(np.intp)
        cand_sum[grp] = table.take(keys, mode='clip').sum(axis=1)
    if nq:
        flat = (idx * row)[:, None] + query.glove_index
        q_sum = dts.take(flat, mode='clip').sum(axis=1, dtype=np.uint32)
        d_qc = q_sum * (1.0 / (DT_SCALE * nq))
        d_cq = np.where(counts > 0, cand_sum / np.maximum(counts, 1.0), ABSENT_PENALTY)
    else:
        d_qc = np.where(counts > 0, ABSENT_PENALTY, 0.0)
        d_cq = d_qc
    return 0.5 * (d_qc + d_cq)


@pytest.mark.parametrize('threads', [1, 2])
def test_rerank_equals_numpy_bit_for_bit(threads: int) -> None:
    db = _db()
    lookup = PoseLookup(db, num_candidates=120, threads=threads)
    rng = np.random.default_rng(5)
    queries = [*random_blob_images(np.random.default_rng(9), 6, blobs=(1, 7), radius=(2, 10)),
               np.asarray(db.tiny[4]), np.zeros((40, 40), np.uint8)]
    for q in queries:
        qd = QueryDistance(q)
        for indices in (np.arange(len(db)), rng.choice(len(db), 120, replace=False),
                        np.array([4]), np.array([], np.intp)):
            for groups in (1, 3, 4, 500):
                lookup._rerank_groups = groups
                got = lookup.rerank(qd, indices)
                want = _numpy_rerank(lookup, qd, indices)
                assert got.dtype == want.dtype and got.shape == want.shape
                assert got.tobytes() == want.tobytes()


def test_candidate_sums_follow_numpy_pairwise_order() -> None:
    """float32 sums of up to 1,700 terms (the pairwise blocks and their halves) equal numpy's
    row sums bit for bit; keys past the table read its last slot, as take(mode='clip')."""
    rng = np.random.default_rng(2)
    table = (rng.random(16001) * 40.0).astype(np.float32)
    keys = rng.integers(0, 16010, (40, 1700)).astype(np.uint16)
    widths = np.concatenate([np.arange(1, 140), rng.integers(140, 1701, 60)])
    for w in widths:
        idx = rng.choice(40, 9, replace=False).astype(np.intp)
        out = np.empty(len(idx))
        lookup_kernel.candidate_sums(table, keys, idx, np.full(len(idx), w, np.intp), out)
        want = table.take(keys[idx, :w].astype(np.intp), mode='clip').sum(axis=1)
        assert out.tobytes() == want.astype(np.float64).tobytes(), w


def test_query_sums_equal_numpy_gather() -> None:
    rng = np.random.default_rng(3)
    dts = rng.integers(0, 256, 50 * 16000).astype(np.uint8)
    glove = np.sort(rng.choice(16000, 900, replace=False)).astype(np.intp)
    idx = rng.choice(50, 20).astype(np.intp)
    out = np.empty(20, np.uint32)
    lookup_kernel.query_sums(dts, idx, 16000, glove, out)
    want = dts.reshape(50, 16000)[idx][:, glove].sum(axis=1, dtype=np.uint32)
    np.testing.assert_array_equal(out, want)


@pytest.mark.parametrize('count', [0, 1, 2, 3, 5])
def test_gathers_with_few_candidates_and_the_last_entry(count: int) -> None:
    """Fewer candidates than the prefetch reaches ahead, the database's last entry among them:
    the sums are numpy's (the prefetched rows stay inside the arrays)."""
    rng = np.random.default_rng(count)
    dts = rng.integers(0, 256, 6 * 1600).astype(np.uint8)
    glove = np.sort(rng.choice(1600, 300, replace=False)).astype(np.intp)
    idx = np.append(rng.choice(5, max(count - 1, 0)), 5)[:count].astype(np.intp)
    out = np.empty(count, np.uint32)
    lookup_kernel.query_sums(dts, idx, 1600, glove, out)
    np.testing.assert_array_equal(
        out, dts.reshape(6, 1600)[idx][:, glove].sum(axis=1, dtype=np.uint32))
    table = (rng.random(1601) * 40.0).astype(np.float32)
    keys = rng.integers(0, 1610, (6, 700)).astype(np.uint16)
    widths = rng.integers(1, 701, count).astype(np.intp)
    sums = np.empty(count)
    lookup_kernel.candidate_sums(table, keys, idx, widths, sums)
    want = [table.take(keys[i, :w].astype(np.intp), mode='clip').sum() for i, w in
            zip(idx, widths, strict=True)]
    assert sums.tobytes() == np.asarray(want, np.float32).astype(np.float64).tobytes()


def test_gathers_prefetch_the_rows_ahead() -> None:
    """Both re-rank gathers ask for the rows ahead (the database's rows are read at random);
    compiled afresh from their source (numba does not show cached code)."""
    import numba

    for kernel in (lookup_kernel.query_sums, lookup_kernel.candidate_sums):
        fresh = numba.njit(kernel.py_func)
        fresh.compile(lookup_kernel._SIGNATURES[kernel])
        code = next(iter(fresh.inspect_llvm().values()))
        assert 'llvm.prefetch' in code, kernel.__name__
    assert lookup_kernel.PREFETCH_AHEAD >= 1


def test_kernels_have_one_signature() -> None:
    """Every kernel runs compiled for one signature and refuses another (no compile per call)."""
    for kernel in lookup_kernel._SIGNATURES:
        assert len(kernel.signatures) == 1
    with pytest.raises(TypeError):
        lookup_kernel.hamming_histogram(np.zeros((3, 4), np.uint64), np.zeros(3, np.uint64),
                                        np.zeros(4, np.uint16), np.zeros(193, np.int64))
    with pytest.raises(TypeError):
        lookup_kernel.query_sums(np.zeros(10, np.float32), np.zeros(1, np.intp), 10,
                                 np.zeros(1, np.intp), np.zeros(1, np.uint32))


@pytest.mark.parametrize('seed', range(40))
def test_finger_scores_equal_numpy_bit_for_bit(seed: int) -> None:
    """The per-finger scores with the compiled nearest-blob search are numpy's, bit for bit:
    hidden patches (NaN centroids), colours no blob has, blobs at equal distances (copies),
    one blob, none, no entry, float32 database centroids as the lookup passes them."""
    from colorglove_ros.core.lookup.finger_evidence import FingerEvidenceConfig, finger_scores

    rng = np.random.default_rng(seed)
    k, p, b = int(rng.integers(0, 40)), 20, int(rng.integers(0, 25))
    xy = rng.uniform(-2.0, 42.0, (k, p, 2)).astype(np.float32 if seed % 2 else np.float64)
    xy[rng.random((k, p)) < 0.3] = np.nan
    pixels = rng.uniform(0.0, 60.0, (k, p)).astype(np.float32)
    digit = rng.integers(-1, 6, (k, p)).astype(np.int8)
    color = rng.integers(1, 11, p).astype(np.uint8 if seed % 3 else np.int64)
    bcol = rng.integers(1, 8, b)                             # colours 8-10 have no blob
    bxy = rng.uniform(0.0, 40.0, (b, 2))
    bpix = rng.uniform(0.5, 80.0, b)
    if b > 2:                                                # a copy: two blobs equally near
        bcol[-1], bxy[-1] = bcol[0], bxy[0]
    if seed % 5 == 0 and k:                                   # a patch exactly on a blob
        xy[0, 0] = bxy[0] if b else xy[0, 0]
    config = FingerEvidenceConfig(cap_tiny_px=float(rng.uniform(2.0, 8.0)))
    args = (xy, pixels, digit, color, bcol, bxy, bpix, config)
    got = finger_scores(*args)
    want = finger_scores_reference(*args)
    assert got.dtype == want.dtype and got.shape == want.shape == (k, 5)
    assert got.tobytes() == want.tobytes()


def test_nearest_same_colour_takes_the_first_of_equals_and_nan() -> None:
    """The first of equally near same-colour blobs, the first NaN distance (as np.argmin),
    infinity and blob 0 where no blob has the patch's colour."""
    d = np.empty((1, 3))
    at = np.empty((1, 3), np.int64)
    xy = np.array([[[0.0, 0.0], [np.nan, 1.0], [5.0, 5.0]]])
    lookup_kernel.nearest_same_colour(xy, np.array([2, 2, 9]), np.array([1, 2, 2, 2]),
                                      np.array([[0.0, 0.0], [3.0, 4.0], [4.0, 3.0],
                                                [0.0, 5.0]]), d, at)
    assert d[0, 0] == 5.0 and at[0, 0] == 1
    assert np.isnan(d[0, 1]) and at[0, 1] == 1
    assert d[0, 2] == np.inf and at[0, 2] == 0


def test_finger_scores_refuse_blob_arrays_of_different_lengths() -> None:
    from colorglove_ros.core.lookup.finger_evidence import (
        FingerEvidenceConfig,
        FingerEvidenceError,
        finger_scores,
    )

    with pytest.raises(FingerEvidenceError, match='centroids'):
        finger_scores(np.zeros((1, 20, 2)), np.ones((1, 20)), np.zeros((1, 20), np.int8),
                      np.ones(20, np.int64), np.array([1, 2]), np.zeros((1, 2)),
                      np.ones(2), FingerEvidenceConfig())
