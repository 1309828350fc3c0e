"""Tests of the scene conditions of the evaluation ladder: named scenes, sleeves, other
people's skin in the background and the camera's colour processing, in rendered frames."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from colorglove_ros.core.camera import PinholeCamera
from colorglove_ros.core.colorimetry import LUMINANCE_WEIGHTS
from colorglove_ros.core.synthetic.backgrounds import make_background
from colorglove_ros.core.synthetic.bare_hand import SKIN_TONES_SRGB, skin_albedo
from colorglove_ros.core.synthetic.conditions import (
    BACKGROUND_KINDS,
    BACKGROUND_SEED_SPLIT,
    PROCEDURAL_BACKGROUND_KINDS,
    SCENE_CONDITIONS,
    SLEEVE_NAMES,
    FrameConditions,
    SynthError,
    background_seed_split,
    sample_conditions,
    scene_conditions,
    sleeve_albedo,
)
from colorglove_ros.core.synthetic.frames import Synthesizer, camera_encode, sample_pose
from colorglove_ros.core.synthetic.people import people_layers
from colorglove_ros.core.synthetic.photos import photo_albedo

CAMERA = PinholeCamera(320, 240, 300.0, 300.0, 159.5, 119.5)
TRAIN_SEED, TEST_SEED = 4242, BACKGROUND_SEED_SPLIT + 4242


@pytest.fixture(scope='module')
def synth() -> Synthesizer:
    s = Synthesizer()
    yield s
    s.release()


@pytest.fixture(scope='module')
def pose() -> np.ndarray:
    q = sample_pose(np.random.default_rng(3), CAMERA, out_of_frame_prob=0.0)
    return q


@pytest.mark.parametrize('name', SCENE_CONDITIONS)
@pytest.mark.parametrize('split', ['train', 'test'])
def test_every_scene_condition_is_deterministic_and_keeps_to_its_split(name: str,
                                                                       split: str) -> None:
    a = [scene_conditions(name, np.random.default_rng(s), split) for s in range(20)]
    b = [scene_conditions(name, np.random.default_rng(s), split) for s in range(20)]
    assert a == b
    assert len({c.background_seed for c in a}) == 20
    assert all(background_seed_split(c.background_seed) == split for c in a)
    photos = name in ('photos', 'all')
    for c in a:
        assert isinstance(c, FrameConditions)
        assert (c.background_kind == 'photo') == photos
        assert c.skin_distractors == photos and c.glove_distractors == photos
        assert c.processes_color == (name in ('color_processing', 'all'))
        if name in ('clean', 'photos', 'sleeve', 'color_processing'):
            assert c.jpeg_quality == 0 and c.blur_px == 0.0 and 0.9 <= c.gain <= 1.1
        if name in ('clean', 'photos', 'color_processing'):
            assert c.sleeve_rgb == FrameConditions().sleeve_rgb
        if name == 'clean':
            assert c.background_kind in ('desk', 'office')
    if name in ('sleeve', 'all'):
        assert len({c.sleeve_rgb for c in a}) == 20


def test_unknown_scene_or_split_is_refused() -> None:
    with pytest.raises(SynthError, match='scene condition must be one of'):
        scene_conditions('proportions', np.random.default_rng(0))
    with pytest.raises(SynthError, match='split must be one of'):
        scene_conditions('clean', np.random.default_rng(0), 'validation')


def test_all_uses_the_splits_light_noise_and_compression() -> None:
    conds = [scene_conditions('all', np.random.default_rng(s), 'test') for s in range(60)]
    assert min(c.noise_sigma for c in conds) >= 0.008
    assert any(c.jpeg_quality > 0 for c in conds) and any(c.blur_px > 0 for c in conds)
    assert {c.gain < 0.75 or c.gain > 1.3 for c in conds} == {True}


def test_sample_conditions_stay_procedural_without_processing() -> None:
    rng = np.random.default_rng(1)
    for split in ('train', 'test'):
        for c in (sample_conditions(rng, split) for _ in range(100)):
            assert c.background_kind in PROCEDURAL_BACKGROUND_KINDS
            assert not c.processes_color and not c.skin_distractors and c.glove_distractors
    assert 'photo' in BACKGROUND_KINDS


@pytest.mark.parametrize('name', SLEEVE_NAMES)
def test_sleeve_albedos(name: str) -> None:
    rgb = np.array([sleeve_albedo(name, np.random.default_rng(s)) for s in range(30)])
    assert np.all((rgb >= 0) & (rgb <= 1))
    luma = rgb @ LUMINANCE_WEIGHTS
    if name == 'skin':
        tones = np.array([skin_albedo(t) for t in range(len(SKIN_TONES_SRGB))])
        assert np.all(rgb[:, 0] > rgb[:, 1]) and np.all(rgb[:, 1] > rgb[:, 2])
        assert len({tuple(np.round(r, 6)) for r in rgb}) > 3
        assert luma.min() >= 0.8 * (tones @ LUMINANCE_WEIGHTS).min()
    elif name == 'dark':
        assert luma.max() < 0.05
    elif name == 'white':
        assert luma.min() > 0.5
    elif name == 'red':
        assert np.all(rgb[:, 0] > 10 * rgb[:, 1])
    elif name == 'denim':
        assert np.all(rgb[:, 2] > 1.5 * rgb[:, 0])
    with pytest.raises(SynthError, match='sleeve must be one of'):
        sleeve_albedo('tartan', np.random.default_rng(0))


def test_sleeve_colour_reaches_the_forearm_pixels(synth: Synthesizer,
                                                  pose: np.ndarray) -> None:
    """The forearm (not glove, not background) takes the requested sleeve's colour."""
    base = replace(scene_conditions('clean', np.random.default_rng(0), 'test'),
                   noise_sigma=0.0, vignetting=0.0)
    frames = {}
    for name in ('dark', 'white', 'red', 'denim'):
        cond = replace(base, sleeve_rgb=sleeve_albedo(name, np.random.default_rng(1)))
        frames[name] = synth.render_frame(pose, CAMERA, np.random.default_rng(2), cond)
    labels = frames['dark'].labels
    diff = np.abs(frames['white'].image_rgb.astype(int) - frames['dark'].image_rgb).sum(-1)
    arm = (diff > 60) & (labels == 0)
    assert arm.sum() > 200
    for f in frames.values():
        np.testing.assert_array_equal(f.labels, labels)
    mean = {n: f.image_rgb[arm].mean(axis=0) for n, f in frames.items()}
    assert mean['white'].mean() > 2 * mean['dark'].mean()
    assert mean['red'][0] > 2 * mean['red'][1]
    assert mean['denim'][2] > mean['denim'][0]


