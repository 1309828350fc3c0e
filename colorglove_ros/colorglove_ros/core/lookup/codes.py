"""Binary codes for tiny images: similarity-sensitive coding (GentleBoost stumps) and baselines."""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from colorglove_ros.core.conventions import NUM_COLORS, TINY_SIZE
from colorglove_ros.core.errors import ColorGloveError
from colorglove_ros.core.lookup.distance import distance_transforms_batch

__all__ = [
    'FEATURE_POOL', 'FEATURE_SIDE', 'FEATURE_DIM', 'HAMMING_BLOCK', 'CodeError', 'BinaryEncoder',
    'features_from_dts', 'pack_codes', 'unpack_codes', 'hamming_distances',
    'hamming_naive', 'train_ssc', 'train_random_projections', 'train_pca_itq',
    'encoder_from_arrays', 'QueryEncoder',
]

FEATURE_POOL = 2
"""Features are the per-colour squared distance transforms D(r) averaged over 2x2 blocks:
40x40x10 -> 20x20x10 = 4,000 dimensions (4x fewer than the paper's 16,000, for speed)."""
FEATURE_SIDE = TINY_SIZE // FEATURE_POOL
FEATURE_DIM = NUM_COLORS * FEATURE_SIDE * FEATURE_SIDE

# Candidate stump thresholds, in pixels of distance (features are squared distances).
_THRESHOLD_PX = np.array([0.5, 1.0, 1.5, 2.0, 2.5, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0, 10.0, 12.0,
                          15.0, 18.0, 22.0, 27.0, 33.0, 40.0, 48.0, 56.0], np.float32)
_THRESHOLDS = _THRESHOLD_PX ** 2


class CodeError(ColorGloveError):
    """Bad code arrays, encoder parameters or training data."""


def features_from_dts(dts: np.ndarray) -> np.ndarray:
    """Features (N, FEATURE_DIM) float32 from distance transforms (N, 10, 40, 40), float32
    pixels: squared distances averaged over FEATURE_POOL x FEATURE_POOL blocks."""
    dts = np.asarray(dts, np.float32)
    if dts.ndim != 4 or dts.shape[1:] != (NUM_COLORS, TINY_SIZE, TINY_SIZE):
        raise CodeError(f'distance transforms must be (N, 10, 40, 40), got {dts.shape}')
    sq = np.square(dts)
    p = FEATURE_POOL
    pooled = np.zeros((len(dts), NUM_COLORS, FEATURE_SIDE, FEATURE_SIDE), np.float32)
    for dy in range(p):
        for dx in range(p):
            pooled += sq[:, :, dy::p, dx::p]
    pooled *= np.float32(1.0 / (p * p))
    return pooled.reshape(len(dts), FEATURE_DIM)


def pack_codes(bits: np.ndarray) -> np.ndarray:
    """Pack (N, B) bool bits into (N, ceil(B/64)) uint64 words; bit j of a row goes to word
    j // 64, bit position j % 64 (least significant first); unused high bits are zero."""
    bits = np.asarray(bits, bool)
    if bits.ndim != 2:
        raise CodeError(f'bits must be (N, B), got shape {bits.shape}')
    n, b = bits.shape
    words = (b + 63) // 64
    padded = np.zeros((n, words * 64), bool)
    padded[:, :b] = bits
    as_bytes = np.packbits(padded.reshape(n, words, 8, 8), axis=3, bitorder='little')
    return np.ascontiguousarray(as_bytes.reshape(n, words * 8)).view('<u8').astype(np.uint64)


def unpack_codes(packed: np.ndarray, num_bits: int) -> np.ndarray:
    """Inverse of :func:`pack_codes`: (N, W) uint64 -> (N, num_bits) bool."""
    packed = np.ascontiguousarray(packed, dtype='<u8')
    n = len(packed)
    as_bytes = packed.view(np.uint8).reshape(n, -1)
    return np.unpackbits(as_bytes, axis=1, bitorder='little')[:, :num_bits].astype(bool)


def hamming_naive(packed_db: np.ndarray, packed_query: np.ndarray) -> np.ndarray:
    """Reference Hamming distances (N,) by unpacking every bit (slow; for tests)."""
    nbits = packed_db.shape[1] * 64
    a = unpack_codes(packed_db, nbits)
    q = unpack_codes(np.asarray(packed_query).reshape(1, -1), nbits)
    return (a != q).sum(axis=1)


HAMMING_BLOCK = 32768
"""Entries per block of the Hamming scan: the XOR scratch of a block stays in cache."""


