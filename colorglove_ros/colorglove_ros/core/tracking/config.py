"""Tracker options and the IK covariances R, Q, P: defaults, ``config/ik.yaml`` and the versioned
covariance files."""
from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from colorglove_ros.core.hand.model import DOF_NAMES, NUM_DOFS
from colorglove_ros.core.tracking.types import IKError
from colorglove_ros.core.validation import check_known_keys, check_number
from colorglove_ros.core.yaml_io import load_yaml_mapping

__all__ = [
    'IK_CONFIG_VERSION', 'COVARIANCE_FORMAT', 'COVARIANCE_VERSION', 'TRACKER_MODES',
    'CONSTRAINT_MODELS', 'IKConfigError', 'IKCovariances', 'IKConfig', 'default_covariances',
    'save_covariances', 'load_covariances', 'load_ik_config',
]

IK_CONFIG_VERSION = 1
COVARIANCE_FORMAT = 'colorglove_ik_covariances'
COVARIANCE_VERSION = 1
TRACKER_MODES = ('blend', 'ik', 'ik_smooth')
CONSTRAINT_MODELS = ('vertex', 'patch')


MAX_VARIANCE = 1e8
"""Larger variances (px^2, m^2, rad^2) mean 'no information': written as a corrupt value."""


class IKConfigError(IKError):
    """An IK configuration or covariance file is missing, malformed or of another version."""


@dataclass(frozen=True)
class IKCovariances:
    """Diagonal covariances: R per pixel axis (px^2), Q (blended pose error) and P
    (frame-to-frame deviation) per DOF in m^2 / rad^2."""

    r_var_px2: np.ndarray
    q_var: np.ndarray
    p_var: np.ndarray
    source: str = 'defaults'

    def __post_init__(self) -> None:
        try:
            r = np.asarray(self.r_var_px2, float).reshape(-1)
            q = np.asarray(self.q_var, float).reshape(-1)
            p = np.asarray(self.p_var, float).reshape(-1)
        except (TypeError, ValueError) as exc:
            raise IKConfigError(f'covariances must be lists of numbers: {exc}') from exc
        if r.size == 1:
            r = np.repeat(r, 2)
        if r.shape != (2,) or q.shape != (NUM_DOFS,) or p.shape != (NUM_DOFS,):
            raise IKConfigError(f'covariances need r (2), q (26), p (26); got {r.shape}, '
                                f'{q.shape}, {p.shape}')
        for name, v in (('r_var_px2', r), ('q_var', q), ('p_var', p)):
            if not np.all(np.isfinite(v)) or np.any(v <= 0) or np.any(v > MAX_VARIANCE):
                raise IKConfigError(f'{name} must be finite, positive and <= {MAX_VARIANCE:g}, '
                                    f'got {v.tolist()}')
        object.__setattr__(self, 'r_var_px2', r)
        object.__setattr__(self, 'q_var', q)
        object.__setattr__(self, 'p_var', p)


def _group_std(entry: Any, where: str) -> np.ndarray:
    """26 standard deviations from {translation_m: 3|1, rotation_rad: 3|1, fingers_rad: 20|1}."""
    if not isinstance(entry, dict):
        raise IKConfigError(f'{where} must be a mapping with translation_m, rotation_rad, '
                            'fingers_rad')
    out = []
    for key, n in (('translation_m', 3), ('rotation_rad', 3), ('fingers_rad', 20)):
        try:
            v = np.asarray(entry[key], dtype=float).reshape(-1)
        except (KeyError, TypeError, ValueError) as exc:
            raise IKConfigError(f'{where}.{key} missing or not numeric: {exc}') from exc
        if v.size == 1:
            v = np.repeat(v, n)
        if v.size != n:
            raise IKConfigError(f'{where}.{key} needs 1 or {n} values, got {v.size}')
        out.append(v)
    return np.concatenate(out)


def default_covariances() -> IKCovariances:
    """Hand-set covariances used when no learned file is given (same as config/ik.yaml)."""
    q_std = np.concatenate([[0.03, 0.03, 0.08], [0.2] * 3, [0.25] * 20])
    p_std = np.concatenate([[0.01, 0.01, 0.015], [0.06] * 3, [0.12] * 20])
    return IKCovariances(np.array([3.0**2, 3.0**2]), q_std**2, p_std**2)


