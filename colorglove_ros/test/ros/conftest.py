"""Session fixtures of the ROS tests: one good rendered frame and the messages the pipeline
makes of it (the observation segmentation_node sends, the candidates lookup_node sends)."""
from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
import pytest
from node_fixtures import (
    NodeAssets,
    candidates_msg,
    glove_frame,
    header,
    node_lookup,
    observation_msg,
)
from repo_paths import CONFIG_DIR

from colorglove_ros.core.camera import load_calibration
from colorglove_ros.core.segmentation.segmenter import load_segmenter

if TYPE_CHECKING:
    from colorglove_msgs.msg import HandObservation, HandPoseCandidates

GOOD_SEED = 1


@pytest.fixture(scope='session')
def good_rgb() -> np.ndarray:
    """A rendered frame in which the segmenter finds the whole hand."""
    return glove_frame(GOOD_SEED).image_rgb


@pytest.fixture(scope='session')
def good_observation(node_assets: NodeAssets, good_rgb: np.ndarray) -> HandObservation:
    """The good frame's observation, stamped 200 s + 500 ns in 'camera_optical_frame'
    (shared: copy it before changing it)."""
    return observation_msg(load_segmenter(str(node_assets.color_config)), good_rgb,
                           header(200, 500, 'camera_optical_frame'))


@pytest.fixture(scope='session')
def good_candidates(node_assets: NodeAssets, good_observation: HandObservation
                    ) -> HandPoseCandidates:
    """The good observation's candidates seen by the calibrated camera (shared: copy it
    before changing it)."""
    camera = load_calibration(CONFIG_DIR / 'calibration.yaml').primary
    return candidates_msg(node_lookup(node_assets), good_observation, camera)
