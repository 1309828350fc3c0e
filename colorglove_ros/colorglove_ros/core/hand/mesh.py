"""Procedural hand mesh, rigidly skinned to the model: capsule phalanges, convex-hull palm.

A hand with finger length factors (``HandModel.finger_length_factors``) gets the mesh of the
standard hand of its length with each capsule keeping its number of rings: the same vertices,
faces and links (so pose-database vertex indices and the glove's face patches stay valid),
stretched to the user's phalanges.
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from colorglove_ros.core.conventions import DEFAULT_HAND_LENGTH_M
from colorglove_ros.core.errors import ColorGloveError
from colorglove_ros.core.hand import model as _model_module
from colorglove_ros.core.hand.disk_cache import cached_arrays
from colorglove_ros.core.hand.model import (
    NOMINAL_FINGER_LENGTH_FACTORS,
    NUM_DOFS,
    HandModel,
    digit_link_index,
)

if TYPE_CHECKING:   # trimesh is imported where a mesh is built or exported (slow to import)
    import trimesh

__all__ = ['HandMeshError', 'HandMesh', 'build_hand_mesh', 'skin_batch', 'PALM_SUBDIVISIONS',
           'RING_SPACING_FRACTION']

# palm: icosphere subdivisions (1280 triangles at 3); phalanges: ring spacing / hand length
PALM_SUBDIVISIONS = 3
RING_SPACING_FRACTION = 0.03


class HandMeshError(ColorGloveError):
    """A mesh does not match the hand model or a pose batch has the wrong shape."""


@dataclass(frozen=True, eq=False)
class HandMesh:
    """Vertices in their links' frames, each bound rigidly to one link of the ``HandModel``."""

    local_vertices: np.ndarray   # (V, 3) float64, link frame
    vertex_link: np.ndarray      # (V,) int64 link index
    faces: np.ndarray            # (F, 3) int32, counter-clockwise seen from outside
    hand_length_m: float = DEFAULT_HAND_LENGTH_M
    finger_length_factors: tuple[float, ...] = NOMINAL_FINGER_LENGTH_FACTORS

    @property
    def num_vertices(self) -> int:
        """Number of vertices V."""
        return int(len(self.local_vertices))

    @property
    def num_faces(self) -> int:
        """Number of triangles F."""
        return int(len(self.faces))

    @property
    def face_link(self) -> np.ndarray:
        """(F,) link of each triangle (all three vertices share it)."""
        return self.vertex_link[self.faces[:, 0]]

    def skin(self, model: HandModel, q: np.ndarray) -> np.ndarray:
        """(V, 3) camera-frame vertex positions for pose q (26,)."""
        return skin_batch(self, model, np.asarray(q, dtype=float)[None], dtype=np.float64)[0]

    def skin_batch(self, model: HandModel, Q: np.ndarray,
                   dtype: type = np.float32) -> np.ndarray:
        """(B, V, 3) camera-frame vertex positions for poses Q (B, 26)."""
        return skin_batch(self, model, Q, dtype=dtype)

    def vertex_jacobian(self, model: HandModel, q: np.ndarray,
                        vertex_indices: np.ndarray) -> np.ndarray:
        """(N, 3, 26) analytic Jacobian of the camera-frame positions of some vertices."""
        idx = np.asarray(vertex_indices, dtype=np.int64)
        return model.point_jacobian(q, self.vertex_link[idx], self.local_vertices[idx])

    def to_trimesh(self, model: HandModel, q: np.ndarray | None = None) -> trimesh.Trimesh:
        """The skinned mesh (rest pose by default) as a ``trimesh.Trimesh``."""
        import trimesh

        q = model.rest_pose() if q is None else q
        return trimesh.Trimesh(self.skin(model, q), self.faces, process=False)


