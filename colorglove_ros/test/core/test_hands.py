"""The two-hand layer (core/hands.py): glove regions of a frame with two rendered hands, the
handedness assignment from the lookup evidence and continuity, the painting of the other
regions, and the two-thread run (the same outcomes as one thread)."""
from __future__ import annotations

import threading
from types import SimpleNamespace

import numpy as np
import pytest

from colorglove_ros.core.hand.handedness import HANDS, mirror_pose
from colorglove_ros.core.hands import (
    MAX_HANDS,
    FrameTiming,
    GloveRegion,
    HandCandidate,
    TwoHandPipeline,
    assign_hands,
    find_glove_regions,
    mask_regions,
    region_window,
    shift_observation,
    slot_lookups,
)
from colorglove_ros.core.pipeline import UNGATED, Tracked, observe_image
from colorglove_ros.core.segmentation.crop import CropTransform
from colorglove_ros.core.synthetic.conditions import sample_conditions
from colorglove_ros.core.synthetic.frames import Synthesizer, default_camera, sample_pose
from colorglove_ros.core.synthetic.sequences import two_hand_sequences
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


@pytest.mark.parametrize('seed', range(4))
def test_painting_cells_marks_exactly_the_pixels_of_glove_cells(seed):
    rng = np.random.default_rng(seed)
    cell_px = int(rng.integers(1, 6))
    cells = rng.random((int(rng.integers(3, 12)), int(rng.integers(3, 12)))) < 0.4
    region = GloveRegion((0, 0, 1, 1), 1, cells, cell_px)
    h, w = int(rng.integers(5, 60)), int(rng.integers(5, 60))
    origin = (int(rng.integers(0, 40)), int(rng.integers(0, 40)))
    out = mask_regions(np.zeros((h, w, 3), np.uint8), [region], origin=origin)
    ys, xs = np.mgrid[0:h, 0:w]
    cy, cx = (ys + origin[1]) // cell_px, (xs + origin[0]) // cell_px
    inside = (cy < cells.shape[0]) & (cx < cells.shape[1])
    expected = np.zeros((h, w), bool)
    expected[inside] = cells[cy[inside], cx[inside]]
    np.testing.assert_array_equal(out[..., 1] == 128, expected)


class _Segmenter:
    def fresh(self, **_: object) -> _Segmenter:
        return self


def test_the_second_slot_runs_on_the_worker_thread_and_errors_reach_the_caller():
    pipeline = TwoHandPipeline(_Segmenter(), [object(), object()], default_camera(), {})
    assert pipeline.parallel

    def job(k: int) -> tuple[int, str]:
        if k == 9:
            raise RuntimeError('slot failed')
        return k, threading.current_thread().name
    (a, first), (b, second) = pipeline._both(job, [(0,), (1,)])
    assert (a, b) == (0, 1) and first == threading.current_thread().name != second
    with pytest.raises(RuntimeError, match='slot failed'):
        pipeline._both(job, [(0,), (9,)])
    pipeline.close()
    assert not pipeline.parallel and pipeline._both(job, [(0,), (1,)])[1][1] == first
    with pytest.raises(ValueError, match='lookups'):
        TwoHandPipeline(_Segmenter(), [object()] * 3, default_camera(), {})


