"""Silhouettes against a calibrated empty scene, and what a predicted hand leaves unexplained."""
from __future__ import annotations

import numpy as np
import pytest

from colorglove_ros.core.tracking.silhouette import (
    BackgroundModel,
    HandOutline,
    Silhouette,
    SilhouetteConfig,
    SilhouetteError,
)


def _scene(seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """An empty textured RGB scene and the same scene with a bright 'finger' bar (x 100-119,
    y 40-159) and noise."""
    rng = np.random.default_rng(seed)
    empty = rng.integers(40, 120, (240, 320, 3)).astype(np.uint8)
    frame = np.clip(empty + rng.normal(0, 3, empty.shape), 0, 255).astype(np.uint8)
    frame[40:160, 100:120] = (200, 160, 140)
    return empty, frame


@pytest.mark.parametrize('scale', [1, 2])
def test_foreground_is_what_differs_from_the_empty_scene(scale: int) -> None:
    empty, frame = _scene()
    model = BackgroundModel.from_frames([empty], SilhouetteConfig(threshold=30, scale=scale))
    sil = model.silhouette(frame)
    assert sil.mask.shape == (240 // scale, 320 // scale)
    assert abs(sil.area_px - 20 * 120) < 0.05 * 20 * 120
    # a skin-coloured object in the empty scene is background, not hand
    empty[200:220, 10:40] = (200, 160, 140)
    frame[200:220, 10:40] = (200, 160, 140)
    sil2 = BackgroundModel.from_frames([empty], SilhouetteConfig(scale=scale)).silhouette(frame)
    assert abs(sil2.area_px - sil.area_px) < 0.02 * sil.area_px


def test_grey_images_work_and_mismatches_are_refused() -> None:
    empty, frame = _scene()
    grey = BackgroundModel.from_frames([empty.mean(axis=2)])
    assert grey.silhouette(frame.mean(axis=2)).area_px > 2000
    with pytest.raises(SilhouetteError):
        grey.silhouette(frame)                     # 3 channels against a grey model
    with pytest.raises(SilhouetteError):
        grey.silhouette(frame[:100].mean(axis=2))  # another size
    with pytest.raises(SilhouetteError):
        BackgroundModel.from_frames([])
    with pytest.raises(SilhouetteError):
        SilhouetteConfig(threshold=0)


def test_outside_distance_is_zero_inside_and_grows_away_from_the_foreground() -> None:
    mask = np.zeros((120, 160), bool)
    mask[20:80, 50:60] = True
    sil = Silhouette(mask, 2)          # full-resolution pixels are twice the mask's
    d, grad = sil.outside_distance(np.array([[110.0, 100.0], [160.0, 100.0], [110.0, 200.0]]))
    assert d[0] == 0.0
    assert d[1] == pytest.approx(160 - 119.5, abs=3.0)
    assert d[2] == pytest.approx(200 - 159.5, abs=3.0)
    assert grad[1, 0] > 0.5 and abs(grad[1, 1]) < 0.3     # away from the bar: +x
    assert grad[2, 1] > 0.5


def _outline(half_width: float, tip_y: float) -> HandOutline:
    """One vertical link from the wrist (y 160) up to ``tip_y``, a palm square below it."""
    return HandOutline(base=np.array([[110.0, 100.0]]), end=np.array([[110.0, tip_y]]),
                       half_width=np.array([half_width]), tip=np.zeros((0, 2)),
                       tip_radius=np.zeros(0),
                       palm=np.array([[100.0, 100.0], [120.0, 100.0], [120.0, 160.0],
                                      [100.0, 160.0]]),
                       wrist=np.array([110.0, 160.0]), axis=np.array([0.0, -1.0]))


def test_unexplained_foreground_is_what_no_part_of_the_hand_covers() -> None:
    empty, frame = _scene()
    frame[160:240, 102:118] = (190, 150, 130)      # the forearm, below the wrist
    sil = BackgroundModel.from_frames([empty]).silhouette(frame)
    loose, share = sil.unexplained(_outline(10.0, 40.0), 3.0)
    assert share < 0.02 and len(loose) < 0.02 * sil.area_px
    # a finger drawn 30 px too short leaves its end unexplained (the forearm never counts)
    loose, share = sil.unexplained(_outline(10.0, 70.0), 3.0)
    assert 0.1 < share < 0.3          # 30 px less 13 px of round cap and tolerance
    assert np.all(loose[:, 1] < 70.0) and np.all(np.abs(loose[:, 0] - 110) < 12)
    # the share alone (the drift check's): the same share, no pixels listed
    none, same = sil.unexplained(_outline(10.0, 70.0), 3.0, pixels=False)
    assert same == share and none.shape == (0, 2)


def test_a_region_limits_where_the_foreground_is_looked_for() -> None:
    empty, frame = _scene()
    frame[200:230, 250:300] = (20, 220, 20)            # something else, far from the hand
    model = BackgroundModel.from_frames([empty])
    everywhere = model.silhouette(frame)
    near = model.silhouette(frame, (80.0, 20.0, 140.0, 180.0))
    assert near.area_px < everywhere.area_px - 1000
    assert abs(near.area_px - 20 * 120) < 0.05 * 20 * 120
    d, _ = near.outside_distance(np.array([[110.0, 100.0], [135.0, 100.0]]))
    assert d[0] == 0.0 and d[1] == pytest.approx(135 - 119.5, abs=3.0)   # image pixels
    loose, share = near.unexplained(_outline(10.0, 40.0), 3.0)
    assert share < 0.02 and len(loose) < 50
