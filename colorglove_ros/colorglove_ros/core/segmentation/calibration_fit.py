"""Fit the glove colour model from labelled frames: sample each class's pixels, re-light them
(light level, black-body light colour, white-balance error, noise), fit one Gaussian mixture
per class and compile the lookup table; read and write labelled frames (PNG pairs), render
synthetic training frames, and fit and save a calibration file from either."""
from __future__ import annotations

import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from colorglove_ros.core.colorimetry import linear_to_srgb, srgb_to_linear
from colorglove_ros.core.conventions import NUM_COLORS
from colorglove_ros.core.segmentation.color_model import (
    FEATURE_KINDS,
    ColorCalibration,
    ColorCalibrationError,
    GaussianMixtureParams,
    compile_lut,
    read_calibration_config,
    rgb_features,
    save_calibration,
)
from colorglove_ros.core.segmentation.light import planckian_illuminants
from colorglove_ros.paths import resolve_path

__all__ = ['RESIDUAL_TEMPERATURES_K', 'DEFAULT_LUT_BITS', 'DEFAULT_MAX_PIXELS_PER_CLASS',
           'MIN_FRAMES', 'MASK_SUFFIX', 'SYNTHETIC_FRAMES_DIR', 'fit_color_calibration',
           'read_labelled_frames', 'write_labelled_frames', 'render_training_frames',
           'CalibrationFit', 'calibrate_frames', 'calibrate_synthetic', 'relit_copies',
           'processed_copies', 'PROCESSING_GROUPS', 'DEFAULT_PROCESSED_COPIES',
           'DEFAULT_PROCESSED_COLORS', 'fit_mixture', 'FIRST_USE_FRAMES',
           'DEFAULT_COLOR_CONFIG', 'prepared_color_config']

DEFAULT_LUT_BITS = 6                  # lookup table bits per RGB channel
DEFAULT_MAX_PIXELS_PER_CLASS = 5000   # training pixels sampled per class
PROCESSING_GROUPS = 16                # colour-processing draws per processed copy
# re-lit copies of the training pixels seen through other cameras' colour processing (off: it
# helps some camera looks and costs others, docs/RESULTS.md issue 14), for the background and
# these glove colours (1-based classes): yellow and lime, the colours other cameras wash out
# past the plain model (every colour also takes warm photo backgrounds, wood, as glove)
DEFAULT_PROCESSED_COPIES = 0
DEFAULT_PROCESSED_COLORS: tuple[int, ...] = (4, 10)
MIN_FRAMES = 8                        # labelled frames a fit needs at least
MASK_SUFFIX = '_mask'                 # NAME.png (RGB image) + NAME_mask.png (labels)
# where rendered training frames are written by default (relative to the working folder)
SYNTHETIC_FRAMES_DIR = Path('data/color_calibration_frames')
FIRST_USE_FRAMES = 12                 # rendered training frames of a missing default calibration
DEFAULT_COLOR_CONFIG = 'config/color_calibration.yaml'   # the package's colour config


def _sample_pixels(frames: Sequence[tuple[np.ndarray, np.ndarray]], num_colors: int,
                   max_per_class: int, erode: int, rng: np.random.Generator,
                   ) -> list[np.ndarray]:
    per_class: list[list[np.ndarray]] = [[] for _ in range(num_colors + 1)]
    kernel = np.ones((2 * erode + 1, 2 * erode + 1), np.uint8) if erode > 0 else None
    for i, (image, mask) in enumerate(frames):
        image = np.asarray(image)
        mask = np.asarray(mask)
        if image.dtype != np.uint8 or image.ndim != 3 or image.shape[2] != 3:
            raise ColorCalibrationError(
                f'frame {i}: image must be (H, W, 3) uint8, got {image.shape} {image.dtype}')
        if mask.shape != image.shape[:2]:
            raise ColorCalibrationError(
                f'frame {i}: mask shape {mask.shape} != image shape {image.shape[:2]}')
        if mask.max(initial=0) > num_colors:
            raise ColorCalibrationError(
                f'frame {i}: mask label {int(mask.max())} > num_colors {num_colors}')
        mask = mask.astype(np.uint8)
        for c in range(num_colors + 1):
            m = (mask == c).astype(np.uint8)
            if kernel is not None:
                m = cv2.erode(m, kernel)  # drop mixed pixels on patch borders
            pix = image[m.astype(bool)]
            if len(pix):
                per_class[c].append(pix)
    out = []
    for c, chunks in enumerate(per_class):
        if not chunks:
            raise ColorCalibrationError(f'no training pixels for class {c}')
        pix = np.concatenate(chunks)
        if len(pix) > max_per_class:
            pix = pix[rng.choice(len(pix), max_per_class, replace=False)]
        out.append(pix)
    return out


