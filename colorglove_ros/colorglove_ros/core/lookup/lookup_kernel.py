"""Compiled (numba) kernels of the lookup's passes over the database (:mod:`search`): the
Hamming scan with the histogram of its distances (the top-k cut without a second pass over the
entries), the entries at or below a cut, and the re-rank's two gathers.

The same results as the numpy code they replaced, bit for bit: the Hamming distances and the
query -> candidate sums are integers; the candidate -> query sums add float32 values in numpy's
pairwise order over each candidate's padded row (``np.add.reduce`` along a contiguous row:
eight accumulators in blocks of up to 128, halves above), so the re-rank's distances keep their
bits. The gathers read the database's rows at random (one row per candidate, much larger than
the caches): each asks the memory for the rows :data:`PREFETCH_AHEAD` candidates ahead while it
sums the current one (a prefetch hint: no result depends on it). Every kernel has one
signature (:func:`compile_kernels`, cached on disk) and releases the GIL, so a worker thread
can run one while the caller runs another. :func:`nearest_same_colour` is the per-finger
blend's search (``finger_evidence.finger_scores``) of each entry patch's nearest blob of its
colour: the same distances as numpy's (a subtraction, two products, their sum and ``sqrt``, in
that order) and the first of equal ones.

The blend's small steps on the 10-30 nearest entries (:func:`gaussian_exponents`,
:func:`divide_by_sum`, :func:`usable_blobs_in_tiny_frame`,
:func:`patch_residual_terms`,
:func:`digit_mean_residuals`, :func:`finger_moments`, :func:`constraint_patches`,
:func:`wrists_on_rays`) replace runs of small numpy calls with the same operations in the same
order, so their results keep numpy's bits: products and sums are not fused, each sum runs in
numpy's order (pairwise along a contiguous row, in order across rows), and ``log`` and ``exp``
stay numpy calls (numpy's own vector versions, which libm need not match in the last bit).
"""
from __future__ import annotations

import numba
import numpy as np
from llvmlite import ir
from numba.core import cgutils, types
from numba.extending import intrinsic

from colorglove_ros.core.kernel_compile import compile_signatures

__all__ = ['hamming_histogram', 'at_most', 'query_sums', 'candidate_sums',
           'nearest_same_colour', 'gaussian_exponents', 'divide_by_sum',
           'usable_blobs_in_tiny_frame', 'patch_residual_terms', 'digit_mean_residuals',
           'finger_moments', 'constraint_patches', 'wrists_on_rays', 'compile_kernels',
           'PAIRWISE_BLOCK', 'PREFETCH_AHEAD']

PAIRWISE_BLOCK = 128
"""numpy's pairwise summation block (``PW_BLOCKSIZE``): rows up to this length are summed with
eight accumulators, longer ones split in two halves (multiples of 8)."""

PREFETCH_AHEAD = 2
"""How many candidates ahead the re-rank's gathers ask for a row to be read into the cache."""

_JIT = {'cache': True, 'nogil': True}
_NUMPY_ERRORS = {**_JIT, 'error_model': 'numpy'}
"""The blend's kernels: a division by zero gives infinity or NaN, as numpy's does."""


@intrinsic
def _popcount(typingctx: object, x: object) -> tuple[object, object]:
    """Set bits of a uint64 (LLVM's ``ctpop``: one instruction where the CPU has one)."""
    signature = types.uint64(types.uint64)

    def codegen(context: object, builder: object, sig: object, args: object) -> object:
        return builder.ctpop(args[0])
    return signature, codegen


@intrinsic
def _prefetch(typingctx: object, array: object, index: object) -> tuple[object, object]:
    """Ask for the cache line of ``array[index]`` (1-d, C-contiguous; an index inside it) to be
    read ahead (LLVM's ``prefetch``: a hint, no load, no fault)."""
    signature = types.void(array, index)

    def codegen(context: object, builder: object, sig: object, args: object) -> object:
        array_type = sig.args[0]
        ary = context.make_array(array_type)(context, builder, args[0])
        pointer = cgutils.get_item_pointer(context, builder, array_type, ary, [args[1]],
                                           wraparound=False)
        byte_pointer = ir.IntType(8).as_pointer()
        i32 = ir.IntType(32)
        function = cgutils.get_or_insert_function(
            builder.module, ir.FunctionType(ir.VoidType(), [byte_pointer, i32, i32, i32]),
            'llvm.prefetch.p0')
        # read, temporal locality 0 (used once), data cache
        builder.call(function, [builder.bitcast(pointer, byte_pointer), ir.Constant(i32, 0),
                                ir.Constant(i32, 0), ir.Constant(i32, 1)])
        return context.get_dummy_value()
    return signature, codegen


