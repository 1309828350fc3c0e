"""Imaging conditions of a synthetic frame (light level and colour, sensor noise, blur, JPEG,
background, sleeve, the camera's colour processing) and their 'train' / 'test' splits: the two
draw from different (mostly disjoint) ranges and disjoint background seeds, so colour models
fitted on 'train' frames are evaluated on unseen conditions.

:func:`scene_conditions` builds the conditions of one named scene of the evaluation ladder
(:data:`SCENE_CONDITIONS`): a clean scene, real-photo backgrounds with skin and glove-coloured
clutter, a coloured sleeve, another camera's colour processing, or all of them at once."""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from colorglove_ros.core.errors import ColorGloveError

__all__ = [
    'SynthError', 'FrameConditions', 'PROCEDURAL_BACKGROUND_KINDS', 'BACKGROUND_KINDS',
    'SPLITS', 'BACKGROUND_SEED_SPLIT', 'GLOVE_ALBEDO', 'SLEEVE_ALBEDOS', 'SLEEVE_NAMES',
    'SCENE_CONDITIONS', 'background_seed_split', 'sample_conditions', 'sleeve_albedo',
    'sample_color_processing', 'scene_conditions',
]

PROCEDURAL_BACKGROUND_KINDS: tuple[str, ...] = ('desk', 'clutter', 'noise', 'office')
# 'photo': a real photograph (``photos.py``, ``config/photos.yaml``)
BACKGROUND_KINDS: tuple[str, ...] = (*PROCEDURAL_BACKGROUND_KINDS, 'photo')
SPLITS: tuple[str, ...] = ('train', 'test')
GLOVE_ALBEDO = 0.85           # reflectance of the brightest printed colour
BACKGROUND_SEED_SPLIT = 1 << 30   # train background seeds < this <= test seeds
_BACKGROUND_SEED_END = 1 << 31
# linear albedos of sleeve fabrics; 'skin' (a bare forearm) is drawn from the skin tones
SLEEVE_ALBEDOS: dict[str, tuple[float, float, float]] = {
    'dark': (0.02, 0.02, 0.025), 'denim': (0.06, 0.10, 0.20), 'grey': (0.2, 0.2, 0.2),
    'white': (0.7, 0.7, 0.68), 'red': (0.40, 0.015, 0.02),
}
SLEEVE_NAMES: tuple[str, ...] = (*SLEEVE_ALBEDOS, 'skin')
# the rungs of the evaluation ladder whose scene this module builds ('proportions' and
# 'borders' vary the hand and its motion, and use the 'clean' scene)
SCENE_CONDITIONS: tuple[str, ...] = ('clean', 'photos', 'sleeve', 'color_processing', 'all')


class SynthError(ColorGloveError):
    """Bad synthesis input: unknown split or background kind, pose or camera mismatch."""


def background_seed_split(seed: int) -> str:
    """The split ('train' or 'test') whose background seed range holds ``seed``."""
    if not 0 <= seed < _BACKGROUND_SEED_END:
        raise SynthError(f'background seed must be in 0..2**31 - 1, got {seed}')
    return 'train' if seed < BACKGROUND_SEED_SPLIT else 'test'


def _background_seed(rng: np.random.Generator, split: str) -> int:
    lo, hi = ((0, BACKGROUND_SEED_SPLIT) if split == 'train'
              else (BACKGROUND_SEED_SPLIT, _BACKGROUND_SEED_END))
    return int(rng.integers(lo, hi))


@dataclass(frozen=True)
class FrameConditions:
    """Everything about a frame except the pose: lighting, sensor, background, sleeve and the
    camera's colour processing (the defaults of the last leave the sensor's image as it is)."""

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
    glove_distractors: bool = True       # the background's saturated glove-coloured objects
    skin_distractors: bool = False       # other people's bare hands, arms and faces behind
    background_photos: tuple[str, ...] = ()   # 'photo' backgrounds: among these (all if empty)
    # camera colour processing, after the sensor noise and before JPEG: white-balance error
    # (linear gains per channel), saturation about the luminance (1 = unchanged), then a tone
    # curve on the sRGB-encoded values: v ** (1 / gamma) and an S-curve of strength contrast
    white_balance_gains: tuple[float, float, float] = (1.0, 1.0, 1.0)
    saturation: float = 1.0
    gamma: float = 1.0
    contrast: float = 0.0

    def __post_init__(self) -> None:
        if self.background_kind not in BACKGROUND_KINDS:
            raise SynthError(f'unknown background kind {self.background_kind!r}')
        if self.gain <= 0 or self.color_temperature_k < 1000 or self.noise_sigma < 0:
            raise SynthError('gain must be > 0, temperature >= 1000 K, noise >= 0')
        if len(self.white_balance_gains) != 3 or min(self.white_balance_gains) <= 0:
            raise SynthError(f'white_balance_gains must be 3 values > 0, '
                             f'got {self.white_balance_gains}')
        if self.saturation < 0 or self.gamma <= 0 or not -1.0 <= self.contrast <= 1.0:
            raise SynthError(f'need saturation >= 0, gamma > 0 and contrast in [-1, 1], got '
                             f'{self.saturation}, {self.gamma}, {self.contrast}')
        if len(self.sleeve_rgb) != 3 or not all(0.0 <= v <= 1.0 for v in self.sleeve_rgb):
            raise SynthError(f'sleeve_rgb must be 3 linear albedos in [0, 1], '
                             f'got {self.sleeve_rgb}')

    @property
    def processes_color(self) -> bool:
        """Whether the camera's colour processing changes the sensor's image."""
        return (tuple(self.white_balance_gains) != (1.0, 1.0, 1.0) or self.saturation != 1.0
                or self.gamma != 1.0 or self.contrast != 0.0)


