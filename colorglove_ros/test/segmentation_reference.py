"""Plain per-pixel references of the segmenter's compiled loops, written from their docstrings
(slow: for small test images only): the border relabelling and the mean shift; and the
junction trim as it was written before its compiled parts (whole-image components, the cells
spread back to pixels with numpy); and, as they were written with OpenCV's connected
components and numpy before their compiled passes (issue 19, nineteenth pass), the blobs'
per-colour components, the glove-like patches, the glove region's reached components, the
multi-colour component test, the tiny image's cell labels and the junction trim's oversized
surfaces; and the static background's match as numpy wrote it before its compiled pass
(twenty-first pass)."""
from __future__ import annotations

import math

import cv2
import numpy as np

from colorglove_ros.core.segmentation.segmenter import _LINEAR_RGB

__all__ = ['relabel_borders_reference', 'mean_shift_reference', 'keep_near_junctions_reference',
           'color_components_reference', 'small_patches_reached_reference',
           'near_or_reaching_reference', 'keep_multicolor_components_reference',
           'cell_labels_reference', 'surface_regions_reference', 'background_match_reference']

_F32 = np.float32


def _borders(labels: np.ndarray, x0: int, x1: int, y0: int, y1: int) -> set[tuple[int, int]]:
    """The pixels of the box [x0, x1) x [y0, y1) with a 4-neighbour of another label inside
    the box."""
    out = set()
    for y in range(y0, y1):
        for x in range(x0, x1):
            for dy, dx in ((-1, 0), (1, 0), (0, -1), (0, 1)):
                ny, nx = y + dy, x + dx
                if y0 <= ny < y1 and x0 <= nx < x1 and labels[ny, nx] != labels[y, x]:
                    out.add((y, x))
                    break
    return out


def relabel_borders_reference(image: np.ndarray, labels: np.ndarray, passes: int,
                              distances: tuple[int, ...], mix_tolerance: float,
                              min_residual: float) -> np.ndarray:
    """``segmenter.relabel_borders``, one pixel at a time: each pass re-decides the border
    pixels (a pixel decided in the last pass whose references all kept their labels and
    sureness keeps its label), from the sure pixels ``distances`` away in the 8 compass
    directions (in the order of ``segmenter._reference_steps``; the nearest colour in float32
    linear RGB, the first of equals; the label's bits break ties of equal distances the same
    way as the compiled loop's sort key)."""
    labels = np.asarray(labels, np.uint8).copy()
    h, w = labels.shape
    if passes < 1 or not distances or min(h, w) < 3:
        return labels
    border = _borders(labels, 0, w, 0, h)
    if not border:
        return labels
    pad = max(distances)
    ys, xs = zip(*border, strict=True)
    y0, y1 = max(min(ys) - pad, 0), min(max(ys) + 1 + pad, h)
    x0, x1 = max(min(xs) - pad, 0), min(max(xs) + 1 + pad, w)
    border = {p for p in border if y0 <= p[0] < y1 and x0 <= p[1] < x1}
    colour = _LINEAR_RGB[image]
    offsets = [(d * sy, d * sx) for d in distances for sy in (-1, 0, 1) for sx in (-1, 0, 1)
               if sy or sx]
    mix2, residual2 = _F32(mix_tolerance ** 2), _F32(min_residual ** 2)
    previous: set[tuple[int, int]] | None = None
    changed: set[tuple[int, int]] = set()
    for k in range(passes):
        if k:
            previous, border = border, _borders(labels, x0, x1, y0, y1)
            moved = (border ^ previous) | changed
        todo = sorted(border)
        if not todo:
            break
        if k:
            todo = [p for p in todo if p not in previous
                    or any((p[0] + dy, p[1] + dx) in moved for dy, dx in offsets)]
            if not todo:
                break

        def sure(y: int, x: int, border: set[tuple[int, int]] = border) -> int | None:
            inside = y0 <= y < y1 and x0 <= x < x1
            return None if not inside or (y, x) in border else int(labels[y, x])

        decided = {}
        for y, x in todo:
            own = colour[y, x]
            refs = []    # (sort key, offset index, label) of the sure references
            for s, (dy, dx) in enumerate(offsets):
                label = sure(y + dy, x + dx)
                if label is None:
                    continue
                d = colour[y + dy, x + dx] - own
                dist = _F32(d[0] * d[0] + d[1] * d[1]) + _F32(d[2] * d[2])
                key = (int(np.array(dist, np.float32).view(np.int32)) & ~0xFF) | label
                refs.append((key, s, label))
            current = int(labels[y, x])
            if not refs:
                continue
            _, nearest, label_a = min(refs)
            if label_a == current:
                continue
            if current != 0:
                others = [r for r in refs if r[2] != label_a]
                second = min(others)[1] if others else nearest
                a = colour[y + offsets[nearest][0], x + offsets[nearest][1]]
                b = colour[y + offsets[second][0], x + offsets[second][1]]
                span, rel = b - a, own - a
                length2 = _F32(_F32(span[0] * span[0] + span[1] * span[1]) + span[2] * span[2])
                along = _F32(_F32(rel[0] * span[0] + rel[1] * span[1]) + rel[2] * span[2])
                off2 = _F32(_F32(rel[0] * rel[0] + rel[1] * rel[1]) + rel[2] * rel[2])
                t = min(max(_F32(along / max(length2, _F32(1e-6))), _F32(0)), _F32(1))
                off2 = _F32(off2 - t * (_F32(2) * along - t * length2))
                if off2 > max(mix2 * length2, residual2):
                    continue
            decided[(y, x)] = label_a
        changed = {p for p, label in decided.items() if label != labels[p]}
        for (y, x), label in decided.items():
            labels[y, x] = label
    return labels


