"""Compiled (numba) kernels of the segmenter's per-pixel loops: the border relabelling's passes
(:func:`segmenter.relabel_borders`), the mean-shift crop, the colour classification, label
counts and boxes, the scene colours' histogram (of the rejected glove pixels in one pass), the
static background's match, the tiny image's cell votes and cell labels,
the colour diversity's box counts, the junction trim's cleared cells and oversized surfaces,
the light estimate's colour sums, the static background's cleared cells, the label borders,
and the connected components (8-connected runs of a row joined by union-find) of the blobs,
the glove-like patches, the glove region's reached components and the multi-colour component
test.

The same arithmetic as the numpy code they replaced (float32 colour distances in the same
order, the same tie rules), as loops over the pixels, so one call replaces the dozens of
whole-array numpy passes per relabelling pass. Every kernel is compiled once and cached on disk
(``cache=True``); :func:`compile_kernels` makes (or loads) them ahead of the first frame and
allows no other signature. Arrays passed in must have the dtypes and layouts in
``_SIGNATURES``.
"""
from __future__ import annotations

import math

import numba
import numpy as np

from colorglove_ros.core.kernel_compile import compile_signatures

__all__ = ['UNSURE', 'relabel_passes', 'mean_shift', 'label_boxes', 'classify',
           'colour_histogram', 'rejected_colour_histogram', 'cell_votes', 'near_or_reaching',
           'box_colour_counts', 'clear_cells', 'colour_blobs', 'small_patches_reached',
           'glove_components', 'colour_components', 'cell_labels', 'colour_sums', 'clear_coarse',
           'surface_regions', 'label_borders', 'region_contacts', 'background_match',
           'compile_kernels']

#: The label of a reference pixel that is not sure (on a label border, or padding).
UNSURE = 255
_NO_KEY = np.int32(np.iinfo(np.int32).max)   # larger than every sort key; label bits 255
_JIT = {'cache': True, 'nogil': True}
@numba.njit(inline='always', **_JIT)
def _on_border(box: np.ndarray, y: int, x: int, pad: int) -> bool:
    """Whether pixel (``y``, ``x``) of ``box`` has a 4-neighbour of another label inside
    ``box`` less its ``pad`` wide frame (pixels outside it are ignored, as an erosion and a
    dilation of that region alone see them)."""
    rows, cols = box.shape
    v = box[y, x]
    return ((y > pad and box[y - 1, x] != v) or (y < rows - pad - 1 and box[y + 1, x] != v)
            or (x > pad and box[y, x - 1] != v) or (x < cols - pad - 1 and box[y, x + 1] != v))


@numba.njit(inline='always', **_JIT)
def _colour(rgb: np.ndarray, table: np.ndarray, i: int, c: int) -> np.float32:
    return table[rgb[i, c]]


@numba.njit(inline='always', **_JIT)
def _decide(current: np.uint8, sure: np.ndarray, rgb: np.ndarray, table: np.ndarray,
            steps: np.ndarray, i: int, mix2: np.float32, residual2: np.float32,
            dists: np.ndarray, bits: np.ndarray, keys: np.ndarray) -> np.uint8:
    """The new label of border pixel ``i`` (label ``current``): that of the sure reference
    (``sure``: the labels, ``UNSURE`` on a border and in the padding) whose linear RGB is
    nearest its own, unless none is sure, or the pixel is glove and its colour no mix of that
    reference's and the nearest other label's."""
    n_steps = len(steps)
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
    if label_a == UNSURE or label_a == current or current == 0:
        return current if label_a == UNSURE else np.uint8(label_a)
    # a glove label keeps its label when its colour is no mix of a and the nearest other b
    second = 0
    second_key = _NO_KEY
    for s in range(n_steps):
        r = i + steps[s]
        key = _NO_KEY if sure[r] == label_a else keys[s]
        if s == 0 or key < second_key:
            second_key = key
            second = s
    if (second_key & 0xFF) == UNSURE:   # no other label: b = a
        second = nearest
    ra, rb = i + steps[nearest], i + steps[second]
    zero = np.float32(0.0)
    length2, along, off2 = zero, zero, zero
    for c in range(3):
        a = _colour(rgb, table, ra, c)
        span = _colour(rgb, table, rb, c) - a
        rel = _colour(rgb, table, i, c) - a
        length2 = length2 + span * span
        along = along + rel * span
        off2 = off2 + rel * rel
    t = along / max(length2, np.float32(1e-6))
    t = min(max(t, zero), np.float32(1.0))
    off2 = off2 - t * (np.float32(2.0) * along - t * length2)
    if off2 > max(mix2 * length2, residual2):
        return current
    return np.uint8(label_a)


