"""Two gloved hands at once: a layer over the one-hand stages of ``core.pipeline``.

Per frame: :func:`find_glove_regions` finds up to two glove regions on a coarse frame (the
segmenter's colour table and glove-region test, ``core.segmentation.detection``); each region
is segmented on its own by the existing segmenter with the other regions painted out
(:func:`mask_regions`), and its query is looked up twice in the right-hand database, as seen
and mirrored (``core.hand.handedness``). Which region is which hand is decided from the
evidence (:func:`assign_hands`): the nearest database image of the mirrored against the
unmirrored query (a right glove matches unmirrored, a left one mirrored), and continuity (each
hand's previous crop centre); with two regions they are a left and a right hand. While both
hands are tracked, a region that plainly continues one hand is looked up as that hand only,
with both lookups again every few frames (``HandsSettings.recheck_frames``); a lookup only the
evidence reads is searched, not blended (:class:`Searched`). Each hand
has its own tracker (a left hand tracked as the mirrored right hand, its pose mirrored back),
so losing one hand never resets the other. A frame in which a region's hand cannot be told
with enough evidence gives that hand no pose (``NoHand``). With one pose lookup per region slot
(:func:`slot_lookups`) the two slots, and then the two hands, run on two threads.

Limitations: two gloves within ``join_px`` coarse pixels of each other (touching) are one
region, whose lookups match neither hand well: neither hand gets a pose until they part. A glove
partly hidden by the other hand's forearm is looked up as what is left of it: lost, or tracked
less well than alone. No rclpy import.
"""
from __future__ import annotations

import math
import time
from collections.abc import Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field, replace
from typing import Any

import cv2
import numpy as np

from colorglove_ros.core.hand.handedness import (
    HANDS,
    from_right_frame,
    mirror_camera_observation,
    mirror_tiny_crop,
)
from colorglove_ros.core.lookup.types import LookupResult, Neighbours
from colorglove_ros.core.pipeline import (
    NODE_LIMITS,
    NoHand,
    StageLimits,
    Tracked,
    blend,
    look_up,
    search,
    too_far,
    track,
)
from colorglove_ros.core.segmentation.crop import CropTransform, TinyCrop
from colorglove_ros.core.segmentation.detection import (
    drop_oversized_components,
    glove_region_mask,
)
from colorglove_ros.core.segmentation.segmenter import keep_multicolor_components
from colorglove_ros.core.tracking.types import Blobs, CameraObservation

__all__ = ['MAX_HANDS', 'HandsSettings', 'GloveRegion', 'Searched', 'HandCandidate', 'HandOutcome',
           'FrameTiming', 'find_glove_regions', 'mask_regions', 'region_window',
           'shift_observation', 'assign_hands', 'slot_lookups', 'TwoHandPipeline',
           'DEFAULT_THREADS']

MAX_HANDS = 2
#: Threads of the two-hand layer by default (:func:`slot_lookups`): one per region slot.
DEFAULT_THREADS = 2


@dataclass(frozen=True)
class HandsSettings:
    """Settings of the two-hand layer. Regions: coarse ``coarse_factor`` downsampling, glove
    pixels joined within ``join_px`` coarse pixels, at least ``min_region_pixels`` coarse glove
    pixels; a region is painted out of the other's image (its joined glove cells; without cells,
    its box grown by ``mask_margin`` times its size), and each region is segmented in its
    window: its box grown on every side by ``window_margin`` times the box's larger side.
    Handedness: a region's evidence is ``(d_left - d_right) / evidence_scale_px`` (nearest
    database images of the mirrored and unmirrored query, tiny px; positive: a right hand);
    continuity costs ``(distance / (continuity_scale * crop half size))^2`` from the hand's
    previous crop centre; an assignment whose score beats the other by less than ``min_margin``
    is not decided (no pose for that frame). While both hands are tracked, a region whose crop
    centre lies within ``continuity_scale`` crop half sizes of one hand's previous centre and at
    most ``settled_ratio`` times as far from it as from the other hand's is looked up as that
    hand only (continuity is its evidence), except on every ``recheck_frames``-th frame, when
    every region is looked up both ways again (0: always both ways)."""

    coarse_factor: int = 4
    join_px: int = 1
    min_region_pixels: int = 40
    mask_margin: float = 0.1
    evidence_scale_px: float = 0.5
    continuity_scale: float = 1.0
    min_margin: float = 1.0
    max_gap_frames: int = 15
    window_margin: float = 0.5
    settled_ratio: float = 0.5
    recheck_frames: int = 5


