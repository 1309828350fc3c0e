"""Database lookup: Hamming scan of binary codes, exact re-rank, Gaussian-weighted pose blend."""
from __future__ import annotations

import time
from concurrent.futures import ThreadPoolExecutor

import numpy as np

from colorglove_ros.core.camera import PinholeCamera
from colorglove_ros.core.conventions import DEFAULT_HAND_LENGTH_M
from colorglove_ros.core.errors import ColorGloveError
from colorglove_ros.core.geometry import rotvec_to_quaternion
from colorglove_ros.core.lookup.blend import blend_poses_with_quaternions, blend_weights
from colorglove_ros.core.lookup.codes import HAMMING_BLOCK, QueryEncoder, hamming_distances
from colorglove_ros.core.lookup.database import PoseDatabase
from colorglove_ros.core.lookup.distance import ABSENT_PENALTY, DT_SCALE, QueryDistance
from colorglove_ros.core.lookup.finger_evidence import (
    FingerEvidenceConfig,
    FingerEvidenceError,
    finger_blend,
    finger_scores,
    patch_digits,
    weighted_fingers,
)
from colorglove_ros.core.lookup.types import LookupResult, Neighbours, ProjectionConstraints
from colorglove_ros.core.segmentation.crop import tiny_to_full

__all__ = ['SearchError', 'PoseLookup', 'DEFAULT_THREADS',
           'top_k_with_ties', 'estimate_global_pose']

DEFAULT_THREADS = 1
"""Threads of a :class:`PoseLookup`'s re-rank: the caller only (2: the caller and one worker,
whose hand-off and wait cost more than its share of the compiled gathers on a busy machine)."""


_NO_FINGER_ENTRIES = np.zeros(0, np.int64)


class SearchError(ColorGloveError):
    """Bad lookup input (image shape, empty query, camera)."""


