"""The per-frame recipe (core/pipeline.py): every gate refuses with its reason, a refusal resets
the tracker, and a rendered glove frame goes through segment -> look up -> track in one
process."""
from __future__ import annotations

import math
from dataclasses import replace
from types import SimpleNamespace

import numpy as np
import pytest

from colorglove_ros.core.lookup.search import PoseLookup
from colorglove_ros.core.lookup.types import LookupResult, ProjectionConstraints
from colorglove_ros.core.pipeline import (
    CUT_BY_BORDER,
    FINGERS_OUTSIDE,
    LAST_JOINT_KEYPOINTS,
    NODE_LIMITS,
    UNGATED,
    FramePipeline,
    NoHand,
    StageLimits,
    TemporalPrior,
    Tracked,
    fingers_outside,
    hand_keypoints_at_plausible_depth,
    image_observer,
    look_up,
    segment_frame,
    track,
    tracked_crop,
)
from colorglove_ros.core.segmentation.calibration_fit import (
    fit_color_calibration,
    render_training_frames,
)
from colorglove_ros.core.segmentation.crop import CropTransform, TinyCrop
from colorglove_ros.core.segmentation.crop_prediction import CropFeedback
from colorglove_ros.core.segmentation.segmenter import GloveSegmenter
from colorglove_ros.core.segmentation.types import Blob, Observation
from colorglove_ros.core.synthetic import frames as synth
from colorglove_ros.core.synthetic.conditions import sample_conditions
from colorglove_ros.core.tracking.tracker import HandTracker, IKResult, away_from_border
from colorglove_ros.core.tracking.types import Blobs, CameraObservation, PosePrior
from colorglove_ros.core.validation import InvalidInputError

CAMERA = synth.default_camera()
FAST_FIT = dict(max_per_class=1500, bits=5, augment_copies=1, background_components=6)


@pytest.fixture(scope='module')
def segmenter() -> GloveSegmenter:
    """A segmenter with a quickly fitted calibration (8 rendered training frames)."""
    return GloveSegmenter(fit_color_calibration(render_training_frames(8, 0), seed=0,
                                                **FAST_FIT))


@pytest.fixture(scope='module')
def glove_rgb() -> np.ndarray:
    """A rendered 640x480 'test' frame with the whole gloved hand in view."""
    rng = np.random.default_rng(1)
    q = synth.sample_pose(rng, CAMERA, out_of_frame_prob=0.0)
    return synth.render_frame(q, CAMERA, rng, sample_conditions(rng, 'test')).image_rgb


@pytest.fixture(scope='module')
def lookup(small_database) -> PoseLookup:
    return PoseLookup(small_database, 40, 10)


@pytest.fixture
def tracker(hand) -> HandTracker:
    model, mesh, glove = hand
    return HandTracker(model, mesh, [CAMERA], glove=glove)


class _FakeTracker:
    """A tracker whose update returns a given result; counts its resets."""

    def __init__(self, model, result: IKResult | Exception) -> None:
        self.model = model
        self.cameras = (CAMERA,)
        self.result = result
        self.resets = 0
        self.previous_pose = None

    def update(self, prior, observations, stamp):
        if isinstance(self.result, Exception):
            raise self.result
        return self.result

    def reset(self) -> None:
        self.resets += 1


def _pose(depth_m: float = 0.5) -> np.ndarray:
    q = np.zeros(26)
    q[2] = depth_m
    return q


def _prior(depth_m: float = 0.5, image_distance: float = 0.5) -> PosePrior:
    """A prior whose lookup was a close match unless ``image_distance`` says otherwise."""
    empty = ProjectionConstraints(np.zeros(0, np.int64), np.zeros(0, np.int64),
                                  np.zeros(0, np.int64), np.zeros((0, 2)), np.zeros(0))
    return PosePrior(_pose(depth_m), empty, image_distance=image_distance)


SEEN = [CameraObservation(True, Blobs(np.array([3]), np.array([[320.0, 240.0]]),
                                      np.array([50.0])), CropTransform(4.0, 240.0, 160.0))]


# ---------------------------------------------------------------------------- segment
def test_segment_refuses_a_bad_image_with_its_reason(segmenter) -> None:
    out = segment_frame(segmenter, np.zeros((480, 640), np.uint8))
    assert isinstance(out, NoHand) and out.warn
    assert out.reason.startswith('bad image: ') and 'shape' in out.reason


