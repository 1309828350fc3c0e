"""Calibrate the colour model to the user's own scene and glove from two short recordings, with
no hand-drawn masks.

1. The empty scene (camera in its place, no glove): a per-pixel background model (median and
   noise, for a static camera), and the scene's colours as extra Gaussian components of the
   background class (class 0) of a starting calibration, so the scene's own warm, dark or
   skin-like colours stop being labelled glove.
2. The glove in view, moving and turning: glove pixels are found without masks. They differ
   from the empty scene, lie near a glove colour once the scene's light colour is divided out
   (a search over black-body lights, refined by :func:`estimate_light_gains`), and form one
   hand-sized group of solid patches of several glove colours. They are clustered in the
   calibration's feature space (:func:`rgb_features`), each cluster seeded by the glove
   colour's reference colour (k-means, far pixels left out), and each glove colour found
   often enough gets its mixture refitted from its cluster at the scene's own light: its
   pixels, copies mixed with their neighbours (as blur and the segmenter's downsampling show
   them) and re-lit copies (as :func:`fit_color_calibration` makes). A colour seen too little
   keeps the starting calibration's colour model, moved to the scene's light.

The scene may not take a glove colour: a scene component that would make the background take
more than ``max_claim`` of a glove colour's pixels as seen in the scene (or, for a kept
colour, of its modelled colours) is down-weighted, and dropped if need be. The reference
colours (the light the segmenter divides out of each frame) are the glove colours as the
segmenter's coarse pass sees them in this scene, so frames of the scene need no correction.
"""
from __future__ import annotations

import inspect
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import cv2
import numpy as np

from colorglove_ros.core.colorimetry import LUMINANCE_WEIGHTS, linear_to_srgb, srgb_to_linear
from colorglove_ros.core.hand.glove import GLOVE_COLOR_NAMES, GLOVE_PALETTE_RGB
from colorglove_ros.core.segmentation.calibration_fit import (
    fit_color_calibration,
    fit_mixture,
    relit_copies,
)
from colorglove_ros.core.segmentation.color_model import (
    ColorCalibration,
    ColorCalibrationError,
    GaussianMixtureParams,
    compile_lut,
    lut_index,
)
from colorglove_ros.core.segmentation.light import (
    estimate_light_gains,
    gain_table,
    planckian_illuminants,
)
from colorglove_ros.core.segmentation.segmenter import GloveSegmenter

__all__ = [
    'LABEL_PALETTE_RGB', 'SceneCalibrationError', 'SceneCalibrationSettings', 'SceneBackground',
    'SceneCalibration', 'check_frames', 'fit_scene_background', 'foreground_mask',
    'estimate_scene_light', 'label_image_rgb', 'scene_figures', 'calibrate_scene',
]

#: Colour of each label in label pictures: black background, then the glove's palette.
LABEL_PALETTE_RGB = np.vstack([[0, 0, 0], GLOVE_PALETTE_RGB]).astype(np.uint8)
LABEL_PALETTE_RGB.setflags(write=False)
_SRGB_TO_LINEAR = srgb_to_linear(np.arange(256) / 255.0).astype(np.float32)
_ASSIGN_BITS = 6   # bits per channel of the nearest-glove-colour table


class SceneCalibrationError(ColorCalibrationError):
    """The scene recordings cannot be used: no frames, unreadable or mixed-size frames, the
    glove in the empty scene, or too little of the glove found."""


@dataclass(frozen=True)
class SceneCalibrationSettings:
    """How the scene calibration finds, clusters and fits (tuned at 320x240, checked at
    640x480)."""

    # --- the empty scene as extra background components
    scene_components: int = 8          # Gaussian components the scene adds to class 0
    scene_weight: float = 0.5          # their share of class 0's mixture
    max_scene_pixels: int = 24000      # scene pixels sampled for the fit
    max_claim: float = 0.01            # largest share of a glove colour's pixels they may take
    max_downweight_steps: int = 4      # a component is divided by 4 this often, then dropped
    # --- static-camera foreground: differs from the empty scene's median by this much
    foreground_levels: float = 24.0    # sRGB levels (largest channel), at least
    foreground_sigmas: float = 5.0     # ... and this many times the pixel's noise
    max_foreground_share: float = 0.6  # more: the camera moved, the frame is not used for it
    # --- glove pixels
    min_level: int = 40                # darker pixels (largest sRGB channel) carry no colour
    assign_radius: float = 4.5         # farthest feature distance from a glove colour's centre
    max_centre_drift: float = 6.0      # a cluster centre farther from its seed: colour not found
    min_component_colors: int = 4      # the glove component shows this many glove colours ...
    min_color_share: float = 0.02      # ... each with this share of its pixels
    min_glove_share: float = 0.002     # and covers this share of the frame at least
    empty_glove_colors: int = 6        # such a region of this many colours in most empty
    #                                    frames: the glove is in the empty scene, refuse
    group_radius_share: float = 0.006  # glove pixels this share of the diagonal apart join up
    min_class_pixels: int = 200        # fewer pixels of a colour: it keeps the start mixture
    min_found_colors: int = 5          # fewer colours found: refuse
    max_pixels_per_class: int = 5000   # training pixels per colour (before re-lighting)
    components: int = 3                # Gaussian components per refitted glove colour
    max_mix: float = 0.3               # training copies mixed with a neighbour up to this share
    light_search_k: tuple[float, float] = (2200.0, 25000.0)   # black bodies searched
    max_light_gain: float = 4.0        # largest light correction per channel (and 1 / it)
    max_frames: int = 40               # frames of each recording used (evenly spaced)

    def __post_init__(self) -> None:
        if not 0.0 < self.scene_weight < 1.0 or not 0.0 <= self.max_claim < 1.0:
            raise SceneCalibrationError('need 0 < scene_weight < 1 and 0 <= max_claim < 1')
        if min(self.scene_components, self.components, self.min_found_colors,
               self.max_frames, self.min_component_colors) < 1:
            raise SceneCalibrationError('component, colour and frame counts must be >= 1')