def test_two_threads_track_as_one_does(node_assets, small_database):
    from repo_paths import CONFIG_DIR

    from colorglove_ros.core.segmentation.segmenter import load_segmenter
    from colorglove_ros.core.tracking.config import load_ik_config
    from colorglove_ros.core.tracking.tracker import HandTracker

    camera = default_camera()
    synth = Synthesizer()
    try:
        poses = two_hand_sequences(1003, 4, camera=camera, model=synth.model)
        conditions = sample_conditions(np.random.default_rng(2), 'test')
        frames = [synth.render_hands([(poses[h][i], h) for h in HANDS], camera,
                                     np.random.default_rng(i), conditions)[0].image_rgb
                  for i in range(4)]
    finally:
        synth.release()
    segmenter = load_segmenter(str(node_assets.color_config))
    config = load_ik_config(CONFIG_DIR / 'ik.yaml')
    runs = {}
    for threads in (1, 2):
        lookups = slot_lookups(small_database, threads)
        assert isinstance(lookups, list) == (threads == 2)
        pipeline = TwoHandPipeline(segmenter, lookups, camera, {
            h: HandTracker(synth.model, synth.mesh, [camera], config, glove=synth.glove)
            for h in HANDS}, limits=UNGATED)     # the small database's matches are far
        assert pipeline.parallel == (threads == 2) and len(pipeline.lookups) == threads
        runs[threads] = []
        for i, f in enumerate(frames):
            runs[threads].append(pipeline.process(f, i / 30.0))
            timing = pipeline.last_timing     # this frame's thread CPU
            assert timing.parallel == (threads == 2) and timing.serial_ms >= 0.0
            assert timing.phases and all(len(p) <= MAX_HANDS for p in timing.phases)
            if threads == 1 or all(len(p) == 1 for p in timing.phases):
                assert timing.critical_path_ms == pytest.approx(timing.cpu_ms)
            else:
                assert timing.critical_path_ms < timing.cpu_ms
        pipeline.close()
    assert any(isinstance(o.outcome, Tracked) for out in runs[1] for o in out.values())
    for one, two in zip(runs[1], runs[2], strict=True):
        for h in HANDS:
            a, b = one[h], two[h]
            assert getattr(a.outcome, 'reason', None) == getattr(b.outcome, 'reason', None)
            assert (a.q is None) == (b.q is None) and a.region == b.region
            if a.q is not None:
                np.testing.assert_array_equal(a.q, b.q)
    with pytest.raises(ValueError, match='threads'):
        slot_lookups(small_database, 3)
    assert MAX_HANDS == len(HANDS)


def test_the_critical_path_is_the_serial_part_and_each_phase_s_slowest_job():
    two = FrameTiming(1.0, ((3.0, 2.0), (0.5, 1.5)), parallel=True)
    assert two.cpu_ms == 8.0 and two.critical_path_ms == 1.0 + 3.0 + 1.5
    one = FrameTiming(1.0, ((3.0, 2.0), (0.5, 1.5)), parallel=False)
    assert one.critical_path_ms == one.cpu_ms == 8.0
    assert FrameTiming(0.5, ((2.0,),), parallel=True).critical_path_ms == 2.5


def test_the_lookups_no_hand_is_tracked_from_are_searched_not_blended(node_assets,
                                                                       small_database):
    # a region of a frame with no hand known is looked up both ways for the assignment's
    # evidence, which needs the nearest distances only: both are searched, and the lookup a
    # hand is then tracked from is blended (as the whole lookup would have made it)
    from colorglove_ros.core.hands import Searched
    from colorglove_ros.core.lookup.search import PoseLookup
    from colorglove_ros.core.pipeline import look_up
    from colorglove_ros.core.segmentation.segmenter import load_segmenter

    camera = default_camera()
    synth = Synthesizer()
    try:
        poses = two_hand_sequences(1003, 1, camera=camera, model=synth.model)
        frame = synth.render_hands([(poses[h][0], h) for h in HANDS], camera,
                                   np.random.default_rng(0),
                                   sample_conditions(np.random.default_rng(2), 'test')
                                   )[0].image_rgb
    finally:
        synth.release()
    pipeline = TwoHandPipeline(load_segmenter(str(node_assets.color_config)),
                               slot_lookups(small_database, 1), camera, {}, limits=UNGATED)
    found = pipeline.candidates(frame)
    assert len(found) == 2
    whole = PoseLookup(small_database)
    for candidate in found:
        assert all(isinstance(candidate.lookups[h], Searched) for h in HANDS)
        for h in HANDS:
            tiny, blobs = pipeline._query(candidate, h)
            expected = look_up(whole, tiny, camera, blobs, UNGATED)
            assert candidate.distance(h) == expected.distances[0]
            blended = pipeline._look_up(candidate, h, 0)
            assert candidate.lookups[h] is blended
            np.testing.assert_array_equal(blended.blended, expected.blended)
            np.testing.assert_array_equal(blended.indices, expected.indices)