def test_segment_refuses_an_implausible_observation() -> None:
    crop = CropTransform(2.0, 10.0, 20.0)
    seen = Observation(True, 'ok', 640, 480, np.ones((40, 40), np.uint8), crop,
                       [Blob(3, 900.0, 50.0, 40)])       # centroid outside the image

    fake = SimpleNamespace(process=lambda image, keep_labels=False: seen)
    out = segment_frame(fake, np.zeros((480, 640, 3), np.uint8))
    assert isinstance(out, NoHand) and not out.warn and out.partial is seen
    assert out.reason.startswith('implausible observation: blob centroid')
    seen.blobs = [Blob(3, 100.0, 50.0, 40)]
    assert segment_frame(fake, np.zeros((480, 640, 3), np.uint8)) is seen


def test_segment_passes_the_segmenters_own_no_hand(segmenter) -> None:
    out = segment_frame(segmenter, np.full((480, 640, 3), 128, np.uint8))
    assert isinstance(out, Observation) and not out.hand_found and out.status


# ---------------------------------------------------------------------------- look up
def test_look_up_failure_and_distance_gate(lookup, small_database) -> None:
    crop = CropTransform(4.0, 240.0, 160.0)
    out = look_up(lookup, TinyCrop(np.zeros((40, 40), np.uint8), crop), CAMERA)
    assert isinstance(out, NoHand) and out.warn and out.partial is None
    assert out.reason == 'lookup: query tiny image has no glove pixels'
    # an entry of the database itself: at distance 0, and refused by a negative limit only
    tiny = TinyCrop(np.asarray(small_database.tiny[5]), crop)
    found = look_up(lookup, tiny, CAMERA, limits=NODE_LIMITS)
    assert isinstance(found, LookupResult) and found.distances[0] == pytest.approx(0.0)
    refused = look_up(lookup, TinyCrop(np.roll(tiny.labels, 3, axis=1), crop), CAMERA,
                      limits=StageLimits(max_image_distance=0.5))
    assert isinstance(refused, NoHand) and not refused.warn
    assert isinstance(refused.partial, LookupResult)
    assert 'more than max_image_distance 0.5): not a hand' in refused.reason
    assert isinstance(look_up(lookup, TinyCrop(np.roll(tiny.labels, 3, axis=1), crop),
                              CAMERA, limits=UNGATED), LookupResult)


# ---------------------------------------------------------------------------- track
def test_track_without_a_prior_says_why(hand, tracker) -> None:
    out = track(tracker, None, SEEN, 0.0, upstream_reason='no_glove')
    assert isinstance(out, NoHand) and out.reason == 'no_glove' and not out.warn
    assert track(tracker, None, SEEN, 0.0).reason == 'lost'


def test_track_refuses_a_prior_at_an_implausible_depth(hand) -> None:
    fake = _FakeTracker(hand[0], IKResult(True, 0.0, q=_pose(), num_constraints=5))
    out = track(fake, _prior(depth_m=-0.4), SEEN, 0.0)
    assert isinstance(out, NoHand) and out.warn and fake.resets == 1
    assert out.reason.startswith('bad candidates: hand depth')
    # the evaluation's limits do not look at the depth
    assert isinstance(track(fake, _prior(depth_m=-0.4), SEEN, 0.0, UNGATED), Tracked)


def test_track_refuses_what_the_tracker_cannot_use(hand) -> None:
    from colorglove_ros.core.tracking.types import IKError

    fake = _FakeTracker(hand[0], IKError('camera mismatch'))
    out = track(fake, _prior(), SEEN, 0.0)
    assert isinstance(out, NoHand) and out.reason == 'bad candidates: camera mismatch'
    assert fake.resets == 1


