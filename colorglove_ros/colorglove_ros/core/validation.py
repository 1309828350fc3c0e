"""Checks at every boundary: one family of shape / dtype / finite / range helpers, and the
validators built from them for what crosses a stage boundary (an observation, a pose prior
with its constraints, a pose) and for configuration values read at start-up.

Each check raises a typed error (by default :class:`InvalidInputError`, a
:class:`~colorglove_ros.core.errors.ColorGloveError` and a ``ValueError``; callers that own a
more specific error family pass it as ``error``) whose message names the field and the value.
"""
from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from colorglove_ros.core.conventions import NUM_COLORS, NUM_PATCHES, TINY_SIZE
from colorglove_ros.core.errors import ColorGloveError
from colorglove_ros.core.hand.model import NUM_DOFS, NUM_FINGER_DOFS

__all__ = [
    'check_known_keys',
    'InvalidInputError', 'InvalidObservationError', 'InvalidPriorError', 'InvalidConfigError',
    'MAX_BLOBS', 'MAX_IMAGE_SIDE', 'MIN_HAND_DEPTH_M', 'MAX_HAND_DEPTH_M',
    'check_number', 'check_array', 'as_rows', 'check_settings', 'SettingRule',
    'validate_image_size', 'validate_crop', 'validate_blobs', 'validate_tiny_labels',
    'validate_observation', 'validate_pose', 'validate_poses', 'validate_constraints',
    'validate_prior',
    'validate_hand_depth', 'validate_segmenter_settings', 'SEGMENTER_RULES',
    'validate_database_arrays',
]

# Plausibility bounds of what crosses a stage boundary.
MAX_BLOBS = 256            # blobs per observation (10 colours; clutter gives a few dozen)
MAX_IMAGE_SIDE = 16384     # pixels
MIN_HAND_DEPTH_M = 0.1     # every hand keypoint at least this far in front of the camera
MAX_HAND_DEPTH_M = 5.0     # ... and at most this far
# The crop window (TINY_SIZE * scale pixels a side) is at most this many image sides wide.
MAX_CROP_WINDOW_IMAGE_SIDES = 4.0
# ... and at least 4 pixels wide (the segmenter's smallest glove spans far more).
MIN_CROP_SCALE = 0.1


class InvalidInputError(ColorGloveError, ValueError):
    """A value crossing a boundary (message, file, setting) is not one the code can use."""


class InvalidObservationError(InvalidInputError):
    """A segmentation observation is inconsistent, non-finite or implausible."""


class InvalidPriorError(InvalidInputError):
    """A lookup result (blended pose, candidates, constraints) is unusable by the IK."""


class InvalidConfigError(InvalidInputError):
    """A configuration value is missing, of the wrong type, non-finite or out of range."""


ErrorType = type[Exception]


# ---------------------------------------------------------------------------- helper family
def check_known_keys(name: str, mapping: dict, known: Any, *,
                     error: ErrorType = InvalidConfigError) -> None:
    """Raise ``error`` naming ``name`` and the keys of ``mapping`` that are not in ``known``
    (a misspelt setting would otherwise be ignored silently)."""
    unknown = sorted(str(key) for key in set(mapping) - set(known))
    if unknown:
        raise error(f'{name}: unknown setting(s) {unknown} (known: {sorted(known)})')


def check_number(name: str, value: Any, *, low: float | None = None,
                 high: float | None = None, low_open: bool = False, integer: bool = False,
                 odd: bool = False, error: ErrorType = InvalidInputError) -> float | int:
    """``value`` as a finite number (an int if ``integer``) within [low, high] (low excluded
    if ``low_open``; odd if ``odd``); raise ``error`` naming ``name`` and the value."""
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise error(f'{name} must be a number, got {value!r}')
    value = value.item() if isinstance(value, np.generic) else value
    if integer:
        if isinstance(value, (float, np.floating)) and not float(value).is_integer():
            raise error(f'{name} must be an integer, got {value!r}')
        if isinstance(value, (float, np.floating)) and not math.isfinite(value):
            raise error(f'{name} must be a finite integer, got {value!r}')
        number: float | int = int(value)
    else:
        number = float(value)
        if not math.isfinite(number):
            raise error(f'{name} must be finite, got {value!r}')
    if low is not None and (number <= low if low_open else number < low):
        bound = 'positive (> 0)' if low_open and low == 0 else \
            f'{">" if low_open else ">="} {low:g}'
        raise error(f'{name} must be {bound}, got {value!r}')
    if high is not None and number > high:
        raise error(f'{name} must be <= {high:g}, got {value!r}')
    if odd and int(number) % 2 == 0:
        raise error(f'{name} must be odd, got {value!r}')
    return number


