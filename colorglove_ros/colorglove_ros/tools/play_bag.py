"""Publish a rosbag2 (sqlite3 or MCAP) into the ROS graph, with its original timing or paced by
the pipeline's output (next frame as soon as the previous one has produced a result).

Like ``ros2 bag play``: each topic is offered with the QoS its recorded publishers offered,
``--clock`` publishes the bag's time on ``/clock`` (for nodes with ``use_sim_time``), and
``--loop`` plays the bag again from the start until Ctrl-C. ``--restamp`` sets the header stamp
of every stamped message to the wall-clock time it is published at (all messages of one
recorded stamp get the same new stamp), so arrival minus header stamp downstream is the latency
of the replayed frame, as with a live camera."""
from __future__ import annotations

import struct
import sys
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any, TextIO

import rclpy
from builtin_interfaces.msg import Time
from rclpy.node import Node
from rosgraph_msgs.msg import Clock

from colorglove_ros.ros.bag_definitions import (
    DefinitionChange,
    DefinitionConversionError,
    convert_message,
    definition_changes,
)
from colorglove_ros.ros.bag_qos import publisher_qos_for_recorded
from colorglove_ros.ros.bags import BagError, bag_messages, open_bag_reader
from colorglove_ros.ros.heap_tuning import keep_freed_buffers
from colorglove_ros.ros.image_codec import header_stamp_from_cdr
from colorglove_ros.ros.typestore import colorglove_typestore, deserialize_cdr, message_class
from colorglove_ros.tools._cli import tool_parser
from colorglove_ros.topic_arguments import topic_argument

__all__ = ['BagDefinitionError', 'BagPlayer', 'PLAYBACK_OPTIONS', 'STAMP_LOG_HEADER',
           'read_stamp_log', 'main']


class BagDefinitionError(ValueError):
    """The bag holds topics recorded with another definition of their message type than the
    installed one that are not to be converted, or cannot be."""

# The player's options: --NAME -> (type, default, help); bool options are flags.
PLAYBACK_OPTIONS: dict[str, tuple[type, object, str]] = {
    'rate': (float, 1.0, 'playback speed factor of the original timing (0 = no delays)'),
    'paced': (bool, False, 'publish each frame after the previous one produced --pace-topic'),
    'pace-on': (str, '/camera/image_raw',
                'the input topic that waits for the output when --paced'),
    'pace-topic': (str, '/hand/tracking_status',
                   'the output topic (std_msgs/String, one per processed frame, hand or no '
                   'hand) whose messages release the next frame'),
    'pace-timeout': (float, 1.0, 'longest wait for an output before going on, seconds'),
    'pace-resends': (int, 1, 'with --paced, publish a frame again (same stamp) this many times '
                     'when no output came within --pace-timeout (a best-effort image can be '
                     'lost on the way; a frame that was only slow is then answered once per '
                     'copy, and the next frame waits for those answers)'),
    'wait-subscribers': (float, 10.0,
                         'wait this long for subscribers on --pace-on (and on the CameraInfo '
                         'topic beside it, if the bag has one) before starting'),
    'min-subscribers': (int, 1, 'subscribers on --pace-on to wait for before starting'),
    'min-info-subscribers': (int, 1, 'subscribers on the CameraInfo topic beside --pace-on to '
                             'wait for before starting (every node that reads CameraInfo)'),
    'settle': (float, 0.5, 'seconds to wait after those subscribers are matched, before the '
               'first message: a subscriber matches the player shortly after the player '
               'matched it, and a message published in between is lost to it'),
    'loop': (bool, False, 'play again from the start until Ctrl-C'),
    'clock': (bool, False, "publish the bag's time on /clock (rosgraph_msgs/Clock)"),
    'restamp': (bool, False, 'stamp each message with its publish time (wall clock) instead of '
                'its recorded header stamp (for latency measurements)'),
    'stamp-log': (str, '', 'with --restamp, write every recorded header stamp and the new '
                  'stamp it was published with (ns, CSV) to this file, so outputs stamped '
                  'with the new stamps map back to the bag\'s frames'),
    'linger': (float, 1.0, 'seconds to stay up after the last message, for late deliveries'),
}

STAMP_LOG_HEADER = 'recorded_stamp_ns,published_stamp_ns'


