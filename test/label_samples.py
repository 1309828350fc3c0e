"""Random 40x40 label images of coloured discs, for tests of distances, codes and search."""
from __future__ import annotations

import numpy as np


def random_blob_images(rng: np.random.Generator, count: int, blobs: int = 5) -> np.ndarray:
    """``count`` (40, 40) uint8 label images, each with ``blobs`` discs of colours 1..10."""
    yy, xx = np.mgrid[0:40, 0:40]
    images = np.zeros((count, 40, 40), np.uint8)
    for i in range(count):
        for _ in range(blobs):
            c, x, y, r = rng.integers(1, 11), *rng.integers(6, 34, 2), rng.integers(3, 8)
            images[i][(xx - x) ** 2 + (yy - y) ** 2 <= r * r] = c
    return images
