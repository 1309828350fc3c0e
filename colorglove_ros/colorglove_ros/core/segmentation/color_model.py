"""The glove colour model (paper section 3): Chong-Gortler-Zickler features, one Gaussian mixture
per class, the RGB lookup table compiled from them, and its versioned file.

Fitting the model lives in ``calibration_fit.py``, the light-colour correction in ``light.py``."""
from __future__ import annotations

import functools
import json
import zipfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from colorglove_ros.core.colorimetry import linear_rgb_to_xyz, srgb_to_linear
from colorglove_ros.core.errors import ColorGloveError

__all__ = [
    'MAX_GLOVE_COLORS', 'CALIBRATION_FORMAT',
    'CALIBRATION_FORMAT_VERSION', 'CGZ_A', 'CGZ_B', 'CGZ_EPS',
    'FEATURE_KINDS', 'ColorCalibrationError', 'ColorCalibration', 'GaussianMixtureParams',
    'xyz_to_cgz', 'rgb_to_cgz', 'cgz_intensity_axis', 'cgz_chroma', 'rgb_features',
    'lut_index', 'index_tables', 'compile_lut', 'save_calibration', 'load_calibration',
    'read_calibration_config',
]

CALIBRATION_FORMAT = 'colorglove_color_calibration'
CALIBRATION_FORMAT_VERSION = 2   # 2: glove reference colours (light-colour correction)

#: Chong, Gortler and Zickler (2008): F(x) = A ln(B x), x linear XYZ.
CGZ_B = np.array([[0.9465229, 0.2946927, -0.1313419],
                  [-0.1179179, 0.9929960, 0.007371554],
                  [0.09230461, -0.04645794, 0.9946464]])
CGZ_A = np.array([[27.07439, -22.80783, -1.806681],
                  [-5.646736, -7.722125, 12.86503],
                  [-4.163133, -4.579428, -4.576049]])
#: Lower clamp of XYZ and of B x before the logarithm (linear units, white = 1).
CGZ_EPS = 1e-3

FEATURE_KINDS = ('chroma', 'cgz')


class ColorCalibrationError(ColorGloveError):
    """A colour calibration cannot be fitted, or its file is missing, corrupt or of another
    version."""


#: Most glove colours a calibration may have: the segmentation kernels keep a bit per label
#: in a 64-bit mask (``segmentation_kernel.label_boxes``), and label 0 is the background.
MAX_GLOVE_COLORS = 63

def xyz_to_cgz(xyz: np.ndarray, eps: float = CGZ_EPS) -> np.ndarray:
    """CIE XYZ (..., 3) -> CGZ space ``A ln(B x)``; XYZ and ``B x`` are clamped to >= eps."""
    x = np.maximum(np.asarray(xyz, dtype=np.float64), eps)
    return np.log(np.maximum(x @ CGZ_B.T, eps)) @ CGZ_A.T


def rgb_to_cgz(rgb: np.ndarray, eps: float = CGZ_EPS) -> np.ndarray:
    """sRGB (..., 3), uint8 (0..255) or float (0..1) -> CGZ coordinates (..., 3)."""
    arr = np.asarray(rgb)
    unit = arr / 255.0 if arr.dtype == np.uint8 else arr
    return xyz_to_cgz(linear_rgb_to_xyz(srgb_to_linear(unit)), eps)


def cgz_intensity_axis() -> np.ndarray:
    """Unit vector along which a change of light level (x -> k x) moves a CGZ point.

    ``A ln(B k x) = A ln(B x) + ln(k) A 1``, so the direction is ``A 1`` normalised.
    """
    v = CGZ_A @ np.ones(3)
    return v / np.linalg.norm(v)


def _chroma_basis() -> np.ndarray:
    v = cgz_intensity_axis()
    # Orthonormal basis: two chroma axes orthogonal to v, then v itself.
    q, _ = np.linalg.qr(np.column_stack([v, np.eye(3)[:, :2]]))
    basis = np.column_stack([q[:, 1], q[:, 2], v])
    return basis


_BASIS = _chroma_basis()