@numba.njit(**_JIT)
def hamming_histogram(columns: np.ndarray, query: np.ndarray, out: np.ndarray,
                      hist: np.ndarray) -> None:
    """Hamming distances ``out`` (N,) uint8 of one packed query (W,) uint64 to a database of
    per-word columns (W, N) uint64 (codes of at most 255 bits), and their histogram ``hist``
    (at least 64 W + 1 bins): word by word over the whole column (a loop the compiler
    vectorises), then one pass counting into four histograms (no stall on repeated values)."""
    words, n = columns.shape
    if words == 0:
        out[:] = 0
    for w in range(words):
        column = columns[w]
        q = query[w]
        if w == 0:
            for i in range(n):
                out[i] = np.uint8(_popcount(column[i] ^ q))
        else:
            for i in range(n):
                out[i] += np.uint8(_popcount(column[i] ^ q))
    bins = len(hist)
    partial = np.zeros((4, bins), np.int64)
    body = n - n % 4
    for i in range(0, body, 4):
        partial[0, out[i]] += 1
        partial[1, out[i + 1]] += 1
        partial[2, out[i + 2]] += 1
        partial[3, out[i + 3]] += 1
    for i in range(body, n):
        partial[0, out[i]] += 1
    for b in range(bins):
        hist[b] = partial[0, b] + partial[1, b] + partial[2, b] + partial[3, b]


@numba.njit(**_JIT)
def at_most(values: np.ndarray, cut: int, dest: np.ndarray) -> int:
    """Write the indices (ascending) of ``values`` at or below ``cut`` into ``dest`` (at least
    as long as ``values``); returns how many."""
    m = 0
    for i in range(len(values)):
        dest[m] = i
        m += values[i] <= cut
    return m


@numba.njit(**_JIT)
def query_sums(dts: np.ndarray, idx: np.ndarray, row: int, glove_index: np.ndarray,
               out: np.ndarray) -> None:
    """``out[c]`` (uint32) = sum of entry ``idx[c]``'s stored distance transform (row ``row``
    bytes of the flat ``dts``) at the query's glove pixels ``glove_index``; the same pixels of
    entry ``idx[c + PREFETCH_AHEAD]`` are prefetched meanwhile."""
    n = len(idx)
    for c in range(n):
        base = idx[c] * row
        ahead = idx[min(c + PREFETCH_AHEAD, n - 1)] * row
        total = 0
        for j in range(len(glove_index)):
            _prefetch(dts, ahead + glove_index[j])
            total += dts[base + glove_index[j]]
        out[c] = total


@numba.njit(**_JIT)
def _block_sum(table: np.ndarray, keys: np.ndarray, start: int, n: int) -> np.float32:
    """numpy's float32 sum of ``table[keys[start:start + n]]`` for ``n`` up to
    :data:`PAIRWISE_BLOCK`: in order below 8 terms, else eight accumulators then the rest in
    order (keys past the table read its last slot, as ``take(mode='clip')``)."""
    last = len(table) - 1
    if n < 8:
        res = np.float32(0.0)
        for i in range(start, start + n):
            res += table[min(keys[i], last)]
        return res
    r0 = table[min(keys[start], last)]
    r1 = table[min(keys[start + 1], last)]
    r2 = table[min(keys[start + 2], last)]
    r3 = table[min(keys[start + 3], last)]
    r4 = table[min(keys[start + 4], last)]
    r5 = table[min(keys[start + 5], last)]
    r6 = table[min(keys[start + 6], last)]
    r7 = table[min(keys[start + 7], last)]
    i = start + 8
    end = start + n - n % 8
    while i < end:
        r0 += table[min(keys[i], last)]
        r1 += table[min(keys[i + 1], last)]
        r2 += table[min(keys[i + 2], last)]
        r3 += table[min(keys[i + 3], last)]
        r4 += table[min(keys[i + 4], last)]
        r5 += table[min(keys[i + 5], last)]
        r6 += table[min(keys[i + 6], last)]
        r7 += table[min(keys[i + 7], last)]
        i += 8
    res = ((r0 + r1) + (r2 + r3)) + ((r4 + r5) + (r6 + r7))
    while i < start + n:
        res += table[min(keys[i], last)]
        i += 1
    return res