@dataclass(frozen=True)
class SceneBackground:
    """The empty scene per pixel: median colour and noise (sRGB levels, largest channel)."""

    median: np.ndarray   # (H, W, 3) uint8
    noise: np.ndarray    # (H, W) float32
    frames: int


@dataclass
class SceneCalibration:
    """The calibration fitted to a scene, with what the fit found: one row per glove colour,
    a summary (light, frames, scene components), and for a few glove frames (keyed by their
    index in the frames given) the glove pixels the fit used (label images, 0 elsewhere)."""

    calibration: ColorCalibration
    classes: list[dict[str, Any]]
    summary: dict[str, Any]
    found_labels: dict[int, np.ndarray] = field(default_factory=dict)


# ----------------------------------------------------------------------------- frames
def check_frames(frames: Sequence[np.ndarray], what: str) -> tuple[int, int]:
    """(height, width) of a non-empty list of same-size (H, W, 3) uint8 frames; raise
    :class:`SceneCalibrationError` naming ``what`` and the offending frame otherwise."""
    if not len(frames):
        raise SceneCalibrationError(f'no {what} frames')
    size: tuple[int, int] | None = None
    for i, frame in enumerate(frames):
        if (not isinstance(frame, np.ndarray) or frame.dtype != np.uint8 or frame.ndim != 3
                or frame.shape[2] != 3 or 0 in frame.shape):
            shape = getattr(frame, 'shape', None)
            raise SceneCalibrationError(f'{what} frame {i}: expected an (H, W, 3) uint8 image, '
                                        f'got {shape} {getattr(frame, "dtype", type(frame))}')
        if size is None:
            size = frame.shape[:2]
        elif frame.shape[:2] != size:
            raise SceneCalibrationError(
                f'{what} frame {i} is {frame.shape[1]}x{frame.shape[0]}, frame 0 is '
                f'{size[1]}x{size[0]}: all frames must come from one camera at one size')
    assert size is not None
    return size


def _filtered(segmenter: GloveSegmenter, frame: np.ndarray) -> np.ndarray:
    """``frame`` after the segmenter's bilateral filter (its settings), as it classifies it."""
    if segmenter.bilateral_diameter > 0 and min(frame.shape[:2]) > segmenter.bilateral_diameter:
        return cv2.bilateralFilter(np.ascontiguousarray(frame), segmenter.bilateral_diameter,
                                   segmenter.bilateral_sigma_color,
                                   segmenter.bilateral_sigma_space)
    return frame


def _evenly_spaced(length: int, count: int) -> list[int]:
    """Up to ``count`` indices evenly spread over ``range(length)``, first and last included."""
    if length <= count:
        return list(range(length))
    return sorted({int(i) for i in np.linspace(0, length - 1, count).round()})


# ----------------------------------------------------------------------------- background
def fit_scene_background(frames: Sequence[np.ndarray], noise_floor: float = 2.0
                         ) -> SceneBackground:
    """Per-pixel median of the empty-scene frames and their noise (1.4826 times the median
    absolute deviation, largest channel; ``noise_floor`` where fewer than 3 frames)."""
    check_frames(frames, 'empty-scene')
    stack = np.stack(frames)
    median = np.median(stack, axis=0)
    if len(frames) >= 3:
        noise = 1.4826 * np.median(np.abs(stack - median), axis=0).max(axis=-1)
    else:
        noise = np.zeros(median.shape[:2])
    return SceneBackground(np.round(median).astype(np.uint8),
                           np.maximum(noise, noise_floor).astype(np.float32), len(frames))


def foreground_mask(background: SceneBackground, frame: np.ndarray,
                    settings: SceneCalibrationSettings) -> np.ndarray | None:
    """Pixels of ``frame`` that differ from the empty scene (after matching the frame's
    exposure, a per-channel gain), or None if too much differs (the camera moved)."""
    if frame.shape != background.median.shape:
        raise SceneCalibrationError(
            f'glove frames are {frame.shape[1]}x{frame.shape[0]}, the empty scene '
            f'{background.median.shape[1]}x{background.median.shape[0]}: record both with '
            'the same camera settings')
    lin_frame = _SRGB_TO_LINEAR[frame]
    lin_scene = _SRGB_TO_LINEAR[background.median]
    lit = lin_scene.max(axis=-1) > 0.02
    if lit.sum() < 100:
        return None
    ratio = np.median(lin_frame[lit] / np.maximum(lin_scene[lit], 1e-4), axis=0)
    expected = 255.0 * linear_to_srgb(np.clip(lin_scene * np.clip(ratio, 0.25, 4.0), 0.0, 1.0),
                                      np.float32)
    diff = np.abs(frame.astype(np.float32) - expected).max(axis=-1)
    mask = diff > np.maximum(settings.foreground_levels,
                             settings.foreground_sigmas * background.noise)
    mask = cv2.morphologyEx(mask.view(np.uint8), cv2.MORPH_OPEN, np.ones((3, 3), np.uint8))
    if mask.mean() > settings.max_foreground_share:
        return None
    return mask.astype(bool)


# ----------------------------------------------------------------------------- light
def _luminance_normalised(gains: np.ndarray) -> np.ndarray:
    return gains / float(gains @ LUMINANCE_WEIGHTS)


def _corrected_features(cal: ColorCalibration, linear_rgb: np.ndarray,
                        gains: np.ndarray) -> np.ndarray:
    return cal.features(linear_to_srgb(np.clip(linear_rgb * gains, 0.0, 1.0)))


