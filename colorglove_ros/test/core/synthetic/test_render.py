"""Tests of the moderngl renderer against PinholeCamera.project and a numpy z-buffer."""
from __future__ import annotations

import numpy as np
import pytest

from colorglove_ros.core.camera import PinholeCamera
from colorglove_ros.core.synthetic.mesh_images import (
    RenderError,
    decimate_hand_mesh,
    patch_centroids,
    patch_ids_to_labels,
    scaled_camera,
    vertex_normals,
)
from colorglove_ros.core.synthetic.render import Renderer

CAM = PinholeCamera(160, 120, 170.0, 190.0, 83.3, 55.7)   # deliberately fx != fy, off-centre


@pytest.fixture(scope='module')
def renderer() -> Renderer:
    r = Renderer(CAM.width, CAM.height, max_batch=6)   # 6 tiles per pass: exercises several
    yield r
    r.release()


def _reference_zbuffer(verts: np.ndarray, faces: np.ndarray, camera: PinholeCamera
                       ) -> tuple[np.ndarray, np.ndarray]:
    """Slow exact rasteriser: nearest face index (-1 none) and Z at every pixel centre."""
    h, w = camera.height, camera.width
    uv = camera.project(verts)
    inv_z = 1.0 / verts[:, 2]
    zbuf = np.full((h, w), np.inf)
    face_at = np.full((h, w), -1)
    for f, (a, b, c) in enumerate(faces):
        p = uv[[a, b, c]]
        x0, y0 = np.maximum(np.floor(p.min(0)).astype(int), 0)
        x1, y1 = np.minimum(np.ceil(p.max(0)).astype(int), [w - 1, h - 1])
        if x1 < x0 or y1 < y0:
            continue
        ys, xs = np.mgrid[y0:y1 + 1, x0:x1 + 1]
        den = (p[1, 1] - p[2, 1]) * (p[0, 0] - p[2, 0]) + (p[2, 0] - p[1, 0]) * (p[0, 1] - p[2, 1])
        if abs(den) < 1e-12:
            continue
        l0 = ((p[1, 1] - p[2, 1]) * (xs - p[2, 0]) + (p[2, 0] - p[1, 0]) * (ys - p[2, 1])) / den
        l1 = ((p[2, 1] - p[0, 1]) * (xs - p[2, 0]) + (p[0, 0] - p[2, 0]) * (ys - p[2, 1])) / den
        l2 = 1.0 - l0 - l1
        inside = (l0 >= 0) & (l1 >= 0) & (l2 >= 0)
        z = 1.0 / (l0 * inv_z[a] + l1 * inv_z[b] + l2 * inv_z[c])
        closer = inside & (z < zbuf[ys, xs])
        zbuf[ys[closer], xs[closer]] = z[closer]
        face_at[ys[closer], xs[closer]] = f
    return face_at, np.where(np.isfinite(zbuf), zbuf, 0.0)


def _pose(model, rng: np.random.Generator, depth: float = 0.45) -> np.ndarray:
    q = model.rest_pose()
    q[2] = depth
    q[3:6] = rng.normal(0.0, 0.5, 3)
    q[6:] = rng.uniform(model.lower_limits[6:], model.upper_limits[6:]) * 0.6
    return q


def test_triangle_covers_exactly_the_projected_pixel_centres(renderer: Renderer) -> None:
    # a triangle 0.5 m away; its projection covers exactly the pixel centres inside it
    tri = np.array([[-0.11, -0.05, 0.5], [0.13, 0.02, 0.62], [-0.02, 0.09, 0.45]])
    uv = CAM.project(tri)
    ids = Renderer(CAM.width, CAM.height, cull_back_faces=False).render_patch_ids(
        tri[None], np.array([[0, 1, 2]]), np.array([4]), CAM)[0]
    assert set(np.unique(ids)) == {0, 5}
    ys, xs = np.mgrid[0:CAM.height, 0:CAM.width]
    e = [(uv[(i + 1) % 3, 0] - uv[i, 0]) * (ys - uv[i, 1])
         - (uv[(i + 1) % 3, 1] - uv[i, 1]) * (xs - uv[i, 0]) for i in range(3)]
    lens = [np.hypot(*(uv[(i + 1) % 3] - uv[i])) for i in range(3)]
    dist = np.stack([ei / li for ei, li in zip(e, lens, strict=True)])  # signed px distances
    sign = np.sign(dist.sum(axis=(1, 2)))[:, None, None]
    dist = dist * sign
    inside = np.all(dist > 0.02, axis=0)
    outside = np.any(dist < -0.02, axis=0)
    assert inside.sum() > 1000
    assert np.all(ids[inside] == 5)
    assert np.all(ids[outside] == 0)


