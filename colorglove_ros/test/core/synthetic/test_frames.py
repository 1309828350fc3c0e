"""Tests of synthetic frames, conditions and seeded sequences."""
from __future__ import annotations

from dataclasses import replace

import cv2
import numpy as np
import pytest
from repo_paths import CONFIG_DIR
from scipy.spatial.transform import Rotation

from colorglove_ros.core.camera import load_calibration
from colorglove_ros.core.colorimetry import illuminant_rgb
from colorglove_ros.core.hand.glove import GLOVE_PALETTE_RGB
from colorglove_ros.core.synthetic.backgrounds import _background, make_background
from colorglove_ros.core.synthetic.conditions import (
    BACKGROUND_SEED_SPLIT,
    FrameConditions,
    SynthError,
    sample_conditions,
)
from colorglove_ros.core.synthetic.frames import (
    Synthesizer,
    default_camera,
    render_frames_multi,
    sample_pose,
)
from colorglove_ros.core.synthetic.mesh_images import patch_ids_to_labels
from colorglove_ros.core.synthetic.sequences import (
    CAPTURE_VOLUME_CENTER,
    CAPTURE_VOLUME_SIZE,
    SyntheticSequenceRenderer,
    generate_sequence,
)

CONFIG = CONFIG_DIR
NEUTRAL = FrameConditions(gain=1.0, color_temperature_k=6500.0, noise_sigma=0.0, blur_px=0.0,
                          background_kind='desk', background_seed=3, ambient=0.5,
                          vignetting=0.0, jpeg_quality=0)


@pytest.fixture(scope='module')
def synth() -> Synthesizer:
    s = Synthesizer()
    yield s
    s.release()


def _rgb_to_chroma(rgb: np.ndarray) -> np.ndarray:
    rgb = np.asarray(rgb, float)
    return rgb / np.maximum(rgb.sum(axis=-1, keepdims=True), 1e-9)


def test_sequences_are_deterministic_smooth_and_in_the_volume() -> None:
    a = generate_sequence(5, 150)
    b = generate_sequence(5, 150)
    c = generate_sequence(6, 150)
    np.testing.assert_array_equal(a, b)
    assert a.shape == (150, 26) and not np.allclose(a, c)
    from colorglove_ros.core.hand.glove import default_hand
    model = default_hand()[0]
    assert np.all(model.within_limits(a))
    # smooth at 30 fps: < 1.5 cm and < 6 deg of wrist motion per frame, < 9 deg per joint
    assert np.abs(np.diff(a[:, :3], axis=0)).max() < 0.015
    rot = Rotation.from_rotvec(a[:, 3:6])
    assert (rot[1:] * rot[:-1].inv()).magnitude().max() < np.deg2rad(6.0)
    assert np.abs(np.diff(a[:, 6:], axis=0)).max() < np.deg2rad(9.0)
    # second differences are small too (no kinks)
    assert np.abs(np.diff(a[:, :3], 2, axis=0)).max() < 0.002
    # the wrist stays near the desk capture volume, depth about 0.4-0.7 m
    lo = CAPTURE_VOLUME_CENTER - CAPTURE_VOLUME_SIZE / 2 - 0.05
    hi = CAPTURE_VOLUME_CENTER + CAPTURE_VOLUME_SIZE / 2 + 0.05
    assert np.all((a[:, :3] > lo) & (a[:, :3] < hi))
    # fingers actually move between shapes, the hand actually travels
    assert np.ptp(a[:, 6:], axis=0).max() > np.deg2rad(30)
    assert np.linalg.norm(np.ptp(a[:, :3], axis=0)) > 0.05


def test_train_and_test_conditions_differ() -> None:
    rng = np.random.default_rng(0)
    train = [sample_conditions(rng, 'train') for _ in range(300)]
    test = [sample_conditions(rng, 'test') for _ in range(300)]
    t_temp = np.array([c.color_temperature_k for c in train])
    s_temp = np.array([c.color_temperature_k for c in test])
    assert t_temp.min() >= 5200 and t_temp.max() <= 7200
    assert np.all((s_temp < 5200) | (s_temp > 7200))
    t_gain = np.array([c.gain for c in train])
    s_gain = np.array([c.gain for c in test])
    assert np.all((s_gain < t_gain.min()) | (s_gain > t_gain.max()))
    assert max(c.background_seed for c in train) < BACKGROUND_SEED_SPLIT
    assert min(c.background_seed for c in test) >= BACKGROUND_SEED_SPLIT
    assert 'office' in {c.background_kind for c in test}
    assert 'office' not in {c.background_kind for c in train}
    assert np.mean([c.noise_sigma for c in test]) > np.mean([c.noise_sigma for c in train])
    with pytest.raises(SynthError):
        sample_conditions(rng, 'validation')
    # same seed, same conditions
    assert sample_conditions(np.random.default_rng(4)) == sample_conditions(
        np.random.default_rng(4))