def check_array(name: str, value: Any, *, shape: Sequence[int | None] | None = None,
                kind: str = 'fiu', finite: bool = True, low: float | None = None,
                high: float | None = None, max_length: int | None = None,
                error: ErrorType = InvalidInputError) -> np.ndarray:
    """``value`` as an array of dtype kind in ``kind`` ('f' float, 'i' signed, 'u' unsigned,
    'b' bool), of ``shape`` (None matches any size), at most ``max_length`` rows, finite and
    within [low, high]; raise ``error`` naming ``name`` and the offending value."""
    if max_length is not None and hasattr(value, '__len__') and len(value) > max_length:
        raise error(f'{name} holds {len(value)} rows, at most {max_length} allowed')
    try:
        array = np.asarray(value)
    except (TypeError, ValueError) as exc:
        raise error(f'{name} is not an array: {exc}') from exc
    if array.size == 0 and shape is not None and any(s in (None, 0) for s in shape):
        return array.reshape([0 if s is None else s for s in shape])    # nothing to check
    if array.dtype.kind not in kind:
        raise error(f'{name} must have dtype kind {kind!r}, got {array.dtype}')
    if shape is not None and (array.ndim != len(shape) or any(
            want is not None and got != want for got, want in zip(array.shape, shape,
                                                                   strict=True))):
        wanted = '(' + ', '.join('N' if s is None else str(s) for s in shape) + ')'
        raise error(f'{name} must have shape {wanted}, got {array.shape}')
    if array.size == 0:
        return array
    floats = array.dtype.kind == 'f'
    # the extremes, once: a NaN makes both NaN and an infinity is one of them, so finite
    # extremes mean every value is finite
    smallest = array.min() if low is not None or finite and floats else None
    largest = array.max() if high is not None or finite and floats else None
    if finite and floats and not (np.isfinite(smallest) and np.isfinite(largest)):
        bad = ~np.isfinite(array)
        raise error(f'{name} must be finite, got {array[bad].ravel()[0].item()!r} at index '
                    f'{tuple(int(i) for i in np.argwhere(bad)[0])}')
    if low is not None and smallest < low:
        raise error(f'{name} must be >= {low:g}, got {smallest.item()!r}')
    if high is not None and largest > high:
        raise error(f'{name} must be <= {high:g}, got {largest.item()!r}')
    return array



def as_rows(name: str, value: Any, dtype: Any, tail: tuple[int, ...],
            error: ErrorType = InvalidInputError) -> np.ndarray:
    """``value`` as an array of ``dtype`` with one row per item: (N,) when ``tail`` is (),
    else (N, *tail); an empty input becomes (0, *tail). Raise ``error`` for other shapes."""
    a = np.asarray(value, dtype=dtype)
    if a.ndim == 1 and tail == () or a.ndim == 2 and a.shape[1:] == tail:
        return a
    if a.size == 0:
        return a.reshape((0, *tail))
    raise error(f'{name} must have shape (N, {", ".join(map(str, tail))}), got {a.shape}')


# ---------------------------------------------------------------------------- configuration
SettingRule = tuple[str, float | None, float | None, bool]
"""(type 'int' | 'float' | 'ints', low, high, odd) of one setting."""

