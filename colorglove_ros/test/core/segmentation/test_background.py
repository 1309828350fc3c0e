"""Tests for the static background a segmenter learns from its camera's frames."""
from __future__ import annotations

import numpy as np
import pytest
from segmentation_reference import background_match_reference
from segmentation_samples import blob_glove_calibration

from colorglove_ros.core.hand.glove import GLOVE_PALETTE_RGB
from colorglove_ros.core.pipeline import image_observer
from colorglove_ros.core.segmentation import segmentation_kernel
from colorglove_ros.core.segmentation.background import StaticBackground
from colorglove_ros.core.segmentation.crop import compiled_kernels, crop_to_tiny
from colorglove_ros.core.segmentation.segmenter import GloveSegmenter, SegmentationConfigError
from colorglove_ros.core.synthetic.blob_glove import (
    BlobConditions,
    render_blob_frame,
)


def _feed(model: StaticBackground, frame: np.ndarray, glove: np.ndarray | None = None
          ) -> np.ndarray | None:
    learnt = model.match(frame)
    model.update(frame, glove)
    return learnt


def _frames(rng: np.random.Generator, count: int, shape: tuple[int, int]) -> list[np.ndarray]:
    """A still scene with sensor noise, a square moving across it, and now and then a jump
    of most of the frame (which restarts the model) or a frame of another size."""
    scene = rng.integers(0, 256, (*shape, 3), dtype=np.uint8)
    frames = []
    for i in range(count):
        noise = rng.integers(-14, 15, scene.shape)   # beyond the tolerance on some pixels
        frame = np.clip(scene.astype(int) + noise * (rng.random(shape) < 0.1)[..., None],
                        0, 255).astype(np.uint8)
        y, x = (i * 3) % max(shape[0] - 4, 1), (i * 5) % max(shape[1] - 4, 1)
        frame[y:y + 4, x:x + 4] = rng.integers(0, 256, 3, dtype=np.uint8)
        if i % 17 == 16:
            frame = 255 - frame
        if i % 23 == 22:
            frame = np.ascontiguousarray(frame[1:, 1:])
        frames.append(frame)
    return frames


@pytest.mark.parametrize('seed', range(8))
def test_the_compiled_match_is_the_numpy_match_bit_for_bit(seed: int) -> None:
    """The match in one compiled pass (``segmentation_kernel.background_match``) against
    main's numpy and OpenCV match, frame after frame through the same updates: the learnt
    background (or None), the frame's match and its float copy, with or without the
    remembered colours and the glove mask, at a tolerance that float32 cannot hold exactly
    (the comparison is in float32, as NumPy 2 compares a float32 array with a Python float),
    on strided frames too."""
    rng = np.random.default_rng(seed)
    shape = (int(rng.integers(3, 40)), int(rng.integers(3, 50)))
    tolerance = (12.0, 12.3, 0.0, 7.7)[seed % 4]
    settings = dict(frames_needed=int(rng.integers(1, 5)), tolerance=tolerance,
                    remember=seed % 2 == 0, max_changed_share=(0.5, 0.95)[seed % 3 == 0])
    model, reference = StaticBackground(**settings), StaticBackground(**settings)
    matched = 0
    for i, frame in enumerate(_frames(rng, 60, shape)):
        if i % 7 == 3:
            frame = frame[::-1]          # a view with negative strides
        glove = None if i % 5 == 0 else rng.random(frame.shape[:2]) < 0.2
        got, want = model.match(frame), background_match_reference(reference, frame)
        assert (got is None) == (want is None), i
        if want is not None:
            matched += 1
            assert got.dtype == want.dtype and np.array_equal(got, want), i
        for name in ('_same', '_frame'):
            a, b = getattr(model, name), getattr(reference, name)
            assert (a is None) == (b is None), (i, name)
            if b is not None:
                assert a.dtype == b.dtype and np.array_equal(a, b), (i, name)
        model.update(frame, glove)
        reference.update(frame, glove)
        for name in ('_colour', '_matched', '_learnt'):
            a, b = getattr(model, name), getattr(reference, name)
            assert (a is None) == (b is None)
            if b is not None:
                assert np.array_equal(a, b, equal_nan=True), (i, name)
    assert matched >= 3, matched


