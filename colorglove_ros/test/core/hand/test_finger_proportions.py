"""Per-user finger proportions: ``HandModel(hand_length_m, finger_length_factors)``, its mesh
and glove (same topology and patches as the standard hand), and the factors solved from
measured digit lengths."""
from __future__ import annotations

import math

import numpy as np
import pytest
from hand_calibration_files import UNEVEN_FACTORS

from colorglove_ros.core.conventions import DEFAULT_HAND_LENGTH_M, FINGER_LENGTH_FACTOR_RANGE
from colorglove_ros.core.hand.glove import default_hand
from colorglove_ros.core.hand.mesh import HandMeshError, build_hand_mesh, skin_batch
from colorglove_ros.core.hand.model import (
    DIGITS,
    KEYPOINT_NAMES,
    NOMINAL_FINGER_LENGTH_FACTORS,
    NUM_DOFS,
    HandModel,
    HandModelError,
    digit_link_index,
    finger_length_factors_for,
)

MIDDLE_TIP = KEYPOINT_NAMES.index('middle_tip')


def _random_poses(model: HandModel, seed: int, count: int = 12) -> np.ndarray:
    rng = np.random.default_rng(seed)
    Q = np.tile(model.rest_pose(), (count, 1))
    Q[:, 6:] = rng.uniform(model.lower_limits[6:], model.upper_limits[6:], (count, 20))
    Q[:, 3:6] = rng.normal(scale=0.8, size=(count, 3))
    return Q


@pytest.mark.parametrize('hand_length_m', [0.16, DEFAULT_HAND_LENGTH_M, 0.23])
def test_all_ones_is_exactly_the_nominal_hand(hand_length_m: float) -> None:
    plain = HandModel(hand_length_m)
    ones = HandModel(hand_length_m, [1, 1, 1, 1, 1])
    assert plain.finger_length_factors == ones.finger_length_factors \
        == NOMINAL_FINGER_LENGTH_FACTORS
    Q = _random_poses(plain, 3)
    assert np.array_equal(plain.keypoints_batch(Q), ones.keypoints_batch(Q))
    assert np.array_equal(plain.keypoint_jacobian(Q[0]), ones.keypoint_jacobian(Q[0]))
    assert np.array_equal(plain.link_lengths, ones.link_lengths) and plain.scale == ones.scale
    assert build_hand_mesh(ones) is build_hand_mesh(plain)
    assert default_hand(hand_length_m, 0, [1.0] * 5) is default_hand(hand_length_m, 0)


@pytest.mark.parametrize('factors', [UNEVEN_FACTORS, (1.0, 1.0, 1.25, 1.0, 1.0),
                                     (0.8, 1.1, 1.0, 1.1, 0.75)])
def test_factors_lengthen_each_digit_and_keep_the_hand_length(factors) -> None:
    length = 0.2
    plain, scaled = HandModel(length), HandModel(length, factors)
    assert scaled.finger_length_factors == tuple(factors)
    rest = scaled.keypoints(scaled.rest_pose(centered=False))
    assert np.linalg.norm(rest[MIDDLE_TIP] - rest[0]) == pytest.approx(length, abs=1e-12)
    overall = scaled.scale / plain.scale            # the palm and radii follow this only
    if factors[DIGITS.index('middle')] == 1.0:
        assert overall == pytest.approx(1.0, abs=1e-12)
    np.testing.assert_allclose(scaled.link_radii, overall * plain.link_radii, rtol=1e-12)
    np.testing.assert_allclose(scaled.finger_anchors, overall * plain.finger_anchors,
                               rtol=1e-12, atol=1e-15)
    for d, factor in enumerate(factors):
        links = [digit_link_index(d, k) for k in range(3)]
        np.testing.assert_allclose(scaled.link_lengths[links],
                                   factor * overall * plain.link_lengths[links], rtol=1e-12)
    np.testing.assert_allclose(scaled.digit_lengths_m / plain.digit_lengths_m,
                               np.array(factors) * overall, rtol=1e-12)
    # the kinematics follow: a flat finger's tip is its knuckle-to-tip length from its base
    for d, digit in enumerate(DIGITS[1:], start=1):
        base = rest[KEYPOINT_NAMES.index(f'{digit}_mcp')]
        tip = rest[KEYPOINT_NAMES.index(f'{digit}_tip')]
        assert np.linalg.norm(tip - base) == pytest.approx(scaled.digit_lengths_m[d], rel=1e-12)


