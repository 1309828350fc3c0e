"""Round trips of synthetic sequences through MCAP rosbag2 files."""
from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from repo_paths import CONFIG_DIR
from rosbags.highlevel import AnyReader

from colorglove_ros.core.camera import CalibrationError, PinholeCamera, load_calibration
from colorglove_ros.core.hand.model import FINGER_DOF_NAMES
from colorglove_ros.core.synthetic.sequences import SyntheticSequenceRenderer
from colorglove_ros.ros.bags import (
    FRAME_ID,
    TOPIC_CAMERA_INFO,
    TOPIC_IMAGE,
    TOPIC_JOINTS,
    TOPIC_KEYPOINTS,
    TOPIC_TF,
    TOPIC_TF_STATIC,
    TOPIC_WRIST,
    BagError,
    SequenceBagWriter,
    bag_camera,
    camera_info_to_pinhole,
    read_sequence_bag,
    read_transforms,
    write_sequence_bag,
)
from colorglove_ros.ros.image_codec import ImageEncodingError, image_to_rgb8
from colorglove_ros.tools import make_bag

CAM = PinholeCamera(160, 120, 150.0, 150.0, 79.5, 59.5)


def _header(topic: str, msg):
    """The header of a bag message (a marker array's and a TF message's first element's)."""
    if topic == TOPIC_KEYPOINTS:
        return msg.markers[0].header
    if topic in (TOPIC_TF, TOPIC_TF_STATIC):
        return msg.transforms[0].header
    return msg.header


@pytest.fixture(scope='module')
def frames():
    seq = SyntheticSequenceRenderer(CAM, seed=9, num_frames=5, split='test')
    out = [seq.render(i) for i in range(5)]
    seq.close()
    return out


def test_round_trip(tmp_path: Path, frames) -> None:
    path = tmp_path / 'seq'
    assert write_sequence_bag(path, frames, CAM, fps=25.0) == 5
    back = list(read_sequence_bag(path))
    assert len(back) == 5
    stamps = [b.stamp_ns for b in back]
    assert np.all(np.diff(stamps) > 0)
    np.testing.assert_allclose(np.diff(stamps), 4e7, atol=1)     # 25 fps
    for f, b in zip(frames, back, strict=True):
        np.testing.assert_array_equal(b.image_rgb, f.image_rgb)
        np.testing.assert_array_equal(b.joint_positions, f.pose[6:])
        assert b.joint_names == list(FINGER_DOF_NAMES)
        np.testing.assert_allclose(b.pose, f.pose, atol=1e-12)
        np.testing.assert_array_equal(b.keypoints_3d, f.keypoints_3d)
        assert (b.camera.fx, b.camera.cx, b.camera.width) == (150.0, 79.5, 160)
        assert b.camera.frame_id == FRAME_ID
    assert bag_camera(path).height == 120
    # every topic: 5 messages, identical stamps, the optical frame, log time = stamp
    with AnyReader([path]) as reader:
        topics = {c.topic: c.msgtype for c in reader.connections}
        assert topics == {TOPIC_IMAGE: 'sensor_msgs/msg/Image',
                          TOPIC_CAMERA_INFO: 'sensor_msgs/msg/CameraInfo',
                          TOPIC_JOINTS: 'sensor_msgs/msg/JointState',
                          TOPIC_WRIST: 'geometry_msgs/msg/PoseStamped',
                          TOPIC_KEYPOINTS: 'visualization_msgs/msg/MarkerArray',
                          TOPIC_TF: 'tf2_msgs/msg/TFMessage'}
        per_topic: dict[str, list[int]] = {}
        for conn, log_ns, raw in reader.messages():
            msg = reader.deserialize(raw, conn.msgtype)
            header = _header(conn.topic, msg)
            stamp = header.stamp.sec * 10**9 + header.stamp.nanosec
            assert stamp == log_ns and header.frame_id == FRAME_ID
            per_topic.setdefault(conn.topic, []).append(stamp)
            if conn.topic == TOPIC_IMAGE:
                assert (msg.encoding, msg.step) == ('rgb8', 480)
    assert all(v == stamps for v in per_topic.values()) and len(per_topic) == 6
    # without images the ground truth still comes back
    light = list(read_sequence_bag(path, with_images=False))
    assert light[2].image_rgb is None
    np.testing.assert_allclose(light[2].pose, frames[2].pose, atol=1e-12)


