"""Glove segmentation of camera frames: colour lookup, bilateral filter, crop, tiny image, blobs."""
from __future__ import annotations

import time
from dataclasses import dataclass, field

import cv2
import numpy as np

from .colorspace import ColorCalibration, load_calibration, read_calibration_config
from .crop import TINY_SIZE, CropTransform, crop_to_tiny, mean_shift_crop

__all__ = [
    'SegmentationInputError', 'SegmentationConfigError', 'Blob', 'Observation', 'GloveSegmenter',
    'STATUS_OK',
    'STATUS_NO_GLOVE', 'STATUS_TOO_SMALL', 'STATUS_OUT_OF_FRAME', 'STAGES', 'load_segmenter',
    'keep_multicolor_components',
]

STATUS_OK = 'ok'
STATUS_NO_GLOVE = 'no_glove'          # (almost) no glove-coloured pixels in the frame
STATUS_TOO_SMALL = 'too_small'        # glove found but too few pixels for a tiny image
STATUS_OUT_OF_FRAME = 'out_of_frame'  # the crop window lies mostly outside the image
#: Timed stages, in pipeline order (``Observation.timings_ms`` also has ``'total'``).
STAGES = ('coarse', 'filter', 'classify', 'cleanup', 'crop', 'blobs')


class SegmentationInputError(ValueError):
    """The image given to the segmenter is not a non-empty (H, W, 3) uint8 array."""


class SegmentationConfigError(ValueError):
    """Bad segmenter settings (unknown key or out-of-range value)."""


@dataclass(frozen=True)
class Blob:
    """One connected component of one glove colour, in full-image pixels."""

    color_label: int
    centroid_x: float
    centroid_y: float
    pixel_count: int


@dataclass
class Observation:
    """What the segmenter saw in one frame."""

    hand_found: bool
    status: str
    image_width: int
    image_height: int
    tiny_labels: np.ndarray | None = None   # (40, 40) uint8 whenever a crop was made
    crop: CropTransform | None = None       # tiny -> full image pixels (or None)
    blobs: list[Blob] = field(default_factory=list)
    glove_pixel_count: int = 0              # glove pixels inside the crop (full-res units)
    timings_ms: dict[str, float] = field(default_factory=dict)
    label_image: np.ndarray | None = None   # (H, W) uint8, only with keep_labels=True


def keep_multicolor_components(labels: np.ndarray, min_colors: int = 3,
                               min_share: float = 0.03, min_pixels: int = 4) -> np.ndarray:
    """Zero every 8-connected glove component with fewer than ``min_colors`` colours each
    holding at least ``min_share`` of its pixels (and ``min_pixels``). The printed glove shows
    many colours side by side; glove-coloured clutter and noise specks show one or two."""
    mask = (labels > 0).view(np.uint8) if labels.dtype == np.bool_ else (labels > 0).astype(
        np.uint8)
    n, comp = cv2.connectedComponents(mask, connectivity=8, ltype=cv2.CV_32S)
    if n <= 1:
        return labels
    nl = int(labels.max()) + 1
    hist = np.bincount((comp * nl + labels).ravel(), minlength=n * nl).reshape(n, nl)[:, 1:]
    size = hist.sum(axis=1, keepdims=True)
    big = (hist >= np.maximum(min_share * size, min_pixels)).sum(axis=1)
    keep = big >= min_colors
    keep[0] = True
    if keep.all():
        return labels
    return np.where(keep[comp], labels, 0).astype(np.uint8)


def _check_image(image: object) -> np.ndarray:
    if not isinstance(image, np.ndarray):
        raise SegmentationInputError(f'expected a numpy array, got {type(image).__name__}')
    if image.dtype != np.uint8:
        raise SegmentationInputError(f'expected dtype uint8, got {image.dtype}')
    if image.ndim != 3 or image.shape[2] != 3:
        raise SegmentationInputError(f'expected shape (H, W, 3), got {image.shape}')
    if image.shape[0] == 0 or image.shape[1] == 0:
        raise SegmentationInputError(f'empty image of shape {image.shape}')
    return image