def mean_shift_reference(mask: np.ndarray, bandwidth_factor: float,
                         initial_bandwidth_factor: float, min_pixels: int,
                         start: tuple[tuple[float, float], float] | None = None,
                         max_iterations: int = 50, tolerance: float = 0.05,
                         min_half_size: float = 2.0
                         ) -> tuple[tuple[float, float], float] | None:
    """``crop.mean_shift_crop`` with the window's moments summed over its pixels."""
    m = np.asarray(mask) != 0
    H, W = m.shape
    if m.sum() < min_pixels:
        return None

    def bounds(c: float, h: float, n: int) -> tuple[int, int]:
        return max(math.ceil(c - h), 0), min(math.floor(c + h) + 1, n)

    def moments(cx: float, cy: float, h: float) -> tuple[float, float, float, float, float]:
        x0, x1 = bounds(cx, h, W)
        y0, y1 = bounds(cy, h, H)
        ys, xs = np.nonzero(m[y0:max(y1, y0), x0:max(x1, x0)])
        n = float(len(xs))
        if not n:
            return 0.0, 0.0, 0.0, 0.0, 0.0
        xs, ys = xs.astype(float) + x0, ys.astype(float) + y0
        mx, my = float(xs.sum()) / n, float(ys.sum()) / n
        return (n, mx, my, max(float((xs * xs).sum()) / n - mx * mx, 0.0),
                max(float((ys * ys).sum()) / n - my * my, 0.0))

    cx, cy, h = 0.5 * (W - 1), 0.5 * (H - 1), 0.5 * max(W, H)
    if start is not None:
        (cx, cy), h = start
    factors = (initial_bandwidth_factor, bandwidth_factor) \
        if initial_bandwidth_factor != bandwidth_factor else (bandwidth_factor,)
    for factor in factors:
        for _ in range(max_iterations):
            n, mx, my, vx, vy = moments(cx, cy, h)
            if n < min_pixels:
                return None
            new_h = max(factor * math.sqrt(max(vx, vy)), min_half_size)
            done = abs(mx - cx) < tolerance and abs(my - cy) < tolerance \
                and abs(new_h - h) < tolerance
            cx, cy, h = mx, my, new_h
            if done:
                break
    if moments(cx, cy, h)[0] < min_pixels:
        return None
    return (cx, cy), h


