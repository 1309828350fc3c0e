"""Convert numpy arrays to and from ``sensor_msgs/Image``, honouring encoding, step, byte order."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from sensor_msgs.msg import Image

__all__ = [
    'ENCODINGS', 'ImageEncodingError', 'ImageFormat', 'image_to_array', 'array_to_image',
    'image_to_rgb8',
]


class ImageEncodingError(ValueError):
    """An image cannot be converted: unsupported encoding, or inconsistent size/step/data."""


@dataclass(frozen=True)
class ImageFormat:
    """Pixel layout of one ``sensor_msgs/Image`` encoding."""

    dtype: np.dtype
    channels: int


ENCODINGS: dict[str, ImageFormat] = {
    'rgb8': ImageFormat(np.dtype(np.uint8), 3),
    'bgr8': ImageFormat(np.dtype(np.uint8), 3),
    'rgba8': ImageFormat(np.dtype(np.uint8), 4),
    'bgra8': ImageFormat(np.dtype(np.uint8), 4),
    'mono8': ImageFormat(np.dtype(np.uint8), 1),
    'mono16': ImageFormat(np.dtype(np.uint16), 1),
    'rgb16': ImageFormat(np.dtype(np.uint16), 3),
    'bgr16': ImageFormat(np.dtype(np.uint16), 3),
    '8UC1': ImageFormat(np.dtype(np.uint8), 1),
    '8UC3': ImageFormat(np.dtype(np.uint8), 3),
    '16UC1': ImageFormat(np.dtype(np.uint16), 1),
    '32FC1': ImageFormat(np.dtype(np.float32), 1),
}

# How to reach RGB order from each colour encoding (channel indices).
_RGB_CHANNELS = {'rgb8': (0, 1, 2), 'bgr8': (2, 1, 0), 'rgba8': (0, 1, 2), 'bgra8': (2, 1, 0),
                 '8UC3': (2, 1, 0)}


def _format_of(encoding: str) -> ImageFormat:
    try:
        return ENCODINGS[encoding]
    except KeyError:
        raise ImageEncodingError(
            f'unsupported image encoding {encoding!r}; supported: {", ".join(ENCODINGS)}'
        ) from None


def image_to_array(msg: Image) -> np.ndarray:
    """Return the pixels of ``msg`` as (H, W) or (H, W, C) in native byte order.

    Row padding (``step`` larger than the packed row) is skipped; big-endian data is
    byte-swapped. The result is a copy only where byte order or padding demand one.
    """
    fmt = _format_of(msg.encoding)
    height, width, step = int(msg.height), int(msg.width), int(msg.step)
    if height == 0 or width == 0:
        raise ImageEncodingError(f'empty image ({width}x{height})')
    row_bytes = width * fmt.channels * fmt.dtype.itemsize
    if step < row_bytes:
        raise ImageEncodingError(
            f'step {step} is smaller than a {msg.encoding} row of {width} pixels '
            f'({row_bytes} bytes)')
    data = np.frombuffer(msg.data, dtype=np.uint8) if not isinstance(msg.data, np.ndarray) \
        else msg.data.view(np.uint8)
    if data.size < step * (height - 1) + row_bytes:
        raise ImageEncodingError(
            f'image data holds {data.size} bytes, {width}x{height} {msg.encoding} with step {step} '
            f'needs {step * (height - 1) + row_bytes}')
    rows = np.lib.stride_tricks.as_strided(
        data, shape=(height, row_bytes), strides=(step, 1), writeable=False)
    dtype = fmt.dtype.newbyteorder('>' if msg.is_bigendian else '<')
    pixels = np.ascontiguousarray(rows).view(dtype) if step != row_bytes else \
        data[:height * row_bytes].view(dtype).reshape(height, -1)
    pixels = pixels.reshape(height, width, fmt.channels)
    if not dtype.isnative:
        pixels = pixels.astype(fmt.dtype)
    return pixels[:, :, 0] if fmt.channels == 1 else pixels


def array_to_image(pixels: np.ndarray, encoding: str, header=None) -> Image:
    """Build an ``Image`` (packed rows, little-endian) from an array matching ``encoding``."""
    fmt = _format_of(encoding)
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
    msg.height, msg.width = int(pixels.shape[0]), int(pixels.shape[1])
    msg.encoding = encoding
    msg.is_bigendian = 0
    msg.step = msg.width * fmt.channels * fmt.dtype.itemsize
    msg.data = little.tobytes()
    return msg


def image_to_rgb8(msg: Image) -> np.ndarray:
    """Return a colour image as contiguous (H, W, 3) uint8 RGB; colour encodings only."""
    if msg.encoding not in _RGB_CHANNELS:
        raise ImageEncodingError(
            f'glove segmentation needs a colour image; got encoding {msg.encoding!r} '
            f'(use one of {", ".join(_RGB_CHANNELS)})')
    pixels = image_to_array(msg)
    return np.ascontiguousarray(pixels[:, :, list(_RGB_CHANNELS[msg.encoding])])
