"""One frame through the tracker: segment -> look up -> track, each stage a function of the core
objects and plain data that returns the stage's result or a :class:`NoHand` with the reason.

Every gate of the per-frame recipe is here once: a bad image, an implausible observation, a
failed lookup, no database image near enough (``max_image_distance``), a prior the tracker
cannot use (or at an implausible depth), a fit with no matched constraint, a non-finite pose,
a fit on too little evidence (weak evidence, a poor fit, missing glove, glove outside the
hand), a fitted hand at an implausible depth. The ROS nodes (segmentation, lookup, ik) call these
stage functions between their message conversions; the evaluation
(``core.evaluation.sequences``) and a single-process runner go through
:class:`FramePipeline`. No rclpy import.
"""
from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from colorglove_ros.core.hand.model import DIGITS, KEYPOINT_NAMES
from colorglove_ros.core.lookup.types import LookupResult, Neighbours
from colorglove_ros.core.segmentation.crop import TinyCrop
from colorglove_ros.core.segmentation.crop_prediction import (
    CropFeedback,
    CropPrediction,
    predict_crop,
)
from colorglove_ros.core.segmentation.types import Observation
from colorglove_ros.core.tracking.line_constraints import glove_edge_image
from colorglove_ros.core.tracking.types import Blobs, CameraObservation, IKError, PosePrior
from colorglove_ros.core.validation import (
    InvalidInputError,
    InvalidObservationError,
    validate_hand_depth,
    validate_observation,
)

if TYPE_CHECKING:
    from colorglove_ros.core.hand.model import HandModel
    from colorglove_ros.core.tracking.evidence import GloveEvidence
    from colorglove_ros.core.tracking.tracker import IKResult

# The stages import the segmenter, the search and the temporal prior where they run: a node
# imports only the stage it runs (start-up time).

__all__ = [
    'DEFAULT_MAX_IMAGE_DISTANCE', 'CUT_BY_BORDER', 'FINGERS_OUTSIDE', 'LAST_JOINT_KEYPOINTS',
    'fingers_outside', 'StageLimits', 'NODE_LIMITS', 'UNGATED',
    'NoHand', 'Tracked', 'glove_seen',
    'TemporalPrior', 'Observer', 'FrameObservations', 'FrameLookup', 'FramePipeline',
    'segment_frame', 'bad_image', 'observe_image', 'image_observer', 'look_up', 'search',
    'blend', 'too_far', 'track',
    'bad_prior', 'hand_keypoints_at_plausible_depth', 'weak_evidence', 'poor_fit',
    'missing_glove',
    'tracked_crop', 'glove_outside',
]

# Nearest database image farther than this from the observation (tiny-image pixels): glove-
# coloured clutter or noise that resembles no hand pose. lookup_node's parameter default.
DEFAULT_MAX_IMAGE_DISTANCE = 4.5
#: The 'no hand' reason of a hand that reaches the image border.
CUT_BY_BORDER = 'hand cut by the image border: its depth and pose are not known until it is in view'
#: ... and of a followed hand (``StageLimits.follow_cut_hands``) whose fingers leave the image.
FINGERS_OUTSIDE = ('hand cut by the image border: its fingers leave the image, their angles are '
                   'not known until they are in view')
#: The hand model's keypoints of each digit's last joint (the thumb's IP, the fingers' DIP):
#: a distal link beyond it follows the link before it (the DIP-PIP coupling), so a digit
#: whose last joint is in view has no angle the image does not show.
LAST_JOINT_KEYPOINTS = tuple(KEYPOINT_NAMES.index(f'{d}_{"ip" if d == "thumb" else "dip"}')
                             for d in DIGITS)


