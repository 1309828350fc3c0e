"""Mean-shift glove crop and label-preserving scaling to 40x40 tiny images."""
from __future__ import annotations

from dataclasses import dataclass
from types import ModuleType

import cv2
import numpy as np

from colorglove_ros.core.conventions import TINY_SIZE
from colorglove_ros.core.errors import ColorGloveError

__all__ = [
    'CROP_ALGORITHM_VERSION', 'crop_signature',
    'CropError', 'CropTransform', 'tiny_to_full', 'TinyCrop', 'mean_shift_crop', 'crop_to_tiny',
    'crop_window', 'DEFAULT_BANDWIDTH_FACTOR', 'DEFAULT_MIN_PIXELS', 'DEFAULT_GLOVE_FRACTION',
    'DEFAULT_RESCUE_SHARE', 'DEFAULT_INITIAL_BANDWIDTH_FACTOR', 'compiled_kernels',
]

DEFAULT_BANDWIDTH_FACTOR = 2.5
DEFAULT_INITIAL_BANDWIDTH_FACTOR = 2.0
DEFAULT_MIN_PIXELS = 20
DEFAULT_GLOVE_FRACTION = 0.4
DEFAULT_RESCUE_SHARE = 0.2
#: Bump when the crop algorithm changes: pose databases record it and are refused when it differs.
CROP_ALGORITHM_VERSION = 2


def crop_signature() -> dict[str, float]:
    """The crop algorithm version and default parameters. A pose database stores this and is
    refused if it differs, since both sides of the lookup must be normalised identically."""
    return {'version': CROP_ALGORITHM_VERSION, 'tiny_size': TINY_SIZE,
            'bandwidth_factor': DEFAULT_BANDWIDTH_FACTOR,
            'initial_bandwidth_factor': DEFAULT_INITIAL_BANDWIDTH_FACTOR,
            'min_pixels': DEFAULT_MIN_PIXELS, 'glove_fraction': DEFAULT_GLOVE_FRACTION,
            'rescue_share': DEFAULT_RESCUE_SHARE}


class CropError(ColorGloveError, ValueError):
    """The input of a crop function has the wrong type, shape or parameters."""


def tiny_to_full(tiny_xy: np.ndarray, scale: float, offset_x: float,
                 offset_y: float) -> np.ndarray:
    """Tiny-image points (..., 2) -> full-image points (..., 2), ``full = offset + scale *
    tiny`` (pixel centres, (x, y)): the mapping of a :class:`CropTransform`."""
    xy = np.asarray(tiny_xy, dtype=np.float64)
    return xy * scale + np.array([offset_x, offset_y])


@dataclass(frozen=True)
class CropTransform:
    """Maps tiny-image pixel centres to full-image pixel centres: ``full = offset + scale * tiny``.

    Both coordinates are (column x, row y) with the origin at the centre of the top-left pixel.
    """

    scale: float
    offset_x: float
    offset_y: float

    def to_full(self, tiny_xy: np.ndarray) -> np.ndarray:
        """Tiny-image points (..., 2) -> full-image points (..., 2)."""
        return tiny_to_full(tiny_xy, self.scale, self.offset_x, self.offset_y)

    def to_tiny(self, full_xy: np.ndarray) -> np.ndarray:
        """Full-image points (..., 2) -> tiny-image points (..., 2)."""
        xy = np.asarray(full_xy, dtype=np.float64)
        return (xy - np.array([self.offset_x, self.offset_y])) / self.scale

    @property
    def half_size(self) -> float:
        """Half the side of the square crop window in full-image pixels."""
        return 0.5 * self.scale * TINY_SIZE

    @property
    def center_xy(self) -> tuple[float, float]:
        """Centre of the crop window in full-image pixels."""
        c = 0.5 * (TINY_SIZE - 1)
        return (self.offset_x + self.scale * c, self.offset_y + self.scale * c)

    @classmethod
    def from_window(cls, center_xy: tuple[float, float], half_size: float,
                    size: int = TINY_SIZE) -> CropTransform:
        """The transform of the square window ``center +- half_size`` split into size^2 cells."""
        scale = 2.0 * float(half_size) / size
        return cls(scale=scale, offset_x=float(center_xy[0]) - half_size + 0.5 * scale,
                   offset_y=float(center_xy[1]) - half_size + 0.5 * scale)