def _nearest(features: np.ndarray, centres: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Index of the nearest centre (N,) and its squared distance (N,)."""
    d2 = ((features[:, None, :] - centres[None]) ** 2).sum(axis=-1)
    nearest = d2.argmin(axis=1)
    return nearest, d2[np.arange(len(nearest)), nearest]


def estimate_scene_light(pixels: np.ndarray, calibration: ColorCalibration,
                         settings: SceneCalibrationSettings,
                         centres: np.ndarray | None = None) -> np.ndarray:
    """Von Kries gains (3,) that bring sRGB ``pixels`` (N, 3) uint8, mostly glove, to the
    calibration's light: the black-body light (``light_search_k``, gains within
    ``max_light_gain``) whose removal puts the pixels nearest a glove colour's centre
    (``centres``, default the reference colours' features; mean squared distance truncated
    at ``assign_radius``), refined with :func:`estimate_light_gains` on the pixels so
    assigned while that brings them nearer."""
    if centres is None:
        centres = calibration.features(linear_to_srgb(calibration.reference_linear_rgb))
    if not len(pixels):
        return np.ones(3)
    lin = _SRGB_TO_LINEAR[np.asarray(pixels, np.uint8)].astype(np.float64)
    r2 = settings.assign_radius ** 2

    def score(gains: np.ndarray) -> tuple[float, np.ndarray]:
        nearest, d2 = _nearest(_corrected_features(calibration, lin, gains), centres)
        return float(np.minimum(d2, r2).mean()), np.where(d2 <= r2, nearest + 1, 0)

    best, (best_score, labels) = np.ones(3), score(np.ones(3))
    for light in planckian_illuminants(*settings.light_search_k, count=48):
        gains = _luminance_normalised(1.0 / light)
        if gains.max() > settings.max_light_gain or gains.min() < 1.0 / settings.max_light_gain:
            continue
        trial, trial_labels = score(gains)
        if trial < best_score:
            best, best_score, labels = gains, trial, trial_labels
    for _ in range(3):
        counts = np.bincount(labels, minlength=len(centres) + 1)[1:]
        if np.count_nonzero(counts >= 20) < 3:
            break
        gains = estimate_light_gains(lin, labels, calibration.reference_linear_rgb,
                                     max_gain=settings.max_light_gain)
        trial, trial_labels = score(gains)
        if trial >= best_score:
            break
        best, best_score, labels = gains, trial, trial_labels
    return best


# ----------------------------------------------------------------------------- glove pixels
def _assignment_table(cal: ColorCalibration, centres: np.ndarray,
                      settings: SceneCalibrationSettings) -> np.ndarray:
    """Label (1..C, 0 for none) of every quantised RGB colour: its nearest glove colour
    centre within ``assign_radius``, none for colours darker than ``min_level``."""
    n = 1 << _ASSIGN_BITS
    step = 256 // n
    levels = np.arange(n) * step + (step - 1) / 2.0
    grid = np.stack(np.meshgrid(levels, levels, levels, indexing='ij'), -1).reshape(-1, 3)
    nearest, d2 = _nearest(cal.features(grid / 255.0), centres)
    near = (d2 <= settings.assign_radius ** 2) & (grid.max(axis=1) >= settings.min_level)
    return np.where(near, nearest + 1, 0).astype(np.uint8)


def _glove_component(labels: np.ndarray, settings: SceneCalibrationSettings
                     ) -> np.ndarray | None:
    """The largest group of candidate glove pixels (solid ones: a 3 x 3 median drops specks;
    joined across thin gaps) showing at least ``min_component_colors`` glove colours and
    ``min_glove_share`` of the frame; None if there is none. Returns the labels there (0
    elsewhere)."""
    h, w = labels.shape
    solid = cv2.medianBlur(labels, 3)
    candidate = (solid > 0).view(np.uint8)
    radius = max(1, int(round(settings.group_radius_share * np.hypot(h, w))))
    kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * radius + 1, 2 * radius + 1))
    n, comp = cv2.connectedComponents(cv2.dilate(candidate, kernel), connectivity=8)
    at = np.flatnonzero(candidate)
    nl = int(solid.max()) + 1
    hist = np.bincount(comp.ravel()[at] * nl + solid.ravel()[at],
                       minlength=n * nl).reshape(n, nl)[:, 1:]
    size = hist.sum(axis=1)
    colours = (hist >= np.maximum(settings.min_color_share * size[:, None], 4)).sum(axis=1)
    ok = (colours >= settings.min_component_colors) & (size >= settings.min_glove_share * h * w)
    ok[0] = False
    if not ok.any():
        return None
    best = int(np.argmax(np.where(ok, size, -1)))
    return np.where(comp == best, labels, 0).astype(np.uint8)


def _interior(labels: np.ndarray) -> np.ndarray:
    """Glove pixels whose 4-neighbours all share their label (no mixed border pixels)."""
    cross = cv2.getStructuringElement(cv2.MORPH_CROSS, (3, 3))
    return (labels > 0) & (cv2.erode(labels, cross) == cv2.dilate(labels, cross))


def _mixed_with_neighbours(image: np.ndarray, at: np.ndarray, max_mix: float,
                           rng: np.random.Generator, reach: int = 4) -> np.ndarray:
    """The pixels ``at`` (a mask) of ``image`` each mixed (in linear RGB) with the pixel a
    random offset of up to ``reach`` away, by a random share up to ``max_mix``: how blur and
    downsampling show a colour next to its neighbours (other patches, the sleeve, the scene)."""
    h, w = image.shape[:2]
    ys, xs = np.nonzero(at)
    ny = np.clip(ys + rng.integers(-reach, reach + 1, len(ys)), 0, h - 1)
    nx = np.clip(xs + rng.integers(-reach, reach + 1, len(xs)), 0, w - 1)
    share = rng.uniform(0.0, max_mix, (len(ys), 1))
    lin = (1.0 - share) * _SRGB_TO_LINEAR[image[ys, xs]] + share * _SRGB_TO_LINEAR[image[ny, nx]]
    return np.round(255.0 * linear_to_srgb(lin)).astype(np.uint8)


def _kmeans(features: np.ndarray, seeds: np.ndarray, radius: float,
            iterations: int = 15, min_members: int = 10) -> np.ndarray:
    """Centres of k-means seeded at ``seeds``, each pixel counted for its nearest centre only
    within ``radius`` (others are outliers: sleeve, skin, mixed colours)."""
    centres = seeds.copy()
    for _ in range(iterations):
        nearest, d2 = _nearest(features, centres)
        near = d2 <= radius * radius
        moved = centres.copy()
        for c in range(len(centres)):
            members = features[near & (nearest == c)]
            if len(members) >= min_members:
                moved[c] = members.mean(axis=0)
        if np.allclose(moved, centres, atol=1e-3):
            break
        centres = moved
    return centres


@dataclass
class _GloveFrames:
    """What was found on the glove frames."""

    gains: list[np.ndarray]                 # per frame: to the starting calibration's light
    labels: list[np.ndarray | None]         # per frame: glove labels, 0 elsewhere (or None)
    foreground: list[np.ndarray | None]     # per frame: differs from the empty scene
    centres: np.ndarray                     # (C, D) colour centres (features, that light)
    shifts: np.ndarray                      # (C,) how far each centre moved from its seed


def _find_glove(cal: ColorCalibration, frames: list[np.ndarray], background: SceneBackground,
                settings: SceneCalibrationSettings, rng: np.random.Generator) -> _GloveFrames:
    """Find the glove on ``frames``: the scene's light (:func:`estimate_scene_light` on the
    pixels that differ from the empty scene), then twice: each frame's candidate pixels
    (nearest colour centre, within the foreground) and its glove group
    (:func:`_glove_component`), each frame's light from its glove pixels, and the colour
    centres by k-means from the reference colours (a centre that moves farther than
    ``max_centre_drift`` goes back to its seed)."""
    seeds = cal.features(linear_to_srgb(cal.reference_linear_rgb))
    foreground = [foreground_mask(background, f, settings) for f in frames]
    # 1. the scene's light, from bright foreground pixels of all frames
    sample = []
    for frame, fg in zip(frames, foreground, strict=True):
        pix = frame[fg] if fg is not None else frame.reshape(-1, 3)
        pix = pix[pix.max(axis=1) >= settings.min_level]
        sample.append(pix[rng.choice(len(pix), min(len(pix), 4000), replace=False)])
    gains = estimate_scene_light(np.concatenate(sample), cal, settings, seeds)
    centres, shifts = seeds, np.zeros(len(seeds))
    per_frame = [gains] * len(frames)
    labels: list[np.ndarray | None] = [None] * len(frames)
    for _ in range(2):   # find the glove, re-estimate light and colour centres, find again
        table = _assignment_table(cal, centres, settings)
        for i, (frame, fg) in enumerate(zip(frames, foreground, strict=True)):
            lab = table.take(lut_index(frame, _ASSIGN_BITS, gain_table(per_frame[i])))
            if fg is not None:
                lab[~fg] = 0
            labels[i] = _glove_component(lab, settings)
        found = [i for i, lab in enumerate(labels) if lab is not None]
        if not found:
            break
        pixels, feats = [], []
        for i in found:
            inner = _interior(labels[i])
            lin = _SRGB_TO_LINEAR[frames[i][inner]].astype(np.float64)
            lab = labels[i][inner]
            if np.count_nonzero(np.bincount(lab, minlength=cal.num_colors + 1)[1:] >= 20) >= 3:
                per_frame[i] = estimate_light_gains(lin, lab, cal.reference_linear_rgb,
                                                    max_gain=settings.max_light_gain)
            take = rng.choice(len(lin), min(len(lin), 6000), replace=False)
            pixels.append(lin[take] * per_frame[i])
        for chunk in pixels:
            feats.append(cal.features(linear_to_srgb(np.clip(chunk, 0.0, 1.0))))
        centres = _kmeans(np.concatenate(feats), seeds, settings.assign_radius)
        shifts = np.linalg.norm(centres - seeds, axis=1)
        centres[shifts > settings.max_centre_drift] = seeds[shifts > settings.max_centre_drift]
        typical = np.median([per_frame[i] for i in found], axis=0)
        per_frame = [per_frame[i] if labels[i] is not None else typical
                     for i in range(len(frames))]
    return _GloveFrames(per_frame, labels, foreground, centres, shifts)


def _frames_showing_glove(cal: ColorCalibration, frames: list[np.ndarray],
                          found: _GloveFrames, settings: SceneCalibrationSettings) -> int:
    """How many ``frames`` show a glove region of ``empty_glove_colors`` colours, found as
    on the glove frames (their typical light, the colour centres found there; no
    foreground)."""
    table = _assignment_table(cal, found.centres, settings)
    light = gain_table(np.median(np.array(found.gains), axis=0))
    strict = replace(settings, min_component_colors=max(settings.min_component_colors,
                                                         settings.empty_glove_colors))
    return sum(_glove_component(table.take(lut_index(frame, _ASSIGN_BITS, light)), strict)
               is not None for frame in frames)


# ----------------------------------------------------------------------------- fitting
def _fit_option(start: ColorCalibration, name: str) -> Any:
    """A fit option as the starting calibration was fitted with (its metadata), else
    :func:`fit_color_calibration`'s default."""
    if name in start.metadata:
        value = start.metadata[name]
        return tuple(value) if isinstance(value, list) else value
    return inspect.signature(fit_color_calibration).parameters[name].default


