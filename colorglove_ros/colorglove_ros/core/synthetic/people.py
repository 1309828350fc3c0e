"""Other people behind the gloved hand, as background layers of real skin: bare hands with
their forearms (the hand mesh in a natural pose, skin-shaded and painted far to near, no
OpenGL) and heads with shoulders (cut from a photo of a person of the split, or drawn).

:func:`people_layers` gives a seed's layers (1-3, at most one head), deterministic and cached;
the split of the seed (``background_seed_split``) picks the person photos. Each layer is a
premultiplied linear-albedo image with its coverage, slightly defocused like the background;
the light and colour of the scene are applied later with the background's."""
from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import cv2
import numpy as np

from colorglove_ros.core.colorimetry import srgb_to_linear
from colorglove_ros.core.geometry import rotvec_to_matrix
from colorglove_ros.core.hand.glove import default_hand
from colorglove_ros.core.hand.poses import pose_collection, sample_global_rotations
from colorglove_ros.core.synthetic.conditions import background_seed_split
from colorglove_ros.core.synthetic.forearm import forearm_mesh
from colorglove_ros.core.synthetic.mesh_images import vertex_normals
from colorglove_ros.core.synthetic.photos import PersonRegion, load_photo, load_photo_manifest

__all__ = ['SkinLayer', 'people_layers', 'skin_tone_albedo', 'NOMINAL_FOCAL_PER_WIDTH']

NOMINAL_FOCAL_PER_WIDTH = 600.0 / 640.0   # the default camera's focal length / image width
ARM_PROBABILITY = 0.65        # each layer is a bare hand and forearm, else a head (at most one)
PERSON_PHOTO_PROBABILITY = 0.7   # a head is cut from a person photo of the split, else drawn
_SUPERSAMPLE = 2
# hair colours (linear albedo): black, dark brown, auburn, blond, grey
_HAIR = np.array([[0.012, 0.01, 0.008], [0.05, 0.025, 0.012], [0.14, 0.045, 0.015],
                  [0.35, 0.24, 0.1], [0.3, 0.3, 0.3]])
# clothing colours (linear albedo): black, navy, grey, white, dark red, olive
_CLOTHES = np.array([[0.02, 0.02, 0.025], [0.02, 0.03, 0.08], [0.18, 0.18, 0.18],
                     [0.65, 0.65, 0.62], [0.2, 0.02, 0.025], [0.08, 0.09, 0.04]])


@dataclass(frozen=True)
class SkinLayer:
    """One person's part over the background: a box of the image, its coverage (0..1) and
    premultiplied linear albedo with the shading baked in."""

    box: tuple[int, int, int, int]     # x0, y0, x1, y1 (exclusive)
    alpha: np.ndarray                  # (y1 - y0, x1 - x0) float32
    rgb: np.ndarray                    # (y1 - y0, x1 - x0, 3) float32, premultiplied


def skin_tone_albedo(rng: np.random.Generator) -> np.ndarray:
    """Linear albedo of a skin tone drawn from ``rng`` (the bare-hand synthesiser's light to
    dark tones, each channel varied by a few per cent)."""
    # imported here: bare_hand builds on the frame synthesiser, which imports this module
    from colorglove_ros.core.synthetic.bare_hand import SKIN_TONES_SRGB, skin_albedo

    base = skin_albedo(int(rng.integers(len(SKIN_TONES_SRGB))))
    return np.clip(base * rng.uniform(0.92, 1.08, 3), 0.0, 1.0)


@lru_cache(maxsize=1)
def _finger_shapes() -> np.ndarray:
    return pose_collection(seed=3, size=400)


def _light(rng: np.random.Generator) -> tuple[np.ndarray, float]:
    """Unit direction toward a light above and in front of the scene, and an ambient level."""
    toward = np.array([rng.uniform(-0.8, 0.8), -rng.uniform(0.4, 1.0), -0.7])
    return toward / np.linalg.norm(toward), float(rng.uniform(0.2, 0.35))