_RANGES = {
    'train': {'gain': [(0.75, 1.3)], 'temp': [(5200.0, 7200.0)], 'noise': (0.003, 0.010),
              'blur_max': 2.0, 'ambient': (0.3, 0.5), 'jpeg': (0, 90, 97),
              'kinds': ('desk', 'clutter', 'noise'), 'light_cone_deg': 40.0,
              'vignetting': (0.05, 0.2)},
    'test': {'gain': [(0.5, 0.75), (1.3, 1.6)], 'temp': [(3800.0, 5200.0), (7200.0, 9500.0)],
             'noise': (0.008, 0.02), 'blur_max': 5.0, 'ambient': (0.2, 0.6),
             'jpeg': (0, 75, 92), 'kinds': PROCEDURAL_BACKGROUND_KINDS, 'light_cone_deg': 60.0,
             'vignetting': (0.1, 0.35)},
}
_SLEEVES = np.array([[0.02, 0.02, 0.025], [0.05, 0.06, 0.12], [0.25, 0.25, 0.25],
                     [0.45, 0.28, 0.2], [0.6, 0.42, 0.33], [0.12, 0.1, 0.08]])


def _pick_range(rng: np.random.Generator, ranges: list[tuple[float, float]]) -> float:
    widths = np.array([hi - lo for lo, hi in ranges])
    lo, hi = ranges[int(rng.choice(len(ranges), p=widths / widths.sum()))]
    return float(rng.uniform(lo, hi))


def _check_split(split: str) -> None:
    if split not in SPLITS:
        raise SynthError(f'split must be one of {SPLITS}, got {split!r}')


def _light_direction(rng: np.random.Generator, cone_deg: float) -> tuple[float, float, float]:
    """A light travelling into the scene from above-left/right of the camera, within a cone
    of ``cone_deg`` about the nominal direction."""
    cone = np.deg2rad(cone_deg)
    axis = np.array([0.0, 0.45, 1.0]) / np.linalg.norm([0.0, 0.45, 1.0])
    theta = np.arccos(rng.uniform(np.cos(cone), 1.0))
    phi = rng.uniform(0, 2 * np.pi)
    ortho1 = np.array([1.0, 0.0, 0.0])
    ortho2 = np.cross(axis, ortho1)
    light = np.cos(theta) * axis + np.sin(theta) * (np.cos(phi) * ortho1 + np.sin(phi) * ortho2)
    return tuple(float(v) for v in light)


def sample_conditions(rng: np.random.Generator, split: str = 'train') -> FrameConditions:
    """Random conditions for a frame. 'train' and 'test' use different (mostly disjoint)
    light levels, colour temperatures, noise/blur/JPEG ranges and disjoint background seeds;
    the 'office' background only appears in 'test'. Procedural backgrounds only, no colour
    processing (see :func:`scene_conditions` for photos, sleeves and other cameras)."""
    _check_split(split)
    r = _RANGES[split]
    light = _light_direction(rng, r['light_cone_deg'])
    blur = float(rng.uniform(0.0, r['blur_max'])) if rng.uniform() < 0.5 else 0.0
    q_lo, q_hi = r['jpeg'][1:]
    jpeg = int(rng.integers(q_lo, q_hi + 1)) if rng.uniform() < 0.5 else r['jpeg'][0]
    return FrameConditions(
        gain=_pick_range(rng, r['gain']),
        color_temperature_k=_pick_range(rng, r['temp']),
        noise_sigma=float(rng.uniform(*r['noise'])),
        blur_px=blur,
        blur_angle=float(rng.uniform(0, np.pi)),
        background_kind=str(rng.choice(r['kinds'])),
        background_seed=_background_seed(rng, split),
        light_dir=light,
        ambient=float(rng.uniform(*r['ambient'])),
        vignetting=float(rng.uniform(*r['vignetting'])),
        jpeg_quality=jpeg,
        sleeve_rgb=tuple(float(v) for v in _SLEEVES[rng.integers(len(_SLEEVES))]
                         * rng.uniform(0.8, 1.2)),
    )