def test_illuminant() -> None:
    np.testing.assert_allclose(illuminant_rgb(6500.0), [1.0, 1.0, 1.0], atol=1e-9)
    warm, cold = illuminant_rgb(3500.0), illuminant_rgb(9500.0)
    assert warm[0] > 1.1 and warm[2] < 0.7
    assert cold[2] > 1.1 and cold[0] < 0.95


def test_frame_ground_truth_and_glove_colours(synth: Synthesizer) -> None:
    cam = default_camera()
    rng = np.random.default_rng(1)
    q = sample_pose(rng, cam, out_of_frame_prob=0.0)
    f = synth.render_frame(q, cam, np.random.default_rng(2), NEUTRAL)
    assert f.image_rgb.shape == (480, 640, 3) and f.image_rgb.dtype == np.uint8
    np.testing.assert_array_equal(f.labels, patch_ids_to_labels(f.patch_ids,
                                                                synth.glove.patch_color))
    np.testing.assert_allclose(f.keypoints_3d, synth.model.keypoints(q))
    np.testing.assert_allclose(f.keypoints_2d, cam.project(f.keypoints_3d))
    assert (f.labels > 0).sum() > 2000 and f.labels.max() <= 10
    # interior pixels of every visible colour are closest in chromaticity to their palette
    # colour: what the labels say is what the image shows
    from scipy.ndimage import binary_erosion
    palette = _rgb_to_chroma(GLOVE_PALETTE_RGB)
    checked = 0
    for label in range(1, 11):
        inner = binary_erosion(f.labels == label, iterations=2)
        if inner.sum() < 30:
            continue
        chroma = _rgb_to_chroma(np.median(f.image_rgb[inner].astype(float), axis=0))
        assert np.argmin(np.linalg.norm(palette - chroma, axis=1)) == label - 1
        checked += 1
    assert checked >= 4
    # the same rng seed and conditions give the same frame; other noise, another frame
    g = synth.render_frame(q, cam, np.random.default_rng(2), NEUTRAL)
    np.testing.assert_array_equal(f.image_rgb, g.image_rgb)
    noisy = replace(NEUTRAL, noise_sigma=0.02)
    h1 = synth.render_frame(q, cam, np.random.default_rng(2), noisy)
    h2 = synth.render_frame(q, cam, np.random.default_rng(3), noisy)
    assert not np.array_equal(h1.image_rgb, h2.image_rgb)
    np.testing.assert_array_equal(h1.labels, h2.labels)


def test_lighting_changes_the_image_not_the_labels(synth: Synthesizer) -> None:
    cam = default_camera()
    q = sample_pose(np.random.default_rng(8), cam, out_of_frame_prob=0.0)
    base = synth.render_frame(q, cam, np.random.default_rng(0), NEUTRAL)
    dark = synth.render_frame(q, cam, np.random.default_rng(0), replace(NEUTRAL, gain=0.5))
    warm = synth.render_frame(q, cam, np.random.default_rng(0),
                              replace(NEUTRAL, color_temperature_k=3800.0))
    blur = synth.render_frame(q, cam, np.random.default_rng(0), replace(NEUTRAL, blur_px=6.0))
    for other in (dark, warm, blur):
        np.testing.assert_array_equal(other.labels, base.labels)
    fg = base.labels > 0
    assert dark.image_rgb[fg].mean() < 0.85 * base.image_rgb[fg].mean()
    rb_base = base.image_rgb[..., 0].mean() / base.image_rgb[..., 2].mean()
    rb_warm = warm.image_rgb[..., 0].mean() / warm.image_rgb[..., 2].mean()
    assert rb_warm > 1.15 * rb_base
    # blur smears the hand's edges: the image gradient inside the hand region drops
    grad = [np.abs(np.diff(x.image_rgb.astype(float), axis=1))[fg[:, 1:]].mean()
            for x in (base, blur)]
    assert grad[1] < 0.8 * grad[0]


