"""One frame's DigitEyes fit of the bare hand: predicted link axes and fingertips, their
measurement, the residuals and the stabilised Gauss-Newton over one or several calibrated
cameras (Rehg & Kanade 1993, sections 3-4). :mod:`edge_tracker` runs it frame after frame.

Per camera the current pose predicts every finger link as a projected cylinder axis (its
base and end points) and every fingertip as the projected centre of its hemisphere;
:mod:`edge_features` measures the axes and tips near those predictions. The residuals are
the paper's:

* link: the signed pixel distance of the predicted axis end points (base and end) from the
  measured line, ``n . x(q) - rho`` (two rows per link);
* tip: predicted minus measured tip centre (two rows per tip);
* palm side (not in the paper): the palm's outline on its ulnar (and optionally radial) side,
  measured as a single silhouette edge (:func:`measure_outline_edges`), with the same signed
  distances for the end points of the palm surface's silhouette generator seen from that
  camera (:func:`palm_outline`). Without it nothing measures the palm: tilting the hand about
  its width while flexing the fingers at their bases the other way changes few finger edges,
  and the tracks drifted that way.

All cameras' residuals are concatenated (a link seen by one camera still counts) and the
pose is corrected by Gauss-Newton with a constant diagonal stabiliser ``S``,
``q <- q - (J^T W J + S)^-1 J^T W R``, projected onto the joint limits (a DOF at a bound
whose step points outward is frozen). ``W`` is 1 for plain least squares (the paper) or,
with ``huber_px > 0``, robust weights at that scale (Cauchy by default: an edge taken from
a neighbouring finger, many pixels off, barely pulls; Huber as an option). The pose and the
Jacobians come from the existing 26-DOF :class:`HandModel` through :class:`FastKinematics`
(same numbers, faster).

The residual functions (:func:`link_axis_residuals`, :func:`tip_residuals`) take predicted
pixels and their Jacobians, so other trackers (the glove IK) can add the same constraints.
"""
from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from typing import Any, TypeVar

import cv2
import numpy as np

from colorglove_ros.core.camera import PinholeCamera
from colorglove_ros.core.errors import ColorGloveError
from colorglove_ros.core.geometry import rotvec_to_matrix
from colorglove_ros.core.hand.keypoints import FINGERTIP_INDICES
from colorglove_ros.core.hand.mesh import build_hand_mesh
from colorglove_ros.core.hand.model import (
    DIGITS,
    DOF_NAMES,
    LINK_NAMES,
    NUM_DOFS,
    HandModel,
    digit_link_index,
)
from colorglove_ros.core.tracking.edge_features import (
    EdgeSearchConfig,
    LinkAxes,
    TipPoints,
    compiled_kernels,
    fixed_linspace,
    measure_link_axes,
    measure_outline_edges,
    measure_tips,
    segment_distances,
)
from colorglove_ros.core.tracking.kinematics import FastKinematics
from colorglove_ros.core.tracking.silhouette import HandOutline, Silhouette

__all__ = [
    'EdgeTrackerError', 'EdgeTrackerConfig', 'DEFAULT_TRACKED_LINKS', 'FeaturePoints',
    'feature_points', 'EdgePrediction', 'EdgeMeasurement', 'EdgeFit', 'link_axis_residuals',
    'tip_residuals', 'predict_features', 'measure_features', 'stack_residuals', 'fit_pose',
    'fingertip_disagreement', 'hand_outline', 'LineRows', 'line_rows', 'even_subsample',
    'REFIT_DOFS', 'REFIT_ABDUCTION',
]

# every phalanx except the thumb metacarpal, which lies inside the palm's outline
DEFAULT_TRACKED_LINKS: tuple[str, ...] = tuple(
    name for name in LINK_NAMES[1:] if name != 'thumb_metacarpal')


PALM_SIDES = ('ulnar', 'radial')
ROBUST_LOSSES = ('huber', 'cauchy')
REFIT_DOFS = ('hand', 'abduction', 'digit', 'flexion')   # what a re-fit candidate fits
REFIT_ABDUCTION = ('start', 'kept', 'both', 'spread')   # where its abduction starts
# viewing angles of the palm-side silhouette generators (see palm_outline)
PALM_ANGLES = np.deg2rad(np.linspace(-75.0, 75.0, 7))
_PALM_OCCLUDER_POINTS = 160       # palm mesh vertices kept as the palm occluder


class EdgeTrackerError(ColorGloveError):
    """Bad tracker input: cameras, images, configuration or pose shapes."""


