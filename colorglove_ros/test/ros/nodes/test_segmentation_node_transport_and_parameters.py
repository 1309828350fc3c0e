"""segmentation_node reads CompressedImage (jpeg, png as OpenCV encodes them) with
``image_transport: compressed``, refuses undecodable data and keeps going; its debug image and
segmenter settings change at run time, checked by the segmenter's own rules; a fresh crop
prediction from ik_node crops the next frames."""
from __future__ import annotations

import cv2
import numpy as np
import pytest
from colorglove_msgs.msg import HandObservation
from geometry_msgs.msg import PolygonStamped
from node_fixtures import NodeAssets, header, running, segmentation_node
from rclpy.parameter import Parameter
from sensor_msgs.msg import CompressedImage, Image

from colorglove_ros.core.segmentation.crop_prediction import CropPrediction
from colorglove_ros.core.segmentation.segmenter import load_segmenter
from colorglove_ros.ros.conversions import crop_from_observation_msg, crop_prediction_to_msg
from colorglove_ros.ros.image import array_to_image

pytestmark = [pytest.mark.dds, pytest.mark.usefixtures('isolated_ros_domain')]


def _compressed(rgb: np.ndarray, fmt: str, sec: int) -> CompressedImage:
    """``rgb`` encoded by OpenCV as image_transport's compressed transport sends it."""
    ok, data = cv2.imencode(f'.{fmt}', cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR))
    assert ok
    return CompressedImage(header=header(sec, 0, 'camera_optical_frame'),
                           format=f'rgb8; {fmt} compressed bgr8', data=data.tobytes())


def test_compressed_jpeg_and_png_are_segmented_and_bad_data_is_refused(
        node_assets: NodeAssets, good_rgb: np.ndarray) -> None:
    """Each compressed frame gives the observation of its decoded pixels (png: the raw frame's
    exactly); undecodable data gives 'bad image', counted, and the next frame is segmented."""
    segmenter = load_segmenter(str(node_assets.color_config))
    raw = segmenter.process(good_rgb)
    with running(segmentation_node(node_assets, image_transport='compressed')) as h:
        out = h.collect(HandObservation, 'hand/observation')
        # image_transport's topic of the compressed transport: '<base topic>/compressed'
        pub = h.publisher(CompressedImage, 'camera/image_raw/compressed')
        png = h.exchange(pub, _compressed(good_rgb, 'png', 10), out)
        jpeg_msg = _compressed(good_rgb, 'jpg', 11)
        jpeg = h.exchange(pub, jpeg_msg, out)
        broken = _compressed(good_rgb, 'jpg', 12)
        broken.data = bytes(64)
        bad = h.exchange(pub, broken, out)
        after = h.exchange(pub, _compressed(good_rgb, 'png', 13), out)
        node = h.nodes[0]
    assert png.hand_found and (png.image_width, png.image_height) == (640, 480)
    assert list(png.tiny_labels) == raw.tiny_labels.reshape(-1).tolist()
    decoded = cv2.cvtColor(cv2.imdecode(np.frombuffer(jpeg_msg.data, np.uint8),
                                        cv2.IMREAD_COLOR), cv2.COLOR_BGR2RGB)
    assert jpeg.hand_found
    assert list(jpeg.tiny_labels) == segmenter.fresh().process(decoded).tiny_labels.reshape(
        -1).tolist()
    assert not bad.hand_found and bad.status.startswith('bad image: compressed image')
    assert bad.header.stamp.sec == 12 and len(bad.tiny_labels) == 0
    assert after.hand_found and after.header.stamp.sec == 13
    assert node.stats.refused == {'bad image': 1} and node.stats.frames == 4


def test_raw_transport_does_not_read_compressed_images(node_assets: NodeAssets,
                                                       good_rgb: np.ndarray) -> None:
    with running(segmentation_node(node_assets)) as h:
        assert h.spin_until(lambda: h.probe.count_publishers('hand/observation') >= 1, 5.0)
        assert h.probe.count_subscribers('camera/image_raw') == 1
        assert h.probe.count_subscribers('camera/image_raw/compressed') == 0