@dataclass(frozen=True)
class GloveRegion:
    """One glove region: its box (x0, y0, x1, y1 in full-image pixels, end exclusive), coarse
    glove pixel count and, when known, its cells: the coarse image (``cell_px`` full pixels a
    cell) true where the region's glove pixels, joined, lie."""

    box: tuple[int, int, int, int]
    pixels: int
    cells: np.ndarray | None = field(default=None, compare=False, repr=False)
    cell_px: int = 1


@dataclass(frozen=True)
class Searched:
    """A lookup searched but not blended yet (``core.pipeline.search``): its candidates, the
    blobs its blend will weigh the fingers by, and its nearest database image distance (inf
    when that is too far for a hand, as the whole lookup would say)."""

    neighbours: Neighbours
    blobs: Any
    nearest: float


@dataclass
class HandCandidate:
    """One region's observation and its two lookups (as seen: right hand; mirrored: left),
    each done, or only searched (:class:`Searched`) until a hand is tracked from it."""

    region: GloveRegion
    observation: CameraObservation
    tiny: TinyCrop | None
    lookups: dict[str, LookupResult | NoHand | Searched] = field(default_factory=dict)

    def distance(self, hand: str) -> float:
        """Nearest database image distance of the query as ``hand`` (inf when none)."""
        found = self.lookups.get(hand)
        if isinstance(found, Searched):
            return found.nearest
        if found is None or isinstance(found, NoHand) or not len(found.distances):
            return math.inf
        return float(found.distances[0])

    @property
    def center(self) -> np.ndarray:
        """The crop window's centre (x, y), full pixels (the box centre without a crop)."""
        crop = self.observation.crop
        if crop is not None:
            return np.array(crop.center_xy, float)
        x0, y0, x1, y1 = self.region.box
        return np.array([(x0 + x1) / 2.0, (y0 + y1) / 2.0])

    @property
    def half_size(self) -> float:
        """The crop window's half size (full pixels)."""
        crop = self.observation.crop
        if crop is not None:
            return float(crop.half_size)
        x0, y0, x1, y1 = self.region.box
        return max(x1 - x0, y1 - y0) / 2.0


@dataclass(frozen=True)
class HandOutcome:
    """One hand's result in a frame: the tracked pose (in that hand's terms) or why not,
    the region it was given (None: none) and the handedness evidence of that region (nearest
    database image of the mirrored minus that of the unmirrored query, tiny px; NaN when the
    region was looked up as one hand only, its hand then following from continuity)."""

    hand: str
    outcome: Tracked | NoHand
    region: GloveRegion | None = None
    evidence: float = math.nan
    q: np.ndarray | None = None


@dataclass(frozen=True)
class FrameTiming:
    """Thread CPU time of one :meth:`TwoHandPipeline.process` call (ms): the caller's outside
    the jobs it ran beside the worker (``serial_ms``), and each parallel phase's jobs (one per
    region slot, then one per hand; each on its own thread when ``parallel``). The critical
    path is what the frame would take with a free core per thread and no wait on the other
    thread's GIL: ``serial_ms`` plus the slowest job of every phase (with one thread, all)."""

    serial_ms: float
    phases: tuple[tuple[float, ...], ...]
    parallel: bool

    @property
    def cpu_ms(self) -> float:
        """The frame's CPU time over both threads."""
        return self.serial_ms + sum(sum(p) for p in self.phases)

    @property
    def critical_path_ms(self) -> float:
        """``serial_ms`` plus each phase's slowest job (with one thread: :attr:`cpu_ms`)."""
        if not self.parallel:
            return self.cpu_ms
        return self.serial_ms + sum(max(p, default=0.0) for p in self.phases)