def test_colour_processing_is_identity_by_default_and_changes_the_image_otherwise() -> None:
    rng = np.random.default_rng(0)
    linear = rng.uniform(0.0, 1.0, (40, 50, 3)).astype(np.float32)
    plain = camera_encode(linear, FrameConditions())
    same = camera_encode(linear, FrameConditions(white_balance_gains=(1.0, 1.0, 1.0),
                                                 saturation=1.0, gamma=1.0, contrast=0.0))
    np.testing.assert_array_equal(plain, same)
    red = camera_encode(linear, FrameConditions(white_balance_gains=(1.3, 1.0, 1.0)))
    assert (red[..., 0] >= plain[..., 0]).all() and red[..., 0].mean() > plain[..., 0].mean() + 5
    np.testing.assert_array_equal(red[..., 1:], plain[..., 1:])
    grey = camera_encode(linear, FrameConditions(saturation=0.0)).astype(int)
    assert np.abs(grey[..., 0] - grey[..., 2]).max() <= 1
    bright = camera_encode(linear, FrameConditions(gamma=1.25)).astype(int)
    assert (bright >= plain).all() and bright.mean() > plain.mean() + 5
    ramp = np.linspace(0.0, 1.0, 4096, dtype=np.float32)[:, None, None].repeat(3, axis=2)
    for contrast in (-1.0, -0.3, 0.6, 1.0):
        curve = camera_encode(ramp, FrameConditions(contrast=contrast))[:, 0, 0].astype(int)
        assert np.all(np.diff(curve) >= 0) and curve[0] == 0 and curve[-1] == 255
    steep = camera_encode(ramp, FrameConditions(contrast=0.6))[:, 0, 0].astype(int)
    flat = camera_encode(ramp, FrameConditions())[:, 0, 0].astype(int)
    low = flat < 60
    assert (steep[low] <= flat[low]).all() and (steep[flat > 200] >= flat[flat > 200]).all()
    for bad in ({'white_balance_gains': (1.0, 0.0, 1.0)}, {'saturation': -0.1},
                {'gamma': 0.0}, {'contrast': 1.5}, {'sleeve_rgb': (1.2, 0.0, 0.0)}):
        with pytest.raises(SynthError):
            FrameConditions(**bad)


def test_colour_processing_changes_the_rendered_image_not_the_labels(
        synth: Synthesizer, pose: np.ndarray) -> None:
    clean = scene_conditions('clean', np.random.default_rng(5), 'test')
    processed = replace(clean, white_balance_gains=(1.2, 1.0, 0.85), saturation=1.4,
                        gamma=0.85, contrast=0.3)
    a = synth.render_frame(pose, CAMERA, np.random.default_rng(9), clean)
    b = synth.render_frame(pose, CAMERA, np.random.default_rng(9), processed)
    again = synth.render_frame(pose, CAMERA, np.random.default_rng(9), clean)
    np.testing.assert_array_equal(a.image_rgb, again.image_rgb)
    np.testing.assert_array_equal(a.labels, b.labels)
    assert np.abs(a.image_rgb.astype(int) - b.image_rgb).mean() > 5
    # a warm white-balance error: more red relative to blue everywhere on average
    ratio = lambda img: img[..., 0].mean() / max(img[..., 2].mean(), 1.0)  # noqa: E731
    assert ratio(b.image_rgb) > 1.1 * ratio(a.image_rgb)