@dataclass(frozen=True)
class TinyCrop:
    """A 40x40 label image and the transform from its pixels to the full image."""

    labels: np.ndarray
    transform: CropTransform


def _as_mask(image: np.ndarray) -> np.ndarray:
    arr = np.asarray(image)
    if arr.ndim != 2:
        raise CropError(f'expected a 2-D mask or label image, got shape {arr.shape}')
    if arr.size == 0:
        raise CropError(f'empty image of shape {arr.shape}')
    return arr != 0


def compiled_kernels() -> ModuleType:
    """The segmentation's compiled per-pixel kernels (:mod:`segmentation_kernel`): numba is
    imported, and the kernels compiled or loaded from their on-disk cache, on the first call
    (so importing this module, or the light modules that import it, loads no numba)."""
    from colorglove_ros.core.segmentation import segmentation_kernel

    segmentation_kernel.compile_kernels()
    return segmentation_kernel


def _window_bounds(c: float, h: float, n: int) -> tuple[int, int]:
    """Integer index range [lo, hi) of pixel centres within c +- h, clipped to [0, n)."""
    lo = max(int(np.ceil(c - h)), 0)
    hi = min(int(np.floor(c + h)) + 1, n)
    return lo, hi


def mean_shift_crop(mask: np.ndarray, bandwidth_factor: float = DEFAULT_BANDWIDTH_FACTOR,
                    min_pixels: int = DEFAULT_MIN_PIXELS, max_iterations: int = 50,
                    tolerance: float = 0.05, min_half_size: float = 2.0,
                    initial_bandwidth_factor: float = DEFAULT_INITIAL_BANDWIDTH_FACTOR,
                    start: tuple[tuple[float, float], float] | None = None,
                    ) -> tuple[tuple[float, float], float] | None:
    """Find the glove by mean-shift with a uniform square kernel of variable bandwidth.

    ``mask`` is a boolean mask or a label image (nonzero = glove). Starts at the image
    centre with a window spanning the whole image; each iteration moves the centre to the
    mean of the glove pixels inside the window and sets the next half-width to a factor times
    their (larger per-axis) standard deviation, until the centre and half-width change by
    less than ``tolerance`` pixels. The factor is ``initial_bandwidth_factor`` until
    convergence (a tight window that sheds outlying blobs), then ``bandwidth_factor`` until
    convergence again (grows the window over the fingers). ``start`` ((cx, cy), half) starts
    from that window instead (where the hand is expected). Returns ``((cx, cy), half_size)``
    in full-image pixels, or None when fewer than ``min_pixels`` glove pixels end up inside.
    """
    m = _as_mask(mask)
    if bandwidth_factor <= 0.0 or initial_bandwidth_factor <= 0.0:
        raise CropError(f'bandwidth factors must be positive, got {initial_bandwidth_factor}, '
                        f'{bandwidth_factor}')
    H, W = m.shape
    # Summed-area table: the moments of a box cost O(W + H) per iteration.
    sat = cv2.integral(m.view(np.uint8), sdepth=cv2.CV_32S)
    if sat[H, W] < min_pixels:
        return None
    cx, cy = 0.5 * (W - 1), 0.5 * (H - 1)
    h = 0.5 * max(W, H)
    if start is not None:
        (cx, cy), h = start
    factors = (initial_bandwidth_factor, bandwidth_factor) \
        if initial_bandwidth_factor != bandwidth_factor else (bandwidth_factor,)
    found, cx, cy, h = compiled_kernels().mean_shift(
        sat, float(cx), float(cy), float(h), np.array(factors, np.float64), int(min_pixels),
        int(max_iterations), float(tolerance), float(min_half_size))
    if not found:
        return None
    return (cx, cy), h