def keep_near_junctions_reference(labels: np.ndarray, num_colors: int, reach: float,
                                  min_pixels: int, max_patch_share: float, step: int,
                                  edges: tuple[bool, bool, bool, bool] | None,
                                  surfaces_only: bool, min_pull: float,
                                  max_window_kept: float) -> np.ndarray:
    """``detection.keep_near_junctions`` with each oversized colour's components found on
    the whole (step) grid and the dropped cells spread back to pixels with numpy."""
    import cv2

    from colorglove_ros.core.segmentation.crop import mean_shift_crop
    from colorglove_ros.core.segmentation.detection import (
        _is_surface,
        _shrinks,
        border_lines,
        junction_mask,
    )

    small = np.ascontiguousarray(labels[::step, ::step])
    junctions = junction_mask(small, num_colors)
    window = mean_shift_crop(junctions, min_pixels=min_pixels)
    if window is None:
        return labels
    crop = mean_shift_crop(small, min_pixels=min_pixels)
    if min_pull > 0 and (crop is None or crop[1] <= min_pull * window[1]):
        return labels
    max_pixels = max_patch_share * (2.0 * window[1]) ** 2
    big_colours = np.flatnonzero(np.bincount(small.ravel(), minlength=num_colors + 1)[1:]
                                 > max_pixels) + 1
    far = cv2.distanceTransform((~junctions).view(np.uint8), cv2.DIST_L2, 3) > (
        reach * window[1])
    drop = np.zeros(small.shape, bool)
    for colour in big_colours:
        n, comp, stats, _ = cv2.connectedComponentsWithStats(
            (small == colour).view(np.uint8), connectivity=8, ltype=cv2.CV_32S)
        big = stats[:, cv2.CC_STAT_AREA] > max_pixels
        big[0] = False
        if edges is not None:   # a pixel on one of the flagged sides
            sides = border_lines(comp, edges)
            reaching = np.zeros(n, bool)
            if sides:
                reaching[np.concatenate(sides)] = True
            big &= reaching
        if edges is not None or surfaces_only:
            for k in np.flatnonzero(big):
                big[k] = _is_surface(small, comp, stats, k)
        drop |= big.take(comp)
    drop &= far
    if not drop.any() or (max_window_kept > 0 and not _shrinks(small, drop, crop,
                                                                max_window_kept, min_pixels)):
        return labels
    h, w = labels.shape
    drop = np.repeat(np.repeat(drop, step, 0), step, 1)[:h, :w]
    out = labels.copy()
    out[drop & np.isin(labels, big_colours)] = 0
    return out


