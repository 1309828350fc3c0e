"""Deterministic custom messages for the DDS round-trip test (shared by both processes)."""
from __future__ import annotations

from array import array
from collections.abc import Iterable

import numpy as np
from colorglove_msgs.msg import HandObservation, HandPoseCandidates


def set_blobs(msg: HandObservation, blobs: Iterable[tuple[int, float, float, int]]) -> None:
    """Give ``msg`` these blobs ((colour, x, y, pixel count) each) in its parallel arrays."""
    blobs = list(blobs)
    msg.blob_colors = array('B', [int(b[0]) for b in blobs])
    msg.blob_centroids = array('d', [float(v) for b in blobs for v in b[1:3]])
    msg.blob_pixel_counts = array('I', [int(b[3]) for b in blobs])


def blob_tuples(msg: HandObservation) -> list[tuple[int, float, float, int]]:
    """(colour, x, y, pixel count) of each blob of ``msg``'s parallel arrays."""
    xy = list(msg.blob_centroids)
    return [(int(c), xy[2 * k], xy[2 * k + 1], int(n))
            for k, (c, n) in enumerate(zip(msg.blob_colors, msg.blob_pixel_counts, strict=True))]


def sample_observation(seq: int) -> HandObservation:
    """An observation whose every field depends on ``seq``."""
    rng = np.random.default_rng(seq)
    msg = HandObservation()
    msg.header.stamp.sec = 1000 + seq
    msg.header.stamp.nanosec = 123456789
    msg.header.frame_id = 'camera_optical_frame'
    msg.hand_found = True
    msg.status = f'frame {seq}'
    msg.image_width, msg.image_height = 640, 480
    msg.tiny_labels = rng.integers(0, 11, HandObservation.TINY_SIZE ** 2, dtype=np.uint8).tolist()
    msg.crop_scale, msg.crop_offset_x, msg.crop_offset_y = 3.25, 100.5 + seq, 80.25
    set_blobs(msg, [(c, 10.0 * c + 0.5, 20.0 * c, 100 * c) for c in range(1, 11)])
    msg.glove_pixel_count = 5500
    msg.processing_time_ms = 4.5
    return msg


def sample_candidates(seq: int) -> HandPoseCandidates:
    """A candidates message with 10 poses of 26 DOFs and the observation inside."""
    rng = np.random.default_rng(1000 + seq)
    msg = HandPoseCandidates()
    msg.header = sample_observation(seq).header
    msg.hand_found = True
    msg.dof_names = [f'dof_{i}' for i in range(26)]
    msg.candidate_indices = [i * 97 + seq for i in range(10)]
    msg.candidate_poses = rng.standard_normal(10 * 26).tolist()
    msg.candidate_distances = [float(i) * 0.5 for i in range(10)]
    msg.candidate_weights = [0.1] * 10
    msg.blended_pose = rng.standard_normal(26).tolist()
    msg.constraint_patch_ids = list(range(20))
    msg.constraint_colors = [p % 10 + 1 for p in range(20)]
    msg.constraint_vertices = [37 * p for p in range(20)]
    msg.constraint_tiny_xy = [v for p in range(20) for v in (float(p), 39.0 - p)]
    msg.constraint_pixel_counts = [5 + p for p in range(20)]
    msg.observation = sample_observation(seq)
    msg.lookup_time_ms = 1.25
    return msg


SAMPLES = {'observation': (HandObservation, sample_observation),
           'candidates': (HandPoseCandidates, sample_candidates)}