def test_the_match_kernel_takes_nan_colours_and_float32_tolerances() -> None:
    """``background_match`` directly: a NaN running or remembered colour matches nothing, the
    tolerance is compared in float32, the count is of the pixels that match, and the learnt
    background needs the count reached or the remembered colour outside the glove."""
    compiled_kernels()
    small = np.array([[[10, 20, 30], [10, 20, 30], [0, 0, 0]]], np.uint8)
    # (the third pixel differs by float32(12.3) exactly: within it in float32, not in float64)
    colour = np.array([[[22.3, 20, 30], [np.nan, 20, 30], [12.3, 0, 0]]], np.float32)
    learnt = np.array([[[np.nan] * 3, [10, 20, 30], [0, 0, 0]]], np.float32)
    matched = np.array([[5, 0, 2]], np.int32)
    frame = np.empty(small.shape, np.float32)
    same, back = np.empty((1, 3), bool), np.empty((1, 3), bool)
    count = segmentation_kernel.background_match(
        small, colour, matched, 3, learnt, np.array([[False, False, True]]),
        np.float32(12.3), frame, same, back)
    assert count == 2 and same.tolist() == [[True, False, True]]
    assert np.array_equal(frame, small.astype(np.float32))
    assert back.tolist() == [[True, True, False]]     # counted; remembered; glove, count 2 < 3
    empty3, empty2 = np.zeros((0, 0, 3), np.float32), np.zeros((0, 0), bool)
    segmentation_kernel.background_match(small, colour, matched, 2, empty3, empty2,
                                         np.float32(12.3), frame, same, back)
    assert back.tolist() == [[True, False, True]]


def test_a_pixel_that_holds_still_becomes_background_and_a_change_restarts_it() -> None:
    frame = np.random.default_rng(0).integers(0, 256, (12, 16, 3), dtype=np.uint8)
    model = StaticBackground(frames_needed=3, tolerance=10)
    seen = [_feed(model, frame) for _ in range(4)]
    assert all(s is None for s in seen)          # the first frame, then 3 matching ones
    learnt = _feed(model, frame)
    assert learnt is not None and learnt.all()
    moved = frame.copy()
    moved[2:4, 5:7] = 255 - moved[2:4, 5:7]      # something moves there
    learnt = _feed(model, moved)
    assert not learnt[2:4, 5:7].any() and learnt.sum() == learnt.size - 4
    learnt = _feed(model, moved)                 # the changed pixels start again
    assert not learnt[2:4, 5:7].any()
    noisy = np.clip(moved.astype(int) + 6, 0, 255).astype(np.uint8)   # within tolerance
    assert _feed(model, noisy)[0, 0]


def test_the_glove_never_becomes_background_and_a_moved_camera_starts_again() -> None:
    frame = np.random.default_rng(1).integers(0, 256, (12, 16, 3), dtype=np.uint8)
    glove = np.zeros((12, 16), bool)
    glove[3:8, 4:10] = True
    model = StaticBackground(frames_needed=2, tolerance=10)
    for _ in range(10):
        learnt = _feed(model, frame, glove)
    assert learnt is not None and not learnt[glove].any() and learnt[~glove].all()
    other = np.random.default_rng(2).integers(0, 256, (12, 16, 3), dtype=np.uint8)
    assert _feed(model, other) is None           # most of the frame changed: forget all
    assert _feed(model, frame[:, :8]) is None    # another size: forget all
    off = StaticBackground(frames_needed=0, tolerance=10)
    assert not off.enabled and all(_feed(off, frame) is None for _ in range(5))


