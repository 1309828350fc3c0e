"""Seeded fuzzing of the node boundaries: a few hundred bad messages per input topic (camera
images, observations, candidates) into segmentation_node, lookup_node and ik_node running in
one process over DDS on loopback. No callback may raise (a node would exit), no JointState
may carry the stamp of an invalid input, and valid frames are tracked again within 2 frames."""
from __future__ import annotations

import copy
from array import array
from collections.abc import Callable

import numpy as np
import pytest
from colorglove_msgs.msg import HandObservation, HandPoseCandidates
from message_samples import set_blobs
from node_fixtures import NodeAssets, header, ik_node, lookup_node, running, segmentation_node
from sensor_msgs.msg import Image, JointState
from std_msgs.msg import String

from colorglove_ros.ros.image import array_to_image

pytestmark = [pytest.mark.dds, pytest.mark.usefixtures('isolated_ros_domain')]

MESSAGES_PER_TOPIC = 200
VALID_EVERY = 25            # after this many bad messages, two valid frames must track
SEED = 16


# good_rgb, good_observation and good_candidates: session fixtures of test/ros/conftest.py
# (every message is copied and stamped anew before it is sent)


# ------------------------------------------------------------------------ bad inputs
def _raw_image(width: int, height: int, encoding: str, step: int, data: bytes) -> Image:
    msg = Image(width=width, height=height, encoding=encoding, step=step)
    msg.data = data
    return msg


def bad_images(rng: np.random.Generator, count: int) -> list[Image]:
    """Images a camera, a bag or a hostile publisher might send: broken layouts, odd
    encodings and sizes, noise, and hand-sized patches of random or block colours."""
    def noise_patch() -> Image:
        frame = np.zeros((480, 640, 3), np.uint8)
        side = int(rng.integers(80, 220))
        y, x = rng.integers(0, 480 - side), rng.integers(0, 640 - side)
        frame[y:y + side, x:x + side] = rng.integers(0, 256, (side, side, 3))
        return array_to_image(frame, 'rgb8')

    def block_patch() -> Image:
        frame = np.zeros((480, 640, 3), np.uint8)
        blocks = int(rng.integers(2, 9))
        cell = int(rng.integers(8, 30))
        patch = rng.integers(0, 256, (blocks, blocks, 3)).astype(np.uint8)
        patch = np.kron(patch, np.ones((cell, cell, 1), np.uint8))
        y, x = 240 - patch.shape[0] // 2, 320 - patch.shape[1] // 2
        frame[y:y + patch.shape[0], x:x + patch.shape[1]] = patch
        return array_to_image(frame, 'rgb8')

    makers: list[Callable[[], Image]] = [
        noise_patch, block_patch,
        lambda: array_to_image(rng.integers(0, 256, (480, 640, 3), np.uint8), 'rgb8'),
        lambda: _raw_image(640, 480, 'rgb8', 1920, bytes(100)),                   # short data
        lambda: _raw_image(640, 480, 'rgb8', 100, bytes(640 * 480 * 3)),          # short step
        lambda: _raw_image(0, 480, 'rgb8', 0, b''),
        lambda: _raw_image(640, 0, 'bgr8', 1920, b''),
        lambda: _raw_image(2 ** 31, 2, 'rgb8', 3 * 2 ** 31, bytes(64)),
        lambda: _raw_image(640, 480, str(rng.choice(['yuv422', 'jpeg', '', 'rgb9'])), 1920,
                           bytes(640 * 480 * 3)),
        lambda: array_to_image(np.zeros((480, 640), np.uint8), 'mono8'),
        lambda: array_to_image(rng.integers(0, 256, (int(rng.integers(1, 12)),
                                                     int(rng.integers(1, 12)), 3), np.uint8),
                               'rgb8'),
        lambda: array_to_image(rng.integers(0, 256, (1, 5000, 3), np.uint8), 'bgr8'),
        lambda: array_to_image(rng.integers(0, 65535, (120, 160, 4), np.uint16), 'rgba16'),
    ]
    return [makers[i % len(makers)]() for i in range(count)]


