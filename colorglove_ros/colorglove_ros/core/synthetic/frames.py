"""Synthetic camera frames of the gloved hand with ground truth (:class:`Synthesizer`), also
seen by several calibrated cameras at once.

Image formation (all in linear RGB, then the camera's sRGB encoding):

* the glove (``GLOVE_PALETTE_RGB`` decoded from sRGB, times ``GLOVE_ALBEDO``) and a forearm
  sleeve are Lambert-shaded (smooth normals, one directional light plus ambient), rendered
  with 2 x 2 samples per pixel so silhouettes blend with the background as in a real camera;
* the light has a colour temperature (its residual cast relative to the camera's white
  balance at ``WHITE_BALANCE_K``, ``core/colorimetry.py``) and a level (``gain``, exposure
  included) that apply to the hand and the background alike;
* a background (``backgrounds.py``: procedural desk, clutter, noise or office, or a real
  photograph; some saturated glove-like colours, never over the hand; optionally other
  people's bare hands, arms and faces), slightly defocused;
* optional linear motion blur of the hand layer, vignetting, shot + read noise, the camera's
  colour processing (white-balance error, saturation, gamma and contrast: identity by
  default), clipping, sRGB gamma, 8-bit quantisation and optional JPEG compression.

Ground truth: ``labels`` (0 background, 1..10 glove colour) and ``patch_ids`` (0 background,
patch + 1) are the visible glove at each pixel centre, from the unblurred geometry. The
imaging conditions and their 'train' / 'test' splits are in ``conditions.py``; seeded motion
sequences in ``sequences.py``.
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace
from functools import lru_cache

import cv2
import numpy as np

from colorglove_ros.core.camera import PinholeCamera
from colorglove_ros.core.colorimetry import (
    LUMINANCE_WEIGHTS,
    illuminant_rgb,
    linear_to_srgb,
    srgb_to_linear,
)
from colorglove_ros.core.conventions import DEFAULT_HAND_LENGTH_M, NUM_PATCHES
from colorglove_ros.core.geometry import matrix_to_rotvec, rotvec_to_matrix
from colorglove_ros.core.hand.glove import GLOVE_PALETTE_RGB, Glove, default_hand
from colorglove_ros.core.hand.handedness import (
    DEFAULT_HAND,
    check_hand,
    hand_faces,
    hand_keypoints,
    mirror_points,
    to_right_frame,
)
from colorglove_ros.core.hand.mesh import HandMesh
from colorglove_ros.core.hand.model import NUM_DOFS, HandModel
from colorglove_ros.core.hand.poses import pose_collection, sample_global_rotations
from colorglove_ros.core.synthetic.backgrounds import scene_background
from colorglove_ros.core.synthetic.conditions import (
    GLOVE_ALBEDO,
    FrameConditions,
    SynthError,
    sample_conditions,
)
from colorglove_ros.core.synthetic.forearm import forearm_mesh
from colorglove_ros.core.synthetic.mesh_images import patch_ids_to_labels, vertex_normals
from colorglove_ros.core.synthetic.render import Renderer

__all__ = [
    'SyntheticFrame', 'Synthesizer', 'render_frame', 'render_frames_multi', 'sample_pose',
    'default_camera', 'transform_pose', 'natural_finger_shapes', 'primary_to_camera',
    'view_of_scene', 'view_background_seed', 'camera_encode',
]

@dataclass
class SyntheticFrame:
    """A rendered camera frame and its ground truth (all in this camera's optical frame)."""

    image_rgb: np.ndarray      # (H, W, 3) uint8 sRGB
    labels: np.ndarray         # (H, W) uint8: 0 background, 1..10 glove colour
    patch_ids: np.ndarray      # (H, W) uint8: 0 background, patch id + 1
    pose: np.ndarray           # (26,) q in this camera's frame
    keypoints_3d: np.ndarray   # (21, 3) metres, camera frame
    keypoints_2d: np.ndarray   # (21, 2) pixels (with the camera's distortion)
    camera: PinholeCamera
    conditions: FrameConditions


# ----------------------------------------------------------------------------- sensor
_SRGB8_LUT = np.round(linear_to_srgb(np.arange(65536) / 65535.0, np.float32) * 255.0
                      ).astype(np.uint8)


def _encode_srgb8(c: np.ndarray, lut: np.ndarray = _SRGB8_LUT) -> np.ndarray:
    """Linear float image -> clipped, sRGB-encoded uint8 (16-bit look-up table)."""
    idx = (np.clip(c, 0.0, 1.0) * 65535.0 + 0.5).astype(np.uint16)
    return lut[idx]


@lru_cache(maxsize=64)
def _tone_lut(gamma: float, contrast: float) -> np.ndarray:
    """The sRGB look-up table followed by the tone curve ``v ** (1 / gamma)`` and the
    S-curve ``v + contrast * v (1 - v) (2 v - 1)`` (monotonic for contrast in [-1, 1])."""
    v = linear_to_srgb(np.arange(65536) / 65535.0) ** (1.0 / gamma)
    v = v + contrast * v * (1.0 - v) * (2.0 * v - 1.0)
    lut = np.round(np.clip(v, 0.0, 1.0) * 255.0).astype(np.uint8)
    lut.setflags(write=False)
    return lut


def camera_encode(linear: np.ndarray, conditions: FrameConditions) -> np.ndarray:
    """A linear sensor image (noise included) -> the camera's 8-bit sRGB: the colour
    processing of ``conditions`` (white-balance gains, saturation about the luminance, then
    the gamma and contrast tone curve on the encoded values), clipping and quantisation.
    With the default conditions it is the plain sRGB encoding."""
    if not conditions.processes_color:
        return _encode_srgb8(linear)
    img = linear * np.asarray(conditions.white_balance_gains, np.float32)
    if conditions.saturation != 1.0:
        luma = img @ LUMINANCE_WEIGHTS.astype(np.float32)
        img = luma[..., None] + np.float32(conditions.saturation) * (img - luma[..., None])
    return _encode_srgb8(img, _tone_lut(float(conditions.gamma), float(conditions.contrast)))


# ----------------------------------------------------------------------------- geometry
def default_camera() -> PinholeCamera:
    """The 640x480, fx = fy = 600 camera of ``config/calibration.yaml``."""
    return PinholeCamera(640, 480, 600.0, 600.0, 319.5, 239.5)


def transform_pose(q: np.ndarray, rotation: np.ndarray, translation: np.ndarray) -> np.ndarray:
    """Express pose q in another frame: ``p' = rotation @ p + translation``."""
    q = np.asarray(q, dtype=float).copy()
    q[0:3] = rotation @ q[0:3] + translation
    q[3:6] = matrix_to_rotvec(rotation @ rotvec_to_matrix(q[3:6]))
    return q


@lru_cache(maxsize=4)
def natural_finger_shapes(seed: int) -> np.ndarray:
    """(4000, 20) natural finger configurations (``pose_collection``), cached per seed."""
    return pose_collection(seed=seed, size=4000)


def sample_pose(rng: np.random.Generator, camera: PinholeCamera | None = None, *,
                model: HandModel | None = None, depth_range: tuple[float, float] = (0.4, 0.7),
                out_of_frame_prob: float = 0.1, back_fraction: float = 0.0) -> np.ndarray:
    """A random natural pose (26,) whose hand centre projects into the image (or, with
    probability ``out_of_frame_prob``, near its border so the hand is partly outside)."""
    camera = default_camera() if camera is None else camera
    model = default_hand()[0] if model is None else model
    coll = natural_finger_shapes(0)
    q = model.rest_pose()
    q[6:] = coll[rng.integers(len(coll))]
    q[3:6] = sample_global_rotations(rng, 1, back_fraction=back_fraction)[0]
    q[0:3] = 0.0
    centre = model.keypoints(q).mean(axis=0)     # hand centre relative to the wrist
    z = rng.uniform(*depth_range)
    if rng.uniform() < out_of_frame_prob:
        side = rng.integers(4)
        u = [rng.uniform(-0.05, 0.05), rng.uniform(0.95, 1.05)][side % 2] * camera.width \
            if side < 2 else rng.uniform(0.1, 0.9) * camera.width
        v = [rng.uniform(-0.05, 0.05), rng.uniform(0.95, 1.05)][side % 2] * camera.height \
            if side >= 2 else rng.uniform(0.1, 0.9) * camera.height
    else:
        u = rng.uniform(0.25, 0.75) * camera.width
        v = rng.uniform(0.25, 0.75) * camera.height
    target = np.array([(u - camera.cx) / camera.fx * z, (v - camera.cy) / camera.fy * z, z])
    q[0:3] = target - centre
    return q


# ----------------------------------------------------------------------------- synthesiser
class Synthesizer:
    """Renders :class:`SyntheticFrame` s of one glove (hand model, mesh, glove from
    ``default_hand``) plus a forearm sleeve; keeps a :class:`Renderer` per image size.
    ``hand`` 'left' renders the left hand wearing the mirror-image glove: the right mesh and
    pattern mirrored in the hand frame (``core.hand.handedness``), so a pose means the same
    finger angles for either hand; :meth:`render_hands` puts several hands in one frame."""

    def __init__(self, hand_length_m: float = DEFAULT_HAND_LENGTH_M, glove_seed: int = 0,
                 supersample: int = 2, hand: tuple[HandModel, HandMesh, Glove] | None = None,
                 handedness: str = DEFAULT_HAND) -> None:
        self.model, self.mesh, self.glove = hand or default_hand(hand_length_m, glove_seed)
        self.handedness = check_hand(handedness)
        self.supersample = int(supersample)
        arm_v, arm_f = forearm_mesh(self.model)
        nv = self.mesh.num_vertices
        self._arm_local = arm_v
        self.faces = np.concatenate([self.mesh.faces, arm_f + nv]).astype(np.int32)
        self.face_patch = np.concatenate([self.glove.face_patch,
                                          np.full(len(arm_f), -1)]).astype(np.int64)
        palette = srgb_to_linear(GLOVE_PALETTE_RGB / 255.0) * GLOVE_ALBEDO
        self._glove_rgb = palette[self.glove.face_labels.astype(np.int64) - 1].astype(np.float32)
        self._num_arm_faces = len(arm_f)
        self._renderers: dict[tuple[int, int], Renderer] = {}
        self._distortion_maps: dict[tuple, tuple[np.ndarray, np.ndarray]] = {}

    def renderer(self, width: int, height: int) -> Renderer:
        """The cached renderer for an image size."""
        key = (int(width), int(height))
        if key not in self._renderers:
            self._renderers[key] = Renderer(*key, max_batch=16,
                                            supersample=self.supersample)
        return self._renderers[key]

    def vertices(self, q: np.ndarray, hand: str | None = None) -> np.ndarray:
        """(V, 3) camera-frame vertices of hand + forearm for pose q (of ``hand``, default
        the synthesiser's)."""
        q = np.asarray(q, dtype=float)
        if q.shape != (NUM_DOFS,):
            raise SynthError(f'pose must have shape (26,), got {q.shape}')
        hand = self.handedness if hand is None else check_hand(hand)
        right = to_right_frame(q, hand)
        skin = self.mesh.skin(self.model, right)
        R = rotvec_to_matrix(right[3:6])
        verts = np.concatenate([skin, self._arm_local @ R.T + right[0:3]])
        return (verts if hand == 'right' else mirror_points(verts)).astype(np.float32)

    def keypoints(self, q: np.ndarray, hand: str | None = None) -> np.ndarray:
        """(..., 21, 3) camera-frame keypoints of pose(s) q (of ``hand``, default the
        synthesiser's)."""
        return hand_keypoints(self.model, q, self.handedness if hand is None else hand)

    def render_frame(self, q: np.ndarray, camera: PinholeCamera, rng: np.random.Generator,
                     conditions: FrameConditions | None = None) -> SyntheticFrame:
        """One synthetic frame of pose q (camera frame) seen by ``camera``; ``rng`` draws
        the sensor noise (and the conditions when ``conditions`` is None)."""
        return self.render_hands([(q, self.handedness)], camera, rng, conditions)[0]

    def render_hands(self, hands: Sequence[tuple[np.ndarray, str]], camera: PinholeCamera,
                     rng: np.random.Generator, conditions: FrameConditions | None = None
                     ) -> tuple[SyntheticFrame, np.ndarray]:
        """One frame showing every (pose, 'right' or 'left') of ``hands``, each with its
        sleeve; the frame's pose and keypoints are the first hand's. Also returns the
        (H, W) uint8 image of which hand's glove is visible at each pixel centre (0 none,
        k + 1 for ``hands[k]``)."""
        if not 1 <= len(hands) <= 254 // NUM_PATCHES:
            raise SynthError(f'need 1..{254 // NUM_PATCHES} hands, got {len(hands)}')
        conditions = sample_conditions(rng, 'train') if conditions is None else conditions
        nv = self.mesh.num_vertices + len(self._arm_local)
        parts = [(self.vertices(q, hand), hand) for q, hand in hands]
        verts = np.concatenate([v for v, _ in parts])
        faces = np.concatenate([hand_faces(self.faces, hand) + k * nv
                                for k, (_, hand) in enumerate(parts)]).astype(np.int32)
        face_patch = np.concatenate([np.where(self.face_patch >= 0,
                                              self.face_patch + k * NUM_PATCHES, -1)
                                     for k in range(len(parts))])
        w, h = camera.width, camera.height
        ideal = PinholeCamera(w, h, camera.fx, camera.fy, camera.cx, camera.cy)
        sleeve = np.tile(np.asarray(conditions.sleeve_rgb, np.float32), (self._num_arm_faces, 1))
        face_rgb = np.tile(np.concatenate([self._glove_rgb, sleeve]), (len(parts), 1))
        light = illuminant_rgb(conditions.color_temperature_k) * conditions.gain
        shaded = self.renderer(w, h).render_shaded(
            verts, faces, face_rgb, ideal, light_dir=conditions.light_dir,
            ambient=conditions.ambient, light_rgb=light, face_patch=face_patch,
            normals=vertex_normals(verts, faces))
        ids, rgb, alpha = shaded.patch_ids, shaded.rgb, shaded.alpha
        if conditions.blur_px >= 1.0:
            kernel = _motion_kernel(conditions.blur_px, conditions.blur_angle)
            rgb = cv2.filter2D(rgb, -1, kernel, borderType=cv2.BORDER_CONSTANT)
            alpha = cv2.filter2D(alpha, -1, kernel, borderType=cv2.BORDER_CONSTANT)
        # background, lit by the same light
        ys, xs = np.nonzero(ids)
        keep_out = None
        if len(xs) and conditions.distractors_avoid_hand:
            keep_out = (int(xs.min()), int(ys.min()), int(xs.max()), int(ys.max()))
        bg, light_field = scene_background(conditions, w, h, keep_out)
        bg *= light_field * light.astype(np.float32)
        img = rgb + (1.0 - alpha[..., None]) * bg
        # optics (lens distortion, vignetting) then the sensor
        if np.any(camera.distortion):
            img, ids = self._distort(camera, img, ids)
        yy, xx = np.mgrid[0:h, 0:w].astype(np.float32)
        r2 = ((xx - camera.cx) ** 2 + (yy - camera.cy) ** 2) / (0.25 * (w**2 + h**2))
        img = img * (1.0 - conditions.vignetting * r2)[..., None]
        sigma = conditions.noise_sigma * np.sqrt(1.0 + 8.0 * np.clip(img, 0.0, None))
        img = img + sigma * rng.standard_normal(img.shape, dtype=np.float32)
        out = camera_encode(img, conditions)
        if conditions.jpeg_quality > 0:
            ok, enc = cv2.imencode('.jpg', out[..., ::-1],
                                   [cv2.IMWRITE_JPEG_QUALITY, int(conditions.jpeg_quality)])
            if not ok:
                raise SynthError('JPEG encoding failed')
            out = cv2.imdecode(enc, cv2.IMREAD_COLOR)[..., ::-1].copy()
        which = np.where(ids > 0, (ids.astype(np.int64) - 1) // NUM_PATCHES + 1, 0)
        ids = np.where(ids > 0, (ids.astype(np.int64) - 1) % NUM_PATCHES + 1, 0).astype(np.uint8)
        q, hand = np.asarray(hands[0][0], dtype=float), hands[0][1]
        kp3 = self.keypoints(q, hand)
        kp2 = _project_distorted(camera, kp3)
        frame = SyntheticFrame(out, patch_ids_to_labels(ids, self.glove.patch_color), ids, q,
                               kp3, kp2, camera, conditions)
        return frame, which.astype(np.uint8)

    def _distort(self, camera: PinholeCamera, img: np.ndarray, ids: np.ndarray
                 ) -> tuple[np.ndarray, np.ndarray]:
        key = (camera.width, camera.height, camera.fx, camera.fy, camera.cx, camera.cy,
               tuple(np.asarray(camera.distortion, float)))
        if key not in self._distortion_maps:
            ys, xs = np.mgrid[0:camera.height, 0:camera.width].astype(np.float64)
            pix = np.stack([xs.ravel(), ys.ravel()], 1)
            und = camera.undistort_pixels(pix).reshape(camera.height, camera.width, 2)
            self._distortion_maps[key] = (und[..., 0].astype(np.float32),
                                          und[..., 1].astype(np.float32))
        mx, my = self._distortion_maps[key]
        img = cv2.remap(img, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
        ids = cv2.remap(ids, mx, my, cv2.INTER_NEAREST, borderMode=cv2.BORDER_CONSTANT)
        return img, ids

    def release(self) -> None:
        """Free the renderers' GL contexts."""
        for r in self._renderers.values():
            r.release()
        self._renderers.clear()


def _motion_kernel(length: float, angle: float) -> np.ndarray:
    size = int(np.ceil(length)) | 1
    k = np.zeros((size, size), np.float32)
    c = size // 2
    d = np.array([np.cos(angle), np.sin(angle)]) * (length - 1) / 2.0
    for t in np.linspace(-1.0, 1.0, 4 * size):
        x, y = c + t * d
        k[int(round(y)), int(round(x))] += 1.0
    return k / k.sum()


def _project_distorted(camera: PinholeCamera, points: np.ndarray) -> np.ndarray:
    if not np.any(camera.distortion):
        return camera.project(points)
    uv, _ = cv2.projectPoints(np.asarray(points, np.float64).reshape(-1, 1, 3), np.zeros(3),
                              np.zeros(3), camera.K, np.asarray(camera.distortion, float))
    return uv.reshape(-1, 2)


@lru_cache(maxsize=2)
def _default_synthesizer() -> Synthesizer:
    return Synthesizer()


def render_frame(q: np.ndarray, camera: PinholeCamera, rng: np.random.Generator,
                 conditions: FrameConditions | None = None, *,
                 synthesizer: Synthesizer | None = None) -> SyntheticFrame:
    """One synthetic frame (see :class:`Synthesizer`); a shared default synthesiser
    (``DEFAULT_HAND_LENGTH_M`` hand, glove seed 0) is used unless one is given."""
    synth = _default_synthesizer() if synthesizer is None else synthesizer
    return synth.render_frame(q, camera, rng, conditions)


def primary_to_camera(cameras: Sequence[PinholeCamera], k: int
                ) -> tuple[np.ndarray, np.ndarray] | None:
    """(R, t) taking the first camera's optical frame to camera ``k``'s (``p_k = R p + t``);
    None for the first camera itself, whose poses and points are used unchanged."""
    if k == 0:
        return None
    R = cameras[k].rotation @ cameras[0].rotation.T
    return R, cameras[k].translation - R @ cameras[0].translation


def view_background_seed(seed: int, k: int) -> int:
    """Background seed of camera ``k`` in a scene whose first camera's seed is ``seed``."""
    return (int(seed) + 7919 * int(k)) % (1 << 31)


def view_of_scene(q: np.ndarray, conditions: FrameConditions, cameras: Sequence[PinholeCamera],
          k: int) -> tuple[np.ndarray, FrameConditions]:
    """Camera ``k``'s pose and conditions of a scene given in the first camera's terms: the
    pose and light direction in camera ``k``'s frame, the background seed offset by the
    camera index (the first camera's are ``q`` and ``conditions`` unchanged)."""
    extrinsics = primary_to_camera(cameras, k)
    if extrinsics is None:
        return np.asarray(q, dtype=float), conditions
    R, t = extrinsics
    light = R @ np.asarray(conditions.light_dir, float)
    return transform_pose(q, R, t), replace(
        conditions, light_dir=tuple(float(v) for v in light),
        background_seed=view_background_seed(conditions.background_seed, k))


def render_frames_multi(q: np.ndarray, cameras: Sequence[PinholeCamera],
                        rng: np.random.Generator, conditions: FrameConditions | None = None,
                        *, synthesizer: Synthesizer | None = None) -> list[SyntheticFrame]:
    """One scene seen by several calibrated cameras. ``q`` is in the first camera's optical
    frame; each frame's ``pose`` and keypoints are in its own camera's frame. Lighting is
    shared (the light direction rotates with each view); each view sees its own background
    (seed offset by the camera index) and noise (drawn from ``rng`` camera by camera, so the
    first view is ``render_frame(q, cameras[0], rng, conditions)``)."""
    if not cameras:
        raise SynthError('need at least one camera')
    conditions = sample_conditions(rng, 'train') if conditions is None else conditions
    frames = []
    for k, cam in enumerate(cameras):
        qk, cond = view_of_scene(q, conditions, cameras, k)
        frames.append(render_frame(qk, cam, rng, cond, synthesizer=synthesizer))
    return frames


