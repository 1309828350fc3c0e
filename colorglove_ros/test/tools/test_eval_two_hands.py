"""colorglove_eval_two_hands' visibility rules: a glove hidden in part by the other hand or its
arm is not fully visible, however far apart the two hands' keypoint boxes are."""
from __future__ import annotations

import numpy as np

from colorglove_ros.core.evaluation.two_hand_frames import (
    FULLY_VISIBLE_SHARE,
    both_visible,
    visible_share,
)


def test_a_glove_hidden_by_the_other_arm_is_not_fully_visible():
    alone = np.zeros((10, 10), np.uint8)
    alone[2:6, 2:6] = 1                            # hand 0 alone: 16 glove pixels
    both = np.where(alone == 1, 1, 0).astype(np.uint8)
    both[7:9, 7:9] = 2                             # the other hand's glove elsewhere
    assert visible_share(both, 0, alone) == 1.0
    both[2:4, 2:6] = 0                             # an arm across half of hand 0's glove
    assert visible_share(both, 0, alone) == 0.5 < FULLY_VISIBLE_SHARE
    other_alone = (both == 2).astype(np.uint8)
    assert visible_share(both, 1, other_alone) == 1.0
    assert visible_share(both, 0, np.zeros_like(alone)) == 1.0   # out of view: nothing hidden


def test_boxes_apart_and_inside_the_image():
    a = np.array([[10.0, 10.0], [50.0, 60.0]])
    assert both_visible({'right': a, 'left': a + [100.0, 0.0]}, 640, 480)
    assert not both_visible({'right': a, 'left': a + [20.0, 5.0]}, 640, 480)     # overlap
    assert not both_visible({'right': a - [15.0, 0.0], 'left': a + [100.0, 0.0]}, 640, 480)
