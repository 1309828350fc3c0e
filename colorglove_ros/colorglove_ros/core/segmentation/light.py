"""Light-colour correction (von Kries): estimate per-channel gains from glove pixels of known
colour, apply them to a byte image through a table, and the black-body lights the colour
calibration is re-lit under."""
from __future__ import annotations

import numpy as np

from colorglove_ros.core.colorimetry import (
    LUMINANCE_WEIGHTS,
    illuminant_rgb,
    linear_to_srgb,
    srgb_to_linear,
)
from colorglove_ros.core.errors import ColorGloveError
from colorglove_ros.core.segmentation.color_model import ColorCalibrationError
from colorglove_ros.core.segmentation.crop import compiled_kernels

__all__ = ['LIGHT_TEMPERATURES_K', 'LightEstimateError', 'colour_means', 'solve_light',
           'estimate_light_gains', 'gain_table', 'planckian_illuminants']

#: Bounds of everyday light colour, as seen through the camera's fixed white balance: from
#: 3300 K (the warm end of the 'intermediate' lamp class of EN 12464-1) to 20000 K (shade
#: under a clear blue sky, the bluest common daylight). Not the evaluation's test conditions.
LIGHT_TEMPERATURES_K = (3300.0, 20000.0)


class LightEstimateError(ColorGloveError, ValueError):
    """Pixels, labels or a light table whose shapes do not belong together."""

def _log_floored(colours: np.ndarray, floor: float = 1e-3) -> np.ndarray:
    """Log of colours (N, 3), each channel floored at ``floor`` times the colour's brightest."""
    return np.log(np.maximum(colours, floor * colours.max(axis=1, keepdims=True) + 1e-12))


