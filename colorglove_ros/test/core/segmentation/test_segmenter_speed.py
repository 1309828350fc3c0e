"""The segmenter skips work whose result is not used (issue 19)."""
from __future__ import annotations

import threading

import numpy as np
import pytest
from segmentation_samples import printed_glove_calibration

from colorglove_ros.core.segmentation import segmenter as segmenter_module
from colorglove_ros.core.synthetic import frames as synth
from colorglove_ros.core.synthetic.conditions import FrameConditions


def test_patch_junctions_are_only_searched_when_oversized_patches_are_shed(monkeypatch) -> None:
    """``max_patch_window_share`` 0 (the default) sheds nothing: the coarse pass does not
    search the patch junctions for the hand's window either."""
    calls = []
    real = segmenter_module.junction_window
    monkeypatch.setattr(segmenter_module, 'junction_window',
                        lambda *args, **kwargs: calls.append(1) or real(*args, **kwargs))
    camera = synth.default_camera()
    rng = np.random.default_rng(4)
    q = synth.sample_pose(rng, camera, out_of_frame_prob=0.0)
    q[0:3] = [0.0, 0.0, 0.6]
    image = synth.render_frame(q, camera, rng, FrameConditions()).image_rgb
    calibration = printed_glove_calibration()
    off = segmenter_module.GloveSegmenter(calibration).process(image)
    assert off.hand_found and not calls
    on = segmenter_module.GloveSegmenter(calibration, max_patch_window_share=0.15).process(image)
    assert on.hand_found and calls


@pytest.fixture(scope='module')
def printed_calibration():
    """The printed glove's calibration, fitted once for this module's tests."""
    return printed_glove_calibration()


def _printed_frame(seed: int) -> np.ndarray:
    """A clean synthetic frame of the printed glove, 0.6 m from the camera."""
    camera = synth.default_camera()
    rng = np.random.default_rng(seed)
    q = synth.sample_pose(rng, camera, out_of_frame_prob=0.0)
    q[0:3] = [0.0, 0.0, 0.6]
    return synth.render_frame(q, camera, rng, FrameConditions()).image_rgb