@numba.njit(**_JIT)
def relabel_passes(box: np.ndarray, rgb: np.ndarray, table: np.ndarray, border: np.ndarray,
                   steps: np.ndarray, pad: int, passes: int, mix2: np.float32,
                   residual2: np.float32) -> None:
    """The passes of :func:`segmenter.relabel_borders` on its padded box, in place.

    ``box`` (H, W) uint8: the labels, with a ``pad`` wide frame of ``UNSURE``; ``rgb``
    (H * W, 3) uint8: the image's bytes there (0 in the frame); ``table`` (256,) float32: a
    byte's linear value; ``border`` (H, W) uint8: 1 at the first pass's border pixels (it is
    overwritten); ``steps`` (S,) int64: flat offsets to the reference pixels; ``mix2``,
    ``residual2``: the squared mix tolerance and minimal residual.

    Each pass decides its border pixels independently (from the labels before it, in any
    order). A label changes only where the last pass relabelled, so only there and at their
    4-neighbours can a pixel join or leave the border, and the pixels to re-decide are the
    new border pixels and those with such a pixel among their references."""
    rows, cols = box.shape
    size = rows * cols
    flat = box.ravel()
    bflat = border.ravel()
    n_steps = len(steps)
    at = np.empty(size, np.int64)          # this pass's border pixels
    count = 0
    for i in range(size):
        if bflat[i]:
            at[count] = i
            count += 1
    sure = flat.copy()                     # the labels, UNSURE on the border
    for j in range(count):
        sure[at[j]] = UNSURE
    todo = np.empty(size, np.int64)        # ... of them, those to decide
    new = np.empty(size, np.uint8)
    changed = np.empty(size, np.int64)     # the pixels the last pass relabelled
    n_changed = 0
    moved = np.zeros(size, np.uint8)       # relabelled, or joined or left the border
    fresh = np.zeros(size, np.uint8)       # joined the border in this pass
    touched = np.empty(2 * size, np.int64)   # moved: (changed) + (border changed)
    dists = np.empty(n_steps, np.float32)
    bits = dists.view(np.int32)   # non-negative float32 values order like their int32 bits
    keys = np.empty(n_steps, np.int32)
    for k in range(passes):
        n_todo = 0
        n_touched = 0
        if k:
            for j in range(n_changed):
                i = changed[j]
                moved[i] = 1
                touched[n_touched] = i
                n_touched += 1
                for q in (i - cols, i + cols, i - 1, i + 1, i):
                    y, x = q // cols, q % cols
                    if y < pad or y >= rows - pad or x < pad or x >= cols - pad:
                        continue
                    b = 1 if _on_border(box, y, x, pad) else 0
                    if b != bflat[q]:
                        if b:
                            fresh[q] = 1
                        bflat[q] = b
                        moved[q] = 1
                        touched[n_touched] = q
                        n_touched += 1
            kept = 0
            for j in range(count):          # left the border: dropped
                if bflat[at[j]]:
                    at[kept] = at[j]
                    kept += 1
            count = kept
            for j in range(n_touched):      # joined it: added (once)
                q = touched[j]
                sure[q] = UNSURE if bflat[q] else flat[q]
                if fresh[q] == 1:
                    at[count] = q
                    count += 1
                    fresh[q] = 2
        if count == 0:
            break
        for j in range(count):
            i = at[j]
            redo = k == 0 or fresh[i] != 0
            if not redo:
                for s in range(n_steps):
                    if moved[i + steps[s]]:
                        redo = True
                        break
            if redo:
                todo[n_todo] = i
                n_todo += 1
        for j in range(n_touched):
            moved[touched[j]] = 0
            fresh[touched[j]] = 0
        if n_todo == 0:
            break
        for j in range(n_todo):
            new[j] = _decide(flat[todo[j]], sure, rgb, table, steps, todo[j], mix2, residual2,
                             dists, bits, keys)
        n_changed = 0
        for j in range(n_todo):
            i = todo[j]
            if new[j] != flat[i]:
                flat[i] = new[j]
                changed[n_changed] = i
                n_changed += 1