def test_rendered_hand_matches_projected_vertices(renderer: Renderer, hand) -> None:
    model, mesh, glove = hand
    q = _pose(model, np.random.default_rng(3))
    verts = mesh.skin(model, q)
    ids, depth = renderer.render_patch_ids_depth(verts[None], mesh.faces, glove.face_patch, CAM)
    ids, depth = ids[0], depth[0]
    uv = CAM.project(verts)
    ys, xs = np.nonzero(ids)
    # covered pixel centres lie inside the projected extent and reach it (pointed fingertips
    # may cover no pixel centre in their last pixel, hence < 2 px)
    lo, hi = uv.min(0), uv.max(0)
    assert lo[0] - 1e-6 <= xs.min() < lo[0] + 2 and hi[0] - 2 < xs.max() <= hi[0] + 1e-6
    assert lo[1] - 1e-6 <= ys.min() < lo[1] + 2 and hi[1] - 2 < ys.max() <= hi[1] + 1e-6
    # visible vertices (depth at their pixel equals their own Z) land on covered pixels
    px = np.round(uv).astype(int)
    ok = (px[:, 0] >= 0) & (px[:, 0] < CAM.width) & (px[:, 1] >= 0) & (px[:, 1] < CAM.height)
    d_at = depth[px[ok, 1], px[ok, 0]]
    visible = np.abs(d_at - verts[ok, 2]) < 2e-3
    assert visible.sum() > 200
    assert np.all(ids[px[ok, 1], px[ok, 0]][visible] > 0)


def test_patch_ids_and_depth_match_reference_zbuffer(renderer: Renderer, hand) -> None:
    model, mesh, glove = hand
    q = _pose(model, np.random.default_rng(7))
    verts = mesh.skin(model, q)
    ids, depth = renderer.render_patch_ids_depth(verts[None], mesh.faces, glove.face_patch, CAM)
    face_at, zref = _reference_zbuffer(verts, mesh.faces, CAM)
    ref_ids = np.where(face_at >= 0, glove.face_patch[np.maximum(face_at, 0)] + 1, 0)
    agree = np.mean(ids[0] == ref_ids)
    fg = ref_ids > 0
    assert fg.sum() > 500
    assert agree > 0.995
    assert np.mean(ids[0][fg] == ref_ids[fg]) > 0.98
    # exactly the visible patches (ignoring patches seen on <= 2 pixels, edge ties)
    counts_ref = np.bincount(ref_ids[fg], minlength=21)
    counts = np.bincount(ids[0][ids[0] > 0], minlength=21)
    assert set(np.flatnonzero(counts_ref > 2)) <= set(np.flatnonzero(counts))
    assert set(np.flatnonzero(counts > 2)) <= set(np.flatnonzero(counts_ref))
    both = fg & (ids[0] > 0)
    np.testing.assert_allclose(depth[0][both], zref[both], atol=2e-3)
    assert np.all(depth[0][ids[0] == 0] == 0)