# What GloveSegmenter can run with (core/segmentation/segmenter.py; its keyword settings are
# exactly these keys, checked whenever one is built); keys absent keep defaults.
SEGMENTER_RULES: dict[str, SettingRule] = {
    'coarse_factor': ('int', 1, 16, False),
    'roi_margin': ('float', 1.0, 10.0, False),
    'max_roi_cells': ('int', TINY_SIZE, MAX_IMAGE_SIDE, False),
    'bilateral_diameter': ('int', 0, 15, False),
    'bilateral_sigma_color': ('float', 0.0, 1000.0, False),
    'bilateral_sigma_space': ('float', 0.0, 100.0, False),
    'median_size': ('int', 1, 15, True),
    'light_passes': ('int', 0, 5, False),
    'border_passes': ('int', 0, 10, False),
    'border_distances': ('ints', 1, 32, False),
    'min_glove_pixels': ('int', 1, MAX_IMAGE_SIDE ** 2, False),
    'min_inside_fraction': ('float', 0.0, 1.0, False),
    'max_border_contact': ('float', 0.0, 4.0, False),
    'diversity_window': ('int', 0, 256, False),
    'min_region_colors': ('int', 1, 64, False),
    'diversity_density': ('float', 0.0, 1.0, False),
    'max_patch_fraction': ('float', 0.0, 1.0, False),
    'max_patch_window_share': ('float', 0.0, 1.0, False),
    'junction_reach': ('float', 0.0, 10.0, False),
    'junction_min_share': ('float', 0.0, 1.0, False),
    'junction_surfaces_only': ('int', 0, 1, False),
    'junction_min_pull': ('float', 0.0, 100.0, False),
    'junction_max_window_kept': ('float', 0.0, 1.0, False),
    'sleeve_reach': ('float', 0.0, 10.0, False),
    'sleeve_min_share': ('float', 0.0, 1.0, False),
    'glove_contact_share': ('float', 0.0, 1.0, False),
    'glove_contact_min_drop': ('float', 0.0, 1.0, False),
    'scene_colour_min_share': ('float', 0.0, 1.0, False),
    'background_frames': ('int', 0, 100000, False),
    'background_tolerance': ('float', 1.0, 255.0, False),
    'background_memory': ('int', 0, 1, False),
    'follow_margin': ('float', 0.0, 100.0, False),
    'search_every': ('int', 1, 1000, False),
    'prediction_margin': ('float', 0.0, 100.0, False),
    'prediction_max_ratio': ('float', 0.0, 100.0, False),
    'saturation_rate': ('float', 0.0, 1.0, False),
    'washed_out_colors': ('int', 0, NUM_COLORS, False),
    'cleanup_factor': ('int', 1, 8, False),
    'learn_in_thread': ('int', 0, 1, False),
    'min_blob_pixels': ('int', 1, MAX_IMAGE_SIDE ** 2, False),
    'min_blob_share': ('float', 0.0, 1.0, False),
    'min_component_colors': ('int', 1, NUM_COLORS, False),
    'reattach_radius': ('int', 0, 64, False),
    'reattach_max_share': ('float', 0.0, 1.0, False),
}


def check_settings(settings: Mapping[str, Any], rules: Mapping[str, SettingRule], where: str,
                   error: ErrorType = InvalidConfigError) -> dict[str, Any]:
    """Check every entry of ``settings`` against ``rules`` (unknown keys are refused);
    return the values converted to int / float / tuple of ints. ``where`` names the file."""
    if not isinstance(settings, Mapping):
        raise error(f'{where}: settings must be a mapping, got {type(settings).__name__}')
    checked: dict[str, Any] = {}
    for key, value in settings.items():
        if key not in rules:
            raise error(f'{where}: unknown setting {key!r} (known: {", ".join(sorted(rules))})')
        kind, low, high, odd = rules[key]
        name = f'{where}: {key}'
        if kind == 'ints':
            if not isinstance(value, (list, tuple)) or not value:
                raise error(f'{name} must be a non-empty list of integers, got {value!r}')
            checked[key] = tuple(int(check_number(f'{name}[{i}]', v, low=low, high=high,
                                                  integer=True, error=error))
                                 for i, v in enumerate(value))
        else:
            checked[key] = check_number(name, value, low=low, high=high, integer=kind == 'int',
                                        odd=odd, error=error)
    return checked


