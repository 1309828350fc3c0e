"""Bare-hand synthetic frames and motion: skin colour, hand mask, hold, speed, determinism."""
from __future__ import annotations

import numpy as np
import pytest

from colorglove_ros.core.hand.model import HandModel
from colorglove_ros.core.synthetic.backgrounds import make_background
from colorglove_ros.core.synthetic.bare_hand import (
    BareHandError,
    BareHandSequence,
    bare_hand_conditions,
    bare_hand_motion,
    skin_albedo,
)
from colorglove_ros.core.synthetic.frames import default_camera, view_background_seed
from colorglove_ros.core.tracking.edge_tracker import initialisation_pose

MODEL = HandModel()


def test_motion_holds_the_initialisation_pose_then_moves_smoothly() -> None:
    Q = bare_hand_motion(3, 120, MODEL, hold_frames=15)
    assert Q.shape == (120, 26)
    assert np.allclose(Q[:16], initialisation_pose(MODEL, (0.0, 0.095, 0.5)))
    assert np.abs(Q[-1] - Q[0]).max() > 0.05
    assert np.all(MODEL.within_limits(Q))
    assert np.abs(np.diff(Q[:, 0:3], axis=0)).max() < 0.01      # < 1 cm per frame
    assert np.array_equal(Q, bare_hand_motion(3, 120, MODEL, hold_frames=15))


def test_speed_scales_the_time_axis() -> None:
    slow = bare_hand_motion(4, 200, MODEL, hold_frames=0)
    fast = bare_hand_motion(4, 100, MODEL, hold_frames=0, speed=2.0)
    assert np.allclose(fast, slow[::2][:100])
    with pytest.raises(BareHandError):
        bare_hand_motion(4, 10, MODEL, speed=0.0)


def test_frame_is_a_skin_coloured_hand_with_its_mask() -> None:
    seq = BareHandSequence(default_camera(), seed=2, num_frames=20, skin_tone=1)
    try:
        frame = seq.render(0)
        hand = frame.patch_ids > 0
        assert 3000 < hand.sum() < 60000
        rgb = frame.image_rgb[hand].astype(float).mean(axis=0)
        assert rgb[0] > rgb[1] > rgb[2]                # skin: red > green > blue
        ring = np.zeros_like(hand)
        ys, xs = np.nonzero(hand)
        ring[max(ys.min() - 15, 0):ys.max() + 15, max(xs.min() - 15, 0):xs.max() + 15] = True
        grey = frame.image_rgb.astype(float).mean(axis=2)
        assert abs(grey[hand].mean() - grey[ring & ~hand].mean()) > 10.0
        assert np.allclose(frame.pose, seq.poses[0])
        again = seq.render(0)
        assert np.array_equal(frame.image_rgb, again.image_rgb)
    finally:
        seq.close()
    assert np.all(skin_albedo(0) > skin_albedo(5))
    with pytest.raises(BareHandError):
        skin_albedo(9)


def test_min_contrast_holds_in_every_view_of_the_rig() -> None:
    luma = np.array([0.2126, 0.7152, 0.0722])
    skin = skin_albedo(1)
    # this generator's first background passes in view 0 but not in view 1
    picks = {views: bare_hand_conditions(np.random.default_rng([5, 23, 1]), skin, 'test',
                                         0.25, 160, 120, views) for views in (1, 2)}
    for views, cond in picks.items():
        skin_grey = float(skin @ luma) * (cond.ambient + (1.0 - cond.ambient) * 0.8)
        contrast = [abs(float(make_background(cond.background_kind,
                                              view_background_seed(cond.background_seed, k),
                                              160, 120).mean(axis=(0, 1)) @ luma) - skin_grey)
                    / skin_grey for k in range(2)]
        assert min(contrast[:views]) >= 0.25
        if views == 1:
            assert contrast[1] < 0.25     # the case the rig-wide check exists for


def test_empty_scene_is_the_same_scene_without_the_hand() -> None:
    from colorglove_ros.core.camera import load_calibration
    from colorglove_ros.paths import resolve_path

    cameras = load_calibration(resolve_path('config/calibration_stereo.yaml')).cameras
    seq = BareHandSequence(cameras[0], seed=2, num_frames=20)
    try:
        empty = seq.render_empty_views(cameras)
        frames = seq.render_views(0, cameras)
    finally:
        seq.close()
    for frame, image in zip(frames, empty, strict=True):
        assert image.shape == frame.image_rgb.shape and image.dtype == np.uint8
        diff = np.abs(frame.image_rgb.astype(int) - image.astype(int)).max(axis=2)
        hand = frame.patch_ids > 0
        assert np.median(diff[hand]) > 30          # the hand is gone
        ys, xs = np.nonzero(hand)
        far = np.ones_like(hand)
        far[max(ys.min() - 20, 0):, max(xs.min() - 20, 0):xs.max() + 20] = False
        assert np.median(diff[far]) < 8 and np.percentile(diff[far], 99) < 25   # new noise only
