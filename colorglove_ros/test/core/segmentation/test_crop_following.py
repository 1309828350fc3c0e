"""Crop following: after a frame with a hand the segmenter searches the next frame only around
it, and the whole frame again when the hand is not there (or after a frame without one)."""
from __future__ import annotations

import cv2
import numpy as np
import pytest
from segmentation_samples import blob_glove_calibration

from colorglove_ros.core.segmentation.segmenter import GloveSegmenter
from colorglove_ros.core.synthetic.blob_glove import (
    BlobConditions,
    render_blob_frame,
)

GREY = 110
LEFT, RIGHT = (150, 240), (470, 240)      # glove centres (x, y) in a 640x480 frame
# the whole-frame search's crop on the two-glove frame lies at least this far from LEFT
WHOLE_FRAME_SHIFT_PX = 60


@pytest.fixture(scope='module')
def calibration():
    return blob_glove_calibration()


@pytest.fixture(scope='module')
def glove() -> tuple[np.ndarray, np.ndarray]:
    """A clean blob glove's pixels and mask, cut to its bounding box."""
    rng = np.random.default_rng(3)
    image, labels = render_blob_frame(rng, BlobConditions(1.0, (1.0, 1.0, 1.0), 1.0, 0, False,
                                                          1.0))
    ys, xs = np.nonzero(labels)
    box = np.s_[ys.min():ys.max() + 1, xs.min():xs.max() + 1]
    return image[box], labels[box] > 0


def _frame(glove: tuple[np.ndarray, np.ndarray], *placed: tuple[tuple[int, int], float]
           ) -> np.ndarray:
    """A grey frame with the glove pasted centred at each (centre, scale)."""
    frame = np.full((480, 640, 3), GREY, np.uint8)
    pixels, mask = glove
    for (cx, cy), scale in placed:
        size = (round(pixels.shape[1] * scale), round(pixels.shape[0] * scale))
        p = cv2.resize(pixels, size, interpolation=cv2.INTER_NEAREST)
        m = cv2.resize(mask.view(np.uint8), size, interpolation=cv2.INTER_NEAREST) > 0
        y0, x0 = cy - size[1] // 2, cx - size[0] // 2
        frame[y0:y0 + size[1], x0:x0 + size[0]][m] = p[m]
    return frame


def _crop_x(segmenter: GloveSegmenter, frame: np.ndarray) -> float | None:
    obs = segmenter.process(frame)
    return obs.crop.center_xy[0] if obs.hand_found else None


def test_the_search_follows_the_hand_past_a_larger_glove_elsewhere(calibration, glove) -> None:
    """With a second, larger glove appearing far away, the followed hand keeps the crop;
    searching the whole frame (following off) the crop leaves the first glove."""
    two = _frame(glove, (LEFT, 1.0), (RIGHT, 1.4))
    following = GloveSegmenter(calibration, follow_margin=2.5)
    assert abs(_crop_x(following, _frame(glove, (LEFT, 1.0))) - LEFT[0]) < 20
    assert abs(_crop_x(following, two) - LEFT[0]) < 20
    whole = GloveSegmenter(calibration, follow_margin=0.0)
    assert abs(_crop_x(whole, _frame(glove, (LEFT, 1.0))) - LEFT[0]) < 20
    assert abs(_crop_x(whole, two) - LEFT[0]) > WHOLE_FRAME_SHIFT_PX


def test_a_hand_that_left_the_followed_region_is_found_on_the_whole_frame(calibration,
                                                                          glove) -> None:
    following = GloveSegmenter(calibration, follow_margin=2.5)
    assert abs(_crop_x(following, _frame(glove, (LEFT, 1.0))) - LEFT[0]) < 20
    assert abs(_crop_x(following, _frame(glove, (RIGHT, 1.0))) - RIGHT[0]) < 20


def test_nothing_is_followed_after_a_frame_without_hand_or_lose_track(calibration,
                                                                      glove) -> None:
    two = _frame(glove, (LEFT, 1.0), (RIGHT, 1.4))
    following = GloveSegmenter(calibration, follow_margin=2.5)
    assert _crop_x(following, _frame(glove, (LEFT, 1.0))) is not None
    assert _crop_x(following, np.full((480, 640, 3), GREY, np.uint8)) is None
    # searched whole again: the crop leaves the first glove
    assert abs(_crop_x(following, two) - LEFT[0]) > WHOLE_FRAME_SHIFT_PX
    assert abs(_crop_x(following, _frame(glove, (LEFT, 1.0))) - LEFT[0]) < 20
    following.lose_track()
    assert abs(_crop_x(following, two) - LEFT[0]) > WHOLE_FRAME_SHIFT_PX
    assert abs(_crop_x(following, _frame(glove, (LEFT, 1.0))) - LEFT[0]) < 20
    fresh = following.fresh()          # a fresh segmenter follows nothing
    assert abs(_crop_x(fresh, two) - LEFT[0]) > WHOLE_FRAME_SHIFT_PX