def test_writer_rejects_bad_input(tmp_path: Path, frames) -> None:
    path = tmp_path / 'bad'
    with SequenceBagWriter(path, CAM) as writer:
        with pytest.raises(BagError):
            writer.write(SimpleNamespace(image_rgb=np.zeros((10, 10, 3), np.uint8),
                                         pose=frames[0].pose,
                                         keypoints_3d=frames[0].keypoints_3d))
        writer.write(frames[0])
    with pytest.raises(BagError):
        SequenceBagWriter(path, CAM)          # exists already
    with pytest.raises(BagError):
        list(read_sequence_bag(tmp_path / 'missing'))


def _msg(encoding: str, pixels: np.ndarray, pad: int = 0, bigendian: bool = False):
    h, w = pixels.shape[:2]
    raw = pixels.astype(pixels.dtype.newbyteorder('>' if bigendian else '<'))
    rows = raw.reshape(h, -1).view(np.uint8).reshape(h, -1)
    rows = np.concatenate([rows, np.full((h, pad), 77, np.uint8)], axis=1)
    return SimpleNamespace(encoding=encoding, height=h, width=w, step=rows.shape[1],
                           is_bigendian=int(bigendian), data=rows.reshape(-1))


@pytest.mark.parametrize('encoding,order,pad', [
    ('rgb8', (0, 1, 2), 0), ('rgb8', (0, 1, 2), 5), ('bgr8', (2, 1, 0), 3),
    ('rgba8', (0, 1, 2, 3), 4), ('bgra8', (2, 1, 0, 3), 0)])
def test_image_conversion_honours_encoding_and_step(encoding: str, order: tuple,
                                                     pad: int) -> None:
    rng = np.random.default_rng(0)
    rgb = rng.integers(0, 256, (7, 9, 3), dtype=np.uint8)
    channels = np.concatenate([rgb, np.full((7, 9, 1), 200, np.uint8)], axis=2)
    stored = np.ascontiguousarray(channels[..., list(order)])
    np.testing.assert_array_equal(image_to_rgb8(_msg(encoding, stored, pad)), rgb)


@pytest.mark.parametrize('bigendian', [False, True])
def test_image_conversion_16bit_and_mono(bigendian: bool) -> None:
    rng = np.random.default_rng(1)
    rgb16 = rng.integers(0, 65536, (4, 5, 3), dtype=np.uint16)
    out = image_to_rgb8(_msg('rgb16', rgb16, 2, bigendian))
    np.testing.assert_array_equal(out, (rgb16 >> 8).astype(np.uint8))
    mono = rng.integers(0, 256, (4, 5), dtype=np.uint8)
    np.testing.assert_array_equal(image_to_rgb8(_msg('mono8', mono[..., None], 1),
                                                allow_mono=True),
                                  np.repeat(mono[..., None], 3, axis=2))
    with pytest.raises(ImageEncodingError, match='colour image.*mono8'):
        image_to_rgb8(_msg('mono8', mono[..., None], 1))
    with pytest.raises(ImageEncodingError, match='yuv422'):
        image_to_rgb8(_msg('yuv422', mono[..., None]))


def test_make_bag_tool(tmp_path: Path, capsys) -> None:
    calib = CONFIG_DIR / 'calibration.yaml'
    out = tmp_path / 'tool_bag'
    assert make_bag.main(['--seed', '2', '--frames', '3', '--output', str(out),
                          '--calibration', str(calib), '--split', 'train']) == 0
    assert 'frames' in capsys.readouterr().out
    back = list(read_sequence_bag(out))
    assert len(back) == 3 and back[0].image_rgb.shape == (480, 640, 3)
    seq = SyntheticSequenceRenderer(bag_camera(out), seed=2, num_frames=3, split='train')
    np.testing.assert_array_equal(back[1].image_rgb, seq.render(1).image_rgb)
    seq.close()


