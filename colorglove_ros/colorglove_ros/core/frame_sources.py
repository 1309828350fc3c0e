"""Where camera frames come from: a V4L2 device, a video file, a folder of images, or the
synthetic renderer (a seeded sequence with ground truth)."""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from colorglove_ros.core.camera import PinholeCamera
from colorglove_ros.core.conventions import DEFAULT_HAND_LENGTH_M
from colorglove_ros.core.errors import ColorGloveError

__all__ = ['FrameSourceError', 'Frame', 'FrameSource', 'open_frame_source', 'IMAGE_SUFFIXES']

IMAGE_SUFFIXES = ('.png', '.jpg', '.jpeg', '.bmp', '.ppm', '.tif', '.tiff')


class FrameSourceError(ColorGloveError):
    """A frame source cannot be opened or read."""


@dataclass
class Frame:
    """One camera frame; ``ground_truth_pose`` (26) and keypoints only for synthetic frames."""

    image_rgb: np.ndarray
    ground_truth_pose: np.ndarray | None = None
    ground_truth_keypoints: np.ndarray | None = None


class FrameSource:
    """Yields frames from a reader function; ``read()`` returns None at the end (or loops)."""

    def __init__(self, description: str, reader: Callable[[int], Frame | None],
                 length: int | None, loop: bool, release: Callable[[], None] = lambda: None):
        self.description = description
        self._reader = reader
        self.length = length
        self.loop = loop
        self._release = release
        self.index = 0

    def read(self) -> Frame | None:
        """The next frame, or None when a non-looping source is exhausted."""
        if self.length is not None and self.index >= self.length:
            if not self.loop:
                return None
            self.index = 0
        frame = self._reader(self.index)
        self.index += 1
        return frame

    def close(self) -> None:
        """Release the device or file."""
        self._release()


def _capture_source(target: str | int, description: str, loop: bool) -> FrameSource:
    capture = cv2.VideoCapture(target)
    if not capture.isOpened():
        raise FrameSourceError(f'cannot open {description}')
    count = int(capture.get(cv2.CAP_PROP_FRAME_COUNT))
    length = count if isinstance(target, str) and count > 0 else None

    def read(index: int) -> Frame | None:
        if index == 0 and length is not None:
            capture.set(cv2.CAP_PROP_POS_FRAMES, 0)
        ok, bgr = capture.read()
        if not ok or bgr is None:
            if length is None:     # a live device: a failed read is an error, not the end
                raise FrameSourceError(f'{description}: frame read failed')
            return None
        return Frame(cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB))

    return FrameSource(description, read, length, loop, capture.release)


def _folder_source(folder: Path, loop: bool) -> FrameSource:
    files = sorted(p for p in folder.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES)
    if not files:
        raise FrameSourceError(
            f'image folder {folder} holds no images ({", ".join(IMAGE_SUFFIXES)})')

    def read(index: int) -> Frame | None:
        bgr = cv2.imread(str(files[index]), cv2.IMREAD_COLOR)
        if bgr is None:
            raise FrameSourceError(f'cannot decode image {files[index]}')
        return Frame(cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB))

    return FrameSource(f'image folder {folder} ({len(files)} images)', read, len(files), loop)


def _synthetic_source(camera: PinholeCamera, seed: int, num_frames: int, loop: bool,
                      hand_length_m: float, prerender: bool) -> FrameSource:
    from colorglove_ros.core.synthetic.sequences import SyntheticSequenceRenderer

    renderer = SyntheticSequenceRenderer(camera, seed=seed, num_frames=num_frames,
                                         hand_length_m=hand_length_m, split='test')

    def render(index: int) -> Frame:
        frame = renderer.render(index)
        return Frame(frame.image_rgb, frame.pose, frame.keypoints_3d)

    description = f'synthetic sequence (seed {seed}, {num_frames} frames)'
    if not prerender:
        return FrameSource(description, render, num_frames, loop, renderer.close)
    frames = [render(index) for index in range(num_frames)]
    renderer.close()
    return FrameSource(f'{description}, pre-rendered', frames.__getitem__, num_frames, loop)


def open_frame_source(spec: str, camera: PinholeCamera, *, seed: int = 1, num_frames: int = 300,
                      loop: bool = True, hand_length_m: float = DEFAULT_HAND_LENGTH_M,
                      prerender: bool = False) -> FrameSource:
    """Open ``spec``: 'synthetic', a V4L2 index ('0') or device path ('/dev/video0'), a video
    file, or a folder of images. Raise :class:`FrameSourceError` if it cannot be opened.
    ``prerender`` renders a synthetic sequence up front (memory for speed at run time)."""
    spec = str(spec).strip()
    if spec in ('', 'synthetic'):
        return _synthetic_source(camera, seed, num_frames, loop, hand_length_m, prerender)
    if spec.isdigit():
        return _capture_source(int(spec), f'V4L2 camera index {spec}', loop)
    path = Path(spec).expanduser()
    if spec.startswith('/dev/'):
        if not path.exists():
            raise FrameSourceError(f'camera device {spec} does not exist')
        return _capture_source(spec, f'camera device {spec}', loop)
    if path.is_dir():
        return _folder_source(path, loop)
    if path.is_file():
        return _capture_source(str(path), f'video file {path}', loop)
    raise FrameSourceError(f'frame source {spec!r} is neither "synthetic", a camera, '
                           'a video file nor an image folder')
