"""numpy <-> sensor_msgs/Image conversion: encodings, row padding, byte order, errors."""
from __future__ import annotations

import numpy as np
import pytest
from sensor_msgs.msg import Image

from colorglove_ros.ros.image import (
    ENCODINGS,
    ImageEncodingError,
    array_to_image,
    image_to_array,
    image_to_rgb8,
)

RNG = np.random.default_rng(7)


def _random_pixels(encoding: str, height: int = 5, width: int = 7) -> np.ndarray:
    fmt = ENCODINGS[encoding]
    shape = (height, width) if fmt.channels == 1 else (height, width, fmt.channels)
    if fmt.dtype.kind == 'f':
        return RNG.standard_normal(shape).astype(fmt.dtype)
    return RNG.integers(0, np.iinfo(fmt.dtype).max, size=shape, endpoint=True).astype(fmt.dtype)


@pytest.mark.parametrize('encoding', ['rgb8', 'bgr8', 'mono8', 'rgba8', 'bgra8', 'mono16', '32FC1'])
def test_round_trip(encoding: str) -> None:
    pixels = _random_pixels(encoding)
    msg = array_to_image(pixels, encoding)
    assert msg.step == pixels.shape[1] * pixels.itemsize * ENCODINGS[encoding].channels
    np.testing.assert_array_equal(image_to_array(msg), pixels)


def _hand_built(pixels: np.ndarray, encoding: str, pad: int, big_endian: bool) -> Image:
    """An Image message built by hand, with ``pad`` junk bytes after every row."""
    order = '>' if big_endian else '<'
    raw = np.ascontiguousarray(pixels, dtype=pixels.dtype.newbyteorder(order))
    rows = raw.reshape(pixels.shape[0], -1).view(np.uint8)
    junk = np.full((pixels.shape[0], pad), 0xAB, dtype=np.uint8)
    msg = Image()
    msg.height, msg.width = pixels.shape[:2]
    msg.encoding = encoding
    msg.is_bigendian = int(big_endian)
    msg.step = rows.shape[1] + pad
    msg.data = np.hstack([rows, junk]).tobytes()
    return msg


@pytest.mark.parametrize('encoding', ['rgb8', 'mono8', 'bgra8', 'mono16', '32FC1'])
@pytest.mark.parametrize('pad', [0, 3, 16])
@pytest.mark.parametrize('big_endian', [False, True])
def test_padded_rows_and_byte_order(encoding: str, pad: int, big_endian: bool) -> None:
    pixels = _random_pixels(encoding)
    msg = _hand_built(pixels, encoding, pad, big_endian)
    out = image_to_array(msg)
    assert out.dtype.isnative
    np.testing.assert_array_equal(out, pixels)


def test_mono16_big_endian_values() -> None:
    msg = Image(height=1, width=2, encoding='mono16', is_bigendian=1, step=4,
                data=bytes([0x01, 0x02, 0xFF, 0x00]))
    np.testing.assert_array_equal(image_to_array(msg), [[0x0102, 0xFF00]])


@pytest.mark.parametrize('encoding, channel_order', [
    ('rgb8', [0, 1, 2]), ('bgr8', [2, 1, 0]), ('rgba8', [0, 1, 2]), ('bgra8', [2, 1, 0])])
def test_rgb8_view_reorders_channels(encoding: str, channel_order: list[int]) -> None:
    pixels = _random_pixels(encoding)
    rgb = image_to_rgb8(_hand_built(pixels, encoding, pad=5, big_endian=False))
    np.testing.assert_array_equal(rgb, pixels[:, :, channel_order])
    assert rgb.flags['C_CONTIGUOUS'] and rgb.shape[2] == 3


def test_unsupported_encoding_names_it() -> None:
    msg = Image(height=2, width=2, encoding='yuv420p10', step=4, data=bytes(8))
    with pytest.raises(ImageEncodingError, match='yuv420p10'):
        image_to_array(msg)


def test_mono_image_is_refused_for_colour_segmentation() -> None:
    msg = array_to_image(np.zeros((4, 4), np.uint8), 'mono8')
    with pytest.raises(ImageEncodingError, match='colour image.*mono8'):
        image_to_rgb8(msg)


@pytest.mark.parametrize('height, width, step, nbytes, message', [
    (0, 0, 0, 0, 'empty'),
    (4, 4, 12, 20, 'holds 20 bytes'),
    (4, 4, 8, 48, 'step 8 is smaller'),
])
def test_inconsistent_messages_raise(height: int, width: int, step: int, nbytes: int,
                                     message: str) -> None:
    msg = Image(height=height, width=width, encoding='rgb8', step=step, data=bytes(nbytes))
    with pytest.raises(ImageEncodingError, match=message):
        image_to_array(msg)


def test_array_shape_must_fit_encoding() -> None:
    with pytest.raises(ImageEncodingError, match='does not fit'):
        array_to_image(np.zeros((4, 4), np.uint8), 'rgb8')
    with pytest.raises(ImageEncodingError, match='dtype'):
        array_to_image(np.zeros((4, 4, 3), np.float64), 'rgb8')