@dataclass(frozen=True)
class StageLimits:
    """The gates' settings. The defaults are the nodes' (the product): a lookup whose nearest
    database image is farther than ``max_image_distance`` is no hand; with
    ``require_constraint`` a fit that matched no observed blob is refused; with
    ``check_depth`` a prior or a fit with any hand keypoint at an implausible depth from any
    camera (``core.validation.validate_hand_depth``) is refused. With ``refuse_cut_hands`` a
    hand cut by the primary image's border (``CameraObservation.cut_by_border``) is no hand:
    the lookup normalises the visible part as if it were the whole hand, so neither the crop's
    size (depth) nor the nearest entries (pose) can be trusted. With ``follow_cut_hands`` a
    hand tracked on the frame before is followed from that pose instead, without the lookup
    (``HandTracker.follow``: the visible patches matched where the last pose puts them), and
    published while every digit's last joint stays in the image (:data:`FINGERS_OUTSIDE`),
    at least ``follow_min_constraints`` of its patches are matched and it passes every gate
    below as a fit without a close lookup; a hand first seen cut stays no hand.

    Weak evidence: a fit whose lookup was not a close match (nearest database image farther
    than ``close_match_distance``, or unknown) and that explains less than
    ``min_explained_blob_share`` of the primary camera's glove blobs is refused. That is the
    signature of glove-coloured clutter inside the hand's crop: the lookup matched hand plus
    clutter to some pose, and the fitted hand leaves the clutter's blobs unexplained.

    Missing glove: a fit that shows more than ``max_missing_glove_share`` of its visible glove
    area on patches the image lacks is refused (:func:`missing_glove`; 1 turns this off). A
    patch counts when at least ``min_shown_patch_px`` of it is visible (pixels at the IK's
    reference focal length) and is found when a blob of its colour with at least
    ``min_patch_blob_share`` of its visible area lies within ``near_patch_sizes`` patch sizes
    of it. That is the signature of glove colours the segmentation missed: the rest of the
    hand looks like a smaller hand farther away, and the lookup and the IK agree with it.

    Glove outside the hand: a fit with more than ``max_outside_blob_share`` of the primary
    camera's glove blob pixels in blobs centred farther than ``outside_reach`` times the
    fitted hand's crop window (:func:`tracked_crop`) from its centre is refused
    (:func:`glove_outside`; 1 turns this off): glove-coloured clutter in the crop that the
    fitted hand does not account for."""

    max_image_distance: float = DEFAULT_MAX_IMAGE_DISTANCE
    require_constraint: bool = True
    check_depth: bool = True
    refuse_cut_hands: bool = True
    follow_cut_hands: bool = True
    follow_min_constraints: int = 10
    close_match_distance: float = 2.0
    min_explained_blob_share: float = 0.5
    max_weak_match_residual_px: float = 6.0
    max_missing_glove_share: float = 0.2
    min_shown_patch_px: float = 30.0
    near_patch_sizes: float = 1.5
    min_patch_blob_share: float = 0.1
    max_outside_blob_share: float = 1.0
    outside_reach: float = 1.0


NODE_LIMITS = StageLimits()

# Every output of the tracker counts (a non-finite pose is still refused): the IK evaluation
# measures the tracker itself, as its figures always have, not the nodes' refusals.
UNGATED = StageLimits(max_image_distance=math.inf, require_constraint=False, check_depth=False,
                      refuse_cut_hands=False, follow_cut_hands=False,
                      min_explained_blob_share=0.0,
                      max_weak_match_residual_px=math.inf, max_missing_glove_share=1.0,
                      max_outside_blob_share=1.0)


@dataclass(frozen=True)
class NoHand:
    """No hand in this frame at one stage, and why (the nodes publish ``reason`` as the 'no
    hand' status). ``warn``: the stage failed on its input or refused a fit (the nodes log a
    warning), as opposed to nothing seen, the track lost or not a hand. ``partial``: what the
    stage computed before it gave up (the segmenter's ``Observation``, the ``LookupResult``,
    the tracker's ``IKResult``), if anything."""

    reason: str
    warn: bool = False
    partial: Any = None


class Tracked:
    """A tracked frame: the tracker's result (``found``, finite ``q``) and the hand keypoints
    at its pose (computed on first use unless the depth gate already did)."""

    def __init__(self, result: IKResult, model: HandModel,
                 keypoints: np.ndarray | None = None) -> None:
        self.result = result
        self._model = model
        self._keypoints = keypoints

    @property
    def keypoints(self) -> np.ndarray:
        """(21, 3) hand keypoints of the pose in the primary camera's optical frame."""
        if self._keypoints is None:
            self._keypoints = self._model.keypoints(self.result.q)
        return self._keypoints


@dataclass(frozen=True)
class TemporalPrior:
    """Settings of the temporal reweighting of the lookup's neighbours
    (``core.lookup.temporal_prior.reweight_by_previous``) by the tracker's previous output."""

    tau_rad: float
    rotation_weight: float = 1.0


