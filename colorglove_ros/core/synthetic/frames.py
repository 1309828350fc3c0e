"""Synthetic camera frames of the gloved hand with ground truth, and seeded motion sequences.

Image formation (all in linear RGB, then the camera's sRGB encoding):

* the glove (``GLOVE_PALETTE_RGB`` decoded from sRGB, times ``GLOVE_ALBEDO``) and a forearm
  sleeve are Lambert-shaded (smooth normals, one directional light plus ambient), rendered
  with 2 x 2 samples per pixel so silhouettes blend with the background as in a real camera;
* the light has a colour temperature (its residual cast relative to the camera's white
  balance at ``WHITE_BALANCE_K``) and a level (``gain``, exposure included) that apply to the
  hand and the background alike;
* a procedural background (desk, clutter, noise or office; some saturated glove-like
  colours, never over the hand), slightly defocused;
* optional linear motion blur of the hand layer, vignetting, shot + read noise, clipping,
  sRGB gamma, 8-bit quantisation and optional JPEG compression.

Ground truth: ``labels`` (0 background, 1..10 glove colour) and ``patch_ids`` (0 background,
patch + 1) are the visible glove at each pixel centre, from the unblurred geometry.
``sample_conditions(rng, 'train')`` and ``(rng, 'test')`` draw from different lighting,
noise and blur ranges and disjoint background seeds, so colour models fitted on 'train'
frames are evaluated on unseen conditions.
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace
from functools import lru_cache

import cv2
import numpy as np
from scipy.interpolate import CubicSpline
from scipy.ndimage import gaussian_filter1d
from scipy.spatial.transform import Rotation, RotationSpline

from colorglove_ros.core.camera import PinholeCamera
from colorglove_ros.core.errors import ColorGloveError
from colorglove_ros.core.hand.glove import GLOVE_PALETTE_RGB, Glove, default_hand
from colorglove_ros.core.hand.mesh import HandMesh
from colorglove_ros.core.hand.model import NUM_DOFS, HandModel, matrix_to_rotvec, rotvec_to_matrix
from colorglove_ros.core.hand.poses import (
    NAMED_SHAPES,
    finger_limits,
    pose_collection,
    sample_global_rotations,
)
from colorglove_ros.core.synthetic.render import Renderer, patch_ids_to_labels, vertex_normals

__all__ = [
    'SynthError', 'FrameConditions', 'SyntheticFrame', 'Synthesizer', 'BACKGROUND_KINDS',
    'SPLITS', 'WHITE_BALANCE_K', 'GLOVE_ALBEDO', 'CAPTURE_VOLUME_CENTER',
    'CAPTURE_VOLUME_SIZE', 'sample_conditions', 'render_frame', 'render_frames_multi',
    'sample_pose', 'generate_sequence', 'illuminant_rgb', 'srgb_to_linear', 'linear_to_srgb',
    'make_background', 'default_camera', 'transform_pose', 'SyntheticSequenceRenderer',
]

BACKGROUND_KINDS: tuple[str, ...] = ('desk', 'clutter', 'noise', 'office')
SPLITS: tuple[str, ...] = ('train', 'test')
WHITE_BALANCE_K = 6500.0
GLOVE_ALBEDO = 0.85           # reflectance of the brightest printed colour
CAPTURE_VOLUME_CENTER = np.array([0.0, 0.02, 0.55])   # metres, camera frame
CAPTURE_VOLUME_SIZE = np.array([0.60, 0.50, 0.30])    # x, y, z extent of the desk volume
_BG_SEED_SPLIT = 1 << 30      # train background seeds < this <= test seeds


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


@dataclass
class SyntheticFrame:
    """A rendered camera frame and its ground truth (all in this camera's optical frame)."""

    image_rgb: np.ndarray      # (H, W, 3) uint8 sRGB
    labels: np.ndarray         # (H, W) uint8: 0 background, 1..10 glove colour
    patch_ids: np.ndarray      # (H, W) uint8: 0 background, patch id + 1
    pose: np.ndarray           # (26,) q in this camera's frame
    keypoints_3d: np.ndarray   # (21, 3) metres, camera frame
    keypoints_2d: np.ndarray   # (21, 2) pixels (with the camera's distortion)
    camera: PinholeCamera
    conditions: FrameConditions


# ----------------------------------------------------------------------------- colour
def srgb_to_linear(c: np.ndarray) -> np.ndarray:
    """sRGB-encoded values in [0, 1] -> linear."""
    c = np.asarray(c, dtype=np.float64)
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


def linear_to_srgb(c: np.ndarray) -> np.ndarray:
    """Linear values in [0, 1] -> sRGB-encoded (float32)."""
    c = np.clip(np.asarray(c, dtype=np.float32), 0.0, 1.0)
    return np.where(c <= 0.0031308, c * 12.92,
                    1.055 * np.power(c, 1.0 / 2.4, dtype=np.float32) - 0.055).astype(np.float32)


_SRGB8_LUT = np.round(linear_to_srgb(np.arange(65536) / 65535.0) * 255.0).astype(np.uint8)


def _encode_srgb8(c: np.ndarray) -> np.ndarray:
    """Linear float image -> clipped, sRGB-encoded uint8 (16-bit look-up table)."""
    idx = (np.clip(c, 0.0, 1.0) * 65535.0 + 0.5).astype(np.uint16)
    return _SRGB8_LUT[idx]


_XYZ_TO_LINEAR_SRGB = np.array([[3.2404542, -1.5371385, -0.4985314],
                                [-0.9692660, 1.8760108, 0.0415560],
                                [0.0556434, -0.2040259, 1.0572252]])


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
    return _XYZ_TO_LINEAR_SRGB @ xyz


def illuminant_rgb(temperature_k: float, white_balance_k: float = WHITE_BALANCE_K) -> np.ndarray:
    """Linear RGB gains of a black-body light seen by a camera white-balanced for
    ``white_balance_k`` (equal gains at equal temperatures), luminance-normalised."""
    rgb = _planck_rgb(temperature_k) / _planck_rgb(white_balance_k)
    luminance = rgb @ np.array([0.2126, 0.7152, 0.0722])
    return rgb / luminance


# ----------------------------------------------------------------------------- conditions
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
    seed_lo, seed_hi = (0, _BG_SEED_SPLIT) if split == 'train' else (_BG_SEED_SPLIT, 1 << 31)
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


# ----------------------------------------------------------------------------- background
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
def _background(kind: str, seed: int, width: int, height: int) -> _Background:
    if kind not in BACKGROUND_KINDS:
        raise SynthError(f'unknown background kind {kind!r}')
    rng = np.random.default_rng(seed)
    h, w = height, width
    scale = max(h, w) / 640.0
    if kind == 'desk':
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
                    keep_out: tuple[int, int, int, int] | None = None) -> np.ndarray:
    """(H, W, 3) float32 linear albedo of a procedural background, deterministic from
    ``seed`` (cached). Its 0-3 saturated glove-coloured objects are left out where their
    box meets ``keep_out`` (x0, y0, x1, y1), so they never touch the hand's box."""
    bg = _background(kind, int(seed), int(width), int(height))
    img = bg.base.copy()
    for (x0, y0, x1, y1), mask, rgb in bg.distractors:
        if keep_out is not None:
            kx0, ky0, kx1, ky1 = keep_out
            if x0 <= kx1 and kx0 <= x1 and y0 <= ky1 and ky0 <= y1:
                continue
        m = mask[..., None]
        img[y0:y1, x0:x1] = img[y0:y1, x0:x1] * (1.0 - m) + m * rgb
    return img