def read_stamp_log(path: str | Path) -> dict[int, int]:
    """A ``--stamp-log`` file as {published stamp: recorded stamp} (ns); a ValueError naming
    the file and line for anything else."""
    lines = Path(path).read_text().splitlines()
    if not lines or lines[0] != STAMP_LOG_HEADER:
        raise ValueError(f'{path}: not a stamp log (first line must be {STAMP_LOG_HEADER!r})')
    mapping = {}
    for number, line in enumerate(lines[1:], 2):
        try:
            recorded, published = (int(field) for field in line.split(','))
        except ValueError:
            raise ValueError(f'{path}:{number}: expected two integers, got {line!r}') from None
        mapping[published] = recorded
    return mapping


def _count(text: str) -> int:
    """A subscriber count of ``--wait-for``: digits only (ValueError otherwise)."""
    if not text.isdigit():
        raise ValueError(f'not a count: {text!r}')
    return int(text)


def _wait_until(condition: Callable[[], bool], timeout_s: float) -> bool:
    """Poll ``condition`` until it holds (True) or ``timeout_s`` passed (False)."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if condition():
            return True
        time.sleep(0.05)
    return False


def _starts_with_header(fielddef: Any) -> bool:
    """Whether a type's fields (a rosbags ``fielddefs`` entry) start with a std_msgs/Header."""
    return bool(fielddef and fielddef[1] and fielddef[1][0][0] == 'header'
                and fielddef[1][0][1][1] == 'std_msgs/msg/Header')