def test_batches_equal_single_renders_and_tiles_do_not_bleed(renderer: Renderer, hand) -> None:
    model, mesh, glove = hand
    rng = np.random.default_rng(11)
    Q = np.stack([_pose(model, rng) for _ in range(14)])   # 3 passes of 6 tiles
    Q[::3, 0] += 0.12      # push some hands half out of their tile, both ways
    Q[1::3, 1] -= 0.10
    verts = mesh.skin_batch(model, Q)
    batch = renderer.render_patch_ids(verts, mesh.faces, glove.face_patch, CAM)
    assert batch.shape == (14, CAM.height, CAM.width) and batch.dtype == np.uint8
    for i in range(14):
        single = renderer.render_patch_ids(verts[i:i + 1], mesh.faces, glove.face_patch, CAM)
        # same pixels up to float rounding of the tile offset (edge/depth ties)
        assert np.sum(batch[i] != single[0]) <= 3
    assert np.all([(b > 0).any() for b in batch])
    # a hand moved far outside its tile leaves every tile of the batch empty
    far = verts.copy()
    far[:, :, 0] += 5.0
    assert not renderer.render_patch_ids(far, mesh.faces, glove.face_patch, CAM).any()


def test_labels_follow_the_patch_colours(renderer: Renderer, hand) -> None:
    model, mesh, glove = hand
    verts = mesh.skin(model, _pose(model, np.random.default_rng(5)))[None]
    ids = renderer.render_patch_ids(verts, mesh.faces, glove.face_patch, CAM)
    labels = renderer.render_labels(verts, mesh.faces, glove.face_patch, glove.patch_color, CAM)
    np.testing.assert_array_equal(labels, patch_ids_to_labels(ids, glove.patch_color))
    assert labels.max() <= 10 and set(np.unique(labels)) - {0}
    assert np.all((labels > 0) == (ids > 0))


def test_shaded_render_lambert_and_patch_ids(hand) -> None:
    model, mesh, glove = hand
    r = Renderer(CAM.width, CAM.height)
    # a camera-facing quad lit head on shows its albedo; lit at 60 deg, ambient + half
    quad = np.array([[-0.1, -0.1, 0.5], [0.1, -0.1, 0.5], [0.1, 0.1, 0.5], [-0.1, 0.1, 0.5]])
    faces = np.array([[0, 2, 1], [0, 3, 2]])    # counter-clockwise seen from the camera
    albedo = np.array([[0.2, 0.4, 0.8], [0.2, 0.4, 0.8]], np.float32)
    img = r.render_shaded(quad, faces, albedo, CAM, light_dir=(0, 0, 1), ambient=0.1,
                          face_patch=np.array([2, 3]))
    inner = img.rgb[40:80, 60:100]
    np.testing.assert_allclose(inner, np.broadcast_to(albedo[0], inner.shape), atol=1e-5)
    assert set(np.unique(img.patch_ids)) == {0, 3, 4}
    np.testing.assert_allclose(img.depth[img.mask], 0.5, atol=1e-5)
    assert np.array_equal(img.alpha > 0, img.mask)
    # 3 x 3 supersampling: coverage sums to the projected area, colour / coverage = albedo
    msaa = Renderer(CAM.width, CAM.height, supersample=3)
    aa = msaa.render_shaded(quad, faces, albedo, CAM, light_dir=(0, 0, 1), ambient=0.1)
    area = (0.2 * CAM.fx / 0.5) * (0.2 * CAM.fy / 0.5)
    assert abs(aa.alpha.sum() - area) < 0.005 * area
    edge = (aa.alpha > 0.1) & (aa.alpha < 0.9)
    assert edge.sum() > 100
    np.testing.assert_allclose(aa.rgb[edge] / aa.alpha[edge, None],
                               np.broadcast_to(albedo[0], (edge.sum(), 3)), atol=1e-4)
    msaa.release()
    tilted = r.render_shaded(quad, faces, albedo, CAM, light_dir=(0, np.sin(np.pi / 3), 0.5),
                             ambient=0.1, light_rgb=(1.0, 0.5, 2.0))
    expect = albedo[0] * (0.1 + 0.9 * 0.5) * np.array([1.0, 0.5, 2.0])
    np.testing.assert_allclose(tilted.rgb[60, 80], expect, atol=1e-5)
    # the hand: shaded patch ids equal the label renderer's, smooth normals too
    verts = mesh.skin(model, _pose(model, np.random.default_rng(2)))
    ids = r.render_patch_ids(verts[None], mesh.faces, glove.face_patch, CAM)[0]
    rgb = (glove.face_rgb / 255.0).astype(np.float32)
    flat = r.render_shaded(verts, mesh.faces, rgb, CAM, face_patch=glove.face_patch)
    smooth = r.render_shaded(verts, mesh.faces, rgb, CAM, face_patch=glove.face_patch,
                             normals=vertex_normals(verts, mesh.faces))
    np.testing.assert_array_equal(flat.patch_ids, ids)
    np.testing.assert_array_equal(smooth.patch_ids, ids)
    assert np.all(flat.rgb[ids == 0] == 0) and flat.rgb[ids > 0].max() > 0.3
    r.release()


