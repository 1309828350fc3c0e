"""Left hand by mirroring: pose and query round trips, the rendered left hand equals the
mirrored rendering of the right hand in the mirrored pose, and the prefixed left-hand URDF."""
from __future__ import annotations

import numpy as np
import pytest
import yourdfpy

from colorglove_ros.core.camera import PinholeCamera
from colorglove_ros.core.hand.glove import default_hand
from colorglove_ros.core.hand.handedness import (
    mirror_crop,
    mirror_observation,
    mirror_pose,
    mirror_tiny_labels,
)
from colorglove_ros.core.hand.model import FINGER_DOF_NAMES, LINK_NAMES, rotvec_to_matrix
from colorglove_ros.core.hand.urdf import UrdfError
from colorglove_ros.core.hand.urdf_variants import hand_urdf_string, prefixed_joint_names
from colorglove_ros.core.segmentation.crop import TINY_SIZE, CropTransform, crop_to_tiny
from colorglove_ros.core.segmentation.segmenter import Blob, Observation
from colorglove_ros.core.synthetic.render import Renderer

S = np.diag([-1.0, 1.0, 1.0])
# principal point at the image centre, so mirroring about cx is a plain column flip
CAMERA = PinholeCamera(width=160, height=120, fx=150.0, fy=150.0, cx=79.5, cy=59.5)


def _random_pose(rng: np.random.Generator) -> np.ndarray:
    model = default_hand()[0]
    q = model.rest_pose()
    q[0:3] = [rng.uniform(-0.03, 0.03), rng.uniform(0.0, 0.08), rng.uniform(0.45, 0.6)]
    q[3:6] = rng.normal(0.0, 0.4, 3)
    q[6:] = rng.uniform(model.lower_limits[6:], model.upper_limits[6:])
    return q


def _left_hand_points(q: np.ndarray, local_right: np.ndarray) -> np.ndarray:
    """A left hand at pose q built directly: hand-frame points of the right model mirrored by
    S, then placed by the wrist pose."""
    return q[0:3] + (local_right @ S.T) @ rotvec_to_matrix(q[3:6]).T


@pytest.mark.parametrize('seed', range(4))
def test_mirror_pose_round_trip_and_geometry(seed: int) -> None:
    model = default_hand()[0]
    q = _random_pose(np.random.default_rng(seed))
    np.testing.assert_allclose(mirror_pose(mirror_pose(q)), q, atol=1e-12)
    mirrored = mirror_pose(q)
    assert not np.allclose(mirrored, q)
    np.testing.assert_array_equal(mirrored[6:], q[6:])
    # the right hand at the mirrored pose is the mirror image of the left hand at q
    q_local = q.copy()
    q_local[0:6] = 0.0
    local_right = model.keypoints(q_local)
    left = _left_hand_points(q, local_right)
    np.testing.assert_allclose(model.keypoints(mirrored), left @ S, atol=1e-12)


def test_mirror_query_round_trip() -> None:
    rng = np.random.default_rng(3)
    tiny = rng.integers(0, 11, (TINY_SIZE, TINY_SIZE)).astype(np.uint8)
    crop = CropTransform(scale=2.5, offset_x=101.0, offset_y=40.0)
    observation = Observation(hand_found=True, status='ok', image_width=320, image_height=240,
                              tiny_labels=tiny, crop=crop,
                              blobs=[Blob(3, 120.5, 60.0, 40), Blob(7, 150.0, 80.0, 12)])
    mirrored = mirror_observation(observation, cx=170.0)
    np.testing.assert_array_equal(mirrored.tiny_labels[:, 0], tiny[:, -1])
    assert [b.centroid_x for b in mirrored.blobs] == [219.5, 190.0]
    back = mirror_observation(mirrored, cx=170.0)
    np.testing.assert_array_equal(back.tiny_labels, tiny)
    assert back.crop.offset_x == pytest.approx(crop.offset_x)
    assert back.blobs == observation.blobs
    # a tiny pixel and its mirrored partner land on mirrored full-image columns
    full = crop.to_full(np.array([5.0, 7.0]))
    full_m = mirror_crop(crop, 170.0).to_full(np.array([TINY_SIZE - 1 - 5.0, 7.0]))
    assert full_m[0] == pytest.approx(2 * 170.0 - full[0])
    assert full_m[1] == pytest.approx(full[1])
    with pytest.raises(ValueError):
        mirror_tiny_labels(np.zeros((10, 10), np.uint8))


