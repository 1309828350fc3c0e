"""A bag recorded "from a camera driver" through the node processes: 1280x720 images in
``yuv422_yuy2`` (usb_cam's yuyv mode), the driver's own frame_id and CameraInfo as the only
intrinsics (the nodes keep the package's calibration_file, whose camera 0 is 640x480: tracking a
1280x720 frame at all means the intrinsics came from CameraInfo). The same synthetic scene
seen by the package's own 640x480 camera is the baseline: the wrist depth error against
ground truth is as small at 1280x720 as at 640x480."""
from __future__ import annotations

from pathlib import Path

import pytest
from node_fixtures import SMALL_DATABASE_GATES, NodeAssets, assert_run_tracked, paced_bag_feed

from colorglove_ros.core.camera import PinholeCamera
from colorglove_ros.core.hand.glove import default_hand
from colorglove_ros.core.synthetic.frames import default_camera
from colorglove_ros.core.synthetic.sequences import SyntheticSequenceRenderer
from colorglove_ros.ros.bags import SequenceBagWriter
from colorglove_ros.ros.pipeline_run import PipelineRun, run_pipeline, summarize

pytestmark = [pytest.mark.dds, pytest.mark.slow, pytest.mark.usefixtures('isolated_ros_domain')]

FRAMES = 20
SEED = 6                     # a held-out sequence seed
VGA = default_camera()       # the package's camera: 640x480, f = 600
# a 720p driver at the same place, 1.5 times the pixel density: the 640x480 view is its
# centre 960x720 pixels (same optical centre and vertical field of view, wider sideways)
DRIVER_FRAME_ID = 'default_cam'          # usb_cam's default frame_id
DRIVER_SCALE = 1.5
DRIVER = PinholeCamera(1280, 720, DRIVER_SCALE * VGA.fx, DRIVER_SCALE * VGA.fy,
                       DRIVER_SCALE * (VGA.cx + 0.5) - 0.5 + 160,
                       DRIVER_SCALE * (VGA.cy + 0.5) - 0.5, name='usb_cam',
                       frame_id=DRIVER_FRAME_ID)


@pytest.fixture(scope='module')
def bags(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """The same sequence as the driver's bag (1280x720, yuv422_yuy2, CameraInfo) and as the
    package camera's (640x480, rgb8); the motion keeps the hand inside the package camera's
    view, which the driver's contains."""
    folder = tmp_path_factory.mktemp('driver')
    paths = {'driver': folder / 'driver', 'vga': folder / 'vga'}
    sequence = SyntheticSequenceRenderer(VGA, seed=SEED, num_frames=FRAMES)
    try:
        with SequenceBagWriter(paths['driver'], DRIVER, frame_id=DRIVER_FRAME_ID,
                               encoding='yuv422_yuy2') as driver, \
                SequenceBagWriter(paths['vga'], VGA) as vga:
            for i in range(FRAMES):
                vga_view, driver_view = sequence.render_views(i, (VGA, DRIVER))
                driver.write(driver_view)
                vga.write(vga_view)
    finally:
        sequence.close()
    return paths


def _run(assets: NodeAssets, bag: Path) -> PipelineRun:
    """segmentation -> lookup -> IK as separate processes, intrinsics from camera_info (the
    nodes' default use_camera_info), fed by ``bag``."""
    parameters = {
        'segmentation': {'color_calibration_file': str(assets.color_config)},
        'lookup': {'database_path': str(assets.database)},
        'ik': {'publish_overlay': False, 'database_path': str(assets.database),
               **SMALL_DATABASE_GATES},
    }
    return run_pipeline(parameters, FRAMES, feed=paced_bag_feed(bag), timeout_s=300.0)


def test_driver_bag_is_tracked_as_well_as_the_package_camera(node_assets: NodeAssets,
                                                             bags: dict[str, Path]) -> None:
    model = default_hand()[0]
    vga, driver = _run(node_assets, bags['vga']), _run(node_assets, bags['driver'])
    at_vga, at_driver = summarize(vga, model), summarize(driver, model)
    print({'640x480 rgb8': at_vga, '1280x720 yuv422_yuy2': at_driver})
    for run, figures in ((vga, at_vga), (driver, at_driver)):
        assert_run_tracked(run, figures, FRAMES)
    # no frame refused for its size or frame_id; only the first may beat its CameraInfo
    refused = [line for line in driver.statuses if line.startswith('no hand: camera:')]
    assert refused in ([], ['no hand: camera: waiting for CameraInfo']), refused
    depth_vga, depth_driver = at_vga['wrist_depth_mm'], at_driver['wrist_depth_mm']
    assert depth_driver <= max(1.5 * depth_vga, depth_vga + 5.0), (depth_vga, depth_driver)