@pytest.mark.parametrize(('result', 'limits', 'reason'), [
    (IKResult(True, 0.0, q=_pose(), num_constraints=0), NODE_LIMITS,
     'no constraint matched an observed blob'),
    (IKResult(True, 0.0, q=np.full(26, np.nan), num_constraints=4), UNGATED, 'non-finite pose'),
    (IKResult(True, 0.0, q=_pose(depth_m=9.0), num_constraints=4), NODE_LIMITS,
     'fitted pose refused: hand depth'),
])
def test_track_refuses_a_fit_with_its_reason(hand, result, limits, reason) -> None:
    fake = _FakeTracker(hand[0], result)
    out = track(fake, _prior(), SEEN, 0.0, limits)
    assert isinstance(out, NoHand) and out.warn and out.reason.startswith(reason)
    assert out.partial is result and fake.resets == 1


@pytest.mark.parametrize(('image_distance', 'share', 'refused'), [
    (3.0, 0.3, True),             # far match, most blobs unexplained: clutter in the crop
    (math.nan, 0.3, True),        # distance unknown: not a close match
    (3.0, math.nan, True),        # no usable blob to explain
    (3.0, 0.8, False),            # far match but the fit explains what was seen
    (1.0, 0.3, False),            # close match: the lookup's own evidence suffices
])
def test_track_refuses_a_fit_on_weak_evidence(hand, image_distance, share, refused) -> None:
    result = IKResult(True, 0.0, q=_pose(), num_constraints=6, explained_blob_share=share)
    fake = _FakeTracker(hand[0], result)
    out = track(fake, _prior(image_distance=image_distance), SEEN, 0.0)
    if refused:
        assert isinstance(out, NoHand) and out.warn and fake.resets == 1
        assert out.reason.startswith('weak evidence: the fitted hand explains')
        assert isinstance(track(fake, _prior(image_distance=image_distance), SEEN, 0.0,
                                UNGATED), Tracked)
    else:
        assert isinstance(out, Tracked)


@pytest.mark.parametrize(('image_distance', 'residual_px', 'refused'), [
    (3.0, 8.0, True),             # far match whose fit misses its own blobs: a pulled crop
    (math.nan, 8.0, True),        # distance unknown: not a close match
    (3.0, 4.0, False),            # far match, but the fitted hand sits on its blobs
    (1.0, 8.0, False),            # close match: the lookup's own evidence suffices
    (3.0, math.nan, False),       # no residual measured (the constraint gate's business)
])
def test_track_refuses_a_poor_fit_after_a_far_lookup(hand, image_distance, residual_px,
                                                     refused) -> None:
    result = IKResult(True, 0.0, q=_pose(), num_constraints=6, explained_blob_share=0.9,
                      reprojection_error_px=residual_px)
    fake = _FakeTracker(hand[0], result)
    out = track(fake, _prior(image_distance=image_distance), SEEN, 0.0)
    if refused:
        assert isinstance(out, NoHand) and out.warn and fake.resets == 1
        assert out.reason.startswith('poor fit: the fitted hand misses its matched blobs by '
                                     '8.0 px')
        off = replace(NODE_LIMITS, max_weak_match_residual_px=math.inf)
        assert isinstance(track(fake, _prior(image_distance=image_distance), SEEN, 0.0, off),
                          Tracked)
    else:
        assert isinstance(out, Tracked)


def test_the_poor_fit_residual_is_in_reference_focal_pixels(tracker) -> None:
    """A camera with twice the reference focal length sees a residual twice as long in its own
    pixels: the same fit passes there."""
    result = IKResult(True, 0.0, q=_pose(), num_constraints=6, explained_blob_share=0.9,
                      reprojection_error_px=8.0)
    fake = _FakeTracker(tracker.model, result)
    fake.config = replace(tracker.config, reference_focal_px=CAMERA.fx)
    assert isinstance(track(fake, _prior(image_distance=3.0), SEEN, 0.0), NoHand)
    fake.config = replace(tracker.config, reference_focal_px=CAMERA.fx / 2.0)
    assert isinstance(track(fake, _prior(image_distance=3.0), SEEN, 0.0), Tracked)


class _GloveTracker(_FakeTracker):
    """A stand-in tracker that also predicts the glove at a pose (a real tracker's patches)."""

    def __init__(self, real: HandTracker, result: IKResult) -> None:
        super().__init__(real.model, result)
        self.patch_surface, self.patch_color = real.patch_surface, real.patch_color
        self.config = real.config


