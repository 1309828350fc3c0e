"""Camera-driver encodings (YUV 4:2:2 both byte orders, NV21, Bayer in four patterns at 8 and
16 bit, 8UC4, mono) and CompressedImage, decoded by ros/image_codec.py and checked against
images encoded by OpenCV's own converters or built by hand, with ``step`` padding."""
from __future__ import annotations

from types import SimpleNamespace

import cv2
import numpy as np
import pytest

from colorglove_ros.ros.image_codec import (
    ImageEncodingError,
    compressed_image_to_rgb8,
    image_to_array,
    image_to_rgb8,
)

H, W = 48, 64


def smooth_rgb(seed: int = 0) -> np.ndarray:
    """A smooth colour image (gradients), where chroma subsampling and demosaicing lose little."""
    rng = np.random.default_rng(seed)
    y, x = np.mgrid[0:H, 0:W].astype(np.float32)
    channels = [60 + 120 * (x / W), 200 - 150 * (y / H), 40 + 80 * ((x + y) / (W + H))]
    rgb = np.stack(channels, axis=-1) + rng.normal(0, 1.0, (H, W, 3))
    return np.clip(rgb, 0, 255).astype(np.uint8)


def message(encoding: str, rows: np.ndarray, height: int, pad: int = 0,
            bigendian: bool = False) -> SimpleNamespace:
    """An Image-like message holding ``rows`` (stored rows x bytes) with ``pad`` bytes per row."""
    flat = rows.reshape(rows.shape[0], -1)
    raw = flat.view(np.uint8).reshape(rows.shape[0], -1)
    padded = np.zeros((raw.shape[0], raw.shape[1] + pad), np.uint8)
    padded[:, :raw.shape[1]] = raw
    return SimpleNamespace(encoding=encoding, height=height, width=W, step=padded.shape[1],
                           is_bigendian=int(bigendian), data=padded.tobytes())


@pytest.mark.parametrize('pad', [0, 6])
@pytest.mark.parametrize(('encoding', 'opencv_encoder'), [
    ('yuv422', cv2.COLOR_RGB2YUV_UYVY), ('uyvy', cv2.COLOR_RGB2YUV_UYVY),
    ('yuv422_yuy2', cv2.COLOR_RGB2YUV_YUYV), ('yuyv', cv2.COLOR_RGB2YUV_YUYV)])
def test_yuv422_both_byte_orders(encoding: str, opencv_encoder: int, pad: int) -> None:
    rgb = smooth_rgb()
    packed = cv2.cvtColor(rgb, opencv_encoder)              # (H, W, 2) as the camera sends it
    decoded = image_to_rgb8(message(encoding, packed, H, pad))
    assert decoded.shape == (H, W, 3) and decoded.dtype == np.uint8
    assert np.abs(decoded.astype(int) - rgb).mean() < 3.0
    # the other byte order reads the same bytes as a different (wrong) image
    other = {'yuv422': 'yuv422_yuy2', 'uyvy': 'yuyv', 'yuv422_yuy2': 'yuv422',
             'yuyv': 'uyvy'}[encoding]
    swapped = image_to_rgb8(message(other, packed, H, pad))
    assert np.abs(swapped.astype(int) - rgb).mean() > 20.0