def find_glove_regions(segmenter: Any, image_rgb: np.ndarray,
                       settings: HandsSettings = HandsSettings(),
                       max_regions: int = MAX_HANDS) -> list[GloveRegion]:
    """Up to ``max_regions`` glove regions of an RGB image, largest first: on the frame
    downsampled by ``settings.coarse_factor``, pixels the ``segmenter``'s colour calibration
    labels glove that lie in a colourful neighbourhood (its glove-region settings), joined within
    ``join_px``; a region needs ``min_region_pixels`` coarse glove pixels."""
    f = int(settings.coarse_factor)
    h, w = image_rgb.shape[:2]
    small = cv2.resize(image_rgb, (w // f, h // f), interpolation=cv2.INTER_AREA)
    calibration = segmenter.calibration
    labels = cv2.medianBlur(calibration.classify(small), 3)
    labels = drop_oversized_components(labels, segmenter.max_patch_fraction * labels.size)
    window = max(int(round(segmenter.diversity_window * segmenter.coarse_factor / f)), 1)
    labels = labels * glove_region_mask(labels, calibration.num_colors, window,
                                        segmenter.min_region_colors,
                                        segmenter.diversity_density).view(np.uint8)
    labels = keep_multicolor_components(labels, 3, min_pixels=2)
    glove = (labels > 0).view(np.uint8)
    size = 2 * int(settings.join_px) + 1
    joined = cv2.dilate(glove, cv2.getStructuringElement(cv2.MORPH_RECT, (size, size)))
    n, comp, stats, _ = cv2.connectedComponentsWithStats(joined, connectivity=8)
    counts = np.bincount(comp[glove > 0], minlength=n)
    regions = []
    for k in range(1, n):
        if counts[k] < settings.min_region_pixels:
            continue
        x, y, bw, bh = stats[k, :4]
        regions.append(GloveRegion((int(x * f), int(y * f), int(min((x + bw) * f, w)),
                                    int(min((y + bh) * f, h))), int(counts[k]), comp == k, f))
    regions.sort(key=lambda r: -r.pixels)
    return regions[:max_regions]


def mask_regions(image_rgb: np.ndarray, regions: Sequence[GloveRegion],
                 margin: float = 0.1, origin: tuple[int, int] = (0, 0)) -> np.ndarray:
    """A copy of the image (whose top-left pixel is image pixel ``origin``: a window of it)
    with every region painted a neutral grey, which no glove colour classifies as: its cells
    where it has them (so a hand next to it keeps its own pixels), else its box grown by
    ``margin`` of its size."""
    out = np.array(image_rgb, copy=True)   # contiguous, whatever the input's strides
    h, w = out.shape[:2]
    ox, oy = origin
    for r in regions:
        if r.cells is not None:
            c = r.cell_px
            cy0, cx0 = oy // c, ox // c        # the cells the window overlaps
            block = r.cells[cy0:(oy + h - 1) // c + 1, cx0:(ox + w - 1) // c + 1]
            if not block.any():
                continue
            up = np.repeat(np.repeat(block, c, 0), c, 1)[oy - cy0 * c:, ox - cx0 * c:]
            up = up[:h, :w]
            out[:up.shape[0], :up.shape[1]][up] = 128
            continue
        x0, y0, x1, y1 = r.box
        mx, my = int(margin * (x1 - x0)), int(margin * (y1 - y0))
        x0, x1, y0, y1 = x0 - mx - ox, x1 + mx - ox, y0 - my - oy, y1 + my - oy
        out[max(y0, 0):max(min(y1, h), 0), max(x0, 0):max(min(x1, w), 0)] = 128
    return out


def region_window(region: GloveRegion, shape: tuple[int, ...], margin: float
                  ) -> tuple[int, int, int, int]:
    """The part of an image of ``shape`` a region is segmented in: its box grown on every
    side by ``margin`` times the box's larger side, clipped to the image (x0, y0, x1, y1, end
    exclusive)."""
    x0, y0, x1, y1 = region.box
    grow = int(math.ceil(margin * max(x1 - x0, y1 - y0)))
    h, w = shape[:2]
    return max(x0 - grow, 0), max(y0 - grow, 0), min(x1 + grow, w), min(y1 + grow, h)


def shift_observation(observation: CameraObservation, tiny: TinyCrop | None, dx: float,
                      dy: float) -> tuple[CameraObservation, TinyCrop | None]:
    """An observation (and lookup query) made on a window whose top-left pixel is image pixel
    ``(dx, dy)``, in the whole image's pixels: blob centroids and crops moved."""
    if dx == 0 and dy == 0:
        return observation, tiny

    def moved(crop: CropTransform | None) -> CropTransform | None:
        return None if crop is None else CropTransform(
            scale=crop.scale, offset_x=crop.offset_x + dx, offset_y=crop.offset_y + dy)

    blobs = observation.blobs
    if len(blobs):
        blobs = Blobs(blobs.color, np.asarray(blobs.centroid_px, float) + [dx, dy],
                      blobs.pixel_count)
    shifted = replace(observation, blobs=blobs, crop=moved(observation.crop))
    return shifted, None if tiny is None else TinyCrop(tiny.labels, moved(tiny.transform))


def assign_hands(candidates: Sequence[HandCandidate],
                 previous: dict[str, np.ndarray | None],
                 settings: HandsSettings = HandsSettings()
                 ) -> tuple[dict[str, int], float]:
    """Which candidate is which hand: ({hand: candidate index}, the winning assignment's
    score margin over the best other). Every assignment of distinct hands to the candidates
    is scored: the sum of each candidate's evidence for its hand (``+-(d_left - d_right) /
    evidence_scale_px``) minus the continuity cost from the hand's previous crop centre
    (``previous[hand]``, None when it was not tracked)."""
    def evidence(c: HandCandidate) -> float:
        if len(c.lookups) < len(HANDS):      # looked up as one hand only: no lookup evidence
            return 0.0
        e = (c.distance('left') - c.distance('right')) / settings.evidence_scale_px
        return float(np.clip(e, -20.0, 20.0)) if math.isfinite(e) else (
            20.0 if c.distance('right') < math.inf else
            -20.0 if c.distance('left') < math.inf else 0.0)

    def score(assignment: dict[str, int]) -> float:
        total = 0.0
        for hand, i in assignment.items():
            c = candidates[i]
            total += evidence(c) if hand == 'right' else -evidence(c)
            prev = previous.get(hand)
            if prev is not None:
                d = np.linalg.norm(c.center - prev) / (settings.continuity_scale
                                                        * max(c.half_size, 1.0))
                total -= float(d * d)
        return total

    if not candidates:
        return {}, math.inf
    if len(candidates) == 1:
        options = [{'right': 0}, {'left': 0}]
    else:
        options = [{'right': 0, 'left': 1}, {'right': 1, 'left': 0}]
    scored = sorted(((score(o), o) for o in options), key=lambda t: -t[0])
    return scored[0][1], scored[0][0] - scored[1][0]


def slot_lookups(database: Any, threads: int = DEFAULT_THREADS) -> Any:
    """The pose lookup(s) of a :class:`TwoHandPipeline` on ``database``: with ``threads`` 2,
    one single-threaded lookup per region slot (the pipeline then runs the two slots on two
    threads); with 1, one lookup shared by the slots, which then run one after the other in
    the caller's thread (the lookup keeps its own default threading)."""
    from colorglove_ros.core.lookup.search import PoseLookup

    if threads not in (1, 2):
        raise ValueError(f'threads must be 1 or 2, got {threads}')
    if threads == 1:
        return PoseLookup(database)
    return [PoseLookup(database, threads=1) for _ in range(MAX_HANDS)]


def _thread_timed(job: Any, *args: Any) -> tuple[Any, float]:
    """``job(*args)`` and the thread CPU time it took (ms) in the thread that ran it."""
    started = time.thread_time()
    result = job(*args)
    return result, 1e3 * (time.thread_time() - started)


class TwoHandPipeline:
    """Segment -> look up -> track for up to two hands (a right and a left glove) in one
    camera's frames. ``segmenter`` is copied once per region slot (``fresh``, no learnt
    background: each sees frames with the other hand painted out); ``trackers`` maps 'right'
    and 'left' to a :class:`HandTracker` of the right-hand model each (the left hand is
    tracked mirrored).

    ``lookup`` is one pose lookup, or one per region slot (``MAX_HANDS`` of the same database;
    a lookup is not thread-safe): with one per slot the two regions are segmented and looked
    up, and then the two hands tracked, on two threads (the caller's and one worker; OpenCV
    and most of numpy's array work release the GIL). Results do not depend on it."""

    def __init__(self, segmenter: Any, lookup: Any, camera: Any, trackers: dict[str, Any], *,
                 limits: StageLimits = NODE_LIMITS, settings: HandsSettings = HandsSettings(),
                 finger_evidence: bool = True) -> None:
        self.segmenter = segmenter
        self.segmenters = [segmenter.fresh(background_frames=0) for _ in range(MAX_HANDS)]
        lookups = list(lookup) if isinstance(lookup, (list, tuple)) else [lookup]
        if len(lookups) not in (1, MAX_HANDS):
            raise ValueError(f'need 1 or {MAX_HANDS} lookups, got {len(lookups)}')
        self.lookups = lookups
        self._pool = ThreadPoolExecutor(1, 'two-hands') if len(lookups) > 1 else None
        self.camera = camera
        self.trackers = trackers
        self.limits = limits
        self.settings = settings
        self.finger_evidence = finger_evidence
        self.previous: dict[str, np.ndarray | None] = {hand: None for hand in HANDS}
        self._missing = {hand: 0 for hand in HANDS}
        self._settled_frames = 0
        self._phases: list[tuple[float, ...]] = []   # this frame's, for last_timing
        self._caller_jobs_ms = 0.0
        #: thread CPU time of the last :meth:`process` call (None before the first)
        self.last_timing: FrameTiming | None = None

    @property
    def parallel(self) -> bool:
        """Whether the two slots run on two threads (one lookup per slot)."""
        return self._pool is not None

    def close(self) -> None:
        """Stop the worker thread (if any); the pipeline then runs in the caller only."""
        if self._pool is not None:
            self._pool.shutdown()
            self._pool = None

    def reset(self) -> None:
        """Forget both hands."""
        for tracker in self.trackers.values():
            tracker.reset()
        self.previous = {hand: None for hand in HANDS}
        self._settled_frames = 0

    def _both(self, job: Any, args: Sequence[tuple[Any, ...]]) -> list[Any]:
        """``[job(*a) for a in args]``, the second on the worker thread when there is one (the
        job of item k uses slot k's lookup and segmenter only); the jobs' thread CPU times are
        a phase of the frame's :class:`FrameTiming`."""
        if self._pool is None or len(args) < 2:
            done = [_thread_timed(job, *a) for a in args]
            in_caller = done
        else:
            pending = self._pool.submit(_thread_timed, job, *args[1])
            try:
                first = _thread_timed(job, *args[0])
            finally:
                second = pending.result()
            done, in_caller = [first, second], [first]
        if done:
            self._phases.append(tuple(ms for _, ms in done))
            self._caller_jobs_ms += sum(ms for _, ms in in_caller)
        return [result for result, _ in done]

    def _continued_hand(self, center: np.ndarray, half_size: float) -> str | None:
        """The hand a region at ``center`` continues without doubt (both hands tracked in the
        previous frame; :class:`HandsSettings`), else None."""
        if self._settled_frames == 0:
            return None
        d = {h: float(np.linalg.norm(center - p)) for h, p in self.previous.items()
             if p is not None}
        if len(d) < len(HANDS):
            return None
        own, other = sorted(d, key=d.get)
        if d[own] <= self.settings.continuity_scale * max(half_size, 1.0) \
                and d[own] <= self.settings.settled_ratio * d[other]:
            return own
        return None

    def _query(self, candidate: HandCandidate, hand: str) -> tuple[TinyCrop, Blobs | None]:
        """``candidate``'s lookup query as ``hand`` (a left hand's mirrored) and the blobs its
        fingers are blended by (None without ``finger_evidence``)."""
        obs, tiny = candidate.observation, candidate.tiny
        if hand != 'right':
            cx = self.camera.cx
            obs, tiny = mirror_camera_observation(obs, cx), mirror_tiny_crop(tiny, cx)
        return tiny, obs.blobs if self.finger_evidence else None

    def _look_up(self, candidate: HandCandidate, hand: str, slot: int
                 ) -> LookupResult | NoHand:
        """``candidate``'s query looked up as ``hand`` with slot ``slot``'s lookup (or its
        search blended), kept."""
        lookup = self.lookups[slot % len(self.lookups)]
        found = candidate.lookups.get(hand)
        if isinstance(found, Searched):
            candidate.lookups[hand] = blend(lookup, found.neighbours, self.camera, found.blobs,
                                            self.limits)
        elif found is None:
            tiny, blobs = self._query(candidate, hand)
            candidate.lookups[hand] = look_up(lookup, tiny, self.camera, blobs, self.limits)
        return candidate.lookups[hand]

    def _search(self, candidate: HandCandidate, hand: str, slot: int) -> None:
        """``candidate``'s query as ``hand`` searched with slot ``slot``'s lookup, its blend
        left to :meth:`_look_up` (if a hand is tracked from it)."""
        tiny, blobs = self._query(candidate, hand)
        found = search(self.lookups[slot % len(self.lookups)], tiny)
        candidate.lookups[hand] = found if isinstance(found, NoHand) else Searched(
            found, blobs, math.inf if too_far(found.nearest, self.limits) else found.nearest)

    def _candidate(self, image_rgb: np.ndarray, regions: Sequence[GloveRegion], k: int
                   ) -> HandCandidate | None:
        """Region ``k`` segmented in its window with the other regions painted out, and
        looked up (both ways, or as the hand it plainly continues); None without a hand."""
        from colorglove_ros.core.pipeline import observe_image

        region = regions[k]
        x0, y0, x1, y1 = region_window(region, image_rgb.shape, self.settings.window_margin)
        others = [r for j, r in enumerate(regions) if j != k]
        window = mask_regions(image_rgb[y0:y1, x0:x1], others, self.settings.mask_margin,
                              (x0, y0))
        seen, tiny = shift_observation(*observe_image(self.segmenters[k], window, True), x0, y0)
        if tiny is None or not seen.hand_found:
            return None
        candidate = HandCandidate(region, seen, tiny)
        continued = self._continued_hand(candidate.center, candidate.half_size)
        every = self.settings.recheck_frames
        if continued is not None and every > 0 and self._settled_frames % every:
            self._look_up(candidate, continued, k)      # a settled hand: that way only
            return candidate
        for hand in HANDS:   # both ways; blended now only as the hand it likely is
            if hand == continued:
                self._look_up(candidate, hand, k)
            else:
                self._search(candidate, hand, k)
        return candidate

    def candidates(self, image_rgb: np.ndarray) -> list[HandCandidate]:
        """Every glove region's observation and its lookups as a right and as a left hand."""
        regions = find_glove_regions(self.segmenter, image_rgb, self.settings)
        found = self._both(self._candidate, [(image_rgb, regions, k)
                                             for k in range(len(regions))])
        return [c for c in found if c is not None]

    def _track(self, hand: str, candidate: HandCandidate, stamp: float) -> HandOutcome:
        """``hand``'s outcome from its candidate (its lookup as that hand, then its tracker)."""
        found = self._look_up(candidate, hand, HANDS.index(hand))
        obs = candidate.observation if hand == 'right' else mirror_camera_observation(
            candidate.observation, self.camera.cx)
        prior = None if isinstance(found, NoHand) else found
        outcome = track(self.trackers[hand], prior, [obs], stamp, self.limits,
                        upstream_reason=found.reason if isinstance(found, NoHand) else '')
        evidence = candidate.distance('left') - candidate.distance('right') \
            if len(candidate.lookups) == len(HANDS) else math.nan
        q = from_right_frame(outcome.result.q, hand) if isinstance(outcome, Tracked) else None
        return HandOutcome(hand, outcome, candidate.region, evidence, q)

    def process(self, image_rgb: np.ndarray, stamp: float) -> dict[str, HandOutcome]:
        """One frame: each hand's outcome (its own tracker; a hand without a region, or
        whose region's handedness is not decided, is 'no hand' and its tracker starts again
        when it comes back)."""
        started = time.thread_time()
        self._phases, self._caller_jobs_ms = [], 0.0
        candidates = self.candidates(image_rgb)
        assignment, margin = assign_hands(candidates, self.previous, self.settings)
        decided = margin >= self.settings.min_margin
        out = {}
        given = []
        for hand in HANDS:
            i = assignment.get(hand)
            if i is None or not decided:
                reason = ('no glove region' if i is None else
                          f'handedness not decided (score margin {margin:.2f} < '
                          f'{self.settings.min_margin:g})')
                self.trackers[hand].reset()
                self._forget(hand)
                out[hand] = HandOutcome(hand, NoHand(reason))
            else:
                given.append((hand, candidates[i], stamp))
        for hand, candidate, _ in given:
            self.previous[hand] = candidate.center
            self._missing[hand] = 0
        for outcome in self._both(self._track, given):
            out[outcome.hand] = outcome
        both = all(isinstance(out[h].outcome, Tracked) for h in HANDS)
        self._settled_frames = self._settled_frames + 1 if both else 0
        self.last_timing = FrameTiming(
            1e3 * (time.thread_time() - started) - self._caller_jobs_ms, tuple(self._phases),
            self.parallel)
        return {h: out[h] for h in HANDS}

    def _forget(self, hand: str) -> None:
        """Keep a lost hand's last position for ``max_gap_frames`` frames (continuity through
        a short loss or a crossing), then forget it."""
        self._missing[hand] += 1
        if self._missing[hand] > self.settings.max_gap_frames:
            self.previous[hand] = None
