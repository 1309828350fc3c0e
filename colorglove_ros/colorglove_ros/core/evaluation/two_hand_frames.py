"""Frames of a two-hand synthetic sequence and when both hands in them are fully visible: the
one definition the two-hand evaluation and the two-hand speed benchmark share.

Both hands are fully visible in a frame when their 2-D keypoint boxes, grown by 15 %, lie
inside the image and apart, and neither glove is hidden by the other hand or its arm: each
shows at least :data:`FULLY_VISIBLE_SHARE` of the glove pixels it shows rendered alone in the
same frame (same pose, light, background and noise)."""
from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from typing import Any

import numpy as np

from colorglove_ros.core.hand.handedness import HANDS

__all__ = ['FULLY_VISIBLE_SHARE', 'RATE_TARGET_PER_HAND_HZ', 'TwoHandFrame', 'both_visible',
           'visible_share', 'two_hand_frames']

#: A glove is fully visible when it shows at least this share of the pixels it shows alone.
FULLY_VISIBLE_SHARE = 0.99
#: Issue 18's rate target: JointStates per second per hand with a 30 Hz camera.
RATE_TARGET_PER_HAND_HZ = 30.0


def both_visible(kp2: dict[str, np.ndarray], width: int, height: int,
                 grow: float = 0.15) -> bool:
    """Both hands fully in view and apart: their 2-D keypoint boxes grown by ``grow`` lie
    inside the image and do not overlap."""
    boxes = []
    for pts in kp2.values():
        lo, hi = pts.min(0), pts.max(0)
        pad = grow * (hi - lo)
        lo, hi = lo - pad, hi + pad
        if lo[0] < 0 or lo[1] < 0 or hi[0] > width - 1 or hi[1] > height - 1:
            return False
        boxes.append((lo, hi))
    (a0, a1), (b0, b1) = boxes
    return bool(np.any(a1 < b0) or np.any(b1 < a0))


def visible_share(which: np.ndarray, k: int, which_alone: np.ndarray) -> float:
    """The share of hand ``k``'s glove pixels when rendered alone (``which_alone`` == 1) that
    the two-hand frame shows as its glove (``which`` == k + 1); 1 for a glove out of view."""
    alone = int(np.count_nonzero(which_alone == 1))
    return 1.0 if alone == 0 else float(np.count_nonzero(which == k + 1)) / alone


@dataclass(frozen=True)
class TwoHandFrame:
    """One rendered two-hand frame: the frame (its ground truth is the first hand of
    :data:`HANDS`), which hand's glove each pixel shows, each hand rendered alone, whether the
    keypoint boxes are apart, and whether both hands are fully visible."""

    frame: Any
    which: np.ndarray
    singles: dict[str, Any]
    apart: bool
    fully_visible: bool


def two_hand_frames(synth: Any, camera: Any, poses: dict[str, np.ndarray], seed: int,
                    conditions: Any, frames: int) -> Iterator[TwoHandFrame]:
    """The first ``frames`` frames of two-hand sequence ``seed`` (``poses``: each hand's
    poses, as ``two_hand_sequences`` gives them) rendered by ``synth`` under ``conditions``,
    with each hand also rendered alone to decide full visibility. Frame ``i``'s noise comes
    from ``default_rng([seed, i, 11])``, so a frame is the same whatever else is rendered."""
    for i in range(frames):
        frame, which = synth.render_hands([(poses[h][i], h) for h in HANDS], camera,
                                          np.random.default_rng([seed, i, 11]), conditions)
        kp2 = {h: camera.project(synth.keypoints(poses[h][i], h)) for h in HANDS}
        apart = both_visible(kp2, camera.width, camera.height)
        singles, shares = {}, []
        for k, h in enumerate(HANDS):
            singles[h], which_alone = synth.render_hands(
                [(poses[h][i], h)], camera, np.random.default_rng([seed, i, 11]), conditions)
            shares.append(visible_share(which, k, which_alone))
        yield TwoHandFrame(frame, which, singles, apart,
                           apart and min(shares) >= FULLY_VISIBLE_SHARE)
