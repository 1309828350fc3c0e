"""Compiled (numba) kernels of the segmenter's per-pixel loops: the border relabelling's passes
(:func:`segmenter.relabel_borders`).

The same arithmetic as the numpy code they replaced (float32 colour distances in the same
order, the same tie rules), as loops over the pixels, so one call replaces the dozens of
whole-array numpy passes per relabelling pass. Every kernel is compiled once and cached on disk
(``cache=True``); :func:`compile_kernels` makes (or loads) them ahead of the first frame and
allows no other signature. Arrays passed in must be C-contiguous, of the dtypes in
``_SIGNATURES``.
"""
from __future__ import annotations

import math
import time

import numba
import numpy as np

__all__ = ['UNSURE', 'relabel_passes', 'mean_shift', 'compile_kernels']

#: The label of a reference pixel that is not sure (on a label border, or padding).
UNSURE = 255
_NO_KEY = np.int32(np.iinfo(np.int32).max)   # larger than every sort key; label bits 255
_JIT = {'cache': True, 'nogil': True}


@numba.njit(**_JIT)
def _inner_borders(box: np.ndarray, border: np.ndarray, pad: int) -> None:
    """``border`` (box's shape, uint8) 1 at the pixels of ``box`` less its ``pad`` wide frame
    with a 4-neighbour of another label inside that region (pixels outside it are ignored, as
    an erosion and a dilation of the region alone see them), else 0."""
    rows, cols = box.shape
    for y in range(pad, rows - pad):
        for x in range(pad, cols - pad):
            v = box[y, x]
            b = ((y > pad and box[y - 1, x] != v) or (y < rows - pad - 1 and box[y + 1, x] != v)
                 or (x > pad and box[y, x - 1] != v)
                 or (x < cols - pad - 1 and box[y, x + 1] != v))
            border[y, x] = 1 if b else 0


@numba.njit(**_JIT)
def _colour(rgb: np.ndarray, table: np.ndarray, i: int, c: int) -> np.float32:
    return table[rgb[i, c]]


@numba.njit(**_JIT)
def relabel_passes(box: np.ndarray, rgb: np.ndarray, table: np.ndarray, border: np.ndarray,
                   steps: np.ndarray, pad: int, passes: int, mix2: np.float32,
                   residual2: np.float32) -> None:
    """The passes of :func:`segmenter.relabel_borders` on its padded box, in place.

    ``box`` (H, W) uint8: the labels, with a ``pad`` wide frame of ``UNSURE``; ``rgb``
    (H * W, 3) uint8: the image's bytes there (0 in the frame); ``table`` (256,) float32: a
    byte's linear value; ``border`` (H, W) uint8: 1 at the first pass's border pixels (it is
    overwritten); ``steps`` (S,) int64: flat offsets to the reference pixels; ``mix2``,
    ``residual2``: the squared mix tolerance and minimal residual."""
    rows, cols = box.shape
    size = rows * cols
    flat = box.ravel()
    bflat = border.ravel()
    n_steps = len(steps)
    sure = np.empty(size, np.uint8)
    was = np.zeros(size, np.uint8)
    moved = np.zeros(size, np.uint8)
    changed = np.zeros(size, np.uint8)   # the pixels the last pass relabelled
    at = np.empty(size, np.int64)
    dists = np.empty(n_steps, np.float32)
    bits = dists.view(np.int32)   # non-negative float32 values order like their int32 bits
    keys = np.empty(n_steps, np.int32)
    two = np.float32(2.0)
    tiny = np.float32(1e-6)
    zero, one = np.float32(0.0), np.float32(1.0)
    for k in range(passes):
        if k:
            was[:] = bflat
            _inner_borders(box, border, pad)
            for i in range(size):
                moved[i] = 1 if (bflat[i] != was[i] or changed[i]) else 0
        count = 0
        for i in range(size):
            if bflat[i]:
                at[count] = i
                count += 1
        if count == 0:
            break
        sure[:] = flat
        for j in range(count):
            sure[at[j]] = UNSURE
        if k:
            # a pixel decided in the last pass whose references kept their labels and
            # sureness would be decided the same again: it keeps its label
            kept = 0
            for j in range(count):
                i = at[j]
                redo = was[i] == 0
                if not redo:
                    for s in range(n_steps):
                        if moved[i + steps[s]]:
                            redo = True
                            break
                if redo:
                    at[kept] = i
                    kept += 1
            count = kept
            if count == 0:
                break
        changed[:] = 0
        for j in range(count):
            i = at[j]
            o0, o1, o2 = (_colour(rgb, table, i, 0), _colour(rgb, table, i, 1),
                          _colour(rgb, table, i, 2))
            # sort keys: the float32 distance's bits with the label in the lowest 8 bits
            best = _NO_KEY
            nearest = 0
            for s in range(n_steps):
                r = i + steps[s]
                d0 = _colour(rgb, table, r, 0) - o0
                d1 = _colour(rgb, table, r, 1) - o1
                d2 = _colour(rgb, table, r, 2) - o2
                dist = d0 * d0 + d1 * d1
                dists[s] = dist + d2 * d2
                label = sure[r]
                key = _NO_KEY if label == UNSURE else (bits[s] & ~0xFF) | np.int32(label)
                keys[s] = key
                if key < best:
                    best = key
                    nearest = s
            label_a = best & 0xFF
            current = flat[i]
            new = current if label_a == UNSURE else np.uint8(label_a)
            if new != current and current != 0:
                # keep a glove label whose colour is no mix of a and the nearest other b
                second = 0
                second_key = _NO_KEY if sure[i + steps[0]] == label_a else keys[0]
                for s in range(1, n_steps):
                    key = _NO_KEY if sure[i + steps[s]] == label_a else keys[s]
                    if key < second_key:
                        second_key = key
                        second = s
                if (second_key & 0xFF) == UNSURE:   # no other label: b = a
                    second = nearest
                ra, rb = i + steps[nearest], i + steps[second]
                length2, along, off2 = zero, zero, zero
                for c in range(3):
                    a = _colour(rgb, table, ra, c)
                    span = _colour(rgb, table, rb, c) - a
                    rel = _colour(rgb, table, i, c) - a
                    length2 = length2 + span * span
                    along = along + rel * span
                    off2 = off2 + rel * rel
                t = along / max(length2, tiny)
                t = min(max(t, zero), one)
                off2 = off2 - t * (two * along - t * length2)
                if off2 > max(mix2 * length2, residual2):
                    new = current
            if new != current:
                changed[i] = 1
                flat[i] = new


