"""The DigitEyes 3-D mouse: mapping, hysteresis buttons, smoothing and gaps."""
from __future__ import annotations

import math

import numpy as np
import pytest

from colorglove_ros.core.hand.model import DOF_NAMES, HandModel
from colorglove_ros.core.tracking.mouse import (
    Mouse3D,
    MouseConfig,
    MouseError,
    TablePlane,
    palm_centre,
    raw_mouse_values,
)

MODEL = HandModel()
THUMB = DOF_NAMES.index('thumb_cmc_abd')
LITTLE = DOF_NAMES.index('little_mcp_abd')
INDEX_MCP = DOF_NAMES.index('index_mcp_flex')
PLANE = TablePlane((0.0, 0.0, 0.5), (1.0, 0.0, 0.0), (0.0, 1.0, 0.0))   # normal +z: away


def _pose(x: float = 0.0, y: float = 0.0) -> np.ndarray:
    q = MODEL.rest_pose()
    q[0:3] = [x, y, 0.5]
    return q


def test_cursor_is_the_palm_in_the_plane_and_height_follows_the_index() -> None:
    cfg = MouseConfig(plane=PLANE, smoothing_s=0.0)
    q = _pose(0.03, -0.02)
    raw = raw_mouse_values(MODEL, q, cfg)
    centre = palm_centre(MODEL.keypoints(q))
    assert np.allclose(raw[:2], centre[:2])
    assert raw[2] == pytest.approx(0.0, abs=1e-9)
    lifted = q.copy()
    lifted[3:6] = [0.0, math.pi, 0.0]   # palm turned away from the camera: flexing the
    lifted[INDEX_MCP] = 0.6             # index toward the palm raises its tip along +z
    assert raw_mouse_values(MODEL, lifted, cfg)[2] > 0.02


def test_buttons_have_hysteresis_and_report_edges() -> None:
    mouse = Mouse3D(MODEL, MouseConfig(plane=PLANE, smoothing_s=0.0, press_deg=(25.0, 10.0),
                                       release_deg=(15.0, 5.0)))
    q = _pose()
    events = []
    for t, deg in enumerate([0, 20, 30, 20, 16, 14, 30]):
        q[THUMB] = math.radians(deg)
        state = mouse.update(q, 0.1 * t)
        events.append((state.buttons[0], state.pressed[0], state.released[0]))
    assert [e[0] for e in events] == [False, False, True, True, True, False, True]
    assert [e[1] for e in events] == [False, False, True, False, False, False, True]
    assert [e[2] for e in events] == [False, False, False, False, False, True, False]
    q[THUMB] = 0.0
    q[LITTLE] = math.radians(-12.0)      # little finger abducted away from the hand
    state = mouse.update(q, 0.8)
    assert state.buttons == (False, True) and state.pressed == (False, True)


def test_smoothing_lags_and_a_gap_restarts() -> None:
    mouse = Mouse3D(MODEL, MouseConfig(plane=PLANE, smoothing_s=0.1, max_gap_s=0.5))
    a = mouse.update(_pose(0.0), 0.0).cursor
    b = mouse.update(_pose(0.1), 0.1).cursor
    frac = (b[0] - a[0]) / 0.1
    assert frac == pytest.approx(1.0 - math.exp(-1.0), rel=1e-6)
    c = mouse.update(_pose(0.1), 2.0).cursor     # gap: restart at the raw value
    assert c[0] - a[0] == pytest.approx(0.1, rel=1e-6)


def test_a_press_waits_for_a_residual_near_the_tracks_usual_one() -> None:
    cfg = MouseConfig(plane=PLANE, smoothing_s=0.0, press_max_residual_ratio=1.5,
                      residual_window_s=1.0)
    mouse, ungated = Mouse3D(MODEL, cfg), Mouse3D(MODEL, MouseConfig(plane=PLANE,
                                                                     smoothing_s=0.0))
    q = _pose()
    # a good track (residual 1 px), then the thumb abducted on a fit three times as poor,
    # then on a fit as good as before
    script = [(5, 1.0)] * 5 + [(40, 3.0)] * 3 + [(40, 1.2), (40, 1.2)]
    pressed, free = [], []
    for t, (deg, residual) in enumerate(script):
        q[THUMB] = math.radians(deg)
        pressed.append(mouse.update(q, 0.1 * t, residual).pressed[0])
        free.append(ungated.update(q, 0.1 * t, residual).pressed[0])
    assert free.index(True) == 5                 # without the gate: the poor fit presses
    assert pressed.index(True) == 8 and sum(pressed) == 1
    # a button already down is released as usual on a poor fit
    q[THUMB] = 0.0
    assert mouse.update(q, 1.0, 9.0).released[0]
    # unknown residuals and the first pose never hold a press back
    q[THUMB] = math.radians(40)
    fresh = Mouse3D(MODEL, cfg)
    assert fresh.update(q, 0.0, 50.0).pressed[0]
    fresh.reset()
    assert fresh.update(q, 0.0).pressed[0]
    # the window forgets old residuals: a slow rise of the residual is the new usual
    slow = Mouse3D(MODEL, cfg)
    q[THUMB] = 0.0
    for t in range(10):
        slow.update(q, 0.1 * t, 1.0)
    q[THUMB] = math.radians(40)
    for t in range(10, 22):
        state = slow.update(q, 0.1 * t, 3.0)
    assert slow.buttons[0] and not state.pressed[0]


def test_bad_settings_are_refused() -> None:
    with pytest.raises(MouseError):
        MouseConfig(press_deg=(10.0, 10.0), release_deg=(20.0, 5.0))
    with pytest.raises(MouseError):
        TablePlane((0, 0, 0), (1, 0, 0), (1, 0, 0))
    for bad in ({'press_max_residual_ratio': 0.0}, {'residual_window_s': -1.0}):
        with pytest.raises(MouseError):
            MouseConfig(**bad)
    with pytest.raises(MouseError):
        raw_mouse_values(MODEL, np.full(26, np.nan), MouseConfig())
    plane = TablePlane.from_camera_tilt(45.0, 0.6)
    assert np.allclose(np.linalg.norm(plane.normal), 1.0) and plane.normal[2] < 0
