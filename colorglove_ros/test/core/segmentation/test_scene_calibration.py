"""Tests for the scene calibration: the user's scene and glove learnt from unlabelled frames.

The frames are rendered (tools/eval_scene_calibration.py): a warm, dim light far from the
starting calibration's training light, an office background with wood, brick, skin-like and
near-black surfaces. The renderer's labels only score the results (and, in one test, pick the
pixels to paint over); the calibration never sees them.
"""
from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import cv2
import numpy as np
import pytest
from scene_samples import (
    FAST_SCENE_SETTINGS,
    scene,
    segmenter_settings,
    start_calibration,
)

from colorglove_ros.core.colorimetry import LUMINANCE_WEIGHTS, illuminant_rgb
from colorglove_ros.core.hand.glove import GLOVE_COLOR_NAMES
from colorglove_ros.core.segmentation.color_model import load_calibration, save_calibration
from colorglove_ros.core.segmentation.scene_calibration import (
    LABEL_PALETTE_RGB,
    SceneCalibration,
    SceneCalibrationError,
    SceneCalibrationSettings,
    calibrate_scene,
    check_frames,
    fit_scene_background,
    foreground_mask,
    label_image_rgb,
    scene_figures,
)
from colorglove_ros.core.segmentation.segmenter import GloveSegmenter
from colorglove_ros.tools.eval_scene_calibration import glove_frame_scores

ORANGE, MAGENTA = GLOVE_COLOR_NAMES.index('orange') + 1, GLOVE_COLOR_NAMES.index('magenta') + 1


@pytest.fixture(scope='module')
def fitted() -> SceneCalibration:
    frames = scene()
    return calibrate_scene(start_calibration(), frames.empty, frames.glove,
                           FAST_SCENE_SETTINGS, segmenter_settings=segmenter_settings())


def _colour_accuracy(calibration, frames, labels, colour: int) -> float:
    segmenter = GloveSegmenter(calibration, **segmenter_settings())
    hits = [segmenter.classify_full(f)[t == colour] == colour
            for f, t in zip(frames, labels, strict=True)]
    return float(np.concatenate(hits).mean())


def _background_as_glove(calibration) -> list[float]:
    """Per held-out glove frame, the share of its other pixels labelled glove."""
    segmenter = GloveSegmenter(calibration, **segmenter_settings())
    frames = scene()
    return [float(np.mean(segmenter.classify_full(f)[t == 0] > 0))
            for f, t in zip(frames.held_glove, frames.held_glove_labels, strict=True)]


def test_scene_calibration_beats_the_start_on_held_out_frames(fitted: SceneCalibration,
                                                              tmp_path: Path) -> None:
    start, frames, settings = start_calibration(), scene(), segmenter_settings()
    before = scene_figures(start, frames.held_empty, frames.held_glove, settings)
    after = scene_figures(fitted.calibration, frames.held_empty, frames.held_glove, settings)
    # (a) the scene's warm and dark surfaces stop being glove
    assert before['empty_labelled_glove'] > 0.05
    assert after['empty_labelled_glove'] < 0.1 * before['empty_labelled_glove']
    # (b) the glove's colours under this light: far better than the start
    accuracy_before, _ = glove_frame_scores(start, frames.held_glove, frames.held_glove_labels,
                                            settings)
    accuracy_after, _ = glove_frame_scores(fitted.calibration, frames.held_glove,
                                           frames.held_glove_labels, settings)
    assert accuracy_after > accuracy_before + 0.03
    assert accuracy_after > 0.9
    # ... and the scene's surfaces behind the hand are background in most glove frames (the
    # segmenter's per-frame light estimate can still fail on a frame showing few colours)
    assert np.median(_background_as_glove(fitted.calibration)) < 0.5 * np.median(
        _background_as_glove(start))
    # (c) the file the nodes read: it loads, and a segmenter on it finds the hand
    loaded = load_calibration(save_calibration(fitted.calibration, tmp_path / 'scene.npz'))
    np.testing.assert_array_equal(loaded.lut, fitted.calibration.lut)
    assert loaded.metadata['scene_calibration']['colours_refitted'] == 10
    segmenter = GloveSegmenter(loaded, **settings)
    found = sum(segmenter.process(frame).hand_found for frame in frames.held_glove)
    assert found >= len(frames.held_glove) - 1
    assert after['empty_hand_found'] == 0.0


