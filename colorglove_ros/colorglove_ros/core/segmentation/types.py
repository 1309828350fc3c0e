"""Data types of a segmentation result (light to import: the ROS message adapters use them)."""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from colorglove_ros.core.segmentation.crop import CropTransform

__all__ = ['Blob', 'Observation']


@dataclass(frozen=True)
class Blob:
    """One connected component of one glove colour, in full-image pixels."""

    color_label: int
    centroid_x: float
    centroid_y: float
    pixel_count: int


@dataclass
class Observation:
    """What the segmenter saw in one frame."""

    hand_found: bool
    status: str
    image_width: int
    image_height: int
    tiny_labels: np.ndarray | None = None   # (40, 40) uint8 whenever a crop was made
    crop: CropTransform | None = None       # tiny -> full image pixels (or None)
    blobs: list[Blob] = field(default_factory=list)
    glove_pixel_count: int = 0              # glove pixels inside the crop (full-res units)
    cut_by_border: bool = False             # glove pixels on the image's outermost pixels
    timings_ms: dict[str, float] = field(default_factory=dict)
    label_image: np.ndarray | None = None   # (H, W) uint8, only with keep_labels=True