@pytest.fixture(scope='module')
def renderer() -> Renderer:
    r = Renderer(CAMERA.width, CAMERA.height, max_batch=4)
    yield r
    r.release()


@pytest.mark.parametrize('seed', range(3))
def test_rendered_left_hand_equals_mirrored_right_rendering(renderer: Renderer,
                                                            seed: int) -> None:
    model, mesh, glove = default_hand()
    q_left = _random_pose(np.random.default_rng(100 + seed))
    q_local = q_left.copy()
    q_local[0:6] = 0.0
    local = mesh.skin_batch(model, q_local[None], dtype=np.float64)[0]
    left_vertices = _left_hand_points(q_left, local)
    # mirroring reverses the winding: flip the faces so the outside stays the front
    left = renderer.render_labels(left_vertices[None].astype(np.float32), mesh.faces[:, ::-1],
                                  glove.face_patch, glove.patch_color, CAMERA)[0]
    right = renderer.render_labels(
        mesh.skin_batch(model, mirror_pose(q_left)[None]), mesh.faces, glove.face_patch,
        glove.patch_color, CAMERA)[0]
    mirrored = right[:, ::-1]
    assert (left > 0).sum() > 500            # the hand is in view
    union = (left > 0) | (mirrored > 0)
    agree = (left == mirrored)[union].mean()
    assert agree > 0.98, agree               # rasterisation may differ on edge pixels
    # and the query the lookup gets: tiny image and crop of the left hand = mirrored ones
    crop_left = crop_to_tiny(left)
    crop_right = crop_to_tiny(right)
    assert (mirror_tiny_labels(crop_right.labels) == crop_left.labels).mean() > 0.97
    m = mirror_crop(crop_right.transform, CAMERA.cx)
    assert m.offset_x == pytest.approx(crop_left.transform.offset_x, abs=0.5)
    assert m.scale == pytest.approx(crop_left.transform.scale, rel=0.02)


@pytest.mark.parametrize('seed', range(3))
def test_left_urdf_is_the_mirrored_hand(tmp_path, seed: int) -> None:
    model = default_hand()[0]
    path = tmp_path / 'left.urdf'
    path.write_text(hand_urdf_string('left'))
    urdf = yourdfpy.URDF.load(str(path), load_meshes=False)
    assert urdf.validate() and urdf.base_link == 'left_palm'
    names = prefixed_joint_names(FINGER_DOF_NAMES, 'left_')
    assert list(urdf.actuated_joint_names) == names
    fingers = np.random.default_rng(seed).uniform(model.lower_limits[6:],
                                                  model.upper_limits[6:])
    urdf.update_cfg(dict(zip(names, fingers, strict=True)))
    q = np.zeros(26)
    q[6:] = fingers
    T = model.link_transforms(q)
    for li, name in enumerate(LINK_NAMES):
        Tu = urdf.get_transform(frame_to=f'left_{name}', frame_from='left_palm')
        np.testing.assert_allclose(Tu[:3, 3], S @ T[li, :3, 3], atol=1e-9)
        np.testing.assert_allclose(Tu[:3, :3], S @ T[li, :3, :3] @ S, atol=1e-9)


def test_right_urdf_with_prefix_keeps_the_geometry() -> None:
    text = hand_urdf_string('right', prefix='right_')
    assert '<link name="right_palm">' in text and 'link="palm"' not in text
    assert hand_urdf_string('right', prefix='').count('name="palm"') == 1
    with pytest.raises(UrdfError):
        hand_urdf_string('middle')
