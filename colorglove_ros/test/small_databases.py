"""Small pose databases for the tests, made one way for every test folder: entries assembled
from label images standing in for renders (:func:`blob_database`), and a small database
rendered by the real builder (:data:`SMALL_BUILD`; conftest.py builds it once per session)."""
from __future__ import annotations

import numpy as np

from colorglove_ros.core.lookup.database import PoseDatabase
from colorglove_ros.core.lookup.database_build import BuildConfig, assemble_database

__all__ = ['RENDER_CAM', 'WRIST_DEPTH_M', 'SMALL_BUILD', 'poses_on_axis', 'blob_database']

# the render camera of the default build settings: 128x128 pixels, focal length 150 px
RENDER_CAM = {'width': 128, 'height': 128, 'fx': 150.0, 'fy': 150.0, 'cx': 63.5, 'cy': 63.5}
WRIST_DEPTH_M = 0.5

# 96 entries (6 finger configurations x 16 orientations) from a 400-pose collection: a few
# seconds to build, enough for the nodes and the evaluation commands to find a hand
SMALL_BUILD = BuildConfig(entries=96, orientations_per_config=16, collection_size=400,
                          num_bits=32, num_pairs=200, training_images=200, batch=64)


def poses_on_axis(rotations: np.ndarray | None = None,
                  fingers: np.ndarray | None = None) -> np.ndarray:
    """(n, 26) poses with the wrist on the optical axis ``WRIST_DEPTH_M`` away, as the
    database renders them: ``rotations`` (n, 3) and finger DOFs ``fingers`` (n, 20), zero
    where not given (one of them sets n)."""
    n = len(rotations) if rotations is not None else len(fingers)
    poses = np.zeros((n, 26))
    poses[:, 2] = WRIST_DEPTH_M
    if rotations is not None:
        poses[:, 3:6] = rotations
    if fingers is not None:
        poses[:, 6:] = fingers
    return poses


def blob_database(tiny: np.ndarray, poses: np.ndarray, crop: np.ndarray | None = None,
                  **settings) -> PoseDatabase:
    """A database of ``tiny`` (n, 40, 40) label images and their ``poses``, rendered (so it
    records) with :data:`RENDER_CAM`; ``crop`` (n, 3) defaults to scale 1 at the origin and
    ``settings`` go to ``assemble_database`` (num_bits, num_pairs, patch arrays ...)."""
    if crop is None:
        crop = np.tile([1.0, 0.0, 0.0], (len(tiny), 1))
    return assemble_database(tiny, poses, crop, RENDER_CAM, **settings)