#: Colour temperatures the calibration is re-lit under by default: the segmenter divides the
#: frame's light colour out first (:func:`estimate_light_gains`), so the classes need only
#: cover what that leaves (estimation error, light mixed with ambient), not all of
#: :data:`LIGHT_TEMPERATURES_K`; the narrower classes keep magenta and purple, orange and
#: yellow apart. Tuned on evaluation seeds 777 and 2024 (4500-10000 K; 5000-9000 K did as
#: well, 6000-7000 K and 3300-20000 K worse).
RESIDUAL_TEMPERATURES_K = (4500.0, 10000.0)


def _augment(pix: np.ndarray, rng: np.random.Generator, light: tuple[float, float],
             white_balance: float, illuminants: np.ndarray | None, noise: float) -> np.ndarray:
    """Re-light sRGB pixels: random level, light colour (a random row of ``illuminants``,
    linear RGB gains) and per-channel gains in linear RGB, plus noise."""
    lin = srgb_to_linear(pix / 255.0)
    k = np.exp(rng.uniform(np.log(light[0]), np.log(light[1]), (len(pix), 1)))
    gains = k * np.exp(rng.uniform(-white_balance, white_balance, (len(pix), 3)))
    if illuminants is not None:
        gains *= illuminants[rng.integers(len(illuminants), size=len(pix))]
    srgb = 255.0 * linear_to_srgb(lin * gains)
    srgb += rng.normal(0.0, noise, srgb.shape)
    return np.clip(np.round(srgb), 0, 255).astype(np.uint8)


def relit_copies(pix: np.ndarray, rng: np.random.Generator, copies: int,
                 light: tuple[float, float], white_balance: float,
                 illuminants: np.ndarray | None, noise: float) -> np.ndarray:
    """sRGB pixels (N, 3) uint8 followed by ``copies`` re-lit copies of them: each pixel under
    a random light level in ``light``, a random row of ``illuminants`` (linear RGB gains,
    e.g. :func:`planckian_illuminants`; None for none), per-channel gains
    ``exp(+-white_balance)`` and Gaussian noise of ``noise`` levels."""
    if copies <= 0:
        return pix
    return np.concatenate([pix] + [_augment(pix, rng, light, white_balance, illuminants, noise)
                                   for _ in range(copies)])


def processed_copies(pix: np.ndarray, rng: np.random.Generator, copies: int,
                     light: tuple[float, float], white_balance: float,
                     illuminants: np.ndarray | None, noise: float,
                     groups: int = PROCESSING_GROUPS) -> np.ndarray:
    """``copies`` copies of sRGB pixels (N, 3) uint8, each re-lit as :func:`relit_copies` does
    and then seen through another camera's colour processing (white-balance error, saturation,
    gamma and contrast drawn by :func:`sample_color_processing`, applied by
    :func:`camera_encode` as the evaluation's cameras do), ``groups`` draws per copy over
    random groups of the pixels; (0, 3) for no copies."""
    from colorglove_ros.core.synthetic.conditions import FrameConditions, sample_color_processing
    from colorglove_ros.core.synthetic.frames import camera_encode

    out = []
    for _ in range(copies):
        lin = srgb_to_linear(_augment(pix, rng, light, white_balance, illuminants, noise)
                             / 255.0).astype(np.float32)
        processed = np.empty_like(pix)
        for idx in np.array_split(rng.permutation(len(pix)), groups):
            look = FrameConditions(**sample_color_processing(rng))
            processed[idx] = camera_encode(lin[idx][:, None, :], look)[:, 0, :]
        out.append(processed)
    return np.concatenate(out) if out else np.zeros((0, 3), np.uint8)


