"""Edge features on drawn bars with known axes: link lines, polarity, tips."""
from __future__ import annotations

import cv2
import numpy as np
import pytest

from colorglove_ros.core.tracking.edge_features import (
    EdgeFeatureError,
    EdgeSearchConfig,
    measure_link_axes,
    measure_outline_edges,
    measure_tips,
    segment_distances,
    to_grey,
)


def _bar_image(a: np.ndarray, b: np.ndarray, radius: float, bright: bool = True,
               noise: float = 2.0, seed: int = 0) -> np.ndarray:
    """A capsule from a to b (anti-aliased, 8x supersampled) on a flat background."""
    s = 8
    img = np.full((240 * s, 320 * s), 60 if bright else 190, np.uint8)
    value = 190 if bright else 60
    pa, pb = (a * s + s / 2).astype(int), (b * s + s / 2).astype(int)
    cv2.line(img, tuple(int(v) for v in pa), tuple(int(v) for v in pb), value,
             int(2 * radius * s))
    cv2.circle(img, tuple(int(v) for v in pb), int(radius * s), value, -1)
    small = cv2.resize(img, (320, 240), interpolation=cv2.INTER_AREA).astype(np.float32)
    return small + np.random.default_rng(seed).normal(0, noise, small.shape).astype(np.float32)


A = np.array([150.0, 200.0])
B = np.array([170.0, 80.0])
R = 9.0


def _line_error(axes, k: int, p: np.ndarray, q: np.ndarray) -> float:
    """Largest distance of the true axis end points from measured line k."""
    n, rho = axes.normal[k], axes.offset[k]
    return max(abs(n @ p - rho), abs(n @ q - rho))


@pytest.mark.parametrize('shift_px, turn_deg', [(0.0, 0.0), (4.0, 0.0), (-3.0, 4.0)])
def test_link_axis_recovered_from_an_offset_prediction(shift_px: float, turn_deg: float) -> None:
    grey = _bar_image(A, B, R)
    u = (B - A) / np.linalg.norm(B - A)
    n = np.array([-u[1], u[0]])
    t = np.radians(turn_deg)
    rot = np.array([[np.cos(t), -np.sin(t)], [np.sin(t), np.cos(t)]])
    mid = 0.5 * (A + B) + shift_px * n
    pa = mid + rot @ (A - 0.5 * (A + B))
    pb = mid + rot @ (B - 0.5 * (A + B))
    axes = measure_link_axes(grey, pa[None], pb[None], np.array([R]))
    assert axes.found[0]
    assert axes.num_points[0] >= 4
    assert axes.polarity[0] == 1
    assert _line_error(axes, 0, A, B) < 0.5


def test_wrong_polarity_finds_nothing_and_either_finds_the_dark_bar() -> None:
    grey = _bar_image(A, B, R, bright=False)
    wrong = measure_link_axes(grey, A[None], B[None], np.array([R]), polarity=1)
    assert not wrong.found[0]
    either = measure_link_axes(grey, A[None], B[None], np.array([R]), polarity=0)
    assert either.found[0] and either.polarity[0] == -1
    assert _line_error(either, 0, A, B) < 0.5


def _shaded_bar_image(radius: float, bright_ramp: bool = True) -> np.ndarray:
    """A vertical finger at x = 160 shaded across its width (light from the right: 90 at its
    left rim rising to 220 at the right one, or a softer inner ramp) before a mid-grey 150
    background: darker than the background on the left edge, brighter on the right."""
    x = np.arange(320, dtype=np.float32)[None, :].repeat(240, axis=0)
    u = np.clip((x - (160.0 - radius)) / (2.0 * radius), 0.0, 1.0)
    shade = 90.0 + 130.0 * (u if bright_ramp else np.sqrt(u))
    inside = np.abs(x - 160.0) <= radius
    img = np.where(inside, shade, 150.0).astype(np.float32)
    img = cv2.GaussianBlur(img, (0, 0), 0.7)
    return img + np.random.default_rng(3).normal(0, 1.0, img.shape).astype(np.float32)


@pytest.mark.parametrize('bright_ramp', [True, False])
def test_shaded_finger_on_mid_grey_is_measured_at_its_rims(bright_ramp: bool) -> None:
    # one rim darker than the background, the other brighter: the two edges have opposite
    # signs of 'entering' and 'leaving', and the inner shading ramp is an edge too
    r = 10.0
    grey = _shaded_bar_image(r, bright_ramp)
    a, b = np.array([160.0, 200.0]), np.array([160.0, 60.0])
    axes = measure_link_axes(grey, a[None], b[None], np.array([r]), polarity=0)
    assert axes.found[0] and axes.num_points[0] >= 5
    assert _line_error(axes, 0, a, b) < 0.5