@numba.njit(**_JIT)
def _pairwise(table: np.ndarray, keys: np.ndarray, n: int) -> np.float32:
    """numpy's pairwise sum (in ``table``'s float type) of ``table[keys[:n]]``: blocks of up to
    :data:`PAIRWISE_BLOCK` by :func:`_block_sum`, a longer run split into two halves (the first
    a multiple of 8) whose sums are added; the recursion unrolled on an explicit stack (numba's
    cache does not load recursive functions)."""
    if n <= PAIRWISE_BLOCK:
        return _block_sum(table, keys, 0, n)
    starts = np.empty(64, np.int64)
    sizes = np.empty(64, np.int64)
    phases = np.zeros(64, np.int64)          # 0: left half next, 1: right half next, 2: add
    sums = np.empty(64, table.dtype)
    starts[0], sizes[0], phases[0] = 0, n, 0
    depth, stacked = 1, 0
    while depth:
        top = depth - 1
        start, size = starts[top], sizes[top]
        if size <= PAIRWISE_BLOCK:
            sums[stacked] = _block_sum(table, keys, start, size)
            stacked += 1
            depth -= 1
            continue
        half = size // 2
        half -= half % 8
        if phases[top] == 0:
            phases[top] = 1
            starts[depth], sizes[depth], phases[depth] = start, half, 0
            depth += 1
        elif phases[top] == 1:
            phases[top] = 2
            starts[depth], sizes[depth], phases[depth] = start + half, size - half, 0
            depth += 1
        else:
            stacked -= 1
            sums[stacked - 1] = sums[stacked - 1] + sums[stacked]
            depth -= 1
    return sums[0]


@numba.njit(**_JIT)
def candidate_sums(table: np.ndarray, keys: np.ndarray, idx: np.ndarray, widths: np.ndarray,
                   out: np.ndarray) -> None:
    """``out[c]`` (float64) = the float32 sum, in numpy's pairwise order, of ``table`` at the
    first ``widths[c]`` keys of row ``idx[c]`` of ``keys`` (N, K) uint16: what
    ``table.take(keys[idx[c], :widths[c]], mode='clip').sum()`` gives; the keys of row
    ``idx[c + PREFETCH_AHEAD]`` are prefetched first."""
    n = len(idx)
    line = 64 // keys.itemsize
    for c in range(n):
        ahead = min(c + PREFETCH_AHEAD, n - 1)
        row = keys[idx[ahead]]
        for k in range(0, widths[ahead], line):
            _prefetch(row, k)
        out[c] = np.float32(0.0) + _pairwise(table, keys[idx[c]], widths[c])


@numba.njit(**_JIT)
def _nearest_blob(x: float, y: float, color: int, blob_color: np.ndarray, blob_xy: np.ndarray
                  ) -> tuple[float, int]:
    """The distance from (x, y) to the nearest blob of colour ``color`` and that blob: the
    first of equal distances, the first NaN one (as ``np.argmin``), (infinity, 0) when no blob
    has the colour."""
    best = np.inf
    at = 0
    found = False
    for b in range(len(blob_color)):
        if blob_color[b] != color:
            continue
        dx = x - blob_xy[b, 0]
        dy = y - blob_xy[b, 1]
        d = np.sqrt(dx * dx + dy * dy)
        if np.isnan(d):
            return d, b
        if not found or d < best:
            best = d
            at = b
            found = True
    return best, at