def fit_mixture(features: np.ndarray, components: int, reg_covar: float,
                seed: int) -> GaussianMixtureParams:
    """A Gaussian mixture of ``components`` full-covariance components fitted to ``features``
    (N, D) by EM (scikit-learn, ``reg_covar`` added to every covariance's diagonal)."""
    from sklearn.mixture import GaussianMixture

    gmm = GaussianMixture(n_components=components, covariance_type='full',
                          reg_covar=reg_covar, random_state=seed, max_iter=200).fit(features)
    return GaussianMixtureParams(gmm.weights_.copy(), gmm.means_.copy(),
                                 gmm.covariances_.copy())


def fit_color_calibration(frames: Sequence[tuple[np.ndarray, np.ndarray]],
                          num_colors: int = NUM_COLORS,
                          components: int = 3, background_components: int = 12,
                          feature_kind: str = 'chroma', intensity_weight: float = 0.1,
                          bits: int = DEFAULT_LUT_BITS, background_prior: float = 0.5,
                          reject_quantile: float = 1e-4,
                          max_per_class: int = DEFAULT_MAX_PIXELS_PER_CLASS,
                          erode: int = 1, glove_covariance_floor: float = 1.0,
                          augment_copies: int = 2, augment_light: tuple[float, float] = (0.4, 1.8),
                          augment_white_balance: float = 0.15,
                          augment_temperatures_k: tuple[float, float] | None = (
                              RESIDUAL_TEMPERATURES_K),
                          augment_noise: float = 3.0,
                          augment_processed_copies: int = DEFAULT_PROCESSED_COPIES,
                          augment_processed_colors: Sequence[int] | None = DEFAULT_PROCESSED_COLORS,
                          seed: int = 0, min_frames: int = MIN_FRAMES,
                          metadata: Mapping[str, Any] | None = None) -> ColorCalibration:
    """Fit one Gaussian mixture per glove colour and one for the background, build the LUT.

    ``frames`` are (image (H, W, 3) uint8 RGB, label mask (H, W), 0 = background). The
    training pixels of every class are augmented with ``augment_copies`` re-lit copies (light
    level in ``augment_light``; light colour a black body in ``augment_temperatures_k``, see
    :func:`planckian_illuminants`, None for none; residual per-channel gains
    ``exp(+-augment_white_balance)``, camera white-balance error; noise)
    so a few labelled frames cover other light levels and colour temperatures, plus
    ``augment_processed_copies`` re-lit copies seen through other cameras' colour processing
    (:func:`processed_copies`: washed-out or over-saturated glove colours) for the glove
    colours ``augment_processed_colors`` (1-based classes; None: every colour); the
    background is augmented alike, or the widened glove classes would claim its pixels.
    Glove covariances get ``glove_covariance_floor`` added to their diagonal. A glove class
    is accepted only where its likelihood is above the ``reject_quantile`` quantile of its
    own training pixels, so unseen colours fall to background. The mean linear RGB of each
    glove colour's (not re-lit) training pixels is kept as its reference colour, the light
    the segmenter corrects frames to.
    """
    if feature_kind not in FEATURE_KINDS:
        raise ColorCalibrationError(f'unknown feature kind {feature_kind!r}')
    if len(frames) < min_frames:
        raise ColorCalibrationError(
            f'need at least {min_frames} labelled frames, got {len(frames)}')
    if not 1 <= bits <= 8:
        raise ColorCalibrationError(f'bits must be in 1..8, got {bits}')
    illuminants = (None if augment_temperatures_k is None
                   else planckian_illuminants(*augment_temperatures_k))
    rng = np.random.default_rng(seed)
    samples = _sample_pixels(frames, num_colors, max_per_class, erode, rng)
    reference = np.array([srgb_to_linear(pix / 255.0).mean(axis=0) for pix in samples[1:]])
    mixtures: list[GaussianMixtureParams] = []
    thresholds = np.full(num_colors + 1, -np.inf)
    counts = []
    processed = {c: augment_processed_copies for c in range(num_colors + 1)
                 if c == 0 or augment_processed_colors is None or c in augment_processed_colors}
    for c, pix in enumerate(samples):
        counts.append(len(pix))
        augmented = (augment_light, augment_white_balance, illuminants, augment_noise)
        pix = np.concatenate([relit_copies(pix, rng, augment_copies, *augmented),
                              processed_copies(pix, rng, processed.get(c, 0), *augmented)])
        feats = rgb_features(pix, feature_kind, intensity_weight)
        k = background_components if c == 0 else components
        k = max(1, min(k, len(np.unique(pix, axis=0))))
        params = fit_mixture(feats, k, 1e-1 if c == 0 else glove_covariance_floor, seed)
        mixtures.append(params)
        if c > 0:
            thresholds[c] = float(np.quantile(params.log_likelihood(feats), reject_quantile))
    priors = np.full(num_colors + 1, (1.0 - background_prior) / num_colors)
    priors[0] = background_prior
    meta = {'num_frames': len(frames), 'pixels_per_class': counts, 'components': components,
            'background_components': background_components, 'reject_quantile': reject_quantile,
            'background_prior': background_prior, 'augment_copies': augment_copies,
            'augment_light': list(augment_light), 'augment_white_balance': augment_white_balance,
            'augment_temperatures_k': None if augment_temperatures_k is None
            else list(augment_temperatures_k),
            'augment_processed_copies': augment_processed_copies,
            'augment_processed_colors': None if augment_processed_colors is None
            else [int(c) for c in augment_processed_colors],
            'glove_covariance_floor': glove_covariance_floor, 'seed': seed,
            **dict(metadata or {})}
    cal = ColorCalibration(lut=np.zeros(0, np.uint8), bits=bits, num_colors=num_colors,
                           feature_kind=feature_kind, intensity_weight=intensity_weight,
                           mixtures=mixtures, thresholds=thresholds, log_priors=np.log(priors),
                           reference_linear_rgb=reference, metadata=meta)
    cal.lut = compile_lut(cal)
    return cal