def test_track_refuses_a_fit_showing_glove_the_image_lacks(tracker) -> None:
    q = synth.sample_pose(np.random.default_rng(3), CAMERA, out_of_frame_prob=0.0)
    area, centroid = tracker.patch_surface.visible_patches(q, CAMERA)
    color = tracker.patch_color
    washed_out = (4, 7, 10)             # yellow, orange, lime
    assert area[np.isin(color, washed_out)].sum() > NODE_LIMITS.max_missing_glove_share \
        * area[area >= NODE_LIMITS.min_shown_patch_px].sum()

    def seen(drop: tuple[int, ...]) -> list[CameraObservation]:
        keep = np.flatnonzero((area > 0) & ~np.isin(color, drop))
        return [CameraObservation(True, Blobs(color[keep], centroid[keep], area[keep]),
                                  CropTransform(4.0, 240.0, 160.0))]

    fake = _GloveTracker(tracker, IKResult(True, 0.0, q=q, num_constraints=6,
                                           explained_blob_share=1.0))
    assert isinstance(track(fake, _prior(), seen(()), 0.0), Tracked)
    out = track(fake, _prior(), seen(washed_out), 0.0)
    assert isinstance(out, NoHand) and out.warn and fake.resets == 1
    assert out.reason.startswith('missing glove: ')
    assert all(name in out.reason for name in ('yellow', 'orange', 'lime'))
    for limits in (replace(NODE_LIMITS, max_missing_glove_share=1.0), UNGATED):
        assert isinstance(track(fake, _prior(), seen(washed_out), 0.0, limits), Tracked)


def test_tracker_knows_its_glove_without_being_given_it(hand) -> None:
    model, mesh, glove = hand
    plain = HandTracker(model, mesh, [CAMERA])
    np.testing.assert_array_equal(plain.patch_color, glove.patch_color)
    assert plain.patch_surface.num_patches == len(glove.patch_color)


def test_pose_prior_keeps_the_nearest_image_distance(lookup, small_database) -> None:
    crop = CropTransform(4.0, 240.0, 160.0)
    result = lookup.lookup(np.roll(np.asarray(small_database.tiny[5]), 3, axis=1), crop, CAMERA)
    prior = PosePrior.from_lookup(result)
    assert prior.image_distance == pytest.approx(float(result.distances[0]))
    assert prior.image_distance > 0


def test_track_refuses_a_hand_cut_by_the_image_border(hand) -> None:
    result = IKResult(True, 0.0, q=_pose(), num_constraints=4)
    fake = _FakeTracker(hand[0], result)
    fake.previous_pose = _pose()          # tracked or not: the crop says nothing reliable
    cut = [replace(SEEN[0], cut_by_border=True)]
    out = track(fake, _prior(), cut, 0.0)
    assert isinstance(out, NoHand) and out.reason == CUT_BY_BORDER and not out.warn
    assert fake.resets == 1
    assert isinstance(track(fake, _prior(), cut, 0.0, UNGATED), Tracked)
    assert isinstance(track(fake, _prior(), SEEN, 0.0), Tracked)


def test_track_lets_a_plausible_fit_through_with_its_keypoints(hand) -> None:
    result = IKResult(True, 0.0, q=_pose(), num_constraints=4)
    fake = _FakeTracker(hand[0], result)
    out = track(fake, _prior(), SEEN, 0.0)
    assert isinstance(out, Tracked) and out.result is result and fake.resets == 0
    np.testing.assert_allclose(out.keypoints, hand[0].keypoints(result.q))
    assert isinstance(track(fake, _prior(), SEEN, 0.0, StageLimits(check_depth=False)),
                      Tracked)


def test_track_reweights_a_lookup_result_by_the_previous_pose(hand, lookup, small_database,
                                                              monkeypatch) -> None:
    from colorglove_ros.core.lookup import temporal_prior

    crop = CropTransform(4.0, 240.0, 160.0)
    result = lookup.lookup(np.asarray(small_database.tiny[5]), crop, CAMERA)
    calls = []

    def spy(res, q_prev, tau, weight):
        calls.append((res, q_prev, tau, weight))
        return res

    monkeypatch.setattr(temporal_prior, 'reweight_by_previous', spy)
    fake = _FakeTracker(hand[0], IKResult(True, 0.0, q=_pose(), num_constraints=4))
    fake.previous_pose = _pose(0.6)
    track(fake, result, SEEN, 0.0, UNGATED, temporal=TemporalPrior(0.3, 0.5))
    assert len(calls) == 1 and calls[0][0] is result and calls[0][2:] == (0.3, 0.5)
    np.testing.assert_array_equal(calls[0][1], _pose(0.6))