def test_stereo_bag_from_make_bag(tmp_path: Path) -> None:
    """A two-camera calibration gives both views at the same stamps, each with its frame_id and
    intrinsics, the extra view written before the primary one within a frame and each view's
    CameraInfo before its image (a reader refuses images before their CameraInfo)."""
    calib_path = CONFIG_DIR / 'calibration_stereo.yaml'
    calibration = load_calibration(calib_path)
    out = tmp_path / 'stereo'
    assert make_bag.main(['--seed', '4', '--frames', '2', '--output', str(out),
                          '--calibration', str(calib_path)]) == 0
    second = calibration.cameras[1]
    order, stamps, frame_ids = [], {}, {}
    with AnyReader([out]) as reader:
        for conn, log_ns, raw in reader.messages():
            msg = reader.deserialize(raw, conn.msgtype)
            header = _header(conn.topic, msg)
            order.append(conn.topic)
            stamps.setdefault(conn.topic, []).append(log_ns)
            frame_ids[conn.topic] = header.frame_id
            if conn.topic == '/camera2/camera/camera_info':
                assert camera_info_to_pinhole(msg).fx == second.fx
    assert stamps['/camera2/camera/image_raw'] == stamps[TOPIC_IMAGE]
    assert len(stamps[TOPIC_IMAGE]) == 2
    assert frame_ids['/camera2/camera/image_raw'] == second.frame_id == 'camera2_optical_frame'
    assert frame_ids[TOPIC_IMAGE] == FRAME_ID
    assert order.index('/camera2/camera/image_raw') < order.index(TOPIC_IMAGE)
    assert order.index(TOPIC_CAMERA_INFO) < order.index(TOPIC_IMAGE)
    assert order.index('/camera2/camera/camera_info') < order.index('/camera2/camera/image_raw')
    assert order[0] == TOPIC_TF_STATIC and order.count(TOPIC_TF_STATIC) == 1
    # the two views differ (another viewpoint) but both show the glove
    back = list(read_sequence_bag(out))
    assert len(back) == 2 and back[0].pose is not None


def test_writer_checks_extra_images(tmp_path: Path, frames) -> None:
    other = PinholeCamera(160, 120, 150.0, 150.0, 79.5, 59.5, name='side', frame_id='side_frame')
    with SequenceBagWriter(tmp_path / 'two', CAM, extra_cameras=[other]) as writer:
        with pytest.raises(BagError, match='1 extra camera'):
            writer.write(frames[0])
        with pytest.raises(BagError, match='camera 1'):
            writer.write(frames[0], extra_images=[np.zeros((5, 5, 3), np.uint8)])
        writer.write(frames[0], extra_images=[frames[1].image_rgb])
    with pytest.raises(BagError, match='distinct names'):
        SequenceBagWriter(tmp_path / 'dup', CAM, extra_cameras=[other, other])


@pytest.mark.parametrize('coefficients', [0, 3, 6, 14])
def test_distortion_of_wrong_length_is_refused(coefficients: int) -> None:
    with pytest.raises(CalibrationError, match=f'got shape \\({coefficients},\\)'):
        PinholeCamera(160, 120, 150.0, 150.0, 79.5, 59.5, distortion=np.zeros(coefficients))
    info = SimpleNamespace(width=160, height=120, k=CAM.K.ravel(), d=np.zeros(coefficients),
                           distortion_model='plumb_bob',
                           header=SimpleNamespace(frame_id=FRAME_ID))
    with pytest.raises(BagError, match='distortion needs 5'):
        camera_info_to_pinhole(info)


def test_camera_info_model_follows_the_coefficients() -> None:
    eight = PinholeCamera(160, 120, 150.0, 150.0, 79.5, 59.5, distortion=np.full(8, 0.01))
    fields = eight.camera_info_fields()
    assert fields['distortion_model'] == 'rational_polynomial' and len(fields['d']) == 8
    assert fields['p'][:3] == [150.0, 0.0, 79.5] and fields['p'][3] == 0.0
    info = SimpleNamespace(width=160, height=120, k=np.asarray(fields['k']),
                           d=np.asarray(fields['d']), distortion_model='plumb_bob',
                           header=SimpleNamespace(frame_id=FRAME_ID))
    with pytest.raises(BagError, match="model 'plumb_bob' with 8"):
        camera_info_to_pinhole(info)