def _soft_shade(normals: np.ndarray, toward_light: np.ndarray, ambient: float) -> np.ndarray:
    """Lambert shading with a little wrap-around (skin scatters light under its surface)."""
    wrap = 0.15
    diffuse = np.clip((normals @ toward_light + wrap) / (1.0 + wrap), 0.0, None)
    return ambient + (1.0 - ambient) * diffuse


def _defocused(box: tuple[int, int, int, int], alpha: np.ndarray, rgb: np.ndarray,
               sigma: float, width: int, height: int) -> SkinLayer | None:
    """Blur a layer's coverage and premultiplied colour (grown by the blur's reach, clipped to
    the image); None when nothing of it is in view."""
    pad = int(np.ceil(3 * sigma)) + 1
    alpha = cv2.copyMakeBorder(alpha, pad, pad, pad, pad, cv2.BORDER_CONSTANT, value=0)
    rgb = cv2.copyMakeBorder(rgb, pad, pad, pad, pad, cv2.BORDER_CONSTANT, value=(0, 0, 0))
    if sigma > 0:
        alpha = cv2.GaussianBlur(alpha, (0, 0), sigma)
        rgb = cv2.GaussianBlur(rgb, (0, 0), sigma)
    x0, y0 = box[0] - pad, box[1] - pad
    cx0, cy0 = max(x0, 0), max(y0, 0)
    cx1, cy1 = min(x0 + alpha.shape[1], width), min(y0 + alpha.shape[0], height)
    if cx1 <= cx0 or cy1 <= cy0:
        return None
    a = np.ascontiguousarray(alpha[cy0 - y0:cy1 - y0, cx0 - x0:cx1 - x0], np.float32)
    c = np.ascontiguousarray(rgb[cy0 - y0:cy1 - y0, cx0 - x0:cx1 - x0], np.float32)
    if float(a.max()) < 0.05:
        return None
    a.setflags(write=False)
    c.setflags(write=False)
    return SkinLayer((cx0, cy0, cx1, cy1), a, c)


def _paint_mesh(verts: np.ndarray, faces: np.ndarray, face_rgb: np.ndarray, focal: float,
                width: int, height: int) -> tuple[tuple[int, int, int, int], np.ndarray,
                                                   np.ndarray] | None:
    """Paint camera-frame triangles far to near (back faces culled), 2 x 2 supersampled:
    box, coverage and premultiplied colour; None when the mesh is out of view."""
    cx, cy = (width - 1) / 2.0, (height - 1) / 2.0
    uv = focal * verts[:, :2] / verts[:, 2:3] + (cx, cy)
    tri = verts[faces]
    normal = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    centroid = tri.mean(axis=1)
    visible = np.einsum('ij,ij->i', normal, centroid) < 0
    order = np.nonzero(visible)[0]
    order = order[np.argsort(-centroid[order, 2], kind='stable')]
    lo = np.floor(uv[faces[order]].reshape(-1, 2).min(axis=0)).astype(int) - 1
    hi = np.ceil(uv[faces[order]].reshape(-1, 2).max(axis=0)).astype(int) + 2
    x0, y0 = max(int(lo[0]), 0), max(int(lo[1]), 0)
    x1, y1 = min(int(hi[0]), width), min(int(hi[1]), height)
    if x1 - x0 < 2 or y1 - y0 < 2:
        return None
    ss = _SUPERSAMPLE
    shift = 4
    canvas = np.zeros(((y1 - y0) * ss, (x1 - x0) * ss, 4), np.float32)
    fine = ((uv - (x0, y0) + 0.5) * ss - 0.5) * (1 << shift)
    pts = np.round(fine).astype(np.int32)[faces]
    for f in order:
        r, g, b = face_rgb[f]
        cv2.fillConvexPoly(canvas, pts[f], (float(r), float(g), float(b), 1.0),
                           cv2.LINE_8, shift)
    small = cv2.resize(canvas, (x1 - x0, y1 - y0), interpolation=cv2.INTER_AREA)
    alpha = small[..., 3].copy()
    return (x0, y0, x1, y1), alpha, small[..., :3] * alpha[..., None] / np.maximum(
        alpha[..., None], 1e-6)