# ---------------------------------------------------------------------------- segment
def bad_image(exc: Exception) -> NoHand:
    """The 'no hand' of a camera image that cannot be segmented (wrong size or encoding)."""
    return NoHand(f'bad image: {exc}', warn=True)


def _check_observation(observation: Observation) -> None:
    """What the lookup and the IK will read from an observation with ``hand_found``
    (``core.validation.validate_observation``); raises ``InvalidObservationError``."""
    blobs = observation.blobs
    crop = observation.crop
    validate_observation(
        image_width=observation.image_width, image_height=observation.image_height,
        tiny_labels=observation.tiny_labels,
        crop=(None, None, None) if crop is None else (crop.scale, crop.offset_x, crop.offset_y),
        blob_color=np.array([b.color_label for b in blobs], dtype=np.int64),
        blob_centroid_px=np.array([[b.centroid_x, b.centroid_y] for b in blobs],
                                  dtype=float).reshape(-1, 2),
        blob_pixel_count=np.array([b.pixel_count for b in blobs], dtype=np.int64),
        glove_pixel_count=observation.glove_pixel_count)


def segment_frame(segmenter: Any, image_rgb: np.ndarray, keep_labels: bool = False,
                  prediction: CropPrediction | None = None,
                  defer_learning: bool = False) -> Observation | NoHand:
    """Segment one (H, W, 3) uint8 RGB image (``GloveSegmenter.process``; with the hand's
    crop ``prediction`` from the tracked pose, :func:`tracked_crop`; with
    ``defer_learning`` the static background learns from it only when the caller calls
    ``segmenter.learn_deferred()``, e.g. after publishing). The observation
    says itself whether the glove was found (``hand_found``, ``status``); :class:`NoHand` for
    an image the segmenter refuses ('bad image') or an observation with a hand that fails its
    own checks ('implausible observation')."""
    from colorglove_ros.core.segmentation.segmenter import SegmentationInputError

    options: dict[str, Any] = {} if prediction is None else {'prediction': prediction}
    if defer_learning:
        options['defer_learning'] = True
    try:
        observation = segmenter.process(image_rgb, keep_labels=keep_labels, **options)
    except SegmentationInputError as exc:
        return bad_image(exc)
    if observation.hand_found:
        try:
            _check_observation(observation)
        except InvalidObservationError as exc:
            return NoHand(f'implausible observation: {exc}', partial=observation)
    return observation


Observer = Callable[[Any, bool], tuple[CameraObservation, TinyCrop | None]]
"""Maps (one camera's view of a frame, is-primary-camera) to the camera's observation for the
tracker and, for the primary camera, the tiny crop the lookup runs on (None = no hand)."""


def observe_image(segmenter: Any, image_rgb: np.ndarray, primary: bool,
                  prediction: CropPrediction | None = None
                  ) -> tuple[CameraObservation, TinyCrop | None]:
    """One camera's observation of an RGB image (:func:`segment_frame`, with the crop
    ``prediction``): its blobs and crop, found when the segmentation found the glove with at
    least one blob; for the primary camera also the tiny crop to look up."""
    observation = segment_frame(segmenter, image_rgb, prediction=prediction)
    if isinstance(observation, NoHand):
        return CameraObservation(False), None
    blobs = Blobs.empty()
    if observation.blobs:
        blobs = Blobs(np.array([b.color_label for b in observation.blobs]),
                      np.array([[b.centroid_x, b.centroid_y] for b in observation.blobs]),
                      np.array([b.pixel_count for b in observation.blobs], float))
    found = bool(observation.hand_found) and len(blobs) > 0
    tiny = TinyCrop(observation.tiny_labels, observation.crop) if found and primary else None
    return CameraObservation(found, blobs, observation.crop, bool(observation.cut_by_border),
                             glove_edge_image(observation.label_image)), tiny


