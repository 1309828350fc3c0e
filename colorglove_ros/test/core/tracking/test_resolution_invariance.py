"""The IK does not depend on the image resolution: a frame and its 2x upscale, seen with
intrinsics scaled alike, give the same pose (its pixel settings are for a reference focal
length, ``IKConfig.reference_focal_px``, and scale with each camera's)."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from repo_paths import CONFIG_DIR

from colorglove_ros.core.camera import PinholeCamera, load_calibration
from colorglove_ros.core.evaluation.sequences import truth_observer
from colorglove_ros.core.lookup.search import PoseLookup
from colorglove_ros.core.pipeline import UNGATED, look_up
from colorglove_ros.core.segmentation.crop import CropTransform
from colorglove_ros.core.synthetic.sequences import SyntheticSequenceRenderer
from colorglove_ros.core.tracking.config import IKConfig, load_ik_config
from colorglove_ros.core.tracking.projection import pixel_scale
from colorglove_ros.core.tracking.tracker import HandTracker
from colorglove_ros.core.tracking.types import Blobs, CameraObservation, PosePrior

FRAMES = 8
UPSCALE = 2


def upscaled_camera(camera: PinholeCamera, k: int = UPSCALE) -> PinholeCamera:
    """``camera`` for its images resized k times (pixel centres: x' = k x + (k - 1) / 2)."""
    shift = 0.5 * (k - 1)
    return replace(camera, width=camera.width * k, height=camera.height * k,
                   fx=camera.fx * k, fy=camera.fy * k, cx=camera.cx * k + shift,
                   cy=camera.cy * k + shift)


def upscaled_observation(obs: CameraObservation, k: int = UPSCALE) -> CameraObservation:
    """What the segmentation reports for the k times resized image: centroids moved as the
    pixel centres, k^2 as many pixels per blob, the crop k times larger."""
    shift = 0.5 * (k - 1)
    blobs = Blobs(obs.blobs.color, obs.blobs.centroid_px * k + shift,
                  obs.blobs.pixel_count * k * k)
    crop = None if obs.crop is None else CropTransform(
        obs.crop.scale * k, obs.crop.offset_x * k + shift, obs.crop.offset_y * k + shift)
    return replace(obs, blobs=blobs, crop=crop)


@pytest.fixture(scope='module')
def stereo_frames(small_database, hand):
    """Lookup priors and both cameras' observations (renderer's labels) of a short synthetic
    sequence seen by the two cameras of config/calibration_stereo.yaml."""
    cameras = load_calibration(CONFIG_DIR / 'calibration_stereo.yaml').cameras
    lookup = PoseLookup(small_database, 40, 10)
    observe = truth_observer()
    renderer = SyntheticSequenceRenderer(cameras[0], seed=3, num_frames=FRAMES)
    frames = []
    try:
        for i in range(FRAMES):
            views = renderer.render_views(i, cameras)
            primary, tiny = observe(views[0], True)
            extra, _ = observe(views[1], False)
            assert tiny is not None and primary.hand_found
            found = look_up(lookup, tiny, cameras[0], primary.blobs, UNGATED)
            frames.append((PosePrior.from_lookup(found), [primary, extra],
                           renderer.poses[i]))
    finally:
        renderer.close()
    return cameras, frames


def _track(hand, cameras, frames, config: IKConfig, upscale: tuple[bool, ...]) -> np.ndarray:
    """The poses (FRAMES, 26) tracked with the cameras marked in ``upscale`` seeing their
    images (and intrinsics) resized 2x."""
    model, mesh, glove = hand
    cams = [upscaled_camera(c) if up else c
            for c, up in zip(cameras[:len(upscale)], upscale, strict=True)]
    tracker = HandTracker(model, mesh, cams, config, glove)
    poses = []
    for i, (prior, observations, _) in enumerate(frames):
        views = [upscaled_observation(o) if up else o
                 for o, up in zip(observations[:len(cams)], upscale, strict=True)]
        result = tracker.update(prior, views, i / 30.0)
        assert result.found and result.num_constraints >= 3
        poses.append(result.q)
    return np.array(poses)


@pytest.mark.parametrize('upscale', [(True,), (True, True), (False, True)],
                         ids=['1 camera', '2 cameras, both 2x', '2 cameras, the extra 2x'])
def test_upscaled_frame_gives_the_same_pose(hand, stereo_frames, upscale) -> None:
    """The shipped IK settings: the pose at 1280x960 with doubled intrinsics equals the pose
    at 640x480 (depth within 2 mm in every frame, in fact to rounding), with smoothing over a
    short sequence, one camera and two."""
    cameras, frames = stereo_frames
    config = load_ik_config(CONFIG_DIR / 'ik.yaml')
    base = _track(hand, cameras, frames, config, (False,) * len(upscale))
    scaled = _track(hand, cameras, frames, config, upscale)
    np.testing.assert_allclose(scaled[:, 2], base[:, 2], atol=2e-3)
    np.testing.assert_allclose(scaled[:, 0:2], base[:, 0:2], atol=1e-3)
    np.testing.assert_allclose(scaled[:, 6:], base[:, 6:], atol=1e-3)


def test_reference_focal_length_sets_the_pixel_unit(hand, stereo_frames) -> None:
    """The settings are pixels of the reference camera: a camera of twice the reference focal
    length scales them by 2, and halving the reference with the same pixel settings is the
    same as doubling every one of them (so the pose changes)."""
    cameras, frames = stereo_frames
    assert pixel_scale(cameras[0], 600.0) == 1.0
    assert pixel_scale(upscaled_camera(cameras[0]), 600.0) == UPSCALE
    assert pixel_scale(cameras[0], None) == 1.0
    config = load_ik_config(CONFIG_DIR / 'ik.yaml')
    assert config.reference_focal_px == cameras[0].fx   # the shipped 640x480 calibration
    base = _track(hand, cameras, frames[:4], config, (False,))
    halved = _track(hand, cameras, frames[:4], replace(config, reference_focal_px=300.0),
                    (False,))
    assert np.abs(halved[:, 0:3] - base[:, 0:3]).max() > 1e-4