def hamming_distances(columns: np.ndarray, query: np.ndarray, out: np.ndarray,
                      scratch: np.ndarray, scratch_count: np.ndarray) -> np.ndarray:
    """Hamming distances of one packed query (W,) uint64 against a database stored as
    per-word columns (W, N) uint64 (each row contiguous), with no big temporaries.

    ``out`` (N,) uint8 (codes up to 255 bits) or uint16 receives the distances; ``scratch``
    uint64 and ``scratch_count`` uint8, each of at least min(N, HAMMING_BLOCK) entries, are
    reused buffers. Entries are scanned in blocks of :data:`HAMMING_BLOCK` (about 20% faster
    at 100k entries than whole columns, whose scratch falls out of the L2 cache)."""
    n = columns.shape[1]
    words = columns.shape[0]
    for s in range(0, n, HAMMING_BLOCK):
        e = min(n, s + HAMMING_BLOCK)
        res, xor, cnt = out[s:e], scratch[:e - s], scratch_count[:e - s]
        start = 0
        if out.dtype == np.uint8 and words > 0:
            np.bitwise_xor(columns[0, s:e], query[0], out=xor)
            np.bitwise_count(xor, out=res)            # first word: no zeroing, no add
            start = 1
        else:
            res[:] = 0
        for w in range(start, words):
            np.bitwise_xor(columns[w, s:e], query[w], out=xor)
            np.bitwise_count(xor, out=cnt)
            np.add(res, cnt, out=res)
    return out


@dataclass
class BinaryEncoder:
    """Bits = [features @ projection - offset > threshold] (linear-threshold codes).

    ``kind='ssc'`` stores stumps as ``dims`` (feature index per bit) and ``thresholds``;
    projection codes store ``mean`` (D,), ``projection`` (D, B) and ``thresholds`` (B,)."""

    kind: str
    thresholds: np.ndarray
    dims: np.ndarray | None = None
    mean: np.ndarray | None = None
    projection: np.ndarray | None = None
    info: dict = field(default_factory=dict)

    @property
    def num_bits(self) -> int:
        """Code length B."""
        return len(self.thresholds)

    def truncated(self, num_bits: int) -> BinaryEncoder:
        """The encoder using only its first ``num_bits`` bits (boosting order for SSC)."""
        return BinaryEncoder(
            self.kind, self.thresholds[:num_bits],
            None if self.dims is None else self.dims[:num_bits], self.mean,
            None if self.projection is None else self.projection[:, :num_bits], dict(self.info))

    def bits_from_features(self, features: np.ndarray) -> np.ndarray:
        """(N, D) features -> (N, B) bool."""
        features = np.asarray(features, np.float32)
        if self.kind == 'ssc':
            return features[:, self.dims] > self.thresholds
        centred = features - self.mean
        return centred @ self.projection > self.thresholds

    def bits_from_dts(self, dts: np.ndarray) -> np.ndarray:
        """(N, 10, 40, 40) float32 distance transforms -> (N, B) bool."""
        return self.bits_from_features(features_from_dts(dts))

    def encode_dts(self, dts: np.ndarray) -> np.ndarray:
        """(N, 10, 40, 40) float32 distance transforms -> packed (N, W) uint64."""
        return pack_codes(self.bits_from_dts(dts))

    def encode(self, label_images: np.ndarray) -> np.ndarray:
        """(N, 40, 40) label images -> packed (N, ceil(B/64)) uint64 codes."""
        return self.encode_dts(distance_transforms_batch(label_images))

    def to_arrays(self) -> dict[str, np.ndarray]:
        """Arrays for storage (see :func:`encoder_from_arrays`)."""
        arrays = {'encoder_thresholds': np.asarray(self.thresholds, np.float32)}
        if self.kind == 'ssc':
            arrays['encoder_dims'] = np.asarray(self.dims, np.int32)
        else:
            arrays['encoder_mean'] = np.asarray(self.mean, np.float32)
            arrays['encoder_projection'] = np.asarray(self.projection, np.float32)
        return arrays