def test_every_colour_found_and_the_scene_keeps_off_them(fitted: SceneCalibration) -> None:
    assert [row['status'] for row in fitted.classes] == ['refitted'] * 10
    assert all(row['pixels'] >= FAST_SCENE_SETTINGS.min_class_pixels for row in fitted.classes)
    assert all(row['scene_claim_after'] <= FAST_SCENE_SETTINGS.max_claim
               for row in fitted.classes)
    assert all(row['scene_agrees'] > 0.98 for row in fitted.classes)
    summary = fitted.summary
    assert summary['glove_frames_with_glove'] == summary['glove_frames'] == 8
    assert summary['glove_frames_with_foreground'] == 8
    assert summary['colours_shared_with_scene'] == []
    assert fitted.calibration.bits == start_calibration().bits
    assert len(fitted.calibration.mixtures[0].weights) == (
        len(start_calibration().mixtures[0].weights) + summary['scene_components'])


def test_the_light_found_is_the_scene_light(fitted: SceneCalibration) -> None:
    light = illuminant_rgb(scene().conditions.color_temperature_k)
    expected = (1.0 / light) / float((1.0 / light) @ LUMINANCE_WEIGHTS)
    np.testing.assert_allclose(fitted.summary['light_gains'], expected, rtol=0.2)


def test_glove_coloured_object_is_down_weighted_and_an_unseen_colour_kept() -> None:
    """An object of the glove's own orange in the empty scene must not take orange from the
    glove; magenta painted out of every glove frame keeps the start's magenta, moved to the
    scene's light."""
    frames, start = scene(), start_calibration()
    inner = cv2.erode((frames.glove_labels[0] == ORANGE).view(np.uint8), np.ones((3, 3)))
    orange = tuple(int(v) for v in np.median(frames.glove[0][inner > 0], axis=0))

    def with_object(images: list[np.ndarray]) -> list[np.ndarray]:
        out = [image.copy() for image in images]
        for image in out:
            cv2.ellipse(image, (40, 40), (30, 22), 0, 0, 360, orange, -1)
        return out

    glove = with_object(frames.glove)
    for image, labels in zip(glove, frames.glove_labels, strict=True):
        image[cv2.dilate((labels == MAGENTA).view(np.uint8), np.ones((5, 5))) > 0] = 90
    fitted = calibrate_scene(start, with_object(frames.empty), glove, FAST_SCENE_SETTINGS,
                             segmenter_settings=segmenter_settings())
    rows = {row['class']: row for row in fitted.classes}
    assert rows[ORANGE]['scene_claim_before'] > FAST_SCENE_SETTINGS.max_claim
    assert rows[ORANGE]['scene_claim_after'] <= FAST_SCENE_SETTINGS.max_claim
    assert (fitted.summary['scene_components_downweighted']
            + fitted.summary['scene_components_dropped']) >= 1
    assert 'orange' in fitted.summary['colours_shared_with_scene']
    assert rows[MAGENTA]['status'] == 'kept from start, re-lit'
    held, labels = frames.held_glove, frames.held_glove_labels
    assert _colour_accuracy(fitted.calibration, held, labels, ORANGE) > 0.9
    magenta_before = _colour_accuracy(start, held, labels, MAGENTA)
    assert _colour_accuracy(fitted.calibration, held, labels, MAGENTA) > max(
        0.7, magenta_before + 0.1)


def test_glove_in_the_empty_scene_is_refused() -> None:
    frames = scene()
    with pytest.raises(SceneCalibrationError, match='8 of 8 empty-scene frames show the glove'):
        calibrate_scene(start_calibration(), frames.glove, frames.glove, FAST_SCENE_SETTINGS,
                        segmenter_settings=segmenter_settings())