# ----------------------------------------------------------------------------- geometry
def default_camera() -> PinholeCamera:
    """The 640x480, fx = fy = 600 camera of ``config/calibration.yaml``."""
    return PinholeCamera(640, 480, 600.0, 600.0, 319.5, 239.5)


def _forearm_mesh(model: HandModel) -> tuple[np.ndarray, np.ndarray]:
    """A closed elliptic frustum (hand frame, along +y from the wrist), outward CCW faces."""
    s = model.hand_length_m / 0.19
    n = 20
    ang = np.linspace(0.0, 2 * np.pi, n, endpoint=False)
    rings = []
    for y, rx, rz in ((-0.004, 0.028, 0.0135), (0.50, 0.040, 0.032)):
        rings.append(np.stack([rx * s * np.cos(ang), np.full(n, y * s),
                               rz * s * np.sin(ang) - 0.001 * s], axis=1))
    verts = np.concatenate([*rings, [[0.0, -0.004 * s, -0.001 * s], [0.0, 0.50 * s, -0.001 * s]]])
    faces = []
    for i in range(n):
        j = (i + 1) % n
        faces += [[i, j, n + j], [i, n + j, n + i]]
        faces += [[2 * n, j, i], [2 * n + 1, n + i, n + j]]
    verts, faces = np.asarray(verts), np.asarray(faces, dtype=np.int32)
    # orient outward: flip all faces if the signed volume is negative
    tri = verts[faces]
    vol = np.einsum('ij,ij->i', tri[:, 0], np.cross(tri[:, 1], tri[:, 2])).sum()
    if vol < 0:
        faces = faces[:, ::-1].copy()
    return verts, faces


