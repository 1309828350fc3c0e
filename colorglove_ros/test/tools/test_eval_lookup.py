"""eval_lookup's helper that turns a tiny label image into full-image blobs for the
per-finger blend (the lookup the nodes run)."""
from __future__ import annotations

import numpy as np

from colorglove_ros.tools.eval_lookup import _tiny_blobs


def test_tiny_blobs_map_to_full_image_pixels() -> None:
    tiny = np.zeros((40, 40), np.uint8)
    tiny[10:14, 20:22] = 3            # 8 pixels, centroid (x 20.5, y 11.5)
    tiny[30, 5] = 7                   # a single pixel still counts
    blobs = _tiny_blobs(tiny, np.array([2.5, 100.0, 50.0]))
    order = np.argsort(blobs.color)
    np.testing.assert_array_equal(blobs.color[order], [3, 7])
    np.testing.assert_allclose(blobs.centroid_px[order],
                               [[100.0 + 2.5 * 20.5, 50.0 + 2.5 * 11.5],
                                [100.0 + 2.5 * 5.0, 50.0 + 2.5 * 30.0]])
    np.testing.assert_allclose(blobs.pixel_count[order], [8 * 6.25, 6.25])