def image_observer(segmenter: Any, image_of: Callable[[Any], np.ndarray] = np.asarray,
                   feedback: CropFeedback | None = None) -> Observer:
    """An :data:`Observer` segmenting each view's RGB image (``image_of(view)``; default: the
    view is the image) with ``segmenter``. A frame's views come primary first, in camera
    order (as :class:`FramePipeline` gives them): every further camera gets a segmenter of its
    own (``segmenter.fresh()``, where it has one), since a segmenter learns its camera's
    static background. With ``feedback`` the primary camera's segmentation gets the crop
    prediction selected for the frame (``CropFeedback.selected``: give the same object to
    the :class:`FramePipeline`, which selects and offers them)."""
    per_camera = [segmenter]
    index = -1

    def observe(view: Any, primary: bool) -> tuple[CameraObservation, TinyCrop | None]:
        nonlocal index
        index = 0 if primary else index + 1
        while len(per_camera) <= index:
            first = per_camera[0]
            per_camera.append(first.fresh() if hasattr(first, 'fresh') else first)
        prediction = feedback.selected if primary and feedback is not None else None
        return observe_image(per_camera[index], image_of(view), primary, prediction)
    return observe


# ---------------------------------------------------------------------------- look up
def look_up(lookup: Any, tiny: TinyCrop, camera: Any, blobs: Blobs | None = None,
            limits: StageLimits = NODE_LIMITS) -> LookupResult | NoHand:
    """Look a tiny crop of ``camera``'s image up (``PoseLookup.lookup``; with the same image's
    ``blobs`` the fingers are blended per finger). :class:`NoHand` when the lookup fails
    ('lookup: ...') or its nearest database image is more than
    ``limits.max_image_distance`` tiny pixels away (not a hand; ``partial`` is the result)."""
    result = _lookup_call(lookup.lookup, tiny.labels, tiny.transform, camera, blobs)
    return result if isinstance(result, NoHand) else _near_enough(result, limits)


def _lookup_call(call: Callable[..., Any], *args: Any) -> Any:
    """``call(*args)`` (a step of ``PoseLookup``), or the 'no hand' of a lookup that failed
    ('lookup: ...')."""
    from colorglove_ros.core.lookup.search import SearchError

    try:
        return call(*args)
    except (SearchError, ValueError) as exc:
        return NoHand(f'lookup: {exc}', warn=True)


def too_far(nearest: float, limits: StageLimits) -> bool:
    """Whether a lookup whose nearest database image is ``nearest`` tiny px away is no hand
    (farther than ``limits.max_image_distance``)."""
    return limits.max_image_distance < math.inf and not nearest <= limits.max_image_distance


def _near_enough(result: LookupResult, limits: StageLimits) -> LookupResult | NoHand:
    """``result``, or :class:`NoHand` when its nearest database image is too far
    (:func:`too_far`; ``partial`` is the result)."""
    if limits.max_image_distance >= math.inf:   # (ungated: a stand-in may have no distances)
        return result
    nearest = float(result.distances[0]) if len(result.distances) else math.inf
    if too_far(nearest, limits):
        return NoHand(f'lookup: nearest database image {nearest:.2f} tiny px away (more '
                      f'than max_image_distance {limits.max_image_distance:g}): not a hand',
                      partial=result)
    return result


def search(lookup: Any, tiny: TinyCrop) -> Neighbours | NoHand:
    """The first part of :func:`look_up` (``PoseLookup.search``): a tiny crop's re-ranked
    candidates, before their poses are blended; :class:`NoHand` when the search fails."""
    return _lookup_call(lookup.search, tiny.labels, tiny.transform)


def blend(lookup: Any, found: Neighbours, camera: Any, blobs: Blobs | None = None,
          limits: StageLimits = NODE_LIMITS) -> LookupResult | NoHand:
    """The rest of :func:`look_up` on :func:`search` 's candidates ``found``
    (``PoseLookup.blend``): ``search`` then ``blend`` give what ``look_up`` gives."""
    result = _lookup_call(lookup.blend, found, camera, blobs)
    return result if isinstance(result, NoHand) else _near_enough(result, limits)


# ---------------------------------------------------------------------------- track
def bad_prior(tracker: Any, exc: Exception) -> NoHand:
    """The 'no hand' of a lookup prior (or observation) the tracker cannot use; the tracker
    starts again from the next frame."""
    tracker.reset()
    return NoHand(f'bad candidates: {exc}', warn=True)


