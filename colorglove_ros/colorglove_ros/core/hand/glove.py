"""The colour glove: 20 patches grown from far-apart seed triangles, 10 saturated colours.

Construction (Wang & Popovic 2009): 20 seed triangles are chosen by greedy farthest-point
sampling over triangle centroids, every other triangle joins the patch of its nearest
seed, and each patch gets one of 10 colours at random. Distances are approximate
**geodesic** distances: shortest paths over a graph joining every triangle centroid to its
k nearest centroids (and to its edge-adjacent triangles), measured on a reference pose with
the fingers spread (``glove_reference_pose``), so a patch does not jump through the palm
or from a finger to its neighbour. Colours: a seeded random permutation of
``[1..10] * 2`` (every colour on exactly two patches), redrawn until no two neighbouring
patches share a colour.

The glove is a printed object: a hand with other finger proportions
(``HandModel.finger_length_factors``) wears the standard glove of its hand length, every mesh
face keeping its patch (the mesh keeps its topology and each face lies on one link, so a patch
stretches with the phalanges under it).
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from colorglove_ros.core.conventions import (
    DEFAULT_GLOVE_SEED,
    DEFAULT_HAND_LENGTH_M,
    NUM_COLORS,
    NUM_PATCHES,
)
from colorglove_ros.core.errors import ColorGloveError
from colorglove_ros.core.hand.disk_cache import cached_arrays
from colorglove_ros.core.hand.mesh import HandMesh, build_hand_mesh
from colorglove_ros.core.hand.model import (
    DOF_NAMES,
    NOMINAL_FINGER_LENGTH_FACTORS,
    HandModel,
    calibrated_hand_model,
    check_finger_length_factors,
)

if TYPE_CHECKING:   # scipy and trimesh are imported where a glove is built (slow to import)
    from scipy.sparse import csr_matrix

    from colorglove_ros.core.camera import Calibration

__all__ = [
    'GLOVE_PALETTE_RGB', 'GLOVE_COLOR_NAMES', 'GloveError',
    'Glove', 'make_glove', 'glove_reference_pose', 'export_glove_mesh', 'default_hand',
    'calibrated_hand', 'colour_adjacency', 'default_colour_adjacency',
]

GLOVE_COLOR_NAMES: tuple[str, ...] = (
    'red', 'green', 'blue', 'yellow', 'magenta', 'cyan', 'orange', 'purple', 'pink', 'lime')
# label k (1..10) has colour GLOVE_PALETTE_RGB[k - 1]
GLOVE_PALETTE_RGB = np.array([
    [225, 20, 30],     # red
    [0, 150, 60],      # green
    [25, 55, 235],     # blue
    [255, 230, 0],     # yellow
    [220, 0, 210],     # magenta
    [0, 215, 235],     # cyan
    [255, 125, 0],     # orange
    [105, 25, 160],    # purple
    [255, 150, 195],   # pink
    [150, 245, 40],    # lime
], dtype=np.uint8)
GLOVE_PALETTE_RGB.setflags(write=False)
_KNN = 8


class GloveError(ColorGloveError):
    """The glove could not be built (disconnected surface graph, bad sizes)."""


@dataclass(frozen=True, eq=False)
class Glove:
    """Patch of every mesh triangle and colour label (1..10) of every patch."""

    face_patch: np.ndarray    # (F,) int64 in 0..19
    patch_color: np.ndarray   # (20,) uint8 in 1..10
    seed_faces: np.ndarray = field(  # (20,) triangle index of each patch's seed, if known
        default_factory=lambda: np.zeros(0, dtype=np.int64))

    @property
    def face_labels(self) -> np.ndarray:
        """(F,) uint8 colour label (1..10) of every triangle."""
        return self.patch_color[self.face_patch]

    @property
    def face_rgb(self) -> np.ndarray:
        """(F, 3) uint8 colour of every triangle."""
        return GLOVE_PALETTE_RGB[self.face_labels.astype(np.int64) - 1]


def glove_reference_pose(model: HandModel) -> np.ndarray:
    """Rest pose with the fingers spread and the thumb abducted: where distances are measured."""
    q = model.rest_pose()
    spread = {'index_mcp_abd': 1.0, 'ring_mcp_abd': -0.7, 'little_mcp_abd': -1.0}
    for name, frac in spread.items():
        i = DOF_NAMES.index(name)
        q[i] = frac * model.upper_limits[i] if frac > 0 else -frac * model.lower_limits[i]
    q[DOF_NAMES.index('thumb_cmc_abd')] = 0.5 * model.upper_limits[DOF_NAMES.index('thumb_cmc_abd')]
    return q


def _surface_graph(centroids: np.ndarray, faces: np.ndarray) -> csr_matrix:
    """Symmetric sparse graph over triangles: k nearest centroids + shared-edge neighbours."""
    import trimesh
    from scipy.sparse import coo_matrix
    from scipy.spatial import cKDTree

    n = len(centroids)
    tree = cKDTree(centroids)
    dist, nbr = tree.query(centroids, k=_KNN + 1)
    rows = [np.repeat(np.arange(n), _KNN)]
    cols = [nbr[:, 1:].ravel()]
    adj = trimesh.graph.face_adjacency(faces=faces)
    rows.append(adj[:, 0])
    cols.append(adj[:, 1])
    r = np.concatenate(rows + cols)
    c = np.concatenate(cols + rows)
    w = np.linalg.norm(centroids[r] - centroids[c], axis=1) + 1e-12
    return coo_matrix((w, (r, c)), shape=(n, n)).tocsr()


def make_glove(mesh: HandMesh, seed: int = DEFAULT_GLOVE_SEED,
               model: HandModel | None = None) -> Glove:
    """Build the glove pattern on ``mesh`` deterministically from ``seed``."""
    from scipy.sparse.csgraph import connected_components, dijkstra

    model = HandModel(mesh.hand_length_m, mesh.finger_length_factors) if model is None else model
    rng = np.random.default_rng(seed)
    verts = mesh.skin(model, glove_reference_pose(model))
    centroids = verts[mesh.faces].mean(axis=1)
    graph = _surface_graph(centroids, mesh.faces)
    ncomp, _ = connected_components(graph, directed=False)
    if ncomp != 1:
        raise GloveError(f'surface graph has {ncomp} components, expected 1')
    # greedy farthest-point seeds; the random start is replaced by the face farthest from it
    start = int(rng.integers(len(centroids)))
    d0 = dijkstra(graph, directed=False, indices=start)
    seeds = [int(np.argmax(d0))]
    dist = np.empty((NUM_PATCHES, len(centroids)))
    dist[0] = dijkstra(graph, directed=False, indices=seeds[0])
    for k in range(1, NUM_PATCHES):
        nxt = int(np.argmax(dist[:k].min(axis=0)))
        seeds.append(nxt)
        dist[k] = dijkstra(graph, directed=False, indices=nxt)
    face_patch = np.argmin(dist, axis=0).astype(np.int64)
    # neighbouring patches (joined by a graph edge)
    g = graph.tocoo()
    pa, pb = face_patch[g.row], face_patch[g.col]
    touching = np.zeros((NUM_PATCHES, NUM_PATCHES), dtype=bool)
    touching[pa, pb] = True
    np.fill_diagonal(touching, False)
    base = np.repeat(np.arange(1, NUM_COLORS + 1), NUM_PATCHES // NUM_COLORS)
    best, best_conflicts = None, None
    for _ in range(2000):
        colors = rng.permutation(base)
        conflicts = int(np.sum(touching & (colors[:, None] == colors[None, :])))
        if best_conflicts is None or conflicts < best_conflicts:
            best, best_conflicts = colors, conflicts
        if conflicts == 0:
            break
    assert best is not None
    glove = Glove(face_patch, best.astype(np.uint8), np.array(seeds, dtype=np.int64))
    for arr in (glove.face_patch, glove.patch_color, glove.seed_faces):
        arr.setflags(write=False)
    return glove


def export_glove_mesh(mesh: HandMesh, glove: Glove, model: HandModel, path: str | Path,
                      q: np.ndarray | None = None, hand: str = 'right') -> Path:
    """Write the coloured glove mesh (pose q, rest pose by default) of the ``hand`` ('left':
    the mirror-image glove, ``core.hand.handedness``).

    ``.ply``: shared vertices, per-face RGBA colour plus face attributes ``patch`` and
    ``label``. ``.glb``/``.obj``: faces unmerged so per-vertex colours reproduce the patches.
    """
    import trimesh

    path = Path(path)
    if len(glove.face_patch) != mesh.num_faces:
        raise GloveError(f'glove has {len(glove.face_patch)} faces, mesh {mesh.num_faces}')
    from colorglove_ros.core.hand.handedness import hand_faces, hand_vertices

    verts = hand_vertices(mesh, model, model.rest_pose() if q is None else q, hand)
    faces = hand_faces(mesh.faces, hand)
    rgba = np.concatenate([glove.face_rgb, np.full((mesh.num_faces, 1), 255, np.uint8)], axis=1)
    path.parent.mkdir(parents=True, exist_ok=True)
    if path.suffix.lower() == '.ply':
        tm = trimesh.Trimesh(verts, faces, face_colors=rgba, process=False)
        tm.face_attributes['patch'] = glove.face_patch.astype(np.int32)
        tm.face_attributes['label'] = glove.face_labels.astype(np.int32)
        path.write_bytes(trimesh.exchange.ply.export_ply(tm, encoding='binary'))
    else:
        flat_v = verts[faces].reshape(-1, 3)
        flat_f = np.arange(len(flat_v)).reshape(-1, 3)
        tm = trimesh.Trimesh(flat_v, flat_f, vertex_colors=np.repeat(rgba, 3, axis=0),
                             process=False)
        tm.export(path)
    return path


def default_hand(hand_length_m: float = DEFAULT_HAND_LENGTH_M,
                 seed: int = DEFAULT_GLOVE_SEED,
                 finger_length_factors: Sequence[float] | None = None
                 ) -> tuple[HandModel, HandMesh, Glove]:
    """The (model, mesh, glove) triple of a hand length, glove seed and finger length factors
    (default: the nominal proportions), cached (in memory, and the glove on disk:
    ``core.hand.disk_cache``). With factors the glove is the standard glove of that hand length
    and seed, on the stretched mesh of the same topology."""
    factors = (NOMINAL_FINGER_LENGTH_FACTORS if finger_length_factors is None else
               check_finger_length_factors('finger_length_factors', finger_length_factors))
    return _hand(float(hand_length_m), int(seed), factors)


def colour_adjacency(glove: Glove, faces: np.ndarray) -> np.ndarray:
    """(NUM_COLORS + 1, NUM_COLORS + 1) bool, symmetric: which colour labels of ``glove``
    border each other somewhere on its surface (two triangles of ``faces``, (F, 3) vertex
    indices of the glove's mesh, sharing an edge). Label 0 (background) borders none, nor
    does a colour itself."""
    faces = np.asarray(faces, np.int64)
    labels = np.asarray(glove.face_labels, np.int64)
    if faces.ndim != 2 or faces.shape[1] != 3 or len(faces) != len(labels):
        raise GloveError(f'need ({len(labels)}, 3) faces for the glove, got {faces.shape}')
    edges = np.sort(np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]]),
                    axis=1)
    key = edges[:, 0] * (int(faces.max()) + 1) + edges[:, 1]
    order = np.argsort(key, kind='stable')
    owner = np.tile(np.arange(len(faces)), 3)[order]
    shared = key[order][1:] == key[order][:-1]          # an edge of two triangles
    a, b = labels[owner[:-1][shared]], labels[owner[1:][shared]]
    out = np.zeros((NUM_COLORS + 1, NUM_COLORS + 1), bool)
    out[a, b] = out[b, a] = True
    np.fill_diagonal(out, False)
    return out


@lru_cache(maxsize=4)
def default_colour_adjacency(seed: int = DEFAULT_GLOVE_SEED) -> np.ndarray:
    """:func:`colour_adjacency` of the standard glove of ``seed`` (:func:`default_hand`;
    the layout does not depend on the hand's length), read only."""
    _, mesh, glove = default_hand(DEFAULT_HAND_LENGTH_M, seed)
    out = colour_adjacency(glove, mesh.faces)
    out.setflags(write=False)
    return out


def calibrated_hand(calibration: Calibration, seed: int = DEFAULT_GLOVE_SEED
                    ) -> tuple[HandModel, HandMesh, Glove]:
    """The user's (model, mesh, glove): ``calibrated_hand_model(calibration)`` (hand length and
    finger length factors) wearing the glove of ``seed``."""
    model = calibrated_hand_model(calibration)
    return default_hand(model.hand_length_m, seed, model.finger_length_factors)


@lru_cache(maxsize=8)
def _hand(hand_length_m: float, seed: int, finger_length_factors: tuple[float, ...]
          ) -> tuple[HandModel, HandMesh, Glove]:
    model = HandModel(hand_length_m, finger_length_factors)
    mesh = build_hand_mesh(model)
    if finger_length_factors != NOMINAL_FINGER_LENGTH_FACTORS:
        _, standard_mesh, glove = _hand(hand_length_m, seed, NOMINAL_FINGER_LENGTH_FACTORS)
        if not np.array_equal(mesh.faces, standard_mesh.faces):
            raise GloveError('the mesh of these finger proportions has another topology than '
                             'the standard mesh: the glove cannot be carried over')
        return model, mesh, glove

    def build() -> dict[str, np.ndarray]:
        glove = make_glove(mesh, seed=seed, model=model)
        return {'face_patch': glove.face_patch, 'patch_color': glove.patch_color,
                'seed_faces': glove.seed_faces}

    arrays = cached_arrays(f'glove-{float(hand_length_m)!r}-{int(seed)}',
                           [Path(__file__), *_mesh_sources()], build)
    glove = Glove(arrays['face_patch'], arrays['patch_color'], arrays['seed_faces'])
    for arr in (glove.face_patch, glove.patch_color, glove.seed_faces):
        arr.setflags(write=False)
    return model, mesh, glove


def _mesh_sources() -> list[Path]:
    """The source files the standard mesh is built from (part of the glove's cache key)."""
    from colorglove_ros.core.hand import mesh as mesh_module
    from colorglove_ros.core.hand import model as model_module

    return [Path(mesh_module.__file__), Path(model_module.__file__)]