def colour_means(linear_rgb: np.ndarray, labels: np.ndarray, num_colors: int,
                 min_pixels: int, table: np.ndarray | None = None
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The glove colours (0-based indices, (n,)) with at least ``min_pixels`` pixels among
    ``labels`` (...; 0 not glove, 1..``num_colors``), their pixel counts (n,) and their mean
    colours (n, 3) in ``linear_rgb`` (..., 3). With ``table`` ((256,) float32) ``linear_rgb``
    is a (H, W, 3) uint8 image and a channel's linear value is ``table`` at its byte: the
    same means as of ``table`` applied first, in one compiled pass over the (H, W) uint8
    ``labels``."""
    num = num_colors + 1
    if table is not None:
        labels = np.asarray(labels, np.uint8)
        if np.shape(linear_rgb) != (*labels.shape, 3) or np.shape(table) != (256,):
            raise LightEstimateError(
                f'colour means of a table-mapped image need a (H, W, 3) image, (H, W) labels '
                f'and a (256,) table, got {np.shape(linear_rgb)}, {labels.shape} and '
                f'{np.shape(table)}')
        counts, sums = compiled_kernels().colour_sums(linear_rgb, table, labels, num)
        counts, sums = counts[1:], sums[1:]
        present = np.flatnonzero(counts >= min_pixels)
        if not len(present):
            return present, counts[present], np.zeros((0, 3))
        return present, counts[present], sums[present] / counts[present, None]
    labels = np.asarray(labels).ravel()
    glove = np.flatnonzero(labels != 0)   # a bool array: 4x faster than on the labels
    labels = labels[glove]
    counts = np.bincount(labels, minlength=num)[1:num]
    present = np.flatnonzero(counts >= min_pixels)
    if not len(present):
        return present, counts[present], np.zeros((0, 3))
    lin = np.asarray(linear_rgb).reshape(-1, 3)[glove].T
    sums = np.stack([np.bincount(labels, channel, minlength=num)[1:num] for channel in lin],
                    axis=1)
    return present, counts[present], sums[present] / counts[present, None]


def solve_light(means: np.ndarray, counts: np.ndarray, reference: np.ndarray,
                weight_reference: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Log light colour (..., 3) (luminance-weighted mix 0) and the weighted squared residual
    (...) of the model ``means_c = s_c * light * reference_c`` (``s_c`` each colour's own
    shading level; ``means`` (n, 3), ``counts`` (n,)), solved by least squares in log space
    with each channel weighted by its share of ``weight_reference`` (n, 3; default
    ``reference``: dark channels are noise) and each colour by the square root of its pixel
    count. ``reference`` (..., n, 3) may hold several candidate reference sets (then
    ``weight_reference`` is needed), solved in one factorisation."""
    r = np.asarray(reference, dtype=np.float64)
    wr = r if weight_reference is None else np.asarray(weight_reference, dtype=np.float64)
    # unknowns: log s_c (n), log light (3); rows: (c, k) residuals + the luminance constraint
    n = r.shape[-2]
    design = np.zeros((3 * n + 1, n + 3))
    rows = np.arange(3 * n)
    design[rows, rows // 3] = 1.0
    design[rows, n + rows % 3] = 1.0
    design[-1, n:] = LUMINANCE_WEIGHTS   # the gains keep this mix of log gains at 0
    log_ratio = _log_floored(means) - _log_floored(r.reshape(-1, 3)).reshape(r.shape)
    batch = log_ratio.shape[:-2]
    target = np.concatenate([log_ratio.reshape(*batch, 3 * n),
                             np.zeros((*batch, 1))], axis=-1).reshape(-1, 3 * n + 1).T
    weight = np.append((wr / wr.max(axis=1, keepdims=True)
                        * np.sqrt(counts[:, None] / counts.max())).ravel(), 10.0) ** 2
    wd = design * weight[:, None]
    sol = np.linalg.solve(design.T @ wd, wd.T @ target)
    residual = design @ sol - target
    cost = (weight[:, None] * residual * residual).sum(axis=0)
    return sol[n:].T.reshape(*batch, 3), cost.reshape(batch)


def estimate_light_gains(linear_rgb: np.ndarray, labels: np.ndarray,
                         reference_linear_rgb: np.ndarray, min_pixels: int = 20,
                         min_colors: int = 3, max_gain: float = 2.0,
                         table: np.ndarray | None = None) -> np.ndarray:
    """Von Kries correction gains (3,) for linear RGB from glove pixels of known colour.

    ``linear_rgb`` (..., 3) are pixels (any common scale) labelled ``labels`` (...): 0 for
    not glove (ignored), 1..C for glove colours whose colours under the calibration's light
    are ``reference_linear_rgb`` (C, 3). Per colour c with at least ``min_pixels`` pixels the
    mean ``m_c`` is modelled as ``s_c * light * reference_c`` (``s_c`` its own shading
    level; :func:`solve_light`). Returns ``1 / light`` normalised to
    luminance 1 (a colour, not a level, correction) and clipped to
    ``1/max_gain .. max_gain``; ones with fewer than ``min_colors`` colours. ``table``: as
    :func:`colour_means`'s (``linear_rgb`` the uint8 image it maps).
    """
    ref = np.asarray(reference_linear_rgb, dtype=np.float64)
    present, counts, means = colour_means(linear_rgb, labels, len(ref), min_pixels, table)
    if len(present) < min_colors:
        return np.ones(3)
    log_light, _ = solve_light(means, counts, ref[present])
    return np.clip(np.exp(-log_light), 1.0 / max_gain, max_gain)


#: sRGB byte -> linear RGB (0..1), and a fine table of linear RGB -> sRGB byte.
_SRGB_TO_LINEAR = srgb_to_linear(np.arange(256) / 255.0)
_LINEAR_STEPS = 4096
_LINEAR_TO_SRGB = np.round(255.0 * linear_to_srgb(np.arange(_LINEAR_STEPS + 1) / _LINEAR_STEPS)
                           ).astype(np.uint8)


def gain_table(gains: np.ndarray) -> np.ndarray:
    """(1, 256, 3) uint8 table for ``cv2.LUT`` that multiplies the linear RGB of an sRGB image
    by ``gains`` (3,) per channel (clipping at white)."""
    lin = _SRGB_TO_LINEAR[:, None] * np.asarray(gains, dtype=np.float64)[None, :]
    steps = np.minimum(np.rint(lin * _LINEAR_STEPS), _LINEAR_STEPS).astype(np.intp)
    return _LINEAR_TO_SRGB[steps][None]


def planckian_illuminants(low_k: float, high_k: float, count: int = 32) -> np.ndarray:
    """Linear RGB gains (count, 3) of black-body lights from ``low_k`` to ``high_k`` kelvin
    (evenly spaced in mired, 1e6 / T, the scale on which equal steps look alike) as a camera
    white-balanced like the synthetic one sees them (:func:`illuminant_rgb`)."""
    if not 1000.0 <= low_k <= high_k:
        raise ColorCalibrationError(
            f'need 1000 K <= low <= high colour temperature, got {low_k}, {high_k}')
    mired = np.linspace(1e6 / low_k, 1e6 / high_k, count)
    return np.array([illuminant_rgb(1e6 / m) for m in mired])