def sleeve_albedo(name: str, rng: np.random.Generator) -> tuple[float, float, float]:
    """Linear albedo of a sleeve of ``SLEEVE_NAMES`` (brightness varied by +-15 % from
    ``rng``); 'skin' is a bare forearm of a skin tone drawn from ``rng``."""
    if name not in SLEEVE_NAMES:
        raise SynthError(f'sleeve must be one of {SLEEVE_NAMES}, got {name!r}')
    if name == 'skin':
        # imported here: bare_hand builds on the frame synthesiser, which imports this module
        from colorglove_ros.core.synthetic.bare_hand import SKIN_TONES_SRGB, skin_albedo

        base = skin_albedo(int(rng.integers(len(SKIN_TONES_SRGB))))
    else:
        base = np.asarray(SLEEVE_ALBEDOS[name])
    return tuple(float(v) for v in np.clip(base * rng.uniform(0.85, 1.15), 0.0, 1.0))


def sample_color_processing(rng: np.random.Generator) -> dict[str, object]:
    """Another camera's colour processing as :class:`FrameConditions` fields: a white-balance
    error of up to about +-20 % in red and blue against green, saturation 0.6-1.5, gamma
    0.8-1.25 and a contrast curve of -0.3..0.6."""
    red, blue = np.exp(rng.uniform(-0.2, 0.2, 2))
    return {'white_balance_gains': (float(red), 1.0, float(blue)),
            'saturation': float(rng.uniform(0.6, 1.5)),
            'gamma': float(np.exp(rng.uniform(np.log(0.8), np.log(1.25)))),
            'contrast': float(rng.uniform(-0.3, 0.6))}


def _clean_conditions(rng: np.random.Generator, split: str) -> FrameConditions:
    """A plain desk or office wall, no distractors, steady product-like light, a good sensor
    and no compression."""
    return FrameConditions(
        gain=float(rng.uniform(0.9, 1.1)),
        color_temperature_k=float(rng.uniform(5500.0, 6800.0)),
        noise_sigma=float(rng.uniform(0.003, 0.006)),
        background_kind=('desk', 'office')[int(rng.integers(2))],
        background_seed=_background_seed(rng, split),
        light_dir=_light_direction(rng, 25.0),
        ambient=float(rng.uniform(0.4, 0.5)),
        vignetting=float(rng.uniform(0.05, 0.15)),
        glove_distractors=False)


def scene_conditions(condition: str, rng: np.random.Generator,
                     split: str = 'test') -> FrameConditions:
    """The conditions of one frame of scene ``condition`` (of :data:`SCENE_CONDITIONS`),
    deterministic from ``rng``; the background seed lies in ``split``'s range.

    * 'clean': a plain desk or office wall, product-like light, no distractors;
    * 'photos': 'clean' light in front of a real photograph of ``split`` (wood, red and
      orange surfaces, dark areas), with other people's skin (hands, arms, faces) and
      glove-coloured clutter;
    * 'sleeve': 'clean' with a sleeve of ``SLEEVE_NAMES`` (dark, denim, grey, white, red or
      a bare forearm);
    * 'color_processing': 'clean' seen by another camera (:func:`sample_color_processing`);
    * 'all': ``split``'s light, noise, blur and JPEG (:func:`sample_conditions`) with the
      photos, a sleeve and another camera's colour processing together.

    'photos', 'sleeve' and 'color_processing' start with the draws of 'clean', so one rng
    seed gives the same light and background seed on each of these rungs.
    """
    if condition not in SCENE_CONDITIONS:
        raise SynthError(f'scene condition must be one of {SCENE_CONDITIONS}, '
                         f'got {condition!r}')
    _check_split(split)
    photos = {'background_kind': 'photo', 'glove_distractors': True, 'skin_distractors': True}
    if condition == 'all':
        base = sample_conditions(rng, split)
        sleeve = SLEEVE_NAMES[int(rng.integers(len(SLEEVE_NAMES)))]
        return replace(base, **photos, sleeve_rgb=sleeve_albedo(sleeve, rng),
                       **sample_color_processing(rng))
    base = _clean_conditions(rng, split)
    if condition == 'photos':
        return replace(base, **photos)
    if condition == 'sleeve':
        sleeve = SLEEVE_NAMES[int(rng.integers(len(SLEEVE_NAMES)))]
        return replace(base, sleeve_rgb=sleeve_albedo(sleeve, rng))
    if condition == 'color_processing':
        return replace(base, **sample_color_processing(rng))
    return base