def bad_observations(rng: np.random.Generator, good: HandObservation, count: int
                     ) -> list[HandObservation]:
    """The good observation spoiled in one field each (as reported in issue 16)."""
    def spoil(msg: HandObservation) -> None:
        kind = int(rng.integers(0, 15))
        value = float(rng.choice([np.nan, np.inf, -np.inf, 1e155, 1.34e154, 0.0, -1.0, 1e30]))
        if kind == 0:
            msg.crop_scale = value
        elif kind == 1:
            msg.crop_offset_x, msg.crop_offset_y = value, float(rng.normal(0, 1e6))
        elif kind == 2:
            msg.blob_colors[int(rng.integers(len(msg.blob_colors)))] = int(
                rng.choice([0, 11, 200, 255]))
        elif kind == 3:
            msg.blob_centroids[0] = float(rng.choice([np.nan, np.inf, -1e9, 1e9]))
        elif kind == 4:
            msg.blob_pixel_counts[0] = int(rng.choice([0, 4_000_000_000]))
        elif kind == 5:
            msg.image_width, msg.image_height = 0, 0
        elif kind == 6:
            msg.tiny_labels = [int(v) for v in rng.integers(0, 256, int(rng.integers(0, 3000)))]
        elif kind == 7:
            msg.tiny_labels = [0] * 1600
        elif kind == 8:
            msg.glove_pixel_count = 4_000_000_000
        elif kind == 9:
            msg.image_width, msg.image_height = 320, 240
        elif kind == 10:
            set_blobs(msg, [(int(rng.integers(1, 11)), float(rng.uniform(0, 640)),
                             float(rng.uniform(0, 480)), 20) for _ in range(2000)])
        elif kind == 11:
            msg.tiny_labels = [11] * 1600
        elif kind == 12:
            msg.image_width = 2 ** 32 - 1
        elif kind == 13:        # the parallel blob arrays of different lengths
            which = ('blob_colors', 'blob_centroids', 'blob_pixel_counts')[int(rng.integers(3))]
            values = getattr(msg, which)
            setattr(msg, which, values[:-1] if rng.integers(2) else values + values[:1])
        else:
            msg.crop_scale = float(rng.uniform(1e-300, 1e-200))

    out = []
    for _ in range(count):
        msg = copy.deepcopy(good)
        spoil(msg)
        out.append(msg)
    # the one from the issue: 50,000 blobs (sent once; it is about 1 MB)
    set_blobs(out[-1], [(1 + i % 10, float(i % 640), float(i % 480), 12)
                        for i in range(50_000)])
    return out


def bad_candidates(rng: np.random.Generator, good: HandPoseCandidates, count: int
                   ) -> list[HandPoseCandidates]:
    """The good candidates spoiled in one field each (as reported in issue 16)."""
    def spoil(msg: HandPoseCandidates) -> None:
        kind = int(rng.integers(0, 18))
        if kind == 0:
            msg.blended_pose[int(rng.integers(26))] = float(rng.choice([np.nan, np.inf]))
        elif kind == 1:
            msg.blended_pose = list(msg.blended_pose)[:int(rng.integers(0, 26))]
        elif kind == 2:
            msg.constraint_patch_ids[0] = int(rng.integers(20, 65535))
        elif kind == 3:
            msg.constraint_vertices[0] = int(rng.integers(10_000, 2 ** 32))
        elif kind == 4:
            msg.constraint_tiny_xy[0] = float(rng.choice([np.nan, np.inf, 1e30]))
        elif kind == 5:
            msg.candidate_indices, msg.candidate_poses = [], []
            msg.candidate_distances, msg.candidate_weights = [], []
        elif kind == 6:
            for field in ('patch_ids', 'colors', 'vertices', 'tiny_xy', 'pixel_counts'):
                setattr(msg, f'constraint_{field}', [])
        elif kind == 7:
            msg.observation.crop_scale = float('nan')
        elif kind == 8:      # part of the hand just in front of the camera plane
            msg.blended_pose = [-1.5, -1.5, 0.1, 1.18, 0.29, 1.13] + [0.0] * 20
        elif kind == 9:      # behind the camera
            msg.blended_pose[2] = float(rng.uniform(-2.0, 0.0))
        elif kind == 10:
            msg.finger_std = [float(v) for v in rng.normal(0, 1, int(rng.integers(1, 30)))]
        elif kind == 11:
            msg.candidate_poses[:26] = array('d', [float('nan')] * 26)
        elif kind == 12:
            msg.candidate_weights[0] = float('nan')
        elif kind == 13:
            msg.observation.hand_found = False
        elif kind == 14:
            msg.constraint_colors[0] = int(rng.choice([0, 11, 255]))
        elif kind == 15:     # arrays of one candidate or constraint out of step
            msg.candidate_poses = msg.candidate_poses[:-int(rng.integers(1, 26))]
        elif kind == 16:
            msg.constraint_tiny_xy = msg.constraint_tiny_xy[:-1]
        else:
            msg.blended_pose[2] = float(rng.uniform(20.0, 1e6))

    out = []
    for _ in range(count):
        msg = copy.deepcopy(good)
        spoil(msg)
        out.append(msg)
    # the message of the issue: blended pose, no candidates, no constraints, crop NaN
    out[-1] = HandPoseCandidates(
        hand_found=True, dof_names=list(good.dof_names),
        blended_pose=[0.0, 0.0, 0.5] + [0.0] * 23,
        observation=HandObservation(hand_found=True, crop_scale=float('nan')))
    return out