@dataclass(frozen=True)
class EdgeTrackerConfig:
    """Everything the edge tracker can be tuned by (pixels, metres, radians).

    ``stabilizer`` is the diagonal of ``S`` for (translation, rotation, finger) DOFs in
    px^2 per unit^2: the larger, the smaller and steadier each Gauss-Newton step.
    ``robust_loss`` with ``huber_px`` sets the residual weights (:func:`_robust`).
    ``min_found_fraction`` of the usable links must be found over all cameras together and
    ``min_camera_found_fraction`` in each camera for a fit to count as good (the 45-degree
    camera of the stereo rig often finds one of its links while the primary finds all of
    theirs, at poses as good as their neighbours': 0.1 lets one of up to ten pass).
    ``palm_sides`` are the palm outline sides measured (``PALM_SIDES``; empty: the paper's
    link and tip features only), on ``palm_slice_range`` of each side, weighted
    ``palm_weight``. A tracked frame whose only fault is too few links found (the residual
    of those found is small) is coasted through, up to ``coast_patience`` frames in a row
    (no pose published, the track kept), and ``resume_frames`` good frames must follow before
    the tracker publishes again; other bad frames count toward ``loss_patience``.
    ``measurement_rounds``: measure-and-fit rounds per tracked frame (each measures the edges
    at the pose the previous round reached; two by default, with ``fault_round`` and
    ``min_camera_found_fraction`` 0.1: with them the two-camera bare-hand runs and fingertips
    and the 3-D mouse's tuning clicks were better than with one round, docs/RESULTS.md,
    DigitEyes eighteenth pass). ``fault_round``: a tracked frame whose fit fails
    a check (too few links found, residual or silhouette drift) is measured and fitted once
    more from that fit's pose, the stabiliser still anchored at the previous frame's pose (as
    a further round would be), before the finger re-fits and the checks judge it: the first
    fit is often close enough for the second measurement to find the links the first missed
    (the 45-degree camera's above all); a fit that still fails publishes nothing.
    ``round_min_move_px`` > 0 (6 by default; 0: every round): a tracked frame's fit and a
    finger re-fit's make a further round only when the round before moved some feature point
    by more than this many pixels in some camera (the initialisation's fit, which starts far
    from the hand, makes all of its rounds): on fresh held-out seeds it kept the two-camera
    bare-hand runs and the 3-D mouse's clicks with less CPU than two full rounds
    (docs/RESULTS.md, DigitEyes nineteenth pass and the lead's decision after it).
    Link slices hidden behind the palm (:func:`_behind_palm`, points within
    ``palm_occlusion_px``; 0 turns it off) are not searched nor counted as missing.
    ``camera_weights`` scale each camera's residual weights in the fit
    (camera i gets ``camera_weights[i]``, 1 beyond the tuple's end): the second camera of
    the stereo rig looks at the hand from 45 degrees, where fingers lie side by side and their
    edges are often taken from a neighbour, so its residuals count a quarter.
    ``camera_check`` (two or more cameras): the primary camera's measurements are also fitted
    alone, from the same start, and a fit whose fingertips (relative to the wrist) lie more
    than ``max_camera_disagreement_mm`` from that fit's counts as drift: the cameras' edges
    disagree, so at least one of them was taken from the wrong place.
    Silhouettes (:mod:`silhouette`, given per camera to :func:`fit_pose`; none: all of this
    is off): with ``silhouette_weight`` > 0 the fit also pulls the hand's axis points that
    fall more than ``silhouette_tolerance_px`` off the foreground back onto it, and its link
    capsules toward up to ``silhouette_points`` foreground pixels that no part of the hand
    explains (farther than the tolerance from every capsule, tip and the palm); a fit
    whose share of such axis points exceeds ``max_off_silhouette`` or whose unexplained
    share of the hand's foreground exceeds ``max_unexplained`` (in any camera) counts as
    drift (1.0: never). With ``silhouette_palm`` (on by default) the unexplained pixels nearer
    the palm's outline than to every capsule (up to ``silhouette_points`` more) pull the palm's
    outline toward them, moving the wrist (needs a palm side: the palm's rigid feature points).
    ``silhouette_palm`` and ``finger_refit`` are on by default: with them the held-out
    bare-hand runs with two cameras last the whole sequence, and the 3-D mouse's clicks are
    about as good as without (docs/RESULTS.md, DigitEyes thirteenth and sixteenth passes);
    without silhouettes neither acts, so a tracker given no background images fits as with
    both off. Each
    frame's silhouette is found only within
    ``silhouette_margin_px`` of the box around the pose it starts from.
    ``finger_refit`` (with silhouettes; on by default): each fit also measures, per digit, the
    share of the
    hand's foreground left unexplained nearest to that digit's capsules
    (:func:`silhouette_measures`); a tracked frame where a digit's share exceeds
    ``max_finger_unexplained`` re-fits that digit from other starting angles (its angles on
    the last frame where it was explained, and the initialisation pose's), each with
    ``finger_refit_rounds`` measurement rounds, and keeps the fit that leaves the least of
    that digit unexplained (:class:`EdgeTracker`); a re-fit that leaves the digit unexplained
    makes it wait ``finger_refit_backoff`` tracked frames before the next (0: none), twice as
    long after each further such re-fit in a row, at most ``finger_refit_max_wait``.
    ``finger_refit_budget`` > 0 bounds the re-fits' CPU: each tracked frame adds that many
    re-fit candidates (fits from another start) to an allowance of at most
    ``finger_refit_burst``, each candidate takes one, and none is tried without.
    ``finger_refit_dofs`` says what a candidate fits ('hand', the default: every DOF;
    'abduction': all but the re-fitted digit's abduction; 'digit': that digit's DOFs alone;
    'flexion': its flexions alone), the rest held at the frame's fit;
    ``finger_refit_abduction`` where its abduction starts ('start', the default: with the
    other start angles; 'kept': at the frame's fit; 'both': one candidate of each;
    'spread': kept, and from the explained angles also moved ``finger_refit_spread_deg`` out
    and in). None of these brought the 3-D mouse's clicks on its check seeds up to the
    defaults' (docs/RESULTS.md, DigitEyes fifteenth pass), so the defaults are the earlier
    re-fit's.
    ``max_finger_off_silhouette`` (with silhouettes; 1, the default: off; 0.15 removes most
    drifted fingers on the bare-hand sequences but withholds most frames of the 3-D mouse's
    table views, docs/RESULTS.md, DigitEyes ninth pass): a fit whose hand passes every
    check but where one of ``finger_check_digits`` has more than this share of its axis points
    (its links' base, middle and end, its tip) off the foreground in some camera publishes no
    pose, the track kept (the finger drifted: the fitted finger lies over the background).
    The thumb is left out by default: its model axis lies off its silhouette even at the true
    pose.
    ``retry_dofs`` (DOF names; empty, the default: off): a tracked frame whose fit fails a
    check (too few links found, residual or silhouette drift) or misses a usable link of
    the digit of one of these DOFs is fitted again from the previous pose with that angle
    moved ``retry_step_deg`` up and down, then twice and up to ``retry_steps`` times that
    (nearest first, until a candidate finds the whole digit); a candidate that passes every
    check and finds more of that digit's links (then more links, then a smaller residual)
    replaces the fit: a digit that moved faster than the edge search reaches (the 3-D
    mouse's thumb clicks) is looked for where it went instead of being left behind. On the
    mouse's table views it lets the tracker follow the thumb's clicks itself (with one camera
    it makes most of them), but it keeps drifted hands tracked (a larger cursor error), costs
    CPU and is not measured on the bare-hand sequences (docs/RESULTS.md, DigitEyes tenth and
    eleventh passes), so it is off. Two guards (inf: off) keep a candidate only when the rest
    of the hand stays as it was: ``retry_max_wrist_move_m``, its wrist within that distance
    of the previous pose's;
    ``retry_rest_margin_px``, it finds at least as many links outside the retried digit as
    the last good frame's fit and its edge residual is at most that much above that fit's.
    """

    search: EdgeSearchConfig = field(default_factory=EdgeSearchConfig)
    tracked_links: tuple[str, ...] = DEFAULT_TRACKED_LINKS
    use_tips: bool = True
    palm_sides: tuple[str, ...] = ('ulnar',)
    palm_slice_range: tuple[float, float] = (0.15, 0.95)
    palm_weight: float = 1.0
    camera_weights: tuple[float, ...] = (1.0, 0.25)
    polarity: int = 0
    measurement_rounds: int = 2
    fault_round: bool = True
    round_min_move_px: float = 6.0
    gn_iterations: int = 3
    stabilizer: tuple[float, float, float] = (4.0e4, 1.0e3, 200.0)
    tip_weight: float = 1.0
    huber_px: float = 3.0
    robust_loss: str = 'cauchy'
    coupling_weight: float = 2000.0
    min_link_px: float = 10.0
    min_depth_m: float = 0.1
    occlusion_margin_px: float = 2.0
    palm_occlusion_px: float = 10.0
    min_found_fraction: float = 0.6
    min_camera_found_fraction: float = 0.1
    max_rms_px: float = 3.0
    camera_check: bool = False
    max_camera_disagreement_mm: float = 10.0
    silhouette_weight: float = 0.3
    silhouette_tolerance_px: float = 4.0
    silhouette_points: int = 80
    silhouette_palm: bool = True
    max_off_silhouette: float = 1.0
    max_unexplained: float = 0.08
    finger_refit: bool = True
    max_finger_unexplained: float = 0.01
    finger_refit_rounds: int = 2
    finger_refit_backoff: int = 0
    finger_refit_max_wait: int = 16
    finger_refit_budget: float = 0.0
    finger_refit_burst: int = 6
    finger_refit_dofs: str = 'hand'
    finger_refit_abduction: str = 'start'
    finger_refit_spread_deg: float = 8.0
    max_finger_off_silhouette: float = 1.0
    finger_check_digits: tuple[str, ...] = ('index', 'middle', 'ring', 'little')
    retry_dofs: tuple[str, ...] = ()
    retry_step_deg: float = 12.0
    retry_steps: int = 3
    retry_max_wrist_move_m: float = math.inf
    retry_rest_margin_px: float = math.inf
    silhouette_margin_px: float = 60.0
    loss_patience: int = 3
    coast_patience: int = 0
    resume_frames: int = 0
    init_wrist_position: tuple[float, float, float] = (0.0, 0.095, 0.5)
    init_rotation_vector: tuple[float, float, float] = (0.0, 0.0, 0.0)
    init_rounds: int = 6
    init_hold_frames: int = 8
    init_hold_tolerance_m: float = 0.004
    init_max_offset_m: float = 0.05

    def __post_init__(self) -> None:
        unknown = [n for n in self.tracked_links if n not in LINK_NAMES[1:]]
        if unknown or not self.tracked_links:
            raise EdgeTrackerError(f'tracked_links must be finger links, got {unknown or "none"}')
        unknown_sides = [n for n in self.palm_sides if n not in PALM_SIDES]
        if unknown_sides:
            raise EdgeTrackerError(f'palm_sides must be among {PALM_SIDES}, got {unknown_sides}')
        if self.robust_loss not in ROBUST_LOSSES:
            raise EdgeTrackerError(f'robust_loss must be one of {ROBUST_LOSSES}, got '
                                   f'{self.robust_loss!r}')
        if self.polarity not in (-1, 0, 1):
            raise EdgeTrackerError(f'polarity must be -1, 0 or 1, got {self.polarity}')
        if self.measurement_rounds < 1 or self.gn_iterations < 1 or self.init_rounds < 1:
            raise EdgeTrackerError('measurement_rounds, gn_iterations, init_rounds must be >= 1')
        if not self.round_min_move_px >= 0:
            raise EdgeTrackerError(f'round_min_move_px must be >= 0, got {self.round_min_move_px}')
        if any(not w >= 0 for w in self.camera_weights):
            raise EdgeTrackerError(f'camera_weights must be >= 0, got {self.camera_weights}')
        if len(self.stabilizer) != 3 or min(self.stabilizer) < 0:
            raise EdgeTrackerError(f'stabilizer needs 3 values >= 0, got {self.stabilizer}')
        if not 0.0 < self.min_found_fraction <= 1.0 or self.max_rms_px <= 0 \
                or not 0.0 <= self.min_camera_found_fraction <= 1.0:
            raise EdgeTrackerError('min_found_fraction must be in (0, 1], '
                                   'min_camera_found_fraction in [0, 1], max_rms_px > 0')
        if self.coast_patience < 0 or self.resume_frames < 0:
            raise EdgeTrackerError('coast_patience and resume_frames must be >= 0')
        if self.silhouette_weight < 0 or self.silhouette_tolerance_px < 0 \
                or self.silhouette_points < 0 or not 0.0 <= self.max_off_silhouette <= 1.0 \
                or not 0.0 <= self.max_unexplained <= 1.0:
            raise EdgeTrackerError('silhouette_weight, silhouette_tolerance_px, '
                                   'silhouette_points must be >= 0, max_off_silhouette and '
                                   'max_unexplained in [0, 1]')
        if not 0.0 <= self.max_finger_unexplained <= 1.0 or self.finger_refit_rounds < 1 \
                or self.finger_refit_backoff < 0 \
                or self.finger_refit_max_wait < self.finger_refit_backoff \
                or not self.finger_refit_budget >= 0 or self.finger_refit_burst < 1:
            raise EdgeTrackerError('max_finger_unexplained must be in [0, 1], '
                                   'finger_refit_rounds >= 1, '
                                   '0 <= finger_refit_backoff <= finger_refit_max_wait, '
                                   'finger_refit_budget >= 0, finger_refit_burst >= 1')
        if self.finger_refit_abduction not in REFIT_ABDUCTION \
                or not self.finger_refit_spread_deg > 0:
            raise EdgeTrackerError(f'finger_refit_abduction must be one of {REFIT_ABDUCTION}, '
                                   f'finger_refit_spread_deg > 0, got '
                                   f'{self.finger_refit_abduction!r}, '
                                   f'{self.finger_refit_spread_deg}')
        if self.finger_refit_dofs not in REFIT_DOFS:
            raise EdgeTrackerError(f'finger_refit_dofs must be one of {REFIT_DOFS}, got '
                                   f'{self.finger_refit_dofs!r}')
        if not 0.0 <= self.max_finger_off_silhouette <= 1.0 \
                or any(d not in DIGITS for d in self.finger_check_digits):
            raise EdgeTrackerError(f'max_finger_off_silhouette must be in [0, 1] and '
                                   f'finger_check_digits among {DIGITS}')
        if self.loss_patience < 1 or self.init_hold_frames < 1:
            raise EdgeTrackerError('loss_patience and init_hold_frames must be >= 1')
        if any(n not in DOF_NAMES[6:] for n in self.retry_dofs) or not self.retry_step_deg > 0 \
                or self.retry_steps < 1 or not self.retry_max_wrist_move_m > 0 \
                or not self.retry_rest_margin_px >= 0:
            raise EdgeTrackerError(f'retry_dofs must be joint DOF names, retry_step_deg > 0, '
                                   f'retry_steps >= 1, retry_max_wrist_move_m > 0 and '
                                   f'retry_rest_margin_px >= 0, got {self.retry_dofs}, '
                                   f'{self.retry_step_deg}, {self.retry_steps}, '
                                   f'{self.retry_max_wrist_move_m}, '
                                   f'{self.retry_rest_margin_px}')

    def stabilizer_diagonal(self) -> np.ndarray:
        """The (26,) diagonal of S."""
        t, r, f = self.stabilizer
        return np.concatenate([np.full(3, t), np.full(3, r), np.full(NUM_DOFS - 6, f)])