def cgz_chroma(cgz: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Split CGZ points (..., 3) into chroma (..., 2), invariant to the light level, and the
    intensity coordinate (...) along :func:`cgz_intensity_axis` (ln k times |A 1|)."""
    p = np.asarray(cgz, dtype=np.float64) @ _BASIS
    return p[..., :2], p[..., 2]


def rgb_features(rgb: np.ndarray, kind: str = 'chroma', intensity_weight: float = 0.1,
                 eps: float = CGZ_EPS) -> np.ndarray:
    """Classification features of sRGB colours (..., 3) -> (..., 3) float64.

    ``'cgz'``: the CGZ coordinates. ``'chroma'``: the two light-level-invariant CGZ chroma
    axes plus the intensity coordinate scaled by ``intensity_weight`` (so brightness changes
    move a colour little, yet black and white stay separable from saturated colours).
    """
    cgz = rgb_to_cgz(rgb, eps)
    if kind == 'cgz':
        return cgz
    if kind == 'chroma':
        p = cgz @ _BASIS
        p[..., 2] *= intensity_weight
        return p
    raise ColorCalibrationError(f'unknown feature kind {kind!r}; expected one of {FEATURE_KINDS}')


def lut_index(rgb: np.ndarray, bits: int, channel_table: np.ndarray | None = None
              ) -> np.ndarray:
    """Index into a (2^bits)^3 table of quantised RGB colours, for uint8 (..., 3) colours;
    ``channel_table`` (1, 256, 3) uint8 (e.g. :func:`gain_table`) maps each channel first,
    in the same pass as the quantisation (only for (H, W, 3) images)."""
    shift = 8 - bits
    if (channel_table is None and isinstance(rgb, np.ndarray) and rgb.ndim == 3
            and rgb.shape[2] == 3 and rgb.dtype == np.uint8):   # the same index, faster
        channel_table = _IDENTITY_TABLE
    if channel_table is not None:   # per plane, a table straight to its shifted index bits
        planes = cv2.split(rgb)
        idx = cv2.LUT(planes[0], _index_bits(channel_table, 0, bits))
        idx |= cv2.LUT(planes[1], _index_bits(channel_table, 1, bits))
        idx |= cv2.LUT(planes[2], _index_bits(channel_table, 2, bits))
        return idx
    q = np.asarray(rgb, dtype=np.uint8) >> shift
    idx = q[..., 0].astype(np.int32) << (2 * bits)
    idx |= q[..., 1].astype(np.int32) << bits
    idx |= q[..., 2]
    return idx


#: The channel table that changes nothing (1, 256, 3).
_IDENTITY_TABLE = np.repeat(np.arange(256, dtype=np.uint8)[None, :, None], 3, axis=2)


def _index_bits(channel_table: np.ndarray, channel: int, bits: int) -> np.ndarray:
    """int32 table: byte -> its mapped, quantised value at ``channel``'s place in the index."""
    quantised = channel_table[0, :, channel] >> (8 - bits)
    return quantised.astype(np.int32) << ((2 - channel) * bits)


def index_tables(bits: int, channel_table: np.ndarray | None = None) -> np.ndarray:
    """(3, 256) int32: per channel, a byte's part of :func:`lut_index`'s index (after
    ``channel_table``), so that a pixel's index is the OR of its three channels' parts."""
    if channel_table is None:
        return _identity_index_tables(bits)
    return np.stack([_index_bits(channel_table, channel, bits) for channel in range(3)])


@functools.lru_cache(maxsize=8)
def _identity_index_tables(bits: int) -> np.ndarray:
    tables = index_tables(bits, _IDENTITY_TABLE)
    tables.flags.writeable = False
    return tables


@dataclass(frozen=True)
class GaussianMixtureParams:
    """A fitted Gaussian mixture (full covariances) in feature space."""

    weights: np.ndarray      # (K,)
    means: np.ndarray        # (K, D)
    covariances: np.ndarray  # (K, D, D)

    def log_likelihood(self, x: np.ndarray) -> np.ndarray:
        """log p(x) for points (N, D)."""
        x = np.asarray(x, dtype=np.float64)
        out = np.empty((x.shape[0], len(self.weights)))
        for k, (w, mu, cov) in enumerate(zip(self.weights, self.means, self.covariances,
                                             strict=True)):
            chol = np.linalg.cholesky(cov)
            z = np.linalg.solve(chol, (x - mu).T)
            logdet = 2.0 * np.sum(np.log(np.diag(chol)))
            out[:, k] = (np.log(w) - 0.5 * np.sum(z * z, axis=0) - 0.5 * logdet
                         - 0.5 * x.shape[1] * np.log(2.0 * np.pi))
        m = out.max(axis=1)
        return m + np.log(np.exp(out - m[:, None]).sum(axis=1))


@dataclass
class ColorCalibration:
    """Per-class Gaussian mixtures (0 = background, 1..N glove colours) compiled into a LUT.

    ``lut`` has one uint8 label per quantised RGB colour; :meth:`classify` is one table read.
    """

    lut: np.ndarray
    bits: int
    num_colors: int
    feature_kind: str
    intensity_weight: float
    mixtures: list[GaussianMixtureParams]
    thresholds: np.ndarray  # (num_colors + 1,) min log-likelihood to accept a glove class
    log_priors: np.ndarray  # (num_colors + 1,)
    #: (num_colors, 3) mean linear RGB (0..1) of each glove colour's training pixels
    reference_linear_rgb: np.ndarray
    metadata: dict[str, Any] = field(default_factory=dict)

    def features(self, rgb: np.ndarray) -> np.ndarray:
        """Feature vectors of sRGB colours (..., 3)."""
        return rgb_features(rgb, self.feature_kind, self.intensity_weight)

    def log_likelihoods(self, rgb: np.ndarray) -> np.ndarray:
        """Per-class log-likelihoods (N, num_colors + 1) of uint8 colours (N, 3)."""
        f = self.features(np.asarray(rgb).reshape(-1, 3))
        return np.column_stack([g.log_likelihood(f) for g in self.mixtures])

    def decide(self, rgb: np.ndarray) -> np.ndarray:
        """Exact (non-quantised) decision for colours (N, 3) -> labels (N,) uint8."""
        ll = self.log_likelihoods(rgb)
        label = np.argmax(ll + self.log_priors, axis=1)
        rows = np.arange(len(label))
        reject = ll[rows, label] < self.thresholds[label]
        label[reject] = 0
        return label.astype(np.uint8)

    def classify(self, image_rgb: np.ndarray, channel_table: np.ndarray | None = None
                 ) -> np.ndarray:
        """Label every pixel of an (H, W, 3) uint8 RGB image -> (H, W) uint8 by table lookup,
        after the per-channel ``channel_table`` if given (see :func:`lut_index`)."""
        return self.lut.take(lut_index(image_rgb, self.bits, channel_table))  # take beats [ ]


def compile_lut(cal: ColorCalibration, chunk: int = 65536) -> np.ndarray:
    """The (2^bits)^3 uint8 table of ``cal``'s exact decision at each quantised colour's bin
    centre."""
    n = 1 << cal.bits
    step = 256 // n
    levels = (np.arange(n) * step + (step - 1) / 2.0)  # bin centres in 0..255
    grid = np.stack(np.meshgrid(levels, levels, levels, indexing='ij'), axis=-1).reshape(-1, 3)
    lut = np.empty(len(grid), dtype=np.uint8)
    for s in range(0, len(grid), chunk):
        lut[s:s + chunk] = cal.decide(grid[s:s + chunk] / 255.0)
    return lut


def save_calibration(cal: ColorCalibration, path: str | Path) -> Path:
    """Write a calibration as a versioned ``.npz`` file."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    arrays: dict[str, np.ndarray] = {
        'format': np.array(CALIBRATION_FORMAT), 'version': np.array(CALIBRATION_FORMAT_VERSION),
        'lut': cal.lut, 'bits': np.array(cal.bits), 'num_colors': np.array(cal.num_colors),
        'feature_kind': np.array(cal.feature_kind),
        'intensity_weight': np.array(cal.intensity_weight),
        'thresholds': cal.thresholds, 'log_priors': cal.log_priors,
        'reference_linear_rgb': cal.reference_linear_rgb,
        'metadata_json': np.array(json.dumps(cal.metadata)),
    }
    for c, g in enumerate(cal.mixtures):
        arrays[f'gmm{c}_weights'] = g.weights
        arrays[f'gmm{c}_means'] = g.means
        arrays[f'gmm{c}_covariances'] = g.covariances
    with path.open('wb') as fh:
        np.savez_compressed(fh, **arrays)
    return path


def load_calibration(path: str | Path) -> ColorCalibration:
    """Read a calibration written by :func:`save_calibration`; raise ColorCalibrationError if it
    is missing, corrupt or of another format version."""
    path = Path(path)
    if not path.is_file():
        raise ColorCalibrationError(f'colour calibration file not found: {path}')
    try:
        with np.load(path, allow_pickle=False) as z:
            data = {k: z[k] for k in z.files}
    except (OSError, ValueError, zipfile.BadZipFile, EOFError) as exc:
        raise ColorCalibrationError(f'cannot read colour calibration {path}: {exc}') from exc
    if str(data.get('format', '')) != CALIBRATION_FORMAT:
        raise ColorCalibrationError(f'{path} is not a colour calibration file')
    version = int(data.get('version', -1))
    if version != CALIBRATION_FORMAT_VERSION:
        raise ColorCalibrationError(
            f'{path} has format version {version}, expected {CALIBRATION_FORMAT_VERSION}; '
            're-run colorglove_calibrate_colors')
    try:
        bits = int(data['bits'])
        num_colors = int(data['num_colors'])
        if not 1 <= num_colors <= MAX_GLOVE_COLORS:
            raise ColorCalibrationError(f'{path} has {num_colors} glove colours; the segmenter '
                                        f'takes 1 to at most {MAX_GLOVE_COLORS}')
        mixtures = [GaussianMixtureParams(data[f'gmm{c}_weights'], data[f'gmm{c}_means'],
                                          data[f'gmm{c}_covariances'])
                    for c in range(num_colors + 1)]
        cal = ColorCalibration(
            lut=data['lut'].astype(np.uint8), bits=bits, num_colors=num_colors,
            feature_kind=str(data['feature_kind']),
            intensity_weight=float(data['intensity_weight']), mixtures=mixtures,
            thresholds=data['thresholds'].astype(np.float64),
            log_priors=data['log_priors'].astype(np.float64),
            reference_linear_rgb=data['reference_linear_rgb'].astype(np.float64),
            metadata=json.loads(str(data['metadata_json'])))
    except (KeyError, ValueError, TypeError) as exc:
        raise ColorCalibrationError(f'corrupt colour calibration {path}: {exc}') from exc
    if (cal.lut.shape != (1 << (3 * bits),) or cal.lut.max(initial=0) > num_colors
            or cal.reference_linear_rgb.shape != (num_colors, 3)):
        raise ColorCalibrationError(
            f'corrupt colour calibration {path}: bad lookup table or reference colours')
    return cal


def read_calibration_config(config_path: str | Path) -> dict[str, Any]:
    """Read ``config/color_calibration.yaml``: ``calibration_file`` (resolved to an absolute
    path) and the ``segmenter`` settings (a dict, possibly empty)."""
    from colorglove_ros.core.validation import check_known_keys
    from colorglove_ros.core.yaml_io import load_yaml_mapping
    from colorglove_ros.paths import resolve_path

    path = resolve_path(config_path)
    cfg = load_yaml_mapping(path, ColorCalibrationError, 'colour calibration config')
    if not isinstance(cfg.get('calibration_file'), str) or not cfg['calibration_file']:
        raise ColorCalibrationError(f'{path}: missing key calibration_file (a path)')
    check_known_keys(str(path), cfg, ('calibration_file', 'segmenter'),
                     error=ColorCalibrationError)
    segmenter = cfg.get('segmenter') or {}
    if not isinstance(segmenter, dict):
        raise ColorCalibrationError(f'{path}: segmenter must be a mapping')
    return {'calibration_file': resolve_path(str(cfg['calibration_file'])),
            'segmenter': dict(segmenter), 'config_path': path}
