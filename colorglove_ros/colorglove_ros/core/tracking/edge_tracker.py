"""DigitEyes bare-hand tracker over time: start from the documented initialisation pose, one
fit per frame (:mod:`edge_fit`), loss after a few bad frames (Rehg & Kanade 1993, section 5).

Start and loss: DigitEyes needs a starting pose. :class:`EdgeTracker` waits until the hand
holds still in the documented initialisation pose (:func:`initialisation_pose`: flat hand,
fingers slightly spread, palm to the primary camera, wrist at the marked spot
``init_wrist_position``) -- a fit from that pose that explains the edges for
``init_hold_frames`` frames in a row while moving less than ``init_hold_tolerance_m`` --
or until :meth:`EdgeTracker.initialize` gives it a pose (e.g. the glove tracker's). While
tracking, a frame whose fit leaves too few links found or too large a residual gives no
pose (with ``fault_round`` only after one more measurement round from its fit has failed
too); ``loss_patience`` such frames in a row declare the track lost and the tracker waits
for re-initialisation. A frame whose only fault is coverage (too few links found, a small
residual on those found) can instead be coasted through for ``coast_patience`` frames (off by
default), publishing nothing and keeping the track. With a background model per camera
(:class:`BackgroundModel`, the user's capture of the empty scene) each frame's silhouettes
join the fit and its drift checks (:class:`EdgeTrackerConfig`); a frame where only a finger
lies off its silhouette is withheld (no pose, reason ``finger withheld: ...``), the track kept.
"""
from __future__ import annotations

import math
import time
from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np

from colorglove_ros.core.camera import PinholeCamera
from colorglove_ros.core.hand.model import DIGITS, NUM_DOFS, HandModel
from colorglove_ros.core.tracking.edge_features import to_grey
from colorglove_ros.core.tracking.edge_fit import (
    EdgeFit,
    EdgeTrackerConfig,
    EdgeTrackerError,
    feature_points,
    fit_pose,
)
from colorglove_ros.core.tracking.kinematics import FastKinematics
from colorglove_ros.core.tracking.silhouette import BackgroundModel, Silhouette

__all__ = ['EdgeTrackResult', 'EdgeTracker', 'FINGER_WITHHELD', 'TRACKER_STATES',
           'initialisation_pose']

TRACKER_STATES = ('waiting', 'tracking')
FINGER_WITHHELD = 'finger withheld'   # the reason's start on a frame the finger check held back
_INIT_SPREAD_DEG = {'index': 6.0, 'middle': 0.0, 'ring': -6.0, 'little': -12.0}


def initialisation_pose(model: HandModel, wrist_position: Sequence[float],
                        rotation_vector: Sequence[float] = (0.0, 0.0, 0.0)) -> np.ndarray:
    """The documented starting pose: flat hand, fingers straight and slightly spread (index
    +6, middle 0, ring -6, little -12 degrees of abduction), thumb relaxed out (20 degrees CMC
    abduction), palm toward the primary camera (rotation vector 0: fingers up in the image),
    wrist at ``wrist_position`` (metres, primary camera frame)."""
    q = np.zeros(NUM_DOFS)
    q[0:3] = np.asarray(wrist_position, dtype=float)
    q[3:6] = np.asarray(rotation_vector, dtype=float)
    for digit, deg in _INIT_SPREAD_DEG.items():
        q[model.dof_names.index(f'{digit}_mcp_abd')] = np.deg2rad(deg)
    q[model.dof_names.index('thumb_cmc_abd')] = np.deg2rad(20.0)
    return model.clamp(q)


@dataclass(frozen=True)
class EdgeTrackResult:
    """One frame's output. ``q`` is the pose to publish, None when the frame gives none
    (``reason`` says why); ``state`` is the tracker's state after the frame ('waiting' for
    an initialisation or 'tracking'); ``fit`` the frame's fit (None if none was made);
    ``time_ms``, ``cpu_ms`` and ``thread_cpu_ms`` the wall-clock, CPU (this process, all
    threads) and CPU (the calling thread, which runs the whole tracker) time it took."""

    state: str
    q: np.ndarray | None
    reason: str
    fit: EdgeFit | None = None
    time_ms: float = 0.0
    cpu_ms: float = 0.0
    thread_cpu_ms: float = 0.0
    lost: bool = False
    initialised: bool = False
    hold_frames: int = 0


