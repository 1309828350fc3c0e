"""The in-process stage profile: the real node classes' callbacks, one frame at a time, every
stage's output carried to the next as serialised messages."""
from __future__ import annotations

import numpy as np
import pytest
from node_fixtures import (
    LOOKUP_BLEND,
    LOOKUP_CANDIDATES,
    SMALL_DATABASE_GATES,
    NodeAssets,
    glove_frame,
)

from colorglove_ros.ros.stage_profile import STAGE_NAMES, profile_stages, stage_summary

pytestmark = [pytest.mark.dds, pytest.mark.usefixtures('isolated_ros_domain')]


def test_every_frame_passes_every_stage_and_a_hand_gives_a_joint_state(
        node_assets: NodeAssets) -> None:
    frames = [(k * 33_000_000, glove_frame(seed).image_rgb) for k, seed in enumerate((1, 2))]
    frames.append((3 * 33_000_000, np.full((480, 640, 3), 110, np.uint8)))   # no hand
    parameters = {
        'segmentation': {'color_calibration_file': str(node_assets.color_config)},
        'lookup': {'database_path': str(node_assets.database),
                   'num_candidates': LOOKUP_CANDIDATES, 'num_neighbors': LOOKUP_BLEND},
        'ik': {'database_path': str(node_assets.database),
               **SMALL_DATABASE_GATES},
    }
    times = profile_stages(frames, parameters, profile=True)
    for name in STAGE_NAMES:
        assert len(times.node_ms[name]) == len(frames)
        assert all(t > 0 for t in times.node_ms[name])
        assert set(times.profiles) == set(STAGE_NAMES)
    # the segmentation's own time on every frame; the lookup and IK ran only with a hand
    assert np.isfinite(times.compute_ms['segmentation']).all()
    assert not np.isfinite(times.compute_ms['lookup'][-1])
    assert not np.isfinite(times.compute_ms['ik'][-1])
    assert times.tracked[-1] is False and any(times.tracked[:2])
    rows = stage_summary(times)
    assert [row['stage'] for row in rows] == [*STAGE_NAMES, 'frame']
    frame = times.frame_ms()
    assert rows[-1]['node_p50_ms'] == pytest.approx(float(np.median(frame)))