def test_bags_carry_tf_and_static_camera_frames(tmp_path: Path, frames) -> None:
    """/tf holds the ground-truth camera -> palm transform of every frame (the wrist pose);
    a rig's /tf_static, once and latched (transient local in the metadata, as rosbag2 records
    a static broadcaster), places each extra camera's optical frame in camera 0's."""
    from colorglove_ros.core.camera import look_at_extrinsics
    from colorglove_ros.core.geometry import quaternion_to_rotvec, rotvec_to_matrix

    rotation, translation = look_at_extrinsics(np.array([0.3, -0.05, 0.2]),
                                               np.array([0.0, 0.0, 0.55]))
    side = PinholeCamera(160, 120, 150.0, 150.0, 79.5, 59.5, rotation=rotation,
                         translation=translation, name='side', frame_id='side_optical_frame')
    path = tmp_path / 'tf'
    with SequenceBagWriter(path, CAM, extra_cameras=[side]) as writer:
        stamps = [writer.write(f, extra_images=[f.image_rgb]) for f in frames]
    dynamic = read_transforms(path)
    assert [t.stamp_ns for t in dynamic] == stamps
    for tf, frame, back in zip(dynamic, frames, read_sequence_bag(path), strict=True):
        assert (tf.parent, tf.child) == (FRAME_ID, 'palm')
        np.testing.assert_allclose(tf.translation, frame.pose[0:3], atol=1e-12)
        np.testing.assert_allclose(tf.rotation_xyzw, back.wrist_quaternion, atol=1e-12)
    (static,) = read_transforms(path, TOPIC_TF_STATIC)
    assert (static.parent, static.child, static.stamp_ns) == (FRAME_ID, 'side_optical_frame',
                                                              stamps[0])
    # the child's origin and axes in camera 0's frame: p0 = R^T (p_side - t)
    np.testing.assert_allclose(static.translation, [0.3, -0.05, 0.2], atol=1e-9)
    np.testing.assert_allclose(rotvec_to_matrix(quaternion_to_rotvec(static.rotation_xyzw)),
                               rotation.T, atol=1e-9)
    with AnyReader([path]) as reader:
        (conn,) = [c for c in reader.connections if c.topic == TOPIC_TF_STATIC]
        (qos,) = conn.ext.offered_qos_profiles
        assert (qos.durability.name, qos.reliability.name) == ('TRANSIENT_LOCAL', 'RELIABLE')
    metadata = (path / 'metadata.yaml').read_text()
    static_entry = metadata[metadata.index(f'name: {TOPIC_TF_STATIC}'):]
    assert 'durability: transient_local' in static_entry.split('type:')[0]


def test_bag_in_a_driver_encoding(tmp_path: Path, frames) -> None:
    """Images written as usb_cam's yuyv mode sends them (yuv422_yuy2, 2 bytes a pixel) come
    back as RGB close to the rendered image (4:2:2 halves the colour resolution)."""
    path = tmp_path / 'yuyv'
    with SequenceBagWriter(path, CAM, encoding='yuv422_yuy2') as writer:
        writer.write(frames[0])
    with AnyReader([path]) as reader:
        (conn,) = [c for c in reader.connections if c.topic == TOPIC_IMAGE]
        (_, _, raw), = list(reader.messages(connections=[conn]))
        msg = reader.deserialize(raw, conn.msgtype)
    assert (msg.encoding, msg.step, len(msg.data)) == ('yuv422_yuy2', 320, 320 * 120)
    back = next(read_sequence_bag(path)).image_rgb
    assert np.abs(back.astype(int) - frames[0].image_rgb).mean() < 6.0
    with pytest.raises(BagError, match='cannot write RGB'):
        SequenceBagWriter(tmp_path / 'bad', CAM, encoding='mono8')