def hand_keypoints_at_plausible_depth(tracker: Any, q: np.ndarray) -> np.ndarray:
    """The hand keypoints of pose ``q`` (primary camera frame), refused with
    ``InvalidPriorError`` when any is at an implausible depth from any of the tracker's
    cameras (behind or just in front of its plane, or far away). With the tracker's own
    kinematics (``kin``), which remembers the poses its fit just visited, the keypoints come
    from there."""
    model = tracker.model
    kin = getattr(tracker, 'kin', None)
    keypoints = model.keypoints(q) if kin is None else \
        kin.points(np.asarray(q, float), model.keypoint_link, model.keypoint_local)[0]
    for camera in tracker.cameras:
        validate_hand_depth(camera.world_to_camera(keypoints), camera.name)
    return keypoints


def weak_evidence(image_distance: float, result: IKResult, limits: StageLimits) -> str:
    """Why the fit rests on too little evidence ('' when it does not): the lookup was not a
    close match (its nearest database image ``image_distance`` tiny pixels away; NaN: no
    lookup, never close) and the fitted hand explains too few of the observed glove blobs
    (:class:`StageLimits`)."""
    share = result.explained_blob_share
    if (limits.min_explained_blob_share <= 0.0
            or image_distance <= limits.close_match_distance
            or share >= limits.min_explained_blob_share):
        return ''
    return (f'weak evidence: the fitted hand explains {share:.0%} of the glove blobs (less '
            f'than {limits.min_explained_blob_share:.0%}) and the nearest database image is '
            f'{image_distance:.2f} tiny px away (more than {limits.close_match_distance:g})')


def primary_pixel_scale(tracker: Any) -> float:
    """How many of the tracker's primary camera's pixels span one pixel at the IK's reference
    focal length (``core.tracking.projection.pixel_scale``): the factor every pixel setting
    of :class:`StageLimits` is scaled by. 1 for a tracker without a ``config`` (a stand-in)."""
    from colorglove_ros.core.tracking.projection import pixel_scale

    config = getattr(tracker, 'config', None)
    return 1.0 if config is None else pixel_scale(tracker.cameras[0], config.reference_focal_px)


def poor_fit(tracker: Any, image_distance: float, result: IKResult, limits: StageLimits
             ) -> str:
    """Why the fit does not fit its own blobs well enough to stand without a close lookup
    ('' when it does, or the gate is off): the lookup was not a close match (its nearest
    database image ``image_distance`` tiny pixels away; NaN: no lookup) and the mean
    reprojection residual is more than ``limits.max_weak_match_residual_px`` (scaled to the
    primary camera's pixels, :func:`primary_pixel_scale`; :class:`StageLimits`)."""
    if (limits.max_weak_match_residual_px >= math.inf
            or image_distance <= limits.close_match_distance):
        return ''
    residual = float(result.reprojection_error_px) / primary_pixel_scale(tracker)
    if not residual > limits.max_weak_match_residual_px:
        return ''
    return (f'poor fit: the fitted hand misses its matched blobs by {residual:.1f} px on '
            f'average (more than max_weak_match_residual_px '
            f'{limits.max_weak_match_residual_px:g}) and the nearest database image is '
            f'{image_distance:.2f} tiny px away (more than {limits.close_match_distance:g})')


def glove_seen(tracker: Any, q: np.ndarray, observation: CameraObservation,
               limits: StageLimits) -> GloveEvidence | None:
    """How much of the glove pose ``q`` shows in the tracker's primary camera has a
    same-colour blob of ``observation`` near it (``core.tracking.evidence.glove_evidence``
    with the tracker's ``patch_surface`` and ``patch_color`` and ``limits``' patch settings;
    of a hand the border cuts, only the patches centred inside the image); None for a tracker
    without a ``patch_surface`` (a stand-in)."""
    from colorglove_ros.core.tracking.evidence import glove_evidence

    surface = getattr(tracker, 'patch_surface', None)
    if surface is None:
        return None
    scale = primary_pixel_scale(tracker)
    return glove_evidence(surface, tracker.patch_color, q, tracker.cameras[0],
                          observation.blobs, min_patch_px=limits.min_shown_patch_px * scale**2,
                          near_patch_sizes=limits.near_patch_sizes,
                          min_blob_share=limits.min_patch_blob_share,
                          inside_image_only=observation.cut_by_border)


