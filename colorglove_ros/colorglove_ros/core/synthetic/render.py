"""Headless moderngl rasteriser: batched patch-id/label images and shaded frames (its numpy
inputs and outputs: :mod:`mesh_images`)."""
from __future__ import annotations

from dataclasses import dataclass

import moderngl
import numpy as np

from colorglove_ros.core.camera import PinholeCamera
from colorglove_ros.core.synthetic.mesh_images import RenderError

__all__ = ['Renderer', 'ShadedImage']

_MAX_ATLAS = 4096          # atlas side in pixels (llvmpipe allows 16384; 4096 keeps reads small)
_FACE_TEX_WIDTH = 1024     # per-face tables are stored as 1024-wide integer/float textures
_GL_CLIP_DISTANCE0 = 0x3000

# Projection: a camera-frame point (X, Y, Z) lands on pixel u = fx X/Z + cx, v = fy Y/Z + cy
# (pixel centres at integers). GL samples window position (u + 0.5, v + 0.5) at pixel centres,
# so the window x of the point is fx X/Z + cx + 0.5 + tile_x0 and likewise for y. Window row 0
# is the first row fbo.read() returns, so image row v is read back as row v (no flip needed).
# Tiles of a batch live side by side in one atlas; clip distances keep each pose in its tile.
_LABEL_VS = """
#version 330
uniform vec4 intr;        // fx, fy, cx + 0.5, cy + 0.5
uniform vec2 atlas;       // atlas width, height (pixels)
uniform vec2 tile;        // tile width, height (pixels)
uniform int cols;         // tiles per atlas row
uniform int nverts;       // vertices per pose
uniform vec2 near_far;
in vec3 in_pos;
in float in_value;
flat out float v_value;
#ifdef WITH_DEPTH
out float v_z;
#endif
out float gl_ClipDistance[4];
void main() {
    int t = gl_VertexID / nverts;
    vec2 origin = vec2(float(t % cols) * tile.x, float(t / cols) * tile.y);
    float X = in_pos.x, Y = in_pos.y, Z = in_pos.z;
    float wx = intr.x * X + intr.z * Z;     // (u + 0.5) * Z, tile-local
    float wy = intr.y * Y + intr.w * Z;
    gl_ClipDistance[0] = wx;
    gl_ClipDistance[1] = tile.x * Z - wx;
    gl_ClipDistance[2] = wy;
    gl_ClipDistance[3] = tile.y * Z - wy;
    float n = near_far.x, f = near_far.y;
    gl_Position = vec4(2.0 * (wx + origin.x * Z) / atlas.x - Z,
                       2.0 * (wy + origin.y * Z) / atlas.y - Z,
                       (f + n) / (f - n) * Z - 2.0 * f * n / (f - n),
                       Z);
    v_value = in_value;
#ifdef WITH_DEPTH
    v_z = Z;
#endif
}
"""

_LABEL_FS = """
#version 330
flat in float v_value;
layout(location = 0) out float out_value;
#ifdef WITH_DEPTH
in float v_z;
layout(location = 1) out float out_depth;
#endif
void main() {
    out_value = v_value;
#ifdef WITH_DEPTH
    out_depth = v_z;
#endif
}
"""


def _with_define(source: str, define: str) -> str:
    head, rest = source.split('\n', 2)[1], source.split('\n', 2)[2]
    return f'{head}\n#define {define}\n{rest}'


_SHADED_VS = """
#version 330
uniform vec4 intr;
uniform vec2 size;
uniform vec2 near_far;
in vec3 in_pos;
in vec3 in_normal;
out vec3 v_pos;
out vec3 v_normal;
void main() {
    float X = in_pos.x, Y = in_pos.y, Z = in_pos.z;
    float n = near_far.x, f = near_far.y;
    gl_Position = vec4(2.0 * (intr.x * X + intr.z * Z) / size.x - Z,
                       2.0 * (intr.y * Y + intr.w * Z) / size.y - Z,
                       (f + n) / (f - n) * Z - 2.0 * f * n / (f - n),
                       Z);
    v_pos = in_pos;
    v_normal = in_normal;
}
"""