@numba.njit(**_JIT)
def label_borders(labels: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The pixels of the 2-D uint8 ``labels`` with a 4-neighbour (inside the image) of another
    label ((H, W) bool: a 3 x 3 cross's erosion differs from its dilation there) and their
    bounding rectangle ((4,) int64: x, y, width, height as ``cv2.boundingRect``; zeros when
    none)."""
    rows, cols = labels.shape
    border = np.zeros((rows, cols), np.bool_)
    x0, x1, y0, y1 = cols, -1, rows, -1
    for y in range(rows):
        for x in range(cols):
            v = labels[y, x]
            if ((y > 0 and labels[y - 1, x] != v) or (y < rows - 1 and labels[y + 1, x] != v)
                    or (x > 0 and labels[y, x - 1] != v)
                    or (x < cols - 1 and labels[y, x + 1] != v)):
                border[y, x] = True
                x0, x1 = min(x0, x), max(x1, x)
                y0, y1 = min(y0, y), max(y1, y)
    box = np.zeros(4, np.int64)
    if x1 >= 0:
        box[0], box[1], box[2], box[3] = x0, y0, x1 - x0 + 1, y1 - y0 + 1
    return border, box


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


@numba.njit(**_JIT)
def label_boxes(labels: np.ndarray, size: int) -> tuple[np.ndarray, np.ndarray]:
    """How many pixels of the 2-D uint8 ``labels`` (any strides) hold each label (max(``size``,
    largest label + 1),) int64, as ``np.bincount(labels.ravel(), minlength=size)``, and the
    bounding rectangle (x, y, width, height; ``cv2.boundingRect`` of its pixels, zeros when
    none) of each label below min(``size``, 64): (``size``, 4) int64."""
    # four histograms, so that runs of one label do not wait on one counter; a bit per label
    # in each row's and each column's mask of the labels seen there
    partial = np.zeros((4, 256), np.int64)
    rows, cols = labels.shape
    row_seen = np.zeros(rows, np.uint64)
    col_seen = np.zeros(cols, np.uint64)
    quads = cols - cols % 4
    one, none = np.uint64(1), np.uint64(0)
    for y in range(rows):
        seen = none
        for x in range(0, quads, 4):
            v0, v1, v2, v3 = labels[y, x], labels[y, x + 1], labels[y, x + 2], labels[y, x + 3]
            partial[0, v0] += 1
            partial[1, v1] += 1
            partial[2, v2] += 1
            partial[3, v3] += 1
            b0, b1 = one << np.uint64(v0 & 63), one << np.uint64(v1 & 63)
            b2, b3 = one << np.uint64(v2 & 63), one << np.uint64(v3 & 63)
            if (v0 | v1 | v2 | v3) >= 64:    # (a label of 64 or more sets no bit)
                b0, b1 = b0 if v0 < 64 else none, b1 if v1 < 64 else none
                b2, b3 = b2 if v2 < 64 else none, b3 if v3 < 64 else none
            col_seen[x] |= b0
            col_seen[x + 1] |= b1
            col_seen[x + 2] |= b2
            col_seen[x + 3] |= b3
            seen |= b0 | b1 | b2 | b3
        for x in range(quads, cols):
            v = labels[y, x]
            partial[0, v] += 1
            if v < 64:
                col_seen[x] |= one << np.uint64(v)
                seen |= one << np.uint64(v)
        row_seen[y] = seen
    counts = partial[0] + partial[1] + partial[2] + partial[3]
    top = 0
    for v in range(256):
        if counts[v]:
            top = v + 1
    boxes = np.zeros((size, 4), np.int64)
    for v in range(min(size, 64)):
        if not counts[v]:
            continue
        bit = one << np.uint64(v)
        x0, x1, y0, y1 = cols, -1, rows, -1
        for x in range(cols):
            if col_seen[x] & bit:
                x0, x1 = min(x0, x), x
        for y in range(rows):
            if row_seen[y] & bit:
                y0, y1 = min(y0, y), y
        boxes[v, 0], boxes[v, 1], boxes[v, 2], boxes[v, 3] = x0, y0, x1 - x0 + 1, y1 - y0 + 1
    return counts[:max(size, top)].copy(), boxes


@numba.njit(**_JIT)
def classify(image: np.ndarray, lut: np.ndarray, index: np.ndarray, scene: np.ndarray,
             scene_index: np.ndarray) -> np.ndarray:
    """(H, W) uint8: the label ``lut[i]`` of each pixel of the (H, W, 3) uint8 ``image`` (any
    strides), its table index ``i = index[0, r] | index[1, g] | index[2, b]``
    (``color_model.lut_index`` with its per-channel tables ``index`` (3, 256) int32); 0
    where ``scene`` (the scene colours: bool, by the index of ``scene_index`` likewise; empty
    for none) holds the pixel's colour."""
    rows, cols = image.shape[:2]
    out = np.empty((rows, cols), np.uint8)
    with_scene = len(scene) > 0
    for y in range(rows):
        for x in range(cols):
            r, g, b = image[y, x, 0], image[y, x, 1], image[y, x, 2]
            label = lut[index[0, r] | index[1, g] | index[2, b]]
            if with_scene and label and scene[scene_index[0, r] | scene_index[1, g]
                                              | scene_index[2, b]]:
                label = 0
            out[y, x] = label
    return out


@numba.njit(**_JIT)
def colour_histogram(image: np.ndarray, where: np.ndarray, index: np.ndarray,
                     size: int) -> np.ndarray:
    """(``size``,) int64: how many pixels of the (H, W, 3) uint8 ``image`` where ``where``
    ((H, W) bool) holds fall in each quantised colour (``index`` as :func:`classify`'s)."""
    counts = np.zeros(size, np.int64)
    rows, cols = where.shape
    for y in range(rows):
        for x in range(cols):
            if where[y, x]:
                counts[index[0, image[y, x, 0]] | index[1, image[y, x, 1]]
                       | index[2, image[y, x, 2]]] += 1
    return counts


@numba.njit(**_JIT)
def rejected_colour_histogram(image: np.ndarray, lut: np.ndarray, index: np.ndarray,
                              kept: np.ndarray, y0: int, x0: int, scene_index: np.ndarray,
                              size: int) -> np.ndarray:
    """(``size``,) int64: how many pixels of the (H, W, 3) uint8 ``image`` (any strides) that
    :func:`classify` labels glove (``lut``, ``index``; no scene colours) and the 2-D uint8
    ``kept`` (the labels kept, placed at row ``y0``, column ``x0``) does not keep (0 there,
    or outside it) fall in each quantised colour (``scene_index`` as :func:`classify`'s):
    :func:`colour_histogram` of those pixels, without their label image."""
    counts = np.zeros(size, np.int64)
    rows, cols = image.shape[:2]
    kept_rows, kept_cols = kept.shape
    for y in range(rows):
        ky = y - y0
        inside_rows = 0 <= ky < kept_rows
        for x in range(cols):
            r, g, b = image[y, x, 0], image[y, x, 1], image[y, x, 2]
            if not lut[index[0, r] | index[1, g] | index[2, b]]:
                continue
            kx = x - x0
            if inside_rows and 0 <= kx < kept_cols and kept[ky, kx]:
                continue
            counts[scene_index[0, r] | scene_index[1, g] | scene_index[2, b]] += 1
    return counts


@numba.njit(**_JIT)
def cell_votes(labels: np.ndarray, cell_y: np.ndarray, cell_x: np.ndarray, size: int,
               num_labels: int) -> np.ndarray:
    """(``num_labels``, ``size`` * ``size``) int64: how many pixels of each label (below
    ``num_labels``) of the 2-D uint8 ``labels`` (any strides) fall in each cell of a
    ``size`` x ``size`` grid, pixel (y, x) in cell (``cell_y[y]``, ``cell_x[x]``)."""
    votes = np.zeros((num_labels, size * size), np.int64)
    rows, cols = labels.shape
    for y in range(rows):
        row = cell_y[y] * size
        for x in range(cols):
            votes[labels[y, x], row + cell_x[x]] += 1
    return votes


#: :func:`box_colour_counts` bounds the box sums of blocks of this many pixels a side.
_BOUND_BLOCK = 8


@numba.njit(inline='always', **_JIT)
def _rect_sum(sat: np.ndarray, y0: int, y1: int, x0: int, x1: int, by: int, bh: int, bx: int,
              bw: int) -> int:
    """The pixels counted in rows [y0, y1) and columns [x0, x1) of the image, from the
    summed-area table ``sat`` of the rectangle (``bx``, ``by``, ``bw``, ``bh``) holding them
    all."""
    y0, y1 = min(max(y0 - by, 0), bh), min(max(y1 - by, 0), bh)
    x0, x1 = min(max(x0 - bx, 0), bw), min(max(x1 - bx, 0), bw)
    if y0 >= y1 or x0 >= x1:
        return 0
    return sat[y1, x1] - sat[y0, x1] - sat[y1, x0] + sat[y0, x0]


@numba.njit(**_JIT)
def box_colour_counts(labels: np.ndarray, colours: np.ndarray, boxes: np.ndarray, window: int,
                      need: int, counts: np.ndarray) -> None:
    """``counts`` ((H, W) uint8) += 1, for each label of ``colours`` ((K,) int64), at the pixels
    whose ``window`` x ``window`` box (``window // 2`` pixels before the pixel on each axis,
    the rest after; nothing outside the image) holds at least ``need`` pixels of it, in place.
    ``boxes`` ((L, 4) int64): each label's bounding rectangle (x, y, width, height) in the 2-D
    uint8 ``labels``, as :func:`label_boxes` gives it.

    Per label, a summed-area table of its rectangle gives any box's count exactly (whole
    numbers). Over each block of pixels (``_BOUND_BLOCK`` a side, at most the window), the box
    common to all its pixels' boxes bounds their counts from below and the box covering them
    all from above: a block is decided whole when the bounds agree, pixel by pixel only
    where the label's density crosses ``need`` (the edges of its dense zone)."""
    rows, cols = labels.shape
    before = window // 2
    after = window - 1 - before
    block = min(_BOUND_BLOCK, window)
    for c in colours:
        bx, by, bw, bh = boxes[c, 0], boxes[c, 1], boxes[c, 2], boxes[c, 3]
        sat = np.zeros((bh + 1, bw + 1), np.int32)
        for y in range(bh):
            run = 0
            for x in range(bw):
                run += labels[by + y, bx + x] == c
                sat[y + 1, x + 1] = sat[y, x + 1] + run
        x0, x1 = max(bx - after, 0), min(bx + bw + before, cols)
        y0, y1 = max(by - after, 0), min(by + bh + before, rows)
        for ya in range(y0, y1, block):
            yb = min(ya + block, y1)
            for xa in range(x0, x1, block):
                xb = min(xa + block, x1)
                if _rect_sum(sat, yb - 1 - before, ya + after + 1, xb - 1 - before,
                             xa + after + 1, by, bh, bx, bw) >= need:
                    for y in range(ya, yb):
                        for x in range(xa, xb):
                            counts[y, x] += 1
                    continue
                if _rect_sum(sat, ya - before, yb + after, xa - before, xb + after, by, bh,
                             bx, bw) < need:
                    continue
                for y in range(ya, yb):
                    for x in range(xa, xb):
                        if _rect_sum(sat, y - before, y + after + 1, x - before,
                                     x + after + 1, by, bh, bx, bw) >= need:
                            counts[y, x] += 1


@numba.njit(**_JIT)
def clear_cells(labels: np.ndarray, cells: np.ndarray, step: int, cleared: np.ndarray
                ) -> np.ndarray:
    """A copy of the 2-D uint8 ``labels`` with 0 at each pixel (y, x) whose cell
    ``cells[y // step, x // step]`` (bool) is set and whose label ``cleared`` (bool, by label)
    holds."""
    rows, cols = labels.shape
    out = labels.copy()
    for y in range(rows):
        for x in range(cols):
            if cells[y // step, x // step] and cleared[labels[y, x]]:
                out[y, x] = 0
    return out


@numba.njit(**_JIT)
def _find(parent: np.ndarray, i: int) -> int:
    """The root of ``i`` in the union-find forest ``parent`` (its path halved)."""
    while parent[i] != i:
        parent[i] = parent[parent[i]]
        i = parent[i]
    return i


@numba.njit(inline='always', **_JIT)
def _row_values(labels: np.ndarray, y: int, num_colors: int, any_label: bool,
                out: np.ndarray) -> None:
    """Row ``y`` of ``labels`` as :func:`_runs` joins it, into ``out`` (W,) uint8: the label
    where it is a glove label up to ``num_colors``, else 0; with ``any_label`` 1 where it is
    nonzero."""
    cols = labels.shape[1]
    if any_label:
        for x in range(cols):
            out[x] = 1 if labels[y, x] != 0 else 0
    else:
        for x in range(cols):
            v = labels[y, x]
            out[x] = v if v <= num_colors else 0


@numba.njit(**_JIT)
def _runs(labels: np.ndarray, num_colors: int, any_label: bool
          ) -> tuple[int, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The runs along the rows of the 2-D uint8 ``labels`` of one glove label 1..``num_colors``
    (other labels are background), or with ``any_label`` of glove (nonzero) pixels of any
    labels, joined into 8-connected components of one label (or of glove): (the run count n;
    per run its row, first column, end column (exclusive), value (its label, or 1 with
    ``any_label``) and component, the index of the component's first run in raster order)."""
    rows, cols = labels.shape
    row = np.empty(cols, np.uint8)
    size = 0   # the runs, counted first (arrays of their number, not the pixels')
    for y in range(rows):
        _row_values(labels, y, num_colors, any_label, row)
        last = 0
        for x in range(cols):
            w = row[x]
            if w != last and w != 0:
                size += 1
            last = w
    ry = np.empty(size, np.int64)
    rx0 = np.empty(size, np.int64)
    rx1 = np.empty(size, np.int64)
    rv = np.empty(size, np.int64)
    parent = np.empty(size, np.int64)
    n = 0
    prev_lo = prev_hi = 0   # the row above's runs: [prev_lo, prev_hi)
    for y in range(rows):
        _row_values(labels, y, num_colors, any_label, row)
        lo = n
        x = 0
        while x < cols:
            w = row[x]
            if w == 0:
                x += 1
                continue
            start = x
            x += 1
            while x < cols and row[x] == w:
                x += 1
            ry[n], rx0[n], rx1[n], rv[n], parent[n] = y, start, x, w, n
            n += 1
        # 8-connected: a run touches the runs above it from the column before its first to
        # the column after its last
        p = prev_lo
        for r in range(lo, n):
            while p < prev_hi and rx1[p] < rx0[r]:
                p += 1
            q = p
            while q < prev_hi and rx0[q] <= rx1[r]:
                if rv[q] == rv[r]:
                    a, b = _find(parent, q), _find(parent, r)
                    if a < b:
                        parent[b] = a
                    elif b < a:
                        parent[a] = b
                q += 1
        prev_lo, prev_hi = lo, n
    for r in range(n):
        parent[r] = _find(parent, r)
    return n, ry, rx0, rx1, rv, parent


@numba.njit(**_JIT)
def _holding(n: int, ry: np.ndarray, rx0: np.ndarray, rx1: np.ndarray, comp: np.ndarray,
             mask: np.ndarray) -> np.ndarray:
    """(n,) bool by root run: whether the component of :func:`_runs`' runs holds a ``mask``
    ((H, W) bool) pixel."""
    hit = np.zeros(n, np.bool_)
    for r in range(n):
        c = comp[r]
        if not hit[c]:
            y = ry[r]
            for x in range(rx0[r], rx1[r]):
                if mask[y, x]:
                    hit[c] = True
                    break
    return hit


@numba.njit(**_JIT)
def _paint(out: np.ndarray, n: int, ry: np.ndarray, rx0: np.ndarray, rx1: np.ndarray,
           comp: np.ndarray, chosen: np.ndarray) -> None:
    """``out`` ((H, W) bool) set, in place, at the pixels of the components of :func:`_runs`'
    runs whose root run ``chosen`` ((n,) bool) holds."""
    for r in range(n):
        if chosen[comp[r]]:
            y = ry[r]
            for x in range(rx0[r], rx1[r]):
                out[y, x] = True


@numba.njit(**_JIT)
def cell_labels(counts: np.ndarray, glove_fraction: float, rescue_share: float) -> np.ndarray:
    """(C,) int64: the label of each cell of a tiny image from its pixels' votes ``counts``
    ((L, C) int64, label by cell; ``crop.crop_window``'s rules): the most frequent glove
    label (the lowest of equals) where glove labels hold at least ``glove_fraction`` of its
    pixels, else 0; then, with ``rescue_share`` > 0, each glove label that no cell took, in
    ascending order, takes the cells where its share of pixels is at least ``rescue_share``
    and at least half its best share, but the last cell of another label."""
    labels, cells = counts.shape
    out = np.zeros(cells, np.int64)
    total = np.zeros(cells, np.int64)
    used = np.zeros(labels, np.int64)
    for j in range(cells):
        glove_total = 0
        best, best_count = 1, -1
        for k in range(1, labels):
            v = counts[k, j]
            glove_total += v
            if v > best_count:
                best, best_count = k, v
        total[j] = glove_total + counts[0, j]
        if glove_total > 0 and glove_total >= glove_fraction * total[j]:
            out[j] = best
        used[out[j]] += 1
    if rescue_share > 0.0:
        missing = np.zeros(labels, np.bool_)
        for k in range(1, labels):   # (decided before any is given cells)
            if used[k] == 0:
                for j in range(cells):
                    if counts[k, j] > 0:
                        missing[k] = True
                        break
        share = np.empty(cells, np.float64)
        for k in range(1, labels):
            if not missing[k]:
                continue
            top_share = -np.inf
            for j in range(cells):
                share[j] = counts[k, j] / max(total[j], 1)
                top_share = max(top_share, share[j])
            if top_share < rescue_share:
                continue
            need = max(rescue_share, 0.5 * top_share)
            for j in range(cells):
                if share[j] >= need:
                    if out[j] > 0 and used[out[j]] <= 1:
                        continue
                    used[out[j]] -= 1
                    out[j] = k
                    used[k] += 1
    return out


@numba.njit(**_JIT)
def colour_sums(image: np.ndarray, table: np.ndarray, labels: np.ndarray, size: int
                ) -> tuple[np.ndarray, np.ndarray]:
    """How many pixels of the (H, W, 3) uint8 ``image`` each label 1..``size`` - 1 of the
    (H, W) uint8 ``labels`` holds ((``size``,) int64, 0 for label 0) and the sums of their
    channels' ``table`` values ((``size``, 3) float64; ``table`` (256,) float32), added in
    raster order as ``np.bincount`` adds its weights."""
    rows, cols = labels.shape
    counts = np.zeros(size, np.int64)
    sums = np.zeros((size, 3), np.float64)
    for y in range(rows):
        for x in range(cols):
            v = labels[y, x]
            if v == 0 or v >= size:
                continue
            counts[v] += 1
            for c in range(3):
                sums[v, c] += np.float64(table[image[y, x, c]])
    return counts, sums


@numba.njit(**_JIT)
def clear_coarse(labels: np.ndarray, coarse: np.ndarray, rows: np.ndarray, cols: np.ndarray
                 ) -> None:
    """0 at each pixel (y, x) of the 2-D uint8 ``labels`` where the coarser bool mask
    ``coarse`` holds at (``rows[y]``, ``cols[x]``), in place."""
    for y in range(labels.shape[0]):
        row = rows[y]
        for x in range(labels.shape[1]):
            if coarse[row, cols[x]]:
                labels[y, x] = 0


@numba.njit(**_JIT)
def surface_regions(labels: np.ndarray, candidate: np.ndarray, max_pixels: float,
                    sides: np.ndarray, off_image: bool, surfaces: bool,
                    max_glove_share: float) -> np.ndarray:
    """(H, W) bool: the pixels of the 8-connected single-label regions of the 2-D uint8
    ``labels`` whose label ``candidate`` ((256,) bool) holds, larger than ``max_pixels``;
    with ``off_image`` only those with a pixel on a side of the image that ``sides`` ((4,)
    bool: left, right, top, bottom) flags, and with ``off_image`` or ``surfaces`` only those
    whose outline (the pixels of the image outside the region 8-adjacent to it) holds fewer
    than ``max_glove_share`` of its pixels of a glove (nonzero) label."""
    rows, cols = labels.shape
    out = np.zeros((rows, cols), np.bool_)
    n, ry, rx0, rx1, rv, comp = _runs(labels, 255, False)
    area = np.zeros(n, np.int64)
    for r in range(n):
        area[comp[r]] += rx1[r] - rx0[r]
    keep = np.zeros(n, np.bool_)
    for r in range(n):
        c = comp[r]
        keep[c] = candidate[rv[r]] and area[c] > max_pixels
    if off_image:
        touches = np.zeros(n, np.bool_)
        for r in range(n):
            c = comp[r]
            if keep[c] and ((sides[0] and rx0[r] == 0) or (sides[1] and rx1[r] == cols)
                            or (sides[2] and ry[r] == 0) or (sides[3] and ry[r] == rows - 1)):
                touches[c] = True
        for r in range(n):
            keep[r] = keep[r] and touches[r]
    if off_image or surfaces:
        order = np.argsort(comp[:n], kind='mergesort')   # each region's runs together
        seen = np.full((rows, cols), -1, np.int64)   # the region whose outline counted it
        j = 0
        while j < n:
            c = comp[order[j]]
            end = j
            while end < n and comp[order[end]] == c:
                end += 1
            if keep[c]:
                ring = glove = 0
                v = rv[c]
                for q in range(j, end):
                    r = order[q]
                    y = ry[r]
                    for x in range(rx0[r], rx1[r]):
                        for ny in range(max(y - 1, 0), min(y + 2, rows)):
                            for nx in range(max(x - 1, 0), min(x + 2, cols)):
                                if labels[ny, nx] != v and seen[ny, nx] != c:
                                    seen[ny, nx] = c
                                    ring += 1
                                    if labels[ny, nx] != 0:
                                        glove += 1
                keep[c] = glove < max_glove_share * ring
            j = end
    _paint(out, n, ry, rx0, rx1, comp, keep)
    return out


@numba.njit(**_JIT)
def near_or_reaching(labels: np.ndarray, reach: np.ndarray, near: np.ndarray) -> np.ndarray:
    """(H, W) bool: ``near`` ((H, W) bool), or in an 8-connected glove (nonzero) component of
    the 2-D uint8 ``labels`` that holds a ``reach`` pixel ((H, W) bool)."""
    n, ry, rx0, rx1, _, comp = _runs(labels, 255, True)
    out = near.copy()
    _paint(out, n, ry, rx0, rx1, comp, _holding(n, ry, rx0, rx1, comp, reach))
    return out


@numba.njit(**_JIT)
def _component_numbers(n: int, comp: np.ndarray) -> tuple[np.ndarray, int]:
    """Each root run of :func:`_runs`' ``n`` runs numbered 1.. in raster order of the
    components' first runs ((n,) int32, 0 for the other runs), and the components' count."""
    number = np.zeros(n, np.int32)
    count = 0
    for r in range(n):
        if comp[r] == r:
            count += 1
            number[r] = count
    return number, count


@numba.njit(**_JIT)
def colour_components(labels: np.ndarray, num_colors: int) -> tuple[np.ndarray, int]:
    """The 8-connected components of one glove label 1..``num_colors`` of the 2-D uint8
    ``labels`` (other labels are background): each pixel's component ((H, W) int32; 0 the
    background, 1..n numbered by their first pixel in raster order) and their count n."""
    rows, cols = labels.shape
    n, ry, rx0, rx1, _, comp = _runs(labels, num_colors, False)
    number, count = _component_numbers(n, comp)
    out = np.zeros((rows, cols), np.int32)
    for r in range(n):
        k = number[comp[r]]
        y = ry[r]
        for x in range(rx0[r], rx1[r]):
            out[y, x] = k
    return out, count


@numba.njit(**_JIT)
def glove_components(labels: np.ndarray, num_labels: int
                     ) -> tuple[np.ndarray, np.ndarray]:
    """The 8-connected glove (nonzero) components of the 2-D uint8 ``labels``, of any
    labels: each pixel's component ((H, W) int32; 0 the background, 1..n numbered by their
    first pixel in raster order) and how many pixels of each label below ``num_labels``
    (above every label) each holds ((n + 1, ``num_labels``) int64, row 0 zeros)."""
    rows, cols = labels.shape
    n, ry, rx0, rx1, _, comp = _runs(labels, 255, True)
    number, count = _component_numbers(n, comp)
    out = np.zeros((rows, cols), np.int32)
    hist = np.zeros((count + 1, num_labels), np.int64)
    for r in range(n):
        k = number[comp[r]]
        y = ry[r]
        for x in range(rx0[r], rx1[r]):
            out[y, x] = k
            hist[k, labels[y, x]] += 1
    return out, hist


@numba.njit(**_JIT)
def colour_blobs(labels: np.ndarray, num_colors: int, min_pixels: int
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The 8-connected components of each glove label 1..``num_colors`` of the 2-D uint8
    ``labels`` with at least ``min_pixels`` pixels, as ``blobs.color_components`` finds them
    with ``cv2.connectedComponentsWithStats`` inside each label's bounding rectangle: labels
    (B,) int64, centroids (B, 2) float64 (x, y: the mean of the rectangle's coordinates plus
    its corner) and pixel counts (B,) int64, label by label in ascending order and within a
    label in OpenCV's order (by the first 2 x 2 block of the rectangle, in raster order of
    the blocks, that holds a pixel of the component)."""
    rows, cols = labels.shape
    n, ry, rx0, rx1, rv, comp = _runs(labels, num_colors, False)
    bx = np.full(num_colors + 1, cols, np.int64)
    by = np.full(num_colors + 1, rows, np.int64)
    for r in range(n):
        v = rv[r]
        bx[v] = min(bx[v], rx0[r])
        by[v] = min(by[v], ry[r])
    area = np.zeros(n, np.int64)
    sum_x = np.zeros(n, np.int64)
    sum_y = np.zeros(n, np.int64)
    size_key = rows * cols + cols + 1   # above every block index
    first = np.full(n, size_key, np.int64)
    for r in range(n):
        c, v = comp[r], rv[r]
        length = rx1[r] - rx0[r]
        dx, dy = rx0[r] - bx[v], ry[r] - by[v]
        area[c] += length
        sum_x[c] += length * dx + length * (length - 1) // 2
        sum_y[c] += length * dy
        first[c] = min(first[c], (dy // 2) * cols + dx // 2)
    count = 0
    for r in range(n):
        if comp[r] == r and area[r] >= min_pixels:
            count += 1
    keys = np.empty(count, np.int64)
    roots = np.empty(count, np.int64)
    count = 0
    for r in range(n):
        if comp[r] == r and area[r] >= min_pixels:
            keys[count] = rv[r] * size_key + first[r]
            roots[count] = r
            count += 1
    order = np.argsort(keys, kind='mergesort')
    colours = np.empty(count, np.int64)
    centroids = np.empty((count, 2), np.float64)
    areas = np.empty(count, np.int64)
    for j in range(count):
        r = roots[order[j]]
        v = rv[r]
        colours[j] = v
        centroids[j, 0] = float(sum_x[r]) / float(area[r]) + float(bx[v])
        centroids[j, 1] = float(sum_y[r]) / float(area[r]) + float(by[v])
        areas[j] = area[r]
    return colours, centroids, areas


@numba.njit(**_JIT)
def small_patches_reached(labels: np.ndarray, num_colors: int, reached: np.ndarray,
                          max_area: float, out: np.ndarray) -> None:
    """``out`` ((H, W) bool) set, in place, at every pixel of each 8-connected component of
    one glove label 1..``num_colors`` of the 2-D uint8 ``labels`` that holds a ``reached``
    pixel ((H, W) bool) and has at most ``max_area`` pixels."""
    n, ry, rx0, rx1, _, comp = _runs(labels, num_colors, False)
    area = np.zeros(n, np.int64)
    for r in range(n):
        area[comp[r]] += rx1[r] - rx0[r]
    chosen = _holding(n, ry, rx0, rx1, comp, reached)
    for r in range(n):
        chosen[r] = chosen[r] and area[r] <= max_area
    _paint(out, n, ry, rx0, rx1, comp, chosen)


@numba.njit(**_JIT)
def region_contacts(labels: np.ndarray, comp: np.ndarray, count: int, adjacency: np.ndarray
                    ) -> tuple[np.ndarray, np.ndarray]:
    """For each component of ``comp`` ((H, W) int32, 0..``count``, e.g.
    :func:`colour_components` of the 2-D uint8 ``labels``): how many of its pixels'
    4-neighbours inside the image carry another label, and how many of those a label that
    ``adjacency`` ((L, L) bool) says borders its own (both (``count`` + 1,) int64; each pair
    of pixels across a label border counts once for each side, for a side of label 0 in
    entry 0)."""
    rows, cols = labels.shape
    outline = np.zeros(count + 1, np.int64)
    beside = np.zeros(count + 1, np.int64)
    for y in range(rows):
        for x in range(cols):
            a = labels[y, x]
            for dy, dx in ((0, 1), (1, 0)):
                yy, xx = y + dy, x + dx
                if yy >= rows or xx >= cols:
                    continue
                b = labels[yy, xx]
                if a == b:
                    continue
                ca, cb = comp[y, x], comp[yy, xx]
                if adjacency[a, b]:
                    beside[ca] += 1
                    beside[cb] += 1
                if a > 0:
                    outline[ca] += 1
                if b > 0:
                    outline[cb] += 1
    return beside, outline


@numba.njit(inline='always', **_JIT)
def _within(frame: np.ndarray, colour: np.ndarray, j: int, tolerance: np.float32) -> bool:
    """Whether the three channels from flat index ``j`` of float32 ``frame`` and ``colour``
    differ by at most ``tolerance`` each (a NaN matches nothing); no branch, so the loops
    calling it vectorise."""
    return ((abs(frame[j] - colour[j]) <= tolerance)
            & (abs(frame[j + 1] - colour[j + 1]) <= tolerance)
            & (abs(frame[j + 2] - colour[j + 2]) <= tolerance))


@numba.njit(**_JIT)
def background_match(small: np.ndarray, colour: np.ndarray, matched: np.ndarray, needed: int,
                     learnt: np.ndarray, glove: np.ndarray, tolerance: np.float32,
                     frame: np.ndarray, same: np.ndarray, background: np.ndarray) -> int:
    """The static background's match of one coarse frame (``background.StaticBackground.match``)
    in three flat passes: ``frame`` ((H, W, 3) float32) = ``small`` ((H, W, 3) uint8);
    ``same`` ((H, W) bool): every channel of ``frame`` within ``tolerance`` of the running
    ``colour`` (float32 differences, as ``cv2.absdiff``; a NaN colour matches nothing);
    ``background`` ((H, W) bool): ``same`` and ``matched`` ((H, W) int32) at least ``needed``,
    or (with ``learnt``, the colours last learnt, (H, W, 3) float32, or empty) matching
    ``learnt`` and not in ``glove`` ((H, W) bool, or empty). Returns how many pixels are
    ``same``."""
    n = matched.size
    small_flat, colour_flat, frame_flat = small.reshape(-1), colour.reshape(-1), frame.reshape(-1)
    matched_flat, same_flat = matched.reshape(-1), same.reshape(-1)
    back_flat = background.reshape(-1)
    for i in range(3 * n):
        frame_flat[i] = np.float32(small_flat[i])
    count = 0
    for i in range(n):
        ok = _within(frame_flat, colour_flat, 3 * i, tolerance)
        same_flat[i] = ok
        count += ok
        back_flat[i] = ok & (matched_flat[i] >= needed)
    if learnt.shape[0] > 0:
        learnt_flat, glove_flat = learnt.reshape(-1), glove.reshape(-1)
        with_glove = glove.shape[0] > 0
        for i in range(n):
            uncovered = _within(frame_flat, learnt_flat, 3 * i, tolerance)
            if with_glove:
                uncovered = uncovered & ~glove_flat[i]
            back_flat[i] = back_flat[i] | uncovered
    return count


def _array(dtype: object, ndim: int, readonly: bool = True, layout: str = 'C') -> object:
    """An array type, C-contiguous or of any strides (``layout`` 'A'); read-only ones take
    writable arrays too."""
    return numba.types.Array(dtype, ndim, layout, readonly=readonly)


_SIGNATURES = {
    relabel_passes: (_array(numba.uint8, 2, False), _array(numba.uint8, 2),
                     _array(numba.float32, 1), _array(numba.uint8, 2, False),
                     _array(numba.int64, 1), numba.int64, numba.int64, numba.float32,
                     numba.float32),
    mean_shift: (_array(numba.int32, 2), numba.float64, numba.float64, numba.float64,
                 _array(numba.float64, 1), numba.int64, numba.int64, numba.float64,
                 numba.float64),
    label_boxes: (_array(numba.uint8, 2, layout='A'), numba.int64),
    classify: (_array(numba.uint8, 3, layout='A'), _array(numba.uint8, 1),
               _array(numba.int32, 2), _array(numba.boolean, 1), _array(numba.int32, 2)),
    colour_histogram: (_array(numba.uint8, 3, layout='A'), _array(numba.boolean, 2, layout='A'),
                       _array(numba.int32, 2), numba.int64),
    rejected_colour_histogram: (_array(numba.uint8, 3, layout='A'), _array(numba.uint8, 1),
                                _array(numba.int32, 2), _array(numba.uint8, 2, layout='A'),
                                numba.int64, numba.int64, _array(numba.int32, 2), numba.int64),
    cell_votes: (_array(numba.uint8, 2, layout='A'), _array(numba.int64, 1),
                 _array(numba.int64, 1), numba.int64, numba.int64),
    box_colour_counts: (_array(numba.uint8, 2, layout='A'), _array(numba.int64, 1),
                        _array(numba.int64, 2), numba.int64, numba.int64,
                        _array(numba.uint8, 2, False)),
    clear_cells: (_array(numba.uint8, 2), _array(numba.boolean, 2), numba.int64,
                  _array(numba.boolean, 1)),
    colour_blobs: (_array(numba.uint8, 2, layout='A'), numba.int64, numba.int64),
    cell_labels: (_array(numba.int64, 2), numba.float64, numba.float64),
    label_borders: (_array(numba.uint8, 2),),
    surface_regions: (_array(numba.uint8, 2, layout='A'), _array(numba.boolean, 1),
                      numba.float64, _array(numba.boolean, 1), numba.boolean, numba.boolean,
                      numba.float64),
    clear_coarse: (_array(numba.uint8, 2, False, layout='A'), _array(numba.boolean, 2, layout='A'),
                   _array(numba.int64, 1), _array(numba.int64, 1)),
    colour_sums: (_array(numba.uint8, 3, layout='A'), _array(numba.float32, 1),
                  _array(numba.uint8, 2, layout='A'), numba.int64),
    near_or_reaching: (_array(numba.uint8, 2, layout='A'),
                       _array(numba.boolean, 2, layout='A'),
                       _array(numba.boolean, 2, layout='A')),
    glove_components: (_array(numba.uint8, 2, layout='A'), numba.int64),
    colour_components: (_array(numba.uint8, 2, layout='A'), numba.int64),
    region_contacts: (_array(numba.uint8, 2, layout='A'), _array(numba.int32, 2),
                      numba.int64, _array(numba.boolean, 2, layout='A')),
    small_patches_reached: (_array(numba.uint8, 2, layout='A'), numba.int64,
                            _array(numba.boolean, 2, layout='A'), numba.float64,
                            _array(numba.boolean, 2, False, layout='A')),
    background_match: (_array(numba.uint8, 3), _array(numba.float32, 3), _array(numba.int32, 2),
                       numba.int64, _array(numba.float32, 3), _array(numba.boolean, 2),
                       numba.float32, _array(numba.float32, 3, False),
                       _array(numba.boolean, 2, False), _array(numba.boolean, 2, False)),
}


def compile_kernels() -> float:
    """Compile every kernel for its one signature (or load it from numba's on-disk cache)
    and allow no other; returns the seconds it took (none once done in this process)."""
    return compile_signatures(_SIGNATURES)