def _component_log_densities(mixture: GaussianMixtureParams, feats: np.ndarray) -> np.ndarray:
    """log N_k(x) of each component k of ``mixture`` at features (N, D) -> (N, K)."""
    return np.column_stack([
        GaussianMixtureParams(np.ones(1), mixture.means[k:k + 1],
                              mixture.covariances[k:k + 1]).log_likelihood(feats)
        for k in range(len(mixture.weights))])


def _log_mix(log_weights: np.ndarray, log_densities: np.ndarray) -> np.ndarray:
    z = log_densities + log_weights
    m = z.max(axis=1)
    return m + np.log(np.exp(z - m[:, None]).sum(axis=1))


@dataclass
class _ClaimCheck:
    """Glove colours' reference pixels scored once, so the background's scene components can
    be re-weighted cheaply."""

    owner: np.ndarray          # (N,) class each reference pixel belongs to (1..C)
    glove_ll: np.ndarray       # (N, C) glove classes' log-likelihoods
    start_bg_ll: np.ndarray    # (N,) the starting background's log-likelihood
    scene_ll: np.ndarray       # (N, K) scene components' log densities
    thresholds: np.ndarray
    log_priors: np.ndarray

    def labels(self, bg_ll: np.ndarray) -> np.ndarray:
        """The calibration's decision (as :meth:`ColorCalibration.decide`) with this
        background log-likelihood."""
        ll = np.column_stack([bg_ll, self.glove_ll])
        label = np.argmax(ll + self.log_priors, axis=1)
        reject = ll[np.arange(len(label)), label] < self.thresholds[label]
        return np.where(reject, 0, label)

    def claims(self, start_share: float, scene_log_w: np.ndarray, num_colors: int
               ) -> tuple[np.ndarray, np.ndarray]:
        """Per glove colour the share of its pixels the background takes only because of the
        scene components (C,), and per scene component how many of those it takes most
        likely (K,)."""
        bg = np.logaddexp(np.log(start_share) + self.start_bg_ll,
                          _log_mix(scene_log_w, self.scene_ll)
                          if np.isfinite(scene_log_w).any() else -np.inf)
        without = self.labels(self.start_bg_ll)
        taken = (without == self.owner) & (self.labels(bg) == 0)
        per_class = (np.bincount(self.owner[taken], minlength=num_colors + 1)[1:]
                     / np.maximum(np.bincount(self.owner, minlength=num_colors + 1)[1:], 1))
        blame = np.argmax(self.scene_ll[taken] + scene_log_w, axis=1)
        return per_class, np.bincount(blame, minlength=len(scene_log_w))


