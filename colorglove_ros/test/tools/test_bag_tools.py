"""play_bag and record_bag: a bag played into the graph is recorded back byte for byte."""
from __future__ import annotations

import signal
import subprocess
import sys
import time
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
import yaml
from message_samples import sample_observation
from rclpy.serialization import serialize_message
from repo_paths import CONFIG_DIR
from rosbag2_compat import check_jazzy_bag
from rosbags.highlevel import AnyReader
from rosbags.rosbag2 import StoragePlugin, Writer
from sensor_msgs.msg import JointState

from colorglove_ros.core.camera import load_calibration
from colorglove_ros.core.synthetic.sequences import SyntheticSequenceRenderer
from colorglove_ros.ros.bags import camera_topics, read_sequence_bag
from colorglove_ros.ros.image_codec import image_to_rgb8
from colorglove_ros.ros.typestore import colorglove_typestore, deserialize_cdr
from colorglove_ros.tools import make_bag

pytestmark = pytest.mark.dds

STEREO_CALIBRATION = CONFIG_DIR / 'calibration_stereo.yaml'


def _write_bag(path: Path) -> dict[str, list[bytes]]:
    store = colorglove_typestore()
    sent: dict[str, list[bytes]] = {'/test/joints': [], '/test/observation': []}
    with Writer(path, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        joints = writer.add_connection('/test/joints', 'sensor_msgs/msg/JointState',
                                       typestore=store)
        observations = writer.add_connection('/test/observation',
                                             'colorglove_msgs/msg/HandObservation', typestore=store)
        for index in range(20):
            msg = JointState(name=['a', 'b'], position=[float(index), -float(index)])
            msg.header.stamp.sec = index
            data = serialize_message(msg)
            sent['/test/joints'].append(data)
            writer.write(joints, 1_000_000_000 + index * 20_000_000, data)
            if index % 4 == 0:
                data = serialize_message(sample_observation(index))
                sent['/test/observation'].append(data)
                writer.write(observations, 1_000_000_000 + index * 20_000_000 + 1, data)
    return sent


def test_play_then_record_round_trip(tmp_path: Path, isolated_ros_domain: dict) -> None:
    sent = _write_bag(tmp_path / 'input')
    recorder = subprocess.Popen(
        [sys.executable, '-m', 'colorglove_ros.tools.record_bag', str(tmp_path / 'recorded'),
         '--topics', '/test/joints', '/test/observation', '--duration', '60'],
        env=isolated_ros_domain, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    time.sleep(1.0)
    player = subprocess.run(
        [sys.executable, '-m', 'colorglove_ros.tools.play_bag', str(tmp_path / 'input'),
         '--rate', '1.0', '--pace-on', '/test/joints', '--wait-subscribers', '10'],
        env=isolated_ros_domain, capture_output=True, text=True, timeout=60)
    assert player.returncode == 0, player.stderr
    assert 'published 25 messages' in player.stdout
    time.sleep(0.5)
    recorder.send_signal(signal.SIGINT)
    recorder_output = recorder.communicate(timeout=30)[0]
    assert recorder.returncode == 0, recorder_output
    with AnyReader([tmp_path / 'recorded'], default_typestore=colorglove_typestore()) as reader:
        received: dict[str, list[bytes]] = {c.topic: [] for c in reader.connections}
        for connection, _, data in reader.messages():
            received[connection.topic].append(bytes(data))
    decoded = [deserialize_cdr(data, 'sensor_msgs/msg/JointState')
               for data in received['/test/joints']]
    # the recorder subscribes once the topic appears, so the first messages may predate it
    assert len(received['/test/joints']) >= 15
    assert received['/test/joints'] == sent['/test/joints'][-len(received['/test/joints']):]
    assert received['/test/observation'] == \
        sent['/test/observation'][-len(received['/test/observation']):]
    assert len(received['/test/observation']) >= 3
    np.testing.assert_array_equal(decoded[-1].position, [19.0, -19.0])
    # colorglove_msgs too decode with an independent reader from the schema in the bag
    observations = check_jazzy_bag(tmp_path / 'recorded')['/test/observation']
    assert [m.crop_offset_x for m in observations] == \
        [sample_observation(i).crop_offset_x for i in range(0, 20, 4)][-len(observations):]


def test_recorder_ends_cleanly_when_ctrl_c_shuts_rclpy_down(tmp_path: Path,
                                                            monkeypatch: pytest.MonkeyPatch,
                                                            isolated_ros_domain: dict) -> None:
    """Ctrl-C can reach the recorder as rclpy's own shutdown of the context in the middle of
    a spin (ExternalShutdownException rather than KeyboardInterrupt): the recorder still
    closes the bag, prints its counts and exits 0."""
    import rclpy
    from rclpy.executors import ExternalShutdownException

    from colorglove_ros.tools import record_bag

    monkeypatch.setenv('ROS_DOMAIN_ID', isolated_ros_domain['ROS_DOMAIN_ID'])

    def shut_down(*_args, **_kwargs) -> None:
        raise ExternalShutdownException()

    monkeypatch.setattr(rclpy, 'spin_once', shut_down)
    assert record_bag.main([str(tmp_path / 'recorded'), '--topics', '/test/joints']) == 0
    assert (tmp_path / 'recorded' / 'metadata.yaml').is_file()


def test_missing_bag_is_a_clear_error(tmp_path: Path) -> None:
    result = subprocess.run([sys.executable, '-m', 'colorglove_ros.tools.play_bag',
                             str(tmp_path / 'nope')], capture_output=True, text=True, timeout=30)
    assert result.returncode == 2 and 'no bag at' in result.stderr


def _small_calibration(path: Path, num_cameras: int) -> Path:
    """The first ``num_cameras`` cameras of the stereo rig at 160 x 120 (a quarter scale)."""
    cameras = []
    for camera in load_calibration(STEREO_CALIBRATION).cameras[:num_cameras]:
        entry = camera.to_dict()
        entry.update(width=160, height=120, fx=camera.fx / 4, fy=camera.fy / 4,
                     cx=(camera.cx + 0.5) / 4 - 0.5, cy=(camera.cy + 0.5) / 4 - 0.5)
        cameras.append(entry)
    path.write_text(yaml.safe_dump({'version': 1, 'hand_length_m': 0.19, 'cameras': cameras}))
    return path


def test_stereo_make_bag_primary_view_is_the_mono_bag(tmp_path: Path) -> None:
    """A two-camera make_bag writes the same primary images as a one-camera one of the same
    seed, and the second camera's images at the same stamps as ``render_views`` gives them."""
    frames, seed = 3, 10
    mono_calibration = _small_calibration(tmp_path / 'mono.yaml', 1)
    stereo_calibration = _small_calibration(tmp_path / 'stereo.yaml', 2)
    for name, calibration in (('mono', mono_calibration), ('stereo', stereo_calibration)):
        assert make_bag.main(['--seed', str(seed), '--frames', str(frames), '--output',
                              str(tmp_path / name), '--calibration', str(calibration)]) == 0
    mono = list(read_sequence_bag(tmp_path / 'mono'))
    stereo = list(read_sequence_bag(tmp_path / 'stereo'))
    assert len(mono) == len(stereo) == frames
    for one, two in zip(mono, stereo, strict=True):
        assert one.stamp_ns == two.stamp_ns and one.image_rgb.shape == (120, 160, 3)
        np.testing.assert_array_equal(one.image_rgb, two.image_rgb)
        np.testing.assert_array_equal(one.pose, two.pose)
    rig = load_calibration(stereo_calibration).cameras
    image_topic = camera_topics(rig[1], 1)[0]
    with AnyReader([tmp_path / 'stereo'], default_typestore=colorglove_typestore()) as reader:
        second = [(reader.deserialize(raw, conn.msgtype), log_ns) for conn, log_ns, raw
                  in reader.messages([c for c in reader.connections if c.topic == image_topic])]
    assert [log_ns for _, log_ns in second] == [frame.stamp_ns for frame in stereo]
    sequence = SyntheticSequenceRenderer(rig[0], seed=seed, num_frames=frames)
    for index, (msg, _) in enumerate(second):
        views = sequence.render_views(index, rig)
        np.testing.assert_array_equal(image_to_rgb8(msg), views[1].image_rgb)
        np.testing.assert_array_equal(views[0].image_rgb, stereo[index].image_rgb)
        assert not np.array_equal(views[1].image_rgb, views[0].image_rgb)
    sequence.close()


def test_restamp_sets_publish_time_and_keeps_frames_together(tmp_path: Path) -> None:
    """--restamp: stamped messages get the wall-clock time of their publication, messages
    recorded with one stamp keep sharing one, and the rest of the bytes is unchanged."""
    import rclpy

    from colorglove_ros.tools.play_bag import BagPlayer

    sent = _write_bag(tmp_path / 'input')
    context = rclpy.Context()
    rclpy.init(context=context)
    try:
        player = BagPlayer(tmp_path / 'input', context=context)
        before = time.time_ns()
        joints = [player.restamped('/test/joints', data) for data in sent['/test/joints']]
        again = player.restamped('/test/joints', sent['/test/joints'][3])
        after = time.time_ns()
        player.close()
        player.destroy_node()
    finally:
        rclpy.try_shutdown(context=context)
    decoded = [deserialize_cdr(data, 'sensor_msgs/msg/JointState') for data in joints]
    stamps = [m.header.stamp.sec * 10**9 + m.header.stamp.nanosec for m in decoded]
    assert all(before <= s <= after for s in stamps) and stamps == sorted(stamps)
    assert again == joints[3]                      # the same recorded stamp, the same new one
    assert [list(m.position) for m in decoded] == [[float(i), -float(i)] for i in range(20)]
    assert all(new[12:] == old[12:] for new, old in zip(joints, sent['/test/joints'],
                                                         strict=True))


def test_each_loop_gets_new_stamps(tmp_path: Path) -> None:
    """--loop --restamp: the bag played again is stamped at its new publication time, not
    with the stamps of the loop before."""
    import rclpy

    from colorglove_ros.tools.play_bag import BagPlayer

    _write_bag(tmp_path / 'input')
    published: list[bytes] = []
    context = rclpy.Context()
    rclpy.init(context=context)
    try:
        player = BagPlayer(tmp_path / 'input', ['/test/joints'], context=context)
        player.publishers_by_topic = {'/test/joints': SimpleNamespace(publish=published.append)}
        loops = []
        for _ in range(2):
            player.play(0.0, None, None, 1.0, restamp=True)
            loops.append(list(published))
            published.clear()
            time.sleep(0.01)
        player.close()
        player.destroy_node()
    finally:
        rclpy.try_shutdown(context=context)
    first, second = ([deserialize_cdr(data, 'sensor_msgs/msg/JointState').header.stamp
                      for data in loop] for loop in loops)
    assert len(first) == len(second) == 20
    assert all((b.sec, b.nanosec) > (a.sec, a.nanosec) for a, b in zip(first, second,
                                                                       strict=True))


def test_stamp_log_maps_each_new_stamp_to_the_recorded_one(tmp_path: Path) -> None:
    """--stamp-log: every new stamp is logged once, beside the recorded stamp it replaced, so
    an output stamped with it maps back to the bag's frame."""
    import io

    import rclpy

    from colorglove_ros.tools.play_bag import STAMP_LOG_HEADER, BagPlayer, read_stamp_log

    sent = _write_bag(tmp_path / 'input')
    context = rclpy.Context()
    rclpy.init(context=context)
    log = io.StringIO()
    try:
        player = BagPlayer(tmp_path / 'input', context=context)
        player.stamp_log = log
        log.write(STAMP_LOG_HEADER + '\n')
        joints = [player.restamped('/test/joints', data) for data in sent['/test/joints']]
        player.restamped('/test/joints', sent['/test/joints'][3])     # not a new stamp
        player.close()
        player.destroy_node()
    finally:
        rclpy.try_shutdown(context=context)
    path = tmp_path / 'stamps.csv'
    path.write_text(log.getvalue())
    mapping = read_stamp_log(path)
    assert len(mapping) == 20
    for index, data in enumerate(joints):
        stamp = deserialize_cdr(data, 'sensor_msgs/msg/JointState').header.stamp
        assert mapping[stamp.sec * 10**9 + stamp.nanosec] == index * 10**9   # recorded: sec i
    path.write_text(STAMP_LOG_HEADER + '\n1,2\nthree,4\n')
    with pytest.raises(ValueError, match=r'stamps.csv:3: expected two integers'):
        read_stamp_log(path)
    path.write_text('1,2\n')
    with pytest.raises(ValueError, match='not a stamp log'):
        read_stamp_log(path)


def test_stamp_log_needs_restamp(tmp_path: Path) -> None:
    _write_bag(tmp_path / 'input')
    done = subprocess.run([sys.executable, '-m', 'colorglove_ros.tools.play_bag',
                           str(tmp_path / 'input'), '--stamp-log', str(tmp_path / 's.csv')],
                          capture_output=True, text=True, timeout=60)
    assert done.returncode == 2 and '--stamp-log needs --restamp' in done.stderr
    assert not (tmp_path / 's.csv').exists()


def _write_camera_bag(path: Path, messages: tuple[tuple[str, str, object], ...]) -> None:
    """A bag with one message on each (topic, type, message)."""
    store = colorglove_typestore()
    with Writer(path, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        for topic, kind, message in messages:
            connection = writer.add_connection(topic, kind, typestore=store)
            writer.write(connection, 1_000_000_000, serialize_message(message))


def test_player_finds_the_camera_info_beside_the_image(tmp_path: Path) -> None:
    """--paced waits for a subscriber on the image's CameraInfo too (a node matched to the
    images before their CameraInfo answers them 'waiting for CameraInfo'): the player finds the
    CameraInfo topic in the image's namespace, raw or compressed, and none where there is none."""
    import rclpy
    from sensor_msgs.msg import CameraInfo, Image

    from colorglove_ros.tools.play_bag import BagPlayer

    _write_camera_bag(tmp_path / 'bag', (
        ('/cam/image_raw', 'sensor_msgs/msg/Image', Image()),
        ('/cam/camera_info', 'sensor_msgs/msg/CameraInfo', CameraInfo()),
        ('/other/image_raw', 'sensor_msgs/msg/Image', Image())))
    context = rclpy.Context()
    rclpy.init(context=context)
    try:
        player = BagPlayer(tmp_path / 'bag', context=context)
        found = [player.camera_info_beside(topic) for topic in (
            '/cam/image_raw', '/cam/image_raw/compressed', '/other/image_raw')]
        player.close()
        player.destroy_node()
    finally:
        rclpy.try_shutdown(context=context)
    assert found == ['/cam/camera_info', '/cam/camera_info', None]


def test_player_waits_for_every_camera_info_subscriber(tmp_path: Path) -> None:
    """--min-info-subscribers: with one CameraInfo reader matched, a wait for two times out
    (a second node still unmatched would answer the first frames 'waiting for CameraInfo')."""
    import rclpy
    from sensor_msgs.msg import CameraInfo, Image

    from colorglove_ros.tools.play_bag import PLAYBACK_OPTIONS, BagPlayer

    assert PLAYBACK_OPTIONS['min-info-subscribers'][1] == 1
    _write_camera_bag(tmp_path / 'bag', (
        ('/cam/image_raw', 'sensor_msgs/msg/Image', Image()),
        ('/cam/camera_info', 'sensor_msgs/msg/CameraInfo', CameraInfo())))
    context = rclpy.Context()
    rclpy.init(context=context)
    try:
        player = BagPlayer(tmp_path / 'bag', context=context)
        reader = rclpy.create_node('info_reader', context=context)
        reader.create_subscription(CameraInfo, '/cam/camera_info', lambda _msg: None, 10)
        one = player.wait_for_subscribers('/cam/camera_info', 5.0, 1)
        two = player.wait_for_subscribers('/cam/camera_info', 0.3, 2)
        reader.destroy_node()
        player.close()
        player.destroy_node()
    finally:
        rclpy.try_shutdown(context=context)
    assert (one, two) == (True, False)


def test_player_primes_each_camera_info(tmp_path: Path) -> None:
    """Before playing, the player publishes the first CameraInfo of each CameraInfo topic, so a
    bag holding a frame's image ahead of its CameraInfo (as drivers publish them) does not
    have its first frame refused 'waiting for CameraInfo'."""
    import rclpy
    from sensor_msgs.msg import CameraInfo, Image

    from colorglove_ros.tools.play_bag import BagPlayer

    _write_camera_bag(tmp_path / 'bag', (
        ('/cam/image_raw', 'sensor_msgs/msg/Image', Image()),
        ('/cam/camera_info', 'sensor_msgs/msg/CameraInfo', CameraInfo(width=640, height=480)),
        ('/cam2/camera_info', 'sensor_msgs/msg/CameraInfo', CameraInfo(width=320))))
    context = rclpy.Context()
    rclpy.init(context=context)
    received: list[tuple[str, int]] = []
    try:
        player = BagPlayer(tmp_path / 'bag', context=context)
        reader = rclpy.create_node('info_reader', context=context)
        for topic in ('/cam/camera_info', '/cam2/camera_info'):
            reader.create_subscription(CameraInfo, topic,
                                       lambda msg, topic=topic: received.append((topic,
                                                                                 msg.width)),
                                       10)
        reader.create_subscription(Image, '/cam/image_raw',
                                   lambda _msg: received.append(('image', 0)), 10)
        assert player.wait_for_subscribers('/cam2/camera_info', 5.0, 1)
        time.sleep(0.5)
        primed = player.prime_camera_infos()
        executor = rclpy.executors.SingleThreadedExecutor(context=context)
        executor.add_node(reader)
        deadline = time.monotonic() + 5.0
        while len(received) < 2 and time.monotonic() < deadline:
            executor.spin_once(timeout_sec=0.1)
        executor.shutdown()
        reader.destroy_node()
        player.close()
        player.destroy_node()
    finally:
        rclpy.try_shutdown(context=context)
    assert sorted(primed) == ['/cam/camera_info', '/cam2/camera_info']
    assert sorted(received) == [('/cam/camera_info', 640), ('/cam2/camera_info', 320)]


def test_paced_player_resends_a_frame_nobody_answered(tmp_path: Path) -> None:
    """--paced with --pace-resends 1: a frame whose output did not come within the pace
    timeout (a best-effort image lost on the way) is published once more, with the same
    bytes; with 0 it is not."""
    import rclpy
    from sensor_msgs.msg import Image

    from colorglove_ros.tools.play_bag import PLAYBACK_OPTIONS, BagPlayer

    assert PLAYBACK_OPTIONS['pace-resends'][1] == 1
    _write_camera_bag(tmp_path / 'bag', (('/cam/image_raw', 'sensor_msgs/msg/Image',
                                          Image(width=3, height=2, encoding='mono8', step=3,
                                                data=bytes(range(6)))),))
    context = rclpy.Context()
    rclpy.init(context=context)
    received: list[bytes] = []
    try:
        reader = rclpy.create_node('image_reader', context=context)
        reader.create_subscription(Image, '/cam/image_raw',
                                   lambda msg: received.append(bytes(msg.data)), 10)
        executor = rclpy.executors.SingleThreadedExecutor(context=context)
        executor.add_node(reader)
        counts = []
        for resends in (1, 0):
            player = BagPlayer(tmp_path / 'bag', context=context)
            assert player.wait_for_subscribers('/cam/image_raw', 5.0, 1)
            time.sleep(0.5)
            player.play(0.0, '/hand/tracking_status', '/cam/image_raw', 0.2,
                        pace_resends=resends)
            deadline = time.monotonic() + 2.0
            while time.monotonic() < deadline:
                executor.spin_once(timeout_sec=0.05)
            counts.append((player.resent, len(received)))
            received.clear()
            player.close()
            player.destroy_node()
        executor.shutdown()
        reader.destroy_node()
    finally:
        rclpy.try_shutdown(context=context)
    assert counts == [(1, 2), (0, 1)]


def test_a_slow_frame_answered_twice_does_not_release_the_next_frame_early(
        tmp_path: Path) -> None:
    """--paced with a resend: a frame that was only slow (each copy answered 0.3 s after it
    was sent, past the 0.2 s pace timeout) releases the next frame only once both copies are
    answered; released by the first answer, the next frame would be published while the
    second copy is still being processed, and replace it in a depth-1 image queue."""
    import threading

    import rclpy
    from sensor_msgs.msg import Image

    from colorglove_ros.tools.play_bag import BagPlayer

    store = colorglove_typestore()
    with Writer(tmp_path / 'bag', version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        connection = writer.add_connection('/cam/image_raw', 'sensor_msgs/msg/Image',
                                           typestore=store)
        for k in range(2):
            writer.write(connection, 1_000_000_000 + k, serialize_message(
                Image(width=1, height=1, encoding='mono8', step=1, data=bytes([k]))))
    sent: list[tuple[float, bytes]] = []
    answers: list[float] = []
    context = rclpy.Context()
    rclpy.init(context=context)
    try:
        player = BagPlayer(tmp_path / 'bag', context=context)

        def answer() -> None:
            answers.append(time.monotonic())
            player.output_answered()

        def publish(data: bytes) -> None:
            sent.append((time.monotonic(), data))
            threading.Timer(0.3, answer).start()

        player.publishers_by_topic = {'/cam/image_raw': SimpleNamespace(publish=publish)}
        player.play(0.0, '/hand/tracking_status', '/cam/image_raw', 0.2, pace_resends=1)
        time.sleep(0.7)
        player.close()
        player.destroy_node()
    finally:
        rclpy.try_shutdown(context=context)
    first_frame = [t for t, data in sent if data == sent[0][1]]
    second_frame = [t for t, data in sent if data != sent[0][1]]
    assert len(first_frame) == 2 and player.resent == 2     # the second frame was slow too
    assert second_frame[0] >= sorted(answers)[1]             # after both answers of the first


def test_player_says_which_subscribers_did_not_come(tmp_path: Path,
                                                    isolated_ros_domain: dict) -> None:
    """The command line's --min-subscribers / --min-info-subscribers reach the waits, and a
    wait that times out is a warning naming the topic and the counts, not silence."""
    from sensor_msgs.msg import CameraInfo, Image

    _write_camera_bag(tmp_path / 'bag', (
        ('/camera/image_raw', 'sensor_msgs/msg/Image', Image()),
        ('/camera/camera_info', 'sensor_msgs/msg/CameraInfo', CameraInfo())))
    done = subprocess.run(
        [sys.executable, '-m', 'colorglove_ros.tools.play_bag', str(tmp_path / 'bag'),
         '--paced', '--pace-timeout', '0.1', '--wait-subscribers', '0.3', '--linger', '0',
         '--min-subscribers', '1', '--min-info-subscribers', '2'],
        env=isolated_ros_domain, capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, done.stderr
    assert '/camera/image_raw has 0 of 1 subscribers' in done.stderr
    assert '/camera/camera_info has 0 of 2 subscribers' in done.stderr
    assert 'no publisher on /hand/tracking_status' in done.stderr


def test_player_waits_for_a_second_cameras_subscribers(tmp_path: Path,
                                                       isolated_ros_domain: dict) -> None:
    """--wait-for TOPIC=COUNT: the player also waits for the subscribers of topics beside the
    paced image's (a second camera's image and CameraInfo) and says which did not come; a
    topic the bag does not play, or no count, is refused before anything is published."""
    from sensor_msgs.msg import CameraInfo, Image

    _write_camera_bag(tmp_path / 'bag', (
        ('/camera/image_raw', 'sensor_msgs/msg/Image', Image()),
        ('/camera/camera_info', 'sensor_msgs/msg/CameraInfo', CameraInfo()),
        ('/cam1/camera/image_raw', 'sensor_msgs/msg/Image', Image()),
        ('/cam1/camera/camera_info', 'sensor_msgs/msg/CameraInfo', CameraInfo())))
    command = [sys.executable, '-m', 'colorglove_ros.tools.play_bag', str(tmp_path / 'bag'),
               '--wait-subscribers', '0.3', '--linger', '0', '--min-subscribers', '0',
               '--min-info-subscribers', '0', '--wait-for']
    done = subprocess.run(command + ['/cam1/camera/image_raw=1', '/cam1/camera/camera_info=2'],
                          env=isolated_ros_domain, capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, done.stderr
    assert '/cam1/camera/image_raw has 0 of 1 subscribers' in done.stderr
    assert '/cam1/camera/camera_info has 0 of 2 subscribers' in done.stderr
    assert 'published 4 messages' in done.stdout
    unknown = subprocess.run(command + ['/cam2/camera/camera_info=1'], env=isolated_ros_domain,
                             capture_output=True, text=True, timeout=60)
    assert unknown.returncode == 2
    assert "--wait-for: the bag plays no topic ['/cam2/camera/camera_info']" in unknown.stderr
    assert 'published' not in unknown.stdout
    malformed = subprocess.run(command + ['/cam1/camera/camera_info'], env=isolated_ros_domain,
                               capture_output=True, text=True, timeout=60)
    assert malformed.returncode == 2 and 'expected TOPIC=COUNT' in malformed.stderr


def test_recorder_timer_after_shutdown_does_nothing(tmp_path: Path) -> None:
    """Ctrl-C: rclpy's handler shuts the context down, and a spin already under way may still
    run the recorder's discovery timer; it must not raise (the recorder then exited 1 with
    'rcl node's context is invalid' instead of closing the bag)."""
    import rclpy

    from colorglove_ros.tools.record_bag import BagRecorder

    context = rclpy.Context()
    rclpy.init(context=context)
    recorder = BagRecorder(tmp_path / 'recorded', ['/test/joints'], context=context)
    try:
        rclpy.shutdown(context=context)
        recorder.discover()
        assert recorder.pending == {'/test/joints'}
    finally:
        recorder.close()
        recorder.destroy_node()
        rclpy.try_shutdown(context=context)
