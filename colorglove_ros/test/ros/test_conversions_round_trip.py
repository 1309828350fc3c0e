"""Message adapters (ros/conversions.py) round-trip: what x_to_msg writes, x_from_msg reads back,
built by hand with no rclpy.init; importing them stays light (no trimesh, sklearn)."""
from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest
from std_msgs.msg import Header

from colorglove_ros.core.camera import PinholeCamera
from colorglove_ros.core.hand.model import NUM_DOFS
from colorglove_ros.core.lookup.types import LookupResult, ProjectionConstraints
from colorglove_ros.core.segmentation.crop import CropTransform
from colorglove_ros.core.segmentation.types import Blob, Observation
from colorglove_ros.ros.conversions import (
    blobs_from_observation_msg,
    camera_from_camera_info_msg,
    camera_observation_from_msg,
    camera_to_camera_info_msg,
    candidate_arrays_from_msg,
    candidates_to_msg,
    crop_from_observation_msg,
    observation_to_msg,
    pose_from_msgs,
    pose_prior_from_candidates_msg,
    pose_to_joint_state_msg,
    pose_to_wrist_pose_msg,
    tiny_labels_from_observation_msg,
)

HEADER = Header(frame_id='usb_cam_optical')


def random_pose(seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    pose = rng.uniform(-0.4, 0.4, NUM_DOFS)
    pose[:3] = [0.05, -0.02, 0.6]
    return pose


@pytest.mark.parametrize('seed', range(5))
def test_pose_round_trips_through_joint_state_and_wrist_pose(seed: int) -> None:
    pose = random_pose(seed)
    back = pose_from_msgs(pose_to_joint_state_msg(pose, HEADER), pose_to_wrist_pose_msg(pose,
                                                                                      HEADER))
    np.testing.assert_allclose(back, pose, atol=1e-12)


@pytest.mark.parametrize('distortion', [np.zeros(5), np.array([-0.1, 0.02, 0.001, 0.0, 0.0]),
                                        np.arange(8) * 0.01, np.array([0.05, -0.01, 0.0, 0.0])])
def test_camera_round_trips_through_camera_info(distortion: np.ndarray) -> None:
    camera = PinholeCamera(1280, 720, 905.0, 903.0, 641.5, 362.5, distortion,
                           frame_id='usb_cam_optical')
    back = camera_from_camera_info_msg(camera_to_camera_info_msg(camera, HEADER))
    assert (back.width, back.height, back.fx, back.fy, back.cx, back.cy) == \
        (1280, 720, 905.0, 903.0, 641.5, 362.5)
    assert back.distortion_model == camera.distortion_model and back.frame_id == 'usb_cam_optical'
    np.testing.assert_array_equal(back.distortion, distortion)


def test_observation_round_trips() -> None:
    tiny = np.random.default_rng(1).integers(0, 11, (40, 40)).astype(np.uint8)
    blobs = [Blob(3, 310.5, 200.25, 90), Blob(7, 330.0, 215.0, 250)]
    observation = Observation(True, '', 640, 480, tiny, CropTransform(4.5, 220.0, 120.0), blobs,
                              glove_pixel_count=1234, timings_ms={'total': 6.5})
    msg = observation_to_msg(observation, HEADER)
    np.testing.assert_array_equal(tiny_labels_from_observation_msg(msg), tiny)
    crop = crop_from_observation_msg(msg)
    assert (crop.scale, crop.offset_x, crop.offset_y) == (4.5, 220.0, 120.0)
    back = blobs_from_observation_msg(msg)
    order = [1, 0]                                    # the message sorts blobs by size
    np.testing.assert_array_equal(back.color, [blobs[i].color_label for i in order])
    np.testing.assert_allclose(back.centroid_px, [[blobs[i].centroid_x, blobs[i].centroid_y]
                                         for i in order])
    np.testing.assert_array_equal(back.pixel_count, [blobs[i].pixel_count for i in order])
    assert camera_observation_from_msg(msg).blobs.centroid_px.shape == (2, 2)
    assert msg.processing_time_ms == 6.5
    assert not camera_observation_from_msg(msg).cut_by_border
    observation.cut_by_border = True
    assert camera_observation_from_msg(observation_to_msg(observation, HEADER)).cut_by_border


def _lookup_result(k: int = 3, m: int = 5) -> LookupResult:
    rng = np.random.default_rng(2)
    constraints = ProjectionConstraints(
        patch_ids=np.arange(m), colors=np.arange(1, m + 1), vertices=np.arange(m) * 7,
        tiny_xy=rng.uniform(0, 39, (m, 2)).astype(np.float32),
        pixel_counts=np.arange(m) + 3.0)
    return LookupResult(indices=np.arange(k) * 1000 + 7, distances=np.linspace(1, 2, k),
                        weights=np.full(k, 1 / k),
                        poses=np.stack([random_pose(i) for i in range(k)]),
                        blended=random_pose(9), constraints=constraints, num_candidates=300,
                        finger_std=np.full(20, 0.05))


def test_candidates_round_trip_into_the_ik_prior() -> None:
    result = _lookup_result()
    constraints = result.constraints
    observation = observation_to_msg(Observation(True, '', 640, 480), HEADER)
    msg = serialized_round_trip(candidates_to_msg(observation, result))
    prior = pose_prior_from_candidates_msg(msg)
    np.testing.assert_array_equal(prior.q_blend, result.blended)
    np.testing.assert_array_equal(prior.finger_std, result.finger_std)
    assert prior.image_distance == result.distances[0]
    for name in ('patch_ids', 'colors', 'vertices', 'tiny_xy', 'pixel_counts'):
        np.testing.assert_array_equal(getattr(prior.constraints, name),
                                      getattr(constraints, name))
    # the candidates travel as parallel arrays, read back with no loss
    back = candidate_arrays_from_msg(msg)
    for name in ('indices', 'poses', 'distances', 'weights'):
        np.testing.assert_array_equal(back[name], getattr(result, name))
    assert back['poses'].shape == (3, NUM_DOFS)


def serialized_round_trip(msg):
    """``msg`` through CDR serialisation, as a subscriber receives it."""
    from rclpy.serialization import deserialize_message, serialize_message

    return deserialize_message(serialize_message(msg), type(msg))


@pytest.mark.parametrize('spoil, message', [
    (lambda m: setattr(m, 'candidate_poses', m.candidate_poses[:-1]), 'candidate_poses'),
    (lambda m: setattr(m, 'candidate_weights', m.candidate_weights[:-1]), 'candidate_weights'),
    (lambda m: m.candidate_distances.__setitem__(0, -1.0), 'candidate_distances'),
    (lambda m: setattr(m, 'constraint_tiny_xy', m.constraint_tiny_xy[:-1]),
     'constraint_tiny_xy'),
    (lambda m: setattr(m, 'constraint_vertices', m.constraint_vertices[:-1]),
     'constraint_vertices'),
    (lambda m: m.constraint_colors.__setitem__(0, 0), 'constraint_colors'),
    (lambda m: m.constraint_patch_ids.__setitem__(0, 20), 'constraint_patch_ids'),
    (lambda m: m.constraint_pixel_counts.__setitem__(0, 10**6), 'constraint_pixel_counts'),
    (lambda m: m.candidate_poses.__setitem__(30, float('nan')), 'candidate_poses'),
    (lambda m: m.candidate_poses.__setitem__(26 + 3, 1e4), r'candidate_poses\[1\].*rotation'),
])
def test_checked_candidates_msg_refuses_arrays_out_of_step(spoil, message) -> None:
    """The parallel arrays must hold one value (or pose, or (x, y)) per candidate or
    constraint, each within its range; a spoiled array is refused naming it as the message
    does."""
    from colorglove_ros.core.validation import InvalidInputError
    from colorglove_ros.ros.message_checks import checked_candidates_msg

    observation = observation_to_msg(Observation(
        True, '', 640, 480, np.ones((40, 40), np.uint8), CropTransform(4.5, 220.0, 120.0),
        [Blob(3, 310.5, 200.25, 90)], glove_pixel_count=90), HEADER)
    good = candidates_to_msg(observation, _lookup_result())
    np.testing.assert_array_equal(checked_candidates_msg(good, 100)[0], good.blended_pose)
    bad = serialized_round_trip(good)
    spoil(bad)
    with pytest.raises(InvalidInputError, match=message):
        checked_candidates_msg(bad, 100)


def test_importing_the_adapters_is_light() -> None:
    code = ('import sys, colorglove_ros.ros.conversions; '
            'print(sorted(m for m in ("trimesh", "sklearn", "moderngl") if m in sys.modules))')
    out = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == '[]'


def test_checked_observation_returns_the_blobs_it_checked() -> None:
    """lookup_node and ik_node convert an observation's blobs once: the check returns them as
    ``blobs_from_observation_msg`` gives them, and the IK's observation takes them as given."""
    from colorglove_ros.core.validation import InvalidObservationError
    from colorglove_ros.ros.message_checks import checked_candidates_msg, checked_observation_msg

    observation = observation_to_msg(Observation(
        True, '', 640, 480, np.ones((40, 40), np.uint8), CropTransform(4.5, 220.0, 120.0),
        [Blob(3, 310.5, 200.25, 90), Blob(7, 100.0, 50.5, 12)], glove_pixel_count=102), HEADER)
    tiny, blobs = checked_observation_msg(observation, (640, 480))
    expected = blobs_from_observation_msg(observation)
    assert tiny.shape == (40, 40)
    for field in ('color', 'centroid_px', 'pixel_count'):
        got, want = getattr(blobs, field), getattr(expected, field)
        assert got.dtype == want.dtype and np.array_equal(got, want)
    q, same = checked_candidates_msg(candidates_to_msg(observation, _lookup_result()), 100)
    assert len(q) == NUM_DOFS and np.array_equal(same.centroid_px, expected.centroid_px)
    assert camera_observation_from_msg(observation, blobs).blobs is blobs
    observation.blob_centroids[2] = float('nan')           # blob 1's x
    with pytest.raises(InvalidObservationError, match='blob centroid must be finite'):
        checked_observation_msg(observation)


def test_stamp_key_is_exact_where_float_seconds_are_not() -> None:
    """Two stamps a nanosecond apart late in the epoch: their float seconds are equal, their
    keys (what pairs a frame's messages across topics) are not."""
    from builtin_interfaces.msg import Time

    from colorglove_ros.ros.conversions import stamp_key, stamp_to_seconds

    first, second = Time(sec=1_796_236_811, nanosec=574_676_832), Time(sec=1_796_236_811,
                                                                       nanosec=574_676_833)
    assert stamp_to_seconds(first) == stamp_to_seconds(second)
    assert stamp_key(first) == (1_796_236_811, 574_676_832) != stamp_key(second)
    assert stamp_key(Time(sec=1_796_236_811, nanosec=574_676_832)) == stamp_key(first)


@pytest.mark.parametrize('seed', range(6))
def test_blobs_travel_as_parallel_arrays_bit_for_bit(seed: int) -> None:
    """The observation's blobs go into the message as three flat arrays (colours, (x, y) pairs,
    pixel counts), largest first, and come back as the same bits in the dtypes the IK takes
    (int64, float64, float64), writable and contiguous, through a serialised message too."""
    from colorglove_msgs.msg import HandObservation
    from rclpy.serialization import deserialize_message, serialize_message

    rng = np.random.default_rng(seed)
    count = int(rng.integers(0, 40))
    blobs = [Blob(int(rng.integers(1, 11)), float(rng.uniform(-0.5, 639.5)),
                  float(rng.uniform(-0.5, 479.5)), int(rng.integers(1, 300_000)))
             for _ in range(count)]
    msg = observation_to_msg(Observation(True, '', 640, 480, np.ones((40, 40), np.uint8),
                                         CropTransform(4.5, 220.0, 120.0), blobs,
                                         glove_pixel_count=10), HEADER)
    ordered = sorted(blobs, key=lambda b: -b.pixel_count)
    assert list(msg.blob_colors) == [b.color_label for b in ordered]
    assert list(msg.blob_centroids) == [v for b in ordered for v in (b.centroid_x, b.centroid_y)]
    assert list(msg.blob_pixel_counts) == [b.pixel_count for b in ordered]
    for message in (msg, deserialize_message(serialize_message(msg), HandObservation)):
        back = blobs_from_observation_msg(message)
        expected = (np.array([b.color_label for b in ordered], np.int64).reshape(-1),
                    np.array([[b.centroid_x, b.centroid_y] for b in ordered]).reshape(-1, 2),
                    np.array([b.pixel_count for b in ordered], float).reshape(-1))
        for got, want in zip((back.color, back.centroid_px, back.pixel_count), expected,
                             strict=True):
            assert got.dtype == want.dtype and got.shape == want.shape
            assert got.tobytes() == want.tobytes()
            assert got.flags.writeable and got.flags.c_contiguous


@pytest.mark.parametrize(('field', 'change'), [
    ('blob_colors', lambda v: v[:-1]), ('blob_centroids', lambda v: v[:-1]),
    ('blob_centroids', lambda v: v + v[:2]), ('blob_pixel_counts', lambda v: v + v[:1])])
def test_blob_arrays_of_different_lengths_are_refused_naming_them(field: str, change) -> None:
    from colorglove_ros.core.validation import InvalidObservationError
    from colorglove_ros.ros.message_checks import checked_observation_msg

    msg = observation_to_msg(Observation(
        True, '', 640, 480, np.ones((40, 40), np.uint8), CropTransform(4.5, 220.0, 120.0),
        [Blob(3, 310.5, 200.25, 90), Blob(7, 100.0, 50.5, 12)], glove_pixel_count=102), HEADER)
    setattr(msg, field, change(getattr(msg, field)))
    with pytest.raises(ValueError, match='blob arrays disagree'):
        blobs_from_observation_msg(msg)
    with pytest.raises(InvalidObservationError, match='blob arrays disagree'):
        checked_observation_msg(msg, (640, 480))
