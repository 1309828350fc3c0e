"""The segmenter skips work whose result is not used (issue 19)."""
from __future__ import annotations

import numpy as np
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