def color_components_reference(labels: np.ndarray, min_pixels: int, num_colors: int
                               ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Each colour 1..``num_colors`` labelled by ``cv2.connectedComponentsWithStats`` inside
    its bounding rectangle: colours, centroids shifted back, areas (the blobs before their
    compiled pass)."""
    counts = np.bincount(labels.ravel(), minlength=num_colors + 1)
    colors, cents, areas = [], [], []
    for c in np.flatnonzero(counts[1:num_colors + 1] >= min_pixels) + 1:
        m = np.ascontiguousarray(labels == c).view(np.uint8)
        bx, by, bw, bh = cv2.boundingRect(m)
        ltype = cv2.CV_16U if bw * bh < np.iinfo(np.uint16).max else cv2.CV_32S
        n, _, stats, centroids = cv2.connectedComponentsWithStats(
            m[by:by + bh, bx:bx + bw], connectivity=8, ltype=ltype)
        for k in range(1, n):
            if stats[k, cv2.CC_STAT_AREA] >= min_pixels:
                colors.append(int(c))
                cents.append(centroids[k] + (bx, by))
                areas.append(int(stats[k, cv2.CC_STAT_AREA]))
    if not colors:
        return np.zeros(0, np.int64), np.zeros((0, 2)), np.zeros(0, np.int64)
    return np.array(colors, np.int64), np.array(cents, float), np.array(areas, np.int64)


def small_patches_reached_reference(labels: np.ndarray, num_colors: int, reached: np.ndarray,
                                    max_area: float, out: np.ndarray) -> None:
    """``out`` |= the single-colour components holding a ``reached`` pixel with at most
    ``max_area`` pixels, each colour labelled by OpenCV on its own (the glove-like patches
    before their compiled pass)."""
    for colour in np.unique(labels[reached]):
        if colour == 0 or colour > num_colors:
            continue
        n, comp, stats, _ = cv2.connectedComponentsWithStats(
            np.ascontiguousarray(labels == colour).view(np.uint8), connectivity=8,
            ltype=cv2.CV_32S)
        patch = np.zeros(n, bool)
        patch[comp[reached]] = True
        patch &= stats[:, cv2.CC_STAT_AREA] <= max_area
        patch[0] = False
        out |= patch.take(comp)


def near_or_reaching_reference(labels: np.ndarray, reach: np.ndarray, near: np.ndarray
                               ) -> np.ndarray:
    """``near`` or in a glove component (OpenCV's, of ``labels`` > 0) holding a ``reach``
    pixel."""
    n, comp = cv2.connectedComponents((labels > 0).view(np.uint8), connectivity=8,
                                      ltype=cv2.CV_32S)
    reached = np.zeros(n, bool)
    reached[comp[reach]] = True
    reached[0] = False
    return near | reached[comp]


def keep_multicolor_components_reference(labels: np.ndarray, min_colors: int, min_share: float,
                                         min_pixels: int, reattach_radius: int,
                                         reattach_max_share: float) -> np.ndarray:
    """``segmenter.keep_multicolor_components`` as written with OpenCV's components and
    numpy's colour counts."""
    glove = labels > 0
    n, comp = cv2.connectedComponents(glove.view(np.uint8), connectivity=8, ltype=cv2.CV_32S)
    if n <= 1:
        return labels
    nl = int(labels.max()) + 1
    glove = np.flatnonzero(glove)
    hist = np.bincount(comp.ravel().take(glove) * nl + labels.ravel().take(glove),
                       minlength=n * nl).reshape(n, nl)[:, 1:]
    size = hist.sum(axis=1, keepdims=True)
    big = (hist >= np.maximum(min_share * size, min_pixels)).sum(axis=1)
    keep = big >= min_colors
    keep[0] = True
    if keep.all():
        return labels
    if reattach_radius > 0 and keep[1:].any():
        kept_table = keep.view(np.uint8).copy()
        kept_table[0] = 0
        kept = kept_table.take(comp)
        width = 2 * int(reattach_radius) + 1
        near = cv2.dilate(kept, cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (width, width)))
        reached = np.zeros(n, dtype=bool)
        reached[comp[near > 0]] = True
        small = size[:, 0] <= reattach_max_share * size[kept_table.view(bool), 0].sum()
        keep |= reached & small
    return labels * keep.view(np.uint8).take(comp)


def cell_labels_reference(counts: np.ndarray, glove_fraction: float,
                          rescue_share: float) -> np.ndarray:
    """``crop.crop_window``'s cell labels from the votes, as written with numpy."""
    glove = counts[1:]
    glove_total = glove.sum(axis=0)
    total = glove_total + counts[0]
    best = np.argmax(glove, axis=0) + 1
    out = np.where((glove_total > 0) & (glove_total >= glove_fraction * total), best, 0)
    if rescue_share > 0.0:
        used = np.bincount(out, minlength=len(counts))
        for k in np.flatnonzero((used[1:] == 0) & (glove.max(axis=1) > 0)):
            share = glove[k] / np.maximum(total, 1)
            top_share = float(share.max())
            if top_share < rescue_share:
                continue
            for cell in np.flatnonzero(share >= max(rescue_share, 0.5 * top_share)):
                if out[cell] > 0 and used[out[cell]] <= 1:
                    continue
                used[out[cell]] -= 1
                out[cell] = k + 1
                used[k + 1] += 1
    return out


def surface_regions_reference(labels: np.ndarray, candidate: np.ndarray, max_pixels: float,
                              sides: np.ndarray, off_image: bool, surfaces: bool,
                              max_glove_share: float) -> np.ndarray:
    """``segmentation_kernel.surface_regions`` with OpenCV: each candidate label's
    components, those on a flagged side of the image (``off_image``), those whose outline (a
    3 x 3 dilation less the region) holds fewer than ``max_glove_share`` glove pixels."""
    rows, cols = labels.shape
    out = np.zeros(labels.shape, bool)
    for colour in np.flatnonzero(candidate):
        n, comp, stats, _ = cv2.connectedComponentsWithStats(
            np.ascontiguousarray(labels == colour).view(np.uint8), connectivity=8,
            ltype=cv2.CV_32S)
        for k in range(1, n):
            if not stats[k, cv2.CC_STAT_AREA] > max_pixels:
                continue
            mine = comp == k
            if off_image:
                lines = [line for on, line in zip(sides, (mine[:, 0], mine[:, -1], mine[0],
                                                          mine[-1]), strict=True) if on]
                if not any(line.any() for line in lines):
                    continue
            if off_image or surfaces:
                ring = cv2.dilate(mine.view(np.uint8), np.ones((3, 3), np.uint8)).view(bool)
                ring &= ~mine
                if not np.count_nonzero(labels[ring]) < max_glove_share * np.count_nonzero(ring):
                    continue
            out |= mine
    return out


def _max_difference(frame: np.ndarray, colour: np.ndarray) -> np.ndarray:
    diff = cv2.absdiff(frame, colour)
    return np.maximum(np.maximum(diff[..., 0], diff[..., 1]), diff[..., 2])


def background_match_reference(model: object, small: np.ndarray) -> np.ndarray | None:
    """``StaticBackground.match`` as it was written in numpy and OpenCV (main before the
    twenty-first pass), on ``model``'s state: the learnt background or None, and the state
    it leaves for ``update``."""
    model._same = model._frame = None
    if not model.enabled:
        return None
    if model._colour is None or model._colour.shape != small.shape:
        model.reset()
        return None
    frame = small.astype(np.float32)
    same = _max_difference(frame, model._colour) <= model.tolerance
    if 1.0 - float(same.mean()) > model.max_changed_share:
        model.reset()
        return None
    model._same, model._frame = same, frame
    learnt = same & (model._matched >= model.frames_needed)
    if model._learnt is not None:
        uncovered = _max_difference(frame, model._learnt) <= model.tolerance
        if model._glove is not None:
            uncovered &= ~model._glove
        learnt |= uncovered
    return learnt if learnt.any() else None