# ------------------------------------------------------------------------ the fuzz run
def _stamp(msg) -> tuple[int, int]:
    return msg.header.stamp.sec, msg.header.stamp.nanosec


def _set_stamp(msg, index: int) -> None:
    """Stamp ``index`` (distinct over the whole run): 1 ms apart from 1000 s on."""
    msg.header = header(1000 + index // 1000, (index % 1000) * 1_000_000)
    if isinstance(msg, HandPoseCandidates):
        msg.observation.header = msg.header


def _fuzz(h, topic: str, msg_type, bad: list, good_factory: Callable[[], object],
          status: list, joints: list, first_index: int) -> dict[str, object]:
    """Send ``bad`` messages (and, after every ``VALID_EVERY``, two valid ones) one at a time,
    each answered by one ik_node status line; return what came back."""
    pub = h.publisher(msg_type, topic)
    bad_stamps, recovered, index = set(), [], first_index
    bad_by_stamp: dict[tuple[int, int], int] = {}
    first_status = len(status)

    def send(msg) -> None:
        nonlocal index
        index += 1
        _set_stamp(msg, index)
        count = len(status)
        pub.publish(msg)
        assert h.spin_until(lambda: len(status) > count, 30.0), \
            f'no status for message {index} on {topic}'

    for number, msg in enumerate(bad, start=1):
        send(msg)
        bad_stamps.add(_stamp(msg))
        bad_by_stamp[_stamp(msg)] = number - 1
        if number % VALID_EVERY == 0 or number == len(bad):
            tracked_before = len(joints)
            for _ in range(2):
                send(good_factory())
            recovered.append(len(joints) > tracked_before)
    h.settle(0.3)
    false = [(m.header.stamp.sec, m.header.stamp.nanosec) for m in joints
             if _stamp(m) in bad_stamps]
    return {'false': false, 'recovered': recovered, 'bad': bad_by_stamp,
            'statuses': [m.data for m in status[first_status:]]}


@pytest.mark.slow
def test_fuzz_node_boundaries(node_assets: NodeAssets, good_rgb: np.ndarray,
                              good_observation: HandObservation,
                              good_candidates: HandPoseCandidates) -> None:
    rng = np.random.default_rng(SEED)
    factories = [segmentation_node(node_assets), lookup_node(node_assets),
                 ik_node(node_assets.database, publish_overlay=False)]
    runs = {}
    with running(*factories) as h:    # an exception in any callback fails the test here
        status = h.collect(String, 'hand/tracking_status')
        joints = h.collect(JointState, 'hand/joint_states')
        runs['images'] = _fuzz(h, 'camera/image_raw', Image,
                               bad_images(rng, MESSAGES_PER_TOPIC),
                               lambda: array_to_image(good_rgb, 'rgb8'), status, joints, 0)
        runs['observations'] = _fuzz(h, 'hand/observation', HandObservation,
                                     bad_observations(rng, good_observation, MESSAGES_PER_TOPIC),
                                     lambda: copy.deepcopy(good_observation), status, joints,
                                     100_000)
        runs['candidates'] = _fuzz(h, 'hand/pose_candidates', HandPoseCandidates,
                                   bad_candidates(rng, good_candidates, MESSAGES_PER_TOPIC),
                                   lambda: copy.deepcopy(good_candidates), status, joints,
                                   200_000)
    for topic, run in runs.items():
        reasons = sorted({s.split(':')[1].strip()[:40] for s in run['statuses']
                          if s.startswith('no hand')})
        print(f'{topic}: {len(run["false"])} false JointStates (bad messages '
              f'{[run["bad"][k] for k in run["false"]]}), recovered '
              f'{sum(run["recovered"])}/{len(run["recovered"])}; reasons {reasons[:8]}')
    for topic, run in runs.items():
        assert not run['false'], (topic, len(run['false']))
        assert all(run['recovered']), (topic, run['recovered'])
