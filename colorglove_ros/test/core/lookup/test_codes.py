"""Tests for binary codes: packing, Hamming distance, similarity-sensitive coding."""
from __future__ import annotations

import numpy as np
import pytest
from label_samples import random_blob_images

from colorglove_ros.core.lookup.codes import (
    CodeError,
    encoder_from_arrays,
    features_from_dts,
    hamming_distances,
    hamming_naive,
    pack_codes,
    train_pca_itq,
    train_random_projections,
    train_ssc,
    unpack_codes,
)
from colorglove_ros.core.lookup.distance import distance_transforms_batch


@pytest.mark.parametrize('bits', [1, 64, 100, 192, 256])
def test_pack_layout_and_round_trip(bits: int) -> None:
    rng = np.random.default_rng(bits)
    b = rng.random((7, bits)) < 0.5
    packed = pack_codes(b)
    assert packed.dtype == np.uint64 and packed.shape == (7, (bits + 63) // 64)
    for i in range(7):
        for w in range(packed.shape[1]):
            want = sum(1 << (j - 64 * w) for j in range(64 * w, min(bits, 64 * w + 64)) if b[i, j])
            assert int(packed[i, w]) == want
    np.testing.assert_array_equal(unpack_codes(packed, bits), b)


def test_hamming_matches_naive() -> None:
    rng = np.random.default_rng(3)
    bits = rng.random((500, 192)) < 0.5
    packed = pack_codes(bits)
    columns = np.ascontiguousarray(packed.T)
    out = np.empty(500, np.uint16)
    scratch = np.empty(500, np.uint64)
    count = np.empty(500, np.uint8)
    out8 = np.full(500, 77, np.uint8)                     # stale contents must not matter
    for q in (0, 17, 499):
        got = hamming_distances(columns, packed[q], out, scratch, count).copy()
        np.testing.assert_array_equal(got, (bits != bits[q]).sum(axis=1))
        np.testing.assert_array_equal(got, hamming_naive(packed, packed[q]))
        assert got[q] == 0
        np.testing.assert_array_equal(hamming_distances(columns, packed[q], out8, scratch, count),
                                      got)


def test_hamming_blocks_match_whole_scan(monkeypatch) -> None:
    """Blocks of 7 entries (a partial last block) give the same distances as one pass."""
    import colorglove_ros.core.lookup.codes as codes_mod

    rng = np.random.default_rng(4)
    bits = rng.random((53, 130)) < 0.5
    packed = pack_codes(bits)
    columns = np.ascontiguousarray(packed.T)
    want = (bits != bits[5]).sum(axis=1)
    monkeypatch.setattr(codes_mod, 'HAMMING_BLOCK', 7)
    for dtype in (np.uint8, np.uint16):
        out = np.full(53, 200, dtype)
        got = hamming_distances(columns, packed[5], out, np.empty(7, np.uint64),
                                np.empty(7, np.uint8))
        np.testing.assert_array_equal(got, want)


def test_features_are_pooled_squared_distances() -> None:
    rng = np.random.default_rng(0)
    dts = rng.random((3, 10, 40, 40)).astype(np.float32) * 50
    want = (dts.astype(np.float64) ** 2).reshape(3, 10, 20, 2, 20, 2).mean(axis=(3, 5))
    np.testing.assert_allclose(features_from_dts(dts), want.reshape(3, -1), rtol=1e-5)


def _blob_pairs(seed: int, n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Images, pairs and similar flags: each base image with a 1-2 px shifted copy."""
    rng = np.random.default_rng(seed)
    base = random_blob_images(rng, n)
    shifted = np.stack([np.roll(b, tuple(rng.integers(-2, 3, 2)), axis=(0, 1)) for b in base])
    imgs = np.concatenate([base, shifted])
    pos = np.stack([np.arange(n), np.arange(n) + n], axis=1)
    neg = np.stack([np.arange(n), (np.arange(n) + 1 + rng.integers(0, n - 1, n)) % n], axis=1)
    pairs = np.concatenate([pos, neg])
    return imgs, pairs, np.concatenate([np.ones(n, bool), np.zeros(n, bool)])


def _auc(ham_pos: np.ndarray, ham_neg: np.ndarray) -> float:
    return float(np.mean(ham_pos[:, None] < ham_neg[None, :])
                 + 0.5 * np.mean(ham_pos[:, None] == ham_neg[None, :]))


def test_ssc_beats_chance_on_held_out_pairs() -> None:
    imgs, pairs, similar = _blob_pairs(0, 300)
    feats = features_from_dts(distance_transforms_batch(imgs))
    enc = train_ssc(feats, pairs, similar, num_bits=48, seed=0)
    assert enc.num_bits == 48 and enc.kind == 'ssc'
    t_imgs, t_pairs, t_sim = _blob_pairs(1, 150)           # unseen images
    bits = enc.bits_from_dts(distance_transforms_batch(t_imgs))
    ham = (bits[t_pairs[:, 0]] != bits[t_pairs[:, 1]]).sum(axis=1)
    auc = _auc(ham[t_sim], ham[~t_sim])
    assert auc > 0.9, auc
    assert ham[t_sim].mean() < 0.6 * ham[~t_sim].mean()
    # reproducible and storable
    again = train_ssc(feats, pairs, similar, num_bits=48, seed=0)
    np.testing.assert_array_equal(enc.dims, again.dims)
    loaded = encoder_from_arrays('ssc', enc.to_arrays())
    np.testing.assert_array_equal(loaded.bits_from_features(feats), enc.bits_from_features(feats))
    np.testing.assert_array_equal(enc.truncated(16).bits_from_features(feats),
                                  enc.bits_from_features(feats)[:, :16])
    np.testing.assert_array_equal(enc.encode(imgs[:5]),
                                  pack_codes(enc.bits_from_features(feats[:5])))


def test_baseline_codes() -> None:
    imgs, _, _ = _blob_pairs(2, 120)
    feats = features_from_dts(distance_transforms_batch(imgs))
    for enc in (train_random_projections(feats, 32, seed=0), train_pca_itq(feats, 32, seed=0)):
        bits = enc.bits_from_features(feats)
        assert bits.shape == (240, 32)
        assert 0.05 < bits.mean() < 0.95
        loaded = encoder_from_arrays(enc.kind, enc.to_arrays())
        np.testing.assert_array_equal(loaded.bits_from_features(feats), bits)


def test_rejects_bad_training_data() -> None:
    feats = np.zeros((4, 4000), np.float32)
    with pytest.raises(CodeError):
        train_ssc(feats, np.array([[0, 1]]), np.array([True]))
    with pytest.raises(CodeError):
        encoder_from_arrays('nope', {'encoder_thresholds': np.zeros(3)})