def missing_glove(tracker: Any, q: np.ndarray, observation: CameraObservation,
                  limits: StageLimits) -> str:
    """Why pose ``q`` shows glove the primary camera's ``observation`` lacks ('' when it
    does not, or the gate is off): the share of its visible glove area on patches with no
    same-colour blob near them (:func:`glove_seen`) is more than
    ``limits.max_missing_glove_share``. A tracker without a ``patch_surface`` (a stand-in) is
    not gated."""
    from colorglove_ros.core.hand.glove import GLOVE_COLOR_NAMES

    if limits.max_missing_glove_share >= 1.0:
        return ''
    seen = glove_seen(tracker, q, observation, limits)
    if seen is None or not seen.missing_share > limits.max_missing_glove_share:
        return ''
    colors = ', '.join(GLOVE_COLOR_NAMES[c - 1] for c in seen.missing_colors)
    return (f'missing glove: {seen.missing_share:.0%} of the glove the fitted hand shows (more '
            f'than {limits.max_missing_glove_share:.0%}) has no blob of its colour near it '
            f'({colors})')


def tracked_crop(tracker: Any, q: np.ndarray, stamp: float) -> CropPrediction | None:
    """The next frame's crop predicted from the tracked pose ``q`` of the frame at ``stamp``
    in the tracker's primary camera (``core.segmentation.crop_prediction.predict_crop`` on
    its ``patch_surface``): what ik_node publishes and :class:`FramePipeline` feeds back.
    None for a tracker without a patch model (a stand-in) or with no glove in view."""
    surface = getattr(tracker, 'patch_surface', None)
    if surface is None:
        return None
    return predict_crop(surface, q, tracker.cameras[0], stamp)


def glove_outside(tracker: Any, q: np.ndarray, observation: CameraObservation,
                  limits: StageLimits) -> str:
    """Why pose ``q`` leaves much of the primary camera's observed glove outside the hand
    ('' when it does not, or the gate is off): the share of the observation's blob pixels
    in blobs whose centroid lies farther than ``limits.outside_reach`` times the fitted
    hand's crop window (:func:`tracked_crop`; per axis) from its centre is more than
    ``limits.max_outside_blob_share``."""
    if limits.max_outside_blob_share >= 1.0 or not len(observation.blobs):
        return ''
    window = tracked_crop(tracker, q, 0.0)
    if window is None:
        return ''
    blobs = observation.blobs
    reach = limits.outside_reach * window.half_size
    off = np.abs(blobs.centroid_px - np.asarray(window.center_xy)).max(axis=1) > reach
    share = float(blobs.pixel_count[off].sum() / max(blobs.pixel_count.sum(), 1e-9))
    if not share > limits.max_outside_blob_share:
        return ''
    return (f'glove outside the hand: {share:.0%} of the glove blob pixels lie beyond '
            f'{limits.outside_reach:g} crop windows of the fitted hand (more than '
            f'{limits.max_outside_blob_share:.0%})')


def track(tracker: Any, prior: PosePrior | LookupResult | None,
          observations: Sequence[CameraObservation], stamp: float,
          limits: StageLimits = NODE_LIMITS, *, temporal: TemporalPrior | None = None,
          upstream_reason: str = '') -> Tracked | NoHand:
    """Track one frame (``HandTracker.update``) from the lookup's ``prior`` (None: no hand
    upstream, ``upstream_reason`` says why) and one observation per camera (primary first),
    ``stamp`` in seconds. With ``temporal`` the neighbours of a ``LookupResult`` are first
    reweighted by the tracker's previous output.

    :class:`NoHand` when the prior is unusable or at an implausible depth ('bad candidates:
    ...'), the tracker found nothing (the upstream reason, or 'lost'), or the fit is refused:
    no constraint matched an observed blob (``limits.require_constraint``), a non-finite pose,
    weak evidence (:func:`weak_evidence`), a poor fit after a lookup that was not a close
    match (:func:`poor_fit`), glove the image lacks (:func:`missing_glove`),
    glove the fitted hand leaves outside (:func:`glove_outside`) or
    a hand at an implausible depth (``limits.check_depth``); with ``limits.refuse_cut_hands``
    a hand cut by the primary image's border is not tracked from the lookup
    (:data:`CUT_BY_BORDER`, or followed: :func:`_follow_cut_hand`). A refusal resets the
    tracker.
    """
    if (limits.refuse_cut_hands and observations and observations[0].hand_found
            and observations[0].cut_by_border
            and (prior is not None or _followable(tracker, limits))):
        return _follow_cut_hand(tracker, observations, stamp, limits)
    if temporal is not None and prior is not None:
        from colorglove_ros.core.lookup.temporal_prior import reweight_by_previous

        prior = reweight_by_previous(prior, tracker.previous_pose, temporal.tau_rad,
                                     temporal.rotation_weight)
    try:
        if prior is not None and not isinstance(prior, PosePrior):
            prior = PosePrior.from_lookup(prior)
        if prior is not None and limits.check_depth:
            hand_keypoints_at_plausible_depth(tracker, prior.q_blend)
        result = tracker.update(prior, observations, stamp)
    except (IKError, InvalidInputError, ValueError) as exc:
        return bad_prior(tracker, exc)
    if not result.found or result.q is None:
        return NoHand(upstream_reason or 'lost', partial=result)
    return _gated(tracker, math.nan if prior is None else prior.image_distance, result,
                  observations, limits)


