"""The two-hand layer (core/hands.py): glove regions of a frame with two rendered hands, and
the handedness assignment from the lookup evidence and continuity."""
from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from colorglove_ros.core.hand.handedness import mirror_pose
from colorglove_ros.core.hands import (
    GloveRegion,
    HandCandidate,
    assign_hands,
    find_glove_regions,
    mask_regions,
    region_window,
    shift_observation,
)
from colorglove_ros.core.pipeline import observe_image
from colorglove_ros.core.segmentation.crop import CropTransform
from colorglove_ros.core.synthetic.conditions import sample_conditions
from colorglove_ros.core.synthetic.frames import Synthesizer, default_camera, sample_pose
from colorglove_ros.core.tracking.types import CameraObservation


def _candidate(d_right: float, d_left: float, center_x: float) -> HandCandidate:
    crop = CropTransform.from_window((center_x, 240.0), 60.0)
    found = {h: SimpleNamespace(distances=np.array([d])) for h, d in
             (('right', d_right), ('left', d_left))}
    return HandCandidate(GloveRegion((0, 0, 1, 1), 100), CameraObservation(True, crop=crop),
                         None, found)


def test_two_regions_take_the_hands_their_evidence_says():
    right, left = _candidate(1.0, 3.0, 100.0), _candidate(3.0, 1.0, 500.0)
    assignment, margin = assign_hands([left, right], {'right': None, 'left': None})
    assert assignment == {'right': 1, 'left': 0} and margin > 1.0


def test_continuity_decides_when_the_evidence_is_even():
    a, b = _candidate(2.0, 2.0, 100.0), _candidate(2.0, 2.0, 500.0)
    assignment, margin = assign_hands([a, b], {'right': np.array([490.0, 240.0]),
                                               'left': np.array([110.0, 240.0])})
    assert assignment == {'right': 1, 'left': 0} and margin > 1.0
    _, margin = assign_hands([a, b], {'right': None, 'left': None})
    assert margin == 0.0                         # nothing to tell them apart: not decided


def test_one_region_is_the_hand_its_evidence_says():
    assignment, _ = assign_hands([_candidate(3.0, 1.5, 300.0)], {'right': None, 'left': None})
    assert assignment == {'left': 0}


def test_two_rendered_gloves_are_two_regions(node_assets):
    from colorglove_ros.core.segmentation.segmenter import load_segmenter

    camera = default_camera()
    q = sample_pose(np.random.default_rng(4), camera, out_of_frame_prob=0.0)
    q[0:3] = [0.0, 0.0, 0.55]
    q_right, q_left = q.copy(), mirror_pose(q)
    q_right[0] += 0.14
    q_left[0] -= 0.14
    synth = Synthesizer()
    try:
        frame, which = synth.render_hands([(q_right, 'right'), (q_left, 'left')], camera,
                                          np.random.default_rng(1),
                                          sample_conditions(np.random.default_rng(4), 'test'))
    finally:
        synth.release()
    segmenter = load_segmenter(str(node_assets.color_config))
    regions = find_glove_regions(segmenter, frame.image_rgb)
    assert len(regions) == 2
    for k in (1, 2):      # each hand's glove lies (mostly) inside one region
        ys, xs = np.nonzero(which == k)
        inside = [np.mean((xs >= r.box[0]) & (xs < r.box[2]) & (ys >= r.box[1])
                          & (ys < r.box[3])) for r in regions]
        assert max(inside) == pytest.approx(1.0, abs=0.05)
    # a region segmented in its window, moved back, is what the image with the other hand
    # painted out gives
    for k, region in enumerate(regions):
        other = regions[1 - k]
        whole, whole_tiny = observe_image(segmenter.fresh(background_frames=0),
                                          mask_regions(frame.image_rgb, [other]), True)
        x0, y0, x1, y1 = region_window(region, frame.image_rgb.shape, 0.5)
        assert (x1 - x0) * (y1 - y0) < 0.6 * frame.image_rgb.shape[0] * frame.image_rgb.shape[1]
        part, part_tiny = shift_observation(*observe_image(
            segmenter.fresh(background_frames=0),
            mask_regions(frame.image_rgb[y0:y1, x0:x1], [other], origin=(x0, y0)), True),
            x0, y0)
        assert whole.hand_found and part.hand_found
        np.testing.assert_allclose(part.crop.center_xy, whole.crop.center_xy, atol=2.0)
        assert part.crop.scale == pytest.approx(whole.crop.scale, rel=0.05)
        np.testing.assert_allclose(np.sort(part.blobs.centroid_px, axis=0),
                                   np.sort(whole.blobs.centroid_px, axis=0), atol=2.0)
        assert np.mean(part_tiny.labels == whole_tiny.labels) > 0.95


def test_a_region_looked_up_as_one_hand_only_is_decided_by_continuity():
    # each region looked up only as the hand continuity gave it last: no lookup evidence, so
    # the nearer previous centre decides, however small the one distance is
    a, b = _candidate(1.0, 3.0, 100.0), _candidate(3.0, 1.0, 300.0)
    del a.lookups['left'], b.lookups['right']
    assignment, margin = assign_hands([a, b], {'right': np.array([300.0, 240.0]),
                                               'left': np.array([100.0, 240.0])})
    assert assignment == {'right': 1, 'left': 0} and margin > 1.0


@pytest.mark.parametrize('origin', [(0, 0), (6, 3)])
def test_a_region_with_cells_is_painted_cell_by_cell(origin):
    cells = np.zeros((6, 8), bool)
    cells[1:3, 2:4] = True                      # full pixels x 8..15, y 4..11 (4 px a cell)
    region = GloveRegion((8, 4, 16, 12), 4, cells, 4)
    image = np.full((24, 32, 3), 7, np.uint8)
    ox, oy = origin
    out = mask_regions(image[oy:, ox:], [region], origin=origin)
    painted = np.zeros((24, 32), bool)
    painted[4:12, 8:16] = True
    np.testing.assert_array_equal(out[..., 0] == 128, painted[oy:, ox:])
    boxed = mask_regions(image, [GloveRegion((8, 4, 16, 12), 4)], margin=0.5)
    assert np.count_nonzero(boxed[..., 0] == 128) > np.count_nonzero(painted)