def _joined(chunks: list[np.ndarray]) -> np.ndarray:
    return np.concatenate(chunks) if chunks else np.zeros((0, 3), np.uint8)


def _apply_gains(pixels: np.ndarray, gains: np.ndarray) -> np.ndarray:
    """sRGB pixels (N, 3) uint8 with their linear RGB multiplied by ``gains`` (3,)."""
    return cv2.LUT(pixels.reshape(-1, 1, 3), gain_table(gains)).reshape(-1, 3)


def _class_colours(cal: ColorCalibration, label: int, count: int,
                   rng: np.random.Generator) -> np.ndarray:
    """``count`` colours (N, 3) uint8 drawn from those the calibration's table gives
    ``label``, each with probability proportional to the class's likelihood there (jittered
    within the table's bins)."""
    n = 1 << cal.bits
    idx = np.flatnonzero(cal.lut == label)
    if not len(idx):
        raise SceneCalibrationError(f'the starting calibration labels no colour '
                                    f'{GLOVE_COLOR_NAMES[label - 1]}')
    step = 256 // n
    bins = np.stack([(idx >> (2 * cal.bits)) & (n - 1), (idx >> cal.bits) & (n - 1),
                     idx & (n - 1)], axis=1) * step
    ll = cal.mixtures[label].log_likelihood(cal.features((bins + (step - 1) / 2.0) / 255.0))
    p = np.exp(ll - ll.max())
    pick = bins[rng.choice(len(bins), count, p=p / p.sum())]
    return np.clip(pick + rng.integers(0, step, pick.shape), 0, 255).astype(np.uint8)