class BagPlayer(Node):
    """Publishes every message of a bag as raw CDR on its original topic and type."""

    def __init__(self, bag: Path, topics: list[str] | None = None, *,
                 convert_definitions: bool = False, **kwargs) -> None:
        super().__init__('bag_player', **kwargs)
        self.bag = bag
        self.reader = open_bag_reader(bag, colorglove_typestore())
        try:
            self._set_up(topics, convert_definitions)
        except BaseException:
            self.reader.close()
            raise

    def _set_up(self, topics: list[str] | None, convert_definitions: bool) -> None:
        """The topics to play, their publishers and conversions (or a ValueError saying why
        the bag cannot be played as asked)."""
        bag = self.bag
        held = sorted(c.topic for c in self.reader.connections)
        if not held:
            raise ValueError(f'bag {bag} holds no messages')
        self.connections = [c for c in self.reader.connections
                            if not topics or c.topic in topics]
        if not self.connections:
            raise ValueError(f'bag {bag} has none of the topics {topics}; it holds '
                             f'{", ".join(held)}')
        installed = colorglove_typestore()
        # topics recorded with an older (or newer) definition of their type: their bytes are
        # decoded with the recorded definition and re-encoded as the installed one
        self.definition_changes: list[DefinitionChange] = definition_changes(
            self.connections, self.reader.typestore, installed)
        unconvertible = [c for c in self.definition_changes if not c.convertible]
        if unconvertible or (self.definition_changes and not convert_definitions):
            raise BagDefinitionError(
                '; '.join(change.describe() for change in self.definition_changes)
                + ('. Leave them out with --topics' if unconvertible else
                   '. Play with --convert-definitions to convert them field by field, or '
                   'leave them out with --topics'))
        self.converted_types = {change.topic: change.msgtype
                                for change in self.definition_changes}
        self._check_conversions()
        self.qos_by_topic = {c.topic: publisher_qos_for_recorded(
            getattr(c.ext, 'offered_qos_profiles', None) or []) for c in self.connections}
        self.publishers_by_topic = {}
        for c in self.connections:
            try:
                message_type = message_class(c.msgtype)
            except (ImportError, AttributeError) as error:
                raise ValueError(f'{c.topic}: its type {c.msgtype} is not installed here '
                                 '(leave the topic out with --topics)') from error
            self.publishers_by_topic[c.topic] = self.create_publisher(
                message_type, c.topic, self.qos_by_topic[c.topic])
        self.clock_publisher = None
        self._answers = 0                 # outputs of the pace topic so far
        self._answered = threading.Condition()
        # topics whose messages, as published, start with a std_msgs/Header (the stamp right
        # after the CDR prefix): the installed definition for converted topics
        self.stamped_topics = {c.topic for c in self.connections if _starts_with_header(
            (installed if c.topic in self.converted_types else self.reader.typestore)
            .fielddefs.get(c.msgtype))}
        self.new_stamps: dict[bytes, bytes] = {}
        self.stamp_log: TextIO | None = None  # --stamp-log: one line per new stamp
        self.resent = 0                   # frames published again after a --pace-timeout
        self.published = 0                # messages published by play(), over every loop

    def _first_message(self, connection: Any) -> Any:
        """The raw bytes of the first message on ``connection``, or None."""
        for _conn, _timestamp, rawdata in bag_messages(self.reader, [connection], self.bag):
            return rawdata
        return None

    def _check_conversions(self) -> None:
        """Convert the first message of every converted topic now, so a value the installed
        definition cannot hold is refused before anything is published."""
        for connection in self.connections:
            rawdata = (self._first_message(connection)
                       if connection.topic in self.converted_types else None)
            if rawdata is None:
                continue
            try:
                self.installed_bytes(connection.topic, rawdata)
            except BagDefinitionError:     # a value that does not fit: it names the topic
                raise
            except (ValueError, TypeError) as error:   # bytes its recorded definition misreads
                raise BagDefinitionError(f'{connection.topic}: its first message cannot be '
                                         f'converted: {error}') from error

    def installed_bytes(self, topic: str, rawdata: bytes | memoryview) -> bytes:
        """``rawdata`` of ``topic`` laid out for the installed definition of its type
        (converted when it was recorded with another one; :class:`BagDefinitionError` when a
        value cannot be)."""
        msgtype = self.converted_types.get(topic)
        if msgtype is None:
            return bytes(rawdata)
        store = colorglove_typestore()
        try:
            message = convert_message(deserialize_cdr(rawdata, msgtype, self.reader.typestore),
                                      msgtype, store)
        except DefinitionConversionError as error:
            raise BagDefinitionError(f'{topic}: {error}') from error
        return bytes(store.serialize_cdr(message, msgtype))

    def restamped(self, topic: str, data: bytes) -> bytes:
        """``data`` with its header stamp replaced by the publish time (the same new stamp for
        every message recorded with the same stamp); unstamped messages unchanged."""
        if topic not in self.stamped_topics or len(data) < 12:
            return data
        order = '<' if data[1] == 1 else '>'
        old = data[4:12]
        if old not in self.new_stamps:
            if len(self.new_stamps) > 10_000:
                self.new_stamps.clear()
            now_ns = time.time_ns()
            self.new_stamps[old] = struct.pack(f'{order}iI', *divmod(now_ns, 10**9))
            if self.stamp_log is not None:
                sec, nanosec = header_stamp_from_cdr(data)
                self.stamp_log.write(f'{sec * 10**9 + nanosec},{now_ns}\n')
                self.stamp_log.flush()
        # one copy of the (image-sized) rest, not a slice and then a concatenation
        return b''.join((data[:4], self.new_stamps[old], memoryview(data)[12:]))

    def publish_clock(self, clock_topic: str = '/clock') -> None:
        """Also publish each message's bag time on ``clock_topic`` (rosgraph_msgs/Clock)."""
        self.clock_publisher = self.create_publisher(Clock, clock_topic, 10)

    def wait_for_subscribers(self, topic: str, timeout_s: float, count: int = 1) -> bool:
        """Wait until ``topic`` has ``count`` subscribers (so the first frames are not lost)."""
        publisher = self.publishers_by_topic[topic]
        return _wait_until(lambda: publisher.get_subscription_count() >= count, timeout_s)

    def wait_for_publisher(self, topic: str, timeout_s: float) -> bool:
        """Wait until ``topic`` has a publisher (--paced: an output published before the
        player hears it releases no frame, and the next frame waits --pace-timeout)."""
        return _wait_until(lambda: self.count_publishers(topic) >= 1, timeout_s)

    def camera_info_beside(self, image_topic: str) -> str | None:
        """The bag's CameraInfo topic in ``image_topic``'s namespace (``/cam/image_raw`` or
        ``/cam/image_raw/compressed`` -> ``/cam/camera_info``), or None."""
        namespace = image_topic.removesuffix('/compressed').rsplit('/', 1)[0]
        topic = f'{namespace}/camera_info'
        types = {c.topic: c.msgtype for c in self.connections}
        return topic if types.get(topic) == 'sensor_msgs/msg/CameraInfo' else None

    def prime_camera_infos(self) -> list[str]:
        """Publish the first CameraInfo of every CameraInfo topic ahead of the playback (as
        recorded, not restamped): a node keeps the newest CameraInfo and refuses the images
        it gets before one, and a bag may hold a frame's image ahead of its CameraInfo (a
        driver publishes the image first). Returns the topics primed."""
        primed = []
        for connection in self.connections:
            rawdata = (self._first_message(connection)
                       if connection.msgtype == 'sensor_msgs/msg/CameraInfo' else None)
            if rawdata is None:
                continue
            self.publishers_by_topic[connection.topic].publish(
                self.installed_bytes(connection.topic, rawdata))
            primed.append(connection.topic)
        return primed

    def play(self, rate: float, pace_topic: str | None, pace_on: str | None,
             pace_timeout_s: float, restamp: bool = False, pace_resends: int = 0) -> int:
        """Publish all messages; return how many were published."""
        self.new_stamps.clear()       # a loop played again gets new stamps, not the last loop's
        start_wall = time.monotonic()
        first_stamp = None
        count = 0
        for connection, timestamp, rawdata in bag_messages(self.reader, self.connections, self.bag):
            if first_stamp is None:
                first_stamp = timestamp
            if pace_on is None and rate > 0:
                due = start_wall + (timestamp - first_stamp) * 1e-9 / rate
                delay = due - time.monotonic()
                if delay > 0:
                    time.sleep(delay)
            if pace_on is not None and connection.topic == pace_on:
                with self._answered:
                    before = self._answers
            if self.clock_publisher is not None:
                sec, nanosec = divmod(int(timestamp), 10**9)
                self.clock_publisher.publish(Clock(clock=Time(sec=sec, nanosec=nanosec)))
            data = self.installed_bytes(connection.topic, rawdata)
            if restamp:
                data = self.restamped(connection.topic, data)
            self.publishers_by_topic[connection.topic].publish(data)
            count += 1
            self.published += 1
            if pace_on is not None and connection.topic == pace_on:
                first_sent = last_sent = time.monotonic()
                copies = 1
                while (not self._wait_for_answers(before + 1, pace_timeout_s)
                       and copies <= pace_resends):
                    self.publishers_by_topic[connection.topic].publish(data)
                    last_sent = time.monotonic()
                    self.resent += 1
                    copies += 1
                if copies > 1:
                    # a frame that was only slow is answered once per copy: a late answer
                    # must not release the next frame early (into an image queue of depth 1
                    # whose frame is not taken yet, where it would replace that frame). The
                    # last copy's answer is due as long after it as the first answer took.
                    took = time.monotonic() - first_sent
                    due = last_sent + took - time.monotonic()
                    self._wait_for_answers(before + copies, max(due, 0.0) + pace_timeout_s)
        return count

    def output_answered(self) -> None:
        """An output of the pace topic arrived (the pace subscription's callback)."""
        with self._answered:
            self._answers += 1
            self._answered.notify_all()

    def _wait_for_answers(self, count: int, timeout_s: float) -> bool:
        """Wait until ``count`` outputs have arrived in all; False after ``timeout_s``."""
        with self._answered:
            return self._answered.wait_for(lambda: self._answers >= count, timeout_s)

    def close(self) -> None:
        """Close the bag."""
        self.reader.close()