class EdgeTracker:
    """Temporal DigitEyes tracker over one or several calibrated cameras (the primary camera,
    ``cameras[0]``, has identity extrinsics; poses are in its optical frame). ``backgrounds``
    (one per camera, None where there is none) give the silhouettes."""

    def __init__(self, model: HandModel, cameras: Sequence[PinholeCamera],
                 config: EdgeTrackerConfig | None = None,
                 backgrounds: Sequence[BackgroundModel | None] | None = None) -> None:
        if not cameras:
            raise EdgeTrackerError('the edge tracker needs at least one camera')
        c0 = cameras[0]
        if not (np.allclose(c0.rotation, np.eye(3)) and np.allclose(c0.translation, 0.0)):
            raise EdgeTrackerError('cameras[0] (primary) must have identity extrinsics')
        self.model = model
        self.kin = FastKinematics(model)
        self.cameras = tuple(cameras)
        self.config = config or EdgeTrackerConfig()
        self.points = feature_points(model, self.config.tracked_links, self.config.use_tips,
                                     self.config.palm_sides)
        self.init_pose = initialisation_pose(model, self.config.init_wrist_position,
                                             self.config.init_rotation_vector)
        # the initialisation's fit starts far from the hand: it makes all of its rounds
        self._init_config = replace(self.config, round_min_move_px=0.0)
        self._names = tuple(c.name for c in self.cameras)
        self.backgrounds: tuple[BackgroundModel | None, ...] = (None,) * len(self.cameras)
        if backgrounds is not None:
            self.set_backgrounds(backgrounds)
        self._digit_dofs = [np.array([i for i, n in enumerate(model.dof_names)
                                      if n.startswith(f'{d}_')]) for d in DIGITS]
        self._retry_dofs = [model.dof_names.index(n) for n in self.config.retry_dofs]
        self._retry_digits = [DIGITS.index(n.split('_')[0]) for n in self.config.retry_dofs]
        self._q: np.ndarray | None = None
        self.fault_rounds = 0       # frames given the extra measurement round (fault_round)
        self._start_track()

    @property
    def state(self) -> str:
        """'tracking' while a track is held, else 'waiting' (for an initialisation)."""
        return 'tracking' if self._q is not None else 'waiting'

    @property
    def pose(self) -> np.ndarray | None:
        """The current estimate (None while waiting)."""
        return None if self._q is None else self._q.copy()

    def _start_track(self) -> None:
        """Clear what a track remembers (loss and coasting counts, the initialisation hold,
        the digits' explained angles and re-fit back-off)."""
        self._bad_frames = 0
        self._coast_frames = 0
        self._resume = 0
        self._hold: list[np.ndarray] = []
        self._good_digits: list[np.ndarray | None] = [None] * len(DIGITS)
        self._refit_failures = np.zeros(len(DIGITS), dtype=np.int64)
        self._refit_next = np.zeros(len(DIGITS), dtype=np.int64)
        self._frame = 0
        self._refit_tokens = float(self.config.finger_refit_burst)
        self._last_good: EdgeFit | None = None

    def reset(self) -> None:
        """Drop the track and wait for an initialisation."""
        self._q = None
        self._start_track()

    def initialize(self, q: np.ndarray) -> None:
        """Start tracking from a given pose (e.g. from the glove tracker)."""
        q = np.asarray(q, dtype=float)
        if q.shape != (NUM_DOFS,) or not np.all(np.isfinite(q)):
            raise EdgeTrackerError(f'initial pose must be 26 finite numbers, got {q.shape}')
        self._q = self.kin.clamp(q)
        self._start_track()

    def set_backgrounds(self, backgrounds: Sequence[BackgroundModel | None]) -> None:
        """Use these empty-scene models (one per camera, None for none) from now on."""
        if len(backgrounds) != len(self.cameras):
            raise EdgeTrackerError(f'{len(self.cameras)} camera(s) but {len(backgrounds)} '
                                   'background model(s)')
        for cam, bg in zip(self.cameras, backgrounds, strict=True):
            if bg is not None and (bg.width, bg.height) != (cam.width, cam.height):
                raise EdgeTrackerError(f'camera {cam.name!r} is {cam.width}x{cam.height} but '
                                       f'its background model {bg.width}x{bg.height}')
        self.backgrounds = tuple(backgrounds)

    def fit(self, images: Sequence[np.ndarray | None], q_start: np.ndarray,
            rounds: int | None = None) -> EdgeFit:
        """Fit one frame from ``q_start`` without touching the tracker's state."""
        greys = self._greys(images)
        return fit_pose(self.kin, self.points, self.cameras, greys, q_start, self.config,
                        rounds or self.config.measurement_rounds,
                        silhouettes=self._silhouettes(images, q_start))

    def _silhouettes(self, images: Sequence[np.ndarray | None], q: np.ndarray
                     ) -> list[Silhouette | None]:
        """Each camera's silhouette within ``silhouette_margin_px`` of the box around the
        feature points of pose ``q``, the pose the fit starts from."""
        if all(bg is None for bg in self.backgrounds):
            return [None] * len(self.cameras)
        world = self.kin.points(q, self.points.point_link, self.points.point_local, False)[0]
        m = self.config.silhouette_margin_px
        out: list[Silhouette | None] = []
        for cam, bg, img in zip(self.cameras, self.backgrounds, images, strict=True):
            if bg is None or img is None:
                out.append(None)
                continue
            pix = cam.project(cam.world_to_camera(world))
            pix = pix[np.all(np.isfinite(pix), axis=1)]
            region = None if not len(pix) else (*(pix.min(axis=0) - m), *(pix.max(axis=0) + m))
            out.append(bg.silhouette(img, region))
        return out

    def _greys(self, images: Sequence[np.ndarray | None]) -> list[np.ndarray | None]:
        if len(images) != len(self.cameras):
            raise EdgeTrackerError(f'{len(self.cameras)} camera(s) but {len(images)} image(s)')
        greys = []
        for cam, img in zip(self.cameras, images, strict=True):
            if img is None:
                greys.append(None)
                continue
            grey = to_grey(img)
            if grey.shape != (cam.height, cam.width):
                raise EdgeTrackerError(f'camera {cam.name!r} is {cam.width}x{cam.height} but '
                                       f'its image is {grey.shape[1]}x{grey.shape[0]}')
            greys.append(grey)
        if all(g is None for g in greys):
            raise EdgeTrackerError('no image from any camera')
        return greys

    def _fit_problem(self, fit: EdgeFit) -> str:
        """'' if the fit explains the edges, else the reason it does not (the finger check
        aside: a re-fit candidate or an initialisation is judged as a whole hand)."""
        return self._check_fit(fit, fingers=False)[1]

    def _check_fit(self, fit: EdgeFit, fingers: bool = True) -> tuple[str, str]:
        """(kind, reason) of a fit that does not explain the edges, ('', '') if it does:
        kind 'coverage' when too few links were found (in a camera or over all) but the
        residual of those found is small, 'drift' when the residual is too large, nothing
        was found or the pose is not finite, 'finger' (with ``fingers``) when the hand passes
        but one of ``finger_check_digits`` has more than ``max_finger_off_silhouette`` of its
        axis points off the silhouette in some camera."""
        cfg = self.config
        if not np.all(np.isfinite(fit.q)):
            return 'drift', 'non-finite pose'
        if fit.found_fraction == 0.0:
            return 'drift', 'no link found'
        if not fit.rms_px <= cfg.max_rms_px:
            return 'drift', f'edge residual {fit.rms_px:.1f} px > {cfg.max_rms_px:.1f} px'
        if fit.off_silhouette > cfg.max_off_silhouette:
            return 'drift', (f'{fit.off_silhouette:.0%} of the hand axis off the silhouette '
                             f'(max {cfg.max_off_silhouette:.0%})')
        if fit.unexplained > cfg.max_unexplained:
            return 'drift', (f'{fit.unexplained:.0%} of the hand silhouette unexplained (max '
                             f'{cfg.max_unexplained:.0%})')
        if cfg.camera_check and fit.camera_disagreement_mm > cfg.max_camera_disagreement_mm:
            return 'drift', (f'the primary camera alone puts a fingertip '
                             f'{fit.camera_disagreement_mm:.0f} mm from the joint fit (max '
                             f'{cfg.max_camera_disagreement_mm:.0f} mm)')
        for name, found, usable in zip(self._names, fit.links_found, fit.links_usable,
                                       strict=True):
            if usable and found < cfg.min_camera_found_fraction * usable:
                return 'coverage', (f'{found} of {usable} links found in {name} '
                                    f'(need {cfg.min_camera_found_fraction:.0%})')
        if fit.found_fraction < cfg.min_found_fraction:
            return 'coverage', (f'{sum(fit.links_found)} of {sum(fit.links_usable)} links '
                                f'found (need {cfg.min_found_fraction:.0%})')
        if fingers:
            for name in cfg.finger_check_digits:
                off = fit.finger_off_silhouette[DIGITS.index(name)]
                if off > cfg.max_finger_off_silhouette:
                    return 'finger', (f'{name} finger: {off:.0%} of its axis off the '
                                      f'silhouette (max {cfg.max_finger_off_silhouette:.0%})')
        return '', ''

    def update(self, images: Sequence[np.ndarray | None]) -> EdgeTrackResult:
        """Process one frame: one image per camera (grey or RGB; None if a camera has no
        frame). Returns the pose to publish or the reason there is none."""
        t0, c0, h0 = time.perf_counter(), time.process_time(), time.thread_time()
        start = self.init_pose if self._q is None else self._q
        result = self._step(self._greys(images), self._silhouettes(images, start))
        return replace(result, time_ms=1e3 * (time.perf_counter() - t0),
                       cpu_ms=1e3 * (time.process_time() - c0),
                       thread_cpu_ms=1e3 * (time.thread_time() - h0))

    def _step(self, greys: list[np.ndarray | None],
              silhouettes: list[Silhouette | None]) -> EdgeTrackResult:
        """One frame's state machine (initialisation, fit, loss), untimed."""
        cfg = self.config
        if self._q is None:
            fit = fit_pose(self.kin, self.points, self.cameras, greys, self.init_pose,
                           self._init_config, cfg.init_rounds, silhouettes=silhouettes)
            reason = self._fit_problem(fit)
            offset = float(np.linalg.norm(fit.q[0:3] - self.init_pose[0:3]))
            if not reason and offset > cfg.init_max_offset_m:
                reason = f'hand {100 * offset:.0f} cm from the marked spot'
            if reason:
                self._hold = []
            else:
                if self._hold and np.linalg.norm(fit.q[0:3] - self._hold[-1][0:3]) \
                        > cfg.init_hold_tolerance_m:
                    self._hold = []
                self._hold.append(fit.q)
            held = len(self._hold)
            if held >= cfg.init_hold_frames:
                self.initialize(fit.q)
                return EdgeTrackResult('tracking', fit.q.copy(), 'initialised', fit,
                                       initialised=True, hold_frames=held)
            why = reason or f'holding still {held}/{cfg.init_hold_frames} frames'
            return EdgeTrackResult(
                'waiting', None, 'waiting for the initialisation pose (flat hand, palm to the '
                f'camera, at the marked spot): {why}', fit, hold_frames=held)
        fit = fit_pose(self.kin, self.points, self.cameras, greys, self._q, cfg,
                       cfg.measurement_rounds, silhouettes=silhouettes)
        if cfg.fault_round and self._check_fit(fit)[0]:
            # measured again where the first fit went, anchored where the frame started
            fit = fit_pose(self.kin, self.points, self.cameras, greys, fit.q, cfg, 1,
                           silhouettes=silhouettes, anchor=self._q)
            self.fault_rounds += 1
        if cfg.finger_refit:
            fit = self._refit_digits(greys, silhouettes, fit)
        kind, reason = self._check_fit(fit)
        if self._retry_dofs:
            fit, kind, reason = self._retry(greys, silhouettes, fit, kind, reason)
        if not np.all(np.isfinite(fit.q)):
            self.reset()
            return EdgeTrackResult('waiting', None, 'lost: non-finite pose', fit, lost=True)
        self._q = fit.q
        if kind == 'coverage' and self._coast_frames < cfg.coast_patience:
            # too few features this frame, those found agree: keep the pose, publish nothing
            self._coast_frames += 1
            self._bad_frames = 0
            self._resume = cfg.resume_frames
            return EdgeTrackResult('tracking', None, f'coasting: {reason}', fit)
        if kind == 'finger':
            # the hand explains its edges and silhouettes but one finger lies off its
            # silhouette: keep the track, publish nothing
            self._bad_frames = 0
            self._coast_frames = 0
            return EdgeTrackResult('tracking', None, f'{FINGER_WITHHELD}: {reason}', fit)
        if kind:
            self._bad_frames += 1
            if self._bad_frames >= cfg.loss_patience:
                self.reset()
                return EdgeTrackResult('waiting', None, f'lost: {reason}', fit, lost=True)
            return EdgeTrackResult('tracking', None, f'poor fit: {reason}', fit)
        self._bad_frames = 0
        self._coast_frames = 0
        self._last_good = fit
        if self._resume > 0:
            self._resume -= 1
            return EdgeTrackResult('tracking', None, 'resuming after coasting: '
                                   f'{self._resume + 1} more good frame(s) needed', fit)
        return EdgeTrackResult('tracking', fit.q.copy(), 'tracking', fit)

    def _refit_digits(self, greys: list[np.ndarray | None],
                      silhouettes: list[Silhouette | None], fit: EdgeFit) -> EdgeFit:
        """``finger_refit``: where a digit leaves more than ``max_finger_unexplained`` of the
        hand's foreground unexplained, re-fit it from its angles on the last frame where it
        was explained and from the initialisation pose's; if it still leaves too much, its
        neighbours likewise (a finger that drifted off its place leaves pixels nearest to the
        next one). A re-fit passing every check is kept when it leaves less near that digit
        (then less of the hand) unexplained. A digit its re-fit left unexplained waits before
        the next (:meth:`_refit_due`)."""
        cfg = self.config
        shares = np.asarray(fit.finger_unexplained)
        if not np.all(np.isfinite(shares)):
            return fit
        self._frame += 1
        if cfg.finger_refit_budget > 0:
            self._refit_tokens = min(self._refit_tokens + cfg.finger_refit_budget,
                                     float(cfg.finger_refit_burst))
        for d in np.argsort(-shares):
            if not fit.finger_unexplained[d] > cfg.max_finger_unexplained \
                    or self._frame < self._refit_next[d]:
                continue
            for e in (d, d - 1, d + 1):
                if not 0 <= e < len(DIGITS) or not fit.finger_unexplained[d] \
                        > cfg.max_finger_unexplained:
                    continue
                dofs = self._digit_dofs[e]
                free = self._free_dofs(e)
                best = fit
                for angles in self._refit_starts(e, fit.q):
                    if cfg.finger_refit_budget > 0:
                        if self._refit_tokens < 1.0:
                            break
                        self._refit_tokens -= 1.0
                    q0 = fit.q.copy()
                    q0[dofs] = angles
                    cand = fit_pose(self.kin, self.points, self.cameras, greys, q0, cfg,
                                    cfg.finger_refit_rounds, silhouettes=silhouettes,
                                    held=None if free.all() else ~free)
                    if not self._fit_problem(cand) and \
                            (cand.finger_unexplained[d], cand.unexplained) \
                            < (best.finger_unexplained[d], best.unexplained):
                        best = cand
                fit = best
            self._refit_due(d, fit.finger_unexplained[d] <= cfg.max_finger_unexplained)
        for d, share in enumerate(fit.finger_unexplained):
            if share <= cfg.max_finger_unexplained:
                self._good_digits[d] = fit.q[self._digit_dofs[d]].copy()
                self._refit_failures[d] = 0
                self._refit_next[d] = 0
        return fit

    def _refit_starts(self, digit: int, q: np.ndarray) -> list[np.ndarray]:
        """The angles of ``digit`` the re-fit candidates start from (``finger_refit_abduction``):
        its angles on the last frame where it was explained (if any) and the initialisation
        pose's, each with its abduction (the first of its DOFs) from those angles ('start'),
        kept at pose ``q``'s ('kept'), or one candidate of each ('both'); 'spread': both kept
        at ``q``'s, and the explained angles also with it moved ``finger_refit_spread_deg``
        out and in (within the joint limits). Re-fits that hold the digit's abduction
        (``finger_refit_dofs`` 'abduction', 'flexion') keep it."""
        dofs = self._digit_dofs[digit]
        mode = 'kept' if self.config.finger_refit_dofs in ('flexion', 'abduction') \
            else self.config.finger_refit_abduction
        out = []
        for angles in (self._good_digits[digit], self.init_pose[dofs]):
            if angles is None:
                continue
            kept = angles.copy()
            kept[0] = q[dofs[0]]
            if mode in ('kept', 'both'):
                out.append(kept)
            if mode == 'spread':
                out.append(kept)
                if angles is self._good_digits[digit]:
                    step = math.radians(self.config.finger_refit_spread_deg)
                    for sign in (1.0, -1.0):
                        moved = kept.copy()
                        moved[0] = np.clip(kept[0] + sign * step, self.kin.lower[dofs[0]],
                                           self.kin.upper[dofs[0]])
                        if moved[0] != kept[0]:
                            out.append(moved)
            if mode in ('start', 'both') and not (mode == 'both' and kept[0] == angles[0]):
                out.append(angles)
        return out

    def _free_dofs(self, digit: int) -> np.ndarray:
        """(26,) the DOFs a re-fit of ``digit`` fits (``finger_refit_dofs``): every DOF
        ('hand'), all but the digit's abduction, the first of its DOFs ('abduction'), the
        digit's own ('digit') or its flexions alone ('flexion'); the others stay at the
        frame's fit."""
        mode = self.config.finger_refit_dofs
        free = np.ones(NUM_DOFS, dtype=bool)
        if mode == 'abduction':
            free[self._digit_dofs[digit][0]] = False
        elif mode != 'hand':
            free[:] = False
            free[self._digit_dofs[digit]] = True
            if mode == 'flexion':
                free[self._digit_dofs[digit][0]] = False
        return free

    def _retry(self, greys: list[np.ndarray | None], silhouettes: list[Silhouette | None],
               fit: EdgeFit, kind: str, reason: str) -> tuple[EdgeFit, str, str]:
        """``retry_dofs``: where the fit failed or missed a usable link of a retried DOF's
        digit, fits from the previous pose with that angle ``retry_step_deg`` up and down,
        then twice that and so on (``retry_steps``; nearest first, stopping once a candidate
        finds the whole digit); the best candidate that passes every check and finds more of
        the digit's links and keeps the rest of the hand as it was (:meth:`_retry_guard`),
        else the fit as it was, with its (kind, reason)."""
        cfg = self.config
        assert self._q is not None
        step = np.radians(cfg.retry_step_deg)
        for dof, digit in zip(self._retry_dofs, self._retry_digits, strict=True):
            found, usable = fit.digit_links_found[digit], fit.digit_links_usable[digit]
            if not kind and found >= usable:
                continue
            best, best_key = None, (found if not kind else -1, sum(fit.links_found),
                                    -fit.rms_px)
            tried: list[float] = []
            for k in range(1, cfg.retry_steps + 1):
                for sign in (1.0, -1.0):
                    q0 = self._q.copy()
                    q0[dof] += sign * k * step
                    q0 = self.kin.clamp(q0)
                    if any(abs(q0[dof] - t) < 1e-9 for t in (self._q[dof], *tried)):
                        continue            # past the joint limit: already tried
                    tried.append(q0[dof])
                    cand = fit_pose(self.kin, self.points, self.cameras, greys, q0, cfg,
                                    cfg.measurement_rounds, silhouettes=silhouettes)
                    key = (cand.digit_links_found[digit], sum(cand.links_found), -cand.rms_px)
                    if not self._check_fit(cand)[0] and key > best_key \
                            and self._retry_guard(cand, digit):
                        best, best_key = cand, key
                if best is not None and best_key[0] >= best.digit_links_usable[digit]:
                    break                   # the digit found whole: no farther start
            if best is not None:
                fit, kind, reason = best, '', ''
        return fit, kind, reason

    def _retry_guard(self, cand: EdgeFit, digit: int) -> bool:
        """Whether a retried candidate leaves the rest of the hand as it was: its wrist within
        ``retry_max_wrist_move_m`` of the previous pose's and, with ``retry_rest_margin_px``
        finite and a good frame since the track started, at least as many links found
        outside ``digit`` as that frame's fit and an edge residual at most the margin above
        its."""
        cfg = self.config
        assert self._q is not None
        if not np.linalg.norm(cand.q[0:3] - self._q[0:3]) <= cfg.retry_max_wrist_move_m:
            return False
        ref = self._last_good
        if not np.isfinite(cfg.retry_rest_margin_px) or ref is None:
            return True
        rest = sum(cand.links_found) - cand.digit_links_found[digit]
        return rest >= sum(ref.links_found) - ref.digit_links_found[digit] \
            and cand.rms_px <= ref.rms_px + cfg.retry_rest_margin_px

    def _refit_due(self, digit: int, fixed: bool) -> None:
        """After a re-fit of ``digit``: a re-fit that left it unexplained makes it wait
        ``finger_refit_backoff`` frames, twice as long after each further such re-fit in a
        row (at most ``finger_refit_max_wait``); one that explained it clears the count."""
        cfg = self.config
        if fixed or cfg.finger_refit_backoff == 0:
            self._refit_failures[digit] = 0
            return
        self._refit_failures[digit] += 1
        wait = cfg.finger_refit_backoff * 2 ** (int(self._refit_failures[digit]) - 1)
        self._refit_next[digit] = self._frame + 1 + min(wait, cfg.finger_refit_max_wait)

    def with_config(self, **changes: object) -> EdgeTracker:
        """A fresh tracker on the same model and cameras with some settings changed."""
        return EdgeTracker(self.model, self.cameras, replace(self.config, **changes),
                           self.backgrounds)
