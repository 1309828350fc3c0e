"""segmentation_node publishes a frame's observation before its segmenter learns the static
background from that frame (the learning is needed only by the next frame), and a failed
learning is logged and counted as a fault while the node keeps answering frames (issue 19)."""
from __future__ import annotations

import numpy as np
import pytest
from node_fixtures import NodeAssets, header, running, segmentation_node

from colorglove_ros.core.segmentation.segmenter import load_segmenter
from colorglove_ros.ros.image import array_to_image

pytestmark = [pytest.mark.dds, pytest.mark.usefixtures('isolated_ros_domain')]


def _recording(node, events: list, published: list) -> None:
    """Record the node's observations as it publishes them and its segmenter's learning, in
    order (``events``: 'published' / 'learnt')."""
    publish = node.publisher.publish
    learn = node.segmenter._learn

    def publishing(msg) -> None:
        events.append('published')
        published.append(msg)
        publish(msg)

    def learning(*args) -> None:
        events.append('learnt')
        learn(*args)

    node.publisher.publish = publishing
    node.segmenter._learn = learning


def test_the_observation_is_published_before_the_background_learns(
        node_assets: NodeAssets, good_rgb: np.ndarray) -> None:
    """Every frame: published, then learnt; the observations are those of a segmenter that
    learns inline (before returning), frame after frame."""
    inline = load_segmenter(str(node_assets.color_config))
    events: list[str] = []
    published: list = []
    with running(segmentation_node(node_assets)) as h:
        _recording(h.nodes[0], events, published)
        for k in range(3):
            h.nodes[0].on_image(array_to_image(good_rgb, 'rgb8', header(20 + k)))
    assert events == ['published', 'learnt'] * 3
    for msg in published:
        expected = inline.process(good_rgb)
        assert msg.hand_found and expected.hand_found
        assert list(msg.tiny_labels) == expected.tiny_labels.reshape(-1).tolist()
        assert msg.glove_pixel_count == expected.glove_pixel_count


def test_a_failed_learning_is_logged_and_the_next_frame_answered(
        node_assets: NodeAssets, good_rgb: np.ndarray, monkeypatch) -> None:
    with running(segmentation_node(node_assets)) as h:
        node = h.nodes[0]
        published: list = []
        _recording(node, [], published)
        errors: list[str] = []
        monkeypatch.setattr(node.get_logger(), 'error',
                            lambda text, **_: errors.append(text))

        def fail(*args) -> None:
            raise RuntimeError('learning failed')

        learn, node.segmenter._learn = node.segmenter._learn, fail
        node.on_image(array_to_image(good_rgb, 'rgb8', header(30)))
        node.segmenter._learn = learn
        node.on_image(array_to_image(good_rgb, 'rgb8', header(31)))
    assert [m.header.stamp.sec for m in published] == [30, 31]
    assert all(m.hand_found for m in published)
    assert len(errors) == 1 and 'background learning failed' in errors[0]
    # in the diagnostics too: a fault beside the outputs, the two frames answered
    assert node.stats.faults == {'background learning': 1} and node.stats.frames == 2
    assert node.stats.refused == {}