_SHADED_FS = """
#version 330
uniform sampler2D face_rgb;
uniform vec3 light_dir;    // direction the light travels, camera frame, unit
uniform vec3 light_rgb;
uniform float ambient;
uniform bool smooth_normals;
in vec3 v_pos;
in vec3 v_normal;
layout(location = 0) out vec4 out_rgb;
void main() {
    int face = gl_PrimitiveID;
    ivec2 at = ivec2(face % 1024, face / 1024);
    vec3 albedo = texelFetch(face_rgb, at, 0).rgb;
    vec3 n = smooth_normals ? normalize(v_normal) : normalize(cross(dFdx(v_pos), dFdy(v_pos)));
    if (dot(n, v_pos) > 0.0) n = -n;       // face the camera (two-sided lighting)
    float diffuse = max(dot(n, -light_dir), 0.0);
    out_rgb = vec4(albedo * (ambient + (1.0 - ambient) * diffuse) * light_rgb, 1.0);
}
"""


_DOWN_VS = """
#version 330
void main() {
    vec2 p = vec2(float((gl_VertexID & 1) * 4 - 1), float((gl_VertexID >> 1) * 4 - 1));
    gl_Position = vec4(p, 0.0, 1.0);
}
"""

_DOWN_FS = """
#version 330
uniform sampler2D fine;
uniform int factor;
out vec4 out_rgb;
void main() {
    ivec2 base = ivec2(gl_FragCoord.xy) * factor;
    vec4 acc = vec4(0.0);
    for (int j = 0; j < factor; ++j)
        for (int i = 0; i < factor; ++i)
            acc += texelFetch(fine, base + ivec2(i, j), 0);
    out_rgb = acc / float(factor * factor);
}
"""


@dataclass
class ShadedImage:
    """One shaded frame: linear RGB premultiplied by coverage, coverage, per-pixel face
    values (patch id + 1, at pixel centres) and depth. Composite over a background with
    ``rgb + (1 - alpha) * background``."""

    rgb: np.ndarray        # (H, W, 3) float32 linear RGB x coverage, 0 on background
    alpha: np.ndarray      # (H, W) float32 coverage in [0, 1] (0/1 without MSAA)
    patch_ids: np.ndarray  # (H, W) uint8, 0 background, face value elsewhere
    depth: np.ndarray      # (H, W) float32 camera-frame Z in metres, 0 on background

    @property
    def mask(self) -> np.ndarray:
        """(H, W) bool: pixel centres covered by a rendered face."""
        return self.depth > 0


