"""Colorimetry shared by the segmentation and the synthetic camera: the sRGB transfer curve,
linear sRGB <-> CIE XYZ, luminance, and black-body light colours seen through a fixed white
balance. Every value is on the 0..1 scale; callers holding bytes scale by 255 themselves."""
from __future__ import annotations

import numpy as np
from numpy.typing import DTypeLike

__all__ = [
    'SRGB_TO_XYZ', 'XYZ_TO_LINEAR_SRGB', 'LUMINANCE_WEIGHTS', 'WHITE_BALANCE_K',
    'srgb_to_linear', 'linear_to_srgb', 'linear_rgb_to_xyz', 'illuminant_rgb',
]

#: Linear sRGB (D65) -> CIE XYZ.
SRGB_TO_XYZ = np.array([[0.4124564, 0.3575761, 0.1804375],
                        [0.2126729, 0.7151522, 0.0721750],
                        [0.0193339, 0.1191920, 0.9503041]])
#: CIE XYZ -> linear sRGB (D65).
XYZ_TO_LINEAR_SRGB = np.array([[3.2404542, -1.5371385, -0.4985314],
                               [-0.9692660, 1.8760108, 0.0415560],
                               [0.0556434, -0.2040259, 1.0572252]])
#: Luminance (Y) weights of linear sRGB.
LUMINANCE_WEIGHTS = np.array([0.2126, 0.7152, 0.0722])
#: Colour temperature (kelvin) the synthetic camera is white-balanced for: looks neutral.
WHITE_BALANCE_K = 6500.0


def srgb_to_linear(srgb: np.ndarray) -> np.ndarray:
    """sRGB-encoded values in 0..1 -> linear values in 0..1 (float64; undo the gamma)."""
    c = np.asarray(srgb, dtype=np.float64)
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


def linear_to_srgb(linear: np.ndarray, dtype: DTypeLike = np.float64) -> np.ndarray:
    """Linear values in 0..1 (clipped) -> sRGB-encoded values in 0..1 (apply the gamma),
    computed and returned in ``dtype``."""
    c = np.clip(np.asarray(linear, dtype=dtype), 0.0, 1.0)
    return np.where(c <= 0.0031308, c * 12.92,
                    1.055 * np.power(c, 1.0 / 2.4, dtype=dtype) - 0.055).astype(dtype)


def linear_rgb_to_xyz(linear_rgb: np.ndarray) -> np.ndarray:
    """Linear sRGB (..., 3) -> CIE XYZ (..., 3)."""
    return np.asarray(linear_rgb, dtype=np.float64) @ SRGB_TO_XYZ.T


def _planck_xy(t: float) -> np.ndarray:
    """CIE 1931 chromaticity of a black body (Kim et al. 2002 cubic fit, 1667-25000 K)."""
    t = float(np.clip(t, 1667.0, 25000.0))
    if t <= 4000:
        x = -0.2661239e9 / t**3 - 0.2343589e6 / t**2 + 0.8776956e3 / t + 0.179910
    else:
        x = -3.0258469e9 / t**3 + 2.1070379e6 / t**2 + 0.2226347e3 / t + 0.240390
    if t <= 2222:
        y = -1.1063814 * x**3 - 1.34811020 * x**2 + 2.18555832 * x - 0.20219683
    elif t <= 4000:
        y = -0.9549476 * x**3 - 1.37418593 * x**2 + 2.09137015 * x - 0.16748867
    else:
        y = 3.0817580 * x**3 - 5.87338670 * x**2 + 3.75112997 * x - 0.37001483
    return np.array([x, y])


def _planck_rgb(t: float) -> np.ndarray:
    x, y = _planck_xy(t)
    xyz = np.array([x / y, 1.0, (1.0 - x - y) / y])
    return XYZ_TO_LINEAR_SRGB @ xyz


def illuminant_rgb(temperature_k: float, white_balance_k: float = WHITE_BALANCE_K) -> np.ndarray:
    """Linear RGB gains of a black-body light seen by a camera white-balanced for
    ``white_balance_k`` (equal gains at equal temperatures), luminance-normalised."""
    rgb = _planck_rgb(temperature_k) / _planck_rgb(white_balance_k)
    luminance = rgb @ LUMINANCE_WEIGHTS
    return rgb / luminance