def save_covariances(path: str | Path, cov: IKCovariances, **provenance: Any) -> Path:
    """Write learned covariances to a versioned YAML file."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    data = {
        'format': COVARIANCE_FORMAT, 'version': COVARIANCE_VERSION,
        'dof_names': list(DOF_NAMES),
        'r_var_px2': [float(v) for v in cov.r_var_px2],
        'q_var': [float(v) for v in cov.q_var],
        'p_var': [float(v) for v in cov.p_var],
        'provenance': {k: (v if isinstance(v, (int, float, str, bool)) else str(v))
                       for k, v in provenance.items()},
    }
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return path


def load_covariances(path: str | Path) -> IKCovariances:
    """Read a covariance file written by :func:`save_covariances`; raise
    :class:`IKConfigError` naming what is wrong."""
    path = Path(path)
    data = load_yaml_mapping(path, IKConfigError, 'IK covariance file')
    if data.get('format') != COVARIANCE_FORMAT:
        raise IKConfigError(f'{path} is not a {COVARIANCE_FORMAT} file')
    if data.get('version') != COVARIANCE_VERSION:
        raise IKConfigError(f'{path} has version {data.get("version")!r}, '
                            f'expected {COVARIANCE_VERSION}')
    if list(data.get('dof_names', [])) != list(DOF_NAMES):
        raise IKConfigError(f'{path}: dof_names do not match the 26-DOF hand model')
    check_known_keys(str(path), data, ('format', 'version', 'dof_names', 'r_var_px2', 'q_var',
                                       'p_var', 'provenance'), error=IKConfigError)
    try:
        return IKCovariances(data['r_var_px2'], data['q_var'], data['p_var'], source=str(path))
    except KeyError as exc:
        raise IKConfigError(f'{path}: missing field {exc}') from exc
    except (TypeError, ValueError, IKConfigError) as exc:
        raise IKConfigError(f'{path}: bad values: {exc}') from exc


@dataclass(frozen=True)
class IKConfig:
    """Tracker options (see ``config/ik.yaml`` for the meaning of each). Every pixel setting
    (R, the gates, ``outlier_px``, ``min_blob_pixels``) is in pixels of a camera whose focal
    length is ``reference_focal_px``; each camera uses them scaled by its own focal length
    (``projection.pixel_scale``), so the pose does not depend on the image resolution."""

    enable_ik: bool = True
    enable_smoothing: bool = True
    max_iterations: int = 3
    multi_camera_iterations: int = 2
    refine_iterations: int = 2
    lambda_init: float = 1e-3
    step_tol: float = 1e-5
    cost_tol: float = 1e-4
    init_translation: bool = True
    shape_at_previous_pose: bool = False
    min_constraints: int = 3
    min_blob_pixels: int = 4
    gate_tiny_px: float = 8.0
    gate_min_px: float = 10.0
    max_blob_ratio: float = 0.0
    extra_gate_px: float = 30.0
    extra_shift_max_px: float = 150.0
    extra_inlier_px: float = 15.0
    extra_rematch: bool = False
    outlier_px: float = 20.0
    max_gap_s: float = 0.25
    min_depth_m: float = 0.05
    constraint_model: str = 'patch'
    reference_focal_px: float = 600.0
    finger_spread_gain: float = 1.0
    finger_spread_floor_rad: float = 0.13
    line_features: bool = False
    line_std_px: float = 2.0
    covariances: IKCovariances = field(default_factory=default_covariances)

    def with_mode(self, mode: str) -> IKConfig:
        """The evaluation variants: 'blend' (blended NN only), 'ik', 'ik_smooth'."""
        if mode not in TRACKER_MODES:
            raise IKConfigError(f'unknown tracker mode {mode!r}, expected one of {TRACKER_MODES}')
        return replace(self, enable_ik=mode != 'blend', enable_smoothing=mode == 'ik_smooth')

    def __post_init__(self) -> None:
        if self.constraint_model not in CONSTRAINT_MODELS:
            raise IKConfigError(f'constraint_model must be one of {CONSTRAINT_MODELS}, got '
                                f'{self.constraint_model!r}')
        for name in _SWITCHES:
            if not isinstance(getattr(self, name), bool):
                raise IKConfigError(f'{name} must be true or false, got '
                                    f'{getattr(self, name)!r}')
        for name, (kind, low, high, low_open) in _NUMBER_LIMITS.items():
            value = check_number(name, getattr(self, name), low=low, high=high,
                                 low_open=low_open, integer=kind is int, error=IKConfigError)
            object.__setattr__(self, name, value)
        if not isinstance(self.covariances, IKCovariances):
            raise IKConfigError(f'covariances must be IKCovariances, got {self.covariances!r}')

    def prior_covariances(self, finger_std: np.ndarray | None) -> IKCovariances:
        """The covariances for one frame: with ``finger_spread_gain`` > 0 and the lookup's
        per-finger spread (20,), each finger DOF's Q variance is max(floor^2, gain *
        spread^2), so the prior holds a finger the neighbours agree on and lets the image
        move one they disagree on (this replaces the configured or learned finger Q);
        otherwise the configured Q."""
        if finger_std is None or self.finger_spread_gain <= 0:
            return self.covariances
        spread = np.asarray(finger_std, float).reshape(-1)
        if spread.shape != (NUM_DOFS - 6,) or not np.all(np.isfinite(spread)):
            raise IKError(f'finger spread must be 20 finite values, got shape {spread.shape}')
        q_var = self.covariances.q_var.copy()
        q_var[6:] = np.maximum(self.finger_spread_floor_rad ** 2,
                               self.finger_spread_gain * spread ** 2)
        return replace(self.covariances, q_var=q_var)


# Tracker switches set by the caller (ik_node parameters, the tools' --modes), never by the file:
# two homes for one switch let one silently win.
_CALLER_SWITCHES = ('enable_ik', 'enable_smoothing')
_SWITCHES = ('enable_ik', 'enable_smoothing', 'init_translation',
             'shape_at_previous_pose', 'extra_rematch', 'line_features')
_NUMBER_LIMITS: dict[str, tuple[type, float, float, bool]] = {
    # name: (int or float, lowest, highest, lowest excluded)
    'line_std_px': (float, 0.0, 1e3, True),
    'max_iterations': (int, 1, 100, False), 'multi_camera_iterations': (int, 0, 100, False),
    'refine_iterations': (int, 0, 100, False), 'lambda_init': (float, 0.0, 1e6, True),
    'step_tol': (float, 0.0, 1.0, True), 'cost_tol': (float, 0.0, 1.0, True),
    'min_constraints': (int, 1, 1000, False), 'min_blob_pixels': (int, 1, 1_000_000, False),
    'gate_tiny_px': (float, 0.0, 1e4, False), 'gate_min_px': (float, 0.0, 1e4, False),
    'max_blob_ratio': (float, 0.0, 1e4, False),
    'extra_gate_px': (float, 0.0, 1e4, False), 'extra_shift_max_px': (float, 0.0, 1e4, False),
    'extra_inlier_px': (float, 0.0, 1e4, False), 'outlier_px': (float, 0.0, 1e4, False),
    'max_gap_s': (float, 0.0, 3600.0, True), 'min_depth_m': (float, 0.0, 10.0, True),
    'reference_focal_px': (float, 0.0, 1e5, True),
    'finger_spread_gain': (float, 0.0, 1e3, False),
    'finger_spread_floor_rad': (float, 0.0, math.pi, True),
}
"""Every number of :class:`IKConfig` with the range the tracker can run with."""
_FILE_SETTINGS = (*(name for name in _SWITCHES if name not in _CALLER_SWITCHES),
                  *_NUMBER_LIMITS, 'constraint_model')


def load_ik_config(path: str | Path) -> IKConfig:
    """Read ``config/ik.yaml``; a non-empty ``covariance_file`` (relative to the YAML's
    folder or absolute) overrides the default covariances written in the file."""
    path = Path(path)
    data = load_yaml_mapping(path, IKConfigError, 'IK config file')
    if data.get('version') != IK_CONFIG_VERSION:
        raise IKConfigError(f'IK config {path} has version {data.get("version")!r}, '
                            f'expected {IK_CONFIG_VERSION}')
    switches = sorted(set(data) & set(_CALLER_SWITCHES))
    if switches:
        raise IKConfigError(f'IK config {path}: {switches} are not IK file settings: set them as '
                            'ik_node parameters (config/nodes.yaml) or with the tools\' --modes')
    if 'glove_seed' in data:
        raise IKConfigError(f'IK config {path}: glove_seed is not an IK setting: the glove comes '
                            'from the pose database the lookup uses (its manifest records the '
                            'glove seed and hand length it was built with)')
    check_known_keys(f'IK config {path}', data,
                     (*_FILE_SETTINGS, 'version', 'covariances', 'covariance_file'),
                     error=IKConfigError)
    kwargs: dict[str, Any] = {key: data[key] for key in _FILE_SETTINGS if key in data}
    cov_file = data.get('covariance_file') or ''
    if not isinstance(cov_file, str):
        raise IKConfigError(f'IK config {path}: covariance_file must be a path, got {cov_file!r}')
    if cov_file:
        cov_path = Path(cov_file)
        if not cov_path.is_absolute():
            cov_path = path.parent / cov_path
        kwargs['covariances'] = load_covariances(cov_path)
    elif 'covariances' in data:
        c = data['covariances']
        if not isinstance(c, dict):
            raise IKConfigError(f'IK config {path}: covariances must be a mapping')
        try:
            r_std = np.asarray(c['r_std_px'], dtype=float)
        except (KeyError, TypeError, ValueError) as exc:
            raise IKConfigError(f'IK config {path}: covariances.r_std_px: {exc}') from exc
        q_std = _group_std(c.get('q_std'), f'{path}: covariances.q_std')
        p_std = _group_std(c.get('p_std'), f'{path}: covariances.p_std')
        try:
            with np.errstate(over='ignore'):       # an overflow to inf is refused below
                r_var, q_var, p_var = r_std**2, q_std**2, p_std**2
            kwargs['covariances'] = IKCovariances(r_var, q_var, p_var, source=str(path))
        except IKConfigError as exc:
            raise IKConfigError(f'IK config {path}: covariances: {exc}') from exc
    try:
        return IKConfig(**kwargs)
    except IKConfigError as exc:
        raise IKConfigError(f'IK config {path}: {exc}') from exc