def _followable(tracker: Any, limits: StageLimits) -> bool:
    """Whether ``limits`` let a cut hand be followed and ``tracker`` can follow it (it has a
    ``follow`` method and tracked the frame before)."""
    return (limits.follow_cut_hands and getattr(tracker, 'follow', None) is not None
            and getattr(tracker, 'previous_pose', None) is not None)


def _follow_cut_hand(tracker: Any, observations: Sequence[CameraObservation], stamp: float,
                     limits: StageLimits) -> Tracked | NoHand:
    """A hand the primary image's border cuts: with ``limits.follow_cut_hands`` and a hand
    tracked on the frame before, followed from that pose without the lookup
    (``HandTracker.follow``) and gated as a fit after a far lookup (the evidence and residual
    gates apply in full), also when the lookup refused it; else, or when that fails,
    :data:`CUT_BY_BORDER`. A hand first seen cut is never tracked: nothing but the crop would
    give its depth."""
    if not _followable(tracker, limits):
        tracker.reset()
        return NoHand(CUT_BY_BORDER)
    try:
        result = tracker.follow(observations, stamp)
    except (IKError, InvalidInputError, ValueError) as exc:
        return bad_prior(tracker, exc)
    if not result.found or result.q is None:
        tracker.reset()
        return NoHand(CUT_BY_BORDER, partial=result)
    if fingers_outside(tracker, result.q):
        tracker.reset()
        return NoHand(FINGERS_OUTSIDE, partial=result)
    if result.num_constraints < limits.follow_min_constraints:
        tracker.reset()
        return NoHand(f'{CUT_BY_BORDER} (followed, {result.num_constraints} patches matched, '
                      f'fewer than {limits.follow_min_constraints})', partial=result)
    return _gated(tracker, math.nan, result, observations, limits)


def fingers_outside(tracker: Any, q: np.ndarray) -> bool:
    """Whether the last joint of a digit of pose ``q`` (:data:`LAST_JOINT_KEYPOINTS`)
    projects outside the tracker's primary image (or behind it): a followed hand's finger out
    of view would only keep its last angles."""
    camera = tracker.cameras[0]
    joints = camera.world_to_camera(
        tracker.model.keypoints(np.asarray(q, float))[list(LAST_JOINT_KEYPOINTS)])
    return bool(np.any(joints[:, 2] <= 0.0) or not camera.in_image(camera.project(joints)).all())


def _gated(tracker: Any, image_distance: float, result: IKResult,
           observations: Sequence[CameraObservation], limits: StageLimits) -> Tracked | NoHand:
    """The fit ``result`` as published, or refused (the tracker reset) with the first gate
    it fails (:func:`track`); ``image_distance`` is the lookup's nearest image distance
    (NaN: none)."""
    reason = ''
    keypoints = None
    if limits.require_constraint and result.num_constraints == 0:
        reason = 'no constraint matched an observed blob'
    elif not np.all(np.isfinite(result.q)):
        reason = 'non-finite pose'
    elif weak := weak_evidence(image_distance, result, limits):
        reason = weak
    elif poor := poor_fit(tracker, image_distance, result, limits):
        reason = poor
    elif missing := missing_glove(tracker, result.q, observations[0], limits):
        reason = missing
    elif outside := glove_outside(tracker, result.q, observations[0], limits):
        reason = outside
    elif limits.check_depth:
        try:
            keypoints = hand_keypoints_at_plausible_depth(tracker, result.q)
        except InvalidInputError as exc:
            reason = f'fitted pose refused: {exc}'
    if reason:
        tracker.reset()
        return NoHand(reason, warn=True, partial=result)
    return Tracked(result, tracker.model, keypoints)