# ---------------------------------------------------------------------------- residuals
def link_axis_residuals(normal: np.ndarray, offset: np.ndarray, base_px: np.ndarray,
                        end_px: np.ndarray, base_jacobian: np.ndarray,
                        end_jacobian: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """DigitEyes link residuals: signed distances ``n . x - rho`` of the predicted axis base
    and end pixels (L, 2) from the measured lines (unit normals (L, 2), offsets (L,)), and
    their Jacobians from the pixel Jacobians (L, 2, D). Returns ((2L,), (2L, D)), rows
    base0, end0, base1, ..."""
    r = np.stack([np.einsum('ij,ij->i', normal, base_px) - offset,
                  np.einsum('ij,ij->i', normal, end_px) - offset], axis=1)
    J = np.stack([np.einsum('ij,ijd->id', normal, base_jacobian),
                  np.einsum('ij,ijd->id', normal, end_jacobian)], axis=1)
    return r.reshape(-1), J.reshape(-1, J.shape[-1])


def tip_residuals(predicted_px: np.ndarray, measured_px: np.ndarray,
                  jacobian: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """DigitEyes tip residuals: predicted minus measured tip centres (T, 2) and the pixel
    Jacobians (T, 2, D) -> ((2T,), (2T, D)), rows x0, y0, x1, ..."""
    return (np.asarray(predicted_px) - np.asarray(measured_px)).reshape(-1), \
        np.asarray(jacobian).reshape(-1, np.shape(jacobian)[-1])


# ---------------------------------------------------------------------------- prediction
@dataclass(frozen=True)
class FeaturePoints:
    """The link-fixed points the features are made of, for one hand model."""

    links: np.ndarray        # (L,) tracked link indices
    tip_links: np.ndarray    # (T,) distal link index of each tip
    tip_row: np.ndarray      # (T,) row of each tip's distal link in ``links`` (-1 if absent)
    point_link: np.ndarray   # (2L + 2T + P (2A + 1),) link of each point
    point_local: np.ndarray  # (..., 3) base, end per link, tip centre, tip end per tip, then
    #                          per palm side each generator's base and end, then the palm centre
    radius: np.ndarray       # (L,) link radius, m
    tip_radius: np.ndarray   # (T,) m
    palm_sign: np.ndarray = field(default_factory=lambda: np.zeros(0))     # (P,) +1 radial
    palm_surface: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))  # (V, 3) palm
    #                          frame, a subsample of the palm mesh's vertices (occluder)
    palm_hull: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))  # (H, 3) palm
    #                          frame, the palm mesh's vertices on its convex hull (its outline)
    outline_radius: np.ndarray = field(default_factory=lambda: np.zeros(0))  # (E,) m: the
    #                          untracked links drawn in the hand's outline (the thumb
    #                          metacarpal), whose base and end are the last 2E points
    outline_digit: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))  # (L +
    #                          E,) the digit (index in DIGITS) of each tracked, then untracked link
    palm_rigid: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))  # (K,) rows
    #                          of the points on the palm link (the palm sides' and its centre)
    palm_affine: np.ndarray = field(default_factory=lambda: np.zeros((0, 4)))  # (K, 4): a palm
    #                          point x's weights over those points are palm_affine @ (x, 1)
    tip_digit: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))  # (T,) the
    #                          digit of each tip

    @property
    def num_palm_sides(self) -> int:
        """P, the number of palm sides."""
        return len(self.palm_sign)

    @property
    def num_links(self) -> int:
        """L, the number of tracked links."""
        return len(self.links)

    @property
    def tip_slice(self) -> slice:
        """Rows of the tip centres among the points (every second from 2L)."""
        return slice(2 * len(self.links), 2 * len(self.links) + 2 * len(self.tip_links), 2)

    @property
    def outline_start(self) -> int:
        """Row of the first untracked outline link's base (bases and ends alternate)."""
        return len(self.point_link) - 2 * len(self.outline_radius)

    @property
    def palm_start(self) -> int:
        """Row of the first palm side's first point."""
        return 2 * len(self.links) + 2 * len(self.tip_links)


def palm_outline(model: HandModel, sides: Sequence[str], angles: np.ndarray) -> np.ndarray:
    """The palm's sides as silhouette generators in the palm frame, from the hand mesh's palm
    (:func:`build_hand_mesh`): per side and per viewing angle ``angles[k]`` (radians; the
    outward direction ``(cos a, 0, sin a)`` turned about the hand's long axis, 0 in the palm's
    plane, + toward the back of the hand) the line through the palm vertices farthest out in
    that direction in 5 mm bands along the side, from its wrist end to its knuckle end:
    (P, A, 2, 3), m. A camera looking at the side across the direction ``a`` sees that line as
    the palm's outline. 'ulnar' is the little-finger side from the wrist to the little
    knuckle, 'radial' the index side from above the thumb's base to the index knuckle."""
    mesh = build_hand_mesh(model)
    palm = mesh.local_vertices[mesh.vertex_link == 0]
    s = model.scale
    out = np.zeros((len(sides), len(angles), 2, 3))
    for i, side in enumerate(sides):
        digit, sign, y_wrist = (4, -1.0, -0.005 * s) if side == 'ulnar' else (1, 1.0, -0.045 * s)
        y_knuckle = model.finger_anchors[digit][1] + 0.01 * s
        edges = np.arange(y_wrist, y_knuckle - 1e-9, -0.005 * s)
        bands = [palm[(palm[:, 1] <= hi) & (palm[:, 1] > lo)]
                 for hi, lo in zip(edges[:-1], edges[1:], strict=True)]
        bands = [b for b in bands if len(b)]
        for k, a in enumerate(angles):
            d = np.array([sign * np.cos(a), 0.0, np.sin(a)])
            far = np.array([b[np.argmax(b @ d)] for b in bands])
            fx = np.polyfit(far[:, 1], far[:, 0], 1)
            fz = np.polyfit(far[:, 1], far[:, 2], 1)
            for j, y in enumerate((edges[0], edges[-1])):
                out[i, k, j] = [np.polyval(fx, y), y, np.polyval(fz, y)]
    return out


