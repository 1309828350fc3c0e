"""Draw the fitted hand skeleton over a camera frame, and the skeleton's bone list."""
from __future__ import annotations

import cv2
import numpy as np

from colorglove_ros.core.camera import PinholeCamera
from colorglove_ros.core.hand.model import DIGITS, KEYPOINT_NAMES

__all__ = ['SKELETON_BONES', 'DIGIT_COLORS_RGB', 'draw_skeleton']


def _bones() -> list[tuple[int, int]]:
    index = {name: i for i, name in enumerate(KEYPOINT_NAMES)}
    bones = []
    for digit in DIGITS:
        chain = [name for name in KEYPOINT_NAMES if name.startswith(f'{digit}_')]
        bones.append((index['wrist'], index[chain[0]]))
        bones += [(index[a], index[b]) for a, b in zip(chain, chain[1:], strict=False)]
    return bones


SKELETON_BONES: tuple[tuple[int, int], ...] = tuple(_bones())
DIGIT_COLORS_RGB = np.array([[255, 64, 64], [255, 200, 0], [64, 220, 64], [0, 170, 255],
                             [200, 80, 255]], dtype=np.uint8)


def draw_skeleton(image_rgb: np.ndarray, keypoints_camera: np.ndarray, camera: PinholeCamera,
                  label: str = '', thickness: int = 2) -> np.ndarray:
    """A copy of ``image_rgb`` with the 21-keypoint skeleton (camera-frame points) drawn in."""
    canvas = np.ascontiguousarray(image_rgb).copy()
    in_front = keypoints_camera[:, 2] > 1e-3
    pixels = np.zeros((len(keypoints_camera), 2))
    pixels[in_front] = camera.project(keypoints_camera[in_front])
    bones_per_digit = len(SKELETON_BONES) // len(DIGITS)
    for bone_index, (a, b) in enumerate(SKELETON_BONES):
        if not (in_front[a] and in_front[b]):
            continue
        color = tuple(int(c) for c in DIGIT_COLORS_RGB[bone_index // bones_per_digit])
        cv2.line(canvas, tuple(np.round(pixels[a]).astype(int)),
                 tuple(np.round(pixels[b]).astype(int)), color, thickness, cv2.LINE_AA)
    for point in pixels[in_front]:
        cv2.circle(canvas, tuple(np.round(point).astype(int)), thickness + 1, (255, 255, 255),
                   -1, cv2.LINE_AA)
    if label:
        cv2.putText(canvas, label, (8, 20), cv2.FONT_HERSHEY_SIMPLEX, 0.55, (255, 255, 255), 2,
                    cv2.LINE_AA)
        cv2.putText(canvas, label, (8, 20), cv2.FONT_HERSHEY_SIMPLEX, 0.55, (0, 0, 0), 1,
                    cv2.LINE_AA)
    return canvas