@numba.njit(**_JIT)
def nearest_same_colour(patch_xy: np.ndarray, patch_color: np.ndarray, blob_color: np.ndarray,
                        blob_xy: np.ndarray, distance: np.ndarray, nearest: np.ndarray) -> None:
    """For every patch j of every entry i (``patch_xy`` (K, P, 2), ``patch_color`` (P,)):
    ``distance[i, j]`` the distance to the nearest blob of its colour (``blob_color`` (B,),
    ``blob_xy`` (B, 2)), the first of equal distances, NaN at the first NaN one (as
    ``np.argmin``), infinity when no blob has its colour; ``nearest[i, j]`` that blob (0 when
    none has its colour)."""
    for i in range(distance.shape[0]):
        for j in range(distance.shape[1]):
            distance[i, j], nearest[i, j] = _nearest_blob(patch_xy[i, j, 0], patch_xy[i, j, 1],
                                                          patch_color[j], blob_color, blob_xy)


@numba.njit(**_NUMPY_ERRORS)
def gaussian_exponents(distances: np.ndarray, out: np.ndarray) -> float:
    """The blend's sigma, numpy's mean of ``distances`` (0 + their pairwise sum, over their
    count), and unless sigma <= 0, ``out`` = -(distances / sigma)^2; returns sigma."""
    n = len(distances)
    sigma = (0.0 + _pairwise(distances, np.arange(n), n)) / n
    if not sigma <= 0.0:
        for i in range(n):
            t = distances[i] / sigma
            out[i] = -(t * t)
    return sigma


@numba.njit(**_NUMPY_ERRORS)
def divide_by_sum(values: np.ndarray) -> None:
    """``values`` over their sum (0 + numpy's pairwise sum), in place."""
    n = len(values)
    total = 0.0 + _pairwise(values, np.arange(n), n)
    for i in range(n):
        values[i] = values[i] / total