@numba.njit(**_JIT)
def _window_bounds(c: float, h: float, n: int) -> tuple[int, int]:
    """Integer index range [lo, hi) of pixel centres within c +- h, clipped to [0, n)."""
    return max(int(math.ceil(c - h)), 0), min(int(math.floor(c + h)) + 1, n)


@numba.njit(**_JIT)
def _moments(sat: np.ndarray, x0: int, x1: int, y0: int, y1: int
             ) -> tuple[float, float, float, float, float]:
    """Count, means and variances of the mask pixels in the box [x0, x1) x [y0, y1) from
    the mask's summed-area table ``sat``. Every sum is of whole numbers (exact in float64,
    in any order), so these are the numpy code's values to the bit."""
    n = float(sat[y1, x1] - sat[y0, x1] - sat[y1, x0] + sat[y0, x0])
    if n <= 0.0:
        return 0.0, 0.0, 0.0, 0.0, 0.0
    sx = sxx = 0.0
    below = sat[y1, x0] - sat[y0, x0]
    for x in range(x0, x1):
        above = sat[y1, x + 1] - sat[y0, x + 1]
        count = float(above - below)
        below = above
        sx += count * x
        sxx += count * (float(x) * float(x))
    sy = syy = 0.0
    left = sat[y0, x1] - sat[y0, x0]
    for y in range(y0, y1):
        right = sat[y + 1, x1] - sat[y + 1, x0]
        count = float(right - left)
        left = right
        sy += count * y
        syy += count * (float(y) * float(y))
    mx, my = sx / n, sy / n
    return n, mx, my, max(sxx / n - mx * mx, 0.0), max(syy / n - my * my, 0.0)


@numba.njit(**_JIT)
def mean_shift(sat: np.ndarray, cx: float, cy: float, h: float, factors: np.ndarray,
               min_pixels: int, max_iterations: int, tolerance: float, min_half_size: float
               ) -> tuple[bool, float, float, float]:
    """The iterations of :func:`crop.mean_shift_crop` on the mask's summed-area table ``sat``
    ((H + 1, W + 1) int32) from the window ((``cx``, ``cy``), ``h``), with each bandwidth
    factor of ``factors`` in turn: (found, cx, cy, half)."""
    rows, cols = sat.shape[0] - 1, sat.shape[1] - 1
    for factor in factors:
        for _ in range(max_iterations):
            x0, x1 = _window_bounds(cx, h, cols)
            y0, y1 = _window_bounds(cy, h, rows)
            n, mx, my, vx, vy = _moments(sat, x0, x1, y0, y1)
            if n < min_pixels:
                return False, cx, cy, h
            new_h = max(factor * math.sqrt(max(vx, vy)), min_half_size)
            done = (abs(mx - cx) < tolerance and abs(my - cy) < tolerance
                    and abs(new_h - h) < tolerance)
            cx, cy, h = mx, my, new_h
            if done:
                break
    x0, x1 = _window_bounds(cx, h, cols)
    y0, y1 = _window_bounds(cy, h, rows)
    n = _moments(sat, x0, x1, y0, y1)[0]
    return n >= min_pixels, cx, cy, h


def _array(dtype: object, ndim: int, readonly: bool = True) -> object:
    """A C-contiguous array type (read-only: writable arrays convert to it)."""
    return numba.types.Array(dtype, ndim, 'C', readonly=readonly)


_SIGNATURES = {
    relabel_passes: (_array(numba.uint8, 2, False), _array(numba.uint8, 2),
                     _array(numba.float32, 1), _array(numba.uint8, 2, False),
                     _array(numba.int64, 1), numba.int64, numba.int64, numba.float32,
                     numba.float32),
}


def compile_kernels() -> float:
    """Compile every kernel for its one signature (or load it from numba's on-disk cache)
    and allow no other; returns the seconds it took (about none once done in this
    process)."""
    started = time.perf_counter()
    for kernel, signature in _SIGNATURES.items():
        if not kernel.signatures:
            kernel.compile(signature)
            kernel.disable_compile()
    return time.perf_counter() - started