# ---------------------------------------------------------------------------- one process
def test_a_rendered_glove_frame_goes_through(segmenter, glove_rgb, lookup, tracker) -> None:
    observation = segment_frame(segmenter, glove_rgb)
    assert isinstance(observation, Observation) and observation.hand_found
    # the small test database is far from every real frame: its distance gate and the
    # evidence gates (weak evidence, missing glove) are lifted
    pipeline = FramePipeline(image_observer(segmenter), lookup, CAMERA,
                             limits=StageLimits(max_image_distance=math.inf,
                                                min_explained_blob_share=0.0,
                                                max_missing_glove_share=1.0))
    seen = pipeline.observe([glove_rgb])
    assert seen.cameras[0].hand_found and seen.tiny is not None
    found = pipeline.look_up(seen)
    assert isinstance(found.result, LookupResult) and found.time_ms > 0
    out = pipeline.track(tracker, found, seen, 0.0)
    assert isinstance(out, Tracked), out.reason
    assert out.result.num_constraints > 0 and np.all(np.isfinite(out.result.q))
    assert out.keypoints.shape == (21, 3) and np.all(out.keypoints[:, 2] > 0.1)
    # a frame without the glove: no hand, the tracker forgets the track
    blank = pipeline.process(tracker, [np.full((480, 640, 3), 128, np.uint8)], 1 / 30)
    assert isinstance(blank, NoHand) and blank.reason == 'no crop'
    assert tracker.previous_pose is None


def test_the_pipeline_feeds_a_tracked_frames_crop_forward(segmenter, glove_rgb, lookup,
                                                          tracker) -> None:
    """With a feedback, a tracked frame's crop prediction (the fitted pose's) is what the
    observer of the next frame gives the segmenter, while fresh; no hand makes none."""
    feedback = CropFeedback(max_age_s=0.1)
    given = []

    class Spy:
        def process(self, image, keep_labels=False, prediction=None):
            given.append(prediction)
            return segmenter.process(image, keep_labels=keep_labels, prediction=prediction)

    pipeline = FramePipeline(image_observer(Spy(), feedback=feedback), lookup, CAMERA,
                             limits=StageLimits(max_image_distance=math.inf,
                                                min_explained_blob_share=0.0,
                                                max_missing_glove_share=1.0),
                             feedback=feedback)
    out = pipeline.process(tracker, [glove_rgb], 1.0)
    assert isinstance(out, Tracked), out.reason
    expected = tracked_crop(tracker, out.result.q, 1.0)
    pipeline.process(tracker, [glove_rgb], 1.0 + 1 / 30)
    pipeline.process(tracker, [glove_rgb], 1.5)           # the newest is stale by then
    assert given[0] is None and given[1] == expected and given[2] is None


def test_depth_gate_keypoints_from_the_trackers_kinematics_equal_the_models(tracker) -> None:
    q = np.zeros(26)
    q[2], q[3:6], q[6:] = 0.5, (0.3, -0.4, 0.2), 0.3
    keypoints = hand_keypoints_at_plausible_depth(tracker, q)
    np.testing.assert_allclose(keypoints, tracker.model.keypoints(q), atol=1e-12)
    q[2] = 0.05                                  # closer than any hand can be
    with pytest.raises(InvalidInputError):
        hand_keypoints_at_plausible_depth(tracker, q)


