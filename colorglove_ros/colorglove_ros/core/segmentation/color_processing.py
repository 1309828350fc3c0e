"""Another camera's colour processing, estimated from the glove's own known palette and undone
in the colour lookup table: a saturation change about the luminance (a camera that washes
colours out, or boosts them) on top of the light colour (``light.py``).

A camera's processing does not change from frame to frame, and a glove found in one frame
shows most of its colours even when it washes a few out (yellow and lime fall outside the
colour model first): the glove pixels of each frame give an estimate of the saturation
(:func:`estimate_saturation`), a running average over frames (:class:`SaturationEstimate`)
settles on the camera's, and the colour table is compiled once per settled value
(:func:`resaturated_lut`) so that classifying a frame costs no more. No ground truth, no
rclpy import.
"""
from __future__ import annotations

import numpy as np

from colorglove_ros.core.colorimetry import LUMINANCE_WEIGHTS, linear_to_srgb, srgb_to_linear
from colorglove_ros.core.segmentation.color_model import lut_index
from colorglove_ros.core.segmentation.light import colour_means, solve_light

__all__ = [
    'SATURATION_RANGE', 'SATURATION_STEP', 'SATURATION_DEADBAND_STEPS', 'WASHED_OUT_STEPS',
    'WINDOW_COLOR_SHARE', 'WASHED_OUT_MAX_SATURATION', 'PLAIN_PALETTE_STEPS',
    'saturation_matrix', 'estimate_saturation', 'resaturated_lut', 'window_colors',
    'reads_plain',
    'SaturationEstimate',
]

#: Saturation factors searched (a camera's processing, relative to the calibration's).
SATURATION_RANGE = (0.5, 2.0)
#: Step of the search and of the settled value, in natural log units (about 5 %).
SATURATION_STEP = 0.05
#: A settled value fewer steps than this below 1 is not undone: clutter in the hand's window
#: moves a plain camera's estimate a step or two, and undoing that widens every glove colour.
SATURATION_DEADBAND_STEPS = 3
#: The washed-out cameras a search for a glove the colour table misses tries, in
#: ``SATURATION_STEP`` log steps below 1 (:meth:`SaturationEstimate.trials`).
WASHED_OUT_STEPS = (4, 7, 10)
#: The largest saturation estimate of a camera that washes colours out: below the dead band.
WASHED_OUT_MAX_SATURATION = float(np.exp(-SATURATION_DEADBAND_STEPS * SATURATION_STEP))
#: A glove whose saturation estimate is at most this many ``SATURATION_STEP`` log steps below
#: 1 reads the calibration's palette (:func:`reads_plain`): a camera switched to a washed-out
#: table goes back (the band between this and ``WASHED_OUT_MAX_SATURATION`` keeps a switch).
PLAIN_PALETTE_STEPS = 1
#: A colour the search counts as shown holds at least this share of the window's glove
#: pixels (a washed-out colour leaves a few stray pixels, a glove's patch many more).
WINDOW_COLOR_SHARE = 0.01


def saturation_matrix(saturation: float) -> np.ndarray:
    """(3, 3) linear-RGB matrix scaling every colour's distance from its luminance (grey of
    the same Y) by ``saturation``: ``luma + s (rgb - luma)``; its inverse is that of
    ``1 / saturation``."""
    grey = np.outer(np.ones(3), LUMINANCE_WEIGHTS)
    return float(saturation) * np.eye(3) + (1.0 - float(saturation)) * grey


def _grid(step: float = SATURATION_STEP) -> np.ndarray:
    lo, hi = np.log(SATURATION_RANGE)
    return np.exp(np.arange(round(lo / step), round(hi / step) + 1) * step)


_GRID = _grid()
_GRID_MATRICES = np.stack([saturation_matrix(s) for s in _GRID])


def estimate_saturation(linear_rgb: np.ndarray, labels: np.ndarray,
                        reference_linear_rgb: np.ndarray, min_pixels: int = 20,
                        min_colors: int = 4) -> float | None:
    """The saturation factor (of :data:`SATURATION_RANGE`, on a ``SATURATION_STEP`` log
    grid) that best explains the glove pixels ``linear_rgb`` (..., 3) labelled ``labels``
    (0: not glove) as the calibration's reference colours (C, 3) under one light colour
    (``light.solve_light``, each colour its own shading level): the references seen through
    :func:`saturation_matrix` of the factor. None with fewer than ``min_colors`` colours of
    at least ``min_pixels`` pixels (the saturation and the light colour need several hues)."""
    ref = np.asarray(reference_linear_rgb, dtype=np.float64)
    present, counts, means = colour_means(linear_rgb, labels, len(ref), min_pixels)
    if len(present) < min_colors:
        return None
    r = ref[present]
    _, costs = solve_light(means, counts, r @ _GRID_MATRICES.transpose(0, 2, 1),
                           weight_reference=r)
    return float(_GRID[int(np.argmin(costs))])


