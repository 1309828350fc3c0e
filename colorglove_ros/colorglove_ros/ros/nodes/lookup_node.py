"""lookup_node: ``HandObservation`` -> ``HandPoseCandidates`` (Hamming search over learned
binary codes, exact re-rank, Gaussian-weighted blend of the nearest database poses).

The camera that turns the crop into a depth is the newest ``camera/camera_info``'s
(``use_camera_info``, the default) or camera 0 of ``calibration_file``; an observation whose
image size or frame_id does not match it is refused ('camera: ...'). The distance gate
``max_image_distance`` can be changed at run time; health goes to ``/diagnostics``."""
from __future__ import annotations

import sys
import time
import traceback
from dataclasses import replace
from typing import Any

from colorglove_msgs.msg import HandObservation, HandPoseCandidates
from rclpy.node import Node

from colorglove_ros.core.camera import load_calibration
from colorglove_ros.core.lookup.database import (
    check_hand_length,
    load_database,
    start_reading_into_page_cache,
)
from colorglove_ros.core.lookup.search import DEFAULT_THREADS, PoseLookup
from colorglove_ros.core.lookup.types import LookupResult
from colorglove_ros.core.pipeline import DEFAULT_MAX_IMAGE_DISTANCE, NoHand, StageLimits, look_up
from colorglove_ros.core.segmentation.crop import TinyCrop
from colorglove_ros.core.validation import InvalidInputError
from colorglove_ros.paths import resolve_path
from colorglove_ros.ros.conversions import candidates_to_msg, crop_from_observation_msg
from colorglove_ros.ros.diagnostics import FrameStats, upstream
from colorglove_ros.ros.message_checks import checked_observation_msg
from colorglove_ros.ros.nodes.common import (
    LATEST_ONLY,
    declare,
    declare_calibration_file,
    declare_database,
    declare_frame_camera,
    declare_opencv_threads,
    run_node,
    startup_errors,
)
from colorglove_ros.ros.nodes.diagnostics_publisher import DiagnosticsPublisher
from colorglove_ros.ros.nodes.live_parameters import Apply, LiveParameters


class LookupNode(Node):
    """Looks every observation up in the pose database."""

    def __init__(self, **kwargs) -> None:
        super().__init__('lookup', **kwargs)
        declare_opencv_threads(self)
        calibration_file = declare_calibration_file(
            self, 'camera calibration YAML (camera 0 is the lookup camera)')
        num_candidates = declare(self, 'num_candidates', 300,
                                 'entries re-ranked with the exact distance', 1, 100000)
        num_neighbors = declare(self, 'num_neighbors', 10, 'nearest entries blended', 1, 300)
        threads = declare(self, 'search_threads', DEFAULT_THREADS,
                          'threads of the re-rank: 1 runs it in the callback, 2 shares its two '
                          'gathers between the callback and a worker thread (more CPU in all, '
                          'and a wait for the worker when no core is free; the same results)',
                          1, 2)
        self.live = LiveParameters(self)
        self.limits = StageLimits(max_image_distance=self.live.declare(
            'max_image_distance', DEFAULT_MAX_IMAGE_DISTANCE,
            'nearest database image farther than this (tiny pixels) from the observation: no '
            'hand (glove-coloured clutter or noise resembles no hand pose)',
            self._check_max_image_distance, 0.0, 1000.0))
        self.finger_evidence = declare(
            self, 'finger_evidence', True, 'blend each finger from the neighbours whose '
            'patches on it match the observed blobs (false: one weight per entry, the paper)')
        with startup_errors('lookup_node'):
            path = declare_database(self)
            calibration = load_calibration(resolve_path(calibration_file))
            started = time.perf_counter()
            database = load_database(path)
            # the memory-mapped arrays mapped into this process and read into the page
            # cache in the background: else the first lookups wait for page faults (and, from a
            # cold cache, for random disk reads)
            self.page_cache_reader = start_reading_into_page_cache(path, database)
            check_hand_length(database.build, calibration.hand_length_m, calibration_file, path)
            self.lookup = PoseLookup(database, num_candidates, num_neighbors, threads)
        self.frame_camera = declare_frame_camera(self, calibration.primary)
        self.stats = FrameStats({'camera': self.frame_camera.refused})
        self.diagnostics = DiagnosticsPublisher(self, 'lookup', calibration.primary.frame_id,
                                                self.stats)
        self.publisher = self.create_publisher(HandPoseCandidates, 'hand/pose_candidates', 10)
        self.create_subscription(HandObservation, 'hand/observation', self.on_observation,
                                 LATEST_ONLY)
        self.get_logger().info(f'loaded {len(self.lookup.db)} database entries from {path} '
                               f'in {time.perf_counter() - started:.1f} s; subscribed')

    def _check_max_image_distance(self, value: Any) -> Apply:
        """The distance gate's new value (its range is the parameter's)."""
        def apply() -> None:
            self.limits = replace(self.limits, max_image_distance=float(value))
        return apply

    def _look_up(self, observation: HandObservation) -> LookupResult | NoHand:
        """The lookup of an observation with a hand (``core.pipeline.look_up``), or 'no hand'
        for one that fails its message checks."""
        camera = self.frame_camera.camera_for(observation.image_width, observation.image_height,
                                              observation.header.frame_id)
        if isinstance(camera, NoHand):
            return camera
        try:
            tiny, blobs = checked_observation_msg(observation, (camera.width, camera.height))
        except InvalidInputError as exc:
            return NoHand(f'lookup: invalid observation: {exc}', warn=True)
        return look_up(self.lookup, TinyCrop(tiny, crop_from_observation_msg(observation)),
                       camera, blobs if self.finger_evidence else None, self.limits)

    def on_observation(self, observation: HandObservation) -> None:
        """Look one observation up and publish the candidates, or a 'no hand' message with
        the reason. No message stops the node."""
        started = time.perf_counter()
        latency_s = self.diagnostics.latency_s(observation.header.stamp)
        if not observation.hand_found:
            self.stats.no_hand(upstream(observation.status), latency_s=latency_s)
            self.publisher.publish(candidates_to_msg(observation, None))
            return
        try:
            result = self._look_up(observation)
        except Exception as exc:   # last line of defence: a message must never stop the node
            self.get_logger().error(f'lookup failed: {exc!r}\n{traceback.format_exc()}',
                                    throttle_duration_sec=1.0)
            self.stats.no_hand(f'lookup failed: {exc!r}', error=True, latency_s=latency_s)
            self.publisher.publish(candidates_to_msg(observation, None,
                                                  status=f'lookup failed: {exc!r}'))
            return
        elapsed_ms = 1e3 * (time.perf_counter() - started)
        if isinstance(result, NoHand):
            if result.warn:
                self.get_logger().warn(result.reason, throttle_duration_sec=1.0)
            self.stats.no_hand(result.reason, result.warn, latency_s)
            # the time of a lookup that ran (its result refused), none of one that failed
            self.publisher.publish(candidates_to_msg(
                observation, None, status=result.reason,
                lookup_time_ms=elapsed_ms if result.partial is not None else 0.0))
            return
        self.stats.hand(latency_s)
        self.publisher.publish(candidates_to_msg(observation, result, lookup_time_ms=elapsed_ms))


def main(args: list[str] | None = None) -> int:
    """Entry point of ``lookup_node``."""
    return run_node(LookupNode, args)


if __name__ == '__main__':
    sys.exit(main())
