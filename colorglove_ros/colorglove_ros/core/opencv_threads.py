"""How many threads OpenCV may use in a process that tracks: one home for the nodes' and the
evaluation tools' setting."""
from __future__ import annotations

__all__ = ['OPENCV_THREADS', 'use_opencv_threads']

#: Default OpenCV thread count of the nodes that run OpenCV per frame, and of the tools that
#: time them: one thread. Their images are small (a coarse frame, a region of interest, 40x40
#: tiny images, an edge tracker's search windows), so OpenCV's worker threads cost the calling
#: thread more in dispatch than they take off it, and the graph's processes share the
#: machine's cores anyway.
OPENCV_THREADS = 1


def use_opencv_threads(threads: int) -> int:
    """Apply ``threads`` to this process (``cv2.setNumThreads``: process-wide; -1 is OpenCV's
    own default, all cores) and return it."""
    import cv2

    cv2.setNumThreads(int(threads))
    return int(threads)