@pytest.mark.parametrize('seed', [TRAIN_SEED, TEST_SEED, TRAIN_SEED + 1, TEST_SEED + 1])
def test_people_layers_are_shaded_skin(seed: int) -> None:
    layers = people_layers(seed, 320, 240)
    assert layers == people_layers(seed, 320, 240)
    assert 1 <= len(layers) <= 3
    for layer in layers:
        x0, y0, x1, y1 = layer.box
        assert 0 <= x0 < x1 <= 320 and 0 <= y0 < y1 <= 240
        assert layer.alpha.shape == (y1 - y0, x1 - x0) and layer.rgb.shape[:2] == layer.alpha.shape
        assert layer.alpha.min() >= 0 and layer.alpha.max() <= 1 + 1e-6
        assert np.all(layer.rgb <= layer.alpha[..., None] + 1e-5)      # premultiplied
    # the skin itself: opaque pixels of warm (r > g > b) colour with visible shading
    skin = np.concatenate([(layer.rgb / np.maximum(layer.alpha[..., None], 1e-6))[
        layer.alpha > 0.99] for layer in layers])
    warm = skin[(skin[:, 0] > skin[:, 1]) & (skin[:, 1] > skin[:, 2])]
    assert len(warm) > 100
    luma = warm @ LUMINANCE_WEIGHTS
    assert luma.std() / luma.mean() > 0.08


def test_skin_distractors_differ_between_seeds_and_tones() -> None:
    tones = set()
    for seed in range(TRAIN_SEED, TRAIN_SEED + 12):
        for layer in people_layers(seed, 160, 120):
            opaque = layer.alpha > 0.99
            if opaque.sum() > 20:
                colour = (layer.rgb[opaque] / layer.alpha[opaque][:, None]).mean(axis=0)
                tones.add(round(float(colour[1] / colour[0]), 2))
    assert len(tones) >= 4


def test_photos_frame_keeps_the_hand_labels_over_a_photo(synth: Synthesizer,
                                                         pose: np.ndarray) -> None:
    """A 'photos' frame has the clean frame's labels; its background pixels (away from the
    hand, other people and clutter) follow the photo's crop for that seed."""
    clean = replace(scene_conditions('clean', np.random.default_rng(7), 'test'),
                    noise_sigma=0.0, vignetting=0.0)
    photos = replace(scene_conditions('photos', np.random.default_rng(7), 'test'),
                     noise_sigma=0.0, vignetting=0.0, background_photos=('grace_hopper',))
    assert photos.background_kind == 'photo' and photos.skin_distractors
    a = synth.render_frame(pose, CAMERA, np.random.default_rng(1), clean)
    b = synth.render_frame(pose, CAMERA, np.random.default_rng(1), photos)
    np.testing.assert_array_equal(a.labels, b.labels)
    np.testing.assert_array_equal(a.patch_ids, b.patch_ids)
    assert (b.labels > 0).sum() > 500
    # background pixels: not the hand or its forearm (differs from a hand-free frame's),
    # not another person's skin or a glove-like object
    away = replace(photos, skin_distractors=False, glove_distractors=False)
    far = pose.copy()
    far[0] += 10.0
    empty = synth.render_frame(far, CAMERA, np.random.default_rng(1), away).image_rgb
    full = make_background('photo', photos.background_seed, 320, 240, photos=('grace_hopper',),
                           skin_distractors=True, glove_distractors=True)
    bare = make_background('photo', photos.background_seed, 320, 240,
                           photos=('grace_hopper',), glove_distractors=False)
    untouched = np.abs(full - bare).sum(-1) < 1e-4
    background = untouched & (np.abs(b.image_rgb.astype(int) - empty).sum(-1) <= 3)
    assert background.mean() > 0.5
    crop, photo = photo_albedo(np.random.default_rng(photos.background_seed), 'test', 320, 240,
                               ('grace_hopper',))
    assert photo.name == 'grace_hopper'
    grey = b.image_rgb.astype(float) @ LUMINANCE_WEIGHTS
    assert np.corrcoef(grey[background], (crop @ LUMINANCE_WEIGHTS)[background])[0, 1] > 0.9
    # and other people's skin is in the frame, outside the hand
    skin_only = make_background('photo', photos.background_seed, 320, 240,
                                photos=('grace_hopper',), skin_distractors=True,
                                glove_distractors=False)
    skin = (np.abs(skin_only - bare).sum(-1) > 1e-3) & (b.labels == 0)
    assert skin.sum() > 200
    assert np.abs(b.image_rgb[skin].astype(int) - empty[skin]).sum(-1).mean() > 10