def test_background_distractors_stay_off_the_hand_box() -> None:
    keep = (200, 150, 420, 400)
    x0, y0, x1, y1 = keep
    with_distractors = would_cover = saturated = 0
    for seed in range(40):
        base = _background('clutter', seed, 640, 480).base
        free = make_background('clutter', seed, 640, 480)
        kept = make_background('clutter', seed, 640, 480, keep_out=keep)
        # never a glove-like object inside the hand box
        np.testing.assert_array_equal(kept[y0:y1 + 1, x0:x1 + 1], base[y0:y1 + 1, x0:x1 + 1])
        changed = np.abs(free - base).max(axis=2) > 0.05
        with_distractors += int(changed.any())
        would_cover += int(changed[y0:y1 + 1, x0:x1 + 1].any())
        if changed.any():
            px = free[changed]
            sat = (px.max(1) - px.min(1)) / np.maximum(px.max(1), 1e-6)
            saturated += int(np.median(sat) > 0.6)
    assert with_distractors > 15 and would_cover > 0 and saturated > 10
    a = make_background('desk', 7, 160, 120)
    np.testing.assert_array_equal(a, make_background('desk', 7, 160, 120))
    assert not np.array_equal(a, make_background('desk', 8, 160, 120))
    with pytest.raises(SynthError):
        make_background('forest', 0, 10, 10)


def test_hand_partly_out_of_frame(synth: Synthesizer) -> None:
    cam = default_camera()
    rng = np.random.default_rng(21)
    touching = 0
    for _ in range(6):
        q = sample_pose(rng, cam, out_of_frame_prob=1.0)
        ids = synth.renderer(cam.width, cam.height).render_patch_ids(
            synth.vertices(q)[None], synth.faces, synth.face_patch, cam)[0]
        border = np.concatenate([ids[0], ids[-1], ids[:, 0], ids[:, -1]])
        kp = cam.project(synth.model.keypoints(q))
        outside = np.any((kp < 0) | (kp > [cam.width - 1, cam.height - 1]), axis=1)
        touching += int(border.any() and outside.any() and (ids > 0).any())
    assert touching >= 4


def test_sequence_renderer_is_order_independent() -> None:
    seq = SyntheticSequenceRenderer(default_camera(), seed=3, num_frames=6, split='train')
    later = seq.render(4)
    first = seq.render(1)
    again = seq.render(4)
    np.testing.assert_array_equal(later.image_rgb, again.image_rgb)
    assert not np.array_equal(first.image_rgb, later.image_rgb)
    np.testing.assert_array_equal(later.pose, generate_sequence(3, 6)[4])
    assert later.conditions.background_seed < BACKGROUND_SEED_SPLIT
    with pytest.raises(SynthError):
        seq.render(6)
    seq.close()


STEREO_SEED = 10          # its hand moves fast: > 5 px of blur in both views at frame 1


@pytest.fixture(scope='module')
def stereo_sequence() -> SyntheticSequenceRenderer:
    cams = load_calibration(CONFIG / 'calibration_stereo.yaml').cameras
    seq = SyntheticSequenceRenderer(cams[0], seed=STEREO_SEED, num_frames=6, split='test')
    yield seq
    seq.close()


def _speed_blur(seq: SyntheticSequenceRenderer, camera, index: int) -> tuple[float, float]:
    """Blur length and angle of frame ``index`` in ``camera`` (extrinsics relative to the
    primary, whose frame is the world): the hand centre's image velocity x the shutter."""
    prv, nxt = max(index - 1, 0), min(index + 1, len(seq) - 1)
    centres = seq.synth.model.keypoints_batch(seq.poses[[prv, nxt]]).mean(axis=1)
    px = camera.project(camera.world_to_camera(centres))
    vel = (px[1] - px[0]) / (nxt - prv)
    return float(np.hypot(*vel) * seq.shutter), float(np.arctan2(vel[1], vel[0]))


def test_sequence_views_primary_is_the_one_camera_frame(stereo_sequence) -> None:
    """View 0 of ``render_views`` is bit for bit the one-camera frame (same conditions,
    noise seed and motion blur), whatever order the frames are asked in."""
    seq = stereo_sequence
    cams = load_calibration(CONFIG / 'calibration_stereo.yaml').cameras
    mono = SyntheticSequenceRenderer(cams[0], seed=STEREO_SEED, num_frames=6, split='test')
    first = {}
    for i in (4, 0, 1, 4):
        views = seq.render_views(i, cams)
        single = mono.render(i)
        assert len(views) == 2
        np.testing.assert_array_equal(views[0].image_rgb, single.image_rgb)
        np.testing.assert_array_equal(views[0].labels, single.labels)
        np.testing.assert_array_equal(views[0].pose, seq.poses[i])
        assert views[0].conditions == single.conditions
        assert (views[0].conditions.blur_px, views[0].conditions.blur_angle) == \
            pytest.approx(_speed_blur(seq, cams[0], i))
        if i in first:       # the second view too is reproducible by index
            np.testing.assert_array_equal(views[1].image_rgb, first[i].image_rgb)
        first[i] = views[1]
    mono.close()
    assert not np.array_equal(first[0].image_rgb, first[4].image_rgb)
    with pytest.raises(SynthError, match='outside'):
        seq.render_views(6, cams)
    with pytest.raises(SynthError, match='at least one camera'):
        seq.render_views(0, [])