def crop_window(labels: np.ndarray, transform: CropTransform,
                glove_fraction: float = DEFAULT_GLOVE_FRACTION, size: int = TINY_SIZE,
                rescue_share: float = DEFAULT_RESCUE_SHARE) -> np.ndarray:
    """Resample a label image into the ``size x size`` grid of ``transform``, keeping labels.

    Every full-image pixel votes for the cell containing its centre. A cell is glove when at
    least ``glove_fraction`` of its in-image pixels are glove, and then takes the most frequent
    glove label (ties to the lower label); otherwise it is background (0). A glove colour that
    thereby vanishes from the grid is given back the one cell where it holds its largest share
    of pixels, if that share is at least ``rescue_share`` (keeps thin patches). Cells that contain
    no pixel centre (upsampling) take the label of the pixel nearest to the cell centre; pixels
    outside the image count as background.
    """
    lab = np.asarray(labels)
    if lab.ndim != 2 or lab.size == 0:
        raise CropError(f'expected a non-empty 2-D label image, got shape {lab.shape}')
    if lab.dtype != np.uint8:
        lab = lab.astype(np.uint8) if lab.dtype == np.bool_ else np.clip(lab, 0, 255).astype(
            np.uint8)
    H, W = lab.shape
    s = transform.scale
    if not s > 0.0:
        raise CropError(f'crop scale must be positive, got {s}')
    left = transform.offset_x - 0.5 * s
    top = transform.offset_y - 0.5 * s
    x0, x1 = _window_bounds(left + 0.5 * size * s, 0.5 * size * s, W)
    y0, y1 = _window_bounds(top + 0.5 * size * s, 0.5 * size * s, H)
    ncell = size * size
    counts = np.zeros((2, ncell), dtype=np.intp)   # (label, cell): rows are contiguous
    if x1 > x0 and y1 > y0:
        cell_x = np.floor((np.arange(x0, x1) - left) / s).astype(np.intp)
        cell_y = np.floor((np.arange(y0, y1) - top) / s).astype(np.intp)
        # Cells are monotonic in the pixel index: keep the contiguous run inside the grid.
        kx0, kx1 = np.searchsorted(cell_x, 0), np.searchsorted(cell_x, size)
        ky0, ky1 = np.searchsorted(cell_y, 0), np.searchsorted(cell_y, size)
        sub = lab[y0 + ky0:y0 + ky1, x0 + kx0:x0 + kx1]
        if sub.size:
            counts = compiled_kernels().cell_votes(sub, cell_y[ky0:ky1], cell_x[kx0:kx1], size,
                                                   max(int(sub.max()) + 1, 2))
    # the votes' majority and the thin patches' rescue, compiled
    out = compiled_kernels().cell_labels(counts, float(glove_fraction), float(rescue_share))
    total = counts.sum(axis=0)
    empty = total == 0
    if np.any(empty):
        idx = np.nonzero(empty)[0]
        tx = transform.offset_x + s * (idx % size)
        ty = transform.offset_y + s * (idx // size)
        px = np.floor(tx + 0.5).astype(np.int64)
        py = np.floor(ty + 0.5).astype(np.int64)
        inside = (px >= 0) & (px < W) & (py >= 0) & (py < H)
        vals = np.zeros(idx.shape, dtype=np.int64)
        vals[inside] = lab[py[inside], px[inside]]
        out[idx] = vals
    return out.reshape(size, size).astype(np.uint8)


def crop_to_tiny(label_image: np.ndarray, bandwidth_factor: float = DEFAULT_BANDWIDTH_FACTOR,
                 min_pixels: int = DEFAULT_MIN_PIXELS,
                 glove_fraction: float = DEFAULT_GLOVE_FRACTION,
                 start: tuple[tuple[float, float], float] | None = None) -> TinyCrop | None:
    """Crop the glove with :func:`mean_shift_crop` and scale the square to a 40x40 tiny image.

    ``label_image`` is (H, W) uint8 (0 = background, 1..10 = glove colours). Deterministic;
    the database builder and the camera pipeline both call this. None if too few glove pixels.
    ``start``: the mean shift's first window (:func:`mean_shift_crop`; default the image).
    """
    result = mean_shift_crop(label_image, bandwidth_factor=bandwidth_factor,
                             min_pixels=min_pixels, start=start)
    if result is None:
        return None
    center, half = result
    transform = CropTransform.from_window(center, half)
    tiny = crop_window(label_image, transform, glove_fraction=glove_fraction)
    return TinyCrop(labels=tiny, transform=transform)
