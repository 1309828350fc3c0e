"""Tests for another camera's saturation, estimated from the glove's palette and undone in the
colour table (``core.segmentation.color_processing``), alone and in the segmenter."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from segmentation_samples import printed_glove_calibration

from colorglove_ros.core.colorimetry import LUMINANCE_WEIGHTS, linear_to_srgb, srgb_to_linear
from colorglove_ros.core.hand.glove import GLOVE_PALETTE_RGB
from colorglove_ros.core.segmentation.color_model import lut_index
from colorglove_ros.core.segmentation.color_processing import (
    SATURATION_STEP,
    WASHED_OUT_STEPS,
    SaturationEstimate,
    estimate_saturation,
    reads_plain,
    resaturated_lut,
    saturation_matrix,
    window_colors,
)
from colorglove_ros.core.segmentation.segmenter import GloveSegmenter, SegmentationConfigError
from colorglove_ros.core.synthetic import frames as synth
from colorglove_ros.core.synthetic.conditions import FrameConditions

YELLOW, LIME = 4, 10


@pytest.fixture(scope='module')
def calibration():
    return printed_glove_calibration()


def test_saturation_matrix_keeps_luminance_and_inverts() -> None:
    rgb = np.array([[0.6, 0.2, 0.05], [0.1, 0.5, 0.7], [0.3, 0.3, 0.3]])
    for s in (0.6, 1.0, 1.4):
        out = rgb @ saturation_matrix(s).T
        np.testing.assert_allclose(out @ LUMINANCE_WEIGHTS, rgb @ LUMINANCE_WEIGHTS)
        np.testing.assert_allclose(out[2], rgb[2])          # a grey stays grey
        np.testing.assert_allclose(out @ saturation_matrix(1.0 / s).T, rgb, atol=1e-12)
    grey = rgb[0] @ LUMINANCE_WEIGHTS
    np.testing.assert_allclose((rgb[0] @ saturation_matrix(0.5).T) - grey,
                               0.5 * (rgb[0] - grey))


@pytest.mark.parametrize('saturation, light, steps', [
    (0.6, (1.0, 1.0, 1.0), 1), (0.7, (1.15, 1.0, 0.85), 1), (1.0, (1.0, 1.0, 1.0), 1),
    (1.35, (0.9, 1.0, 1.2), 2)])
def test_estimate_saturation_from_glove_pixels(saturation, light, steps) -> None:
    """Glove pixels = own shading * light * (the reference colour seen through the
    saturation) + noise: the estimate lands within a grid step of the truth, whatever the
    light colour (two steps when boosted saturation pushes channels below black, where
    the noise hides how far)."""
    rng = np.random.default_rng(5)
    ref = srgb_to_linear(GLOVE_PALETTE_RGB / 255.0)
    labels = rng.integers(1, 11, 4000)
    shown = np.clip(ref @ saturation_matrix(saturation).T, 0.0, None)
    shading = rng.uniform(0.3, 0.6, (4000, 1)) * rng.uniform(0.6, 1.0, 11)[labels, None]
    pix = shading * np.asarray(light) * shown[labels - 1] + rng.normal(0.0, 0.003, (4000, 3))
    est = estimate_saturation(np.clip(pix, 1e-4, 1.0), labels, ref)
    assert est is not None
    assert abs(np.log(est / saturation)) <= 1.01 * steps * SATURATION_STEP
    few = np.isin(labels, (1, 2, 3))   # three hues: not enough to tell saturation from light
    assert estimate_saturation(pix[few], labels[few], ref) is None


def test_resaturated_table_recovers_washed_out_yellow_and_lime(calibration) -> None:
    """The palette's yellow and lime washed out to 0.6 of their saturation: the calibration's
    own table loses them; the table resaturated for 0.6 gives them back and keeps grey and
    the other colours."""
    bits = calibration.bits
    palette = srgb_to_linear(GLOVE_PALETTE_RGB / 255.0) * 0.8
    washed = palette @ saturation_matrix(0.6).T
    srgb = np.round(255 * linear_to_srgb(washed)).astype(np.uint8)[None]
    plain = calibration.classify(srgb)[0]
    table = resaturated_lut(calibration.lut, bits, 0.6)
    fixed = table.take(lut_index(srgb, bits))[0]
    assert plain[YELLOW - 1] != YELLOW and plain[LIME - 1] != LIME
    assert fixed[YELLOW - 1] == YELLOW and fixed[LIME - 1] == LIME
    assert (fixed == np.arange(1, 11)).sum() >= 9
    grey = np.full((1, 1, 3), 128, np.uint8)
    assert table.take(lut_index(grey, bits))[0, 0] == 0
    np.testing.assert_array_equal(resaturated_lut(calibration.lut, bits, 1.0), calibration.lut)


def test_saturation_estimate_settles_and_caches_tables(calibration) -> None:
    est = SaturationEstimate(calibration.lut, calibration.bits, 0.5)
    assert est.saturation == 1.0 and est.lut() is calibration.lut
    est.update(None)
    assert est.saturation == 1.0
    est.update(0.7)                       # half way (the rate) in log saturation
    assert abs(np.log(est.saturation / np.sqrt(0.7))) <= 0.5 * SATURATION_STEP
    for _ in range(12):
        est.update(0.7)
    assert abs(np.log(est.saturation / 0.7)) <= SATURATION_STEP
    first = est.lut()
    assert first is est.lut() and first is not calibration.lut
    boosted = SaturationEstimate(calibration.lut, calibration.bits, 1.0)
    boosted.update(1.4)                   # a camera that boosts saturation is not undone
    assert boosted.saturation == 1.0 and boosted.lut() is calibration.lut
    boosted.update(0.92)                  # nor one within the dead band of 1
    assert boosted.saturation == 1.0
    boosted.update(0.8)
    assert abs(np.log(boosted.saturation / 0.8)) <= 0.5 * SATURATION_STEP
    with pytest.raises(ValueError, match='rate'):
        SaturationEstimate(calibration.lut, calibration.bits, 0.0)


def _washed_out_frames(count: int) -> list[tuple[np.ndarray, np.ndarray]]:
    """Frames of the printed glove seen by a camera that washes colours out (saturation
    0.75), one hand moving slightly."""
    rng = np.random.default_rng(3)
    camera = synth.default_camera()
    q = synth.sample_pose(rng, camera, out_of_frame_prob=0.0)
    look = replace(FrameConditions(glove_distractors=False), saturation=0.75)
    out = []
    for k in range(count):
        frame = synth.render_frame(q + np.r_[0.002 * k, np.zeros(25)], camera,
                                   np.random.default_rng(k), look)
        out.append((frame.image_rgb, frame.labels))
    return out


def test_segmenter_settles_on_a_washed_out_camera(calibration) -> None:
    """With ``saturation_rate`` the segmenter finds yellow and lime again after a few frames of
    a washed-out camera; without, it labels almost none of them."""
    frames = _washed_out_frames(6)
    adapting = GloveSegmenter(calibration, saturation_rate=0.5)
    plain = GloveSegmenter(calibration)
    for image, _ in frames[:-1]:
        adapting.process(image)
        plain.process(image)
    image, truth = frames[-1]
    recall = {}
    for name, seg in (('adapting', adapting), ('plain', plain)):
        labels = seg.process(image, keep_labels=True).label_image
        washed = np.isin(truth, (YELLOW, LIME))
        recall[name] = float(np.mean(labels[washed] == truth[washed]))
    assert recall['plain'] < 0.3, recall
    assert recall['adapting'] > 0.8, recall
    assert adapting.settings()['saturation_rate'] == 0.5
    with pytest.raises(SegmentationConfigError, match='saturation_rate'):
        GloveSegmenter(calibration, saturation_rate=1.5)


def test_window_colors_counts_the_colours_inside_the_window() -> None:
    labels = np.zeros((20, 20), np.uint8)
    labels[2:4, 2:4] = 1          # inside the window, 4 pixels
    labels[5, 5] = 2              # inside, 1 pixel: under min_pixels
    labels[15:18, 15:18] = 3      # outside the window
    assert window_colors(labels, ((4.0, 4.0), 3.0)) == 1
    assert window_colors(labels, ((4.0, 4.0), 3.0), min_pixels=1) == 2
    assert window_colors(labels, ((10.0, 10.0), 10.0)) == 2
    assert window_colors(labels, ((10.0, 10.0), 10.0), min_share=0.3) == 1   # 4 of 14: stray
    assert window_colors(labels, None) == 0


def test_saturation_estimate_trials_and_settle(calibration) -> None:
    est = SaturationEstimate(calibration.lut, calibration.bits, 1.0)
    assert est.trials() == tuple(-k for k in WASHED_OUT_STEPS)
    est.settle(-WASHED_OUT_STEPS[1])
    assert est.step == -WASHED_OUT_STEPS[1]
    assert abs(np.log(est.saturation) + WASHED_OUT_STEPS[1] * SATURATION_STEP) < 1e-9
    assert est.trials() == (0, -WASHED_OUT_STEPS[0], -WASHED_OUT_STEPS[2])


def _look_frames(count: int, saturation: float) -> list[tuple[np.ndarray, np.ndarray]]:
    """Frames of the printed glove seen by a camera with ``saturation`` (1: a plain one),
    one hand moving slightly."""
    rng = np.random.default_rng(5)
    camera = synth.default_camera()
    q = synth.sample_pose(rng, camera, out_of_frame_prob=0.0)
    look = replace(FrameConditions(glove_distractors=False), saturation=saturation)
    return [(f.image_rgb, f.labels) for f in
            (synth.render_frame(q + np.r_[0.002 * k, np.zeros(25)], camera,
                                np.random.default_rng(k), look) for k in range(count))]


def test_washed_out_search_finds_a_glove_the_table_misses(calibration) -> None:
    """A camera washing colours out to 0.6 hides most glove colours from the calibration's
    table; with ``washed_out_colors`` the segmenter searches again with a washed-out
    camera's saturation undone, settles on it and labels every colour; a plain camera's
    glove shows its colours and is left alone (the same observations as without)."""
    frames = _look_frames(5, 0.6)
    plain = GloveSegmenter(calibration)
    searching = GloveSegmenter(calibration, washed_out_colors=8)
    for image, _ in frames[:-1]:
        plain.process(image)
        searching.process(image)
    image, truth = frames[-1]
    glove = truth > 0
    recall = {}
    for name, seg in (('plain', plain), ('searching', searching)):
        labels = seg.process(image, keep_labels=True).label_image
        recall[name] = float(np.mean(labels[glove] == truth[glove])) if labels is not None else 0
    assert recall['plain'] < 0.5, recall
    assert recall['searching'] > 0.8, recall
    assert searching._saturation.step <= -WASHED_OUT_STEPS[0]
    plain, searching = GloveSegmenter(calibration), GloveSegmenter(calibration, washed_out_colors=8)
    for image, _ in _look_frames(3, 1.0):
        a, b = plain.process(image, keep_labels=True), searching.process(image, keep_labels=True)
        assert a.status == b.status == 'ok' and a.crop == b.crop
        np.testing.assert_array_equal(a.label_image, b.label_image)
    assert searching._saturation.step == 0
    with pytest.raises(SegmentationConfigError, match='washed_out_colors'):
        GloveSegmenter(calibration, washed_out_colors=11)


def test_washed_out_search_returns_to_a_plain_camera(calibration) -> None:
    """A segmenter settled on a washed-out camera (as a search on a hand entering the view
    can leave it) that sees a plain camera's glove with all its colours returns to the
    calibration's own table within a few frames, its observations then the plain ones."""
    frames = _look_frames(5, 1.0)
    searching = GloveSegmenter(calibration, washed_out_colors=8)
    searching._saturation.settle(-WASHED_OUT_STEPS[1])
    for image, _ in frames[:-1]:
        searching.process(image)
    assert searching._saturation.step == 0
    image = frames[-1][0]
    a = GloveSegmenter(calibration).process(image, keep_labels=True)
    np.testing.assert_array_equal(searching.process(image, keep_labels=True).label_image,
                                  a.label_image)