def test_width_far_from_the_prediction_is_rejected() -> None:
    grey = _bar_image(A, B, R, noise=0.5)
    axes = measure_link_axes(grey, A[None], B[None], np.array([R * 4.0]),
                             EdgeSearchConfig(search_px=4.0))
    assert not axes.found[0]


def test_slices_switched_off_are_not_used() -> None:
    grey = _bar_image(A, B, R)
    cfg = EdgeSearchConfig()
    valid = np.zeros((1, cfg.slices_per_link), bool)
    valid[0, :2] = True
    axes = measure_link_axes(grey, A[None], B[None], np.array([R]), cfg, slice_valid=valid)
    assert axes.num_points[0] <= 2 and not axes.found[0]
    # a link with no usable slice at all is not searched, and not found
    none = measure_link_axes(grey, A[None], B[None], np.array([R]), cfg,
                             slice_valid=np.zeros((1, cfg.slices_per_link), bool))
    assert not none.found[0] and none.num_points[0] == 0
    # the slices searched give the same line as searching all and dropping the rest
    some = np.ones((1, cfg.slices_per_link), bool)
    some[0, 1] = False
    kept = measure_link_axes(grey, A[None], B[None], np.array([R]), cfg, slice_valid=some)
    assert kept.found[0] and np.isnan(kept.midpoints[0, 1]).all()


def test_tip_centre_is_the_end_edge_moved_back_by_the_radius() -> None:
    grey = _bar_image(A, B, R)
    u = (B - A) / np.linalg.norm(B - A)
    predicted_end = B + 5.0 * u          # predicted extremity 5 px beyond the true centre
    tips = measure_tips(grey, A[None], u[None], predicted_end[None], np.array([R]),
                        polarity=1)
    assert tips.found[0]
    assert np.linalg.norm(tips.centre[0] - B) < 1.0


def test_segment_distances_and_grey_conversion() -> None:
    d, s = segment_distances(np.array([[0.0, 1.0], [3.0, 0.0]]), np.array([[0.0, 0.0]]),
                             np.array([[2.0, 0.0]]))
    assert np.allclose(d[:, 0], [1.0, 1.0]) and np.allclose(s[:, 0], [0.0, 1.0])
    rgb = np.zeros((4, 5, 3), np.uint8)
    rgb[..., 0] = 255
    assert to_grey(rgb).shape == (4, 5) and 70 < to_grey(rgb)[0, 0] < 80
    with pytest.raises(EdgeFeatureError):
        to_grey(np.zeros((2, 2, 2)))
    with pytest.raises(EdgeFeatureError):
        EdgeSearchConfig(width_ratio=(1.2, 2.0))


@pytest.mark.parametrize('shift_px', [-4.0, 3.0])
def test_outline_edge_found_from_an_offset_prediction_normal_outward(shift_px: float) -> None:
    # a bright shape filling x < 200 (a vertical side at x = 200): predicted at 200 + shift
    # with the outside toward +x
    grey = np.full((240, 320), 40.0, dtype=np.float32)
    grey[:, :200] = 180.0
    grey = cv2.GaussianBlur(grey, (5, 5), 1.0)
    axes = measure_outline_edges(grey, np.array([[200.0 + shift_px, 200.0]]),
                                 np.array([[200.0 + shift_px, 60.0]]), np.array([[1.0, 0.0]]),
                                 EdgeSearchConfig())
    assert axes.found[0] and axes.polarity[0] == 1
    assert np.allclose(axes.normal[0], [1.0, 0.0], atol=1e-3)
    assert abs(axes.offset[0] - 199.5) < 0.3     # the step lies between pixels 199 and 200


@pytest.mark.parametrize('dtype', [np.uint8, np.float64])
def test_link_axes_are_measured_in_a_grey_image_of_any_dtype(dtype) -> None:
    """An 8-bit or float64 grey image is sampled as it is and its samples differentiated as
    float32, as the outline and tip measurements do (not only the tracker's float32 grey)."""
    grey = _bar_image(A, B, R)
    image = np.clip(np.rint(grey), 0, 255).astype(dtype)
    axes = measure_link_axes(image, A[None], B[None], np.array([R]))
    assert axes.found[0] and _line_error(axes, 0, A, B) < 0.5