def main(argv: list[str] | None = None) -> int:
    """``colorglove_play_bag BAG [--rate R | --paced]``."""
    parser = tool_parser(__doc__.splitlines()[0], json_help=None)
    parser.add_argument('bag', type=Path, help='rosbag2 folder (sqlite3 or MCAP)')
    parser.add_argument('--topics', nargs='*', help='only these topics (default: all)')
    parser.add_argument('--convert-definitions', action='store_true',
                        help='play topics recorded with another definition of their message '
                        'type (an older colorglove_msgs) by converting each message field by '
                        'field by name; without it such a bag is refused, naming the fields')
    parser.add_argument('--wait-for', nargs='+', default=[], metavar='TOPIC=COUNT',
                        type=topic_argument('COUNT', _count),
                        help='also wait (up to --wait-subscribers) until each TOPIC of the bag '
                        'has COUNT subscribers before starting, e.g. a second camera\'s image '
                        'and CameraInfo topics')
    for name, (kind, default, text) in PLAYBACK_OPTIONS.items():
        if kind is bool:
            parser.add_argument(f'--{name}', action='store_true', help=text)
        else:
            parser.add_argument(f'--{name}', type=kind, default=default, help=text)
    args, ros_args = parser.parse_known_args(argv)
    if not args.bag.exists():
        print(f'colorglove_play_bag: no bag at {args.bag}', file=sys.stderr)
        return 2
    if args.stamp_log and not args.restamp:
        print('colorglove_play_bag: --stamp-log needs --restamp', file=sys.stderr)
        return 2
    keep_freed_buffers()     # the frames' buffers, as in the nodes (ros.heap_tuning)
    rclpy.init(args=ros_args)
    player = None
    executor = rclpy.executors.SingleThreadedExecutor()
    spinner = threading.Thread(target=executor.spin, daemon=True)
    try:
        try:
            player = BagPlayer(args.bag, args.topics,
                               convert_definitions=args.convert_definitions)
        except (BagError, ValueError) as error:     # a bag it cannot play as asked: say why
            print(f'colorglove_play_bag: {error}', file=sys.stderr, flush=True)
            return 2
        for change in player.definition_changes:
            print(f'colorglove_play_bag: converting {change.describe()}', file=sys.stderr,
                  flush=True)
        executor.add_node(player)
        if args.stamp_log:
            player.stamp_log = open(args.stamp_log, 'w', encoding='utf-8')  # noqa: SIM115
            player.stamp_log.write(STAMP_LOG_HEADER + '\n')
        if args.paced:
            output_type = message_class('std_msgs/msg/String')
            player.create_subscription(output_type, args.pace_topic,
                                       lambda _msg: player.output_answered(), 10)
        spinner.start()
        unknown = [topic for topic, _ in args.wait_for
                   if topic not in player.publishers_by_topic]
        if unknown:
            print(f'colorglove_play_bag: --wait-for: the bag plays no topic {unknown}',
                  file=sys.stderr, flush=True)
            return 2
        waits = []
        if args.pace_on in player.publishers_by_topic:
            # the image's subscribers and its CameraInfo's: a node that gets images before it
            # is matched to their CameraInfo answers them 'waiting for CameraInfo'
            waits.append((args.pace_on, args.min_subscribers))
            camera_info = player.camera_info_beside(args.pace_on)
            if camera_info is not None:
                waits.append((camera_info, args.min_info_subscribers))
        waits += args.wait_for
        if waits:
            for topic, wanted in waits:
                if not player.wait_for_subscribers(topic, args.wait_subscribers, wanted):
                    seen = player.publishers_by_topic[topic].get_subscription_count()
                    print(f'colorglove_play_bag: warning: {topic} has {seen} of {wanted} '
                          f'subscribers after {args.wait_subscribers:g} s; playing anyway',
                          file=sys.stderr, flush=True)
            if args.paced and not player.wait_for_publisher(args.pace_topic,
                                                            args.wait_subscribers):
                print(f'colorglove_play_bag: warning: no publisher on {args.pace_topic} after '
                      f'{args.wait_subscribers:g} s; each frame waits --pace-timeout',
                      file=sys.stderr, flush=True)
            time.sleep(args.settle)
        player.prime_camera_infos()
        if args.clock:
            player.publish_clock()
        while True:
            started = time.monotonic()
            count = player.play(args.rate, args.pace_topic if args.paced else None,
                                args.pace_on if args.paced else None, args.pace_timeout,
                                args.restamp, args.pace_resends if args.paced else 0)
            elapsed = time.monotonic() - started
            resent = f' ({player.resent} frames resent)' if player.resent else ''
            print(f'published {count} messages in {elapsed:.1f} s{resent}', flush=True)
            if not args.loop:
                break
        time.sleep(args.linger)
    except KeyboardInterrupt:
        pass
    except (BagError, BagDefinitionError) as error:   # what was published stays published
        print(f'colorglove_play_bag: {error} ({player.published} messages published before)',
              file=sys.stderr, flush=True)
        return 1
    finally:
        executor.shutdown()
        if spinner.is_alive():
            spinner.join(timeout=5.0)
        if player is not None:
            if player.stamp_log is not None:
                player.stamp_log.close()
            player.close()
            player.destroy_node()
        rclpy.try_shutdown()
    return 0


if __name__ == '__main__':
    sys.exit(main())