def feature_points(model: HandModel, tracked: Sequence[str], use_tips: bool,
                   palm_sides: Sequence[str] = ()) -> FeaturePoints:
    """The feature points of the tracked links, the tips (if ``use_tips``) and the palm's
    ``palm_sides`` (:func:`palm_outline`; the inner point is the palm's centre)."""
    links = np.array([LINK_NAMES.index(n) for n in tracked], dtype=np.int64)
    tip_links = np.array([digit_link_index(d, 2) for d in range(len(DIGITS))] if use_tips
                         else [], dtype=np.int64)
    length = model.link_lengths
    radius = model.link_radii
    local = []
    for li in links:
        local += [[0.0, 0.0, 0.0], [0.0, -length[li], 0.0]]
    for li in tip_links:
        local += [[0.0, -(length[li] - radius[li]), 0.0], [0.0, -length[li], 0.0]]
    generators = palm_outline(model, palm_sides, PALM_ANGLES)
    centre = np.array([0.0, 0.5 * model.finger_anchors[2][1], 0.0])
    for side in generators:
        local += [*side.reshape(-1, 3), centre]
    untracked = np.array([i for i in range(1, len(LINK_NAMES)) if i not in set(links)
                          and model.link_parent[i] >= 0], dtype=np.int64)
    for li in untracked:
        local += [[0.0, 0.0, 0.0], [0.0, -length[li], 0.0]]
    point_link = np.concatenate([np.repeat(links, 2), np.repeat(tip_links, 2),
                                 np.zeros(generators.shape[0] * (2 * len(PALM_ANGLES) + 1),
                                          dtype=np.int64), np.repeat(untracked, 2)])
    palm_sign = np.array([1.0 if side == 'radial' else -1.0 for side in palm_sides])
    row = {int(li): k for k, li in enumerate(links)}
    tip_row = np.array([row.get(int(li), -1) for li in tip_links], dtype=np.int64)
    mesh = build_hand_mesh(model)
    palm = mesh.local_vertices[mesh.vertex_link == 0]
    from scipy.spatial import ConvexHull  # here: nodes importing this module stay light

    hull = palm[ConvexHull(palm).vertices]
    palm = palm[::max(1, len(palm) // _PALM_OCCLUDER_POINTS)]
    digit = np.array([DIGITS.index(LINK_NAMES[li].split('_')[0])
                      for li in np.concatenate([links, untracked])], dtype=np.int64)
    local = np.asarray(local, dtype=float).reshape(-1, 3)
    start = 2 * len(links) + 2 * len(tip_links)
    rigid = np.arange(start, start + generators.shape[0] * (2 * len(PALM_ANGLES) + 1))
    basis = np.vstack([local[rigid].T, np.ones(len(rigid))])
    affine = np.linalg.pinv(basis) if len(rigid) >= 4 and np.linalg.matrix_rank(basis) == 4 \
        else np.zeros((0, 4))
    tip_digit = np.array([DIGITS.index(LINK_NAMES[li].split('_')[0]) for li in tip_links],
                         dtype=np.int64)
    return FeaturePoints(links, tip_links, tip_row, point_link, local, radius[links],
                          radius[tip_links], palm_sign, np.asarray(palm, dtype=float),
                          np.asarray(hull, dtype=float), radius[untracked], digit,
                          rigid[:len(affine)], affine, tip_digit)


@dataclass(frozen=True)
class EdgePrediction:
    """What one camera should see at pose q: per tracked link the axis base and end pixels
    (L, 2), their Jacobians (L, 2, 26), the projected radius (L,) and which slices are usable
    (L, S: in front of the camera, long enough, not behind another link); per tip the centre
    and extremity pixels (T, 2), the centre's Jacobian (T, 2, 26), projected radius (T,) and
    whether it is usable (T,)."""

    base_px: np.ndarray
    end_px: np.ndarray
    base_jacobian: np.ndarray
    end_jacobian: np.ndarray
    half_width_px: np.ndarray
    slice_valid: np.ndarray
    link_usable: np.ndarray
    tip_px: np.ndarray
    tip_end_px: np.ndarray
    tip_jacobian: np.ndarray
    tip_radius_px: np.ndarray
    tip_usable: np.ndarray
    palm_base_px: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    palm_end_px: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    palm_outward_px: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    palm_generator: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    palm_slice_valid: np.ndarray = field(default_factory=lambda: np.zeros((0, 0), bool))
    palm_usable: np.ndarray = field(default_factory=lambda: np.zeros(0, bool))


# pose-derived values one frame asks for several times (every camera's prediction, occlusion
# and outline) and the next frame again (its start is this frame's final pose): key ->
# (the objects the key names by id, kept alive so no id is reused while cached; value)
_MEMO: dict[tuple[object, ...], tuple[tuple[object, ...], Any]] = {}
_MEMO_SIZE = 16
_T = TypeVar('_T')


def _memo(kind: str, owners: tuple[object, ...], q: np.ndarray, make: Callable[[], _T]) -> _T:
    """``make()``, remembered for the last few (``kind``, ``owners``, pose ``q``)."""
    key = (kind, *(id(o) for o in owners), np.asarray(q, dtype=float).tobytes())
    hit = _MEMO.get(key)
    if hit is not None:
        return hit[1]
    value = make()
    if len(_MEMO) >= _MEMO_SIZE:
        _MEMO.pop(next(iter(_MEMO)))
    _MEMO[key] = (owners, value)
    return value


def _palm_rotation(q: np.ndarray) -> np.ndarray:
    """The palm's rotation matrix of pose ``q`` (read-only)."""
    def make() -> np.ndarray:
        R = rotvec_to_matrix(q[3:6])
        R.setflags(write=False)
        return R
    return _memo('rotation', (), q[3:6], make)


def _project(camera: PinholeCamera, p_world: np.ndarray, J_world: np.ndarray | None
             ) -> tuple[np.ndarray, np.ndarray | None, np.ndarray]:
    """Pixels, pixel Jacobians (N, 2, 26) and depths of primary-frame points in a camera."""
    pc = camera.world_to_camera(p_world)
    depth = pc[:, 2].copy()
    safe = pc.copy()
    safe[:, 2] = np.where(np.abs(depth) < 1e-6, 1e-6, depth)
    pix = camera.project(safe)
    if J_world is None:
        return pix, None, depth
    A = camera.project_jacobian(safe) @ camera.rotation                     # (N, 2, 3)
    return pix, A @ J_world, depth


# the feature points' projections of the last few point sets: a round's prediction, its
# first Gauss-Newton step, its move and its final checks project the same points again
_PROJECTED: dict[tuple[int, tuple[int, ...], bytes], tuple[object, ...]] = {}
_PROJECTED_SIZE = 8


def _project_points(camera: PinholeCamera, p_world: np.ndarray, J_world: np.ndarray | None
                    ) -> tuple[np.ndarray, np.ndarray | None, np.ndarray]:
    """:func:`_project` of the feature points (read-only arrays), remembered for the last few
    (camera, points) and, with Jacobians, for the last ``J_world`` array of those points."""
    key = (id(camera), p_world.shape, p_world.tobytes())
    hit = _PROJECTED.get(key)
    if hit is not None and (J_world is None or hit[3] is J_world):
        return hit[1], (None if J_world is None else hit[4]), hit[2]   # type: ignore[return-value]
    pix, Jpix, depth = _project(camera, p_world, J_world)
    for a in (pix, Jpix, depth):
        if a is not None:
            a.setflags(write=False)
    if hit is None and len(_PROJECTED) >= _PROJECTED_SIZE:
        _PROJECTED.pop(next(iter(_PROJECTED)))
    # the camera and the Jacobians are kept so that their ids are not reused while cached
    _PROJECTED[key] = (camera, pix, depth, J_world, Jpix)
    return pix, Jpix, depth


def _pixel_radius(radius: np.ndarray, camera: PinholeCamera, depth: np.ndarray) -> np.ndarray:
    """Image radius (pixels) of cylinders or discs of ``radius`` (m) at ``depth`` (m)."""
    focal = 0.5 * (camera.fx + camera.fy)
    return radius * focal / np.maximum(depth, 1e-6)


def predict_features(kin: FastKinematics, points: FeaturePoints, camera: PinholeCamera,
                     q: np.ndarray, config: EdgeTrackerConfig,
                     world: tuple[np.ndarray, np.ndarray] | None = None) -> EdgePrediction:
    """Project the feature points of pose ``q`` into ``camera`` (``world`` = precomputed
    primary-frame points and Jacobians) and decide which slices and tips can be measured."""
    p, J = world if world is not None else kin.points(q, points.point_link,
                                                      points.point_local, True)
    pix, Jpix, depth = _project_points(camera, p, J)
    L = len(points.links)
    Jb, Je = Jpix[0:2 * L:2], Jpix[1:2 * L:2]
    S = config.search.slices_per_link
    frac = fixed_linspace(*config.search.slice_range, S)
    focal = 0.5 * (camera.fx + camera.fy)           # as _pixel_radius takes it
    kernels = compiled_kernels()
    # the links' ends, depths, radii, usability and slices (edge_kernel.link_prediction)
    base, end, zb, ze, hw, usable, centres, inside, z_self = kernels.link_prediction(
        pix, depth, L, points.radius, focal, frac, float(config.min_depth_m),
        float(config.min_link_px), float(config.search.search_px), camera.width,
        camera.height)
    # occlusion: a slice is spoilt where the silhouette of a nearer link (other than its
    # neighbours in the chain, which meet it at the joints outside the slice range) overlaps
    # its own, widened by ``occlusion_margin_px`` (edge_kernel.occluded_slices)
    occluded = kernels.occluded_slices(
        centres, S, base, end, zb, ze, hw, z_self, float(config.occlusion_margin_px), usable,
        _exempt_links(kin, points)).reshape(L, S)
    centres = centres.reshape(L, S, 2)
    if config.palm_occlusion_px > 0 and len(points.palm_surface):
        occluded |= _behind_palm(points, camera, config, q, centres, z_self.reshape(L, S))
    slice_valid = usable[:, None] & inside & ~occluded
    link_usable = slice_valid.sum(1) >= config.search.min_slices
    T = len(points.tip_links)
    tip = pix[points.tip_slice]
    tip_end = pix[2 * L + 1:points.palm_start:2]
    Jt = Jpix[points.tip_slice] if T else np.zeros((0, 2, NUM_DOFS))
    # a tip lying on another (nearer) link cannot be told from it (edge_kernel.tip_prediction)
    tip_r, tip_ok = kernels.tip_prediction(
        pix, depth, points.tip_slice.start, T, points.tip_radius, focal, points.tip_row,
        link_usable, float(config.min_depth_m), float(config.search.tip_search_px),
        camera.width, camera.height, base, end, zb, ze, hw, usable)
    palm = _predict_palm(points, camera, config, q, p, pix, depth, base, end, zb, ze, hw,
                         usable)
    return EdgePrediction(base, end, Jb, Je, hw, slice_valid, link_usable, tip, tip_end, Jt,
                          tip_r, tip_ok, *palm)


_EXEMPT: dict[tuple[int, int], tuple[FastKinematics, FeaturePoints, np.ndarray]] = {}


def _exempt_links(kin: FastKinematics, points: FeaturePoints) -> np.ndarray:
    """(L, L) the tracked links each link's occlusion test leaves out: itself, its parent and
    its children (remembered per kinematics and feature points)."""
    key = (id(kin), id(points))
    hit = _EXEMPT.get(key)
    if hit is None:
        L = len(points.links)
        parent = np.asarray(kin.model.link_parent)[points.links]
        exempt = (np.eye(L, dtype=bool) | (parent[:, None] == points.links[None, :])
                  | (parent[None, :] == points.links[:, None]))
        exempt.setflags(write=False)
        if len(_EXEMPT) >= 8:
            _EXEMPT.pop(next(iter(_EXEMPT)))
        hit = _EXEMPT[key] = (kin, points, exempt)    # kept: their ids are not reused
    return hit[2]


def _behind_palm(points: FeaturePoints, camera: PinholeCamera, config: EdgeTrackerConfig,
                 q: np.ndarray, centres: np.ndarray, z_self: np.ndarray) -> np.ndarray:
    """(L, S) slices hidden by the palm: inside the convex hull of the projected palm
    surface points and farther from the camera, by more than the link's radius, than the
    nearest of those points within ``palm_occlusion_px`` (or the nearest one): e.g. fingers
    curled behind the back of the hand."""
    world = q[0:3] + points.palm_surface @ _palm_rotation(q).T
    pix, _, depth = _project(camera, world, None)
    ok = depth > config.min_depth_m
    if ok.sum() < 3:
        return np.zeros(centres.shape[:2], dtype=bool)
    pix, depth = pix[ok], depth[ok]
    hull = cv2.convexHull(pix.astype(np.float32))[:, 0, :].astype(float)
    out = compiled_kernels().behind_palm(
        hull, np.ascontiguousarray(centres.reshape(-1, 2)), np.ascontiguousarray(pix),
        np.ascontiguousarray(depth), float(config.palm_occlusion_px) ** 2,
        np.ascontiguousarray(z_self.reshape(-1)), np.repeat(points.radius, centres.shape[1]))
    return out.reshape(centres.shape[:2])


def palm_rows(points: FeaturePoints, generator: np.ndarray, sides: np.ndarray | None = None
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Point rows and weights of the palm sides' chosen generators: ``generator`` (N, 2)
    holds, for each of the palm sides ``sides`` (N indices into ``points``' sides; None:
    every side, in order), the index k of the first of the two generators and the weight of
    the second; returns the rows of the k-th base (N,), of the k-th end (N,) and the weight
    (N,); the (k+1)-th are 2 rows on."""
    A = len(PALM_ANGLES)
    k = generator[:, 0].astype(np.int64)
    side = np.arange(points.num_palm_sides) if sides is None else np.asarray(sides, np.int64)
    if side.shape != k.shape:
        raise EdgeTrackerError(f'{len(k)} palm generator(s) for {len(side)} side(s)')
    first = points.palm_start + side * (2 * A + 1) + 2 * k
    return first, first + 1, generator[:, 1]


def _blend(x: np.ndarray, rows: np.ndarray, alpha: np.ndarray) -> np.ndarray:
    w = alpha.reshape((-1,) + (1,) * (x.ndim - 1))
    return (1.0 - w) * x[rows] + w * x[rows + 2]


def _predict_palm(points: FeaturePoints, camera: PinholeCamera, config: EdgeTrackerConfig,
                  q: np.ndarray, world: np.ndarray, pix: np.ndarray, depth: np.ndarray,
                  base: np.ndarray, end: np.ndarray, zb: np.ndarray, ze: np.ndarray,
                  hw: np.ndarray, link_usable: np.ndarray) -> tuple[np.ndarray, ...]:
    """The palm sides' predicted outlines in the camera: the generator for the camera's view
    of each side (interpolated between the two nearest of ``PALM_ANGLES``), its projected
    base and end (P, 2), outward unit normals (P, 2), the generator choice (P, 2: index,
    weight), usable slices (P, S: inside the image, not behind a nearer tracked link) and
    which sides are usable."""
    P, A = points.num_palm_sides, len(PALM_ANGLES)
    S = config.search.slices_per_link
    stride = 2 * A + 1
    centre_rows = points.palm_start + np.arange(P) * stride + 2 * A
    # the view direction in the palm frame picks the generator: the outline is where the
    # surface's outward cross-section normal is perpendicular to the line of sight
    R = _palm_rotation(q)
    eye = -camera.rotation.T @ camera.translation
    view = (world[centre_rows] - eye) @ R                                    # (P, 3) palm frame
    # the outward normal (sign cos a, 0, sin a) is perpendicular to the view (vx, vz):
    # sign vx cos a + vz sin a = 0, the root with cos a > 0
    vz = view[:, 2]
    angle = np.arctan2(-points.palm_sign * view[:, 0] * np.where(vz < 0, -1.0, 1.0), np.abs(vz))
    pos = np.clip(np.interp(angle, PALM_ANGLES, np.arange(A)), 0.0, A - 1 - 1e-9)
    generator = np.stack([np.floor(pos), pos - np.floor(pos)], axis=1)
    rb, re, alpha = palm_rows(points, generator)
    # the generators' ends, normals and usable slices (edge_kernel.palm_prediction)
    pb, pe, n, slice_valid, usable = compiled_kernels().palm_prediction(
        pix, depth, rb, re, np.ascontiguousarray(alpha), centre_rows,
        fixed_linspace(*config.palm_slice_range, S),
        float(config.min_depth_m), float(config.min_link_px), float(config.search.search_px),
        camera.width, camera.height, base, end, zb, ze, hw, link_usable,
        config.search.min_slices)
    return pb, pe, n, generator, slice_valid, usable


def hand_outline(points: FeaturePoints, camera: PinholeCamera, q: np.ndarray,
                 pix: np.ndarray, depth: np.ndarray) -> HandOutline:
    """The predicted hand of pose ``q`` in ``camera`` (``pix``, ``depth``: the feature
    points projected): link capsules, tip discs, the projected palm surface, the wrist and the
    direction from the wrist to the palm's centre (remembered for the last few poses: a
    frame's final check and the next frame's start ask for the same)."""
    return _memo('outline', (points, camera), q,
                 lambda: _hand_outline(points, camera, q, pix, depth))


def _hand_outline(points: FeaturePoints, camera: PinholeCamera, q: np.ndarray,
                  pix: np.ndarray, depth: np.ndarray) -> HandOutline:
    L, o = len(points.links), points.outline_start
    base = np.concatenate([pix[0:2 * L:2], pix[o::2]])
    end = np.concatenate([pix[1:2 * L:2], pix[o + 1::2]])
    zb = np.concatenate([depth[0:2 * L:2], depth[o::2]])
    ze = np.concatenate([depth[1:2 * L:2], depth[o + 1::2]])
    radius = np.concatenate([points.radius, points.outline_radius])
    hw = _pixel_radius(radius, camera, 0.5 * (zb + ze))
    zt = depth[points.tip_slice]
    R = _palm_rotation(q)
    centre = np.array([0.0, 0.5 * np.mean(points.palm_hull[:, 1]), 0.0]) \
        if len(points.palm_hull) else np.zeros(3)
    extra = q[0:3] + np.concatenate([points.palm_hull, [np.zeros(3), centre]]) @ R.T
    epix, _, edepth = _project(camera, extra, None)
    palm = epix[:-2][edepth[:-2] > 0]
    axis = epix[-1] - epix[-2]
    axis = axis / max(float(np.linalg.norm(axis)), 1e-9)
    return HandOutline(base, end, hw, pix[points.tip_slice],
                       _pixel_radius(points.tip_radius, camera, zt), palm, epix[-2], axis)


def _axis_points(points: FeaturePoints, pix: np.ndarray, Jpix: np.ndarray | None,
                 camera: PinholeCamera) -> tuple[np.ndarray, np.ndarray | None, np.ndarray]:
    """The hand's axis points that must lie on its silhouette (each link's base, middle and
    end, each tip centre) inside the image, their pixel Jacobians and their digits (index
    in DIGITS)."""
    L = len(points.links)
    base, end = pix[0:2 * L:2], pix[1:2 * L:2]
    px = np.concatenate([base, 0.5 * (base + end), end, pix[points.tip_slice]])
    J = None
    if Jpix is not None:
        Jb, Je = Jpix[0:2 * L:2], Jpix[1:2 * L:2]
        J = np.concatenate([Jb, 0.5 * (Jb + Je), Je, Jpix[points.tip_slice]])
    inside = camera.in_image(px)
    digit = np.concatenate([np.tile(points.outline_digit[:L], 3), points.tip_digit])
    return px[inside], None if J is None else J[inside], digit[inside]


def silhouette_measures(points: FeaturePoints, camera: PinholeCamera, silhouette: Silhouette,
                        q: np.ndarray, pix: np.ndarray, depth: np.ndarray,
                        config: EdgeTrackerConfig) -> np.ndarray:
    """How well pose ``q`` explains one camera's silhouette, for the drift checks that are
    on (NaN for a check that is off, ``max_off_silhouette`` or ``max_unexplained`` 1, or
    ``finger_refit`` false, ``max_finger_off_silhouette`` 1), (12,): the share of the hand's
    axis points more than ``silhouette_tolerance_px`` off the foreground, the unexplained
    share of the hand's foreground (:meth:`Silhouette.unexplained` of the predicted hand,
    :func:`hand_outline`), per digit the share of the hand's foreground left unexplained
    nearest to that digit's capsules (:func:`_digit_shares`) and per digit the share of its
    axis points off the foreground (0 for a digit with none in the image)."""
    tol = config.silhouette_tolerance_px
    D = len(DIGITS)
    out = np.full(2 + 2 * D, math.nan)
    if config.max_off_silhouette < 1.0 or config.max_finger_off_silhouette < 1.0:
        ax, _, digit = _axis_points(points, pix, None, camera)
        off = silhouette.outside_distance(ax)[0] > tol
        if config.max_off_silhouette < 1.0:
            out[0] = float(np.mean(off)) if len(ax) else 0.0
        if config.max_finger_off_silhouette < 1.0:
            count = np.bincount(digit, minlength=D)
            out[2 + D:] = np.bincount(digit, weights=off, minlength=D) / np.maximum(count, 1)
    if config.max_unexplained < 1.0 or config.finger_refit:
        outline = hand_outline(points, camera, q, pix, depth)
        loose, out[1] = silhouette.unexplained(outline, tol, pixels=config.finger_refit)
        if config.finger_refit:
            out[2:2 + D] = _digit_shares(points, outline, loose, out[1])
    return out


_DIGIT_SAMPLES = 200     # unexplained pixels (at most) assigned to digits per camera


def even_subsample(length: int, count: int) -> np.ndarray:
    """Indices of at most ``count`` of ``length`` items, evenly through them (first and last
    included, rounded down): all of them when there are no more than ``count``."""
    if length <= count:
        return np.arange(length, dtype=np.int64)
    return np.linspace(0, length - 1, count).astype(np.int64)


def _digit_shares(points: FeaturePoints, outline: HandOutline, loose: np.ndarray,
                  share: float) -> np.ndarray:
    """(5,) the unexplained ``share`` of the hand's foreground split over the digits: each
    of the ``loose`` pixels (an even subsample) goes to the digit of its nearest capsule,
    none when the palm's outline is nearer."""
    out = np.zeros(len(DIGITS))
    if not len(loose) or not len(outline.base):
        return out
    sample = loose[even_subsample(len(loose), _DIGIT_SAMPLES)]
    to_link = segment_distances(sample, outline.base, outline.end)[0] \
        - outline.half_width[None, :]
    nearest = np.argmin(to_link, axis=1)
    keep = np.ones(len(sample), dtype=bool)
    if len(outline.palm) >= 3:
        hull = cv2.convexHull(outline.palm.astype(np.float32))[:, 0, :].astype(float)
        to_palm = segment_distances(sample, hull, np.roll(hull, -1, axis=0))[0].min(axis=1)
        keep = to_link[np.arange(len(sample)), nearest] < to_palm
    counts = np.bincount(points.outline_digit[nearest[keep]], minlength=len(DIGITS))
    return share * counts / len(sample)