def _face_table(values: np.ndarray, components: int) -> tuple[np.ndarray, int]:
    """Pad a per-face table to a (rows, 1024, components) texture layout."""
    n = values.shape[0]
    rows = max(1, -(-n // _FACE_TEX_WIDTH))
    table = np.zeros((rows * _FACE_TEX_WIDTH, components), dtype=values.dtype)
    table[:n] = values.reshape(n, components)
    return table, rows


@dataclass
class _SplitMesh:
    """A mesh whose vertices are duplicated wherever faces of different values meet, so a
    flat per-vertex value gives per-face values (``gl_PrimitiveID`` is 2x slower on llvmpipe)."""

    vertex_map: np.ndarray   # (V',) index of the original vertex
    faces: np.ndarray        # (F, 3) int32 into the split vertices
    values: np.ndarray       # (V',) uint8 value of each split vertex


def _split_by_value(faces: np.ndarray, values: np.ndarray) -> _SplitMesh:
    corner_vertex = faces.ravel().astype(np.int64)
    corner_value = np.repeat(values.astype(np.int64), 3)
    keys = corner_vertex * 256 + corner_value
    uniq, inverse = np.unique(keys, return_inverse=True)
    return _SplitMesh((uniq // 256).astype(np.int64),
                      inverse.reshape(faces.shape).astype(np.int32),
                      (uniq % 256).astype(np.uint8))


class Renderer:
    """One EGL context and reusable framebuffers rendering (width x height) images for a
    :class:`PinholeCamera` (OpenCV optical frame; pixel centres match ``camera.project``).

    Label renders draw up to ``max_batch`` poses per pass as tiles of one atlas (one vertex
    buffer write, one draw call, one read per pass). With ``cull_back_faces`` (default)
    meshes must be closed with faces counter-clockwise seen from outside (as ``HandMesh``);
    culling halves the triangles llvmpipe sets up. Not thread-safe; one per thread."""

    def __init__(self, width: int, height: int, *, max_batch: int = 256,
                 near: float = 0.01, far: float = 20.0, cull_back_faces: bool = True,
                 supersample: int = 1, context: moderngl.Context | None = None) -> None:
        if width <= 0 or height <= 0:
            raise RenderError(f'renderer size must be positive, got {width}x{height}')
        if width > _MAX_ATLAS or height > _MAX_ATLAS:
            raise RenderError(f'renderer size {width}x{height} exceeds {_MAX_ATLAS}')
        if not 0.0 < near < far:
            raise RenderError(f'need 0 < near < far, got {near}, {far}')
        self.width, self.height = int(width), int(height)
        self.near, self.far = float(near), float(far)
        self.cull_back_faces = bool(cull_back_faces)
        if not 1 <= supersample <= 4:
            raise RenderError(f'supersample must be 1..4, got {supersample}')
        self.supersample = int(supersample)
        try:
            self.ctx = context or moderngl.create_standalone_context(backend='egl')
        except Exception as exc:  # moderngl raises plain Exception on EGL failures
            raise RenderError(f'cannot create an EGL OpenGL context: {exc}') from exc
        cols = max(1, min(_MAX_ATLAS // self.width, max_batch))
        rows = max(1, min(_MAX_ATLAS // self.height, -(-max_batch // cols)))
        self.cols, self.rows = cols, rows
        self.max_batch = cols * rows
        aw, ah = cols * self.width, rows * self.height
        with self.ctx:
            self._label_prog = self.ctx.program(vertex_shader=_LABEL_VS,
                                                fragment_shader=_LABEL_FS)
            self._label_depth_prog = self.ctx.program(
                vertex_shader=_with_define(_LABEL_VS, 'WITH_DEPTH'),
                fragment_shader=_with_define(_LABEL_FS, 'WITH_DEPTH'))
            self._shaded_prog = self.ctx.program(vertex_shader=_SHADED_VS,
                                                 fragment_shader=_SHADED_FS)
            self._atlas_value = self.ctx.texture((aw, ah), 1, dtype='f1')
            self._atlas_depth = self.ctx.texture((aw, ah), 1, dtype='f4')
            self._atlas_zbuf = self.ctx.depth_renderbuffer((aw, ah))
            self._atlas_fbo = self.ctx.framebuffer([self._atlas_value], self._atlas_zbuf)
            self._atlas_depth_fbo = self.ctx.framebuffer(
                [self._atlas_value, self._atlas_depth], self._atlas_zbuf)
            ss = self.supersample
            fine = (self.width * ss, self.height * ss)
            self._fine_rgb = self.ctx.texture(fine, 4, dtype='f4')
            self._fine_rgb.filter = (moderngl.NEAREST, moderngl.NEAREST)
            self._fine_fbo = self.ctx.framebuffer(
                [self._fine_rgb], self.ctx.depth_renderbuffer(fine))
            self._shade_rgb = self.ctx.texture((self.width, self.height), 4, dtype='f4')
            self._shade_fbo = self.ctx.framebuffer([self._shade_rgb])
            self._down_prog = self.ctx.program(vertex_shader=_DOWN_VS,
                                               fragment_shader=_DOWN_FS)
            self._down_vao = self.ctx.vertex_array(self._down_prog, [])
        # label geometry (depends on faces and face values), rebuilt when they change
        self._label_key: tuple | None = None
        self._split: _SplitMesh | None = None
        self._label_objs: list = []
        # shaded geometry (depends on faces), rebuilt when they change
        self._shaded_key: tuple | None = None
        self._shaded_objs: list = []
        self._rgb_key: bytes | None = None
        self._rgb_tex: moderngl.Texture | None = None

    # ------------------------------------------------------------------ helpers
    def release(self) -> None:
        """Free the GL context and everything in it."""
        self.ctx.release()

    def _set_state(self) -> None:
        if self.cull_back_faces:
            self.ctx.enable_only(moderngl.DEPTH_TEST | moderngl.CULL_FACE)
            # image rows run down but GL window rows up: outside-CCW faces appear clockwise
            self.ctx.front_face = 'cw'
            self.ctx.cull_face = 'back'
        else:
            self.ctx.enable_only(moderngl.DEPTH_TEST)

    def _check_camera(self, camera: PinholeCamera) -> None:
        if (camera.width, camera.height) != (self.width, self.height):
            raise RenderError(f'camera is {camera.width}x{camera.height} but the renderer '
                              f'is {self.width}x{self.height}')

    @staticmethod
    def _intrinsics(camera: PinholeCamera) -> tuple[float, float, float, float]:
        return (float(camera.fx), float(camera.fy), float(camera.cx) + 0.5,
                float(camera.cy) + 0.5)

    @staticmethod
    def _check_faces(faces: np.ndarray, num_vertices: int) -> np.ndarray:
        faces = np.ascontiguousarray(faces, dtype=np.int32)
        if faces.ndim != 2 or faces.shape[1] != 3:
            raise RenderError(f'faces must be (F, 3), got {faces.shape}')
        if faces.size and (faces.min() < 0 or faces.max() >= num_vertices):
            raise RenderError('faces index outside the vertex array')
        return faces

    def _prepare_label_mesh(self, faces: np.ndarray, values: np.ndarray,
                            num_vertices: int) -> _SplitMesh:
        faces = self._check_faces(faces, num_vertices)
        values = np.ascontiguousarray(values, dtype=np.uint8)
        if values.shape != (faces.shape[0],):
            raise RenderError(f'need one value per face ({faces.shape[0]}), got {values.shape}')
        key = (num_vertices, faces.shape[0], hash(faces.tobytes()), hash(values.tobytes()))
        if key == self._label_key and self._split is not None:
            return self._split
        for obj in self._label_objs:
            obj.release()
        split = _split_by_value(faces, values)
        nv, b = len(split.vertex_map), self.max_batch
        offsets = (np.arange(b, dtype=np.int32) * nv)[:, None, None]
        vbo = self.ctx.buffer(reserve=b * nv * 12)
        vals = self.ctx.buffer(np.tile(split.values, b).tobytes())
        ibo = self.ctx.buffer((split.faces[None] + offsets).astype(np.int32).tobytes())
        attrs = [(vbo, '3f', 'in_pos'), (vals, 'f1', 'in_value')]
        vao = self.ctx.vertex_array(self._label_prog, attrs, index_buffer=ibo,
                                    index_element_size=4)
        vao_depth = self.ctx.vertex_array(self._label_depth_prog, attrs, index_buffer=ibo,
                                          index_element_size=4)
        self._label_objs = [vao, vao_depth, vbo, vals, ibo]
        self._label_vbo, self._label_vao, self._label_depth_vao = vbo, vao, vao_depth
        self._split, self._label_key = split, key
        self._gather_buf = np.empty((b, nv, 3), np.float32)
        return split

    def _prepare_shaded_mesh(self, faces: np.ndarray, num_vertices: int) -> int:
        faces = self._check_faces(faces, num_vertices)
        key = (num_vertices, faces.shape[0], hash(faces.tobytes()))
        if key != self._shaded_key:
            for obj in self._shaded_objs:
                obj.release()
            vbo = self.ctx.buffer(reserve=num_vertices * 12)
            nbo = self.ctx.buffer(reserve=num_vertices * 12)
            ibo = self.ctx.buffer(faces.tobytes())
            vao = self.ctx.vertex_array(
                self._shaded_prog, [(vbo, '3f', 'in_pos'), (nbo, '3f', 'in_normal')],
                index_buffer=ibo, index_element_size=4)
            self._shaded_objs = [vao, vbo, nbo, ibo]
            self._shaded_vbo, self._shaded_nbo, self._shaded_vao = vbo, nbo, vao
            self._shaded_key = key
        return faces.shape[0]

    def _prepare_rgb(self, face_rgb: np.ndarray, num_faces: int) -> None:
        rgb = np.ascontiguousarray(face_rgb, dtype=np.float32)
        if rgb.shape != (num_faces, 3):
            raise RenderError(f'face_rgb must be ({num_faces}, 3), got {rgb.shape}')
        key = rgb.tobytes()
        if key == self._rgb_key:
            return
        table, rows = _face_table(rgb, 3)
        table4 = np.concatenate([table, np.ones((len(table), 1), np.float32)], axis=1)
        if self._rgb_tex is None or self._rgb_tex.size != (_FACE_TEX_WIDTH, rows):
            if self._rgb_tex is not None:
                self._rgb_tex.release()
            self._rgb_tex = self.ctx.texture((_FACE_TEX_WIDTH, rows), 4, dtype='f4')
            self._rgb_tex.filter = (moderngl.NEAREST, moderngl.NEAREST)
        self._rgb_tex.write(table4.tobytes())
        self._rgb_key = key

    # ------------------------------------------------------------------ label renders
    def render_face_values(self, vertices: np.ndarray, faces: np.ndarray,
                           face_values: np.ndarray, camera: PinholeCamera, *,
                           with_depth: bool = False
                           ) -> np.ndarray | tuple[np.ndarray, np.ndarray]:
        """Rasterise (B, V, 3) camera-frame poses sharing ``faces``; each pixel takes the
        uint8 value of its nearest face (0 = nothing). Returns (B, H, W) uint8, and with
        ``with_depth`` also (B, H, W) float32 camera Z (0 where nothing)."""
        verts = np.asarray(vertices, dtype=np.float32)
        if verts.ndim == 2:
            verts = verts[None]
        if verts.ndim != 3 or verts.shape[2] != 3:
            raise RenderError(f'vertices must be (B, V, 3), got {verts.shape}')
        self._check_camera(camera)
        n_pose, n_vert = verts.shape[:2]
        out = np.empty((n_pose, self.height, self.width), dtype=np.uint8)
        depth = np.empty((n_pose, self.height, self.width), np.float32) if with_depth else None
        with self.ctx:
            split = self._prepare_label_mesh(faces, face_values, n_vert)
            prog = self._label_depth_prog if with_depth else self._label_prog
            vao = self._label_depth_vao if with_depth else self._label_vao
            fbo = self._atlas_depth_fbo if with_depth else self._atlas_fbo
            prog['intr'].value = self._intrinsics(camera)
            prog['atlas'].value = (float(self.cols * self.width), float(self.rows * self.height))
            prog['tile'].value = (float(self.width), float(self.height))
            prog['cols'].value = self.cols
            prog['nverts'].value = len(split.vertex_map)
            prog['near_far'].value = (self.near, self.far)
            self._set_state()
            for i in range(4):  # gl_ClipDistance[i] needs GL_CLIP_DISTANCEi enabled
                self.ctx.enable_direct(_GL_CLIP_DISTANCE0 + i)
            fbo.use()
            fbo.viewport = (0, 0, self.cols * self.width, self.rows * self.height)
            n_tri = len(split.faces) * 3
            try:
                for start in range(0, n_pose, self.max_batch):
                    chunk = verts[start:start + self.max_batch]
                    nb = len(chunk)
                    used_rows = -(-nb // self.cols)
                    used_cols = self.cols if used_rows > 1 else nb
                    used_vp = (0, 0, used_cols * self.width, used_rows * self.height)
                    fbo.clear(0.0, 0.0, 0.0, 0.0, depth=1.0, viewport=used_vp)
                    gathered = self._gather_buf[:nb]
                    np.take(chunk, split.vertex_map, axis=1, out=gathered)
                    self._label_vbo.write(gathered)
                    vao.render(moderngl.TRIANGLES, vertices=nb * n_tri)
                    self._unpack(fbo.read(used_vp, components=1, dtype='f1', attachment=0),
                                 out, start, nb, used_rows, used_cols, np.uint8)
                    if depth is not None:
                        self._unpack(fbo.read(used_vp, components=1, dtype='f4',
                                              attachment=1),
                                     depth, start, nb, used_rows, used_cols, np.float32)
            finally:
                for i in range(4):
                    self.ctx.disable_direct(_GL_CLIP_DISTANCE0 + i)
        return (out, depth) if depth is not None else out

    def _unpack(self, raw: bytes, out: np.ndarray, start: int, nb: int, rows: int, cols: int,
                dtype: type) -> None:
        h, w = self.height, self.width
        atlas = np.frombuffer(raw, dtype=dtype).reshape(rows, h, cols, w)
        out[start:start + nb] = atlas.transpose(0, 2, 1, 3).reshape(rows * cols, h, w)[:nb]

    def render_patch_ids(self, vertices: np.ndarray, faces: np.ndarray,
                         face_patch: np.ndarray, camera: PinholeCamera) -> np.ndarray:
        """(B, H, W) uint8 patch-id images: 0 background, ``face_patch + 1`` elsewhere.
        Faces with a negative patch (e.g. a forearm) occlude but read as background."""
        return self.render_face_values(vertices, faces, _patch_values(face_patch), camera)

    def render_patch_ids_depth(self, vertices: np.ndarray, faces: np.ndarray,
                               face_patch: np.ndarray, camera: PinholeCamera
                               ) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`render_patch_ids` plus (B, H, W) float32 camera Z (0 on background)."""
        ids, depth = self.render_face_values(vertices, faces, _patch_values(face_patch),
                                             camera, with_depth=True)
        return ids, depth

    def render_labels(self, vertices: np.ndarray, faces: np.ndarray, face_patch: np.ndarray,
                      patch_color: np.ndarray, camera: PinholeCamera) -> np.ndarray:
        """(B, H, W) uint8 label images (0 background, ``patch_color[p]`` on patch p),
        rasterised directly with per-face colour labels."""
        fp = np.asarray(face_patch)
        values = np.where(fp >= 0, np.asarray(patch_color, np.int64)[np.maximum(fp, 0)], 0)
        return self.render_face_values(vertices, faces, values.astype(np.uint8), camera)

    # ------------------------------------------------------------------ shaded render
    def render_shaded(self, vertices: np.ndarray, faces: np.ndarray, face_rgb: np.ndarray,
                      camera: PinholeCamera, *, light_dir: np.ndarray = (0.3, 0.5, 1.0),
                      ambient: float = 0.35, light_rgb: np.ndarray = (1.0, 1.0, 1.0),
                      face_patch: np.ndarray | None = None,
                      normals: np.ndarray | None = None) -> ShadedImage:
        """Lambert-shaded render of one (V, 3) camera-frame mesh with per-face linear albedo
        ``face_rgb`` (F, 3): ``albedo * light_rgb * (ambient + (1 - ambient) * max(n.l, 0))``.
        ``light_dir`` is the direction the light travels (camera frame); ``normals`` (V, 3)
        gives smooth shading, None flat per-face normals. With ``supersample`` s > 1 the
        colour is the mean of s x s samples per pixel (coverage in ``alpha``). The patch-id
        image uses ``face_patch`` (0 where a face has patch < 0 or none is given)."""
        verts = np.ascontiguousarray(vertices, dtype=np.float32)
        if verts.ndim != 2 or verts.shape[1] != 3:
            raise RenderError(f'vertices must be (V, 3), got {verts.shape}')
        self._check_camera(camera)
        light = np.asarray(light_dir, dtype=np.float64)
        if not np.linalg.norm(light) > 0:
            raise RenderError('light_dir must be non-zero')
        light = light / np.linalg.norm(light)
        nrm = None
        if normals is not None:
            nrm = np.ascontiguousarray(normals, dtype=np.float32)
            if nrm.shape != verts.shape:
                raise RenderError(f'normals must be {verts.shape}, got {nrm.shape}')
        n_faces = len(np.asarray(faces))
        values = (_patch_values(face_patch) if face_patch is not None
                  else np.zeros(n_faces, np.uint8))
        ids, depth = self.render_face_values(verts[None], faces, values, camera,
                                             with_depth=True)
        with self.ctx:
            self._prepare_shaded_mesh(faces, len(verts))
            self._prepare_rgb(face_rgb, n_faces)
            prog = self._shaded_prog
            ss = self.supersample
            fx, fy, cx, cy = self._intrinsics(camera)
            prog['intr'].value = (fx * ss, fy * ss, cx * ss, cy * ss)
            prog['size'].value = (float(self.width * ss), float(self.height * ss))
            prog['near_far'].value = (self.near, self.far)
            prog['light_dir'].value = tuple(float(x) for x in light)
            prog['light_rgb'].value = tuple(float(x) for x in np.asarray(light_rgb, float))
            prog['ambient'].value = float(ambient)
            prog['smooth_normals'].value = nrm is not None
            prog['face_rgb'].value = 0
            self._rgb_tex.use(0)
            self._shaded_vbo.write(verts)
            if nrm is not None:
                self._shaded_nbo.write(nrm)
            self._set_state()
            fbo = self._fine_fbo
            fbo.use()
            fbo.viewport = (0, 0, self.width * ss, self.height * ss)
            fbo.clear(0.0, 0.0, 0.0, 0.0, depth=1.0)
            self._shaded_vao.render(moderngl.TRIANGLES)
            # box-filter the s x s samples of every pixel into the output texture
            self.ctx.enable_only(moderngl.NOTHING)
            self._shade_fbo.use()
            self._shade_fbo.viewport = (0, 0, self.width, self.height)
            self._fine_rgb.use(0)
            self._down_prog['fine'].value = 0
            self._down_prog['factor'].value = ss
            self._down_vao.render(moderngl.TRIANGLES, vertices=3)
            rgba = np.empty((self.height, self.width, 4), np.float32)
            self._shade_fbo.read_into(rgba, components=4, dtype='f4', attachment=0)
        return ShadedImage(rgba[..., :3], rgba[..., 3], ids[0], depth[0])


def _patch_values(face_patch: np.ndarray) -> np.ndarray:
    fp = np.asarray(face_patch, dtype=np.int64)
    if fp.size and fp.max() > 254:
        raise RenderError(f'patch ids must be <= 254, got {fp.max()}')
    return np.where(fp >= 0, fp + 1, 0).astype(np.uint8)