def transform_pose(q: np.ndarray, rotation: np.ndarray, translation: np.ndarray) -> np.ndarray:
    """Express pose q in another frame: ``p' = rotation @ p + translation``."""
    q = np.asarray(q, dtype=float).copy()
    q[0:3] = rotation @ q[0:3] + translation
    q[3:6] = matrix_to_rotvec(rotation @ rotvec_to_matrix(q[3:6]))
    return q


@lru_cache(maxsize=4)
def _collection(seed: int) -> np.ndarray:
    return pose_collection(seed=seed, size=4000)


def sample_pose(rng: np.random.Generator, camera: PinholeCamera | None = None, *,
                model: HandModel | None = None, depth_range: tuple[float, float] = (0.4, 0.7),
                out_of_frame_prob: float = 0.1, back_fraction: float = 0.0) -> np.ndarray:
    """A random natural pose (26,) whose hand centre projects into the image (or, with
    probability ``out_of_frame_prob``, near its border so the hand is partly outside)."""
    camera = default_camera() if camera is None else camera
    model = default_hand()[0] if model is None else model
    coll = _collection(0)
    q = model.rest_pose()
    q[6:] = coll[rng.integers(len(coll))]
    q[3:6] = sample_global_rotations(rng, 1, back_fraction=back_fraction)[0]
    q[0:3] = 0.0
    centre = model.keypoints(q).mean(axis=0)     # hand centre relative to the wrist
    z = rng.uniform(*depth_range)
    if rng.uniform() < out_of_frame_prob:
        side = rng.integers(4)
        u = [rng.uniform(-0.05, 0.05), rng.uniform(0.95, 1.05)][side % 2] * camera.width \
            if side < 2 else rng.uniform(0.1, 0.9) * camera.width
        v = [rng.uniform(-0.05, 0.05), rng.uniform(0.95, 1.05)][side % 2] * camera.height \
            if side >= 2 else rng.uniform(0.1, 0.9) * camera.height
    else:
        u = rng.uniform(0.25, 0.75) * camera.width
        v = rng.uniform(0.25, 0.75) * camera.height
    target = np.array([(u - camera.cx) / camera.fx * z, (v - camera.cy) / camera.fy * z, z])
    q[0:3] = target - centre
    return q