class QueryEncoder:
    """Fast packed code of one query from its float32 distance transforms (10, 40, 40).

    For SSC only the pixels under the stumps' pooling blocks are read (4 per bit), with the
    same float32 arithmetic as :func:`features_from_dts`, so the bits equal
    ``encoder.bits_from_dts``; other encoders fall back to the full feature path.
    Buffers are reused: one instance is not thread-safe."""

    def __init__(self, encoder: BinaryEncoder) -> None:
        self.encoder = encoder
        self.words = (encoder.num_bits + 63) // 64
        self._bytes = np.zeros(self.words * 8, np.uint8)
        self._pixels: np.ndarray | None = None
        if encoder.kind == 'ssc':
            dims = np.asarray(encoder.dims, np.intp)
            area = FEATURE_SIDE * FEATURE_SIDE
            color, rem = np.divmod(dims, area)
            by, bx = np.divmod(rem, FEATURE_SIDE)
            p = FEATURE_POOL
            cols = []
            for dy in range(p):            # same order as the accumulation in features_from_dts
                for dx in range(p):
                    cols.append(color * TINY_SIZE * TINY_SIZE
                                + (p * by + dy) * TINY_SIZE + p * bx + dx)
            self._pixels = np.stack(cols, axis=1)                  # (B, p*p)
            self._thresholds = np.asarray(encoder.thresholds, np.float32)

    def bits(self, dts: np.ndarray) -> np.ndarray:
        """(B,) bool bits of one query's float32 distance transforms (10, 40, 40)."""
        if self._pixels is None:
            return self.encoder.bits_from_dts(np.asarray(dts, np.float32)[None])[0]
        vals = np.asarray(dts, np.float32).reshape(-1)[self._pixels]
        np.multiply(vals, vals, out=vals)
        acc = vals[:, 0].copy()
        for j in range(1, vals.shape[1]):
            acc += vals[:, j]
        acc *= np.float32(1.0 / (FEATURE_POOL * FEATURE_POOL))
        return acc > self._thresholds

    def encode(self, dts: np.ndarray) -> np.ndarray:
        """Packed (W,) uint64 code (layout of :func:`pack_codes`)."""
        packed = np.packbits(self.bits(dts), bitorder='little')
        self._bytes[:len(packed)] = packed
        return self._bytes.view('<u8').astype(np.uint64)


def encoder_from_arrays(kind: str, arrays: dict[str, np.ndarray]) -> BinaryEncoder:
    """Rebuild an encoder saved with :meth:`BinaryEncoder.to_arrays`."""
    try:
        thresholds = np.asarray(arrays['encoder_thresholds'], np.float32)
        if kind == 'ssc':
            dims = np.asarray(arrays['encoder_dims'], np.intp)
            if dims.shape != thresholds.shape or dims.min() < 0 or dims.max() >= FEATURE_DIM:
                raise CodeError('SSC encoder dims do not match its thresholds or features')
            return BinaryEncoder('ssc', thresholds, dims=dims)
        if kind in ('rp', 'itq', 'pca'):
            mean = np.asarray(arrays['encoder_mean'], np.float32)
            proj = np.asarray(arrays['encoder_projection'], np.float32)
            if proj.shape != (FEATURE_DIM, len(thresholds)) or mean.shape != (FEATURE_DIM,):
                raise CodeError(f'{kind} encoder projection has shape {proj.shape}')
            return BinaryEncoder(kind, thresholds, mean=mean, projection=proj)
    except KeyError as exc:
        raise CodeError(f'encoder array missing: {exc}') from exc
    raise CodeError(f'unknown encoder kind {kind!r}')