def validate_segmenter_settings(settings: Mapping[str, Any], where: str,
                                error: ErrorType = InvalidConfigError) -> dict[str, Any]:
    """The ``segmenter`` section of a colour config, checked against :data:`SEGMENTER_RULES`
    (odd median kernel, finite numbers, ranges); raises ``error`` naming file and key."""
    checked = check_settings(settings, SEGMENTER_RULES, where, error)
    for key in {'bilateral_sigma_color', 'bilateral_sigma_space'} & set(checked):
        if checked[key] <= 0.0:
            raise error(f'{where}: {key} must be > 0, got {settings[key]!r}')
    return checked


# ---------------------------------------------------------------------------- observation
def validate_image_size(width: Any, height: Any,
                        error: ErrorType = InvalidObservationError) -> tuple[int, int]:
    """A positive, plausible image size (at most :data:`MAX_IMAGE_SIDE` a side)."""
    return (int(check_number('image_width', width, low=1, high=MAX_IMAGE_SIDE, integer=True,
                             error=error)),
            int(check_number('image_height', height, low=1, high=MAX_IMAGE_SIDE, integer=True,
                             error=error)))


def validate_crop(scale: Any, offset_x: Any, offset_y: Any, width: int, height: int,
                  error: ErrorType = InvalidObservationError) -> None:
    """A crop transform (tiny -> full image) whose window is finite, positive, at most a few
    image sides wide and overlaps the image."""
    side = max(width, height)
    scale = check_number('crop_scale', scale, low=MIN_CROP_SCALE,
                         high=MAX_CROP_WINDOW_IMAGE_SIDES * side / TINY_SIZE, error=error)
    window = scale * TINY_SIZE
    check_number('crop_offset_x', offset_x, low=-window, high=width, error=error)
    check_number('crop_offset_y', offset_y, low=-window, high=height, error=error)


def validate_blobs(color: Any, centroid_px: Any, pixel_count: Any, width: int, height: int,
                   num_colors: int = NUM_COLORS,
                   error: ErrorType = InvalidObservationError) -> None:
    """Blobs: at most :data:`MAX_BLOBS`, colours 1..num_colors, centroids finite inside the
    image, pixel counts 1..width*height, arrays of one length."""
    color = check_array('blob color_label', color, shape=(None,), kind='iu', low=1,
                        high=num_colors, max_length=MAX_BLOBS, error=error)
    check_array('blob centroid', centroid_px, shape=(len(color), 2), kind='fiu', low=-0.5,
                high=max(width, height) - 0.5, error=error)
    xy = np.asarray(centroid_px, float).reshape(-1, 2)
    if len(xy) and (xy[:, 0].max() > width - 0.5 or xy[:, 1].max() > height - 0.5):
        raise error(f'blob centroid outside the {width}x{height} image: '
                    f'max x {xy[:, 0].max():g}, max y {xy[:, 1].max():g}')
    check_array('blob pixel_count', pixel_count, shape=(len(color),), kind='fiu', low=1,
                high=width * height, error=error)


def validate_tiny_labels(labels: Any, num_colors: int = NUM_COLORS,
                         error: ErrorType = InvalidObservationError) -> np.ndarray:
    """The 40x40 tiny label image (flat or square) with labels 0..num_colors; returned
    (40, 40) uint8."""
    flat = check_array('tiny_labels', np.asarray(labels).reshape(-1), shape=(TINY_SIZE ** 2,),
                       kind='iu', low=0, high=num_colors, error=error)
    if not flat.any():
        raise error('tiny_labels hold no glove pixel although the hand was found')
    return flat.astype(np.uint8).reshape(TINY_SIZE, TINY_SIZE)


