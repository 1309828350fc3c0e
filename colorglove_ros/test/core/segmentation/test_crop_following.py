"""Crop following: after a frame with a hand the segmenter searches the next frame only around
it, and the whole frame again when the hand is not there (or after a frame without one)."""
from __future__ import annotations

import numpy as np
import pytest
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


def _searches(monkeypatch: pytest.MonkeyPatch) -> list[int]:
    """Counts the coarse searches of every segmenter (one entry per search)."""
    calls: list[int] = []
    search = GloveSegmenter._coarse

    def counted(self, *args, **kwargs):
        calls.append(1)
        return search(self, *args, **kwargs)
    monkeypatch.setattr(GloveSegmenter, '_coarse', counted)
    return calls


@pytest.mark.parametrize('every', [2, 3])
def test_the_search_runs_every_few_frames_while_the_hand_is_followed(blob_calibration, blob_glove,
                                                                      monkeypatch,
                                                                      every: int) -> None:
    """``search_every``: while the hand is found, the coarse search runs on one frame in
    ``every``; on the others the region of interest follows the last crop, and a glove moving
    a few pixels per frame gives the observations of a segmenter that searches every frame."""
    searches = _searches(monkeypatch)
    skipping = GloveSegmenter(blob_calibration, follow_margin=2.5, search_every=every)
    frames = [paste_gloves(blob_glove, ((LEFT[0] + 6 * step, LEFT[1] + 3 * step), 1.0))
              for step in range(6)]
    seen = [skipping.process(frame) for frame in frames]
    assert len(searches) == -(-len(frames) // every)      # frames 0, every, 2 every, ...
    searching = GloveSegmenter(blob_calibration, follow_margin=2.5)
    for a, frame in zip(seen, frames, strict=True):
        b = searching.process(frame)
        assert a.hand_found and b.hand_found
        assert np.array_equal(a.tiny_labels, b.tiny_labels)
        # the region of interest lies elsewhere (filters near its edge differ): the same
        # tiny image, the crop equal up to rounding, the blobs within a pixel
        assert (a.crop.scale, a.crop.offset_x, a.crop.offset_y) == pytest.approx(
            (b.crop.scale, b.crop.offset_x, b.crop.offset_y), abs=1e-9)
        assert [x.color_label for x in a.blobs] == [x.color_label for x in b.blobs]
        np.testing.assert_allclose([(x.centroid_x, x.centroid_y, x.pixel_count)
                                    for x in a.blobs],
                                   [(x.centroid_x, x.centroid_y, x.pixel_count)
                                    for x in b.blobs], atol=1.0)


def test_a_hand_that_left_the_region_of_interest_is_searched_for_at_once(
        blob_calibration, blob_glove, monkeypatch) -> None:
    """A frame that would not be searched, but whose hand is no longer found whole inside the
    followed region of interest, is searched after all (the same frame, not the next)."""
    searches = _searches(monkeypatch)
    skipping = GloveSegmenter(blob_calibration, follow_margin=2.5, search_every=5)
    assert abs(_crop_x(skipping, paste_gloves(blob_glove, (LEFT, 1.0))) - LEFT[0]) < 20
    nudged = (LEFT[0] + 4, LEFT[1])
    assert abs(_crop_x(skipping, paste_gloves(blob_glove, (nudged, 1.0))) - LEFT[0]) < 24
    assert len(searches) == 1
    # found, but its crop window reaches past the region of interest: searched
    moved = (LEFT[0] + 50, LEFT[1])
    assert abs(_crop_x(skipping, paste_gloves(blob_glove, (moved, 1.0))) - moved[0]) < 20
    assert len(searches) == 2
    # not found in the region of interest: searched
    assert abs(_crop_x(skipping, paste_gloves(blob_glove, (RIGHT, 1.0))) - RIGHT[0]) < 20
    assert len(searches) == 3
    skipping.lose_track()             # nothing followed: the next frame is searched
    assert abs(_crop_x(skipping, paste_gloves(blob_glove, (RIGHT, 1.0))) - RIGHT[0]) < 20
    assert len(searches) == 4


def test_search_every_is_checked(blob_calibration) -> None:
    from colorglove_ros.core.segmentation.segmenter import SegmentationConfigError

    with pytest.raises(SegmentationConfigError, match='search_every'):
        GloveSegmenter(blob_calibration, search_every=0)


@pytest.mark.parametrize('jump', [False, True])
def test_the_static_background_learns_on_frames_without_the_search(blob_calibration, blob_glove,
                                                                     jump: bool) -> None:
    """The static background counts every frame once, searched or not (or searched after
    all): the still background of a moving glove has matched as many frames in a row as with
    a search on every frame."""
    frames = [paste_gloves(blob_glove, ((LEFT[0] + 6 * step, LEFT[1]), 1.0)) for step in range(6)]
    if jump:           # the glove leaves the region of interest: frame 4 is searched after all
        frames[4:] = [paste_gloves(blob_glove, ((LEFT[0] + 90 + 6 * step, LEFT[1]), 1.0))
                      for step in range(2)]
    skipping = GloveSegmenter(blob_calibration, follow_margin=2.5, search_every=3,
                              background_frames=50)
    searching = GloveSegmenter(blob_calibration, follow_margin=2.5, background_frames=50)
    for frame in frames:
        assert skipping.process(frame).hand_found and searching.process(frame).hand_found
    far = np.s_[:, 110:]       # coarse columns right of the glove
    assert searching.background._matched[far].min() == len(frames) - 1
    assert np.array_equal(skipping.background._matched[far], searching.background._matched[far])
