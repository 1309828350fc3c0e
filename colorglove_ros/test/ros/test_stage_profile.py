"""The in-process stage profile: the real node classes' callbacks, one frame at a time, every
stage's output carried to the next as serialised messages."""
from __future__ import annotations

import gc

import numpy as np
import pytest
from node_fixtures import (
    LOOKUP_BLEND,
    LOOKUP_CANDIDATES,
    SMALL_DATABASE_GATES,
    NodeAssets,
    glove_frame,
)

from colorglove_ros.ros.nodes.ik_node import IKNode
from colorglove_ros.ros.nodes.lookup_node import LookupNode
from colorglove_ros.ros.nodes.segmentation_node import SegmentationNode
from colorglove_ros.ros.stage_profile import (
    STAGE_NAMES,
    StageTimes,
    passes_summary,
    profile_stages,
    stage_summary,
)


def stage_times(segmentation: list[float], lookup: list[float], ik: list[float],
                tracked: list[bool]) -> StageTimes:
    """A pass's times: these node times per frame, the CPU times half of them, the compute
    times a third."""
    node = {'segmentation': segmentation, 'lookup': lookup, 'ik': ik}
    return StageTimes(node_ms=node, cpu_ms={k: [v / 2 for v in vs] for k, vs in node.items()},
                      compute_ms={k: [v / 3 for v in vs] for k, vs in node.items()},
                      tracked=tracked)


def test_passes_are_summarised_by_the_median_of_their_medians() -> None:
    passes = [stage_times([4.0, 5.0, 9.0], [2.0, 2.0, 3.0], [1.0, 2.0, 1.0], [True] * 3),
              stage_times([6.0, 6.0, 7.0], [3.0, 2.0, 2.0], [2.0, 2.0, 2.0], [True] * 3),
              stage_times([5.0, 4.0, 4.0], [2.0, 3.0, 2.0], [1.0, 1.0, 2.0], [True, False, True])]
    rows, per_pass = passes_summary(passes)
    # per-frame totals: (7, 9, 13), (11, 10, 11), (8, 8, 8): medians 9, 11, 8
    assert [row['frame_p50_ms'] for row in per_pass] == [9.0, 11.0, 8.0]
    assert [row['frame_cpu_p50_ms'] for row in per_pass] == [4.5, 5.5, 4.0]
    assert [row['segmentation_p50_ms'] for row in per_pass] == [5.0, 6.0, 4.0]
    assert [row['pass'] for row in per_pass] == [1, 2, 3]
    assert [row['tracked'] for row in per_pass] == [3, 3, 2]
    by_stage = {row['stage']: row for row in rows}
    assert by_stage['frame']['node_p50_ms'] == 9.0            # the median pass, not 8 or 11
    assert by_stage['frame']['node_cpu_p50_ms'] == 4.5
    assert by_stage['lookup']['node_p50_ms'] == 2.0
    # each figure the median over the passes of that pass's figure
    assert by_stage['segmentation']['node_p95_ms'] == pytest.approx(float(np.median(
        [stage_summary(times)[0]['node_p95_ms'] for times in passes])))
    assert passes_summary(passes[:1])[0] == stage_summary(passes[0])
    with pytest.raises(ValueError):
        passes_summary([])


@pytest.mark.dds
@pytest.mark.usefixtures('isolated_ros_domain')
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
    # the nodes are gone when it returns: a next pass starts with one set of nodes in memory
    # (type(), not isinstance(): a dead weak proxy among the objects raises on isinstance)
    node_types = (SegmentationNode, LookupNode, IKNode)
    assert not [obj for obj in gc.get_objects() if type(obj) in node_types]
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