# ----------------------------------------------------------------------------- synthesiser
class Synthesizer:
    """Renders :class:`SyntheticFrame` s of one glove (hand model, mesh, glove from
    ``default_hand``) plus a forearm sleeve; keeps a :class:`Renderer` per image size."""

    def __init__(self, hand_length_m: float = 0.19, glove_seed: int = 0,
                 supersample: int = 2, hand: tuple[HandModel, HandMesh, Glove] | None = None
                 ) -> None:
        self.model, self.mesh, self.glove = hand or default_hand(hand_length_m, glove_seed)
        self.supersample = int(supersample)
        arm_v, arm_f = _forearm_mesh(self.model)
        nv = self.mesh.num_vertices
        self._arm_local = arm_v
        self.faces = np.concatenate([self.mesh.faces, arm_f + nv]).astype(np.int32)
        self.face_patch = np.concatenate([self.glove.face_patch,
                                          np.full(len(arm_f), -1)]).astype(np.int64)
        palette = srgb_to_linear(GLOVE_PALETTE_RGB / 255.0) * GLOVE_ALBEDO
        self._glove_rgb = palette[self.glove.face_labels.astype(np.int64) - 1].astype(np.float32)
        self._num_arm_faces = len(arm_f)
        self._renderers: dict[tuple[int, int], Renderer] = {}
        self._distortion_maps: dict[tuple, tuple[np.ndarray, np.ndarray]] = {}

    def renderer(self, width: int, height: int) -> Renderer:
        """The cached renderer for an image size."""
        key = (int(width), int(height))
        if key not in self._renderers:
            self._renderers[key] = Renderer(*key, max_batch=16,
                                            supersample=self.supersample)
        return self._renderers[key]

    def vertices(self, q: np.ndarray) -> np.ndarray:
        """(V, 3) camera-frame vertices of hand + forearm for pose q."""
        q = np.asarray(q, dtype=float)
        if q.shape != (NUM_DOFS,):
            raise SynthError(f'pose must have shape (26,), got {q.shape}')
        hand = self.mesh.skin(self.model, q)
        R = rotvec_to_matrix(q[3:6])
        arm = self._arm_local @ R.T + q[0:3]
        return np.concatenate([hand, arm]).astype(np.float32)

    def render_frame(self, q: np.ndarray, camera: PinholeCamera, rng: np.random.Generator,
                     conditions: FrameConditions | None = None) -> SyntheticFrame:
        """One synthetic frame of pose q (camera frame) seen by ``camera``; ``rng`` draws
        the sensor noise (and the conditions when ``conditions`` is None)."""
        conditions = sample_conditions(rng, 'train') if conditions is None else conditions
        q = np.asarray(q, dtype=float)
        verts = self.vertices(q)
        w, h = camera.width, camera.height
        ideal = PinholeCamera(w, h, camera.fx, camera.fy, camera.cx, camera.cy)
        sleeve = np.tile(np.asarray(conditions.sleeve_rgb, np.float32), (self._num_arm_faces, 1))
        face_rgb = np.concatenate([self._glove_rgb, sleeve])
        light = illuminant_rgb(conditions.color_temperature_k) * conditions.gain
        shaded = self.renderer(w, h).render_shaded(
            verts, self.faces, face_rgb, ideal, light_dir=conditions.light_dir,
            ambient=conditions.ambient, light_rgb=light, face_patch=self.face_patch,
            normals=vertex_normals(verts, self.faces))
        ids, rgb, alpha = shaded.patch_ids, shaded.rgb, shaded.alpha
        if conditions.blur_px >= 1.0:
            kernel = _motion_kernel(conditions.blur_px, conditions.blur_angle)
            rgb = cv2.filter2D(rgb, -1, kernel, borderType=cv2.BORDER_CONSTANT)
            alpha = cv2.filter2D(alpha, -1, kernel, borderType=cv2.BORDER_CONSTANT)
        # background, lit by the same light
        ys, xs = np.nonzero(ids)
        keep_out = None
        if len(xs) and conditions.distractors_avoid_hand:
            keep_out = (int(xs.min()), int(ys.min()), int(xs.max()), int(ys.max()))
        bg = make_background(conditions.background_kind, conditions.background_seed, w, h,
                             keep_out=keep_out)
        light_field = _background(conditions.background_kind, conditions.background_seed,
                                  w, h).light_field
        bg *= light_field * light.astype(np.float32)
        img = rgb + (1.0 - alpha[..., None]) * bg
        # optics (lens distortion, vignetting) then the sensor
        if np.any(camera.distortion):
            img, ids = self._distort(camera, img, ids)
        yy, xx = np.mgrid[0:h, 0:w].astype(np.float32)
        r2 = ((xx - camera.cx) ** 2 + (yy - camera.cy) ** 2) / (0.25 * (w**2 + h**2))
        img = img * (1.0 - conditions.vignetting * r2)[..., None]
        sigma = conditions.noise_sigma * np.sqrt(1.0 + 8.0 * np.clip(img, 0.0, None))
        img = img + sigma * rng.standard_normal(img.shape, dtype=np.float32)
        out = _encode_srgb8(img)
        if conditions.jpeg_quality > 0:
            ok, enc = cv2.imencode('.jpg', out[..., ::-1],
                                   [cv2.IMWRITE_JPEG_QUALITY, int(conditions.jpeg_quality)])
            if not ok:
                raise SynthError('JPEG encoding failed')
            out = cv2.imdecode(enc, cv2.IMREAD_COLOR)[..., ::-1].copy()
        kp3 = self.model.keypoints(q)
        kp2 = _project_distorted(camera, kp3)
        return SyntheticFrame(out, patch_ids_to_labels(ids, self.glove.patch_color), ids, q,
                              kp3, kp2, camera, conditions)

    def _distort(self, camera: PinholeCamera, img: np.ndarray, ids: np.ndarray
                 ) -> tuple[np.ndarray, np.ndarray]:
        key = (camera.width, camera.height, camera.fx, camera.fy, camera.cx, camera.cy,
               tuple(np.asarray(camera.distortion, float)))
        if key not in self._distortion_maps:
            ys, xs = np.mgrid[0:camera.height, 0:camera.width].astype(np.float64)
            pix = np.stack([xs.ravel(), ys.ravel()], 1)
            und = camera.undistort_pixels(pix).reshape(camera.height, camera.width, 2)
            self._distortion_maps[key] = (und[..., 0].astype(np.float32),
                                          und[..., 1].astype(np.float32))
        mx, my = self._distortion_maps[key]
        img = cv2.remap(img, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
        ids = cv2.remap(ids, mx, my, cv2.INTER_NEAREST, borderMode=cv2.BORDER_CONSTANT)
        return img, ids

    def release(self) -> None:
        """Free the renderers' GL contexts."""
        for r in self._renderers.values():
            r.release()
        self._renderers.clear()


def _motion_kernel(length: float, angle: float) -> np.ndarray:
    size = int(np.ceil(length)) | 1
    k = np.zeros((size, size), np.float32)
    c = size // 2
    d = np.array([np.cos(angle), np.sin(angle)]) * (length - 1) / 2.0
    for t in np.linspace(-1.0, 1.0, 4 * size):
        x, y = c + t * d
        k[int(round(y)), int(round(x))] += 1.0
    return k / k.sum()


def _project_distorted(camera: PinholeCamera, points: np.ndarray) -> np.ndarray:
    if not np.any(camera.distortion):
        return camera.project(points)
    uv, _ = cv2.projectPoints(np.asarray(points, np.float64).reshape(-1, 1, 3), np.zeros(3),
                              np.zeros(3), camera.K, np.asarray(camera.distortion, float))
    return uv.reshape(-1, 2)


@lru_cache(maxsize=2)
def _default_synthesizer() -> Synthesizer:
    return Synthesizer()


def render_frame(q: np.ndarray, camera: PinholeCamera, rng: np.random.Generator,
                 conditions: FrameConditions | None = None, *,
                 synthesizer: Synthesizer | None = None) -> SyntheticFrame:
    """One synthetic frame (see :class:`Synthesizer`); a shared default synthesiser
    (0.19 m hand, glove seed 0) is used unless one is given."""
    synth = _default_synthesizer() if synthesizer is None else synthesizer
    return synth.render_frame(q, camera, rng, conditions)


def _primary_to(cameras: Sequence[PinholeCamera], k: int
                ) -> tuple[np.ndarray, np.ndarray] | None:
    """(R, t) taking the first camera's optical frame to camera ``k``'s (``p_k = R p + t``);
    None for the first camera itself, whose poses and points are used unchanged."""
    if k == 0:
        return None
    R = cameras[k].rotation @ cameras[0].rotation.T
    return R, cameras[k].translation - R @ cameras[0].translation


def _view(q: np.ndarray, conditions: FrameConditions, cameras: Sequence[PinholeCamera],
          k: int) -> tuple[np.ndarray, FrameConditions]:
    """Camera ``k``'s pose and conditions of a scene given in the first camera's terms: the
    pose and light direction in camera ``k``'s frame, the background seed offset by the
    camera index (the first camera's are ``q`` and ``conditions`` unchanged)."""
    extrinsics = _primary_to(cameras, k)
    if extrinsics is None:
        return np.asarray(q, dtype=float), conditions
    R, t = extrinsics
    light = R @ np.asarray(conditions.light_dir, float)
    return transform_pose(q, R, t), replace(
        conditions, light_dir=tuple(float(v) for v in light),
        background_seed=(conditions.background_seed + 7919 * k) % (1 << 31))


def render_frames_multi(q: np.ndarray, cameras: Sequence[PinholeCamera],
                        rng: np.random.Generator, conditions: FrameConditions | None = None,
                        *, synthesizer: Synthesizer | None = None) -> list[SyntheticFrame]:
    """One scene seen by several calibrated cameras. ``q`` is in the first camera's optical
    frame; each frame's ``pose`` and keypoints are in its own camera's frame. Lighting is
    shared (the light direction rotates with each view); each view sees its own background
    (seed offset by the camera index) and noise (drawn from ``rng`` camera by camera, so the
    first view is ``render_frame(q, cameras[0], rng, conditions)``)."""
    if not cameras:
        raise SynthError('need at least one camera')
    conditions = sample_conditions(rng, 'train') if conditions is None else conditions
    frames = []
    for k, cam in enumerate(cameras):
        qk, cond = _view(q, conditions, cameras, k)
        frames.append(render_frame(qk, cam, rng, cond, synthesizer=synthesizer))
    return frames


# ----------------------------------------------------------------------------- sequences
def _min_jerk(s: np.ndarray) -> np.ndarray:
    return s**3 * (10.0 - 15.0 * s + 6.0 * s**2)


def generate_sequence(seed: int, num_frames: int, fps: float = 30.0, *,
                      camera: PinholeCamera | None = None,
                      model: HandModel | None = None) -> np.ndarray:
    """(num_frames, 26) smooth hand motion, deterministic from ``seed``.

    Fingers move between natural shapes (named letters/gestures and pose-collection
    entries), holding each 0.15-0.6 s and moving with minimum-jerk profiles over 0.4-1.0 s
    (longer for large changes, so no joint exceeds ~4 rad/s),
    plus a small smooth jiggle (~1.5 deg). The wrist follows a C2 cubic spline through
    waypoints 0.7-1.6 s apart inside the ``CAPTURE_VOLUME_*`` desk volume (60 x 50 x 30 cm,
    depth 0.4-0.7 m), chosen so the hand centre projects inside ``camera``'s image
    (default 640x480, f = 600); orientation follows a rotation spline through waypoints
    from ``sample_global_rotations`` (each the nearest of 6 candidates to the previous,
    so the hand turns at natural speeds)."""
    if num_frames < 1 or fps <= 0:
        raise SynthError(f'need num_frames >= 1 and fps > 0, got {num_frames}, {fps}')
    rng = np.random.default_rng(seed)
    camera = default_camera() if camera is None else camera
    model = default_hand()[0] if model is None else model
    lo, hi = finger_limits(model)
    t = np.arange(num_frames) / fps
    duration = t[-1] + 1e-9
    # ---- fingers: holds and minimum-jerk transitions between natural shapes
    named = np.clip(np.stack(list(NAMED_SHAPES.values())), lo, hi)
    coll = _collection(0)

    def shape() -> np.ndarray:
        return named[rng.integers(len(named))] if rng.uniform() < 0.6 \
            else coll[rng.integers(len(coll))]

    fingers = np.empty((num_frames, 20))
    cur, time = shape(), -rng.uniform(0.0, 0.5)
    segments = []          # (start, end, from, to): holds and moves
    while time <= duration:
        hold, nxt = rng.uniform(0.15, 0.6), shape()
        # minimum-jerk peak speed 1.875 * delta / move: keep it under ~4 rad/s per joint
        move = max(rng.uniform(0.4, 1.0), 0.5 * float(np.abs(nxt - cur).max()))
        segments.append((time, time + hold, cur, cur))
        segments.append((time + hold, time + hold + move, cur, nxt))
        cur, time = nxt, time + hold + move
    for t0, t1, a, b in segments:
        sel = (t >= t0) & (t < t1)
        fingers[sel] = a + _min_jerk((t[sel] - t0) / (t1 - t0))[:, None] * (b - a)
    jiggle = gaussian_filter1d(rng.normal(0.0, 1.0, (num_frames + 20, 20)), 0.12 * fps,
                               axis=0, mode='reflect')[10:10 + num_frames]
    jiggle *= np.deg2rad(1.5) / max(float(jiggle.std()), 1e-9)
    fingers = np.clip(fingers + jiggle, lo, hi)
    # ---- global motion: waypoints in the capture volume, C2 splines
    half = CAPTURE_VOLUME_SIZE / 2.0
    centre_local = np.array([0.0, -0.45 * model.hand_length_m, 0.0])  # hand centre, hand frame
    n_way = int(np.ceil(duration / 0.7)) + 3
    times = np.concatenate([[-0.5], np.cumsum(rng.uniform(0.7, 1.6, n_way)) - 0.5])
    rotations = [sample_global_rotations(rng, 1)[0]]
    positions = []
    for k in range(len(times)):
        if k > 0:
            cands = sample_global_rotations(rng, 6)
            prev = Rotation.from_rotvec(rotations[-1])
            ang = [(Rotation.from_rotvec(c) * prev.inv()).magnitude() for c in cands]
            rotations.append(cands[int(np.argmin(ang))])
        R = rotvec_to_matrix(rotations[-1])
        for _attempt in range(200):
            p = CAPTURE_VOLUME_CENTER + rng.uniform(-half, half)
            if positions and np.linalg.norm(p - positions[-1]) > 0.22:
                continue
            c = p + R @ centre_local
            u, v = camera.project(c)
            if 0.15 * camera.width < u < 0.85 * camera.width \
                    and 0.15 * camera.height < v < 0.85 * camera.height:
                break
        positions.append(p)
    pos = CubicSpline(times, np.array(positions), axis=0, bc_type='natural')(t)
    rot = RotationSpline(times, Rotation.from_rotvec(np.array(rotations)))(t).as_rotvec()
    Q = np.zeros((num_frames, NUM_DOFS))
    Q[:, 0:3] = pos
    Q[:, 3:6] = rot
    Q[:, 6:] = fingers
    return Q


class SyntheticSequenceRenderer:
    """Frames of one seeded sequence (``generate_sequence``) under one set of conditions
    (``sample_conditions`` for ``split``, drawn from the seed; the background's glove-like
    objects stay in place while the hand passes in front), with motion blur following
    the hand's image speed over a ``shutter`` fraction of the frame interval. ``render(i)``
    is deterministic and independent of the order frames are asked for."""

    def __init__(self, camera: PinholeCamera, *, seed: int = 1, num_frames: int = 300,
                 fps: float = 30.0, hand_length_m: float = 0.19, split: str = 'test',
                 shutter: float = 0.5, glove_seed: int = 0,
                 conditions: FrameConditions | None = None) -> None:
        self.camera = camera
        self.seed = int(seed)
        self.synth = Synthesizer(hand_length_m, glove_seed)
        self.poses = generate_sequence(seed, num_frames, fps, camera=camera,
                                       model=self.synth.model)
        rng = np.random.default_rng([self.seed, 7])
        cond = sample_conditions(rng, split) if conditions is None else conditions
        self.conditions = replace(cond, distractors_avoid_hand=False)
        self.shutter = float(shutter)
        self.fps = float(fps)
        # hand centres (primary camera frame), whose image velocity sets each view's blur
        self._centres = self.synth.model.keypoints_batch(self.poses).mean(axis=1)

    def __len__(self) -> int:
        return len(self.poses)

    def render(self, index: int) -> SyntheticFrame:
        """Frame ``index`` (0-based) of the sequence."""
        return self.render_views(index, (self.camera,))[0]

    def render_views(self, index: int, cameras: Sequence[PinholeCamera]) -> list[SyntheticFrame]:
        """Frame ``index`` as each of ``cameras`` sees it, primary (the sequence's camera, in
        whose frame the poses are) first; the others as in :func:`render_frames_multi`. Each
        view's motion blur follows the hand's velocity in that view's image; the noise of all
        views comes from the frame's seed, primary first, so view 0 is ``render(index)``."""
        if not 0 <= index < len(self.poses):
            raise SynthError(f'frame {index} outside 0..{len(self.poses) - 1}')
        if not cameras:
            raise SynthError('need at least one camera')
        nxt = min(index + 1, len(self.poses) - 1)
        prv = max(index - 1, 0)
        rng = np.random.default_rng([self.seed, index, 11])
        frames = []
        for k, cam in enumerate(cameras):
            q, cond = _view(self.poses[index], self.conditions, cameras, k)
            centres = self._centres[[prv, nxt]]
            extrinsics = _primary_to(cameras, k)
            if extrinsics is not None:
                centres = centres @ extrinsics[0].T + extrinsics[1]
            px = cam.project(centres)
            vel = (px[1] - px[0]) / max(nxt - prv, 1)
            cond = replace(cond, blur_px=float(np.hypot(*vel) * self.shutter),
                           blur_angle=float(np.arctan2(vel[1], vel[0])))
            frames.append(self.synth.render_frame(q, cam, rng, cond))
        return frames

    def close(self) -> None:
        """Free the GL contexts."""
        self.synth.release()