class GloveSegmenter:
    """Turns RGB camera frames into :class:`Observation` s (paper section 4.3).

    Pipeline: a coarse pass (area-downsampled frame, table lookup, median, mean-shift) finds
    the glove; only a region around it (``roi_margin`` times the coarse window, reduced so
    the crop spans at most ``max_roi_cells`` pixels) is bilateral-filtered, classified at
    (near) full resolution and cleaned with a median filter; :func:`crop_to_tiny` there gives
    the tiny image and crop; connected components per colour give the blobs.
    """

    def __init__(self, calibration: ColorCalibration, *, coarse_factor: int = 4,
                 roi_margin: float = 1.5, max_roi_cells: int = 160,
                 bilateral_diameter: int = 5, bilateral_sigma_color: float = 30.0,
                 bilateral_sigma_space: float = 3.0, median_size: int = 3,
                 min_glove_pixels: int = 300, min_inside_fraction: float = 0.5,
                 min_blob_pixels: int = 12, min_component_colors: int = 3) -> None:
        if coarse_factor < 1 or max_roi_cells < TINY_SIZE or roi_margin < 1.0:
            raise SegmentationConfigError(
                f'need coarse_factor >= 1, max_roi_cells >= {TINY_SIZE}, roi_margin >= 1; got '
                f'{coarse_factor}, {max_roi_cells}, {roi_margin}')
        self.calibration = calibration
        self.coarse_factor = int(coarse_factor)
        self.roi_margin = float(roi_margin)
        self.max_roi_cells = int(max_roi_cells)
        self.bilateral_diameter = int(bilateral_diameter)
        self.bilateral_sigma_color = float(bilateral_sigma_color)
        self.bilateral_sigma_space = float(bilateral_sigma_space)
        self.median_size = int(median_size)
        self.min_glove_pixels = int(min_glove_pixels)
        self.min_inside_fraction = float(min_inside_fraction)
        self.min_blob_pixels = int(min_blob_pixels)
        self.min_component_colors = int(min_component_colors)

    # ------------------------------------------------------------------ helpers
    def _coarse(self, image: np.ndarray) -> tuple[tuple[float, float], float] | None:
        f = self.coarse_factor
        h, w = image.shape[:2]
        if f > 1 and h >= 2 * f and w >= 2 * f:
            small = cv2.resize(image, (w // f, h // f), interpolation=cv2.INTER_LINEAR)
            sx, sy = w / (w // f), h / (h // f)
        else:
            small, sx, sy = image, 1.0, 1.0
        labels = self.calibration.classify(small)
        if self.median_size > 1 and min(labels.shape) >= self.median_size:
            labels = cv2.medianBlur(labels, self.median_size)
        if self.min_component_colors > 1:
            labels = keep_multicolor_components(labels, self.min_component_colors, min_pixels=2)
        min_px = max(int(self.min_glove_pixels / (sx * sy)), 1)
        found = mean_shift_crop(labels, min_pixels=min_px)
        if found is None:
            return None
        (cx, cy), half = found
        # small pixel u covers full pixels [u * s, (u + 1) * s): centre (u + 0.5) s - 0.5
        return ((cx + 0.5) * sx - 0.5, (cy + 0.5) * sy - 0.5), half * max(sx, sy)

    def _blobs(self, labels: np.ndarray, r: int, x0: int, y0: int,
               window: tuple[int, int, int, int]) -> list[Blob]:
        """Connected components of each colour inside ``window`` (ROI pixel bounds)."""
        wx0, wx1, wy0, wy1 = window
        sub = labels[wy0:wy1, wx0:wx1]
        blobs: list[Blob] = []
        min_px = max(int(np.ceil(self.min_blob_pixels / (r * r))), 1)
        counts = np.bincount(sub.ravel(), minlength=self.calibration.num_colors + 1)
        for c in np.flatnonzero(counts >= min_px):
            if c == 0:
                continue
            m = sub == c
            rows = np.flatnonzero(m.any(axis=1))
            cols = np.flatnonzero(m.any(axis=0))
            bx, by = int(cols[0]), int(rows[0])
            box = m[by:int(rows[-1]) + 1, bx:int(cols[-1]) + 1].view(np.uint8)
            n, _, stats, cents = cv2.connectedComponentsWithStats(box, connectivity=8)
            for k in range(1, n):
                area = int(stats[k, cv2.CC_STAT_AREA])
                if area < min_px:
                    continue
                fx = x0 + r * (cents[k, 0] + bx + wx0) + 0.5 * (r - 1)
                fy = y0 + r * (cents[k, 1] + by + wy0) + 0.5 * (r - 1)
                blobs.append(Blob(int(c), float(fx), float(fy), area * r * r))
        return blobs

    def classify_full(self, image_rgb: np.ndarray) -> np.ndarray:
        """Filter, classify and clean a whole frame at full resolution (as :meth:`process`
        does inside its region of interest); for evaluation and debug images."""
        image = _check_image(image_rgb)
        if self.bilateral_diameter > 0 and min(image.shape[:2]) > self.bilateral_diameter:
            image = cv2.bilateralFilter(np.ascontiguousarray(image), self.bilateral_diameter,
                                        self.bilateral_sigma_color, self.bilateral_sigma_space)
        labels = self.calibration.classify(image)
        if self.median_size > 1 and min(labels.shape) >= self.median_size:
            labels = cv2.medianBlur(labels, self.median_size)
        return labels

    # ------------------------------------------------------------------ main entry
    def process(self, image_rgb: np.ndarray, keep_labels: bool = False) -> Observation:
        """Segment one (H, W, 3) uint8 RGB frame. Never raises on such a frame; raises
        :class:`SegmentationInputError` on anything else."""
        image = _check_image(image_rgb)
        t0 = time.perf_counter()
        h, w = image.shape[:2]
        timings: dict[str, float] = {}
        obs = Observation(False, STATUS_NO_GLOVE, w, h, timings_ms=timings)

        def tick(stage: str, t: float) -> float:
            now = time.perf_counter()
            timings[stage] = (now - t) * 1e3
            return now

        coarse = self._coarse(image)
        t = tick('coarse', t0)
        if coarse is None:
            timings['total'] = (time.perf_counter() - t0) * 1e3
            return obs
        (ccx, ccy), chalf = coarse
        # Region of interest around the coarse window, at an integer reduction r.
        rhalf = chalf * self.roi_margin
        x0, x1 = max(int(np.floor(ccx - rhalf)), 0), min(int(np.ceil(ccx + rhalf)) + 1, w)
        y0, y1 = max(int(np.floor(ccy - rhalf)), 0), min(int(np.ceil(ccy + rhalf)) + 1, h)
        r = max(1, int(np.floor(2.0 * chalf / self.max_roi_cells)))
        x1 = x0 + max((x1 - x0) // r, 1) * r
        y1 = y0 + max((y1 - y0) // r, 1) * r
        roi = image[y0:y1, x0:x1]
        if r > 1:
            roi = cv2.resize(roi, ((x1 - x0) // r, (y1 - y0) // r),
                             interpolation=cv2.INTER_AREA)
        if self.bilateral_diameter > 0 and min(roi.shape[:2]) > self.bilateral_diameter:
            roi = cv2.bilateralFilter(np.ascontiguousarray(roi), self.bilateral_diameter,
                                      self.bilateral_sigma_color, self.bilateral_sigma_space)
        t = tick('filter', t)
        labels = self.calibration.classify(roi)
        t = tick('classify', t)
        if self.median_size > 1 and min(labels.shape) >= self.median_size:
            labels = cv2.medianBlur(labels, self.median_size)
        if self.min_component_colors > 1:
            labels = keep_multicolor_components(labels, self.min_component_colors,
                                                min_pixels=max(self.min_blob_pixels // (r * r), 2))
        t = tick('cleanup', t)
        if keep_labels:
            full = np.zeros((h, w), np.uint8)
            up = labels if r == 1 else np.repeat(np.repeat(labels, r, 0), r, 1)
            full[y0:y0 + up.shape[0], x0:x0 + up.shape[1]] = up
            obs.label_image = full
        min_px = max(int(self.min_glove_pixels / (r * r)), 1)
        tiny = crop_to_tiny(labels, min_pixels=min_px)
        t = tick('crop', t)
        if tiny is None:
            obs.status = STATUS_TOO_SMALL
            timings['total'] = (time.perf_counter() - t0) * 1e3
            return obs
        tr = tiny.transform
        crop = CropTransform(scale=tr.scale * r, offset_x=x0 + r * tr.offset_x + 0.5 * (r - 1),
                             offset_y=y0 + r * tr.offset_y + 0.5 * (r - 1))
        obs.crop = crop
        obs.tiny_labels = tiny.labels
        # Glove pixels inside the crop window, in full-resolution pixel units.
        cx, cy = tr.center_xy
        half = tr.half_size
        wx0, wx1 = max(int(np.ceil(cx - half)), 0), int(np.floor(cx + half)) + 1
        wy0, wy1 = max(int(np.ceil(cy - half)), 0), int(np.floor(cy + half)) + 1
        obs.glove_pixel_count = int(np.count_nonzero(labels[wy0:wy1, wx0:wx1])) * r * r
        obs.blobs = self._blobs(labels, r, x0, y0, (wx0, wx1, wy0, wy1))
        tick('blobs', t)
        # Reasons to reject: crop mostly outside the frame, or too little glove.
        fcx, fcy = crop.center_xy
        fh = crop.half_size
        inside_w = max(0.0, min(fcx + fh, w - 0.5) - max(fcx - fh, -0.5))
        inside_h = max(0.0, min(fcy + fh, h - 0.5) - max(fcy - fh, -0.5))
        inside = inside_w * inside_h / max((2.0 * fh) ** 2, 1e-9)
        if inside < self.min_inside_fraction:
            obs.status = STATUS_OUT_OF_FRAME
        elif obs.glove_pixel_count < self.min_glove_pixels:
            obs.status = STATUS_TOO_SMALL
        else:
            obs.status = STATUS_OK
            obs.hand_found = True
        timings['total'] = (time.perf_counter() - t0) * 1e3
        return obs


def load_segmenter(config_path: str = 'config/color_calibration.yaml') -> GloveSegmenter:
    """A segmenter with the calibration file and settings named in a colour config YAML."""
    cfg = read_calibration_config(config_path)
    calibration = load_calibration(cfg['calibration_file'])
    try:
        return GloveSegmenter(calibration, **cfg['segmenter'])
    except TypeError as exc:
        raise SegmentationConfigError(
            f'{cfg["config_path"]}: bad segmenter setting: {exc}') from exc