def test_nv21_from_opencv_i420_with_chroma_interleaved_vu() -> None:
    rgb = smooth_rgb(1)
    i420 = cv2.cvtColor(rgb, cv2.COLOR_RGB2YUV_I420)        # Y, then U plane, then V plane
    y_plane, chroma = i420[:H], i420[H:].reshape(-1)
    u, v = chroma[:H * W // 4], chroma[H * W // 4:]
    vu = np.stack([v, u], axis=-1).reshape(H // 2, W)        # NV21: V first
    nv21 = np.vstack([y_plane, vu])
    decoded = image_to_rgb8(message('nv21', nv21, H, pad=4))
    assert decoded.shape == (H, W, 3)
    assert np.abs(decoded.astype(int) - rgb).mean() < 3.0


def mosaic(rgb: np.ndarray, pattern: str) -> np.ndarray:
    """A Bayer mosaic of ``rgb``; ``pattern`` names the 2x2 tile from the first row (ROS)."""
    index = {'r': 0, 'g': 1, 'b': 2}
    out = np.zeros(rgb.shape[:2], rgb.dtype)
    for k, colour in enumerate(pattern):
        dy, dx = divmod(k, 2)
        out[dy::2, dx::2] = rgb[dy::2, dx::2, index[colour]]
    return out


@pytest.mark.parametrize('bits', [8, 16])
@pytest.mark.parametrize('pattern', ['rggb', 'bggr', 'gbrg', 'grbg'])
def test_bayer_all_patterns(pattern: str, bits: int) -> None:
    rgb = smooth_rgb(2)
    source = rgb.astype(np.uint16) * 257 if bits == 16 else rgb
    decoded = image_to_rgb8(message(f'bayer_{pattern}{bits}', mosaic(source, pattern), H, pad=2))
    inner = (slice(2, -2), slice(2, -2))                     # demosaicing borders differ
    assert np.abs(decoded[inner].astype(int) - rgb[inner]).mean() < 4.0


def test_bayer16_big_endian_is_swapped() -> None:
    rgb = smooth_rgb(3)
    big = mosaic(rgb.astype(np.uint16) * 257, 'rggb').astype('>u2')
    decoded = image_to_rgb8(message('bayer_rggb16', big, H, bigendian=True))
    assert np.abs(decoded[2:-2, 2:-2].astype(int) - rgb[2:-2, 2:-2]).mean() < 4.0


def test_8uc4_is_bgra_and_mono_needs_allow_mono() -> None:
    rgb = smooth_rgb(4)
    bgra = cv2.cvtColor(rgb, cv2.COLOR_RGB2BGRA)
    np.testing.assert_array_equal(image_to_rgb8(message('8UC4', bgra, H, pad=3)), rgb)
    grey = cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY)
    with pytest.raises(ImageEncodingError, match='needs a colour image'):
        image_to_rgb8(message('mono8', grey, H))
    as_rgb = image_to_rgb8(message('mono16', grey.astype(np.uint16) * 257, H), allow_mono=True)
    np.testing.assert_array_equal(as_rgb, np.repeat(grey[..., None], 3, axis=2))


def test_yuv_odd_width_and_truncated_data_are_refused() -> None:
    packed = cv2.cvtColor(smooth_rgb(), cv2.COLOR_RGB2YUV_YUYV)
    msg = message('yuyv', packed, H)
    msg.width = W - 1
    with pytest.raises(ImageEncodingError, match='even image size'):
        image_to_array(msg)
    short = message('yuyv', packed, H)
    short.data = short.data[:-10]
    with pytest.raises(ImageEncodingError, match='needs'):
        image_to_rgb8(short)


@pytest.mark.parametrize(('fmt', 'ext'), [('jpeg', '.jpg'), ('png', '.png'),
                                          ('rgb8; jpeg compressed bgr8', '.jpg')])
def test_compressed_image_jpeg_and_png(fmt: str, ext: str) -> None:
    rgb = smooth_rgb(5)
    ok, data = cv2.imencode(ext, cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR),
                            [cv2.IMWRITE_JPEG_QUALITY, 95] if ext == '.jpg' else [])
    assert ok
    decoded = compressed_image_to_rgb8(SimpleNamespace(format=fmt, data=data.tobytes()))
    tolerance = 0.0 if ext == '.png' else 3.0
    assert np.abs(decoded.astype(int) - rgb).mean() <= tolerance


@pytest.mark.parametrize(('fmt', 'data', 'message_part'), [
    ('tiff', b'\x00' * 10, 'unsupported compressed image format'),
    ('jpeg', b'', 'empty compressed image'),
    ('jpeg', b'not a jpeg at all', 'does not decode'),
])
def test_compressed_image_refusals(fmt: str, data: bytes, message_part: str) -> None:
    with pytest.raises(ImageEncodingError, match=message_part):
        compressed_image_to_rgb8(SimpleNamespace(format=fmt, data=data))
