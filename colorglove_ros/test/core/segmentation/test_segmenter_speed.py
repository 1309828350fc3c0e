"""The segmenter's cheaper per-pixel steps (issue 19): the same decisions as the full-resolution
ones they replace, at the precision they are stated with."""
from __future__ import annotations

import numpy as np
from segmentation_samples import printed_glove_calibration

from colorglove_ros.core.segmentation import segmenter as segmenter_module
from colorglove_ros.core.segmentation.detection import glove_region_mask
from colorglove_ros.core.segmentation.segmenter import sampled_glove_region_mask
from colorglove_ros.core.synthetic import frames as synth
from colorglove_ros.core.synthetic.conditions import FrameConditions


def _scene(scale: int) -> np.ndarray:
    """A colourful patchwork with a long one-colour finger and a far two-colour texture (the
    scene of test_detection's region-mask test), each pixel ``scale`` x ``scale``."""
    labels = np.zeros((80, 160), np.uint8)
    yy, xx = np.mgrid[0:24, 0:24]
    labels[10:34, 10:34] = ((yy // 4) * 3 + (xx // 4)) % 8 + 1
    labels[20:24, 34:70] = 3
    labels[40:78, 100:158] = np.where(np.arange(58)[None, :] % 8 < 4, 1, 2)
    return np.kron(labels, np.ones((scale, scale), np.uint8))


def test_sampled_region_mask_with_step_one_is_the_full_one() -> None:
    labels = _scene(1)
    assert np.array_equal(sampled_glove_region_mask(labels, 10, 12, 6, 0.02, 1),
                          glove_region_mask(labels, 10, 12, 6, 0.02))


def test_sampled_region_mask_keeps_the_glove_and_finger_and_drops_far_texture() -> None:
    labels = _scene(4)
    full = glove_region_mask(labels, 10, 48, 6, 0.02)
    sampled = sampled_glove_region_mask(labels, 10, 48, 6, 0.02, 4)
    assert sampled.shape == labels.shape and sampled.dtype == bool
    assert sampled[40:136, 40:136].all() and sampled[80:96, 136:280].all()
    assert not sampled[240:312, 520:632].any()
    # the full mask's own decisions, but for a band of about the sampling step at its edge
    assert np.mean(sampled == full) > 0.98
    edge = np.zeros(labels.shape, bool)
    for dy in range(-4, 5):
        for dx in range(-4, 5):
            edge |= np.roll(full, (dy, dx), axis=(0, 1)) != full
    assert np.array_equal(sampled[~edge], full[~edge])


def test_sampled_region_mask_is_empty_without_a_colourful_window() -> None:
    labels = _scene(4)[160:]
    assert not sampled_glove_region_mask(labels, 10, 48, 6, 0.02, 4).any()
    odd = _scene(4)[:157, :301]                      # sizes no multiple of the step
    mask = sampled_glove_region_mask(odd, 10, 48, 6, 0.02, 4)
    assert mask.shape == odd.shape and mask[40:136, 40:136].all()


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
