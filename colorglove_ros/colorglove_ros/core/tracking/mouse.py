"""The DigitEyes 3-D mouse (Rehg & Kanade 1993, section 6.1): a hand on a table drives a
3-D cursor and two buttons.

Mapping (all lengths in metres, in the calibrated table frame):

* the table plane is given by an origin and two in-plane unit axes in the camera's optical
  frame (:class:`TablePlane`; its normal ``x_axis x y_axis`` points up, away from the table);
* cursor x, y = the palm centre (mean of the wrist and the four finger MCP joints) expressed
  in the plane's axes, times ``plane_gain``;
* cursor z = the height of the index fingertip above the plane, minus ``index_rest_height_m``
  (the height of the fingertip when the hand rests flat), clipped at 0, times ``height_gain``;
* button 0 = thumb abduction (``thumb_cmc_abd``), button 1 = little-finger abduction away
  from the hand (``-little_mcp_abd``, at most 15 degrees in the hand model): button k goes
  down when its angle rises above ``press_deg[k]`` and up when it falls below
  ``release_deg[k]`` (hysteresis);
* the cursor and the two angles are smoothed by a first-order low-pass filter with time
  constant ``smoothing_s`` (0 = none), stepped by the messages' stamps; a gap longer than
  ``max_gap_s`` restarts the filter and releases the buttons;
* a press needs evidence (``press_max_residual_ratio``, off by default): given the tracker's
  fit residual of each pose (e.g. the edge tracker's edge residual), a button may go down only
  on a pose whose residual is at most that many times the median residual of the poses of the
  last ``residual_window_s`` before it (a drifted fit explains its frame worse than the
  track usually does); unknown residuals (NaN, or no earlier pose) never hold a press back,
  and a button already down is released as usual.
"""
from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, field

import numpy as np

from colorglove_ros.core.errors import ColorGloveError
from colorglove_ros.core.hand.model import DOF_NAMES, KEYPOINT_NAMES, NUM_DOFS, HandModel

__all__ = ['MouseError', 'TablePlane', 'MouseConfig', 'MouseState', 'Mouse3D', 'BUTTON_NAMES',
           'BUTTON_DOFS', 'palm_centre', 'raw_mouse_values']

BUTTON_NAMES: tuple[str, ...] = ('thumb', 'little')
BUTTON_DOFS: tuple[str, ...] = ('thumb_cmc_abd', 'little_mcp_abd')   # the joints they read
_PALM_KEYPOINTS = [KEYPOINT_NAMES.index(n) for n in
                   ('wrist', 'index_mcp', 'middle_mcp', 'ring_mcp', 'little_mcp')]
_INDEX_TIP = KEYPOINT_NAMES.index('index_tip')
_THUMB_ABD, _LITTLE_ABD = (DOF_NAMES.index(n) for n in BUTTON_DOFS)


class MouseError(ColorGloveError):
    """Bad 3-D mouse input: table plane, thresholds or pose."""


@dataclass(frozen=True)
class TablePlane:
    """The table in the camera's optical frame: a point on it and two orthonormal in-plane
    axes (the cursor's x and y)."""

    origin: tuple[float, float, float]
    x_axis: tuple[float, float, float]
    y_axis: tuple[float, float, float]

    def __post_init__(self) -> None:
        x, y = np.asarray(self.x_axis, float), np.asarray(self.y_axis, float)
        if np.asarray(self.origin).shape != (3,) or x.shape != (3,) or y.shape != (3,):
            raise MouseError('table origin and axes need 3 values each')
        if abs(np.linalg.norm(x) - 1) > 1e-6 or abs(np.linalg.norm(y) - 1) > 1e-6 \
                or abs(x @ y) > 1e-6:
            raise MouseError('table x_axis and y_axis must be orthonormal')

    @property
    def normal(self) -> np.ndarray:
        """Unit normal ``x_axis x y_axis`` (up, away from the table)."""
        return np.cross(self.x_axis, self.y_axis)

    def to_plane(self, points: np.ndarray) -> np.ndarray:
        """(..., 3) camera-frame points -> (..., 3) plane coordinates (x, y, height)."""
        d = np.asarray(points, float) - np.asarray(self.origin, float)
        return np.stack([d @ np.asarray(self.x_axis, float), d @ np.asarray(self.y_axis, float),
                         d @ self.normal], axis=-1)

    @classmethod
    def from_camera_tilt(cls, tilt_deg: float, distance_m: float) -> TablePlane:
        """The table seen by a camera looking down at it ``tilt_deg`` from the vertical
        (DigitEyes used about 45), the optical axis meeting the table ``distance_m`` away;
        the cursor's x runs along the image rows, y away from the camera."""
        t = math.radians(tilt_deg)
        # camera frame: x right, y down, z forward; the table normal points up-and-back
        up = np.array([0.0, -math.sin(t), -math.cos(t)])
        x_axis = np.array([1.0, 0.0, 0.0])
        y_axis = np.cross(up, x_axis)
        return cls(tuple(float(v) for v in (0.0, 0.0, distance_m)),
                   tuple(float(v) for v in x_axis), tuple(float(v) for v in y_axis))