def _silhouette_targets(loose: np.ndarray, base: np.ndarray, end: np.ndarray,
                        hw: np.ndarray, count: int, palm: np.ndarray,
                        points: FeaturePoints | None = None) -> SilhouetteTargets:
    """Up to ``count`` of the unexplained pixels (evenly through the list), each with its
    nearest link capsule; pixels nearer the palm's outline ``palm`` (K, 2) than to every
    capsule are left out (the palm is rigid with the wrist, and its rim would pull a finger),
    or, given ``points`` (``silhouette_palm``; ``palm`` then the projection of every point of
    ``points.palm_hull``), kept as up to ``count`` palm targets."""
    loose = loose[even_subsample(len(loose), 2 * count)]
    palm_targets: dict[str, np.ndarray] = {}
    if len(loose) and len(palm) >= 3:
        # unexplained pixels lie outside the palm's hull: their distance to it is that to
        # its nearest edge
        index = cv2.convexHull(palm.astype(np.float32), returnPoints=False)[:, 0]
        hull = palm.astype(np.float32)[index].astype(float)
        to_edge, along = segment_distances(loose, hull, np.roll(hull, -1, axis=0))
        to_palm = to_edge.min(axis=1)
        to_link = (segment_distances(loose, base, end)[0] - hw[None, :]).min(axis=1) \
            if len(base) else np.full(len(loose), np.inf)
        near_palm = to_link >= to_palm
        if points is not None and near_palm.any() and len(points.palm_affine) \
                and len(palm) == len(points.palm_hull):
            palm_targets = _palm_targets(loose[near_palm], hull, index,
                                         to_edge[near_palm], along[near_palm], count, points)
        loose = loose[~near_palm]
    loose = loose[even_subsample(len(loose), count)]
    if not len(loose) or not len(base):
        return SilhouetteTargets(np.zeros((0, 2)), np.zeros(0, np.int64), np.zeros(0),
                                 np.zeros((0, 2)), **palm_targets)
    dist, along = segment_distances(loose, base, end)
    link = np.argmin(dist - hw[None, :], axis=1)
    rows = np.arange(len(loose))
    s = along[rows, link]
    closest = base[link] + s[:, None] * (end[link] - base[link])
    d = loose - closest
    direction = d / np.maximum(np.linalg.norm(d, axis=1, keepdims=True), 1e-9)
    return SilhouetteTargets(loose, link, s, direction, **palm_targets)