@pytest.mark.parametrize('remember', [False, True])
def test_a_surface_uncovered_as_it_was_is_background_at_once_when_remembered(
        remember: bool) -> None:
    """An arm sweeping over a learnt surface: with ``remember`` the pixels it uncovers are
    background again in the first frame they show their old colour (without, only after
    ``frames_needed`` frames); pixels uncovered showing something else are not, nor pixels
    the glove covered a frame ago (a glove of the surface's colour)."""
    frame = np.random.default_rng(3).integers(0, 256, (12, 16, 3), dtype=np.uint8)
    model = StaticBackground(frames_needed=3, tolerance=10, remember=remember)
    for _ in range(5):
        learnt = _feed(model, frame)
    assert learnt is not None and learnt.all()
    covered = frame.copy()
    covered[:, 4:9] = 255 - covered[:, 4:9]      # the arm over columns 4..8
    for _ in range(2):                           # passing: too short to be learnt itself
        learnt = _feed(model, covered)
    uncovered = frame.copy()
    uncovered[0:3, 4:9] = 128                    # ... except something new left there
    learnt = _feed(model, uncovered)
    assert learnt[3:, 4:9].all() == remember     # uncovered as it was
    assert not learnt[3:, 4:9].any() or remember
    assert not learnt[0:3, 4:9].any()            # changed: not background
    assert learnt[:, :4].all() and learnt[:, 9:].all()
    glove = np.zeros((12, 16), bool)             # the glove found over columns 10..12 ...
    glove[:, 10:13] = True
    gloved = uncovered.copy()
    gloved[:, 10:13] = 255 - gloved[:, 10:13]
    _feed(model, gloved, glove)
    learnt = _feed(model, uncovered)             # ... then showing the remembered colour
    assert learnt[3:, 4:9].all() == remember and not learnt[:, 10:13].any()
    model.reset()                                # a reset forgets the remembered colours
    assert _feed(model, frame) is None and _feed(model, frame) is None


@pytest.fixture(scope='module')
def calibration():
    return blob_glove_calibration()


def _glove_clutter(image: np.ndarray, x0: int, y0: int, cell: int = 12) -> None:
    """Paint a 3 x 3 grid of distinct glove colours (a poster, a toy) at (x0, y0)."""
    for k in range(9):
        r, c = divmod(k, 3)
        image[y0 + r * cell:y0 + (r + 1) * cell, x0 + c * cell:x0 + (c + 1) * cell] = \
            GLOVE_PALETTE_RGB[k + 1]


def _moving_hand_frames(count: int, step: int = 10
                        ) -> tuple[list[np.ndarray], list[np.ndarray]]:
    """A hand sliding left over a still scene until it is just above glove-coloured clutter
    (a poster, a toy: a grid of distinct glove colours)."""
    img, lab = render_blob_frame(np.random.default_rng(8),
                                 BlobConditions(1.0, (1.0, 1.0, 1.0), 0.0, 0, False, 1.0))
    ys, xs = np.nonzero(lab)
    hand = img[ys.min():ys.max() + 1, xs.min():xs.max() + 1]
    hand_lab = lab[ys.min():ys.max() + 1, xs.min():xs.max() + 1]
    scene = np.full_like(img, 110)
    scene[:, :, 2] = 125
    y = (scene.shape[0] - hand.shape[0]) // 2
    _glove_clutter(scene, 150, y + hand.shape[0] + 4)    # just below the final palm
    frames, labels = [], []
    for i in range(count):
        x = 84 + step * (count - 1 - i)
        frame, truth = scene.copy(), np.zeros(lab.shape, np.uint8)
        region = (slice(y, y + hand.shape[0]), slice(x, x + hand.shape[1]))
        frame[region] = np.where(hand_lab[..., None] > 0, hand, frame[region])
        truth[region] = hand_lab
        frames.append(frame)
        labels.append(truth)
    return frames, labels


