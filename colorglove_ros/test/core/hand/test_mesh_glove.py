"""Tests for the procedural hand mesh (skinning, Jacobians) and the glove pattern."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import trimesh

from colorglove_ros.core.conventions import DEFAULT_HAND_LENGTH_M, NUM_COLORS, NUM_PATCHES
from colorglove_ros.core.hand.glove import (
    GLOVE_PALETTE_RGB,
    GloveError,
    colour_adjacency,
    default_colour_adjacency,
    export_glove_mesh,
    glove_reference_pose,
    make_glove,
)
from colorglove_ros.core.hand.mesh import HandMeshError, build_hand_mesh, skin_batch
from colorglove_ros.core.hand.model import NUM_DOFS, HandModel


def test_mesh_size_and_binding(hand) -> None:
    model, mesh, _ = hand
    assert 2000 <= mesh.num_faces <= 12000
    assert mesh.faces.dtype == np.int32 and mesh.faces.min() == 0
    assert mesh.faces.max() == mesh.num_vertices - 1
    assert set(np.unique(mesh.vertex_link)) == set(range(16))
    # every triangle lies on a single link
    assert np.all(mesh.vertex_link[mesh.faces] == mesh.face_link[:, None])
    # the rest-pose mesh spans the hand length (+ fingertip radius at most)
    v = mesh.skin(model, model.rest_pose())
    assert 0.19 <= np.ptp(v[:, 1]) <= 0.23
    tm = trimesh.Trimesh(v, mesh.faces, process=False)
    assert 0.03 < tm.area < 0.09  # m^2: a plausible hand surface


def test_mesh_cached_per_length() -> None:
    a = build_hand_mesh(HandModel(DEFAULT_HAND_LENGTH_M))
    b = build_hand_mesh(HandModel(DEFAULT_HAND_LENGTH_M))
    c = build_hand_mesh(HandModel(0.17))
    assert a is b and c is not a
    assert np.isclose(np.ptp(c.local_vertices[c.vertex_link == 0][:, 1]) /
                      np.ptp(a.local_vertices[a.vertex_link == 0][:, 1]),
                      0.17 / DEFAULT_HAND_LENGTH_M, rtol=1e-6)
    with pytest.raises(HandMeshError):
        skin_batch(c, HandModel(DEFAULT_HAND_LENGTH_M), np.zeros((1, NUM_DOFS)))


@pytest.mark.parametrize('seed', [0, 1, 2])
def test_skin_batch_matches_transform_points(hand, seed: int) -> None:
    model, mesh, _ = hand
    rng = np.random.default_rng(seed)
    Q = np.tile(model.rest_pose(), (4, 1))
    Q[:, 6:] = rng.uniform(model.lower_limits[6:], model.upper_limits[6:], (4, 20))
    Q[:, 3:6] = rng.normal(scale=0.8, size=(4, 3))
    V = skin_batch(mesh, model, Q, dtype=np.float64)
    for b in range(4):
        ref = model.transform_points(Q[b], mesh.vertex_link, mesh.local_vertices)
        assert np.abs(V[b] - ref).max() < 1e-12
    V32 = mesh.skin_batch(model, Q)
    assert V32.dtype == np.float32 and np.abs(V32 - V).max() < 1e-6


def test_vertex_jacobian(hand) -> None:
    model, mesh, _ = hand
    rng = np.random.default_rng(5)
    q = model.rest_pose()
    q[6:] = rng.uniform(model.lower_limits[6:], model.upper_limits[6:])
    q[3:6] = [0.3, -0.4, 0.9]
    idx = rng.choice(mesh.num_vertices, 30, replace=False)
    J = mesh.vertex_jacobian(model, q, idx)
    eps = 1e-6
    for i in range(NUM_DOFS):
        d = np.zeros(NUM_DOFS)
        d[i] = eps
        num = (mesh.skin(model, q + d)[idx] - mesh.skin(model, q - d)[idx]) / (2 * eps)
        assert np.abs(J[:, :, i] - num).max() < 1e-8


def test_glove_patches(hand) -> None:
    model, mesh, glove = hand
    assert glove.face_patch.shape == (mesh.num_faces,)
    counts = np.bincount(glove.face_patch, minlength=NUM_PATCHES)
    assert len(counts) == NUM_PATCHES and np.all(counts > 20)
    assert glove.patch_color.dtype == np.uint8
    assert np.array_equal(np.bincount(glove.patch_color, minlength=11)[1:], np.full(10, 2))
    labels = glove.face_labels
    assert labels.min() >= 1 and labels.max() <= NUM_COLORS
    # each seed belongs to its own patch, and every patch has non-trivial area
    assert np.array_equal(glove.face_patch[glove.seed_faces], np.arange(NUM_PATCHES))
    tm = mesh.to_trimesh(model)
    area = np.bincount(glove.face_patch, weights=tm.area_faces)
    assert area.min() > 0.1 * area.mean()
    # every digit carries at least one seed (its own patch)
    for d in range(5):
        links = 1 + 3 * d + np.arange(3)
        assert np.any(np.isin(mesh.face_link[glove.seed_faces], links))


def test_palette_distinct() -> None:
    p = GLOVE_PALETTE_RGB.astype(float)
    assert p.shape == (10, 3)
    d = np.linalg.norm(p[:, None] - p[None], axis=2) + np.eye(10) * 1e9
    assert d.min() > 60
    assert np.all(p.max(1) - p.min(1) > 100)  # saturated


def test_glove_deterministic(hand) -> None:
    model, mesh, glove = hand
    g0 = make_glove(mesh, seed=0, model=model)
    g1 = make_glove(mesh, seed=1, model=model)
    assert np.array_equal(g0.face_patch, glove.face_patch)
    assert np.array_equal(g0.patch_color, glove.patch_color)
    assert not np.array_equal(g0.patch_color, g1.patch_color)


def test_seeds_far_apart(hand) -> None:
    model, mesh, glove = hand
    v = mesh.skin(model, glove_reference_pose(model))
    cent = v[mesh.faces].mean(1)
    seeds = cent[glove.seed_faces]
    dmin = np.linalg.norm(seeds[:, None] - seeds[None], axis=2) + np.eye(NUM_PATCHES)
    assert dmin.min() > 0.015  # seeds are spread out (> 1.5 cm apart)


def test_export_ply(hand, tmp_path: Path) -> None:
    model, mesh, glove = hand
    path = export_glove_mesh(mesh, glove, model, tmp_path / 'glove.ply')
    loaded = trimesh.load(path, process=False)
    assert loaded.faces.shape == mesh.faces.shape
    raw = loaded.metadata['_ply_raw']['face']['data']
    assert np.array_equal(raw['patch'], glove.face_patch)
    assert np.array_equal(loaded.visual.face_colors[:, :3], glove.face_rgb)
    glb = export_glove_mesh(mesh, glove, model, tmp_path / 'glove.glb')
    assert glb.stat().st_size > 10000


def test_export_tool(tmp_path: Path) -> None:
    from colorglove_ros.tools.export_glove import main

    assert main(['--out', str(tmp_path), '--json', str(tmp_path / 'summary.json')]) == 0
    for name in ('glove.ply', 'glove.glb', 'glove.png', 'summary.json'):
        assert (tmp_path / name).stat().st_size > 1000
    import json

    summary = json.loads((tmp_path / 'summary.json').read_text())
    assert len(summary['patches']) == NUM_PATCHES
    assert sum(p['faces'] for p in summary['patches']) == summary['faces']


def test_colour_adjacency_is_the_colours_of_triangles_sharing_an_edge(hand) -> None:
    """Which colours border each other on the glove: the colour pairs of every two triangles
    sharing an edge, found here edge by edge; symmetric, no colour beside itself or the
    background, and the standard glove's cached copy is the same and read only."""
    model, mesh, glove = hand
    labels = glove.face_labels
    by_edge: dict[tuple[int, int], list[int]] = {}
    for f, tri in enumerate(np.asarray(mesh.faces)):
        for a, b in ((tri[0], tri[1]), (tri[1], tri[2]), (tri[2], tri[0])):
            by_edge.setdefault((min(a, b), max(a, b)), []).append(f)
    expected = np.zeros((NUM_COLORS + 1, NUM_COLORS + 1), bool)
    for faces in by_edge.values():
        for i in faces:
            for j in faces:
                if labels[i] != labels[j]:
                    expected[labels[i], labels[j]] = True
    got = colour_adjacency(glove, mesh.faces)
    assert np.array_equal(got, expected)
    assert np.array_equal(got, got.T) and not got.diagonal().any() and not got[0].any()
    assert 0 < got.sum() < NUM_COLORS * (NUM_COLORS - 1)    # some pairs never meet
    standard = default_colour_adjacency()
    assert np.array_equal(standard, got) and not standard.flags.writeable
    with pytest.raises(GloveError):
        colour_adjacency(glove, mesh.faces[:-1])