def _bare_arm(rng: np.random.Generator, width: int, height: int) -> tuple | None:
    """Another person's bare hand and forearm in a natural pose, 0.6-1.4 m away, its hand
    somewhere in the image and its forearm reaching out of it."""
    model, mesh, _ = default_hand()
    scale = rng.uniform(0.16, 0.21) / model.hand_length_m
    q = model.rest_pose()
    shapes = _finger_shapes()
    q[6:] = shapes[int(rng.integers(len(shapes)))]
    q[3:6] = sample_global_rotations(rng, 1)[0]
    q[0:3] = 0.0
    rotation = rotvec_to_matrix(q[3:6])
    focal = NOMINAL_FOCAL_PER_WIDTH * width
    principal = np.array([(width - 1) / 2, (height - 1) / 2])
    z = rng.uniform(0.6, 1.4)
    u, v = rng.uniform(0.05, 0.95) * width, rng.uniform(0.05, 0.95) * height
    offset = np.array([(u - principal[0]) / focal * z, (v - principal[1]) / focal * z, z]) \
        - model.keypoints(q).mean(axis=0) * scale
    # the forearm reaches out of the frame (its end never shows), as a person's arm does
    for length in np.linspace(0.3, 1.2, 10):
        arm_v, arm_f = forearm_mesh(model, float(length))
        arm_v = arm_v @ rotation.T * scale + offset
        end = arm_v[-1]                                      # centre of the far end cap
        if end[2] < 0.1:
            break
        margin = 0.05 * scale * focal / end[2]
        eu, ev = focal * end[:2] / end[2] + principal
        if not (-margin < eu < width + margin and -margin < ev < height + margin):
            break
    verts = np.concatenate([mesh.skin(model, q) * scale + offset, arm_v])
    faces = np.concatenate([mesh.faces, arm_f + mesh.num_vertices]).astype(np.int64)
    verts[:, 2] += max(0.0, 0.25 - float(verts[:, 2].min()))   # keep the arm before the lens
    tone = skin_tone_albedo(rng)
    toward_light, ambient = _light(rng)
    shade = _soft_shade(vertex_normals(verts, faces).astype(float), toward_light, ambient)
    face_shade = shade[faces].mean(axis=1)
    vary = 1.0 + 0.03 * rng.standard_normal((len(faces), 1))
    face_rgb = np.clip(tone * face_shade[:, None] * vary, 0.0, 1.0)
    return _paint_mesh(verts, faces, face_rgb, focal, width, height)


def _person_mask(region: PersonRegion, factor: float, shape: tuple[int, int]) -> np.ndarray:
    mask = np.zeros(shape, np.float32)
    cx, cy, ax, ay = (v * factor for v in region.head_ellipse)
    cv2.ellipse(mask, (round(cx), round(cy)), (round(ax), round(ay)), 0.0, 0, 360, 1.0, -1)
    torso = np.round(np.array(region.torso) * factor).astype(np.int32)
    cv2.fillPoly(mask, [torso], 1.0)
    return cv2.GaussianBlur(mask, (0, 0), 1.0)