def reads_plain(estimate: float | None) -> bool:
    """Whether a glove's saturation estimate (:func:`estimate_saturation`; None: none) reads
    the calibration's own palette: at most ``PLAIN_PALETTE_STEPS`` steps below 1."""
    return (estimate is not None
            and round(float(np.log(estimate)) / SATURATION_STEP) >= -PLAIN_PALETTE_STEPS)


def window_colors(labels: np.ndarray, found: tuple[tuple[float, float], float] | None,
                  min_share: float = WINDOW_COLOR_SHARE, min_pixels: int = 2) -> int:
    """How many glove colours the label image ``labels`` shows inside the hand's window
    ``found`` ((cx, cy), half, in its pixels; 0 for None): each with at least ``min_share``
    of the window's glove pixels and ``min_pixels`` pixels."""
    if found is None:
        return 0
    (cx, cy), half = found
    x0, y0 = max(int(cx - half), 0), max(int(cy - half), 0)
    part = labels[y0:max(int(np.ceil(cy + half)) + 1, y0), x0:max(int(np.ceil(cx + half)) + 1, x0)]
    counts = np.bincount(part.ravel(), minlength=1)[1:]
    return int(np.count_nonzero(counts >= max(min_pixels, min_share * counts.sum())))


def resaturated_lut(lut: np.ndarray, bits: int, saturation: float) -> np.ndarray:
    """The colour table ``lut`` ((2^bits)^3 labels of quantised sRGB colours,
    ``color_model.lut_index``) for a camera whose processing multiplied saturation by
    ``saturation``: each quantised colour (bin centre) gets the label of its colour with
    that saturation undone (:func:`saturation_matrix` of ``1 / saturation`` in linear RGB,
    clipped to the gamut)."""
    n = 1 << bits
    step = 256 // n
    levels = srgb_to_linear((np.arange(n) * step + (step - 1) / 2.0) / 255.0)
    grid = np.stack(np.meshgrid(levels, levels, levels, indexing='ij'), axis=-1).reshape(-1, 3)
    undone = grid @ saturation_matrix(1.0 / saturation).T
    srgb = np.round(255.0 * linear_to_srgb(undone, np.float32)).astype(np.uint8)
    return lut.take(lut_index(srgb, bits))


class SaturationEstimate:
    """One camera's saturation, settled over frames: each frame's estimate
    (:func:`estimate_saturation`, None: no estimate) moves the running log-saturation by
    ``rate`` of the way to it; :attr:`saturation` is that value on the ``SATURATION_STEP``
    grid, at most 1 and 1 within ``SATURATION_DEADBAND_STEPS`` of it (1 until a frame gave
    an estimate), and :meth:`lut` the base table
    resaturated for it (compiled once per value, the last few kept). Only a washed-out camera
    is undone: one that boosts saturation clips channels at black and white, which no
    matrix undoes (undoing it washes the clipped colours out), and its colours stay
    nearer their own hue than the calibration's, which the colour model tolerates."""

    _CACHED = 4

    def __init__(self, lut: np.ndarray, bits: int, rate: float) -> None:
        if not 0.0 < rate <= 1.0:
            raise ValueError(f'rate must be in (0, 1], got {rate}')
        self._base = lut
        self._bits = bits
        self.rate = float(rate)
        self._log = 0.0
        self._tables: dict[int, np.ndarray] = {0: lut}

    @property
    def step(self) -> int:
        """The settled saturation as a whole number of ``SATURATION_STEP`` log steps: 0, or
        at least ``SATURATION_DEADBAND_STEPS`` below it (a washed-out camera)."""
        step = int(round(self._log / SATURATION_STEP))
        return step if step <= -SATURATION_DEADBAND_STEPS else 0

    @property
    def saturation(self) -> float:
        """The settled saturation factor, at most 1 (1: the calibration's own)."""
        return float(np.exp(self.step * SATURATION_STEP))

    def trials(self) -> tuple[int, ...]:
        """The settled steps a search for a missed glove tries instead of this one: the
        calibration's own (0) and each of ``WASHED_OUT_STEPS``, the current one left out."""
        return tuple(s for s in (0, *(-k for k in WASHED_OUT_STEPS)) if s != self.step)

    def settle(self, step: int) -> None:
        """Settle on ``step`` log steps (0 or at most ``-SATURATION_DEADBAND_STEPS``): a
        search found the glove with this camera's saturation undone."""
        self._log = float(step) * SATURATION_STEP

    def update(self, estimate: float | None) -> None:
        """Move the running value towards one frame's estimate."""
        if estimate is not None and estimate > 0:
            self._log += self.rate * (float(np.log(estimate)) - self._log)

    def lut(self) -> np.ndarray:
        """The colour table for the settled saturation."""
        step = self.step
        table = self._tables.get(step)
        if table is None:
            if len(self._tables) >= self._CACHED:
                self._tables.pop(next(k for k in self._tables if k != 0))
            table = resaturated_lut(self._base, self._bits, self.saturation)
            self._tables[step] = table
        return table
