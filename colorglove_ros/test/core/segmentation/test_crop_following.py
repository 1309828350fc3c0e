"""Crop following: after a frame with a hand the segmenter searches the next frame only around
it, and the whole frame again when the hand is not there (or after a frame without one)."""
from __future__ import annotations

import numpy as np
from segmentation_samples import (
    GREY,
    LEFT,
    RIGHT,
    paste_gloves,
)

from colorglove_ros.core.segmentation.segmenter import GloveSegmenter

# the whole-frame search's crop on the two-glove frame lies at least this far from LEFT
WHOLE_FRAME_SHIFT_PX = 60


def _crop_x(segmenter: GloveSegmenter, frame: np.ndarray) -> float | None:
    obs = segmenter.process(frame)
    return obs.crop.center_xy[0] if obs.hand_found else None


def test_the_search_follows_the_hand_past_a_larger_glove_elsewhere(blob_calibration,
                                                                   blob_glove) -> None:
    """With a second, larger glove appearing far away, the followed hand keeps the crop;
    searching the whole frame (following off) the crop leaves the first glove."""
    two = paste_gloves(blob_glove, (LEFT, 1.0), (RIGHT, 1.4))
    following = GloveSegmenter(blob_calibration, follow_margin=2.5)
    assert abs(_crop_x(following, paste_gloves(blob_glove, (LEFT, 1.0))) - LEFT[0]) < 20
    assert abs(_crop_x(following, two) - LEFT[0]) < 20
    whole = GloveSegmenter(blob_calibration, follow_margin=0.0)
    assert abs(_crop_x(whole, paste_gloves(blob_glove, (LEFT, 1.0))) - LEFT[0]) < 20
    assert abs(_crop_x(whole, two) - LEFT[0]) > WHOLE_FRAME_SHIFT_PX


def test_a_hand_that_left_the_followed_region_is_found_on_the_whole_frame(blob_calibration,
                                                                          blob_glove) -> None:
    following = GloveSegmenter(blob_calibration, follow_margin=2.5)
    assert abs(_crop_x(following, paste_gloves(blob_glove, (LEFT, 1.0))) - LEFT[0]) < 20
    assert abs(_crop_x(following, paste_gloves(blob_glove, (RIGHT, 1.0))) - RIGHT[0]) < 20


def test_nothing_is_followed_after_a_frame_without_hand_or_lose_track(blob_calibration,
                                                                      blob_glove) -> None:
    two = paste_gloves(blob_glove, (LEFT, 1.0), (RIGHT, 1.4))
    following = GloveSegmenter(blob_calibration, follow_margin=2.5)
    assert _crop_x(following, paste_gloves(blob_glove, (LEFT, 1.0))) is not None
    assert _crop_x(following, np.full((480, 640, 3), GREY, np.uint8)) is None
    # searched whole again: the crop leaves the first glove
    assert abs(_crop_x(following, two) - LEFT[0]) > WHOLE_FRAME_SHIFT_PX
    assert abs(_crop_x(following, paste_gloves(blob_glove, (LEFT, 1.0))) - LEFT[0]) < 20
    following.lose_track()
    assert abs(_crop_x(following, two) - LEFT[0]) > WHOLE_FRAME_SHIFT_PX
    assert abs(_crop_x(following, paste_gloves(blob_glove, (LEFT, 1.0))) - LEFT[0]) < 20
    fresh = following.fresh()          # a fresh segmenter follows nothing
    assert abs(_crop_x(fresh, two) - LEFT[0]) > WHOLE_FRAME_SHIFT_PX


def test_following_gives_the_same_observations_on_a_slow_motion(blob_calibration,
                                                                blob_glove) -> None:
    """A glove moving a few pixels per frame: following finds what the whole-frame search
    finds (tiny image, crop and blobs)."""
    following = GloveSegmenter(blob_calibration, follow_margin=2.5)
    whole = GloveSegmenter(blob_calibration, follow_margin=0.0)
    for step in range(6):
        frame = paste_gloves(blob_glove, ((LEFT[0] + 6 * step, LEFT[1] + 3 * step), 1.0))
        a, b = following.process(frame), whole.process(frame)
        assert a.hand_found and b.hand_found
        assert np.array_equal(a.tiny_labels, b.tiny_labels)
        assert a.crop == b.crop and a.blobs == b.blobs


def test_the_scene_colours_are_the_whole_frames_while_following(blob_calibration,
                                                                blob_glove) -> None:
    """A large surface far from the hand in the glove's commonest colour is background, and
    its colour a scene colour the region of interest drops: following the hand, the surface
    outside the followed region still counts, and the observation is the whole-frame one."""
    pixels, mask = blob_glove
    colours, counts = np.unique(pixels[mask].reshape(-1, 3), axis=0, return_counts=True)
    surface = paste_gloves(blob_glove, (LEFT, 1.0))
    surface[40:440, 420:630] = colours[np.argmax(counts)]
    following = GloveSegmenter(blob_calibration, follow_margin=2.5)
    whole = GloveSegmenter(blob_calibration, follow_margin=0.0)
    for frame in (paste_gloves(blob_glove, (LEFT, 1.0)), surface):
        a, b = following.process(frame), whole.process(frame)
    assert b.hand_found and a.hand_found
    assert np.array_equal(a.tiny_labels, b.tiny_labels)
    assert a.crop == b.crop and a.blobs == b.blobs