@pytest.mark.parametrize('seed', [4, 8])
def test_two_resolution_cleans_the_region_on_a_coarser_grid_and_keeps_the_observation(
        monkeypatch, printed_calibration, seed: int) -> None:
    """``cleanup_factor`` 2: the region of interest's clutter filter runs on a grid half as
    fine, and the glove's labels, crop, tiny image and blobs come from full resolution:
    on a clean frame the observation is the one-resolution one."""
    shapes: list[tuple[int, int]] = []
    real = segmenter_module.glove_region_mask
    monkeypatch.setattr(segmenter_module, 'glove_region_mask',
                        lambda labels, *a, **k: shapes.append(labels.shape) or real(
                            labels, *a, **k))
    image = _printed_frame(seed)
    calibration = printed_calibration
    one = segmenter_module.GloveSegmenter(calibration).process(image)
    (_, roi_shape), shapes[:] = shapes, []
    two = segmenter_module.GloveSegmenter(calibration, cleanup_factor=2).process(image)
    (_, cleaned_shape) = shapes
    assert cleaned_shape == (roi_shape[0] // 2, roi_shape[1] // 2)
    assert one.hand_found and two.hand_found
    assert one.crop == two.crop
    np.testing.assert_array_equal(one.tiny_labels, two.tiny_labels)
    assert one.blobs == two.blobs
    assert one.glove_pixel_count == two.glove_pixel_count


def test_the_finer_grid_keeps_whole_components_that_reach_the_kept_glove() -> None:
    """A glove component of the finer grid is kept whole when one of its pixels lies in the
    kept glove (a fingertip cut off on the coarser grid stays with its finger), a component
    reaching none is dropped, and so are the removed pixels (clutter touching the glove)."""
    labels = np.zeros((12, 16), np.uint8)
    labels[2:6, 2:8] = 1          # the hand's piece, kept on the coarser grid
    labels[6:10, 7:9] = 2         # a fingertip touching it: not kept on the coarser grid
    labels[2:4, 12:15] = 3        # clutter reaching no kept pixel
    labels[6, 2:4] = 4            # clutter touching the hand, removed on the coarser grid
    reached = np.zeros(labels.shape, bool)
    reached[3:5, 3:6] = True
    removed = labels == 4
    out = segmenter_module.keep_reaching_components(labels, reached, removed)
    expected = labels.copy()
    expected[labels >= 3] = 0
    np.testing.assert_array_equal(out, expected)


def test_cleanup_factor_is_checked(blob_calibration) -> None:
    with pytest.raises(segmenter_module.SegmentationConfigError, match='cleanup_factor'):
        segmenter_module.GloveSegmenter(blob_calibration, cleanup_factor=0)


def test_learning_in_a_thread_gives_the_same_observations_and_learns_on_the_worker(
        monkeypatch, printed_calibration) -> None:
    """``learn_in_thread`` 1: the static background learns from each frame on the worker
    thread while the region of interest is segmented, and is done when ``process``
    returns: frame after frame the observations, the learnt background and the glove-like
    mask are those of learning in the caller's thread."""
    threads: list[str] = []
    real = segmenter_module.StaticBackground.update

    def update(self, *args, **kwargs) -> None:
        threads.append(threading.current_thread().name)
        real(self, *args, **kwargs)

    monkeypatch.setattr(segmenter_module.StaticBackground, 'update', update)
    image = _printed_frame(4)
    settings = {'background_frames': 2, 'background_memory': 1}
    inline = segmenter_module.GloveSegmenter(printed_calibration, **settings)
    worker = segmenter_module.GloveSegmenter(printed_calibration, learn_in_thread=1, **settings)
    main = threading.current_thread().name
    for _ in range(4):
        one, threads[:] = inline.process(image), []
        two = worker.process(image)
        assert threads and main not in threads and worker._learning is None
        assert one.status == two.status and one.crop == two.crop and one.blobs == two.blobs
        np.testing.assert_array_equal(one.tiny_labels, two.tiny_labels)
        np.testing.assert_array_equal(inline._glove_like_mask, worker._glove_like_mask)
        np.testing.assert_array_equal(inline.background._matched, worker.background._matched)
    assert one.hand_found and inline.background.match(
        inline._small(image)[0]) is not None    # (something was learnt and is used)


def test_a_failed_learning_in_the_thread_is_raised_by_process(monkeypatch,
                                                              printed_calibration) -> None:
    """An error of the worker's learning is not lost: ``process`` raises it."""
    def update(self, *args, **kwargs) -> None:
        raise RuntimeError('learning failed')

    monkeypatch.setattr(segmenter_module.StaticBackground, 'update', update)
    seg = segmenter_module.GloveSegmenter(printed_calibration, background_frames=2,
                                          learn_in_thread=1)
    with pytest.raises(RuntimeError, match='learning failed'):
        seg.process(_printed_frame(4))
    assert seg._learning is None


def test_a_deferred_learning_gives_the_same_observations_and_waits_for_its_call(
        printed_calibration) -> None:
    """``defer_learning``: the frame's static-background learning runs only in
    ``learn_deferred`` (the node calls it after publishing) or, if nobody calls it, at the
    start of the next ``process``; frame after frame the observations, the glove-like mask and
    the learnt counts are those of learning inline."""
    images = [_printed_frame(4), _printed_frame(5), _printed_frame(4), _printed_frame(6)]
    settings = {'background_frames': 2, 'background_memory': 1}
    inline = segmenter_module.GloveSegmenter(printed_calibration, **settings)
    called = segmenter_module.GloveSegmenter(printed_calibration, **settings)
    next_call = segmenter_module.GloveSegmenter(printed_calibration, **settings)
    for image in images:
        one = inline.process(image)
        before = _copy(called.background._matched)
        two = called.process(image, defer_learning=True)
        assert called._deferred is not None          # not learnt yet
        _assert_same(called.background._matched, before)
        called.learn_deferred()
        assert called._deferred is None
        three = next_call.process(image, defer_learning=True)
        for other in (two, three):
            assert one.status == other.status and one.crop == other.crop
            assert one.blobs == other.blobs
            np.testing.assert_array_equal(one.tiny_labels, other.tiny_labels)
        np.testing.assert_array_equal(inline._glove_like_mask, called._glove_like_mask)
        np.testing.assert_array_equal(inline.background._matched, called.background._matched)
    assert one.hand_found and inline.background._matched is not None
    called.learn_deferred()                           # nothing pending: nothing happens
    np.testing.assert_array_equal(inline.background._matched, called.background._matched)


def _copy(values: np.ndarray | None) -> np.ndarray | None:
    return None if values is None else values.copy()


def _assert_same(values: np.ndarray | None, expected: np.ndarray | None) -> None:
    assert (values is None) == (expected is None)
    if expected is not None:
        np.testing.assert_array_equal(values, expected)