# ---------------------------------------------------------------------------- one process
@dataclass(frozen=True)
class FrameObservations:
    """What every camera saw in one frame (primary first) and the primary camera's tiny crop
    (None = no hand)."""

    cameras: tuple[CameraObservation, ...]
    tiny: TinyCrop | None


@dataclass(frozen=True)
class FrameLookup:
    """The look-up stage's outcome for one frame and its wall time (0 when nothing was looked
    up)."""

    outcome: LookupResult | NoHand
    time_ms: float

    @property
    def result(self) -> LookupResult | None:
        """The lookup result, None when no hand."""
        return None if isinstance(self.outcome, NoHand) else self.outcome


class FramePipeline:
    """Observe -> look up -> track in one process: ``observer`` turns each camera's view into
    its observation (:func:`image_observer` segments RGB images), the lookup runs once on the
    primary camera (``camera``), and any number of trackers (whose camera rigs start with the
    same primary camera) track from that one lookup. With ``finger_evidence`` the lookup gets
    the primary camera's blobs; ``limits`` are the gates (the nodes' by default);
    ``temporal`` reweights the neighbours by each tracker's previous output. With
    ``feedback`` (the object its observer reads, :func:`image_observer`), :meth:`process`
    feeds each tracked frame's crop prediction (:func:`tracked_crop`) forward to the next
    frames, as ik_node and segmentation_node do over the crop prediction topic.
    ``last_lookup`` is the last :meth:`process` frame's lookup (None before the first)."""

    def __init__(self, observer: Observer, lookup: Any, camera: Any, *,
                 limits: StageLimits = NODE_LIMITS, finger_evidence: bool = True,
                 temporal: TemporalPrior | None = None,
                 feedback: CropFeedback | None = None) -> None:
        self.observer = observer
        self.lookup = lookup
        self.camera = camera
        self.limits = limits
        self.finger_evidence = bool(finger_evidence)
        self.temporal = temporal
        self.feedback = feedback
        self.last_lookup: FrameLookup | None = None

    def observe(self, views: Sequence[Any]) -> FrameObservations:
        """Every camera's observation of one frame's views (primary first)."""
        seen = [self.observer(view, k == 0) for k, view in enumerate(views)]
        return FrameObservations(tuple(obs for obs, _ in seen), seen[0][1] if seen else None)

    def look_up(self, seen: FrameObservations) -> FrameLookup:
        """:func:`look_up` on the primary camera's crop, timed; no hand without one."""
        primary = seen.cameras[0] if seen.cameras else None
        if seen.tiny is None or primary is None or not primary.hand_found:
            return FrameLookup(NoHand('no crop'), 0.0)
        started = time.perf_counter()
        outcome = look_up(self.lookup, seen.tiny, self.camera,
                          primary.blobs if self.finger_evidence else None, self.limits)
        return FrameLookup(outcome, 1e3 * (time.perf_counter() - started))

    def track(self, tracker: Any, found: FrameLookup, seen: FrameObservations,
              stamp: float) -> Tracked | NoHand:
        """:func:`track` with the frame's lookup and the observations of the tracker's own
        cameras (the first ``len(tracker.cameras)``)."""
        outcome = found.outcome
        prior = None if isinstance(outcome, NoHand) else outcome
        return track(tracker, prior, seen.cameras[:len(tracker.cameras)], stamp, self.limits,
                     temporal=self.temporal,
                     upstream_reason=outcome.reason if isinstance(outcome, NoHand) else '')

    def process(self, tracker: Any, views: Sequence[Any], stamp: float) -> Tracked | NoHand:
        """One frame: observe every view (with the crop prediction the feedback selects for
        ``stamp``), look up, track (a tracked frame's prediction is offered to the
        feedback)."""
        if self.feedback is not None:
            self.feedback.select(stamp)
        seen = self.observe(views)
        self.last_lookup = self.look_up(seen)
        outcome = self.track(tracker, self.last_lookup, seen, stamp)
        if self.feedback is not None and isinstance(outcome, Tracked):
            self.feedback.offer(tracked_crop(tracker, outcome.result.q, stamp))
        return outcome