def test_track_refuses_a_fit_leaving_much_glove_outside_the_hand(tracker) -> None:
    q = synth.sample_pose(np.random.default_rng(3), CAMERA, out_of_frame_prob=0.0)
    area, centroid = tracker.patch_surface.visible_patches(q, CAMERA)
    color = tracker.patch_color
    keep = np.flatnonzero(area > 0)
    window = tracked_crop(tracker, q, 0.0)
    far = np.asarray(window.center_xy) + [1.5 * window.half_size, 0.0]

    def seen(clutter_px: float) -> list[CameraObservation]:
        """The hand's blobs and a glove-coloured blob of ``clutter_px`` beside it."""
        return [CameraObservation(True, Blobs(np.append(color[keep], 5),
                                              np.vstack([centroid[keep], far]),
                                              np.append(area[keep], clutter_px)),
                                  CropTransform(4.0, 240.0, 160.0))]

    limits = replace(NODE_LIMITS, max_outside_blob_share=0.2)
    fake = _GloveTracker(tracker, IKResult(True, 0.0, q=q, num_constraints=6,
                                           explained_blob_share=1.0))
    hand_px = area[keep].sum()
    assert isinstance(track(fake, _prior(), seen(0.1 * hand_px), 0.0, limits), Tracked)
    assert isinstance(track(fake, _prior(), seen(hand_px), 0.0), Tracked)   # off by default
    out = track(fake, _prior(), seen(hand_px), 0.0, limits)
    assert isinstance(out, NoHand) and out.warn and fake.resets == 1
    assert out.reason.startswith('glove outside the hand: 50% of the glove blob pixels')
    wide = replace(limits, outside_reach=2.0)
    assert isinstance(track(fake, _prior(), seen(hand_px), 0.0, wide), Tracked)


PATCH_CROP = CropTransform(6.0, 160.0, 120.0)


def _patch_view(tracker: HandTracker, q: np.ndarray) -> tuple[np.ndarray, Blobs]:
    """The glove patches pose ``q`` shows inside the image and a blob at each visible part's
    centroid (its colour, its area): what a perfect segmentation gives (patch ids, blobs)."""
    area, centroid = tracker.patch_surface.visible_patches(q, CAMERA)
    inside = (area >= 30.0) & (centroid[:, 0] >= 0) & (centroid[:, 0] < CAMERA.width) \
        & (centroid[:, 1] >= 0) & (centroid[:, 1] < CAMERA.height)
    ids = np.flatnonzero(inside)
    return ids, Blobs(tracker.patch_color[ids], centroid[ids], area[ids])


def _patch_prior(tracker: HandTracker, hand, q: np.ndarray, ids: np.ndarray,
                 blobs: Blobs) -> PosePrior:
    """A close lookup at ``q`` whose constraints are, as the database's, the vertex of each
    patch in ``ids`` nearest to where its blob in ``blobs`` is (also given in
    :data:`PATCH_CROP`'s tiny image)."""
    model, mesh, glove = hand
    faces = np.asarray(mesh.faces)
    face_patch = np.asarray(glove.face_patch)
    points = mesh.skin(model, q)
    projected = CAMERA.project(points)
    vertices = []
    for patch, xy in zip(ids, blobs.centroid_px, strict=True):
        f = faces[face_patch == patch]
        normal = np.cross(points[f[:, 1]] - points[f[:, 0]], points[f[:, 2]] - points[f[:, 0]])
        own = np.unique(f[np.einsum('ij,ij->i', normal, -points[f[:, 0]]) > 0])   # facing
        vertices.append(own[np.argmin(np.linalg.norm(projected[own] - xy, axis=1))])
    vertices = np.array(vertices)
    constraints = ProjectionConstraints(ids, tracker.patch_color[ids], vertices,
                                        PATCH_CROP.to_tiny(blobs.centroid_px),
                                        np.full(len(ids), 30))
    return PosePrior(q.copy(), constraints, image_distance=0.5)


