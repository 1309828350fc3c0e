"""Random 40x40 label images of coloured discs, for tests of distances, codes and search."""
from __future__ import annotations

import numpy as np


def random_blob_images(rng: np.random.Generator, count: int, blobs: int | tuple[int, int] = 5,
                       radius: tuple[int, int] = (3, 8)) -> np.ndarray:
    """``count`` (40, 40) uint8 label images, each with ``blobs`` discs of colours 1..10 (a
    number drawn from [lo, hi) per image when ``blobs`` is a pair), radii from ``radius``
    [lo, hi)."""
    yy, xx = np.mgrid[0:40, 0:40]
    images = np.zeros((count, 40, 40), np.uint8)
    for i in range(count):
        discs = blobs if isinstance(blobs, int) else int(rng.integers(*blobs))
        for _ in range(discs):
            c, x, y, r = rng.integers(1, 11), *rng.integers(6, 34, 2), rng.integers(*radius)
            images[i][(xx - x) ** 2 + (yy - y) ** 2 <= r * r] = c
    return images