def _palm_targets(px: np.ndarray, hull: np.ndarray, index: np.ndarray, to_edge: np.ndarray,
                  along: np.ndarray, count: int, points: FeaturePoints) -> dict[str, np.ndarray]:
    """The palm targets of :class:`SilhouetteTargets` for unexplained pixels ``px`` nearest
    the palm's projected hull (vertices ``hull``, rows ``index`` of ``points.palm_hull``;
    ``to_edge``, ``along``: each pixel's distance to each hull edge and the closest point's
    place on it): up to ``count`` pixels, the palm point under each one's closest point as
    weights of the palm's rigid feature points, the direction to the pixel."""
    keep = even_subsample(len(px), count)
    px, to_edge, along = px[keep], to_edge[keep], along[keep]
    rows = np.arange(len(px))
    edge = np.argmin(to_edge, axis=1)
    s = along[rows, edge]
    nxt = (edge + 1) % len(hull)
    closest = hull[edge] + s[:, None] * (hull[nxt] - hull[edge])
    d = px - closest
    direction = d / np.maximum(np.linalg.norm(d, axis=1, keepdims=True), 1e-9)
    local = (1.0 - s)[:, None] * points.palm_hull[index[edge]] \
        + s[:, None] * points.palm_hull[index[nxt]]
    weights = np.hstack([local, np.ones((len(px), 1))]) @ points.palm_affine.T
    return {'palm_px': px, 'palm_weights': weights, 'palm_direction': direction}


def _silhouette_residuals(points: FeaturePoints, camera: PinholeCamera, meas: EdgeMeasurement,
                          pix: np.ndarray, Jpix: np.ndarray, depth: np.ndarray,
                          config: EdgeTrackerConfig,
                          world: tuple[np.ndarray, np.ndarray | None] | None = None
                          ) -> tuple[np.ndarray, np.ndarray]:
    """One camera's silhouette rows: each axis point's distance beyond the tolerance off the
    foreground, each unexplained pixel's distance beyond the tolerance from its link's
    capsule and (palm targets, ``world`` the feature points and Jacobians) from its point of
    the palm (rows only where positive)."""
    tol = config.silhouette_tolerance_px
    kernels = compiled_kernels()
    L = len(points.links)
    ax, place = kernels.axis_points(pix, L, points.tip_slice.start, len(points.tip_links),
                                    camera.width, camera.height)
    d, grad = meas.silhouette.outside_distance(ax)
    t = meas.loose
    targets = t if t is not None and len(t.px) else _NO_TARGETS
    rows, Jrows = kernels.silhouette_rows(
        pix, Jpix, depth, L, points.tip_slice.start, place, np.ascontiguousarray(d), grad,
        float(tol), targets.px, targets.link, targets.along, targets.direction,
        points.radius, 0.5 * (camera.fx + camera.fy))
    r, J = [rows], [Jrows]
    if t is not None and len(t.palm_px) and world is not None and world[1] is not None:
        rigid = points.palm_rigid
        c, Jc, _ = _project(camera, t.palm_weights @ world[0][rigid],
                            np.einsum('nk,kad->nad', t.palm_weights, world[1][rigid]))
        rp = np.einsum('ij,ij->i', t.palm_direction, t.palm_px - c) - tol
        keep = rp > 0
        r.append(rp[keep])
        J.append(-np.einsum('ij,ijd->id', t.palm_direction[keep], Jc[keep]))
    return np.concatenate(r), np.concatenate(J)


# ---------------------------------------------------------------------------- measurement
@dataclass(frozen=True)
class EdgeMeasurement:
    """One camera's measured features for a prediction: the link axes, which links were
    usable and found, the measured tip centres (T, 2) and which tips were found."""

    prediction: EdgePrediction
    axes: LinkAxes
    link_found: np.ndarray   # (L,) bool
    tips: TipPoints
    tip_found: np.ndarray    # (T,) bool
    palm: LinkAxes | None = None
    palm_found: np.ndarray = field(default_factory=lambda: np.zeros(0, bool))
    silhouette: Silhouette | None = None
    loose: SilhouetteTargets | None = None
    lines: LineRows | None = None


@dataclass(frozen=True)
class SilhouetteTargets:
    """Foreground pixels no part of the predicted hand explains, each assigned to its nearest
    link capsule: the pixels (M, 2), the link's row (M,), the closest point's fraction along
    the link (M,) and the unit direction from that point to the pixel (M, 2); with
    ``silhouette_palm`` also pixels nearest the palm's outline (N, 2), the point of the palm
    nearest each as weights of the palm's rigid feature points (N, K: an affine combination,
    exact under any motion of the palm) and the unit direction from it to the pixel (N, 2)."""

    px: np.ndarray
    link: np.ndarray
    along: np.ndarray
    direction: np.ndarray
    palm_px: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    palm_weights: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))
    palm_direction: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))


