"""The crop predicted from the tracked pose (core/segmentation/crop_prediction.py): the window
matches the crop of the rendered blob_glove, the feedback serves only fresh predictions, and the
segmenter given one crops the hand, not a glove-coloured neighbour touching it."""
from __future__ import annotations

import numpy as np
import pytest
from segmentation_samples import (
    GREY,
    LEFT,
    paste_gloves,
)

from colorglove_ros.core.pipeline import tracked_crop
from colorglove_ros.core.segmentation.crop import crop_to_tiny, mean_shift_crop
from colorglove_ros.core.segmentation.crop_prediction import (
    CropFeedback,
    CropPrediction,
    covers,
    predicted_size_crop,
    prediction_bounds,
    window_from_moments,
)
from colorglove_ros.core.segmentation.segmenter import GloveSegmenter
from colorglove_ros.core.synthetic import frames as synth
from colorglove_ros.core.tracking.tracker import HandTracker

CAMERA = synth.default_camera()
SIZE = (640, 480)


def _prediction(center: tuple[float, float], half: float, stamp: float = 0.0
                ) -> CropPrediction:
    return CropPrediction(stamp, center, half, SIZE)


def test_window_of_a_uniform_square_is_the_mean_shift_window() -> None:
    ys, xs = np.mgrid[100:160, 200:260]
    uv = np.column_stack([xs.ravel(), ys.ravel()]).astype(float)
    (cx, cy), half = window_from_moments(np.ones(len(uv)), uv)
    assert (cx, cy) == pytest.approx((229.5, 129.5))
    assert half == pytest.approx(2.5 * np.sqrt((60 ** 2 - 1) / 12))
    mask = np.zeros((480, 640), bool)
    mask[100:160, 200:260] = True
    (mx, my), mhalf = mean_shift_crop(mask)
    assert (mx, my) == pytest.approx((cx, cy)) and mhalf == pytest.approx(half, rel=0.05)
    assert window_from_moments(np.zeros(3), uv[:3]) is None


@pytest.fixture(scope='module')
def hand():
    s = synth.Synthesizer()
    yield s
    s.release()


def test_the_prediction_at_the_true_pose_is_the_crop_of_the_rendered_glove(hand) -> None:
    tracker = HandTracker(hand.model, hand.mesh, [CAMERA], glove=hand.glove)
    rng = np.random.default_rng(5)
    for k in range(4):
        q = synth.sample_pose(rng, CAMERA, out_of_frame_prob=0.0)
        frame = synth.render_frame(q, CAMERA, rng, synthesizer=hand)
        (tx, ty), half = mean_shift_crop(frame.labels)
        p = tracked_crop(tracker, q, 0.5 * k)
        assert p.stamp == 0.5 * k and p.image_size == (CAMERA.width, CAMERA.height)
        assert p.half_size == pytest.approx(half, rel=0.1)
        assert np.hypot(tx - p.center_xy[0], ty - p.center_xy[1]) < 0.1 * half


def test_feedback_serves_the_newest_prediction_only_while_fresh() -> None:
    feedback = CropFeedback(max_age_s=0.1)
    assert feedback.for_frame(1.0) is None
    old, new = _prediction((100, 100), 50, 1.0), _prediction((110, 100), 50, 1.05)
    feedback.offer(new)
    feedback.offer(old)                       # older than the one kept: ignored
    assert feedback.for_frame(1.1) is new
    assert feedback.for_frame(1.05) is None   # not older than the frame
    assert feedback.for_frame(1.2) is None    # stale
    assert feedback.select(1.08) is new and feedback.selected is new
    assert feedback.select(1.5) is None and feedback.selected is None
    feedback.clear()
    assert feedback.for_frame(1.1) is None
    off = CropFeedback(max_age_s=0.0)
    off.offer(new)
    assert off.for_frame(1.1) is None
    with pytest.raises(ValueError):
        CropFeedback(max_age_s=-1.0)


