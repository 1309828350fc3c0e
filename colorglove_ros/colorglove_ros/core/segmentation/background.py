"""What a static camera learns about its scene while it tracks: a pixel whose colour has held
still for a while is background, whatever colour it has.

Warm wood, a red mug or an orange shirt beside the hand are labelled glove colours, and no
colour rule can tell them from the glove's own patches. A camera on a desk or a tripod sees
them unchanged frame after frame, while the glove moves. :class:`StaticBackground` keeps, per
pixel of the segmenter's coarse (downsampled) frame, a running colour and for how many frames
in a row the pixel has matched it; a pixel that has matched for ``frames_needed`` frames and
still matches is background. Pixels at and around the glove found in a frame do not count
towards that (a hand held still never becomes background), and a pixel that changes starts
again. When most of the frame changes at once (the camera moved, the exposure jumped) the
model starts again: until it has learnt, the segmenter works as without it.

With ``remember`` a pixel also keeps the colour it had when it was last learnt background,
through the frames something covers it: the arm sweeping across a wooden desk or a red
cushion uncovers it again as it was, and it is background again at once instead of after
``frames_needed`` frames (the band the arm swept would otherwise be glove-coloured clutter
right beside the hand until then).

One model per camera stream, fed its frames in order. No rclpy import.
"""
from __future__ import annotations

from types import ModuleType

import cv2
import numpy as np

__all__ = ['StaticBackground']

_NO_COLOUR = np.zeros((0, 0, 3), np.float32)   # no learnt colours (the kernels' empty array)
_NO_MASK = np.zeros((0, 0), bool)               # no glove mask


def _kernels() -> ModuleType:
    """The segmentation's compiled kernels (loaded on the first match, not on import)."""
    from colorglove_ros.core.segmentation.crop import compiled_kernels

    return compiled_kernels()


class StaticBackground:
    """Per-pixel background of one static camera's coarse frames.

    ``frames_needed``: frames a pixel must match its running colour before it counts as
    background; ``tolerance``: the largest channel difference (sRGB levels) that still
    matches; ``adapt``: how fast the running colour follows slow changes (share per frame);
    ``max_changed_share``: when more of the frame than this changes at once, start again;
    ``remember``: a pixel showing again the colour it had when it was last learnt background
    is background (a surface uncovered as it was), within ``tolerance``, unless it was in
    the glove mask of the last :meth:`update` (the glove, moving over a surface of about its
    own colour, would match it)."""

    def __init__(self, frames_needed: int, tolerance: float, adapt: float = 0.05,
                 max_changed_share: float = 0.5, remember: bool = False) -> None:
        self.frames_needed = int(frames_needed)
        self.tolerance = float(tolerance)
        self.adapt = float(adapt)
        self.max_changed_share = float(max_changed_share)
        self.remember = bool(remember)
        self._colour: np.ndarray | None = None    # (h, w, 3) float32 running colour
        self._matched: np.ndarray | None = None   # (h, w) int32 frames matched in a row
        self._same: np.ndarray | None = None      # this frame's match, from :meth:`match`
        self._frame: np.ndarray | None = None     # ... and the frame as float32
        # remember: each pixel's colour when it was last learnt background (NaN: never), and
        # the last frame's glove mask, where a glove over a surface of its colour would match
        self._learnt: np.ndarray | None = None
        self._glove: np.ndarray | None = None

    @property
    def enabled(self) -> bool:
        """False when ``frames_needed`` is 0 (no background is ever learnt)."""
        return self.frames_needed > 0

    def reset(self) -> None:
        """Forget everything learnt (a new stream, the camera moved)."""
        self._colour = self._matched = self._same = self._frame = None
        self._learnt = self._glove = None

    def match(self, small: np.ndarray) -> np.ndarray | None:
        """(h, w) bool: the pixels of coarse frame ``small`` (uint8 RGB) that are learnt
        background and still show it; None when nothing is learnt yet (or disabled). Call
        :meth:`update` with the same frame afterwards."""
        self._same = self._frame = None
        if not self.enabled:
            return None
        if self._colour is None or self._colour.shape != small.shape:
            self.reset()
            return None
        small = np.ascontiguousarray(small, np.uint8)
        frame = np.empty(small.shape, np.float32)
        same = np.empty(small.shape[:2], bool)
        learnt = np.empty(small.shape[:2], bool)
        # (one compiled pass: the frame as float32, its match, and the learnt background)
        count = _kernels().background_match(
            small, self._colour, self._matched, self.frames_needed,
            _NO_COLOUR if self._learnt is None else self._learnt,
            _NO_MASK if self._glove is None else self._glove,
            np.float32(self.tolerance), frame, same, learnt)
        if 1.0 - count / same.size > self.max_changed_share:
            self.reset()
            return None
        self._same, self._frame = same, frame
        return learnt if learnt.any() else None

    def update(self, small: np.ndarray, glove: np.ndarray | None) -> None:
        """Learn from coarse frame ``small`` (the one just given to :meth:`match`): pixels that
        matched count one frame more, unless in ``glove`` ((h, w) bool: the glove found and a
        margin around it), which keep their count; the others start again from this frame's
        colour."""
        if not self.enabled:
            return
        if self._colour is None or self._same is None:
            self._colour = small.astype(np.float32)
            self._matched = np.zeros(small.shape[:2], np.int32)
            self._same = self._frame = None
            return
        frame = self._frame       # the float copy match() made of the same frame
        same = self._same
        counting = same if glove is None else same & ~glove
        self._matched += counting
        self._matched *= same
        # matched pixels follow slow changes (light drifting); changed ones restart
        cv2.accumulateWeighted(frame, self._colour, self.adapt, counting.view(np.uint8))
        if self.remember:
            self._glove = None if glove is None else glove.copy()
            if self._learnt is None:
                self._learnt = np.full(frame.shape, np.nan, np.float32)
            cv2.copyTo(self._colour, (self._matched >= self.frames_needed).view(np.uint8),
                       self._learnt)
        cv2.copyTo(frame, (~same).view(np.uint8), self._colour)    # (in place)
        self._same = self._frame = None
