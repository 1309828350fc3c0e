"""Validate the pipeline's messages at each node boundary with ``core.validation``: what a
node reads from a ``HandObservation`` or ``HandPoseCandidates`` is checked (finite, in range,
consistent lengths, plausible sizes) before any core code sees it. No rclpy import."""
from __future__ import annotations

import numpy as np
from colorglove_msgs.msg import HandObservation, HandPoseCandidates

from colorglove_ros.core.validation import (
    MAX_BLOBS,
    InvalidObservationError,
    InvalidPriorError,
    validate_observation,
    validate_prior,
)

__all__ = ['check_observation_msg', 'check_candidates_msg']

_DOFS = 26


def check_observation_msg(msg: HandObservation, camera_size: tuple[int, int] | None = None
                          ) -> np.ndarray:
    """Check an observation with ``hand_found`` (image size, equal to ``camera_size`` when
    given; tiny labels; crop; blobs); return its (40, 40) tiny label image. Raises
    :class:`~colorglove_ros.core.validation.InvalidObservationError` naming the field."""
    if not msg.hand_found:
        raise InvalidObservationError('hand_found is false')
    blobs = msg.blobs
    if len(blobs) > MAX_BLOBS:      # refused before building arrays of them
        raise InvalidObservationError(f'{len(blobs)} blobs, at most {MAX_BLOBS} allowed')
    tiny = validate_observation(
        image_width=msg.image_width, image_height=msg.image_height,
        tiny_labels=msg.tiny_labels,
        crop=(msg.crop_scale, msg.crop_offset_x, msg.crop_offset_y),
        blob_color=np.array([b.color_label for b in blobs], dtype=np.int64),
        blob_centroid_px=np.array([[b.x, b.y] for b in blobs], dtype=float).reshape(-1, 2),
        blob_pixel_count=np.array([b.pixel_count for b in blobs], dtype=np.int64),
        glove_pixel_count=msg.glove_pixel_count)
    if camera_size is not None and (msg.image_width, msg.image_height) != tuple(camera_size):
        raise InvalidObservationError(
            f'image {msg.image_width}x{msg.image_height}, but the camera is calibrated for '
            f'{camera_size[0]}x{camera_size[1]}')
    return tiny


def check_candidates_msg(msg: HandPoseCandidates, num_vertices: int,
                         camera_size: tuple[int, int] | None = None) -> np.ndarray:
    """Check candidates with ``hand_found``: the observation they carry, then the blended
    pose, candidates, constraints (patches and vertices of a mesh of ``num_vertices``) and
    finger spread; return the blended pose. Raises ``InvalidObservationError`` or
    :class:`~colorglove_ros.core.validation.InvalidPriorError` naming the field."""
    if not msg.hand_found:
        raise InvalidPriorError('hand_found is false')
    if len(msg.blended_pose) != _DOFS:
        raise InvalidPriorError(f'blended_pose holds {len(msg.blended_pose)} values, '
                                f'expected {_DOFS}')
    check_observation_msg(msg.observation, camera_size)
    if len(msg.candidates) > 10_000:
        raise InvalidPriorError(f'{len(msg.candidates)} candidates, at most 10000 allowed')
    candidates = msg.candidates
    poses = []
    for index, candidate in enumerate(candidates):
        if len(candidate.pose) != _DOFS:
            raise InvalidPriorError(f'candidates[{index}].pose holds {len(candidate.pose)} '
                                    f'values, expected {_DOFS}')
        poses.append(np.asarray(candidate.pose, dtype=float))
    c = msg.constraints
    return validate_prior(
        blended_pose=np.asarray(msg.blended_pose, dtype=float),
        candidate_poses=poses,
        candidate_weights=np.array([k.weight for k in candidates], dtype=float),
        candidate_distances=np.array([k.image_distance for k in candidates], dtype=float),
        constraints=(np.array([k.patch_id for k in c], dtype=np.int64),
                     np.array([k.color_label for k in c], dtype=np.int64),
                     np.array([k.vertex_index for k in c], dtype=np.int64),
                     np.array([[k.tiny_x, k.tiny_y] for k in c], dtype=float).reshape(-1, 2),
                     np.array([k.pixel_count for k in c], dtype=np.int64)),
        num_vertices=num_vertices,
        finger_std=np.asarray(msg.finger_std, dtype=float))