def top_k_with_ties(values: np.ndarray, k: int) -> np.ndarray:
    """Indices (ascending) of the k smallest ``values`` plus every index tied with the k-th.

    Small unsigned integer values (Hamming distances) find the cut by counting instead of
    ``argpartition`` (several times slower on 100k entries): a strided sample gives a value
    that about 2k + 400 entries are expected to be at or below, one pass keeps those, and a
    histogram of the kept entries gives the exact cut; if the guess keeps fewer than k
    entries, the histogram is taken over all values."""
    values = np.asarray(values)
    n = len(values)
    if k >= n:
        return np.arange(n)
    if values.dtype.kind == 'u' and values.dtype.itemsize <= 2:
        step = max(1, n // 2048)
        sample = values[::step]
        j = min(len(sample) - 1, (2 * k) // step + 8)
        guess = int(np.partition(sample, j)[j])
        sel = np.flatnonzero(values <= guess)
        if len(sel) < k:
            sel = np.arange(n)
        sub = values[sel]
        cum = np.cumsum(np.bincount(sub))
        cut = int(np.searchsorted(cum, k))      # smallest value with >= k entries at or below
        return sel[sub <= cut]
    cut = values[np.argpartition(values, k - 1)[:k]].max()
    return np.flatnonzero(values <= cut)


def _standard_vertex_link(database: PoseDatabase) -> np.ndarray:
    """Vertex -> link table of the standard mesh of ``database``'s hand length."""
    from colorglove_ros.core.hand.mesh import build_hand_mesh
    from colorglove_ros.core.hand.model import HandModel

    length = float(database.meta.get('build', {}).get('hand_length_m', DEFAULT_HAND_LENGTH_M))
    return build_hand_mesh(HandModel(length)).vertex_link


def _entry_place_terms(entry_global: np.ndarray, entry_crop: np.ndarray,
                       render_camera: dict, anchor_local: np.ndarray | None) -> np.ndarray:
    """The query-independent part of :func:`estimate_global_pose`, (k, 10) per entry: the
    anchor's tiny-image x, y; its range (distance from the camera) times the crop scale; the
    hand rotation as a quaternion (x, y, z, w); and the anchor's offset from the wrist in the
    camera frame, R_e anchor_local (zero without an anchor)."""
    g = np.asarray(entry_global, np.float64).reshape(-1, 6)
    crop = np.asarray(entry_crop, np.float64).reshape(-1, 3)
    quats = rotvec_to_quaternion(g[:, 3:6])
    offset = np.zeros((len(g), 3))
    if anchor_local is not None:
        local = np.asarray(anchor_local, np.float64)
        qv, qw = quats[:, :3], quats[:, 3:4]            # q a q*: a + 2 w (v x a) + 2 v x (v x a)
        t = 2.0 * np.cross(qv, local)
        offset = local + qw * t + np.cross(qv, t)
    anchor = g[:, 0:3] + offset
    rc = render_camera
    u = rc['fx'] * anchor[:, 0] / anchor[:, 2] + rc['cx']
    v = rc['fy'] * anchor[:, 1] / anchor[:, 2] + rc['cy']
    return np.column_stack([(u - crop[:, 1]) / crop[:, 0], (v - crop[:, 2]) / crop[:, 0],
                            np.linalg.norm(anchor, axis=1) * crop[:, 0], quats, offset])


def _place_wrists(terms: np.ndarray, render_camera: dict,
                  query_crop: tuple[float, float, float], camera: PinholeCamera) -> np.ndarray:
    """Wrist positions (k, 3) in the query camera from :func:`_entry_place_terms` rows."""
    from colorglove_ros.core.lookup import lookup_kernel

    sq, oqx, oqy = query_crop
    full = tiny_to_full(terms[:, 0:2], sq, oqx, oqy)
    if np.any(camera.distortion):
        full = camera.undistort_pixels(full)
    out = np.empty((len(terms), 3))
    # range along the unit ray through the anchor's pixel
    lookup_kernel.compile_kernels()
    lookup_kernel.wrists_on_rays(
        np.ascontiguousarray(full, np.float64), np.ascontiguousarray(terms, np.float64),
        camera.cx, camera.cy, camera.fx, camera.fy,
        (camera.fx + camera.fy) / (render_camera['fx'] + render_camera['fy']) / sq, out)
    return out


def estimate_global_pose(entry_global: np.ndarray, entry_crop: np.ndarray,
                         render_camera: dict, query_crop: tuple[float, float, float],
                         camera: PinholeCamera, anchor_local: np.ndarray | None = None
                         ) -> np.ndarray:
    """Global poses (k, 6) (wrist position, rotation vector) in the query camera of entries
    rendered with global poses ``entry_global`` (k, 6) and crops ``entry_crop`` (k, 3)
    (scale, offset_x, offset_y).

    The anchor (the hand-frame point ``anchor_local``, e.g. the hand's centre; the wrist if
    None) keeps its tiny-image position, mapped into the query image with the query crop,
    undistorted and back-projected to a ray; its distance along the ray (range, not depth:
    apparent size goes with range off the optical axis too) scales with apparent size,
    r_q = r_e (f_q / f_r) (s_e / s_q). The rotation is the entry's, and the wrist keeps its
    offset from the anchor."""
    terms = _entry_place_terms(entry_global, entry_crop, render_camera, anchor_local)
    out = np.asarray(entry_global, np.float64).reshape(-1, 6).copy()
    out[:, 0:3] = _place_wrists(terms, render_camera, _crop_tuple(query_crop), camera)
    return out


def _crop_tuple(crop_transform: object) -> tuple[float, float, float]:
    if hasattr(crop_transform, 'scale'):
        vals = (crop_transform.scale, crop_transform.offset_x, crop_transform.offset_y)
    else:
        vals = tuple(np.asarray(crop_transform, float).ravel())
    if len(vals) != 3 or not np.all(np.isfinite(vals)) or not float(vals[0]) > 0.0:
        raise SearchError(f'bad crop transform {crop_transform!r}')
    return float(vals[0]), float(vals[1]), float(vals[2])


class PoseLookup:
    """Nearest-neighbour pose lookup in a :class:`PoseDatabase`.

    The Hamming scan and the re-rank's gathers are compiled (:mod:`lookup_kernel`: compiled or
    loaded from numba's cache when the first instance is made); the scan's buffers are reused,
    so one instance is not thread-safe. ``threads=1`` (default) runs everything in the caller;
    ``threads=2`` runs the re-rank's two gathers at once, one in a worker thread (the same
    results; more CPU in all, the hand-off, and a wait for the worker when no core is free)."""

    def __init__(self, database: PoseDatabase, num_candidates: int = 300,
                 num_blend: int = 10, threads: int = DEFAULT_THREADS,
                 finger_evidence: FingerEvidenceConfig | None = None,
                 vertex_link: np.ndarray | None = None) -> None:
        if num_candidates < 1 or num_blend < 1:
            raise SearchError('num_candidates and num_blend must be positive')
        if threads not in (1, 2):
            raise SearchError(f'threads must be 1 or 2, got {threads}')
        from colorglove_ros.core.lookup import lookup_kernel

        lookup_kernel.compile_kernels()
        self._kernels = lookup_kernel
        # one worker thread for the re-rank's query -> candidate gather (None: all in the caller)
        self._pool = ThreadPoolExecutor(1, 'pose-lookup') if threads == 2 else None
        self.db = database
        self.num_candidates = int(num_candidates)
        self.num_blend = int(num_blend)
        self.finger_evidence = finger_evidence or FingerEvidenceConfig()
        self._vertex_link = (_standard_vertex_link(database) if vertex_link is None
                             else np.asarray(vertex_link))
        n = len(database)
        self._columns = np.ascontiguousarray(database.codes)
        # Hamming distances fit a byte up to 255 bits: the compiled scan (with the distances'
        # histogram) takes those; longer codes go through numpy (uint16 distances)
        self._compiled_scan = database.num_bits <= 255
        self._ham = np.empty(n, np.uint8 if self._compiled_scan else np.uint16)
        self._hist = np.zeros(64 * self._columns.shape[0] + 1, np.int64)
        self._selected = np.empty(n if self._compiled_scan else 0, np.intp)
        self._xor = np.empty(0 if self._compiled_scan else min(n, HAMMING_BLOCK), np.uint64)
        self._cnt = np.empty(len(self._xor), np.uint8)
        self._qenc = QueryEncoder(database.encoder)
        # plain ndarray views of the (memory-mapped) arrays: no np.memmap indexing overhead
        self._a = {name: np.asarray(getattr(database, name)) for name in (
            'dts', 'pixel_keys', 'poses', 'crop', 'patch_vertex', 'patch_xy', 'patch_color',
            'patch_pixels')}
        self._keys = np.ascontiguousarray(self._a['pixel_keys'])
        self._row = int(np.prod(self._a['dts'].shape[1:]))
        self._dts_all = np.ascontiguousarray(self._a['dts']).reshape(-1)
        self._counts = np.asarray(database.pixel_counts, np.float64)
        # query DT lookup table, last slot (the padding key 16000) reads zero
        self._table = np.zeros(self._row + 1, np.float32)
        self._rerank_groups = 4
        anchor = database.meta.get('hand_centre_local')
        self._anchor = None if anchor is None else np.asarray(anchor, np.float64)
        # the query-independent part of placing every entry in a query's view, once
        self._place_table = _entry_place_terms(self._a['poses'][:, 0:6], self._a['crop'],
                                               database.render_camera, self._anchor)
        # every entry's patch digits (a patch vertex beyond the mesh is refused here, once)
        try:
            self._patch_digit = patch_digits(self._a['patch_vertex'], self._vertex_link)
        except FingerEvidenceError as exc:
            raise SearchError(f'per-finger blend: {exc}') from exc

    @property
    def buffer_bytes(self) -> int:
        """Memory held by this lookup besides the database: the scan's buffers and the
        per-entry tables computed at construction."""
        arrays = [self._ham, self._hist, self._selected, self._xor, self._cnt, self._table,
                  self._place_table, self._patch_digit]
        return int(sum(a.nbytes for a in arrays))

    def hamming(self, tiny_labels: np.ndarray) -> np.ndarray:
        """Hamming distances (N,) of a query to every entry (a copy)."""
        qd = QueryDistance(tiny_labels)
        return self._hamming_dts(qd.dts).copy()

    def _hamming_dts(self, dts: np.ndarray) -> np.ndarray:
        """Hamming distances of the query with distance transforms ``dts`` to every entry
        (this lookup's buffer; the compiled scan also fills the distances' histogram)."""
        code = self._qenc.encode(dts)
        if self._compiled_scan:
            self._kernels.hamming_histogram(self._columns, code, self._ham, self._hist)
            return self._ham
        return hamming_distances(self._columns, code, self._ham, self._xor, self._cnt)

    def _candidates(self, dts: np.ndarray) -> np.ndarray:
        """:func:`top_k_with_ties` of the query's Hamming distances (``num_candidates``),
        from the compiled scan's histogram where it ran: the smallest distance with at least
        k entries at or below it is the cut."""
        ham = self._hamming_dts(dts)
        if not self._compiled_scan:
            return top_k_with_ties(ham, self.num_candidates)
        if self.num_candidates >= len(ham):
            return np.arange(len(ham))
        cut = int(np.searchsorted(np.cumsum(self._hist), self.num_candidates))
        count = self._kernels.at_most(ham, cut, self._selected)
        return self._selected[:count].copy()

    def _group_widths(self, counts: np.ndarray) -> np.ndarray:
        """Per candidate, how many of its pixel keys the candidate -> query sum runs over:
        candidates in ``_rerank_groups`` groups of similar glove-pixel count, each summed up
        to its largest count (padding keys read zero; the width fixes the sum's pairwise
        order, so the distances keep their bits)."""
        order = np.argsort(counts, kind='stable')
        groups = min(self._rerank_groups, max(1, len(counts)))
        bounds = (len(counts) * np.arange(groups + 1)) // groups
        widths = np.empty(len(counts), np.intp)
        for g in range(groups):
            grp = order[bounds[g]:bounds[g + 1]]
            if len(grp):
                widths[grp] = max(1, int(counts[grp[-1]]))
        return np.minimum(widths, self._keys.shape[1], out=widths)

    def rerank(self, query: QueryDistance, indices: np.ndarray) -> np.ndarray:
        """Exact image distances (k,) from the query to database entries ``indices``.

        With ``threads=2`` the query -> candidate sums run in a worker thread while this
        thread does the candidate -> query ones (both compiled, releasing the GIL)."""
        idx = np.ascontiguousarray(indices, np.intp)
        nq = query.num_pixels
        kernels = self._kernels
        q_sum = np.empty(len(idx), np.uint32)
        # the query's pixels in ascending address order: each entry's row is read forwards
        # (an integer sum, the same in any order)
        gather = (self._dts_all, idx, self._row, np.sort(query.glove_index), q_sum)
        pending = (self._pool.submit(kernels.query_sums, *gather)
                   if nq and self._pool is not None else None)
        counts = self._counts[idx]
        table = self._table
        table[:-1] = query.dts.reshape(-1)
        cand_sum = np.empty(len(idx), np.float64)
        kernels.candidate_sums(table, self._keys, idx, self._group_widths(counts), cand_sum)
        if nq:
            if pending is not None:
                pending.result()
            else:
                kernels.query_sums(*gather)
            d_qc = q_sum * (1.0 / (DT_SCALE * nq))
            d_cq = np.where(counts > 0, cand_sum / np.maximum(counts, 1.0), ABSENT_PENALTY)
        else:
            d_qc = np.where(counts > 0, ABSENT_PENALTY, 0.0)
            d_cq = d_qc
        return 0.5 * (d_qc + d_cq)

    def lookup(self, tiny_labels: np.ndarray, crop_transform: object,
               camera: PinholeCamera, blobs: object = None) -> LookupResult:
        """Look up a (40, 40) label image cropped from ``camera``'s image with
        ``crop_transform`` (``CropTransform`` or (scale, offset_x, offset_y)).

        With ``blobs`` (the same image's patch blobs: ``color``, ``centroid_px`` in full-image
        pixels, ``pixel_count``: ``tracking.types.Blobs``) each finger of the blend is weighted by
        how well the nearest ``finger_evidence.num_neighbours`` entries' patches on that finger
        match the blobs (:mod:`core.lookup.finger_evidence`) and the result carries the fingers'
        spread (``finger_std``); without, every DOF is blended with the image weights (the
        paper)."""
        return self.blend(self.search(tiny_labels, crop_transform), camera, blobs)

    def search(self, tiny_labels: np.ndarray, crop_transform: object) -> Neighbours:
        """The first part of :meth:`lookup`: the query's candidates by Hamming distance,
        re-ranked by exact image distance (what the handedness evidence of two lookups of
        one region needs); :meth:`blend` makes the lookup's result from them."""
        t0 = time.perf_counter()
        crop = _crop_tuple(crop_transform)
        try:
            query = QueryDistance(tiny_labels)
        except Exception as exc:
            raise SearchError(f'bad query image: {exc}') from exc
        if query.num_pixels == 0:
            raise SearchError('query tiny image has no glove pixels')
        t1 = time.perf_counter()
        cand = self._candidates(query.dts)
        t2 = time.perf_counter()
        dist = self.rerank(query, cand)
        t3 = time.perf_counter()
        return Neighbours(cand, dist, crop, {'encode_ms': 1e3 * (t1 - t0),
                                             'hamming_ms': 1e3 * (t2 - t1),
                                             'rerank_ms': 1e3 * (t3 - t2)})

    def blend(self, found: Neighbours, camera: PinholeCamera, blobs: object = None
              ) -> LookupResult:
        """The second part of :meth:`lookup`: the nearest of the :meth:`search` 's candidates
        ``found`` blended into the pose prior (with ``blobs``, per finger) and the nearest
        entry's projection constraints, in ``camera``'s view of the query."""
        t3 = time.perf_counter()
        cand, dist, crop = found.candidates, found.distances, found.crop
        wide = min(max(self.num_blend, self.finger_evidence.num_neighbours
                       if blobs is not None else 0), len(cand))
        near = np.argpartition(dist, wide - 1)[:wide] if wide < len(cand) else np.arange(len(cand))
        near = near[np.lexsort((cand[near], dist[near]))]
        k = min(self.num_blend, len(cand))
        idx, d = cand[near[:k]], dist[near[:k]]
        weights = blend_weights(d)
        poses = self._a['poses'][idx].astype(np.float64)
        terms = self._place_table[idx]
        poses[:, 0:3] = _place_wrists(terms, self.db.render_camera, crop, camera)
        blended = blend_poses_with_quaternions(poses, terms[:, 3:7], weights)
        finger_std = finger_entries = None
        evidence = None if blobs is None else self._finger_blend(cand[near], crop, blobs)
        if evidence is not None:
            fingers, finger_std, finger_entries, seen = evidence
            # a finger no entry shows a matching patch of keeps the image-weighted blend
            # (already in blended) and that blend's spread
            dofs = np.repeat(seen, 4)
            blended[6:] = np.where(dofs, fingers, blended[6:])
            if not seen.all():
                finger_std = np.where(dofs, finger_std, weighted_fingers(poses, weights)[1])
            finger_entries = np.where(seen, finger_entries, idx[0])
        constraints = self._constraints(int(idx[0]), crop, finger_entries)
        t4 = time.perf_counter()
        timings = {**found.timings_ms, 'blend_ms': 1e3 * (t4 - t3)}
        timings['total_ms'] = sum(timings.values())
        return LookupResult(idx, d, weights, poses, blended, constraints, len(cand), timings,
                            finger_std)

    def _finger_blend(self, entries: np.ndarray, crop: tuple[float, float, float],
                      blobs: object
                      ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None:
        """Per-finger blend (20,) and spread (20,) of ``entries`` against full-image
        ``blobs`` (:mod:`core.lookup.finger_evidence`), the best-scoring entry of each digit (5,),
        whose patches on that digit become its projection constraints, and which digits had
        evidence (5,); None when there are no usable blobs (the paper's blend stands)."""
        try:
            color = np.asarray(blobs.color).reshape(-1)
            xy = np.asarray(blobs.centroid_px, np.float64).reshape(-1, 2)
            pixels = np.asarray(blobs.pixel_count, np.float64).reshape(-1)
        except (AttributeError, ValueError) as exc:
            raise SearchError(f'blobs need color, centroid_px (B, 2) and pixel_count: {exc}'
                              ) from exc
        if not len(color) == len(xy) == len(pixels):
            raise SearchError('blob colour, centroid and pixel-count arrays differ in length')
        scale, ox, oy = crop
        # the blobs with a finite centroid and pixels, in the query's tiny frame
        color, xy, pixels = self._kernels.usable_blobs_in_tiny_frame(
            np.ascontiguousarray(color, np.int64), np.ascontiguousarray(xy),
            np.ascontiguousarray(pixels), scale, ox, oy, scale ** 2)
        if not len(color):
            return None
        try:
            scores = finger_scores(self._a['patch_xy'][entries],
                                   self._a['patch_pixels'][entries],
                                   self._patch_digit[entries], self._a['patch_color'],
                                   color, xy, pixels, self.finger_evidence)
            fingers, spread, seen = finger_blend(self._a['poses'][entries], scores,
                                                 self.finger_evidence)
        except FingerEvidenceError as exc:
            raise SearchError(f'per-finger blend: {exc}') from exc
        return fingers, spread, entries[np.argmin(scores, axis=0)], seen

    @property
    def anchor_local(self) -> np.ndarray | None:
        """The hand-frame point the lookup places entries by (the hand centre; None: the
        wrist)."""
        return None if self._anchor is None else self._anchor.copy()

    def place(self, indices: np.ndarray | None, crop_transform: object,
              camera: PinholeCamera) -> np.ndarray:
        """Global poses (k, 6) of entries ``indices`` (None: all) placed in the view of a
        query cropped with ``crop_transform`` (:func:`estimate_global_pose`)."""
        sel = slice(None) if indices is None else indices
        out = self._a['poses'][sel, 0:6].astype(np.float64)
        out[:, 0:3] = _place_wrists(self._place_table[sel], self.db.render_camera,
                                    _crop_tuple(crop_transform), camera)
        return out

    def _constraints(self, entry: int, crop: tuple[float, float, float],
                     finger_entries: np.ndarray | None = None) -> ProjectionConstraints:
        """Projection constraints of ``entry``'s visible patches; with ``finger_entries``
        (5,), the patches on digit g are taken from entry ``finger_entries[g]`` (the entry
        that best explains that finger) instead."""
        finger = _NO_FINGER_ENTRIES if finger_entries is None else \
            np.ascontiguousarray(finger_entries, np.int64)
        ids, colors, vertices, tiny_xy, pixels = self._kernels.constraint_patches(
            entry, finger, self._a['patch_vertex'], self._patch_digit, self._a['patch_xy'],
            self._a['patch_pixels'], self._a['patch_color'])
        return ProjectionConstraints(patch_ids=ids, colors=colors, vertices=vertices,
                                     tiny_xy=tiny_xy, pixel_counts=pixels,
                                     full_xy=tiny_to_full(tiny_xy, *crop))