_NO_TARGETS = SilhouetteTargets(np.zeros((0, 2)), np.zeros(0, np.int64), np.zeros(0),
                                np.zeros((0, 2)))


def measure_features(grey: np.ndarray, prediction: EdgePrediction, config: EdgeTrackerConfig,
                     tip_rows: np.ndarray, polarity: int | None = None) -> EdgeMeasurement:
    """Measure one camera's links near the prediction, then each tip along its distal link's
    measured axis (a tip whose distal link was not found is not measured); ``tip_rows``
    gives each tip's distal link row."""
    pol = config.polarity if polarity is None else polarity
    pred = prediction
    axes = measure_link_axes(grey, pred.base_px, pred.end_px, pred.half_width_px,
                             config.search, pol, pred.slice_valid)
    link_found = axes.found & pred.link_usable
    palm, palm_found = None, np.zeros(0, dtype=bool)
    if len(pred.palm_generator):
        palm = measure_outline_edges(grey, pred.palm_base_px, pred.palm_end_px,
                                     pred.palm_outward_px, config.search, pred.palm_slice_valid,
                                     config.palm_slice_range)
        palm_found = palm.found & pred.palm_usable
    T = len(pred.tip_px)
    if T == 0:
        empty = TipPoints(np.zeros((0, 2)), np.zeros(0, dtype=bool))
        return EdgeMeasurement(pred, axes, link_found, empty, np.zeros(0, dtype=bool), palm,
                               palm_found)
    rows = np.maximum(tip_rows, 0)
    n = axes.normal[rows]
    rho = axes.offset[rows]
    # the measured axis, directed like the predicted link, through the predicted extremity's
    # foot point
    u = np.stack([n[:, 1], -n[:, 0]], axis=1)
    pred_dir = pred.end_px[rows] - pred.base_px[rows]
    u *= np.where(np.einsum('ij,ij->i', u, pred_dir) < 0, -1.0, 1.0)[:, None]
    foot = pred.tip_end_px - (np.einsum('ij,ij->i', n, pred.tip_end_px) - rho)[:, None] * n
    tip_pol = np.where(axes.polarity[rows] != 0, axes.polarity[rows], pol)
    tips = measure_tips(grey, foot, u, pred.tip_end_px, pred.tip_radius_px, config.search,
                        tip_pol)
    tip_found = tips.found & pred.tip_usable & (tip_rows >= 0) & link_found[rows]
    return EdgeMeasurement(pred, axes, link_found, tips, tip_found, palm, palm_found)


def _robust(r: np.ndarray, k: float, loss: str) -> np.ndarray:
    """IRLS weights of residuals ``r`` (pixels) at scale ``k`` (all 1 for k <= 0): Huber
    (1 within k, k / |r| beyond) or Cauchy (1 / (1 + (r / k)^2), which all but ignores a
    measurement many times k off, e.g. a finger edge taken from its neighbour)."""
    if k <= 0:
        return np.ones_like(r)
    a = np.abs(r)
    if loss == 'cauchy':
        return 1.0 / (1.0 + (a / k) ** 2)
    return np.where(a <= k, 1.0, k / np.maximum(a, 1e-12))


@dataclass(frozen=True)
class LineRows:
    """One camera's measured lines, links first, then palm sides, as rows of the feature
    points: each line's model base and end rows (a palm side's generator blends a row with
    the one two rows on by ``alpha``; links have alpha 0), the measured unit normals and
    offsets, the number of link lines, and the rows of the measured tip centres."""

    base: np.ndarray
    end: np.ndarray
    alpha: np.ndarray
    normal: np.ndarray
    offset: np.ndarray
    num_links: int
    tips: np.ndarray


def line_rows(points: FeaturePoints, meas: EdgeMeasurement) -> LineRows:
    """The :class:`LineRows` of one camera's measurement (``meas.lines`` if already set)."""
    if meas.lines is not None:
        return meas.lines
    f = np.flatnonzero(meas.link_found)
    rows_b, rows_e, alpha = 2 * f, 2 * f + 1, np.zeros(len(f))
    normal, offset = meas.axes.normal[f], meas.axes.offset[f]
    pf = meas.palm_found
    if meas.palm is not None and pf.any():
        rb, re, a = palm_rows(points, meas.prediction.palm_generator[pf], np.flatnonzero(pf))
        rows_b, rows_e = np.concatenate([rows_b, rb]), np.concatenate([rows_e, re])
        alpha = np.concatenate([alpha, a])
        normal = np.concatenate([normal, meas.palm.normal[pf]])
        offset = np.concatenate([offset, meas.palm.offset[pf]])
    tips = np.arange(points.tip_slice.start, points.tip_slice.stop, 2)[meas.tip_found]
    return LineRows(rows_b, rows_e, alpha, normal, offset, len(f), tips)


def stack_residuals(points: FeaturePoints, cameras: Sequence[PinholeCamera],
                    measured: Sequence[EdgeMeasurement | None],
                    world: tuple[np.ndarray, np.ndarray | None], config: EdgeTrackerConfig,
                    jacobian: bool = True
                    ) -> tuple[np.ndarray, np.ndarray | None, np.ndarray]:
    """All cameras' link, tip, palm-side and silhouette residuals at the pose of ``world``
    (points, Jacobians), their Jacobian and their weights (robust x feature x camera
    weight); per camera the rows are links, tips, palm sides, silhouette."""
    p, Jw = world
    kernels = compiled_kernels()
    cauchy = config.robust_loss == 'cauchy'
    rs, Js, ws = [], [], []
    for index, (cam, meas) in enumerate(zip(cameras, measured, strict=True)):
        if meas is None:
            continue
        pix, Jpix, depth = _project_points(cam, p, Jw if jacobian else None)
        lines = line_rows(points, meas)
        scaled = index < len(config.camera_weights)
        # links, tips, palm sides (edge_kernel.line_rows: link_axis_residuals,
        # tip_residuals and _robust in one pass)
        r, J, w = kernels.line_rows(
            pix, Jpix if jacobian else _NO_JACOBIAN, lines.base, lines.end, lines.alpha,
            lines.normal, lines.offset, lines.num_links, lines.tips,
            meas.tips.centre[meas.tip_found], float(config.huber_px), cauchy,
            float(config.tip_weight), float(config.palm_weight),
            float(config.camera_weights[index]) if scaled else 1.0, scaled, jacobian)
        rs.append(r)
        Js.append(J)
        ws.append(w)
        if meas.silhouette is not None and config.silhouette_weight > 0 and jacobian:
            r, J = _silhouette_residuals(points, cam, meas, pix, Jpix, depth, config, world)
            if len(r):
                w = np.full(len(r), config.silhouette_weight)
                rs.append(r)
                Js.append(J)
                ws.append(config.camera_weights[index] * w if scaled else w)
    if not rs:
        return np.zeros(0), np.zeros((0, NUM_DOFS)) if jacobian else None, np.zeros(0)
    return (np.concatenate(rs), np.concatenate(Js) if jacobian else None, np.concatenate(ws))


_NO_JACOBIAN = np.zeros((0, 2, NUM_DOFS))
_NO_JACOBIAN.setflags(write=False)


# ---------------------------------------------------------------------------- estimation
@dataclass(frozen=True)
class EdgeFit:
    """Result of :func:`fit_pose`: the pose, the weighted RMS (``sqrt(mean(w r^2))``, Huber
    weights) of the final residuals against the last round's measurements (pixels, NaN if
    none), per camera the links found, the links usable
    and the tips found, the number of Gauss-Newton iterations taken and, with
    ``camera_check``, how far the primary camera's fit alone puts the fingertips from the
    joint fit's (:func:`fingertip_disagreement`, mm; NaN when not computed) and, with
    silhouettes, the largest over the cameras of the share of the hand's axis points off the
    foreground and of the unexplained share of the foreground (:func:`silhouette_measures`;
    NaN without silhouettes) and, with ``finger_refit``, per digit the largest over the
    cameras of the share of the foreground left unexplained nearest to that digit and, with
    ``max_finger_off_silhouette`` < 1, per digit the largest over the cameras of the share of
    its axis points off the foreground; per digit the links found and usable over the
    cameras (the last round's)."""

    q: np.ndarray
    rms_px: float
    links_found: tuple[int, ...]
    links_usable: tuple[int, ...]
    tips_found: tuple[int, ...]
    iterations: int
    camera_disagreement_mm: float = math.nan
    off_silhouette: float = math.nan
    unexplained: float = math.nan
    finger_unexplained: tuple[float, ...] = (math.nan,) * len(DIGITS)
    finger_off_silhouette: tuple[float, ...] = (math.nan,) * len(DIGITS)
    digit_links_found: tuple[int, ...] = (0,) * len(DIGITS)
    digit_links_usable: tuple[int, ...] = (0,) * len(DIGITS)

    @property
    def found_fraction(self) -> float:
        """Found over usable links, all cameras together (0 when none was usable)."""
        usable = sum(self.links_usable)
        return sum(self.links_found) / usable if usable else 0.0