def validate_observation(*, image_width: Any, image_height: Any, tiny_labels: Any,
                         crop: tuple[Any, Any, Any], blob_color: Any, blob_centroid_px: Any,
                         blob_pixel_count: Any, glove_pixel_count: Any,
                         num_colors: int = NUM_COLORS) -> np.ndarray:
    """Everything the lookup and the IK read from an observation with ``hand_found``:
    image size, tiny labels, crop transform, blobs and glove pixel count. Returns the tiny
    label image (40, 40); raises :class:`InvalidObservationError` naming the field."""
    width, height = validate_image_size(image_width, image_height)
    check_number('glove_pixel_count', glove_pixel_count, low=0, high=width * height,
                 integer=True, error=InvalidObservationError)
    validate_crop(*crop, width, height)
    validate_blobs(blob_color, blob_centroid_px, blob_pixel_count, width, height, num_colors)
    return validate_tiny_labels(tiny_labels, num_colors)


# ---------------------------------------------------------------------------- pose prior
def validate_pose(name: str, pose: Any, error: ErrorType = InvalidPriorError) -> np.ndarray:
    """A 26-DOF pose of finite values (metres, radians) with a plausible rotation vector."""
    q = check_array(name, pose, shape=(NUM_DOFS,), kind='fiu', error=error).astype(float)
    _check_pose_values(name, q[None], error)
    return q


def validate_poses(name: str, poses: Any, error: ErrorType = InvalidPriorError) -> np.ndarray:
    """Poses (K, 26), each as :func:`validate_pose`, checked all at once."""
    q = check_array(name, poses, shape=(None, NUM_DOFS), kind='fiu', error=error
                    ).astype(float)
    _check_pose_values(name, q, error)
    return q


def _check_pose_values(name: str, q: np.ndarray, error: ErrorType) -> None:
    """Finite poses (K, 26) with plausible rotation vectors and finger angles; the message
    names the first bad pose (``name[k]``, or ``name`` alone for one pose)."""
    if not len(q):
        return
    angle = np.linalg.norm(q[:, 3:6], axis=1)
    finger = np.abs(q[:, 6:]).max(axis=1)
    bad = np.flatnonzero((angle > 1e3) | (finger > 2 * math.pi))
    if not len(bad):
        return
    k = int(bad[0])
    where = name if len(q) == 1 else f'{name}[{k}]'
    if angle[k] > 1e3:
        raise error(f'{where}: wrist rotation vector of norm {angle[k]:g} rad is not a rotation')
    raise error(f'{where}: finger angle {finger[k]:g} rad beyond a full turn')


def validate_constraints(patch_id: Any, color: Any, vertex: Any, tiny_xy: Any,
                         pixel_count: Any, num_vertices: int,
                         error: ErrorType = InvalidPriorError) -> None:
    """Projection constraints: patch ids 0..19, colours 1..10, vertices of the mesh, tiny
    centroids finite within (a margin around) the tiny image, pixel counts 0..1600."""
    patch_id = check_array('constraint_patch_ids', patch_id, shape=(None,), kind='iu', low=0,
                           high=NUM_PATCHES - 1, max_length=NUM_PATCHES * 4, error=error)
    n = len(patch_id)
    check_array('constraint_colors', color, shape=(n,), kind='iu', low=1,
                high=NUM_COLORS, error=error)
    check_array('constraint_vertices', vertex, shape=(n,), kind='iu', low=0,
                high=num_vertices - 1, error=error)
    check_array('constraint_tiny_xy', tiny_xy, shape=(n, 2), kind='fiu', low=-TINY_SIZE,
                high=2 * TINY_SIZE, error=error)
    check_array('constraint_pixel_counts', pixel_count, shape=(n,), kind='fiu', low=0,
                high=TINY_SIZE ** 2, error=error)


