"""The glove's patches as link-fixed mesh faces: the predicted centroid of the part of each patch
a camera sees (the ``patch`` constraint model of the tracker)."""
from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from colorglove_ros.core.camera import PinholeCamera
from colorglove_ros.core.tracking.kinematics import FastKinematics
from colorglove_ros.core.tracking.types import IKError, MeshLike

__all__ = ['PatchSurface']


class PatchSurface:
    """The glove's patches as link-fixed mesh faces, to predict the centroid of the part of
    each patch a camera sees: the projected-area-weighted mean of the patch's visible faces
    (weight = area x cosine toward the camera / depth^2), kept per link as one link-fixed
    point so the weights stay fixed while the pose is solved.

    A face is visible if it faces the camera and no front face projecting into the same
    cell of a coarse depth buffer (cells ``cell_m`` wide at the hand's depth) is more than
    ``depth_tol_m`` nearer. A patch whose visible faces carry less than
    ``min_visible_fraction`` of its front-facing weight (hidden, or the pose is off) uses
    all its front faces instead. Faces are merged into elements (same patch, link and facing,
    one ``element_m`` voxel); links with less than ``min_link_weight`` of a patch's visible
    weight are left out."""

    def __init__(self, kin: FastKinematics, mesh: MeshLike, face_patch: np.ndarray,
                 cell_m: float = 0.004, depth_tol_m: float = 0.004,
                 element_m: float = 0.006, min_link_weight: float = 0.1,
                 min_visible_fraction: float = 0.2) -> None:
        faces = np.asarray(getattr(mesh, 'faces', np.zeros((0, 3))), np.int64)
        face_patch = np.asarray(face_patch, np.int64)
        links = np.asarray(mesh.vertex_link, np.int64)
        if faces.ndim != 2 or faces.shape[1] != 3 or len(faces) == 0 \
                or len(face_patch) != len(faces):
            raise IKError(f'the patch model needs mesh faces (F, 3) and one patch per face; got '
                          f'{faces.shape} faces and {face_patch.shape} patch ids')
        face_link = links[faces[:, 0]]
        if np.any(links[faces[:, 1]] != face_link) or np.any(links[faces[:, 2]] != face_link):
            raise IKError('the patch model needs every mesh face on one link')
        v = np.asarray(mesh.local_vertices, float)[faces]                  # (F, 3, 3)
        centre = v.mean(axis=1)
        area_normal = 0.5 * np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0])
        area = np.linalg.norm(area_normal, axis=1)
        # surface elements: the faces of one patch and link in one element_m voxel, facing the
        # same way (dominant normal axis and sign); sorted by kinematic frame
        dominant = np.argmax(np.abs(area_normal), axis=1)
        facing = 2 * dominant + (area_normal[np.arange(len(faces)), dominant] > 0)
        key = np.column_stack([kin.link_frame[face_link], face_patch, face_link, facing,
                               np.floor(centre / element_m).astype(np.int64)])
        keys, elem = np.unique(key, axis=0, return_inverse=True)
        elem = elem.reshape(-1)
        n = len(keys)
        elem_area = np.bincount(elem, area, n)
        self._centre = np.stack([np.bincount(elem, area * centre[:, i], n) for i in range(3)],
                                axis=1) / elem_area[:, None]
        self._area_normal = np.stack([np.bincount(elem, area_normal[:, i], n)
                                      for i in range(3)], axis=1)
        frame, elem_patch, elem_link = keys[:, 0], keys[:, 1], keys[:, 2]
        self._element_frame = np.ascontiguousarray(frame)
        self._elem_patch = np.ascontiguousarray(elem_patch)
        self._kin = kin
        pairs, self._group = np.unique(np.stack([elem_patch, elem_link], axis=1), axis=0,
                                       return_inverse=True)
        self._group = self._group.reshape(-1)
        num_patches = int(elem_patch.max()) + 1
        slots = np.bincount(pairs[:, 0], minlength=num_patches)
        self.max_links = int(slots.max())
        if not 0.0 <= min_link_weight < 1.0 / self.max_links:
            # a seen patch must keep its largest link (weight >= 1 / max_links)
            raise IKError(f'min_link_weight must be in [0, 1/{self.max_links}) for a glove '
                          f'with up to {self.max_links} links per patch, got {min_link_weight}')
        self._table = np.full((num_patches, self.max_links), -1, np.int64)
        first = np.concatenate([[0], np.cumsum(slots)[:-1]])
        for g, (p, _) in enumerate(pairs):
            self._table[p, g - first[p]] = g
        self._group_link = np.ascontiguousarray(pairs[:, 1])
        self.num_patches = num_patches
        self.cell_m = float(cell_m)
        self.depth_tol_m = float(depth_tol_m)
        self.min_visible_fraction = float(min_visible_fraction)
        self.min_link_weight = float(min_link_weight)
        self._posed_cache: tuple[bytes, tuple[np.ndarray, np.ndarray]] | None = None

    def _posed(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Element centres and area normals (E, 3) in the primary camera frame at pose ``q``
        (read-only; the last pose is remembered, as every camera of a frame asks for it)."""
        q = np.asarray(q, dtype=float)
        key = q.tobytes()
        if self._posed_cache is not None and self._posed_cache[0] == key:
            return self._posed_cache[1]
        Rs, ts, _ = self._kin.frames(q)
        centre, normal = self._kin.kernels.posed_elements(Rs, ts, self._element_frame, self._centre,
                                                  self._area_normal)
        centre.setflags(write=False)
        normal.setflags(write=False)
        self._posed_cache = (key, (centre, normal))
        return centre, normal

    def points(self, q: np.ndarray, camera: PinholeCamera, patch_id: np.ndarray
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """For each patch id: links (K, S), link-frame points (K, S, 3) and weights (K, S)
        of its visible part seen by ``camera`` at pose ``q``, and whether any of it faces the
        camera (K,) (rows that do not keep weight 0)."""
        patch_id = np.asarray(patch_id, np.int64)
        return self.points_by_camera(q, [camera], np.zeros(len(patch_id), np.int64), patch_id)

    def _element_weights(self, pc: np.ndarray, normal: np.ndarray, camera: PinholeCamera
                         ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Element centres in ``camera``'s optical frame (E, 3), the projected-area weight (E,)
        of every element facing ``camera`` (area x cosine / depth^2), and the same with the
        elements hidden in the coarse depth buffer set to 0 (``ik_kernel.element_weights``)."""
        return self._kin.kernels.element_weights(
            pc, normal, np.asarray(camera.rotation, float), np.asarray(camera.translation, float),
            float(camera.fx), float(camera.fy), self.cell_m, self.depth_tol_m)

    def points_by_camera(self, q: np.ndarray, cameras: Sequence[PinholeCamera],
                         camera_index: np.ndarray, patch_id: np.ndarray
                         ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """:meth:`points` for rows seen by different cameras (row k by
        ``cameras[camera_index[k]]``) in one pass over the posed glove."""
        patch_id = np.ascontiguousarray(patch_id, np.int64)
        camera_index = np.ascontiguousarray(camera_index, np.int64)
        if len(patch_id) and (patch_id.min() < 0 or patch_id.max() >= self.num_patches):
            raise IKError(f'patch id outside [0, {self.num_patches})')
        if len(camera_index) != len(patch_id) or (
                len(camera_index) and (camera_index.min() < 0
                                       or camera_index.max() >= len(cameras))):
            raise IKError(f'camera index outside [0, {len(cameras)}) or not one per patch id')
        pc, normal = self._posed(q)
        # per camera: all front weights and the visible ones; patches mostly hidden in the
        # depth buffer fall back to all their front faces, and links holding a sliver of the
        # visible patch are dropped (fewer points to move): ik_kernel.patch_points
        weights = [self._element_weights(pc, normal, cam) for cam in cameras]
        return self._kin.kernels.patch_points(
            np.concatenate([front for _, front, _ in weights]),
            np.concatenate([vis for _, _, vis in weights]), self._elem_patch, self._group,
            self._centre, self.num_patches, self._group_link, self._table, patch_id,
            camera_index, self.min_visible_fraction, self.min_link_weight)

    def visible_faces(self, q: np.ndarray, camera: PinholeCamera
                      ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The glove's visible surface elements in ``camera``'s image at pose ``q``: each
        one's patch (M,), undistorted pixel centre (M, 2) and visible area (M, pixels);
        hidden and back-facing elements are left out."""
        pc, _, w_vis = self._element_weights(*self._posed(q), camera)
        shown = w_vis > 0
        uv = camera.project(pc[shown]) if shown.any() else np.zeros((0, 2))
        return self._elem_patch[shown], uv, w_vis[shown] * (camera.fx * camera.fy)

    def visible_patches(self, q: np.ndarray, camera: PinholeCamera
                        ) -> tuple[np.ndarray, np.ndarray]:
        """Every patch's visible area in ``camera``'s image at pose ``q`` (num_patches,
        pixels; hidden and back-facing faces count nothing) and the undistorted pixel
        centroid of that area (num_patches, 2; NaN where nothing is visible): what the
        segmenter should see of the glove if the pose is right."""
        pc, _, w_vis = self._element_weights(*self._posed(q), camera)
        return self._kin.kernels.patch_areas(pc, w_vis, self._elem_patch, self.num_patches,
                                             float(camera.fx), float(camera.fy),
                                             float(camera.cx), float(camera.cy))
