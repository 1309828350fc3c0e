"""Hausdorff-like distance between tiny label images (Wang and Popovic 2009, section 4.4)."""
from __future__ import annotations

import math

import cv2
import numpy as np

from colorglove_ros.core.conventions import NUM_COLORS, TINY_SIZE
from colorglove_ros.core.errors import ColorGloveError

__all__ = [
    'ABSENT_PENALTY', 'DT_SCALE', 'DistanceError',
    'distance_transforms', 'distance_transforms_batch', 'quantize_dts', 'dequantize_dts',
    'directed_distance', 'image_distance', 'QueryDistance',
]

ABSENT_PENALTY = float(math.hypot(TINY_SIZE, TINY_SIZE))
"""Distance (px) charged to a pixel whose colour is absent from the other image: the image
diagonal, 40*sqrt(2) = 56.57 px, just above the largest possible in-image distance
(39*sqrt(2) = 55.15 px). Distance transforms are clipped to it, so every distance is bounded."""
DT_SCALE = 4.0
"""Stored distance transforms are ``uint8(round(dt * DT_SCALE))``: 0.25 px steps, error
<= 0.125 px, ABSENT_PENALTY -> 226 fits in a byte."""


_COLORS = np.arange(1, NUM_COLORS + 1, dtype=np.uint8)[:, None, None]


class DistanceError(ColorGloveError):
    """A label image has the wrong shape, type or colour values."""


def _check_labels(labels: np.ndarray, batch: bool) -> np.ndarray:
    labels = np.asarray(labels)
    want = 3 if batch else 2
    if labels.ndim != want or labels.shape[-2:] != (TINY_SIZE, TINY_SIZE):
        raise DistanceError(f'expected {"(N, " if batch else "("}{TINY_SIZE}, {TINY_SIZE}) '
                            f'label image(s), got shape {labels.shape}')
    if labels.dtype != np.uint8:
        if not np.issubdtype(labels.dtype, np.integer):
            raise DistanceError(f'label images must be integer, got {labels.dtype}')
        labels = labels.astype(np.uint8)
    if labels.size and int(labels.max()) > NUM_COLORS:
        raise DistanceError(f'label value {int(labels.max())} > NUM_COLORS={NUM_COLORS}')
    return labels


_DT_ALIGN = 64
"""Byte alignment of the planes OpenCV's precise distance transform writes: its result
differs in the last bit with the output's address (vector loops peel a misaligned head), and
NumPy aligns a fresh array to 16 bytes only, so the same label image could give other
distances (and, through the re-rank, other poses) from run to run."""


def _aligned_dts() -> np.ndarray:
    """An uninitialised (NUM_COLORS, 40, 40) float32 array starting on a
    :data:`_DT_ALIGN`-byte boundary (each 6400-byte plane does too)."""
    nbytes = NUM_COLORS * TINY_SIZE * TINY_SIZE * 4
    raw = np.empty(nbytes + _DT_ALIGN, np.uint8)
    start = -raw.ctypes.data % _DT_ALIGN
    return raw[start:start + nbytes].view(np.float32).reshape(NUM_COLORS, TINY_SIZE, TINY_SIZE)


def _dts_into(labels: np.ndarray, out: np.ndarray) -> None:
    """Fill ``out`` (NUM_COLORS, 40, 40) float32 with clipped per-colour Euclidean DTs (the
    same bits whatever ``out``'s address: computed in aligned planes, :data:`_DT_ALIGN`)."""
    present = np.bincount(labels.ravel(), minlength=NUM_COLORS + 1)
    masks = (labels[None] != _COLORS).view(np.uint8)      # all ten masks in one pass
    work = out if out.ctypes.data % _DT_ALIGN == 0 and out.flags.c_contiguous \
        else _aligned_dts()
    for c in range(1, NUM_COLORS + 1):
        if present[c] == 0:
            work[c - 1] = ABSENT_PENALTY
            continue
        cv2.distanceTransform(masks[c - 1], cv2.DIST_L2, cv2.DIST_MASK_PRECISE, dst=work[c - 1])
    np.minimum(work, ABSENT_PENALTY, out=out)


def distance_transforms(labels: np.ndarray) -> np.ndarray:
    """Per-colour Euclidean distance transforms of one (40, 40) label image.

    Returns (NUM_COLORS, 40, 40) float32: ``dts[c-1, y, x]`` is the distance (px) from
    (x, y) to the nearest pixel of colour c, clipped to :data:`ABSENT_PENALTY` (which is
    also the value everywhere when colour c is absent)."""
    labels = _check_labels(labels, batch=False)
    out = _aligned_dts()
    _dts_into(labels, out)
    return out


def distance_transforms_batch(labels: np.ndarray) -> np.ndarray:
    """:func:`distance_transforms` of (N, 40, 40) label images: (N, NUM_COLORS, 40, 40)."""
    labels = _check_labels(labels, batch=True)
    out = np.empty((len(labels), NUM_COLORS, TINY_SIZE, TINY_SIZE), np.float32)
    for i in range(len(labels)):
        _dts_into(labels[i], out[i])
    return out