def _photo_person(rng: np.random.Generator, photo_name: str, width: int,
                  height: int) -> tuple | None:
    """A head and shoulders cut from a person photo, seen from the chest up at the bottom
    of the frame, its head 12-30 % of the frame high."""
    photo = load_photo_manifest().get(photo_name)
    rgb, factor = load_photo(photo.name)
    region = photo.person
    mask = _person_mask(region, factor, rgb.shape[:2])
    ys, xs = np.nonzero(mask > 0.01)
    crop = (slice(ys.min(), ys.max() + 1), slice(xs.min(), xs.max() + 1))
    colour, mask = rgb[crop], mask[crop]
    head_px = 2.0 * region.head_ellipse[3] * factor
    zoom = rng.uniform(0.12, 0.30) * height / head_px
    size = (max(2, round(colour.shape[1] * zoom)), max(2, round(colour.shape[0] * zoom)))
    interp = cv2.INTER_AREA if zoom < 1 else cv2.INTER_LINEAR
    colour = cv2.resize(colour, size, interpolation=interp)
    mask = cv2.resize(mask, size, interpolation=interp)
    if rng.uniform() < 0.5:
        colour, mask = colour[:, ::-1], mask[:, ::-1]
    linear = (srgb_to_linear(colour / 255.0) * rng.uniform(0.6, 0.9)).astype(np.float32)
    x0 = int(rng.uniform(-0.2, 0.8) * width)
    y0 = height - int(size[1] * rng.uniform(0.55, 1.0))
    return _place(x0, y0, np.ascontiguousarray(mask, np.float32),
                  np.ascontiguousarray(linear), width, height)


def _place(x0: int, y0: int, alpha: np.ndarray, rgb: np.ndarray, width: int,
           height: int) -> tuple | None:
    """Clip an (alpha, rgb) image whose top-left is at (x0, y0) to the frame."""
    h, w = alpha.shape
    cx0, cy0, cx1, cy1 = max(x0, 0), max(y0, 0), min(x0 + w, width), min(y0 + h, height)
    if cx1 - cx0 < 2 or cy1 - cy0 < 2:
        return None
    sub = (slice(cy0 - y0, cy1 - y0), slice(cx0 - x0, cx1 - x0))
    return (cx0, cy0, cx1, cy1), alpha[sub].copy(), rgb[sub].copy()