def test_still_glove_coloured_clutter_stops_pulling_the_crop(calibration) -> None:
    """Clutter of many glove colours beside a moving hand pulls the crop towards it until the
    segmenter has seen it hold still; without the background model it always does."""
    frames, labels = _moving_hand_frames(30)
    errors = {}
    for needed in (0, 10):
        segmenter = GloveSegmenter(calibration, background_frames=needed)
        errors[needed] = []
        for frame, truth in zip(frames, labels, strict=True):
            obs = segmenter.process(frame)
            true_crop = crop_to_tiny(truth).transform
            assert obs.crop is not None
            errors[needed].append(abs(obs.crop.half_size / true_crop.half_size - 1.0))
    assert max(errors[0][:10]) < 0.02            # far from the hand, the clutter is shed
    assert min(errors[0][-10:]) > 0.1            # beside it, it is in the crop
    assert max(errors[10][-10:]) < 0.02          # ... unless it has been seen holding still


def test_a_surface_cut_by_the_learnt_background_does_not_swamp_the_glove(calibration) -> None:
    """A red surface larger than any glove (more than ``max_patch_fraction`` of the frame),
    learnt as background but for the band beside the glove (the arm just left it): the band
    alone would pass for small and, joined to the glove, leave each glove colour under 3 % of
    their component, so that the glove is dropped with it. Judged whole, the surface is
    background and the glove is kept."""
    small = np.full((120, 160, 3), 110, np.uint8)
    small[:, :70] = GLOVE_PALETTE_RGB[1]                 # the red surface, 8400 coarse px
    _glove_clutter(small, 70, 50, cell=6)                # the glove beside it, 324 px
    static = np.zeros((120, 160), bool)
    static[:, :58] = True                                # learnt but the 12-px band
    segmenter = GloveSegmenter(calibration, background_frames=5)
    factor = segmenter.coarse_factor                      # a 640x480 frame's coarse pass
    labels = segmenter._coarse_labels(small, None, float(factor), small.size // 3 * factor ** 2,
                                      static)
    glove = labels[50:68, 70:88]                         # (its red cell joined the surface)
    assert (glove > 0).mean() > 0.85 and len(np.unique(glove)) == 9
    assert not labels[:, :70].any()                      # the whole surface is background


def test_a_hand_held_still_stays_found(calibration) -> None:
    """The glove's patches, however large and still, never become background (a few
    outline pixels may)."""
    frames, labels = _moving_hand_frames(1)
    segmenter = GloveSegmenter(calibration, background_frames=3)
    first = segmenter.process(frames[0])
    for _ in range(20):
        obs = segmenter.process(frames[0])
    assert obs.hand_found and obs.glove_pixel_count >= 0.99 * first.glove_pixel_count
    assert obs.crop.half_size == pytest.approx(first.crop.half_size, rel=0.01)


def test_every_camera_gets_its_own_background(calibration) -> None:
    segmenter = GloveSegmenter(calibration, background_frames=5)
    fresh = segmenter.fresh()
    assert fresh is not segmenter and fresh.background is not segmenter.background
    assert fresh.settings() == segmenter.settings()
    seen: list[int] = []
    made: list[int] = []

    class Recording:
        """Says which of the per-camera segmenters segments each view."""

        def __init__(self) -> None:
            self.number = len(made)
            made.append(self.number)

        def fresh(self) -> Recording:
            return Recording()

        def process(self, image: np.ndarray, keep_labels: bool = False) -> object:
            seen.append(self.number)
            return GloveSegmenter.process(segmenter, image, keep_labels)

    observe = image_observer(Recording())
    blank = np.zeros((48, 64, 3), np.uint8)
    for _ in range(2):
        for k in range(3):
            observe(blank, k == 0)
    assert seen == [0, 1, 2, 0, 1, 2]
    with pytest.raises(SegmentationConfigError, match='background_tolerance'):
        GloveSegmenter(calibration, background_tolerance=0.0)
