"""A 2-D stand-in glove for fast colour tests: a palm and five fingers cut into 20 patches of
the glove colours, on a textured background with clutter, under 'train' or 'test' imaging
conditions (the 'test' ones: other light levels, colour temperatures, more noise and clutter
with glove-like colours). The rendered 3-D glove is in ``frames.py``."""
from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from colorglove_ros.core.conventions import NUM_COLORS
from colorglove_ros.core.hand.glove import GLOVE_PALETTE_RGB

__all__ = ['BlobConditions', 'sample_blob_conditions', 'render_blob_frame']


@dataclass(frozen=True)
class BlobConditions:
    """Imaging conditions of one synthetic blob-glove frame."""

    light: float                 # overall light level multiplier
    white_balance: tuple[float, float, float]  # per-channel gains (colour temperature)
    noise_sigma: float           # sensor noise, 0..255 units
    clutter: int                 # number of coloured background rectangles
    glove_like_clutter: bool     # clutter may take (desaturated / shifted) glove colours
    hand_scale: float            # glove size in units of 100 px


def sample_blob_conditions(rng: np.random.Generator, split: str) -> BlobConditions:
    """Random conditions: 'train' is mild; 'test' has other light levels, colour temperatures,
    more noise and clutter with glove-like colours."""
    if split == 'train':
        light = float(rng.uniform(0.75, 1.15))
        wb = rng.uniform(0.92, 1.08, 3)
        return BlobConditions(light, (float(wb[0]), float(wb[1]), float(wb[2])),
                              float(rng.uniform(1.0, 3.0)), int(rng.integers(2, 8)), False,
                              float(rng.uniform(1.0, 1.8)))
    if split == 'test':
        light = float(rng.choice([rng.uniform(0.5, 0.75), rng.uniform(1.15, 1.35)]))
        temp = float(rng.uniform(-0.15, 0.15))  # warm (+) / cool (-)
        wb = np.array([1.0 + temp, 1.0, 1.0 - temp]) * rng.uniform(0.95, 1.05, 3)
        return BlobConditions(light, (float(wb[0]), float(wb[1]), float(wb[2])),
                              float(rng.uniform(2.0, 6.0)), int(rng.integers(5, 15)), True,
                              float(rng.uniform(0.8, 2.2)))
    raise ValueError(f"split must be 'train' or 'test', got {split!r}")


def _smooth_noise(rng: np.random.Generator, h: int, w: int, cells: int) -> np.ndarray:
    small = rng.uniform(0.0, 1.0, (cells, cells)).astype(np.float32)
    return cv2.resize(small, (w, h), interpolation=cv2.INTER_CUBIC)


def render_blob_frame(rng: np.random.Generator, cond: BlobConditions, width: int = 640,
                      height: int = 480) -> tuple[np.ndarray, np.ndarray]:
    """A stand-in glove (palm + five fingers cut into 20 coloured patches) on a textured,
    cluttered background -> (image (H, W, 3) uint8 RGB, labels (H, W) uint8)."""
    s = 100.0 * cond.hand_scale
    cx = rng.uniform(0.3, 0.7) * width
    cy = rng.uniform(0.35, 0.7) * height
    ang = rng.uniform(-0.6, 0.6)
    rot = np.array([[np.cos(ang), -np.sin(ang)], [np.sin(ang), np.cos(ang)]])
    colors = rng.integers(1, NUM_COLORS + 1, 20)
    labels = np.zeros((height, width), np.uint8)

    def pt(x: float, y: float) -> tuple[int, int]:
        p = rot @ np.array([x, y]) * s + [cx, cy]
        return int(round(p[0] * 16)), int(round(p[1] * 16))

    # Palm: 2x3 grid of patches (ids 0..5).
    k = 0
    for i in range(3):
        for j in range(2):
            x0, x1 = -0.45 + 0.45 * j, 0.45 * j
            y0, y1 = -0.3 + 0.3 * i, 0.3 * i - 0.0
            poly = np.array([pt(x0, y0), pt(x1, y0), pt(x1, y1), pt(x0, y1)], np.int32)
            cv2.fillConvexPoly(labels, poly, int(colors[k]), cv2.LINE_8, 4)
            k += 1
    # Fingers: thick segments; thumb 2 patches, others 3 (ids 6..19).
    bases = [(-0.55, 0.3, -2.3), (-0.38, -0.32, -1.7), (-0.12, -0.34, -1.57),
             (0.12, -0.32, -1.45), (0.36, -0.28, -1.3)]
    for f, (bx, by, a) in enumerate(bases):
        a += rng.uniform(-0.25, 0.25)
        nseg = 2 if f == 0 else 3
        seg = (0.42 if f else 0.25) * rng.uniform(0.8, 1.1) / nseg * 3 / 2
        thick = max(int(0.14 * s), 2)
        x, y = bx, by
        for _ in range(nseg):
            nx, ny = x + seg * np.cos(a), y + seg * np.sin(a)
            cv2.line(labels, pt(x, y), pt(nx, ny), int(colors[min(k, 19)]), thick, cv2.LINE_8, 4)
            x, y, k = nx, ny, k + 1
            a += rng.uniform(-0.2, 0.35)
    # Background: muted smooth texture plus clutter rectangles (muted random colours; in
    # 'test' also desaturated glove colours).
    base = rng.uniform(50, 190) + rng.normal(0, 10, 3)
    tex = _smooth_noise(rng, height, width, 6)[..., None] * rng.uniform(30, 70) * (
        1.0 + rng.normal(0, 0.1, 3))
    bg = np.clip(base + tex + rng.normal(0, 5, (height, width, 1)), 0, 255)
    for _ in range(cond.clutter):
        w, h = rng.integers(15, 140, 2)
        x0, y0 = rng.integers(0, width - w), rng.integers(0, height - h)
        if cond.glove_like_clutter and rng.uniform() < 0.5:
            c = GLOVE_PALETTE_RGB[rng.integers(NUM_COLORS)].astype(float)
        else:
            c = rng.uniform(0, 255, 3)
        gray = c.mean()
        c = gray + (c - gray) * rng.uniform(0.2, 0.5)
        bg[y0:y0 + h, x0:x0 + w] = np.clip(c, 0, 255)
    glove = GLOVE_PALETTE_RGB[np.maximum(labels, 1) - 1].astype(np.float64)
    shade = 0.7 + 0.3 * _smooth_noise(rng, height, width, 4)[..., None]
    img = np.where(labels[..., None] > 0, glove * shade, bg)
    img = cv2.GaussianBlur(img.astype(np.float32), (0, 0), 0.7)
    img = img * cond.light * np.array(cond.white_balance, np.float32)
    img = img + rng.normal(0.0, cond.noise_sigma, img.shape)
    return np.clip(np.round(img), 0, 255).astype(np.uint8), labels
