"""Imaging conditions of a synthetic frame (light level and colour, sensor noise, blur, JPEG,
background) and their 'train' / 'test' splits: the two draw from different (mostly disjoint)
ranges and disjoint background seeds, so colour models fitted on 'train' frames are evaluated
on unseen conditions."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from colorglove_ros.core.errors import ColorGloveError

__all__ = [
    'SynthError', 'FrameConditions', 'BACKGROUND_KINDS', 'SPLITS', 'BACKGROUND_SEED_SPLIT',
    'GLOVE_ALBEDO', 'sample_conditions',
]

BACKGROUND_KINDS: tuple[str, ...] = ('desk', 'clutter', 'noise', 'office')
SPLITS: tuple[str, ...] = ('train', 'test')
GLOVE_ALBEDO = 0.85           # reflectance of the brightest printed colour
BACKGROUND_SEED_SPLIT = 1 << 30   # train background seeds < this <= test seeds


class SynthError(ColorGloveError):
    """Bad synthesis input: unknown split or background kind, pose or camera mismatch."""


@dataclass(frozen=True)
class FrameConditions:
    """Everything about a frame except the pose: lighting, sensor and background."""

    gain: float = 1.0                    # light level x exposure (1 = nominal)
    color_temperature_k: float = 6500.0  # light colour; WHITE_BALANCE_K looks neutral
    noise_sigma: float = 0.006           # read noise std (linear, full scale = 1); shot
    #                                      noise makes it sigma * sqrt(1 + 8 * intensity)
    blur_px: float = 0.0                 # motion-blur length of the hand layer, pixels
    blur_angle: float = 0.0              # motion direction in the image, radians
    background_kind: str = 'desk'
    background_seed: int = 0
    light_dir: tuple[float, float, float] = (0.3, 0.5, 1.0)   # direction light travels
    ambient: float = 0.4                 # ambient fraction of the lighting
    vignetting: float = 0.15             # relative fall-off at the image corners
    jpeg_quality: int = 0                # 0 = no compression
    sleeve_rgb: tuple[float, float, float] = (0.18, 0.2, 0.25)   # linear forearm albedo
    # glove-like background objects near the hand's box are left out (single frames); a
    # sequence keeps them all (a fixed scene the hand moves in front of, no flicker)
    distractors_avoid_hand: bool = True

    def __post_init__(self) -> None:
        if self.background_kind not in BACKGROUND_KINDS:
            raise SynthError(f'unknown background kind {self.background_kind!r}')
        if self.gain <= 0 or self.color_temperature_k < 1000 or self.noise_sigma < 0:
            raise SynthError('gain must be > 0, temperature >= 1000 K, noise >= 0')


_RANGES = {
    'train': {'gain': [(0.75, 1.3)], 'temp': [(5200.0, 7200.0)], 'noise': (0.003, 0.010),
              'blur_max': 2.0, 'ambient': (0.3, 0.5), 'jpeg': (0, 90, 97),
              'kinds': ('desk', 'clutter', 'noise'), 'light_cone_deg': 40.0,
              'vignetting': (0.05, 0.2)},
    'test': {'gain': [(0.5, 0.75), (1.3, 1.6)], 'temp': [(3800.0, 5200.0), (7200.0, 9500.0)],
             'noise': (0.008, 0.02), 'blur_max': 5.0, 'ambient': (0.2, 0.6),
             'jpeg': (0, 75, 92), 'kinds': BACKGROUND_KINDS, 'light_cone_deg': 60.0,
             'vignetting': (0.1, 0.35)},
}
_SLEEVES = np.array([[0.02, 0.02, 0.025], [0.05, 0.06, 0.12], [0.25, 0.25, 0.25],
                     [0.45, 0.28, 0.2], [0.6, 0.42, 0.33], [0.12, 0.1, 0.08]])


def _pick_range(rng: np.random.Generator, ranges: list[tuple[float, float]]) -> float:
    widths = np.array([hi - lo for lo, hi in ranges])
    lo, hi = ranges[int(rng.choice(len(ranges), p=widths / widths.sum()))]
    return float(rng.uniform(lo, hi))


def sample_conditions(rng: np.random.Generator, split: str = 'train') -> FrameConditions:
    """Random conditions for a frame. 'train' and 'test' use different (mostly disjoint)
    light levels, colour temperatures, noise/blur/JPEG ranges and disjoint background seeds;
    the 'office' background only appears in 'test'."""
    if split not in _RANGES:
        raise SynthError(f'split must be one of {SPLITS}, got {split!r}')
    r = _RANGES[split]
    cone = np.deg2rad(r['light_cone_deg'])
    # light travelling into the scene from above-left/right of the camera, within a cone
    axis = np.array([0.0, 0.45, 1.0]) / np.linalg.norm([0.0, 0.45, 1.0])
    theta = np.arccos(rng.uniform(np.cos(cone), 1.0))
    phi = rng.uniform(0, 2 * np.pi)
    ortho1 = np.array([1.0, 0.0, 0.0])
    ortho2 = np.cross(axis, ortho1)
    light = np.cos(theta) * axis + np.sin(theta) * (np.cos(phi) * ortho1 + np.sin(phi) * ortho2)
    blur = float(rng.uniform(0.0, r['blur_max'])) if rng.uniform() < 0.5 else 0.0
    q_lo, q_hi = r['jpeg'][1:]
    jpeg = int(rng.integers(q_lo, q_hi + 1)) if rng.uniform() < 0.5 else r['jpeg'][0]
    seed_lo, seed_hi = ((0, BACKGROUND_SEED_SPLIT) if split == 'train'
                        else (BACKGROUND_SEED_SPLIT, 1 << 31))
    return FrameConditions(
        gain=_pick_range(rng, r['gain']),
        color_temperature_k=_pick_range(rng, r['temp']),
        noise_sigma=float(rng.uniform(*r['noise'])),
        blur_px=blur,
        blur_angle=float(rng.uniform(0, np.pi)),
        background_kind=str(rng.choice(r['kinds'])),
        background_seed=int(rng.integers(seed_lo, seed_hi)),
        light_dir=tuple(float(v) for v in light),
        ambient=float(rng.uniform(*r['ambient'])),
        vignetting=float(rng.uniform(*r['vignetting'])),
        jpeg_quality=jpeg,
        sleeve_rgb=tuple(float(v) for v in _SLEEVES[rng.integers(len(_SLEEVES))]
                         * rng.uniform(0.8, 1.2)),
    )
