"""Backgrounds of synthetic frames, deterministic from a seed: procedural (desk, clutter,
noise, office: muted textures and objects) or a real photograph ('photo': ``photos.py``),
slightly defocused, plus 0-3 saturated glove-coloured distractors that single frames keep
away from the hand and, on request, other people's skin (``people.py``: bare hands and arms,
faces) anywhere behind it."""
from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import cv2
import numpy as np

from colorglove_ros.core.colorimetry import srgb_to_linear
from colorglove_ros.core.hand.glove import GLOVE_PALETTE_RGB
from colorglove_ros.core.synthetic.conditions import (
    BACKGROUND_KINDS,
    GLOVE_ALBEDO,
    FrameConditions,
    SynthError,
    background_seed_split,
)
from colorglove_ros.core.synthetic.people import people_layers
from colorglove_ros.core.synthetic.photos import photo_albedo

__all__ = ['make_background', 'background_light_field', 'scene_background']


def _fbm(rng: np.random.Generator, h: int, w: int, channels: int = 1,
         base_cells: int = 3, octaves: int = 5) -> np.ndarray:
    """Smooth fractal value noise in about [-1, 1], (h, w, channels) float32; the octaves
    are summed on a 4x coarser grid and upsampled once."""
    lh, lw = max(8, h // 4), max(8, w // 4)
    out = np.zeros((lh, lw, channels), np.float32)
    amp, total = 1.0, 0.0
    for o in range(octaves):
        cells = base_cells * 2**o
        gh = max(2, cells * h // max(h, w) + 2)
        gw = max(2, cells * w // max(h, w) + 2)
        grid = rng.uniform(-1.0, 1.0, (gh, gw, channels)).astype(np.float32)
        out += amp * cv2.resize(grid, (lw, lh), interpolation=cv2.INTER_CUBIC).reshape(
            lh, lw, channels)
        total += amp
        amp *= 0.5
    return cv2.resize(out / total, (w, h), interpolation=cv2.INTER_LINEAR).reshape(
        h, w, channels)


def _random_muted(rng: np.random.Generator) -> np.ndarray:
    """A desaturated linear albedo typical of desks, walls, paper and packaging."""
    grey = rng.uniform(0.03, 0.7)
    tint = rng.normal(0.0, 0.08, 3)
    return np.clip(grey * (1.0 + tint), 0.01, 0.9)


def _glove_like(rng: np.random.Generator) -> np.ndarray:
    base = srgb_to_linear(GLOVE_PALETTE_RGB[rng.integers(len(GLOVE_PALETTE_RGB))] / 255.0)
    return np.clip(base * GLOVE_ALBEDO * rng.uniform(0.7, 1.1) + rng.normal(0, 0.02, 3),
                   0.0, 1.0)


def _draw_shape(img: np.ndarray, rng: np.random.Generator, color: np.ndarray,
                center: tuple[int, int], size: float) -> None:
    kind = rng.integers(4)
    c = tuple(float(v) for v in color)
    cx, cy = center
    if kind == 0:
        w2, h2 = size * rng.uniform(0.4, 1.0), size * rng.uniform(0.4, 1.0)
        rect = ((cx, cy), (2 * w2, 2 * h2), float(rng.uniform(0, 180)))
        pts = cv2.boxPoints(rect).astype(np.int32)
        cv2.fillPoly(img, [pts], c)
    elif kind == 1:
        axes = (int(size * rng.uniform(0.3, 1.0)), int(size * rng.uniform(0.3, 1.0)))
        cv2.ellipse(img, (cx, cy), axes, float(rng.uniform(0, 180)), 0, 360, c, -1)
    elif kind == 2:
        n = int(rng.integers(3, 7))
        ang = np.sort(rng.uniform(0, 2 * np.pi, n))
        rad = size * rng.uniform(0.4, 1.0, n)
        pts = np.stack([cx + rad * np.cos(ang), cy + rad * np.sin(ang)], 1).astype(np.int32)
        cv2.fillPoly(img, [pts], c)
    else:
        a = rng.uniform(0, np.pi)
        d = np.array([np.cos(a), np.sin(a)]) * size
        p0 = (int(cx - d[0]), int(cy - d[1]))
        p1 = (int(cx + d[0]), int(cy + d[1]))
        cv2.line(img, p0, p1, c, int(rng.integers(2, 8)))


@dataclass(frozen=True)
class _Background:
    base: np.ndarray                 # (H, W, 3) linear albedo, defocused
    light_field: np.ndarray          # (H, W, 1) smooth illumination variation
    distractors: tuple               # ((x0, y0, x1, y1), mask (h, w), rgb (3,)) glove-like


@lru_cache(maxsize=16)
def _background(kind: str, seed: int, width: int, height: int,
                photos: tuple[str, ...] = ()) -> _Background:
    if kind not in BACKGROUND_KINDS:
        raise SynthError(f'unknown background kind {kind!r}')
    rng = np.random.default_rng(seed)
    h, w = height, width
    scale = max(h, w) / 640.0
    if kind == 'photo':
        img, _ = photo_albedo(rng, background_seed_split(seed), w, h, photos)
        n_objects = 0
    elif kind == 'desk':
        img = np.ones((h, w, 3), np.float32) * _random_muted(rng)
        grain_dir = rng.uniform(0, np.pi)
        ys, xs = np.mgrid[0:h, 0:w].astype(np.float32)
        t = xs * np.cos(grain_dir) + ys * np.sin(grain_dir)
        warp = _fbm(rng, h, w, 1, 2, 3)[..., 0] * 40 * scale
        stripes = 0.5 + 0.5 * np.sin((t + warp) * rng.uniform(0.05, 0.25) / scale)
        img *= (1.0 + rng.uniform(0.0, 0.25) * (stripes[..., None] - 0.5))
        img *= 1.0 + 0.15 * _fbm(rng, h, w, 1, 3, 5)
        n_objects = int(rng.integers(1, 5))
    elif kind == 'clutter':
        img = np.ones((h, w, 3), np.float32) * _random_muted(rng)
        img *= 1.0 + 0.2 * _fbm(rng, h, w, 1, 2, 4)
        n_objects = int(rng.integers(8, 25))
    elif kind == 'noise':
        img = _random_muted(rng).astype(np.float32) * (1.0 + 0.35 * _fbm(rng, h, w, 3, 4, 6))
        n_objects = int(rng.integers(0, 4))
    else:   # office: wall above a desk edge, posters with text-like lines
        wall, desk = _random_muted(rng), _random_muted(rng)
        edge = int(h * rng.uniform(0.3, 0.7))
        img = np.empty((h, w, 3), np.float32)
        img[:edge], img[edge:] = wall, desk
        img *= 1.0 + 0.1 * _fbm(rng, h, w, 1, 2, 4)
        for _ in range(int(rng.integers(1, 4))):
            x0, y0 = int(rng.uniform(0, w)), int(rng.uniform(0, edge))
            x1, y1 = x0 + int(rng.uniform(40, 200) * scale), y0 + int(rng.uniform(30, 150) * scale)
            cv2.rectangle(img, (x0, y0), (x1, y1), tuple(float(v) for v in _random_muted(rng)),
                          -1)
            for yy in range(y0 + 8, y1 - 4, max(4, int(10 * scale))):
                cv2.line(img, (x0 + 6, yy), (x1 - 6, yy),
                         tuple(float(v) for v in _random_muted(rng) * 0.5), 1)
        n_objects = int(rng.integers(2, 8))
    for _ in range(n_objects):
        center = (int(rng.uniform(0, w)), int(rng.uniform(0, h)))
        _draw_shape(img, rng, _random_muted(rng), center, rng.uniform(15, 120) * scale)
    defocus = float(rng.uniform(0.6, 1.8)) * scale
    base = np.clip(cv2.GaussianBlur(img, (0, 0), defocus), 0.0, 1.0).astype(np.float32)
    distractors = []
    for _ in range(int(rng.integers(0, 4))):
        size = rng.uniform(8, 40) * scale
        center = (int(rng.uniform(0, w)), int(rng.uniform(0, h)))
        pad = int(2 * size + 4 * defocus + 4)
        x0, y0 = max(0, center[0] - pad), max(0, center[1] - pad)
        x1, y1 = min(w, center[0] + pad + 1), min(h, center[1] + pad + 1)
        mask = np.zeros((y1 - y0, x1 - x0), np.float32)
        _draw_shape(mask, rng, np.ones(3), (center[0] - x0, center[1] - y0), size)
        mask = cv2.GaussianBlur(mask, (0, 0), defocus)
        distractors.append(((x0, y0, x1, y1), mask, _glove_like(rng).astype(np.float32)))
    light_field = (1.0 + 0.25 * _fbm(rng, h, w, 1, 1, 2)).astype(np.float32)
    for arr in (base, light_field):
        arr.setflags(write=False)
    return _Background(base, light_field, tuple(distractors))


def make_background(kind: str, seed: int, width: int, height: int,
                    keep_out: tuple[int, int, int, int] | None = None, *,
                    photos: tuple[str, ...] = (), glove_distractors: bool = True,
                    skin_distractors: bool = False) -> np.ndarray:
    """(H, W, 3) float32 linear albedo of a background, deterministic from ``seed`` (cached);
    kind 'photo' uses a photo of the seed's split (among ``photos`` when given). With
    ``skin_distractors`` other people's hands, arms or a face stand in it. Its 0-3 saturated
    glove-coloured objects (none without ``glove_distractors``) are left out where their
    box meets ``keep_out`` (x0, y0, x1, y1), so they never touch the hand's box."""
    bg = _background(kind, int(seed), int(width), int(height), tuple(photos))
    img = bg.base.copy()
    if skin_distractors:
        for layer in people_layers(int(seed), int(width), int(height)):
            x0, y0, x1, y1 = layer.box
            img[y0:y1, x0:x1] = img[y0:y1, x0:x1] * (1.0 - layer.alpha[..., None]) + layer.rgb
    for (x0, y0, x1, y1), mask, rgb in bg.distractors:
        if not glove_distractors:
            break
        if keep_out is not None:
            kx0, ky0, kx1, ky1 = keep_out
            if x0 <= kx1 and kx0 <= x1 and y0 <= ky1 and ky0 <= y1:
                continue
        m = mask[..., None]
        img[y0:y1, x0:x1] = img[y0:y1, x0:x1] * (1.0 - m) + m * rgb
    return img


def background_light_field(kind: str, seed: int, width: int, height: int, *,
                           photos: tuple[str, ...] = ()) -> np.ndarray:
    """(H, W, 1) float32 smooth illumination variation over the background ``(kind, seed)``."""
    return _background(kind, int(seed), int(width), int(height), tuple(photos)).light_field


def scene_background(conditions: FrameConditions, width: int, height: int,
                     keep_out: tuple[int, int, int, int] | None = None
                     ) -> tuple[np.ndarray, np.ndarray]:
    """The background albedo (:func:`make_background`) and light field
    (:func:`background_light_field`) that ``conditions`` ask for."""
    kind, seed, photos = (conditions.background_kind, conditions.background_seed,
                          tuple(conditions.background_photos))
    albedo = make_background(kind, seed, width, height, keep_out, photos=photos,
                             glove_distractors=conditions.glove_distractors,
                             skin_distractors=conditions.skin_distractors)
    return albedo, background_light_field(kind, seed, width, height, photos=photos)