def test_a_tracked_hand_the_border_cuts_is_followed_from_its_last_pose(hand) -> None:
    model, mesh, glove = hand
    # a hand whose wrist is its lowest keypoint, 66 px below its lowest fingertip
    q0 = synth.sample_pose(np.random.default_rng(11), CAMERA, out_of_frame_prob=0.0)
    # the wrist 20 px above the bottom border; then the hand moves 50 px down, and the border
    # cuts it below the fingertips, while the fingers curl a little
    low = CAMERA.project(model.keypoints(q0))[:, 1].max()
    q0[1] += (CAMERA.height - 20 - low) * q0[2] / CAMERA.fy
    q1 = q0.copy()
    q1[1] += 50 * q0[2] / CAMERA.fy
    q1[7::4] = np.clip(q1[7::4] + 0.05, model.lower_limits[7::4], model.upper_limits[7::4])
    limits = replace(NODE_LIMITS, check_depth=True)

    def tracker_after_one_frame() -> HandTracker:
        tracker = HandTracker(model, mesh, [CAMERA], glove=glove)
        ids, blobs = _patch_view(tracker, q0)
        seen = [CameraObservation(True, blobs, PATCH_CROP)]
        assert isinstance(track(tracker, _patch_prior(tracker, hand, q0, ids, blobs), seen,
                                0.0, limits), Tracked)
        return tracker

    tracker = tracker_after_one_frame()
    ids1, blobs1 = _patch_view(tracker, q1)
    uncut = q1.copy()
    uncut[:3] = q0[:3]
    assert 0 < len(ids1) < len(_patch_view(tracker, uncut)[0])   # the border hides patches
    cut = [CameraObservation(True, blobs1, PATCH_CROP, True)]
    # the lookup of a cut hand is wrong: a prior far from the hand is not used
    wrong = _patch_prior(tracker, hand, _pose(0.9), ids1, blobs1)
    out = track(tracker, wrong, cut, 1 / 30, limits)
    assert isinstance(out, Tracked), getattr(out, 'reason', '')
    assert out.result.followed
    assert out.result.num_constraints >= NODE_LIMITS.follow_min_constraints
    error = np.linalg.norm(model.keypoints(out.result.q) - model.keypoints(q1), axis=1)
    stayed = np.linalg.norm(model.keypoints(q0) - model.keypoints(q1), axis=1)
    assert error.mean() < 0.25 * stayed.mean()            # it followed the image
    assert abs(out.result.q[2] - q1[2]) < 0.01            # and kept the depth
    # the blobs the border cuts (centroid nearer to it than their side) are not matched
    inner = away_from_border(cut[0], CAMERA).blobs
    assert len(inner) < len(blobs1)
    assert out.result.num_constraints <= len(inner)
    # a cut hand the lookup refused (no prior) is followed all the same
    refused = track(tracker_after_one_frame(), None, cut, 1 / 30, limits,
                    upstream_reason='lookup: too far')
    assert isinstance(refused, Tracked) and refused.result.followed
    np.testing.assert_allclose(refused.result.q, out.result.q, atol=1e-9)
    # further down a finger leaves the image: its angles would only be kept
    tip_low = CAMERA.project(model.keypoints(q1)[list(LAST_JOINT_KEYPOINTS)])[:, 1].max()
    q2 = q1.copy()
    q2[1] += (CAMERA.height + 30 - tip_low) * q0[2] / CAMERA.fy
    assert fingers_outside(tracker, q2) and not fingers_outside(tracker, q1)
    ids2, blobs2 = _patch_view(tracker, q2)
    gone = track(tracker, wrong, [CameraObservation(True, blobs2, PATCH_CROP, True)], 2 / 30,
                 limits)
    assert isinstance(gone, NoHand) and gone.reason == FINGERS_OUTSIDE
    assert tracker.previous_pose is None
    # too few of its patches matched: no pose, and the track ends
    tracker = tracker_after_one_frame()
    few = track(tracker, wrong, cut, 1 / 30,
                replace(limits, follow_min_constraints=out.result.num_constraints + 1))
    assert isinstance(few, NoHand) and few.reason.startswith(CUT_BY_BORDER)
    assert 'patches matched' in few.reason and tracker.previous_pose is None
    # off: the cut hand is no hand, and the track ends
    tracker = tracker_after_one_frame()
    off = track(tracker, wrong, cut, 1 / 30, replace(limits, follow_cut_hands=False))
    assert isinstance(off, NoHand) and off.reason == CUT_BY_BORDER
    assert tracker.previous_pose is None
    # a hand first seen cut is never tracked: nothing but the crop would give its depth
    fresh = HandTracker(model, mesh, [CAMERA], glove=glove)
    first = track(fresh, wrong, cut, 0.0, limits)
    assert isinstance(first, NoHand) and first.reason == CUT_BY_BORDER
    # nor after a gap longer than the tracker's max_gap_s
    tracker = tracker_after_one_frame()
    late = track(tracker, wrong, cut, 5.0, limits)
    assert isinstance(late, NoHand) and late.reason == CUT_BY_BORDER