def test_bounds_of_the_predicted_window_in_a_reduced_label_image() -> None:
    p = _prediction((100.0, 60.0), 20.0)
    assert prediction_bounds(p, 1.0, (0.0, 0.0), 1.0, (480, 640)) == (80, 121, 40, 81)
    assert prediction_bounds(p, 1.5, (60.0, 40.0), 2.0, (100, 100)) == (5, 36, 0, 26)
    assert prediction_bounds(p, 1.0, (400.0, 0.0), 1.0, (480, 640)) == (0, 0, 40, 81)
    assert covers(p, (90, 50), (101, 61)) and not covers(p, (90, 50), (100, 70))


def test_a_crop_far_off_the_predicted_size_is_trimmed_to_it() -> None:
    labels = np.zeros((200, 300), np.uint8)
    labels[70:130, 70:130] = 3                  # the hand
    labels[60:140, 130:290] = 5                 # a surface touching it
    found = crop_to_tiny(labels)
    assert found.transform.half_size > 1.5 * 75
    window = ((100.0, 100.0), 75.0)
    assert predicted_size_crop(labels, found, window, 0.0, 20) is found
    assert predicted_size_crop(labels, found, window, 3.0, 20) is found
    trimmed = predicted_size_crop(labels, found, window, 1.2, 20)
    assert trimmed.transform.half_size == pytest.approx(75.0)
    assert 100 < trimmed.transform.center_xy[0] < 150   # pulled right by the surface only
    assert predicted_size_crop(labels, found, ((100.0, 100.0), 75.0), 1.2, 10 ** 6) is None


def _touching(glove: tuple[np.ndarray, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """The glove at LEFT and a second, larger copy close to it on its right (a glove-coloured
    neighbour no colour filter can tell from the hand); and the first glove alone."""
    width = glove[0].shape[1]
    right = (LEFT[0] + int(0.5 * width + 0.6 * 1.3 * width), LEFT[1])
    return paste_gloves(glove, (LEFT, 1.0), (right, 1.3)), paste_gloves(glove, (LEFT, 1.0))


def test_a_prediction_keeps_a_touching_neighbour_out_of_the_crop(blob_calibration,
                                                                 blob_glove) -> None:
    both, alone = _touching(blob_glove)
    plain = GloveSegmenter(blob_calibration)
    hand = plain.process(alone).crop
    merged = GloveSegmenter(blob_calibration).process(both).crop
    assert merged.half_size > 1.4 * hand.half_size      # the neighbour grows the crop
    predicted = _prediction(hand.center_xy, hand.half_size)
    segmenter = GloveSegmenter(blob_calibration, prediction_margin=1.3)
    obs = segmenter.process(both, prediction=predicted)
    assert obs.hand_found
    assert obs.crop.half_size == pytest.approx(hand.half_size, rel=0.15)
    assert abs(obs.crop.center_xy[0] - hand.center_xy[0]) < 0.15 * hand.half_size
    # margin 0 (off), or a prediction for another image size: as without one
    for seg, p in ((GloveSegmenter(blob_calibration), predicted),
                   (segmenter, CropPrediction(0.0, hand.center_xy, hand.half_size, (320, 240)))):
        assert seg.process(both, prediction=p).crop.half_size == pytest.approx(
            merged.half_size, rel=0.02)


def test_a_hand_away_from_the_prediction_is_found_on_the_whole_frame(blob_calibration,
                                                                     blob_glove) -> None:
    frame = paste_gloves(blob_glove, (LEFT, 1.0))
    segmenter = GloveSegmenter(blob_calibration, prediction_margin=1.3)
    obs = segmenter.process(frame, prediction=_prediction((500.0, 240.0), 60.0))
    assert obs.hand_found and abs(obs.crop.center_xy[0] - LEFT[0]) < 20
    assert np.all(frame[0, 0] == GREY)