def test_reads_plain_within_a_step_of_the_calibration() -> None:
    """A saturation estimate reads the calibration's palette within one log step of 1 (and
    above: a camera that boosts saturation); none, or two steps and more below, does not."""
    step = np.exp(-SATURATION_STEP)
    assert reads_plain(1.0) and reads_plain(step) and reads_plain(1.3)
    assert not reads_plain(step ** 2) and not reads_plain(0.6) and not reads_plain(None)


@pytest.mark.parametrize('washed_out', [WASHED_OUT_STEPS[1], WASHED_OUT_STEPS[2]])
def test_a_plain_glove_returns_at_once_whatever_the_trial(calibration, washed_out) -> None:
    """A segmenter switched to a washed-out table (as odd frames can leave a plain camera)
    is back on the calibration's table after the first frame whose glove reads plain, even
    when that frame's turn would try another washed-out table (the colour count alone waits
    for the calibration's turn, and a boosted table showing more colours blocks it), and its
    observations are then the plain ones; a washed-out camera's glove does not return it."""
    frames = _look_frames(2, 1.0)
    searching = GloveSegmenter(calibration, washed_out_colors=8)
    searching._saturation.settle(-washed_out)
    searching._washed_out_turn = 1     # the next trial: a washed-out table, not the plain one
    searching.process(frames[0][0])
    assert searching._saturation.step == 0
    image = frames[1][0]
    a = GloveSegmenter(calibration).process(image, keep_labels=True)
    np.testing.assert_array_equal(searching.process(image, keep_labels=True).label_image,
                                  a.label_image)
    washed = GloveSegmenter(calibration, washed_out_colors=8)
    washed._saturation.settle(-WASHED_OUT_STEPS[2])
    for image, _ in _look_frames(3, 0.6):
        washed.process(image)
    assert washed._saturation.step <= -WASHED_OUT_STEPS[0]


@pytest.mark.parametrize('saturation, washed', [(0.6, True), (1.0, False), (1.4, False)])
def test_a_switch_needs_the_palette_washed_out(calibration, saturation, washed) -> None:
    """The glove a search finds with a washed-out camera's saturation undone counts as washed
    out only when its palette says so: not on a plain camera, nor on one that boosts
    saturation (undoing it there boosts it further and clutter turns glove-coloured)."""
    image, _ = _look_frames(1, saturation)[0]
    seg = GloveSegmenter(calibration, washed_out_colors=8)
    small, sx, sy = seg._small(image)
    region = (0, small.shape[1], 0, small.shape[0])
    seg._saturation.settle(-WASHED_OUT_STEPS[1])
    tried = seg._detect(small, region, float(np.sqrt(sx * sy)), image.shape[0] * image.shape[1],
                        None, max(int(seg.min_glove_pixels / (sx * sy)), 1))
    assert tried[0] is not None
    assert seg._washed_out(small, region, tried) is washed