# ---------------------------------------------------------------------------- labelled frames
def read_labelled_frames(folder: str | Path) -> list[tuple[np.ndarray, np.ndarray]]:
    """Read every ``NAME.png`` + ``NAME_mask.png`` pair in a folder (sorted by name): the RGB
    camera image and its single-channel 8-bit labels (0 background, 1..10 glove colour)."""
    folder = Path(folder)
    if not folder.is_dir():
        raise ColorCalibrationError(f'frame folder not found: {folder}')
    frames = []
    for mask_path in sorted(folder.glob(f'*{MASK_SUFFIX}.png')):
        image_path = mask_path.with_name(mask_path.name[:-len(MASK_SUFFIX) - 4] + '.png')
        if not image_path.is_file():
            raise ColorCalibrationError(f'{mask_path} has no image {image_path.name}')
        bgr = cv2.imread(str(image_path), cv2.IMREAD_COLOR)
        mask = cv2.imread(str(mask_path), cv2.IMREAD_UNCHANGED)
        if bgr is None or mask is None:
            raise ColorCalibrationError(f'cannot read {image_path} or {mask_path}')
        if mask.ndim != 2 or mask.dtype != np.uint8:
            raise ColorCalibrationError(f'{mask_path} must be a single-channel 8-bit PNG')
        frames.append((np.ascontiguousarray(bgr[..., ::-1]), mask))
    return frames