@pytest.mark.parametrize('factors, message', [
    ((1.0, 1.0, 1.0, 1.0), 'list of 5'),
    ((1.0,) * 6, 'list of 5'),
    ('11111', 'list of 5'),
    (1.0, 'list of 5'),
    ((1.0, math.nan, 1.0, 1.0, 1.0), 'index factor nan'),
    ((1.0, 1.0, math.inf, 1.0, 1.0), 'middle factor inf'),
    ((1.0, 1.0, 1.0, FINGER_LENGTH_FACTOR_RANGE[1] + 0.01, 1.0), 'ring factor'),
    ((FINGER_LENGTH_FACTOR_RANGE[0] - 0.01, 1.0, 1.0, 1.0, 1.0), 'thumb factor'),
    ((1.0, 1.0, 1.0, 1.0, True), 'little factor must be a number'),
    ((1.0, 1.0, '1.0', 1.0, 1.0), 'middle factor must be a number'),
])
def test_bad_factors_are_refused(factors, message: str) -> None:
    with pytest.raises(HandModelError, match=message):
        HandModel(DEFAULT_HAND_LENGTH_M, factors)
    with pytest.raises(HandModelError, match=message):
        default_hand(DEFAULT_HAND_LENGTH_M, 0, factors)


@pytest.mark.parametrize('seed', [0, 1, 2])
def test_factors_solved_from_measured_lengths(seed: int) -> None:
    rng = np.random.default_rng(seed)
    length = float(rng.uniform(0.16, 0.22))
    factors = tuple(rng.uniform(0.8, 1.2, 5))
    truth = HandModel(length, factors)
    solved = finger_length_factors_for(length, truth.digit_lengths_m)
    np.testing.assert_allclose(solved, factors, rtol=1e-12)
    np.testing.assert_allclose(HandModel(length, solved).digit_lengths_m, truth.digit_lengths_m,
                               rtol=1e-12)


def test_solving_refuses_impossible_lengths() -> None:
    nominal = HandModel().digit_lengths_m
    with pytest.raises(HandModelError, match='shorter than the hand'):
        finger_length_factors_for(0.09, nominal)
    with pytest.raises(HandModelError, match='positive finite'):
        finger_length_factors_for(0.19, [*nominal[:4], -0.05])
    with pytest.raises(HandModelError, match='positive finite'):
        finger_length_factors_for(0.19, nominal[:4])
    with pytest.raises(HandModelError, match='hand length'):
        finger_length_factors_for(math.nan, nominal)


def test_mesh_keeps_the_topology_and_follows_the_fingers() -> None:
    length = DEFAULT_HAND_LENGTH_M
    model, mesh, glove = default_hand(length, 0, UNEVEN_FACTORS)
    standard_model, standard_mesh, standard_glove = default_hand(length, 0)
    assert model.finger_length_factors == mesh.finger_length_factors == UNEVEN_FACTORS
    assert build_hand_mesh(HandModel(length, UNEVEN_FACTORS)) is mesh       # cached per factors
    # one topology: pose-database vertex indices and the glove's face patches stay valid
    assert np.array_equal(mesh.faces, standard_mesh.faces)
    assert np.array_equal(mesh.vertex_link, standard_mesh.vertex_link)
    assert np.array_equal(glove.face_patch, standard_glove.face_patch)
    assert np.array_equal(glove.patch_color, standard_glove.patch_color)
    assert not np.allclose(mesh.local_vertices, standard_mesh.local_vertices)
    for d in range(5):
        for k in range(3):
            link = digit_link_index(d, k)
            v = mesh.local_vertices[mesh.vertex_link == link]
            radius, link_length = model.link_radii[link], model.link_lengths[link]
            # every vertex on the capsule: distance to the link's axis segment = the radius
            axial = np.clip(-v[:, 1], 0.0, link_length - (radius if k == 2 else 0.0))
            closest = np.stack([np.zeros_like(axial), -axial, np.zeros_like(axial)], axis=1)
            np.testing.assert_allclose(np.linalg.norm(v - closest, axis=1), radius,
                                       rtol=1e-9)
            if k == 2:      # a fingertip capsule ends exactly at the tip
                assert -v[:, 1].max() == pytest.approx(-radius, rel=1e-9)
                assert -v[:, 1].min() == pytest.approx(link_length, rel=1e-12)
    # skinned at a pose, each glove patch stays on the links it was on
    q = _random_poses(model, 5, 1)[0]
    moved = mesh.skin(model, q)
    for face in np.flatnonzero(glove.face_patch == glove.face_patch[0])[:5]:
        link = int(mesh.face_link[face])
        transform = model.link_transforms(q)[link]
        local = (moved[mesh.faces[face]] - transform[:3, 3]) @ transform[:3, :3]
        np.testing.assert_allclose(local, mesh.local_vertices[mesh.faces[face]], atol=1e-12)
    assert standard_model.finger_length_factors == NOMINAL_FINGER_LENGTH_FACTORS


def test_mesh_and_model_of_other_proportions_are_refused() -> None:
    model = HandModel(DEFAULT_HAND_LENGTH_M, UNEVEN_FACTORS)
    standard = build_hand_mesh(HandModel(DEFAULT_HAND_LENGTH_M))
    with pytest.raises(HandMeshError, match='finger length factors'):
        skin_batch(standard, model, np.zeros((1, NUM_DOFS)))
    with pytest.raises(HandMeshError, match='finger length factors'):
        skin_batch(build_hand_mesh(model), HandModel(DEFAULT_HAND_LENGTH_M),
                   np.zeros((1, NUM_DOFS)))

