"""The renderer's arrays in numpy, no OpenGL: the supersampled camera, vertex normals, a
decimated hand mesh for small label renders, and patch-id images read as labels and centroids
(:mod:`render` rasterises; these prepare what it draws and read what it returns)."""
from __future__ import annotations

import numpy as np

from colorglove_ros.core.camera import PinholeCamera
from colorglove_ros.core.errors import ColorGloveError
from colorglove_ros.core.hand.mesh import HandMesh

__all__ = [
    'RenderError', 'scaled_camera', 'vertex_normals', 'decimate_hand_mesh',
    'patch_ids_to_labels', 'patch_centroids',
]


class RenderError(ColorGloveError):
    """Bad renderer input (shapes, sizes) or an OpenGL context that cannot be made."""


def scaled_camera(camera: PinholeCamera, factor: int) -> PinholeCamera:
    """The same camera sampled ``factor`` times more densely (for supersampling): pixel
    centres of the fine image map to ``u = (u_fine + 0.5) / factor - 0.5``."""
    f = float(factor)
    return PinholeCamera(int(camera.width * factor), int(camera.height * factor),
                         camera.fx * f, camera.fy * f,
                         (camera.cx + 0.5) * f - 0.5, (camera.cy + 0.5) * f - 0.5,
                         camera.distortion, camera.rotation, camera.translation,
                         camera.name, camera.frame_id)


def vertex_normals(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Area-weighted unit vertex normals of (..., V, 3) vertices: (..., V, 3) float32."""
    v = np.asarray(vertices, dtype=np.float32)
    tri = v[..., faces, :]                                   # (..., F, 3, 3)
    fn = np.cross(tri[..., 1, :] - tri[..., 0, :], tri[..., 2, :] - tri[..., 0, :])
    out = np.zeros_like(v)
    flat_out = out.reshape(-1, v.shape[-2], 3)
    flat_fn = fn.reshape(-1, fn.shape[-2], 3)
    for b in range(flat_out.shape[0]):
        for k in range(3):
            np.add.at(flat_out[b], faces[:, k], flat_fn[b])
    norm = np.linalg.norm(out, axis=-1, keepdims=True)
    return out / np.maximum(norm, 1e-12)


def decimate_hand_mesh(mesh: HandMesh, face_patch: np.ndarray, cell_m: float = 0.004
                       ) -> tuple[HandMesh, np.ndarray]:
    """A coarser copy of a rigidly skinned hand mesh for fast small label renders, by vertex
    clustering in every link's own frame (cells of ``cell_m``; a cluster's vertex is the
    mean of its members). Surviving faces keep their winding and their patch; collapsed
    and duplicate faces are dropped. Returns (mesh, face_patch); skin it as usual.
    ``tools/render_benchmark`` prints the faces kept and the share of glove pixels whose
    patch id survives."""
    if cell_m <= 0:
        raise RenderError(f'cell_m must be positive, got {cell_m}')
    face_patch = np.asarray(face_patch)
    if face_patch.shape != (mesh.num_faces,):
        raise RenderError(f'face_patch must be ({mesh.num_faces},), got {face_patch.shape}')
    local = np.asarray(mesh.local_vertices, dtype=float)
    keys = np.concatenate([np.asarray(mesh.vertex_link)[:, None],
                           np.floor(local / cell_m).astype(np.int64)], axis=1)
    _, inverse = np.unique(keys, axis=0, return_inverse=True)
    inverse = inverse.ravel()
    n = int(inverse.max()) + 1
    count = np.bincount(inverse, minlength=n)
    verts = np.stack([np.bincount(inverse, local[:, k], n) / count for k in range(3)], axis=1)
    links = np.zeros(n, dtype=np.int64)
    links[inverse] = mesh.vertex_link
    faces = inverse[mesh.faces]
    keep = (faces[:, 0] != faces[:, 1]) & (faces[:, 1] != faces[:, 2]) \
        & (faces[:, 0] != faces[:, 2])
    faces, patches = faces[keep], face_patch[keep]
    _, first = np.unique(np.sort(faces, axis=1), axis=0, return_index=True)
    first = np.sort(first)
    coarse = HandMesh(verts, links, faces[first].astype(np.int32), mesh.hand_length_m)
    return coarse, patches[first]


def patch_ids_to_labels(patch_ids: np.ndarray, patch_color: np.ndarray) -> np.ndarray:
    """Map patch-id images (0 background, p + 1 for patch p) to label images
    (0 background, ``patch_color[p]`` elsewhere) with a look-up table."""
    patch_color = np.asarray(patch_color)
    if patch_color.ndim != 1 or len(patch_color) > 255:
        raise RenderError(f'patch_color must be 1-D with <= 255 entries, got {patch_color.shape}')
    lut = np.zeros(256, dtype=np.uint8)
    lut[1:len(patch_color) + 1] = patch_color
    return lut[np.asarray(patch_ids, dtype=np.uint8)]


def patch_centroids(patch_ids: np.ndarray, num_patches: int) -> tuple[np.ndarray, np.ndarray]:
    """Centroid (x, y) pixels and pixel count of every patch in (B, H, W) or (H, W)
    patch-id images (0 background, p + 1 for patch p): ((B, P, 2) float64 with NaN for
    absent patches, (B, P) int64); sparse over the glove pixels."""
    ids = np.asarray(patch_ids)
    single = ids.ndim == 2
    if single:
        ids = ids[None]
    b = ids.shape[0]
    bi, ys, xs = np.nonzero(ids)
    key = bi * (num_patches + 1) + ids[bi, ys, xs]
    size = b * (num_patches + 1)
    cnt = np.bincount(key, minlength=size).reshape(b, -1)[:, 1:]
    sx = np.bincount(key, xs, minlength=size).reshape(b, -1)[:, 1:]
    sy = np.bincount(key, ys, minlength=size).reshape(b, -1)[:, 1:]
    with np.errstate(invalid='ignore', divide='ignore'):
        cen = np.stack([sx / cnt, sy / cnt], axis=-1)
    return (cen[0], cnt[0]) if single else (cen, cnt)