def test_following_gives_the_same_observations_on_a_slow_motion(calibration, glove) -> None:
    """A glove moving a few pixels per frame: following finds what the whole-frame search
    finds (tiny image, crop and blobs)."""
    following = GloveSegmenter(calibration, follow_margin=2.5)
    whole = GloveSegmenter(calibration, follow_margin=0.0)
    for step in range(6):
        frame = _frame(glove, ((LEFT[0] + 6 * step, LEFT[1] + 3 * step), 1.0))
        a, b = following.process(frame), whole.process(frame)
        assert a.hand_found and b.hand_found
        assert np.array_equal(a.tiny_labels, b.tiny_labels)
        assert a.crop == b.crop and a.blobs == b.blobs


def test_the_scene_colours_are_the_whole_frames_while_following(calibration, glove) -> None:
    """A large surface far from the hand in the glove's commonest colour is background, and
    its colour a scene colour the region of interest drops: following the hand, the surface
    outside the followed region still counts, and the observation is the whole-frame one."""
    pixels, mask = glove
    colours, counts = np.unique(pixels[mask].reshape(-1, 3), axis=0, return_counts=True)
    surface = _frame(glove, (LEFT, 1.0))
    surface[40:440, 420:630] = colours[np.argmax(counts)]
    following = GloveSegmenter(calibration, follow_margin=2.5)
    whole = GloveSegmenter(calibration, follow_margin=0.0)
    for frame in (_frame(glove, (LEFT, 1.0)), surface):
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
def test_the_search_runs_every_few_frames_while_the_hand_is_followed(calibration, glove,
                                                                      monkeypatch,
                                                                      every: int) -> None:
    """``search_every``: while the hand is found, the coarse search runs on one frame in
    ``every``; on the others the region of interest follows the last crop, and a glove moving
    a few pixels per frame gives the observations of a segmenter that searches every frame."""
    searches = _searches(monkeypatch)
    skipping = GloveSegmenter(calibration, follow_margin=2.5, search_every=every)
    frames = [_frame(glove, ((LEFT[0] + 6 * step, LEFT[1] + 3 * step), 1.0))
              for step in range(6)]
    seen = [skipping.process(frame) for frame in frames]
    assert len(searches) == -(-len(frames) // every)      # frames 0, every, 2 every, ...
    searching = GloveSegmenter(calibration, follow_margin=2.5)
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


def test_a_hand_that_left_the_region_of_interest_is_searched_for_at_once(calibration, glove,
                                                                         monkeypatch) -> None:
    """A frame that would not be searched, but whose hand is no longer found whole inside the
    followed region of interest, is searched after all (the same frame, not the next)."""
    searches = _searches(monkeypatch)
    skipping = GloveSegmenter(calibration, follow_margin=2.5, search_every=5)
    assert abs(_crop_x(skipping, _frame(glove, (LEFT, 1.0))) - LEFT[0]) < 20
    assert abs(_crop_x(skipping, _frame(glove, ((LEFT[0] + 4, LEFT[1]), 1.0))) - LEFT[0]) < 24
    assert len(searches) == 1
    # found, but its crop window reaches past the region of interest: searched
    moved = (LEFT[0] + 50, LEFT[1])
    assert abs(_crop_x(skipping, _frame(glove, (moved, 1.0))) - moved[0]) < 20
    assert len(searches) == 2
    assert abs(_crop_x(skipping, _frame(glove, (RIGHT, 1.0))) - RIGHT[0]) < 20   # not found
    assert len(searches) == 3
    skipping.lose_track()             # nothing followed: the next frame is searched
    assert abs(_crop_x(skipping, _frame(glove, (RIGHT, 1.0))) - RIGHT[0]) < 20
    assert len(searches) == 4


def test_search_every_is_checked(calibration) -> None:
    from colorglove_ros.core.segmentation.segmenter import SegmentationConfigError

    with pytest.raises(SegmentationConfigError, match='search_every'):
        GloveSegmenter(calibration, search_every=0)


@pytest.mark.parametrize('jump', [False, True])
def test_the_static_background_learns_on_frames_without_the_search(calibration, glove,
                                                                     jump: bool) -> None:
    """The static background counts every frame once, searched or not (or searched after
    all): the still background of a moving glove has matched as many frames in a row as with
    a search on every frame."""
    frames = [_frame(glove, ((LEFT[0] + 6 * step, LEFT[1]), 1.0)) for step in range(6)]
    if jump:           # the glove leaves the region of interest: frame 4 is searched after all
        frames[4:] = [_frame(glove, ((LEFT[0] + 90 + 6 * step, LEFT[1]), 1.0))
                      for step in range(2)]
    skipping = GloveSegmenter(calibration, follow_margin=2.5, search_every=3,
                              background_frames=50)
    searching = GloveSegmenter(calibration, follow_margin=2.5, background_frames=50)
    for frame in frames:
        assert skipping.process(frame).hand_found and searching.process(frame).hand_found
    far = np.s_[:, 110:]       # coarse columns right of the glove
    assert searching.background._matched[far].min() == len(frames) - 1
    assert np.array_equal(skipping.background._matched[far], searching.background._matched[far])