def skin_batch(mesh: HandMesh, model: HandModel, Q: np.ndarray,
               dtype: type = np.float32) -> np.ndarray:
    """(B, 26) poses -> (B, V, 3) vertex positions, vectorised per link."""
    Q = np.asarray(Q, dtype=float)
    if Q.ndim != 2 or Q.shape[1] != NUM_DOFS:
        raise HandMeshError(f'poses must have shape (B, 26), got {Q.shape}')
    if not np.isclose(mesh.hand_length_m, model.hand_length_m):
        raise HandMeshError(
            f'mesh built for {mesh.hand_length_m} m, model is {model.hand_length_m} m')
    if not np.allclose(mesh.finger_length_factors, model.finger_length_factors):
        raise HandMeshError(
            f'mesh built for finger length factors {mesh.finger_length_factors}, model has '
            f'{model.finger_length_factors}')
    T = model.link_transforms_batch(Q).astype(dtype)
    out = np.empty((len(Q), mesh.num_vertices, 3), dtype=dtype)
    for link, idx in enumerate(_link_groups(mesh)):
        if len(idx) == 0:
            continue
        local = mesh.local_vertices[idx].astype(dtype)
        out[:, idx] = np.matmul(local[None], np.swapaxes(T[:, link, :3, :3], 1, 2)) \
            + T[:, link, None, :3, 3]
    return out


def _link_groups(mesh: HandMesh) -> list[np.ndarray]:
    return [np.flatnonzero(mesh.vertex_link == k) for k in range(16)]


def _cylinder_height(length: float, radius: float, is_tip: bool) -> float:
    """Length of a phalanx capsule's cylinder (a fingertip's ends in its cap)."""
    return max(length - radius, 1e-4) if is_tip else length


def _ring_count(model: HandModel, link: int, is_tip: bool) -> int:
    """Cylinder segments of a phalanx capsule of ``model``: rings at most
    ``RING_SPACING_FRACTION * hand length`` apart (even triangles for the glove patches)."""
    height = _cylinder_height(model.link_lengths[link], model.link_radii[link], is_tip)
    return max(1, int(np.ceil(height / (RING_SPACING_FRACTION * model.hand_length_m))))


def _capsule(length: float, radius: float, is_tip: bool, n_cyl: int) -> trimesh.Trimesh:
    """Capsule along the link's -y axis from the joint (y=0), with ``n_cyl`` cylinder
    segments; a fingertip capsule ends exactly at -length."""
    import trimesh

    height = _cylinder_height(length, radius, is_tip)
    n_theta, n_cap = 12, 4
    prof = [(radius * np.sin(a), radius * np.cos(a))
            for a in np.linspace(-np.pi / 2, 0.0, n_cap + 1)[1:]]
    prof += [(z, radius) for z in np.linspace(0.0, height, n_cyl + 1)[1:]]
    prof += [(height + radius * np.sin(a), radius * np.cos(a))
             for a in np.linspace(0.0, np.pi / 2, n_cap + 1)[1:-1]]
    pr = np.array(prof)
    th = np.linspace(0.0, 2 * np.pi, n_theta, endpoint=False)
    rings = np.stack([np.outer(pr[:, 1], np.cos(th)), np.outer(pr[:, 1], np.sin(th)),
                      np.repeat(pr[:, :1], n_theta, axis=1)], axis=-1).reshape(-1, 3)
    verts = np.concatenate([[[0.0, 0.0, -radius]], rings, [[0.0, 0.0, height + radius]]])
    j = np.arange(n_theta)
    jn = (j + 1) % n_theta
    faces = [np.stack([np.zeros(n_theta, np.int64), 1 + jn, 1 + j], axis=1)]
    for r in range(len(pr) - 1):
        a, b = 1 + r * n_theta, 1 + (r + 1) * n_theta
        faces += [np.stack([a + j, a + jn, b + jn], axis=1),
                  np.stack([a + j, b + jn, b + j], axis=1)]
    a = 1 + (len(pr) - 1) * n_theta
    faces.append(np.stack([np.full(n_theta, len(verts) - 1), a + j, a + jn], axis=1))
    # z -> -y (rotation of +90 deg about x)
    verts = np.stack([verts[:, 0], -verts[:, 2], verts[:, 1]], axis=1)
    return trimesh.Trimesh(verts, np.concatenate(faces), process=False)