def _decide_weights(check: _ClaimCheck, scene: GaussianMixtureParams, settings:
                    SceneCalibrationSettings, num_colors: int
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per scene component its weight factor (1, 1/4, ... or 0), and the claims per glove
    colour before and after down-weighting."""
    factor = np.ones(len(scene.weights))
    start_share = 1.0 - settings.scene_weight

    def log_w() -> np.ndarray:
        with np.errstate(divide='ignore'):
            return np.log(settings.scene_weight * scene.weights * factor)

    first, blame = check.claims(start_share, log_w(), num_colors)
    claims = first
    for _ in range(settings.max_downweight_steps * len(factor) + 1):
        if claims.max(initial=0.0) <= settings.max_claim or not blame.any():
            break
        worst = int(np.argmax(blame))
        factor[worst] = 0.0 if factor[worst] <= 4.0 ** -settings.max_downweight_steps \
            else factor[worst] / 4.0
        claims, blame = check.claims(start_share, log_w(), num_colors)
    return factor, first, claims


def _coarse_references(cal: ColorCalibration, frames: list[np.ndarray],
                       glove_labels: list[np.ndarray], gains: list[np.ndarray],
                       coarse_factor: int, min_pixels: int = 20) -> np.ndarray:
    """Mean linear RGB (C, 3) of each glove colour on the frames downsampled by
    ``coarse_factor`` as the segmenter's coarse pass does, at the light ``gains`` bring each
    frame to, labelled by ``cal`` near the glove found (``glove_labels``); the calibration's
    own reference colour where a colour has fewer than ``min_pixels`` such pixels."""
    num = cal.num_colors
    sums = np.zeros((3, num + 1))
    counts = np.zeros(num + 1)
    near = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (9, 9))
    for frame, labels, frame_gains in zip(frames, glove_labels, gains, strict=True):
        image = cv2.LUT(frame, gain_table(frame_gains))
        region = cv2.dilate((labels > 0).view(np.uint8), near)
        h, w = labels.shape
        f = coarse_factor
        if f > 1 and h >= 2 * f and w >= 2 * f:
            image = cv2.resize(image, (w // f, h // f), interpolation=cv2.INTER_LINEAR)
            region = cv2.resize(region, (w // f, h // f), interpolation=cv2.INTER_NEAREST)
        lab = (cal.classify(image) * region).ravel()
        lin = _SRGB_TO_LINEAR[image].reshape(-1, 3)
        counts += np.bincount(lab, minlength=num + 1)
        sums += [np.bincount(lab, lin[:, k], minlength=num + 1) for k in range(3)]
    ok = counts[1:] >= min_pixels
    reference = cal.reference_linear_rgb.copy()
    reference[ok] = (sums[:, 1:] / np.maximum(counts[1:], 1)).T[ok]
    return reference


def _scene_mixture(start: ColorCalibration, empty: list[np.ndarray], glove: list[np.ndarray],
                   found: _GloveFrames, typical_gains: np.ndarray,
                   settings: SceneCalibrationSettings, rng: np.random.Generator,
                   seed: int) -> GaussianMixtureParams:
    """The scene's colours as a Gaussian mixture (``scene_components``): pixels of the empty
    frames (half of them among those the starting calibration calls glove) and what else the
    glove frames show away from the glove (sleeve, arm), at the scene's light, with mildly
    re-lit copies."""
    with_glove = [i for i, labels in enumerate(found.labels) if labels is not None]
    per_frame = max(settings.max_scene_pixels // (3 * len(empty)), 50)
    scene = []
    for frame in empty:
        flat = frame.reshape(-1, 3)
        starts_glove = np.flatnonzero(start.classify(frame).ravel() > 0)
        scene += [flat[rng.choice(flat.shape[0], per_frame, replace=False)],
                  flat[rng.choice(starts_glove, min(per_frame, len(starts_glove)),
                                  replace=False)]]
    margin = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (9, 9))
    for i in with_glove:
        away = cv2.dilate((found.labels[i] > 0).view(np.uint8), margin) == 0
        if found.foreground[i] is not None:
            away &= found.foreground[i]
        pix = cv2.LUT(glove[i], gain_table(found.gains[i] / typical_gains))[away]
        if len(pix):
            scene.append(pix[rng.choice(len(pix), min(len(pix), per_frame), replace=False)])
    pixels = relit_copies(np.concatenate(scene), rng, 1, (0.7, 1.4), 0.03, None, 2.0)
    return fit_mixture(start.features(pixels), settings.scene_components, 1e-1, seed)


def _background_with_scene(start: ColorCalibration, mixtures: list[GaussianMixtureParams],
                           thresholds: np.ndarray, reference_pixels: list[np.ndarray],
                           scene: GaussianMixtureParams, settings: SceneCalibrationSettings
                           ) -> tuple[GaussianMixtureParams, np.ndarray, np.ndarray,
                                      np.ndarray]:
    """The background class: the start's components and the scene's (``scene_weight`` of
    it), each scene component down-weighted or dropped while it takes more than
    ``max_claim`` of a glove colour's ``reference_pixels`` (sRGB, one array per colour).
    Returns it, each scene component's weight factor (0: dropped) and the claims per glove
    colour before and after."""
    owners = np.concatenate([np.full(len(p), c + 1) for c, p in enumerate(reference_pixels)])
    feats = start.features(np.concatenate(reference_pixels))
    check = _ClaimCheck(owners, np.column_stack([m.log_likelihood(feats) for m in mixtures[1:]]),
                        start.mixtures[0].log_likelihood(feats),
                        _component_log_densities(scene, feats), thresholds, start.log_priors)
    factor, before, after = _decide_weights(check, scene, settings, start.num_colors)
    keep = factor > 0
    weights = np.concatenate([(1.0 - settings.scene_weight) * start.mixtures[0].weights,
                              settings.scene_weight * scene.weights[keep] * factor[keep]])
    background = GaussianMixtureParams(
        weights / weights.sum(), np.concatenate([start.mixtures[0].means, scene.means[keep]]),
        np.concatenate([start.mixtures[0].covariances, scene.covariances[keep]]))
    return background, factor, before, after


# ----------------------------------------------------------------------------- figures
def label_image_rgb(labels: np.ndarray) -> np.ndarray:
    """A label image (H, W) in glove colours (background black) -> (H, W, 3) uint8."""
    return LABEL_PALETTE_RGB[np.minimum(labels, len(LABEL_PALETTE_RGB) - 1)]


def scene_figures(calibration: ColorCalibration, empty_frames: Sequence[np.ndarray],
                  glove_frames: Sequence[np.ndarray],
                  segmenter_settings: Mapping[str, Any] | None = None) -> dict[str, float]:
    """What a calibration does on a scene, with the segmenter built on it
    (``segmenter_settings``): the share of the empty scene's pixels its full-frame labelling
    (:meth:`GloveSegmenter.classify_full`) calls glove (``empty_labelled_glove``) and its
    final label image keeps after the clean-up (``empty_pipeline_glove``), and the share of
    empty and of glove frames with a hand found."""
    segmenter = GloveSegmenter(calibration, **dict(segmenter_settings or {}))
    labelled, pipeline, empty_found = [], [], 0
    for frame in empty_frames:
        labelled.append(float(np.mean(segmenter.classify_full(frame) > 0)))
        segmenter.lose_track()   # frames of a scene, not of one motion: none follows another
        obs = segmenter.process(frame, keep_labels=True)
        pipeline.append(0.0 if obs.label_image is None else float(np.mean(obs.label_image > 0)))
        empty_found += int(obs.hand_found)
    glove_found = 0
    for frame in glove_frames:
        segmenter.lose_track()
        glove_found += int(segmenter.process(frame).hand_found)
    nan = float('nan')
    return {'empty_labelled_glove': float(np.mean(labelled)) if labelled else nan,
            'empty_pipeline_glove': float(np.mean(pipeline)) if pipeline else nan,
            'empty_hand_found': empty_found / len(empty_frames) if empty_frames else nan,
            'glove_hand_found': glove_found / len(glove_frames) if glove_frames else nan}


# ----------------------------------------------------------------------------- main entry
def calibrate_scene(start: ColorCalibration, empty_frames: Sequence[np.ndarray],
                    glove_frames: Sequence[np.ndarray],
                    settings: SceneCalibrationSettings | None = None, *, seed: int = 0,
                    segmenter_settings: Mapping[str, Any] | None = None,
                    picture_frames: int = 4, source: str = '') -> SceneCalibration:
    """Fit ``start`` to a scene: ``empty_frames`` show it without the glove, ``glove_frames``
    with the glove in view (same camera, same size). Returns the new calibration (same
    format, lookup table compiled), per glove colour what was found, a summary, and the glove
    pixels found on ``picture_frames`` evenly spaced glove frames. Raises
    :class:`SceneCalibrationError` on unusable frames, a glove in the empty scene, or fewer
    than ``min_found_colors`` glove colours found."""
    from threadpoolctl import threadpool_limits

    # one thread: the fits' matrices are 3 x 3, where BLAS and OpenMP threads only cost time
    with threadpool_limits(limits=1):
        return _calibrate_scene(start, empty_frames, glove_frames,
                                settings or SceneCalibrationSettings(), seed,
                                segmenter_settings, picture_frames, source)


def _calibrate_scene(start: ColorCalibration, empty_frames: Sequence[np.ndarray],
                     glove_frames: Sequence[np.ndarray], settings: SceneCalibrationSettings,
                     seed: int, segmenter_settings: Mapping[str, Any] | None,
                     picture_frames: int, source: str) -> SceneCalibration:
    rng = np.random.default_rng(seed)
    size_empty = check_frames(empty_frames, 'empty-scene')
    size_glove = check_frames(glove_frames, 'glove')
    if size_empty != size_glove:
        raise SceneCalibrationError(
            f'empty-scene frames are {size_empty[1]}x{size_empty[0]}, glove frames '
            f'{size_glove[1]}x{size_glove[0]}: record both with the same camera settings')
    segmenter = GloveSegmenter(start, **dict(segmenter_settings or {}))
    # the colours the segmenter classifies: after its bilateral filter
    empty = [_filtered(segmenter, empty_frames[i])
             for i in _evenly_spaced(len(empty_frames), settings.max_frames)]
    glove_index = _evenly_spaced(len(glove_frames), settings.max_frames)
    glove = [_filtered(segmenter, glove_frames[i]) for i in glove_index]
    background = fit_scene_background(empty)
    found = _find_glove(start, glove, background, settings, rng)
    shown = _frames_showing_glove(start, empty, found, settings)
    if shown > len(empty) // 2:
        raise SceneCalibrationError(
            f'{shown} of {len(empty)} empty-scene frames show the glove (a region of '
            f'{settings.empty_glove_colors} or more glove colours side by side): record the '
            'scene without the glove, or move such an object out of view')
    frames_with_glove = [i for i, lab in enumerate(found.labels) if lab is not None]
    if not frames_with_glove:
        raise SceneCalibrationError(
            f'no glove found in any of the {len(glove)} glove frames (a hand-sized region of '
            f'at least {settings.min_component_colors} glove colours that differs from the '
            'empty scene): is the glove in view and lit, and the camera where it was for the '
            'empty scene?')

    # --- glove colours at the scene's own light (each frame's deviation from the typical
    # light divided out), so frames of this scene need no correction at run time
    num = start.num_colors
    typical_gains = np.median(np.array([found.gains[i] for i in frames_with_glove]), axis=0)
    per_class: list[list[np.ndarray]] = [[] for _ in range(num)]
    frames_seen = np.zeros(num, int)
    corrected_class: list[list[np.ndarray]] = [[] for _ in range(num)]
    mixed_class: list[list[np.ndarray]] = [[] for _ in range(num)]
    for i in frames_with_glove:
        labels = found.labels[i]
        inner = _interior(labels)
        lab = labels[inner]
        scene_light = cv2.LUT(glove[i], gain_table(found.gains[i] / typical_gains))
        mixed = _mixed_with_neighbours(scene_light, inner, settings.max_mix, rng)
        at_start_light = cv2.LUT(glove[i], gain_table(found.gains[i]))[inner]
        for c in range(1, num + 1):
            mine = lab == c
            if mine.any():
                per_class[c - 1].append(scene_light[inner][mine])
                mixed_class[c - 1].append(mixed[mine])
                corrected_class[c - 1].append(at_start_light[mine])
                frames_seen[c - 1] += int(np.count_nonzero(mine) >= 20)
    illuminants = _fit_option(start, 'augment_temperatures_k')
    relight = dict(copies=int(_fit_option(start, 'augment_copies')),
                   light=tuple(_fit_option(start, 'augment_light')),
                   white_balance=float(_fit_option(start, 'augment_white_balance')),
                   illuminants=None if illuminants is None
                   else planckian_illuminants(*illuminants),
                   noise=float(_fit_option(start, 'augment_noise')))
    covariance_floor = float(_fit_option(start, 'glove_covariance_floor'))
    reject_quantile = float(_fit_option(start, 'reject_quantile'))
    mixtures = list(start.mixtures)
    thresholds = start.thresholds.copy()
    reference = start.reference_linear_rgb / typical_gains
    rows: list[dict[str, Any]] = []
    reference_pixels: list[np.ndarray] = []
    refitted = np.zeros(num, bool)
    for c in range(1, num + 1):
        pix = _joined(per_class[c - 1])
        row = {'class': c, 'name': GLOVE_COLOR_NAMES[c - 1], 'pixels': len(pix),
               'frames': int(frames_seen[c - 1]),
               'centre_shift': float(found.shifts[c - 1]),
               'status': 'refitted'}
        if len(pix) >= settings.min_class_pixels:
            take = rng.choice(len(pix), min(len(pix), settings.max_pixels_per_class),
                              replace=False)
            pix = pix[take]
            train = relit_copies(np.concatenate([pix, _joined(mixed_class[c - 1])[take]]), rng,
                                 **relight)
            reference[c - 1] = _SRGB_TO_LINEAR[pix].astype(np.float64).mean(axis=0)
            refitted[c - 1] = True
        else:   # the starting calibration's colour, moved to the scene's light
            train = _apply_gains(_class_colours(start, c, settings.max_pixels_per_class, rng),
                                 1.0 / typical_gains)
            row['status'] = 'kept from start, re-lit'
        feats = start.features(train)
        k = max(1, min(settings.components, len(np.unique(train, axis=0))))
        mixtures[c] = fit_mixture(feats, k, covariance_floor, seed)
        thresholds[c] = float(np.quantile(mixtures[c].log_likelihood(feats), reject_quantile))
        # what the scene may not take: the colour as seen in this scene (its re-lit copies
        # stand for other lights, where the scene looks different too), else the start's
        reference_pixels.append(pix if refitted[c - 1] else train)
        rows.append(row)
    if refitted.sum() < settings.min_found_colors:
        missing = [GLOVE_COLOR_NAMES[c] for c in np.flatnonzero(~refitted)]
        raise SceneCalibrationError(
            f'found only {int(refitted.sum())} of {num} glove colours often enough '
            f'(>= {settings.min_class_pixels} pixels; missing: {", ".join(missing)}), need '
            f'{settings.min_found_colors}: turn the glove so every side is seen, with more '
            'light')

    scene_mixture = _scene_mixture(start, empty, glove, found, typical_gains, settings, rng,
                                   seed)
    mixtures[0], factor, claims_before, claims_after = _background_with_scene(
        start, mixtures, thresholds, reference_pixels, scene_mixture, settings)
    keep = factor > 0
    for row, before, after in zip(rows, claims_before, claims_after, strict=True):
        row['scene_claim_before'] = float(before)
        row['scene_claim_after'] = float(after)

    summary = {
        'empty_frames': len(empty), 'glove_frames': len(glove),
        'glove_frames_with_glove': len(frames_with_glove),
        'glove_frames_with_foreground': sum(fg is not None for fg in found.foreground),
        'light_gains': typical_gains.tolist(),
        'colours_refitted': int(refitted.sum()),
        'scene_components': int(keep.sum()),
        'scene_components_downweighted': int(((factor < 1) & keep).sum()),
        'scene_components_dropped': int((~keep).sum()),
        # glove colours the scene itself shows: they stay glove, the segmenter's other cues
        # must tell them apart
        'colours_shared_with_scene': [row['name'] for row in rows
                                      if row['scene_claim_before'] > settings.max_claim],
    }
    metadata = {**start.metadata, 'source': source or 'scene calibration',
                'start_source': start.metadata.get('source', ''),
                'scene_calibration': {**summary, 'seed': seed,
                                      'settings': {k: v for k, v in vars(settings).items()},
                                      'refitted': refitted.tolist()}}
    cal = replace(start, lut=np.zeros(0, np.uint8), mixtures=mixtures, thresholds=thresholds,
                  reference_linear_rgb=reference, metadata=metadata)
    cal.lut = compile_lut(cal)
    # the light the segmenter divides out is estimated on its coarse frame, where patches mix
    # with their neighbours: reference colours seen that way keep that estimate at one here
    cal.reference_linear_rgb = _coarse_references(
        cal, [glove_frames[glove_index[i]] for i in frames_with_glove],
        [found.labels[i] for i in frames_with_glove],
        [found.gains[i] / typical_gains for i in frames_with_glove], segmenter.coarse_factor)
    for row in rows:   # the start at its light, the new calibration at the scene's
        c = row['class']
        for key, model, pix in (('start_agrees', start, _joined(corrected_class[c - 1])),
                                ('scene_agrees', cal, _joined(per_class[c - 1]))):
            pix = pix[::max(1, len(pix) // settings.max_pixels_per_class)]
            row[key] = float(np.mean(model.decide(pix) == c)) if len(pix) else float('nan')
    found_labels = {glove_index[i]: (found.labels[i] if found.labels[i] is not None
                                     else np.zeros(glove[i].shape[:2], np.uint8))
                    for i in _evenly_spaced(len(glove), picture_frames)}
    return SceneCalibration(cal, rows, summary, found_labels)