@numba.njit(**_NUMPY_ERRORS)
def usable_blobs_in_tiny_frame(color: np.ndarray, centroid: np.ndarray, pixels: np.ndarray,
                               scale: float, offset_x: float, offset_y: float,
                               area_scale: float
                               ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The blobs with a finite centroid (B, 2) and a finite positive pixel count, in order,
    mapped into a query's tiny frame: colours, centroids (centroid - offset) / scale and
    areas pixels / area_scale (the caller's scale squared)."""
    m = 0
    keep = np.empty(len(color), np.bool_)
    for b in range(len(color)):
        keep[b] = (np.isfinite(centroid[b, 0]) and np.isfinite(centroid[b, 1])
                   and np.isfinite(pixels[b]) and pixels[b] > 0)
        m += keep[b]
    out_color = np.empty(m, np.int64)
    out_xy = np.empty((m, 2))
    out_pixels = np.empty(m)
    at = 0
    for b in range(len(color)):
        if keep[b]:
            out_color[at] = color[b]
            out_xy[at, 0] = (centroid[b, 0] - offset_x) / scale
            out_xy[at, 1] = (centroid[b, 1] - offset_y) / scale
            out_pixels[at] = pixels[b] / area_scale
            at += 1
    return out_color, out_xy, out_pixels


@numba.njit(**_NUMPY_ERRORS)
def patch_residual_terms(patch_xy: np.ndarray, patch_pixels: np.ndarray,
                         patch_color: np.ndarray, blob_color: np.ndarray, blob_xy: np.ndarray,
                         blob_pixels: np.ndarray, distance: np.ndarray, area_ratio: np.ndarray
                         ) -> None:
    """The per-finger blend's two terms of every patch j of every entry i (``patch_xy``
    (K, P, 2), ``patch_pixels`` (K, P), ``patch_color`` (P,)): ``distance[i, j]`` to the nearest
    blob of its colour (:func:`nearest_same_colour`) and ``area_ratio[i, j]`` = (patch area + 1)
    / (that blob's area + 1), blob 0's where no blob has the colour (the caller takes the
    log, in numpy)."""
    for i in range(distance.shape[0]):
        for j in range(distance.shape[1]):
            d, at = _nearest_blob(patch_xy[i, j, 0], patch_xy[i, j, 1], patch_color[j],
                                  blob_color, blob_xy)
            distance[i, j] = d
            area_ratio[i, j] = (patch_pixels[i, j] + 1.0) / (blob_pixels[at] + 1.0)


@numba.njit(**_NUMPY_ERRORS)
def digit_mean_residuals(distance: np.ndarray, log_area_ratio: np.ndarray, digit: np.ndarray,
                         num_digits: int, cap: float, area_weight: float, out: np.ndarray
                         ) -> None:
    """``out[i, g]`` (K, num_digits): the mean over entry i's patches on digit g (``digit``
    (K, P)) of the residual min(cap, distance + area_weight |log_area_ratio|) (the cap where it
    is not finite), the cap for a digit without patches. numpy's sums: per entry and digit the
    row of P residuals with zeros off the digit, 0 + its pairwise sum (non-negative terms), over
    the count."""
    k, p = distance.shape
    residual = np.empty(p)
    row = np.empty(p)
    order = np.arange(p)
    for i in range(k):
        for j in range(p):
            r = distance[i, j] + area_weight * np.abs(log_area_ratio[i, j])
            residual[j] = min(cap, r) if np.isfinite(r) else cap
        for g in range(num_digits):
            count = 0
            for j in range(p):
                member = digit[i, j] == g
                row[j] = residual[j] if member else 0.0
                count += member
            out[i, g] = (0.0 + _pairwise(row, order, p)) / count if count > 0 else cap


@numba.njit(**_NUMPY_ERRORS)
def finger_moments(poses: np.ndarray, weights: np.ndarray, normalise: bool, first_dof: int,
                   mean: np.ndarray, std: np.ndarray) -> None:
    """Per digit g the weighted mean ``mean[g * D + d]`` and standard deviation ``std`` of
    the finger DOFs ``poses[:, first_dof + g * D + d]`` (K, 26) with the weights column
    ``weights[:, g]`` (K, G; D = (26 - first_dof) / G DOFs a digit): the sums in order over
    the entries from 0 (as ``np.einsum('kg,kgd->gd')``). ``normalise``: each column first
    divided by its sum in order (equal weights 1 / K where the sum is not positive), in place."""
    k, digits = weights.shape
    per = len(mean) // digits
    if normalise:
        for g in range(digits):
            total = weights[0, g]
            for i in range(1, k):
                total += weights[i, g]
            for i in range(k):
                weights[i, g] = weights[i, g] / total if total > 0 else 1.0 / max(k, 1)
    for g in range(digits):
        for d in range(per):
            col = first_dof + g * per + d
            m = 0.0
            for i in range(k):
                m += weights[i, g] * poses[i, col]
            v = 0.0
            for i in range(k):
                e = poses[i, col] - m
                v += weights[i, g] * (e * e)
            mean[g * per + d] = m
            std[g * per + d] = np.sqrt(v)


@numba.njit(**_JIT)
def constraint_patches(entry: int, finger_entries: np.ndarray, patch_vertex: np.ndarray,
                       patch_digit: np.ndarray, patch_xy: np.ndarray, patch_pixels: np.ndarray,
                       patch_color: np.ndarray
                       ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The lookup's projection constraints (``PoseLookup._constraints``): entry ``entry``'s
    visible patches (``patch_vertex`` >= 0), then digit by digit in order where
    ``finger_entries[g]`` is another entry, the nearest's patches on digit g dropped and that
    entry's patches on digit g taken (``finger_entries`` empty: all from ``entry``). Returns
    the patch ids, colours, vertices, tiny-image centroids (M, 2) and areas, by patch id."""
    p = patch_vertex.shape[1]
    source = np.empty(p, np.int64)
    for j in range(p):
        source[j] = entry if patch_vertex[entry, j] >= 0 else -1
    for g in range(len(finger_entries)):
        e = finger_entries[g]
        if e == entry:
            continue
        for j in range(p):
            if patch_digit[entry, j] == g and source[j] == entry:
                source[j] = -1
        for j in range(p):
            if patch_digit[e, j] == g:
                source[j] = e
    m = 0
    for j in range(p):
        m += source[j] >= 0
    ids = np.empty(m, np.int64)
    colors = np.empty(m, np.int64)
    vertices = np.empty(m, np.int64)
    tiny_xy = np.empty((m, 2))
    pixels = np.empty(m)
    at = 0
    for j in range(p):
        e = source[j]
        if e < 0:
            continue
        ids[at] = j
        colors[at] = patch_color[j]
        vertices[at] = patch_vertex[e, j]
        tiny_xy[at, 0] = patch_xy[e, j, 0]
        tiny_xy[at, 1] = patch_xy[e, j, 1]
        pixels[at] = patch_pixels[e, j]
        at += 1
    return ids, colors, vertices, tiny_xy, pixels


@numba.njit(**_NUMPY_ERRORS)
def wrists_on_rays(pixels: np.ndarray, terms: np.ndarray, cx: float, cy: float, fx: float,
                   fy: float, range_factor: float, out: np.ndarray) -> None:
    """``out[i]`` (K, 3): the point at range ``terms[i, 2] * range_factor`` along the ray
    through the undistorted pixel ``pixels[i]`` of a camera (cx, cy, fx, fy), less the anchor's
    offset from the wrist ``terms[i, 7:10]`` (``search._place_wrists``: the ray's direction
    ((u - cx) / fx, (v - cy) / fy, 1) scaled by range / its length)."""
    for i in range(len(out)):
        x = (pixels[i, 0] - cx) / fx
        y = (pixels[i, 1] - cy) / fy
        f = terms[i, 2] * range_factor / np.sqrt(x * x + y * y + 1.0)
        out[i, 0] = x * f - terms[i, 7]
        out[i, 1] = y * f - terms[i, 8]
        out[i, 2] = f - terms[i, 9]


def _array(dtype: object, ndim: int, readonly: bool = True) -> object:
    """A C-contiguous array type (read-only: writable arrays convert to it)."""
    return numba.types.Array(dtype, ndim, 'C', readonly=readonly)


_I1 = _array(numba.intp, 1)
_SIGNATURES = {
    hamming_histogram: (_array(numba.uint64, 2), _array(numba.uint64, 1),
                        _array(numba.uint8, 1, False), _array(numba.int64, 1, False)),
    at_most: (_array(numba.uint8, 1), numba.int64, _array(numba.intp, 1, False)),
    query_sums: (_array(numba.uint8, 1), _I1, numba.int64, _I1,
                 _array(numba.uint32, 1, False)),
    candidate_sums: (_array(numba.float32, 1), _array(numba.uint16, 2), _I1, _I1,
                     _array(numba.float64, 1, False)),
    nearest_same_colour: (_array(numba.float64, 3), _array(numba.int64, 1),
                          _array(numba.int64, 1), _array(numba.float64, 2),
                          _array(numba.float64, 2, False), _array(numba.int64, 2, False)),
    gaussian_exponents: (_array(numba.float64, 1), _array(numba.float64, 1, False)),
    divide_by_sum: (_array(numba.float64, 1, False),),
    usable_blobs_in_tiny_frame: (_array(numba.int64, 1), _array(numba.float64, 2),
                                 _array(numba.float64, 1), numba.float64, numba.float64,
                                 numba.float64, numba.float64),
    patch_residual_terms: (_array(numba.float64, 3), _array(numba.float64, 2),
                           _array(numba.int64, 1), _array(numba.int64, 1),
                           _array(numba.float64, 2), _array(numba.float64, 1),
                           _array(numba.float64, 2, False), _array(numba.float64, 2, False)),
    digit_mean_residuals: (_array(numba.float64, 2), _array(numba.float64, 2),
                           _array(numba.int64, 2), numba.int64, numba.float64, numba.float64,
                           _array(numba.float64, 2, False)),
    finger_moments: (_array(numba.float64, 2), _array(numba.float64, 2, False), numba.boolean,
                     numba.int64, _array(numba.float64, 1, False),
                     _array(numba.float64, 1, False)),
    constraint_patches: (numba.int64, _array(numba.int64, 1), _array(numba.int32, 2),
                         _array(numba.int8, 2), _array(numba.float32, 3),
                         _array(numba.float32, 2), _array(numba.uint8, 1)),
    wrists_on_rays: (_array(numba.float64, 2), _array(numba.float64, 2), numba.float64,
                     numba.float64, numba.float64, numba.float64, numba.float64,
                     _array(numba.float64, 2, False)),
}


def compile_kernels() -> float:
    """Compile every kernel for its one signature (or load it from numba's on-disk cache) and
    allow no other; returns the seconds it took."""
    return compile_signatures(_SIGNATURES)