def quantize_dts(dts: np.ndarray) -> np.ndarray:
    """Distance transforms to the stored uint8 form (see :data:`DT_SCALE`)."""
    return np.rint(np.asarray(dts, np.float32) * DT_SCALE).astype(np.uint8)


def dequantize_dts(qdts: np.ndarray) -> np.ndarray:
    """Stored uint8 distance transforms back to float32 pixels."""
    return np.asarray(qdts, np.float32) * np.float32(1.0 / DT_SCALE)


def directed_distance(a: np.ndarray, b: np.ndarray) -> float:
    """Mean over glove pixels of ``a`` of the distance to the nearest same-colour pixel of
    ``b`` (absent colour: :data:`ABSENT_PENALTY`). If ``a`` has no glove pixels the result
    is 0 when ``b`` has none either and ABSENT_PENALTY otherwise."""
    a = _check_labels(a, batch=False)
    b = _check_labels(b, batch=False)
    ys, xs = np.nonzero(a)
    if len(ys) == 0:
        return 0.0 if not b.any() else ABSENT_PENALTY
    dts = distance_transforms(b)
    return float(dts[a[ys, xs].astype(np.intp) - 1, ys, xs].astype(np.float64).mean())


def image_distance(a: np.ndarray, b: np.ndarray) -> float:
    """Symmetric Hausdorff-like distance (px): mean of the two directed distances."""
    return 0.5 * (directed_distance(a, b) + directed_distance(b, a))


class QueryDistance:
    """One query image against many candidates, vectorised.

    The query's distance transforms are computed once; candidates are given as label
    images plus their (stored, possibly quantised) distance transforms."""

    def __init__(self, labels: np.ndarray, dts: np.ndarray | None = None) -> None:
        self.labels = _check_labels(labels, batch=False)
        if dts is None:
            self.dts = _aligned_dts()
            _dts_into(self.labels, self.dts)
        else:
            self.dts = np.asarray(dts, np.float32)
        if self.dts.shape != (NUM_COLORS, TINY_SIZE, TINY_SIZE):
            raise DistanceError(f'query distance transforms have shape {self.dts.shape}')
        npix = TINY_SIZE * TINY_SIZE
        flat = self.labels.ravel()
        pix = np.flatnonzero(flat)
        self._qidx = (flat[pix].astype(np.intp) - 1) * npix + pix   # into (10*1600,) DTs
        self._table: np.ndarray | None = None     # built by to_many only

    def _lookup_table(self) -> np.ndarray:
        """Table indexed by label * npix + pixel; label 0 (background) reads zeros."""
        if self._table is None:
            npix = TINY_SIZE * TINY_SIZE
            self._table = np.concatenate([np.zeros(npix, np.float32), self.dts.ravel()])
        return self._table

    @property
    def glove_index(self) -> np.ndarray:
        """Query glove pixels as indices into the flattened (NUM_COLORS*40*40) DTs."""
        return self._qidx

    @property
    def num_pixels(self) -> int:
        """Glove pixels in the query."""
        return len(self._qidx)

    def to_many(self, labels: np.ndarray, dts: np.ndarray | None = None) -> np.ndarray:
        """Symmetric distances (K,) float64 to candidate label images (K, 40, 40).

        ``dts`` are the candidates' distance transforms, (K, NUM_COLORS, 40, 40), either
        float32 pixels or uint8 quantised with :data:`DT_SCALE`; computed here if None."""
        labels = _check_labels(labels, batch=True)
        k = len(labels)
        if dts is None:
            dts = distance_transforms_batch(labels)
        dts = np.asarray(dts)
        if dts.shape != (k, NUM_COLORS, TINY_SIZE, TINY_SIZE):
            raise DistanceError(f'candidate distance transforms have shape {dts.shape}')
        scale = 1.0 / DT_SCALE if dts.dtype == np.uint8 else 1.0
        npix = TINY_SIZE * TINY_SIZE
        flat = labels.reshape(k, npix)
        # candidate -> query: read the query's DT at each candidate glove pixel.
        idx = flat.astype(np.intp)
        idx *= npix
        idx += np.arange(npix, dtype=np.intp)
        cand_sum = self._lookup_table()[idx].sum(axis=1, dtype=np.float64)
        cand_cnt = np.count_nonzero(flat, axis=1)
        # query -> candidate: read each candidate's DT at the query glove pixels.
        if len(self._qidx):
            q_sum = dts.reshape(k, -1)[:, self._qidx].sum(axis=1, dtype=np.float64) * scale
        else:
            q_sum = np.zeros(k)
        nq = len(self._qidx)
        with np.errstate(invalid='ignore', divide='ignore'):
            d_cq = np.where(cand_cnt > 0, cand_sum / np.maximum(cand_cnt, 1),
                            ABSENT_PENALTY if nq else 0.0)
            d_qc = (q_sum / nq) if nq else np.where(cand_cnt > 0, ABSENT_PENALTY, 0.0)
        return 0.5 * (d_cq + d_qc)