def write_labelled_frames(folder: str | Path,
                          frames: Sequence[tuple[np.ndarray, np.ndarray]]) -> list[Path]:
    """Write (image RGB, labels) pairs as ``frame_NNNN.png`` + ``frame_NNNN_mask.png``."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    paths = []
    for i, (rgb, mask) in enumerate(frames):
        p = folder / f'frame_{i:04d}.png'
        cv2.imwrite(str(p), np.ascontiguousarray(rgb[..., ::-1]))
        cv2.imwrite(str(folder / f'frame_{i:04d}{MASK_SUFFIX}.png'), mask.astype(np.uint8))
        paths.append(p)
    return paths


def render_training_frames(count: int, seed: int, split: str = 'train'
                           ) -> list[tuple[np.ndarray, np.ndarray]]:
    """Render ``count`` synthetic (image, labels) frames, hand fully in view
    (``core.synthetic.frames``) under ``split`` imaging conditions."""
    from colorglove_ros.core.synthetic import frames as synth
    from colorglove_ros.core.synthetic.conditions import sample_conditions

    rng = np.random.default_rng(seed)
    camera = synth.default_camera()
    frames = []
    for _ in range(count):
        q = synth.sample_pose(rng, camera, out_of_frame_prob=0.0)
        frame = synth.render_frame(q, camera, rng, sample_conditions(rng, split))
        frames.append((frame.image_rgb, frame.labels))
    return frames


# ---------------------------------------------------------------------------- calibration file
@dataclass(frozen=True)
class CalibrationFit:
    """A calibration fitted and saved: the model, the file, the frames it was fitted on and
    the fit time (seconds, LUT included)."""

    calibration: ColorCalibration
    output: Path
    frames: list[tuple[np.ndarray, np.ndarray]]
    fit_s: float


def calibrate_frames(frames: Sequence[tuple[np.ndarray, np.ndarray]], output: str | Path,
                     source: str, *, seed: int = 0, **options: Any) -> CalibrationFit:
    """Fit the colour calibration on labelled ``frames`` (:func:`fit_color_calibration` with
    ``options``; ``source`` is recorded in its metadata) and save it at ``output``."""
    started = time.perf_counter()
    calibration = fit_color_calibration(frames, seed=seed, metadata={'source': source},
                                        **options)
    fit_s = time.perf_counter() - started
    return CalibrationFit(calibration, save_calibration(calibration, output), list(frames),
                          fit_s)


def calibrate_synthetic(count: int, output: str | Path, frames_out: str | Path, *,
                        seed: int = 0, **options: Any) -> CalibrationFit:
    """Render ``count`` synthetic 'train' frames (:func:`render_training_frames`), write them
    to ``frames_out`` as labelled pairs, and fit and save the calibration at ``output``
    (:func:`calibrate_frames`)."""
    if count < 1:
        raise ColorCalibrationError(f'need at least one synthetic frame, got {count}')
    frames = render_training_frames(count, seed)
    write_labelled_frames(frames_out, frames)
    return calibrate_frames(frames, output, f'synthetic train frames, seed {seed} ({frames_out})',
                            seed=seed, **options)


def prepared_color_config(color_config: str | Path | None = None,
                          progress: Callable[[str], None] = print) -> Path:
    """The colour config to run with: ``color_config`` as given (its calibration file is the
    user's to make; a missing one is the segmenter's error), or without it the package's
    :data:`DEFAULT_COLOR_CONFIG`, whose calibration file is fitted first on
    :data:`FIRST_USE_FRAMES` rendered training frames (seed 0, :func:`calibrate_synthetic`) if it
    is missing, saying so through ``progress``."""
    if color_config:
        return Path(color_config)
    config = resolve_path(DEFAULT_COLOR_CONFIG)
    calibration_file = Path(read_calibration_config(str(config))['calibration_file'])
    if not calibration_file.is_file():
        progress(f'no colour calibration at {calibration_file}: calibrating from '
                 f'{FIRST_USE_FRAMES} rendered training frames (once)')
        fit = calibrate_synthetic(FIRST_USE_FRAMES, calibration_file, SYNTHETIC_FRAMES_DIR)
        progress(f'colour calibration saved at {fit.output} ({fit.fit_s:.1f} s)')
    return config