@dataclass(frozen=True)
class MouseConfig:
    """Mapping gains, button thresholds (degrees) and smoothing (see the module docstring)."""

    plane: TablePlane = field(default_factory=lambda: TablePlane.from_camera_tilt(45.0, 0.6))
    plane_gain: float = 1.0
    height_gain: float = 1.0
    index_rest_height_m: float = 0.0
    press_deg: tuple[float, float] = (25.0, 10.0)
    release_deg: tuple[float, float] = (15.0, 5.0)
    smoothing_s: float = 0.05
    max_gap_s: float = 0.5
    press_max_residual_ratio: float = math.inf
    residual_window_s: float = 2.0

    def __post_init__(self) -> None:
        if len(self.press_deg) != 2 or len(self.release_deg) != 2 or not all(
                r < p for r, p in zip(self.release_deg, self.press_deg, strict=True)):
            raise MouseError(f'release_deg {self.release_deg} must be below press_deg '
                             f'{self.press_deg}, one value per button')
        if self.smoothing_s < 0 or self.max_gap_s <= 0:
            raise MouseError('smoothing_s must be >= 0 and max_gap_s > 0')
        if not self.press_max_residual_ratio > 0 or not self.residual_window_s > 0:
            raise MouseError('press_max_residual_ratio and residual_window_s must be > 0')


@dataclass(frozen=True)
class MouseState:
    """One output: cursor (x, y, z) in the table frame, the buttons (thumb, little) and
    which of them went down or up at this update."""

    cursor: np.ndarray
    buttons: tuple[bool, bool]
    pressed: tuple[bool, bool]
    released: tuple[bool, bool]


def palm_centre(keypoints: np.ndarray) -> np.ndarray:
    """Mean of the wrist and the four finger MCP keypoints, (21, 3) -> (3,)."""
    return np.asarray(keypoints)[_PALM_KEYPOINTS].mean(axis=0)


def raw_mouse_values(model: HandModel, q: np.ndarray, config: MouseConfig) -> np.ndarray:
    """Unsmoothed (cursor x, y, z, thumb abduction deg, little abduction deg) of pose q."""
    q = np.asarray(q, dtype=float)
    if q.shape != (NUM_DOFS,) or not np.all(np.isfinite(q)):
        raise MouseError(f'pose must be 26 finite numbers, got shape {q.shape}')
    kp = model.keypoints(q)
    plane = config.plane.to_plane(np.stack([palm_centre(kp), kp[_INDEX_TIP]]))
    height = max(plane[1, 2] - config.index_rest_height_m, 0.0)
    return np.array([plane[0, 0] * config.plane_gain, plane[0, 1] * config.plane_gain,
                     height * config.height_gain, math.degrees(q[_THUMB_ABD]),
                     -math.degrees(q[_LITTLE_ABD])])


class Mouse3D:
    """Pose stream -> smoothed cursor and hysteresis buttons."""

    def __init__(self, model: HandModel, config: MouseConfig | None = None) -> None:
        self.model = model
        self.config = config or MouseConfig()
        self._filtered: np.ndarray | None = None
        self._stamp: float | None = None
        self._buttons = [False, False]
        self._residuals: deque[tuple[float, float]] = deque()   # (stamp, residual px)

    def reset(self) -> None:
        """Forget the filter state and the residuals seen, release the buttons."""
        self._filtered = None
        self._stamp = None
        self._buttons = [False, False]
        self._residuals.clear()

    @property
    def buttons(self) -> tuple[bool, bool]:
        """Current button states (thumb, little)."""
        return self._buttons[0], self._buttons[1]

    def _press_allowed(self, residual_px: float, stamp: float) -> bool:
        """Whether a pose of fit residual ``residual_px`` at ``stamp`` may press a button
        (``press_max_residual_ratio``); records the residual for the later poses."""
        cfg = self.config
        window = self._residuals
        while window and not 0.0 <= stamp - window[0][0] <= cfg.residual_window_s:
            window.popleft()
        allowed = True
        if math.isfinite(residual_px) and window and cfg.press_max_residual_ratio < math.inf:
            allowed = residual_px <= cfg.press_max_residual_ratio * float(
                np.median([r for _, r in window]))
        if math.isfinite(residual_px):
            window.append((stamp, residual_px))
        return allowed

    def update(self, q: np.ndarray, stamp: float, residual_px: float = math.nan
               ) -> MouseState:
        """Feed one hand pose (camera frame) at time ``stamp`` (seconds), with the
        tracker's fit residual of it if known (``press_max_residual_ratio``)."""
        cfg = self.config
        raw = raw_mouse_values(self.model, q, cfg)
        may_press = self._press_allowed(residual_px, stamp)
        before = tuple(self._buttons)
        gap = None if self._stamp is None else stamp - self._stamp
        if gap is None or not 0.0 <= gap <= cfg.max_gap_s or self._filtered is None:
            self._filtered = raw
            self._buttons = [False, False]
            before = (False, False)
        else:
            a = 1.0 if cfg.smoothing_s <= 0 else 1.0 - math.exp(-gap / cfg.smoothing_s)
            self._filtered = self._filtered + a * (raw - self._filtered)
        self._stamp = stamp
        for k, angle in enumerate(self._filtered[3:5]):
            if not self._buttons[k] and angle > cfg.press_deg[k] and may_press:
                self._buttons[k] = True
            elif self._buttons[k] and angle < cfg.release_deg[k]:
                self._buttons[k] = False
        now = self.buttons
        return MouseState(self._filtered[0:3].copy(), now,
                          tuple(n and not b for n, b in zip(now, before, strict=True)),
                          tuple(b and not n for n, b in zip(now, before, strict=True)))