def _gradient_along(image: np.ndarray, angle: float, mask: np.ndarray) -> float:
    grey = image.astype(np.float64).mean(axis=2)
    gx = cv2.Sobel(grey, cv2.CV_64F, 1, 0)
    gy = cv2.Sobel(grey, cv2.CV_64F, 0, 1)
    return float(np.abs(np.cos(angle) * gx + np.sin(angle) * gy)[mask].mean())


def test_second_view_is_blurred_by_its_own_image_velocity(stereo_sequence) -> None:
    """The second camera's blur follows the hand's velocity in that camera's image; against
    the same frame rendered without blur (same labels, noise and background) the hand is
    smeared along the motion, and only near the moving hand and arm do pixels change."""
    seq = stereo_sequence
    cams = load_calibration(CONFIG / 'calibration_stereo.yaml').cameras
    index = 1
    views = seq.render_views(index, cams)
    blur, angle = _speed_blur(seq, cams[1], index)
    assert (views[1].conditions.blur_px, views[1].conditions.blur_angle) == \
        pytest.approx((blur, angle))
    assert blur > 5.0 and abs(blur - views[0].conditions.blur_px) > 1.0
    still = render_frames_multi(seq.poses[index], cams,
                                np.random.default_rng([STEREO_SEED, index, 11]),
                                replace(seq.conditions, blur_px=0.0), synthesizer=seq.synth)
    for view, sharp in zip(views, still, strict=True):
        np.testing.assert_array_equal(view.labels, sharp.labels)
        np.testing.assert_allclose(view.pose, sharp.pose, atol=1e-12)
        hand = view.labels > 0
        changed = np.any(view.image_rgb != sharp.image_rgb, axis=2)
        assert changed[hand].mean() > 0.5 and changed.mean() < 0.25
        assert _gradient_along(view.image_rgb, view.conditions.blur_angle, hand) < \
            0.95 * _gradient_along(sharp.image_rgb, view.conditions.blur_angle, hand)


def test_multi_camera_views_agree(synth: Synthesizer) -> None:
    cams = load_calibration(CONFIG / 'calibration_stereo.yaml').cameras
    q = sample_pose(np.random.default_rng(2), cams[0], out_of_frame_prob=0.0)
    frames = render_frames_multi(q, cams, np.random.default_rng(0), NEUTRAL, synthesizer=synth)
    assert len(frames) == 2
    np.testing.assert_allclose(frames[0].pose, q)
    R = cams[1].rotation @ cams[0].rotation.T
    t = cams[1].translation - R @ cams[0].translation
    np.testing.assert_allclose(frames[1].keypoints_3d, frames[0].keypoints_3d @ R.T + t,
                               atol=1e-9)
    direct = synth.render_frame(frames[1].pose, cams[1], np.random.default_rng(0),
                                frames[1].conditions)
    np.testing.assert_array_equal(direct.labels, frames[1].labels)
    assert (frames[1].labels > 0).sum() > 500
    assert frames[0].conditions.background_seed != frames[1].conditions.background_seed


def test_lens_distortion_is_applied_consistently(synth: Synthesizer) -> None:
    import cv2

    plain = default_camera()
    bent = replace(plain, distortion=np.array([-0.25, 0.08, 0.0, 0.0, 0.0]))
    q = sample_pose(np.random.default_rng(5), plain, out_of_frame_prob=0.0)
    q[0] += 0.08                                   # off-centre, where distortion is strong
    a = synth.render_frame(q, plain, np.random.default_rng(0), NEUTRAL)
    b = synth.render_frame(q, bent, np.random.default_rng(0), NEUTRAL)
    assert np.mean(a.labels != b.labels) > 0.002
    # undistorting the distorted labels gives back the pinhole labels
    mx, my = cv2.initUndistortRectifyMap(bent.K, bent.distortion, None, bent.K,
                                         (bent.width, bent.height), cv2.CV_32FC1)
    back = cv2.remap(b.labels, mx, my, cv2.INTER_NEAREST)
    fg = (a.labels > 0) | (back > 0)
    assert np.mean(back[fg] == a.labels[fg]) > 0.95
    # keypoints follow the lens model
    uv, _ = cv2.projectPoints(b.keypoints_3d, np.zeros(3), np.zeros(3), bent.K, bent.distortion)
    np.testing.assert_allclose(b.keypoints_2d, uv.reshape(-1, 2), atol=1e-6)
    assert np.abs(b.keypoints_2d - a.keypoints_2d).max() > 2.0
