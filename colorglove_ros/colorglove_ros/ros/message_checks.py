"""Validate the pipeline's messages at each node boundary with ``core.validation``: what a
node reads from a ``HandObservation`` or ``HandPoseCandidates`` is checked (finite, in range,
consistent lengths, plausible sizes) before any core code sees it. No rclpy import."""
from __future__ import annotations

import numpy as np
from colorglove_msgs.msg import HandObservation, HandPoseCandidates

from colorglove_ros.core.tracking.types import Blobs
from colorglove_ros.core.validation import (
    MAX_BLOBS,
    InvalidObservationError,
    InvalidPriorError,
    validate_observation,
    validate_prior,
)
from colorglove_ros.ros.conversions import (
    blobs_from_observation_msg,
    candidate_arrays_from_msg,
    constraint_arrays_from_msg,
)

__all__ = ['checked_observation_msg', 'checked_candidates_msg']

_DOFS = 26
MAX_CANDIDATES = 10_000   # candidates per message


def checked_observation_msg(msg: HandObservation, camera_size: tuple[int, int] | None = None
                            ) -> tuple[np.ndarray, Blobs]:
    """Check an observation with ``hand_found`` (image size, equal to ``camera_size`` when
    given; tiny labels; crop; blobs); return its (40, 40) tiny label image and the blobs it
    checked (as ``ros.conversions.blobs_from_observation_msg`` gives them, so a caller that
    reads them next does not convert the message's blobs again). Raises
    :class:`~colorglove_ros.core.validation.InvalidObservationError` naming the field."""
    if not msg.hand_found:
        raise InvalidObservationError('hand_found is false')
    if len(msg.blob_colors) > MAX_BLOBS:      # refused before building arrays of them
        raise InvalidObservationError(f'{len(msg.blob_colors)} blobs, at most {MAX_BLOBS} '
                                      'allowed')
    try:
        blobs = blobs_from_observation_msg(msg)
    except ValueError as exc:           # the parallel blob arrays' lengths disagree
        raise InvalidObservationError(str(exc)) from exc
    tiny = validate_observation(
        image_width=msg.image_width, image_height=msg.image_height,
        tiny_labels=msg.tiny_labels,
        crop=(msg.crop_scale, msg.crop_offset_x, msg.crop_offset_y),
        blob_color=blobs.color, blob_centroid_px=blobs.centroid_px,
        blob_pixel_count=blobs.pixel_count, glove_pixel_count=msg.glove_pixel_count)
    if camera_size is not None and (msg.image_width, msg.image_height) != tuple(camera_size):
        raise InvalidObservationError(
            f'image {msg.image_width}x{msg.image_height}, but the camera is calibrated for '
            f'{camera_size[0]}x{camera_size[1]}')
    return tiny, blobs


def checked_candidates_msg(msg: HandPoseCandidates, num_vertices: int,
                           camera_size: tuple[int, int] | None = None
                           ) -> tuple[np.ndarray, Blobs]:
    """Check candidates with ``hand_found``: the observation they carry
    (:func:`checked_observation_msg`), then the blended pose, candidates (one pose per index,
    one distance and weight each), constraints (patches and vertices of a mesh of
    ``num_vertices``) and finger spread; return the blended pose and the observation's blobs.
    Raises ``InvalidObservationError`` or
    :class:`~colorglove_ros.core.validation.InvalidPriorError` naming the field."""
    if not msg.hand_found:
        raise InvalidPriorError('hand_found is false')
    if len(msg.blended_pose) != _DOFS:
        raise InvalidPriorError(f'blended_pose holds {len(msg.blended_pose)} values, '
                                f'expected {_DOFS}')
    _, blobs = checked_observation_msg(msg.observation, camera_size)
    count = len(msg.candidate_indices)
    if count > MAX_CANDIDATES:
        raise InvalidPriorError(f'{count} candidates, at most {MAX_CANDIDATES} allowed')
    if len(msg.candidate_poses) != count * _DOFS:
        raise InvalidPriorError(f'candidate_poses holds {len(msg.candidate_poses)} values for '
                                f'{count} candidates, expected {count * _DOFS}')
    if len(msg.constraint_tiny_xy) != 2 * len(msg.constraint_patch_ids):
        raise InvalidPriorError(f'constraint_tiny_xy holds {len(msg.constraint_tiny_xy)} '
                                f'values for {len(msg.constraint_patch_ids)} constraints')
    candidates = candidate_arrays_from_msg(msg)
    c = constraint_arrays_from_msg(msg)
    return validate_prior(
        blended_pose=np.frombuffer(msg.blended_pose, np.float64),
        candidate_poses=candidates['poses'], candidate_weights=candidates['weights'],
        candidate_distances=candidates['distances'],
        constraints=(c['patch_ids'], c['colors'], c['vertices'], c['tiny_xy'],
                     c['pixel_counts']),
        num_vertices=num_vertices,
        finger_std=np.frombuffer(msg.finger_std, np.float64)), blobs