def validate_prior(*, blended_pose: Any, candidate_poses: Any,
                   candidate_weights: Any, candidate_distances: Any,
                   constraints: tuple[Any, Any, Any, Any, Any], num_vertices: int,
                   finger_std: Any = None) -> np.ndarray:
    """A lookup result as the IK receives it: a finite 26-DOF blended pose, at least one
    candidate (``candidate_poses`` (K, 26) or K poses; finite poses, weights and distances
    >= 0), at least one constraint pointing at
    existing patches and mesh vertices, and ``finger_std`` empty or 20 finite values >= 0.
    Returns the blended pose; raises :class:`InvalidPriorError` naming the field."""
    q = validate_pose('blended_pose', blended_pose)
    if len(candidate_poses) == 0:
        raise InvalidPriorError('hand_found with no candidates')
    k = len(validate_poses('candidate_poses', candidate_poses))
    check_array('candidate_weights', candidate_weights, shape=(k,), low=0.0, high=1.0 + 1e-6,
                error=InvalidPriorError)
    check_array('candidate_distances', candidate_distances, shape=(k,), low=0.0,
                error=InvalidPriorError)
    if len(constraints[0]) == 0:
        raise InvalidPriorError('hand_found with no projection constraints')
    validate_constraints(*constraints, num_vertices=num_vertices)
    if finger_std is not None and len(finger_std):
        check_array('finger_std', finger_std, shape=(NUM_FINGER_DOFS,), low=0.0,
                    error=InvalidPriorError)
    return q


def validate_hand_depth(points_camera: Any, camera_name: str = 'camera',
                        min_depth_m: float = MIN_HAND_DEPTH_M,
                        max_depth_m: float = MAX_HAND_DEPTH_M,
                        error: ErrorType = InvalidPriorError) -> None:
    """Every hand point (N, 3) of a pose, in a camera's optical frame, at a plausible depth
    (a hand at or behind the camera plane cannot be seen, and one just in front of it would
    make the IK's depth buffer unbounded)."""
    z = check_array('hand points', points_camera, shape=(None, 3), error=error)[:, 2]
    if len(z) and (z.min() < min_depth_m or z.max() > max_depth_m):
        raise error(f'hand depth {z.min():.3g}..{z.max():.3g} m from {camera_name}, '
                    f'plausible {min_depth_m:g}..{max_depth_m:g} m')


# ---------------------------------------------------------------------------- database
def validate_database_arrays(db: Any, where: str, num_vertices: int | None = None,
                             error: ErrorType = InvalidInputError) -> None:
    """The contents of a pose database (``core.lookup.database.PoseDatabase``) the lookup
    indexes with: finite poses, crops with a positive scale, patch colours 0..10, patch
    vertices -1 (none) or of the mesh (``num_vertices`` when given), finite patch areas,
    glove pixel keys within the padded range and a finite, positive render camera.
    ``load_database`` remembers a pass (``CONTENTS_CHECK``): rename that when this changes."""
    check_array(f'{where}: poses', db.poses, shape=(None, NUM_DOFS), error=error)
    crop = check_array(f'{where}: crop', db.crop, shape=(None, 3), error=error)
    if len(crop) and crop[:, 0].min() <= 0.0:
        raise error(f'{where}: crop scale must be > 0, got {crop[:, 0].min().item()!r}')
    check_array(f'{where}: patch_color', db.patch_color, shape=(NUM_PATCHES,), kind='iu',
                low=0, high=NUM_COLORS, error=error)      # 0: colour not recorded
    check_array(f'{where}: patch_vertex', db.patch_vertex, shape=(None, NUM_PATCHES),
                kind='iu', low=-1,
                high=None if num_vertices is None else num_vertices - 1, error=error)
    check_array(f'{where}: patch_pixels', db.patch_pixels, shape=(None, NUM_PATCHES),
                low=0.0, high=TINY_SIZE ** 2, error=error)
    check_array(f'{where}: pixel_keys', db.pixel_keys, kind='iu', low=0,
                high=NUM_COLORS * TINY_SIZE ** 2, error=error)
    check_array(f'{where}: tiny', db.tiny, kind='u', high=NUM_COLORS, error=error)
    camera = db.render_camera
    for key in ('fx', 'fy'):
        if key in camera:
            check_number(f'{where}: render_camera {key}', camera[key], low=0.0,
                         low_open=True, error=error)
    for key in ('cx', 'cy'):
        if key in camera:
            check_number(f'{where}: render_camera {key}', camera[key], error=error)
