"""Serialized sensor_msgs/Image read in place (``image_from_cdr``), checked against rclpy's own
serialization; no ``rclpy.init`` needed."""
from __future__ import annotations

import numpy as np
import pytest
from rclpy.serialization import serialize_message
from sensor_msgs.msg import Image
from std_msgs.msg import Header

from colorglove_ros.ros.image import array_to_image
from colorglove_ros.ros.image_codec import (
    ImageEncodingError,
    header_stamp_from_cdr,
    image_from_cdr,
    image_to_rgb8,
    rgb8_to_encoding,
)

PIXELS = np.random.default_rng(0).integers(0, 256, (6, 10, 3), dtype=np.uint8)


def _header(frame_id: str) -> Header:
    header = Header(frame_id=frame_id)
    header.stamp.sec, header.stamp.nanosec = 1_795_000_123, 456_789
    return header


@pytest.mark.parametrize('frame_id', ['', 'a', 'ab', 'abc', 'camera_optical_frame'])
@pytest.mark.parametrize('encoding', ['rgb8', 'bgr8', '8UC3', 'yuv422_yuy2'])
def test_fields_and_pixels_match_the_message(frame_id: str, encoding: str) -> None:
    msg = array_to_image(rgb8_to_encoding(PIXELS, encoding), encoding, _header(frame_id))
    image = image_from_cdr(serialize_message(msg))
    assert (image.stamp_sec, image.stamp_nanosec, image.frame_id) == \
        (1_795_000_123, 456_789, frame_id)
    assert (image.height, image.width, image.encoding, image.is_bigendian, image.step) == \
        (msg.height, msg.width, encoding, 0, msg.step)
    np.testing.assert_array_equal(image_to_rgb8(image), image_to_rgb8(msg))


def test_padded_rows_are_skipped() -> None:
    msg = Image(header=_header('cam'), height=6, width=10, encoding='rgb8', step=32)
    padded = np.zeros((6, 32), np.uint8)
    padded[:, :30] = PIXELS.reshape(6, 30)
    msg.data = padded.tobytes()
    np.testing.assert_array_equal(image_to_rgb8(image_from_cdr(serialize_message(msg))), PIXELS)


def test_rgb8_is_read_in_place_only_when_asked() -> None:
    data = serialize_message(array_to_image(PIXELS, 'rgb8', _header('cam')))
    image = image_from_cdr(data)
    view = image_to_rgb8(image, read_only=True)
    assert np.shares_memory(view, image.data) and not view.flags.writeable
    copy = image_to_rgb8(image)
    assert not np.shares_memory(copy, image.data) and copy.flags.writeable
    np.testing.assert_array_equal(view, copy)


@pytest.mark.parametrize('cut', [3, 10, 30, -1])
def test_truncated_or_foreign_bytes_are_refused(cut: int) -> None:
    data = serialize_message(array_to_image(PIXELS, 'rgb8', _header('camera_optical_frame')))
    with pytest.raises(ImageEncodingError):
        image_from_cdr(data[:cut])
    with pytest.raises(ImageEncodingError):
        image_from_cdr(b'\x07\x07' + data[2:])


def test_header_stamp_of_any_stamped_message() -> None:
    """The stamp read in place equals the message's, for an image and another stamped type."""
    from sensor_msgs.msg import JointState

    image = array_to_image(PIXELS, 'rgb8')
    image.header = _header('camera')
    joints = JointState(header=_header(''), name=['a'], position=[1.0])
    for message in (image, joints):
        assert header_stamp_from_cdr(serialize_message(message)) == (1_795_000_123, 456_789)
    with pytest.raises(ImageEncodingError):
        header_stamp_from_cdr(b'\x00\x01\x00')