def _drawn_person(rng: np.random.Generator, width: int, height: int) -> tuple | None:
    """A drawn head and shoulders: a shaded skin head with hair, eyes and mouth, a neck and
    clothed shoulders, seen from the chest up at the bottom of the frame."""
    head_h = rng.uniform(0.12, 0.30) * height
    ay, ax = head_h / 2, head_h / 2 * rng.uniform(0.72, 0.82)
    w, h = int(6 * ax), int(head_h * rng.uniform(1.8, 2.6))
    hx, hy = w / 2, ay * 1.15
    ys, xs = np.mgrid[0:h, 0:w].astype(np.float32) + 0.5
    dx, dy = (xs - hx) / ax, (ys - hy) / ay
    r2 = dx**2 + dy**2
    nz = np.sqrt(np.clip(1.0 - r2, 0.0, 1.0))
    normals = np.stack([dx, dy, nz], axis=-1) / np.sqrt(dx**2 + dy**2 + nz**2 + 1e-9)[..., None]
    toward_light, ambient = _light(rng)
    shade = _soft_shade(normals, toward_light, ambient)[..., None]
    skin = skin_tone_albedo(rng)
    clothes = _CLOTHES[int(rng.integers(len(_CLOTHES)))] * rng.uniform(0.85, 1.15)
    hair_rgb = _HAIR[int(rng.integers(len(_HAIR)))]
    rgb = np.zeros((h, w, 3), np.float32)
    alpha = np.zeros((h, w), np.float32)

    def over(mask: np.ndarray, colour: np.ndarray) -> None:
        """Lay ``colour`` over what is drawn so far where ``mask`` (0..1) covers."""
        m = mask[..., None]
        rgb[:] = rgb * (1.0 - m) + m * colour
        alpha[:] = np.maximum(alpha, mask)

    shoulders = np.zeros((h, w), np.float32)
    top = hy + ay * rng.uniform(1.25, 1.45)
    pts = np.array([[hx - 1.1 * ax, top], [hx + 1.1 * ax, top], [w - 1, top + 0.5 * ay],
                    [w - 1, h], [0, h], [0, top + 0.5 * ay]], np.int32)
    cv2.fillPoly(shoulders, [pts], 1.0)
    folds = 1.0 + 0.08 * np.sin(xs / max(ax, 1.0) * rng.uniform(2.0, 4.0))
    over(shoulders, clothes * ((0.7 + 0.25 * (1 - ys / h)) * folds)[..., None])
    neck = np.zeros((h, w), np.float32)
    cv2.rectangle(neck, (int(hx - 0.75 * ax), int(hy + 0.5 * ay)), (int(hx + 0.75 * ax),
                  int(top + 0.2 * ay)), 1.0, -1)
    over(neck, skin * 0.6)
    over(np.clip((1.0 - r2) * ax, 0.0, 1.0), skin * shade)     # head, about 1 px soft edge
    hairline = rng.uniform(-0.45, -0.25) + 0.25 * dx**2
    hair = ((r2 < 1.12) & (dy < hairline)).astype(np.float32)
    over(hair, hair_rgb * (0.6 + 0.5 * shade))
    for side in (-1, 1):
        ex, ey = hx + side * 0.38 * ax, hy - 0.05 * ay
        cv2.ellipse(rgb, (int(ex), int(ey)), (max(1, int(0.16 * ax)), max(1, int(0.07 * ay))),
                    0.0, 0, 360, (0.02, 0.015, 0.012), -1)
        cv2.line(rgb, (int(ex - 0.2 * ax), int(ey - 0.16 * ay)),
                 (int(ex + 0.2 * ax), int(ey - 0.18 * ay)),
                 tuple(float(c) for c in hair_rgb * 0.7), max(1, int(0.05 * ay)))
    cv2.ellipse(rgb, (int(hx), int(hy + 0.5 * ay)),
                (max(1, int(0.28 * ax)), max(1, int(0.05 * ay))), 0.0, 0, 360,
                tuple(float(c) for c in skin * np.array([0.8, 0.45, 0.45])), -1)
    x0 = int(rng.uniform(-0.2, 0.8) * width)
    y0 = height - int(h * rng.uniform(0.75, 1.0))
    return _place(x0, y0, alpha, np.clip(rgb, 0.0, 1.0), width, height)


@lru_cache(maxsize=16)
def people_layers(seed: int, width: int, height: int) -> tuple[SkinLayer, ...]:
    """The skin layers (1-3) of background ``seed``: bare hands and forearms and at most one
    head with shoulders, far to near; deterministic and cached."""
    split = background_seed_split(int(seed))
    rng = np.random.default_rng([int(seed), 31])
    person_photos = [p.name for p in load_photo_manifest().photos
                     if p.split == split and p.person is not None]
    scale = max(width, height) / 640.0
    layers: list[tuple[int, SkinLayer]] = []
    have_head = False
    for _ in range(int(rng.integers(1, 4))):
        is_head = not have_head and rng.uniform() >= ARM_PROBABILITY
        if not is_head:
            drawn = _bare_arm(rng, width, height)
        else:
            have_head = True
            if person_photos and rng.uniform() < PERSON_PHOTO_PROBABILITY:
                name = person_photos[int(rng.integers(len(person_photos)))]
                drawn = _photo_person(rng, name, width, height)
            else:
                drawn = _drawn_person(rng, width, height)
        sigma = float(rng.uniform(0.6, 1.8)) * scale
        if drawn is None:
            continue
        box, alpha, colour = drawn
        layer = _defocused(box, alpha.astype(np.float32),
                           (colour * alpha[..., None]).astype(np.float32), sigma, width, height)
        if layer is not None:
            layers.append((0 if is_head else 1, layer))
    # a head stands further back than the hands: it is laid first
    return tuple(layer for _, layer in sorted(layers, key=lambda item: item[0]))