def test_scaled_camera_keeps_pixel_geometry() -> None:
    fine = scaled_camera(CAM, 3)
    p = np.array([[0.03, -0.02, 0.4], [-0.1, 0.05, 0.7]])
    u, uf = CAM.project(p), fine.project(p)
    np.testing.assert_allclose((uf + 0.5) / 3 - 0.5, u, atol=1e-9)
    assert (fine.width, fine.height) == (480, 360)


def test_patch_centroids() -> None:
    ids = np.zeros((2, 10, 12), np.uint8)
    ids[0, 2:4, 3:7] = 1          # patch 0: x 3..6, y 2..3
    ids[1, 5, 9] = 20             # patch 19 in the second image
    cen, cnt = patch_centroids(ids, 20)
    np.testing.assert_allclose(cen[0, 0], [4.5, 2.5])
    np.testing.assert_allclose(cen[1, 19], [9.0, 5.0])
    assert cnt[0, 0] == 8 and cnt[1, 19] == 1 and cnt.sum() == 9
    assert np.isnan(cen[0, 1]).all()


def test_bad_inputs_raise(renderer: Renderer) -> None:
    with pytest.raises(RenderError):
        renderer.render_patch_ids(np.zeros((1, 3, 3)), np.array([[0, 1, 5]]), [0], CAM)
    with pytest.raises(RenderError):
        renderer.render_patch_ids(np.zeros((1, 3, 3)), np.array([[0, 1, 2]]), [0],
                                  PinholeCamera(64, 64, 50, 50, 31.5, 31.5))
    with pytest.raises(RenderError):
        Renderer(0, 10)


def test_decimated_mesh_renders_nearly_the_same_labels(hand) -> None:
    model, mesh, glove = hand
    coarse, coarse_patch = decimate_hand_mesh(mesh, glove.face_patch, 0.004)
    assert coarse.num_faces < 0.8 * mesh.num_faces
    assert coarse_patch.shape == (coarse.num_faces,)
    assert set(np.unique(coarse_patch)) == set(np.unique(glove.face_patch))
    cam = PinholeCamera(128, 128, 260.0, 260.0, 63.5, 63.5)
    rng = np.random.default_rng(4)
    Q = np.stack([_pose(model, rng, depth=0.5) for _ in range(8)])
    Q[:, 1] = 0.0
    r = Renderer(128, 128)
    full = r.render_patch_ids(mesh.skin_batch(model, Q), mesh.faces, glove.face_patch, cam)
    cv = coarse.skin_batch(model, Q)
    ids = r.render_patch_ids(cv, coarse.faces, coarse_patch, cam)
    fg = (full > 0) | (ids > 0)
    assert np.mean((full > 0)[fg] == (ids > 0)[fg]) > 0.98
    assert np.mean(full[fg] == ids[fg]) > 0.95
    # winding survives: culling back faces changes nothing
    nocull = Renderer(128, 128, cull_back_faces=False)
    both = nocull.render_patch_ids(cv, coarse.faces, coarse_patch, cam)
    assert np.mean(both != ids) < 1e-3
    r.release()
    nocull.release()