def _palm(model: HandModel) -> trimesh.Trimesh:
    """Convex hull of the wrist cross-section, the knuckles and the thumb base, triangulated
    evenly by projecting a subdivided sphere (stretched to the hull's extents) onto it."""
    import trimesh

    s = model.scale
    pts = []
    ang = np.linspace(0.0, 2 * np.pi, 24, endpoint=False)
    # wrist: ellipse 62 mm wide, 30 mm thick
    for y in (0.008 * s, -0.012 * s):
        pts.append(np.stack([0.031 * s * np.cos(ang), np.full_like(ang, y),
                             0.015 * s * np.sin(ang) - 0.001 * s], axis=1))
    # knuckles: circles at every finger base
    for d in range(1, 5):
        anchor = model.finger_anchors[d]
        r = model.link_radii[digit_link_index(d, 0)] * 1.05
        for dy in (0.0, 0.012 * s):
            pts.append(anchor + np.stack([r * np.cos(ang), np.full_like(ang, dy),
                                          r * np.sin(ang)], axis=1))
    # thenar eminence at the thumb base
    sphere = trimesh.creation.icosphere(subdivisions=1, radius=model.link_radii[1] * 1.1)
    pts.append(sphere.vertices + model.finger_anchors[0])
    hull = trimesh.convex.convex_hull(np.concatenate(pts))
    centre = hull.bounds.mean(axis=0)
    extent = (hull.bounds[1] - hull.bounds[0]) / 2.0
    ico = trimesh.creation.icosphere(subdivisions=PALM_SUBDIVISIONS)
    u = ico.vertices * extent
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    n = hull.face_normals
    b = np.einsum('fj,fj->f', n, hull.vertices[hull.faces[:, 0]]) - n @ centre
    nu = u @ n.T
    with np.errstate(divide='ignore', invalid='ignore'):
        t = np.where(nu > 1e-12, b[None] / nu, np.inf).min(axis=1)
    return trimesh.Trimesh(centre + u * t[:, None], ico.faces, process=False)


def build_hand_mesh(model: HandModel) -> HandMesh:
    """Build (cached per hand length and finger length factors) the procedural mesh for
    ``model``."""
    return _build_cached(round(float(model.hand_length_m), 9),
                         tuple(round(float(f), 9) for f in model.finger_length_factors))


@lru_cache(maxsize=8)
def _build_cached(hand_length_m: float, finger_length_factors: tuple[float, ...]) -> HandMesh:
    name = f'hand_mesh-{hand_length_m!r}'
    if finger_length_factors != NOMINAL_FINGER_LENGTH_FACTORS:
        name += '-fingers-' + '-'.join(repr(f) for f in finger_length_factors)
    arrays = cached_arrays(name, [Path(__file__), Path(_model_module.__file__)],
                           lambda: _build_arrays(hand_length_m, finger_length_factors))
    mesh = HandMesh(arrays['local_vertices'], arrays['vertex_link'], arrays['faces'],
                    hand_length_m, finger_length_factors)
    for arr in (mesh.local_vertices, mesh.vertex_link, mesh.faces):
        arr.setflags(write=False)
    return mesh


def _build_arrays(hand_length_m: float,
                  finger_length_factors: tuple[float, ...] = NOMINAL_FINGER_LENGTH_FACTORS
                  ) -> dict[str, np.ndarray]:
    """The mesh arrays built with trimesh (palm hull, phalanx capsules), the capsules with the
    ring counts of the standard hand of this length (one topology for every proportion)."""
    model = HandModel(hand_length_m, finger_length_factors)
    standard = HandModel(hand_length_m)
    parts = [(0, _palm(model))]
    for d in range(5):
        for k in range(3):
            li = digit_link_index(d, k)
            parts.append((li, _capsule(model.link_lengths[li], model.link_radii[li], k == 2,
                                        _ring_count(standard, li, k == 2))))
    verts, links, faces = [], [], []
    offset = 0
    for li, m in parts:
        verts.append(np.asarray(m.vertices, dtype=float))
        links.append(np.full(len(m.vertices), li, dtype=np.int64))
        faces.append(np.asarray(m.faces, dtype=np.int64) + offset)
        offset += len(m.vertices)
    return {'local_vertices': np.concatenate(verts), 'vertex_link': np.concatenate(links),
            'faces': np.concatenate(faces).astype(np.int32)}