def test_glove_frames_without_the_glove_are_refused() -> None:
    frames = scene()
    with pytest.raises(SceneCalibrationError, match='no glove found in any of the 3 glove'):
        calibrate_scene(start_calibration(), frames.empty, frames.held_empty,
                        FAST_SCENE_SETTINGS, segmenter_settings=segmenter_settings())


def test_too_few_glove_colours_are_refused() -> None:
    frames = scene()
    settings = replace(FAST_SCENE_SETTINGS, min_class_pixels=10**7)
    with pytest.raises(SceneCalibrationError, match='found only 0 of 10 glove colours'):
        calibrate_scene(start_calibration(), frames.empty, frames.glove, settings,
                        segmenter_settings=segmenter_settings())


def test_frames_of_another_size_than_the_empty_scene_are_refused() -> None:
    frames = scene()
    small = [f[:200, :300].copy() for f in frames.glove]
    with pytest.raises(SceneCalibrationError, match='empty-scene frames are 320x240, glove '
                                                    'frames 300x200'):
        calibrate_scene(start_calibration(), frames.empty, small, FAST_SCENE_SETTINGS)


@pytest.mark.parametrize('frames, message', [
    ([], 'no test frames'),
    ([np.zeros((4, 4, 3), np.float32)], r'test frame 0: expected an \(H, W, 3\) uint8'),
    ([np.zeros((4, 4), np.uint8)], r'test frame 0: expected an \(H, W, 3\) uint8'),
    ([np.zeros((4, 4, 3), np.uint8), np.zeros((4, 5, 3), np.uint8)],
     'test frame 1 is 5x4, frame 0 is 4x4'),
])
def test_check_frames_refuses_bad_frames(frames: list, message: str) -> None:
    with pytest.raises(SceneCalibrationError, match=message):
        check_frames(frames, 'test')


def test_check_frames_returns_the_size() -> None:
    assert check_frames([np.zeros((4, 6, 3), np.uint8)] * 2, 'test') == (4, 6)


@pytest.mark.parametrize('change', [{'scene_weight': 1.0}, {'max_claim': -0.1},
                                    {'scene_components': 0}, {'max_frames': 0}])
def test_settings_are_checked(change: dict) -> None:
    with pytest.raises(SceneCalibrationError):
        SceneCalibrationSettings(**change)


def test_foreground_is_the_hand() -> None:
    frames, settings = scene(), SceneCalibrationSettings()
    background = fit_scene_background(frames.empty)
    mask = foreground_mask(background, frames.glove[0], settings)
    glove = frames.glove_labels[0] > 0
    assert mask is not None and mask[glove].mean() > 0.9 and mask.mean() < 0.3
    assert not foreground_mask(background, frames.held_empty[0], settings).any()


def test_foreground_is_none_when_the_camera_moved() -> None:
    rng = np.random.default_rng(5)
    texture = cv2.resize(rng.uniform(0, 255, (12, 16, 3)).astype(np.float32), (320, 240),
                         interpolation=cv2.INTER_CUBIC)

    def frame(shift: int) -> np.ndarray:
        noisy = np.roll(texture, shift, axis=1) + rng.normal(0.0, 2.0, texture.shape)
        return np.clip(noisy, 0, 255).astype(np.uint8)

    settings = SceneCalibrationSettings()
    background = fit_scene_background([frame(0) for _ in range(4)])
    assert foreground_mask(background, frame(0), settings).mean() < 0.01
    assert foreground_mask(background, frame(40), settings) is None


def test_label_image_colours() -> None:
    labels = np.array([[0, 1], [10, 3]], np.uint8)
    picture = label_image_rgb(labels)
    assert picture.shape == (2, 2, 3) and picture.dtype == np.uint8
    np.testing.assert_array_equal(picture[0, 0], [0, 0, 0])
    np.testing.assert_array_equal(picture[1, 0], LABEL_PALETTE_RGB[10])