def train_ssc(features: np.ndarray, pairs: np.ndarray, similar: np.ndarray, num_bits: int = 192,
              seed: int = 0, dim_groups: int = 4) -> BinaryEncoder:
    """Similarity-sensitive coding (Shakhnarovich et al. 2003; Torralba et al. 2008) with
    GentleBoost on pairs.

    Each round picks the stump h(r) = [features[d] > T] (any dimension d, T from a fixed grid
    of squared pixel distances) whose pair regressor f = a if h(r_i) == h(r_j) else b
    minimises the weighted squared error against y = +1 (similar) / -1 (dissimilar); the
    pair weights then become w * exp(-y f). For speed the dimensions are split at random
    (seeded) into ``dim_groups`` disjoint groups searched in turn, one group a round, each
    exhaustively over (d, T): the pairs' disagreement intervals are held in one sparse
    matrix per group so a round is one sparse product."""
    from scipy import sparse  # only when training codes (loading a database does not)

    features = np.asarray(features, np.float32)
    pairs = np.asarray(pairs, np.intp)
    y = np.where(np.asarray(similar, bool), 1.0, -1.0)
    if pairs.ndim != 2 or pairs.shape[1] != 2 or len(pairs) != len(y) or len(y) == 0:
        raise CodeError('pairs must be (P, 2) indices with one similar flag each')
    if np.all(y > 0) or np.all(y < 0):
        raise CodeError('SSC needs both similar and dissimilar pairs')
    n_pairs, dim = len(pairs), features.shape[1]
    nt = len(_THRESHOLDS)
    # rank r(v) = #thresholds below v; bit_t(v) = t < r(v); disagree at t iff lo <= t < hi.
    r_lo = np.empty((n_pairs, dim), np.uint8)
    r_hi = np.empty((n_pairs, dim), np.uint8)
    for s in range(0, n_pairs, 2048):
        fa, fb = features[pairs[s:s + 2048, 0]], features[pairs[s:s + 2048, 1]]
        r_lo[s:s + 2048] = np.searchsorted(_THRESHOLDS, np.minimum(fa, fb), side='left')
        r_hi[s:s + 2048] = np.searchsorted(_THRESHOLDS, np.maximum(fa, fb), side='left')
    rng = np.random.default_rng(seed)
    groups = np.array_split(rng.permutation(dim), max(1, min(dim_groups, dim)))
    mats = []
    for g in groups:
        lo, hi = r_lo[:, g], r_hi[:, g]
        p_idx, d_idx = np.nonzero(lo != hi)
        base = d_idx * (nt + 1)
        rows = np.concatenate([base + lo[p_idx, d_idx], base + hi[p_idx, d_idx]])
        vals = np.concatenate([np.ones(len(p_idx)), -np.ones(len(p_idx))])
        mats.append(sparse.csr_matrix((vals, (rows, np.concatenate([p_idx, p_idx]))),
                                      shape=(len(g) * (nt + 1), n_pairs)))
    w = np.full(n_pairs, 1.0 / n_pairs)
    dims_out = np.empty(num_bits, np.intp)
    thr_out = np.empty(num_bits, np.float32)
    eps = 1e-12
    for b in range(num_bits):
        g = groups[b % len(groups)]
        hist = mats[b % len(groups)] @ np.stack([w * y, w], axis=1)   # (len(g)*(nt+1), 2)
        cum = np.cumsum(hist.reshape(len(g), nt + 1, 2), axis=1)[:, :nt]
        s_d, w_d = cum[..., 0], cum[..., 1]
        s_a, w_a = float(np.sum(w * y)) - s_d, float(np.sum(w)) - w_d
        gain = s_d ** 2 / np.maximum(w_d, eps) + s_a ** 2 / np.maximum(w_a, eps)
        j, t = divmod(int(np.argmax(gain)), nt)
        f_dis = s_d[j, t] / max(w_d[j, t], eps)
        f_agr = s_a[j, t] / max(w_a[j, t], eps)
        d = int(g[j])
        disagree = (r_lo[:, d] <= t) & (t < r_hi[:, d])
        w = w * np.exp(-y * np.where(disagree, f_dis, f_agr))
        w /= w.sum()
        dims_out[b], thr_out[b] = d, _THRESHOLDS[t]
    return BinaryEncoder('ssc', thr_out, dims=dims_out,
                         info={'pairs': int(n_pairs), 'seed': int(seed)})


def train_random_projections(features: np.ndarray, num_bits: int = 192,
                             seed: int = 0) -> BinaryEncoder:
    """Sign of random Gaussian projections of the centred features (LSH baseline)."""
    features = np.asarray(features, np.float32)
    rng = np.random.default_rng(seed)
    mean = features.mean(axis=0)
    proj = rng.standard_normal((features.shape[1], num_bits)).astype(np.float32)
    return BinaryEncoder('rp', np.zeros(num_bits, np.float32), mean=mean, projection=proj)


def train_pca_itq(features: np.ndarray, num_bits: int = 192, seed: int = 0,
                  iterations: int = 50) -> BinaryEncoder:
    """PCA (randomised SVD) followed by iterative quantisation (Gong and Lazebnik 2011)."""
    from sklearn.utils.extmath import randomized_svd  # heavy: only when training codes

    x = np.asarray(features, np.float64)
    if num_bits > min(x.shape):
        raise CodeError(f'ITQ needs at least {num_bits} samples and dimensions')
    mean = x.mean(axis=0)
    xc = x - mean
    _, _, vt = randomized_svd(xc, n_components=num_bits, n_iter=4, random_state=seed)
    pca = vt.T
    v = xc @ pca
    rng = np.random.default_rng(seed)
    rot, _ = np.linalg.qr(rng.standard_normal((num_bits, num_bits)))
    for _ in range(iterations):
        b = np.where(v @ rot >= 0, 1.0, -1.0)
        u, _, wt = np.linalg.svd(b.T @ v)
        rot = (u @ wt).T
    proj = (pca @ rot).astype(np.float32)
    return BinaryEncoder('itq', np.zeros(num_bits, np.float32), mean=mean.astype(np.float32),
                         projection=proj)
