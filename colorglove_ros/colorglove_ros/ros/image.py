"""Convert numpy arrays to and from ``sensor_msgs/Image``, honouring encoding, step, byte order.

Decoding is ``ros.image_codec`` (shared with the bag reader); this module adds the rclpy message
builder."""
from __future__ import annotations

import numpy as np
from sensor_msgs.msg import Image

from colorglove_ros.ros.image_codec import (
    ENCODINGS,
    ImageEncodingError,
    ImageFormat,
    compressed_image_to_rgb8,
    image_format,
    image_to_array,
    image_to_rgb8,
)

__all__ = [
    'ENCODINGS', 'ImageEncodingError', 'ImageFormat', 'image_to_array', 'array_to_image',
    'image_to_rgb8', 'compressed_image_to_rgb8',
]


def array_to_image(pixels: np.ndarray, encoding: str, header=None) -> Image:
    """Build an ``Image`` (packed rows, little-endian) from an array matching ``encoding``."""
    fmt = image_format(encoding)
    pixels = np.asarray(pixels)
    expected_ndim = 2 if fmt.channels == 1 else 3
    if pixels.ndim == 3 and fmt.channels == 1 and pixels.shape[2] == 1:
        pixels = pixels[:, :, 0]
    if pixels.ndim != expected_ndim or (fmt.channels > 1 and pixels.shape[2] != fmt.channels):
        raise ImageEncodingError(
            f'array of shape {pixels.shape} does not fit encoding {encoding!r} '
            f'({fmt.channels} channel(s))')
    if pixels.dtype != fmt.dtype:
        raise ImageEncodingError(f'array dtype {pixels.dtype} does not fit encoding {encoding!r} '
                                 f'({fmt.dtype})')
    little = np.ascontiguousarray(pixels, dtype=fmt.dtype.newbyteorder('<'))
    msg = Image()
    if header is not None:
        msg.header = header
    numerator, denominator = fmt.rows_per_height
    msg.height, msg.width = int(pixels.shape[0]) * denominator // numerator, int(pixels.shape[1])
    msg.encoding = encoding
    msg.is_bigendian = 0
    msg.step = msg.width * fmt.channels * fmt.dtype.itemsize
    msg.data = little.tobytes()
    return msg
