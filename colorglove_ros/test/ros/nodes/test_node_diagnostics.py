"""Each pipeline node publishes a DiagnosticArray on /diagnostics about once a second, as
diagnostic_updater does: '<node>: <what>', rate, latency, frames refused per kind, hand lost =
WARN, every frame refused = ERROR, the IK's constraint counts."""
from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from node_fixtures import (
    NodeAssets,
    header,
    ik_node,
    lookup_node,
    params,
    running,
    segmentation_node,
)
from sensor_msgs.msg import Image
from std_msgs.msg import String

from colorglove_ros.ros.image import array_to_image
from colorglove_ros.ros.nodes.camera_node import CameraNode

pytestmark = [pytest.mark.dds, pytest.mark.usefixtures('isolated_ros_domain')]

NAMES = ('segmentation: segmentation', 'lookup: lookup', 'ik: tracking')


def _latest(reports: list[DiagnosticArray], name: str, start: int = 0) -> DiagnosticStatus | None:
    """The newest status called ``name`` among ``reports[start:]``."""
    statuses = [s for report in reports[start:] for s in report.status if s.name == name]
    return statuses[-1] if statuses else None


def _report_after(h, reports: list, name: str, start: int) -> DiagnosticStatus:
    assert h.spin_until(lambda: _latest(reports, name, start) is not None, 3.0), name
    return _latest(reports, name, start)


def test_pipeline_nodes_report_rate_latency_refusals_and_constraints(
        node_assets: NodeAssets, small_database_path: Path, good_rgb: np.ndarray) -> None:
    with running(segmentation_node(node_assets), lookup_node(node_assets),
                 ik_node(small_database_path, publish_overlay=False)) as h:
        reports = h.collect(DiagnosticArray, '/diagnostics')
        status = h.collect(String, 'hand/tracking_status')
        pub = h.publisher(Image, 'camera/image_raw')
        assert h.spin_until(lambda: h.probe.count_subscribers('hand/pose_candidates') >= 1, 10.0)
        frame = array_to_image(good_rgb, 'rgb8', header(1))
        frame.header.stamp = h.probe.get_clock().now().to_msg()    # latency: now - stamp
        line = h.exchange(pub, frame, status)
        assert line.data.startswith('tracking:'), line.data
        start = len(reports)
        good = {name: _report_after(h, reports, name, start) for name in NAMES}
        bad_image = Image(header=header(2), encoding='rgb8', width=0, height=0, step=0)
        line = h.exchange(pub, bad_image, status)
        start = len(reports)
        bad = {name: _report_after(h, reports, name, start) for name in NAMES}
    for name, report in good.items():
        values = {kv.key: kv.value for kv in report.values}
        assert report.level == DiagnosticStatus.OK, (name, report.message)
        assert values['frames'] == '1' and values['frames with hand'] == '1', name
        assert 0.0 < float(values['latency max (ms)']) < 30_000.0, name
        assert report.hardware_id == 'camera_optical_frame'
    ik_values = {kv.key: kv.value for kv in good['ik: tracking'].values}
    assert int(ik_values['constraints']) > 0
    assert int(ik_values['constraints']) == int(ik_values['constraints camera'])
    # a frame that cannot be decoded: the segmentation refused it (ERROR: every frame of the
    # period), the stages after it lost the hand (WARN); the refusal counted by its kind
    segmentation = bad['segmentation: segmentation']
    assert segmentation.level == DiagnosticStatus.ERROR
    assert segmentation.message.startswith('frames refused: bad image: image_width')
    assert {kv.key: kv.value for kv in segmentation.values}['refused: bad image'] == '1'
    for name in ('lookup: lookup', 'ik: tracking'):
        assert bad[name].level == DiagnosticStatus.WARN, name
        assert bad[name].message.startswith('hand lost: upstream: bad image'), bad[name].message
        assert {kv.key: kv.value for kv in bad[name].values}['refused: upstream'] == '1'


def test_camera_node_reports_frames_it_refuses(tmp_path: Path) -> None:
    cv2.imwrite(str(tmp_path / 'small.png'), np.zeros((240, 320, 3), np.uint8))
    with running(lambda ctx: CameraNode(context=ctx, parameter_overrides=params(
            source=str(tmp_path), rate_hz=20.0, loop=True))) as h:
        reports = h.collect(DiagnosticArray, '/diagnostics')
        report = _report_after(h, reports, 'camera: frames', 0)
    assert report.level == DiagnosticStatus.ERROR
    assert report.message.startswith('frames refused: size: frame of 320x240')
    values = {kv.key: kv.value for kv in report.values}
    assert int(values['refused: size']) >= 5 and values['frames with image'] == '0'