def test_unknown_image_transport_stops_the_start(node_assets: NodeAssets) -> None:
    from colorglove_ros.ros.nodes.common import StartupError

    with pytest.raises(StartupError, match="image_transport 'theora' is not one of raw, "
                                           'compressed'):
        with running(segmentation_node(node_assets, image_transport='theora')):
            pass


def test_debug_image_and_segmenter_settings_change_at_run_time(node_assets: NodeAssets,
                                                              good_rgb: np.ndarray) -> None:
    """publish_debug_image starts and stops the debug image; segmenter.min_glove_pixels is the
    threshold the next frame is segmented with; values the segmenter's rules refuse, and
    read-only parameters, are refused with the reason and change nothing."""
    frame = array_to_image(good_rgb, 'rgb8')
    with running(segmentation_node(node_assets)) as h:
        node = h.nodes[0]
        out = h.collect(HandObservation, 'hand/observation')
        debug = h.collect(Image, 'hand/segmentation_debug')
        pub = h.publisher(Image, 'camera/image_raw')

        def send(sec: int) -> HandObservation:
            frame.header = header(sec)
            msg = h.exchange(pub, frame, out)
            h.settle(0.2)
            return msg

        first = send(1)
        assert first.hand_found and debug == []
        assert node.set_parameters([Parameter('publish_debug_image', value=True)])[0].successful
        assert send(2).hand_found and [m.header.stamp.sec for m in debug] == [2]
        assert node.set_parameters([Parameter('publish_debug_image', value=False)])[0].successful
        send(3)
        assert [m.header.stamp.sec for m in debug] == [2]

        high = first.glove_pixel_count + 1          # the frame's glove is now too small
        assert node.set_parameters([Parameter('segmenter.min_glove_pixels',
                                              value=high)])[0].successful
        assert node.segmenter.min_glove_pixels == high
        too_few = send(4)
        core = load_segmenter(str(node_assets.color_config))
        core.min_glove_pixels = high
        assert not too_few.hand_found and too_few.status == core.process(good_rgb).status

        # refused: out of the rule's range (by the descriptor), even median kernel (by the
        # segmenter's rule), and a batch with one bad value changes none of it
        for name, value, reason in [('segmenter.min_glove_pixels', 0, 'out of range'),
                                    ('segmenter.median_size', 4, 'must be odd'),
                                    ('segmenter.border_distances', [0, 4], '>= 1')]:
            result = node.set_parameters([Parameter(name, value=value)])[0]
            assert not result.successful and reason in result.reason, result.reason
        batch = node.set_parameters_atomically([
            Parameter('segmenter.min_glove_pixels', value=300),
            Parameter('segmenter.median_size', value=4)])
        assert not batch.successful
        assert node.segmenter.min_glove_pixels == high and node.segmenter.median_size == 3
        assert node.get_parameter('segmenter.min_glove_pixels').value == high
        result = node.set_parameters([Parameter('image_transport', value='compressed')])[0]
        assert not result.successful and 'read-only' in result.reason

        assert node.set_parameters([Parameter('segmenter.min_glove_pixels',
                                              value=300)])[0].successful
        assert send(5).hand_found


def test_segmenter_setting_given_at_start_up_is_used(node_assets: NodeAssets) -> None:
    with running(segmentation_node(node_assets, **{'segmenter.median_size': 5,
                                                   'segmenter.border_distances': [3]})) as h:
        node = h.nodes[0]
        assert node.segmenter.median_size == 5 and node.segmenter.border_distances == (3,)
        assert node.get_parameter('segmenter.coarse_factor').value == 4
        assert not node.describe_parameter('segmenter.median_size').read_only