def _gauss_newton(kin: FastKinematics, points: FeaturePoints, cameras: Sequence[PinholeCamera],
                  measured: Sequence[EdgeMeasurement | None],
                  world: tuple[np.ndarray, np.ndarray | None], q: np.ndarray,
                  q_anchor: np.ndarray, S: np.ndarray, C: np.ndarray | None,
                  config: EdgeTrackerConfig, held: np.ndarray | None = None
                  ) -> tuple[np.ndarray, int]:
    """``gn_iterations`` stabilised Gauss-Newton steps from ``q`` on fixed measurements
    (``world``: the points and Jacobians at ``q``), joint limits enforced, the DOFs where
    ``held`` (26,) is true left as they are; (q, steps)."""
    steps = 0
    CtC = config.coupling_weight * (C.T @ C) if C is not None else None
    for it in range(config.gn_iterations):
        if it > 0:
            world = kin.points(q, points.point_link, points.point_local, True)
        r, J, w = stack_residuals(points, cameras, measured, world, config)
        WJ = J.T * w
        H = WJ @ J + S
        g = WJ @ r + S @ (q - q_anchor)
        if C is not None:
            H += CtC
            g += config.coupling_weight * (C.T @ (C @ q))
        at_lo = (q <= kin.lower + 1e-9) & (g > 0)
        at_hi = (q >= kin.upper - 1e-9) & (g < 0)
        free = ~(at_lo | at_hi) if held is None else ~(at_lo | at_hi | held)
        dq = np.zeros(NUM_DOFS)
        try:
            dq[free] = -np.linalg.solve(H[np.ix_(free, free)], g[free])
        except np.linalg.LinAlgError:
            break
        q = kin.clamp(q + dq)
        steps += 1
    return q, steps


def fingertip_disagreement(kin: FastKinematics, q_a: np.ndarray, q_b: np.ndarray) -> float:
    """Largest distance (mm) between the fingertips of two poses, each relative to its own
    wrist (the wrist's translation removed, its rotation kept)."""
    ka, kb = kin.model.keypoints(q_a), kin.model.keypoints(q_b)
    tips = list(FINGERTIP_INDICES)
    rel = (ka[tips] - ka[0]) - (kb[tips] - kb[0])
    return float(1e3 * np.linalg.norm(rel, axis=1).max())


def fit_pose(kin: FastKinematics, points: FeaturePoints, cameras: Sequence[PinholeCamera],
             greys: Sequence[np.ndarray | None], q_start: np.ndarray,
             config: EdgeTrackerConfig, rounds: int, polarity: int | None = None,
             silhouettes: Sequence[Silhouette | None] | None = None,
             held: np.ndarray | None = None, anchor: np.ndarray | None = None) -> EdgeFit:
    """Fit the pose to the edges of the cameras' grey images (None: no frame from that
    camera): ``rounds`` times predict at the current pose, measure, and take
    ``gn_iterations`` stabilised Gauss-Newton steps on the concatenated residuals with the
    joint limits enforced. The stabiliser is anchored at ``q_start``: the steps minimise
    ``|R(q)|^2_W + |q - q_start|^2_S``, ``dq = -(J^T W J + S)^-1 (J^T W R + S (q - q_start))``,
    whose first step is the paper's ``-(J^T J + S)^-1 J^T R``; further steps converge on the
    same measurements without letting weakly observed DOFs wander. ``silhouettes`` (one per
    camera, None where there is none) add the silhouette residuals and measures (see
    :class:`EdgeTrackerConfig`). ``held`` ((26,) bool): DOFs kept at ``q_start`` (clamped)
    while the others are fitted. ``anchor`` (26,): the stabiliser's anchor instead of
    ``q_start`` (clamped), so a fit continued from an earlier fit's pose with the earlier
    start as anchor takes the same steps as further rounds of that fit."""
    sils = list(silhouettes) if silhouettes is not None else [None] * len(cameras)
    if len(sils) != len(cameras):
        raise EdgeTrackerError(f'{len(cameras)} camera(s) but {len(sils)} silhouette(s)')
    if held is not None:
        held = np.asarray(held, dtype=bool)
        if held.shape != (NUM_DOFS,):
            raise EdgeTrackerError(f'held must be {NUM_DOFS} booleans, got {held.shape}')
    q = kin.clamp(np.asarray(q_start, dtype=float))
    q_anchor = q.copy() if anchor is None else kin.clamp(np.asarray(anchor, dtype=float))
    S = np.diag(config.stabilizer_diagonal())
    C = kin.model.coupling_prior() if config.coupling_weight > 0 else None
    iterations = 0
    rms = math.nan
    found: tuple[int, ...] = ()
    usable: tuple[int, ...] = ()
    tips: tuple[int, ...] = ()
    moved = math.inf
    for k in range(rounds):
        if k > 0 and not moved > config.round_min_move_px:
            break               # the last round barely moved: the same edges again
        world = kin.points(q, points.point_link, points.point_local, True)
        measured: list[EdgeMeasurement | None] = []
        for cam, grey, sil in zip(cameras, greys, sils, strict=True):
            if grey is None:
                measured.append(None)
                continue
            pred = predict_features(kin, points, cam, q, config, world)
            meas = measure_features(grey, pred, config, points.tip_row, polarity)
            extra: dict[str, object] = {'lines': line_rows(points, meas)}
            if sil is not None and config.silhouette_weight > 0:
                pix, _, depth = _project_points(cam, world[0], None)
                outline = hand_outline(points, cam, q, pix, depth)
                loose = sil.unexplained(outline, config.silhouette_tolerance_px)[0]
                extra.update(silhouette=sil, loose=_silhouette_targets(
                    loose, pred.base_px, pred.end_px, pred.half_width_px,
                    config.silhouette_points, outline.palm,
                    points if config.silhouette_palm else None))
            measured.append(replace(meas, **extra))
        found = tuple(0 if m is None else int(m.link_found.sum()) for m in measured)
        usable = tuple(0 if m is None else int(m.prediction.link_usable.sum())
                       for m in measured)
        tips = tuple(0 if m is None else int(m.tip_found.sum()) for m in measured)
        digit_found, digit_usable = _digit_counts(points, measured)
        if sum(found) == 0:
            return EdgeFit(q, math.nan, found, usable, tips, iterations,
                           digit_links_found=digit_found, digit_links_usable=digit_usable)
        before = world[0]
        q, steps = _gauss_newton(kin, points, cameras, measured, world, q, q_anchor, S, C,
                                 config, held)
        iterations += steps
        world = kin.points(q, points.point_link, points.point_local, False)
        if config.round_min_move_px > 0 and k + 1 < rounds:
            moved = _largest_move_px(cameras, greys, before, world[0])
        r, _, w = stack_residuals(points, cameras, measured, world, config, jacobian=False)
        rms = float(np.sqrt(np.mean(w * r**2))) if len(r) else math.nan
    disagreement = math.nan
    if config.camera_check and len(cameras) > 1 and measured[0] is not None \
            and measured[0].link_found.any() and any(m is not None for m in measured[1:]):
        alone = [measured[0]] + [None] * (len(cameras) - 1)
        world0 = kin.points(q_anchor, points.point_link, points.point_local, True)
        q0, _ = _gauss_newton(kin, points, cameras, alone, world0, q_anchor.copy(), q_anchor,
                              S, C, config, held)
        disagreement = fingertip_disagreement(kin, q, q0)
    D = len(DIGITS)
    shares = np.full(2 + 2 * D, math.nan)
    checks = config.max_off_silhouette < 1.0 or config.max_unexplained < 1.0 \
        or config.finger_refit or config.max_finger_off_silhouette < 1.0
    if checks and any(sil is not None for sil in sils):
        p_final = world[0]          # the final pose's points, as for the RMS above
        per_camera = []
        for cam, sil in zip(cameras, sils, strict=True):
            if sil is not None:
                pix, _, depth = _project_points(cam, p_final, None)
                per_camera.append(silhouette_measures(points, cam, sil, q, pix, depth, config))
        shares = np.max(per_camera, axis=0)
    return EdgeFit(q, rms, found, usable, tips, iterations, disagreement, float(shares[0]),
                   float(shares[1]), tuple(float(v) for v in shares[2:2 + D]),
                   tuple(float(v) for v in shares[2 + D:]), digit_found, digit_usable)


def _largest_move_px(cameras: Sequence[PinholeCamera], greys: Sequence[np.ndarray | None],
                     before: np.ndarray, after: np.ndarray) -> float:
    """The largest image distance (pixels) any of the points moved from ``before`` to
    ``after`` (primary-frame points (N, 3)) in the cameras with an image."""
    out = 0.0
    for cam, grey in zip(cameras, greys, strict=True):
        if grey is not None:
            d = _project_points(cam, after, None)[0] - _project_points(cam, before, None)[0]
            out = max(out, float(np.sqrt(np.max(np.einsum('ij,ij->i', d, d)))))
    return out


def _digit_counts(points: FeaturePoints, measured: Sequence[EdgeMeasurement | None]
                  ) -> tuple[tuple[int, ...], tuple[int, ...]]:
    """Per digit, the links found and the links usable over the cameras."""
    digit = points.outline_digit[:points.num_links]
    found, usable = np.zeros(len(DIGITS), np.int64), np.zeros(len(DIGITS), np.int64)
    for m in measured:
        if m is not None:
            np.add.at(found, digit[m.link_found], 1)
            np.add.at(usable, digit[m.prediction.link_usable], 1)
    return tuple(int(v) for v in found), tuple(int(v) for v in usable)