@pytest.mark.parametrize('threads', [None, 3])
def test_opencv_threads_parameter_sets_the_process_threads(node_assets: NodeAssets,
                                                           threads: int | None) -> None:
    """segmentation_node runs OpenCV in the calling thread by default (``OPENCV_THREADS``)
    and with ``opencv_threads`` as many threads as asked; the setting is process-wide."""
    from colorglove_ros.ros.nodes.common import OPENCV_THREADS

    before = cv2.getNumThreads()
    try:
        cv2.setNumThreads(2)
        overrides = {} if threads is None else {'opencv_threads': threads}
        with running(segmentation_node(node_assets, **overrides)) as h:
            assert h.nodes[0].get_parameter('opencv_threads').value == (threads or
                                                                         OPENCV_THREADS)
            assert cv2.getNumThreads() == (threads or OPENCV_THREADS)
    finally:
        cv2.setNumThreads(before)


def test_a_fresh_crop_prediction_crops_the_next_frames(node_assets: NodeAssets,
                                                       good_rgb: np.ndarray) -> None:
    """A crop prediction on hand/crop_prediction crops the frames of its frame_id up to
    prediction_max_age_s newer than it, as the segmenter given it does; older frames are
    segmented as without one."""
    segmenter = load_segmenter(str(node_assets.color_config)).fresh(prediction_margin=1.3)
    crop = segmenter.fresh().process(good_rgb).crop
    # a third of the hand's window at its centre: a crop visibly smaller than the hand's
    prediction = CropPrediction(9.0, crop.center_xy, 0.3 * crop.half_size, (640, 480))
    same = segmenter.fresh()
    expected = [same.process(good_rgb).crop, same.process(good_rgb, prediction=prediction).crop,
                same.process(good_rgb).crop]
    assert expected[1].half_size < 0.9 * expected[0].half_size
    assert expected[2] == expected[0]
    with running(segmentation_node(node_assets, **{'segmenter.prediction_margin': 1.3,
                                                   'prediction_max_age_s': 0.1})) as h:
        out = h.collect(HandObservation, 'hand/observation')
        images = h.publisher(Image, 'camera/image_raw')
        predictions = h.publisher(PolygonStamped, 'hand/crop_prediction')
        got = [h.exchange(images, array_to_image(good_rgb, 'rgb8', header(9, 0)), out)]
        predictions.publish(crop_prediction_to_msg(prediction, header(9, 0)))
        node = h.nodes[0]
        assert h.spin_until(lambda: node.feedback.for_frame(9.05) is not None, 5.0)
        got.append(h.exchange(images, array_to_image(good_rgb, 'rgb8',
                                                     header(9, 50_000_000)), out))
        got.append(h.exchange(images, array_to_image(good_rgb, 'rgb8',
                                                     header(9, 200_000_000)), out))
    for msg, want in zip(got, expected, strict=True):
        assert crop_from_observation_msg(msg) == want


def test_crop_predictions_are_subscribed_only_while_the_segmenter_uses_them(
        node_assets: NodeAssets) -> None:
    """With prediction_margin 0 (the default) the node does not subscribe to
    hand/crop_prediction, so ik_node computes none; raising the margin subscribes, setting it
    back to 0 unsubscribes and forgets the kept prediction."""
    with running(segmentation_node(node_assets)) as h:
        node = h.nodes[0]
        assert node.count_subscribers('hand/crop_prediction') == 0
        assert node.set_parameters([Parameter('segmenter.prediction_margin',
                                              value=1.3)])[0].successful
        assert node.count_subscribers('hand/crop_prediction') == 1
        node.feedback.offer(CropPrediction(9.0, (320.0, 240.0), 50.0, (640, 480)))
        assert node.set_parameters([Parameter('segmenter.prediction_margin',
                                              value=0.0)])[0].successful
        assert node.count_subscribers('hand/crop_prediction') == 0
        assert node.feedback.for_frame(9.01) is None
