"""Synthetic frames and sequences of a bare (unmarked, skin-coloured) hand, with ground truth,
for the DigitEyes edge tracker.

The image formation is the glove synthesiser's (:mod:`colorglove_ros.core.synthetic.frames`:
Lambert shading with smooth normals, 2 x 2 supersampled silhouettes, a forearm, procedural
backgrounds, light colour and level, per-view motion blur, vignetting, noise, JPEG) with the
glove's printed colours replaced by one skin albedo (with a little per-face variation) and
the forearm bare. ``SyntheticFrame.patch_ids`` is then the hand mask (1 on the hand,
0 elsewhere, forearm excluded).

Motion (:func:`bare_hand_motion`): the hand first holds still in the edge tracker's
initialisation pose at the marked spot for ``hold_frames`` frames, then moves smoothly
(clamped cubic splines through random waypoints) with the palm kept roughly toward the
primary camera and the fingers flexing part-way, as DigitEyes' sequences avoided heavy
self-occlusion (MCP flexion up to 34 degrees, PIP up to 40, DIP about 2/3 PIP; the
fingers bend but do not fold over the palm). ``speed`` scales the motion's time axis: 1 is
slow natural motion (waypoints 0.6-1.2 s apart, wrist within +-8/6/6 cm of the marked
spot, rotation within +-0.25/0.25/0.35 rad), 2 and 4 are the faster sequences where edge
tracking at 30 Hz breaks.

Backgrounds: with ``min_contrast`` > 0 the background seed is redrawn (deterministically)
until the background's mean grey level differs from the lit skin's by at least that
fraction of the skin's in every one of the rig's ``views`` cameras (each camera sees its own
background), the analogue of DigitEyes' dark backdrop; 0 keeps any background.
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace

import numpy as np
from scipy.interpolate import CubicSpline

from colorglove_ros.core.camera import PinholeCamera
from colorglove_ros.core.colorimetry import srgb_to_linear
from colorglove_ros.core.conventions import DEFAULT_HAND_LENGTH_M
from colorglove_ros.core.errors import ColorGloveError
from colorglove_ros.core.hand.model import NUM_DOFS, HandModel
from colorglove_ros.core.synthetic.backgrounds import make_background
from colorglove_ros.core.synthetic.conditions import FrameConditions, sample_conditions
from colorglove_ros.core.synthetic.frames import Synthesizer, view_background_seed, view_of_scene
from colorglove_ros.core.synthetic.sequences import SyntheticSequenceRenderer
from colorglove_ros.core.tracking.edge_tracker import initialisation_pose

__all__ = [
    'BareHandError', 'SKIN_TONES_SRGB', 'BareHandSynthesizer', 'BareHandSequence',
    'bare_hand_conditions', 'bare_hand_motion', 'skin_albedo', 'DEFAULT_INIT_WRIST',
]

# sRGB skin reflectances from light to dark (approximate Fitzpatrick I-VI swatches)
SKIN_TONES_SRGB = np.array([[236, 200, 180], [224, 172, 150], [198, 146, 116],
                            [165, 114, 84], [125, 82, 56], [90, 58, 40]], dtype=float)
DEFAULT_INIT_WRIST = (0.0, 0.095, 0.5)   # the edge tracker's default marked spot, metres
_OUT_OF_VIEW_M = 100.0   # depth that puts the hand and forearm beyond the renderer's far plane
_LUMA = np.array([0.2126, 0.7152, 0.0722])


class BareHandError(ColorGloveError):
    """Bad bare-hand synthesis input (skin tone, speed, frame counts)."""


def skin_albedo(tone: int) -> np.ndarray:
    """Linear RGB albedo of skin tone ``tone`` (0 light .. 5 dark of ``SKIN_TONES_SRGB``)."""
    if not 0 <= tone < len(SKIN_TONES_SRGB):
        raise BareHandError(f'skin tone must be 0..{len(SKIN_TONES_SRGB) - 1}, got {tone}')
    return srgb_to_linear(SKIN_TONES_SRGB[tone] / 255.0)


class BareHandSynthesizer(Synthesizer):
    """A :class:`Synthesizer` drawing the hand in skin (albedo ``skin_rgb``, linear RGB, each
    face varied by a seeded 3 % so the surface is not perfectly flat in colour)."""

    def __init__(self, skin_rgb: Sequence[float], hand_length_m: float = DEFAULT_HAND_LENGTH_M,
                 supersample: int = 2, seed: int = 0) -> None:
        super().__init__(hand_length_m, 0, supersample)
        skin = np.asarray(skin_rgb, dtype=float)
        if skin.shape != (3,) or np.any(skin <= 0) or np.any(skin > 1):
            raise BareHandError(f'skin_rgb must be 3 values in (0, 1], got {skin_rgb}')
        rng = np.random.default_rng(seed)
        n = self.mesh.num_faces
        vary = 1.0 + 0.03 * rng.standard_normal((n, 1))
        self._glove_rgb = np.clip(skin[None, :] * vary, 0.0, 1.0).astype(np.float32)
        # one "patch" for the whole hand: patch_ids becomes the hand mask
        self.face_patch = np.where(self.face_patch >= 0, 0, -1).astype(np.int64)
        self.skin_rgb = skin


def bare_hand_conditions(rng: np.random.Generator, skin_rgb: Sequence[float],
                         split: str = 'test', min_contrast: float = 0.0,
                         width: int = 640, height: int = 480, views: int = 1) -> FrameConditions:
    """Frame conditions for a bare hand: ``sample_conditions`` with a bare forearm (skin),
    and, with ``min_contrast``, backgrounds whose mean grey level differs from the lit skin's
    by at least that fraction in each of the first ``views`` cameras of a rig (each view has
    its own background, :func:`view_background_seed`; up to 64 seeds are tried, the one with
    the best worst view is kept)."""
    if views < 1:
        raise BareHandError(f'views must be >= 1, got {views}')
    cond = sample_conditions(rng, split)
    skin = np.asarray(skin_rgb, dtype=float)
    cond = replace(cond, sleeve_rgb=tuple(float(v) for v in skin))
    if min_contrast <= 0:
        return cond
    skin_grey = float(skin @ _LUMA) * (cond.ambient + (1.0 - cond.ambient) * 0.8)
    best, best_score = cond, -1.0
    for _ in range(64):
        score = min(abs(float(make_background(cond.background_kind,
                                              view_background_seed(cond.background_seed, k),
                                              width, height).mean(axis=(0, 1)) @ _LUMA)
                        - skin_grey) / skin_grey for k in range(views))
        if score > best_score:
            best, best_score = cond, score
        if score >= min_contrast:
            break
        cond = replace(cond, background_seed=int(rng.integers(cond.background_seed + 1,
                                                               cond.background_seed + 1000)))
    return best


def bare_hand_motion(seed: int, num_frames: int, model: HandModel, *, fps: float = 30.0,
                     speed: float = 1.0, hold_frames: int = 15,
                     init_wrist: Sequence[float] = DEFAULT_INIT_WRIST) -> np.ndarray:
    """(num_frames, 26) poses in the primary camera frame, deterministic from ``seed``:
    ``hold_frames`` still frames in :func:`initialisation_pose` at ``init_wrist``, then
    smooth motion (see the module docstring) played ``speed`` times faster than the slow
    natural reference."""
    if num_frames < 1 or fps <= 0 or speed <= 0 or hold_frames < 0:
        raise BareHandError('need num_frames >= 1, fps > 0, speed > 0, hold_frames >= 0')
    rng = np.random.default_rng([seed, 17])
    q0 = initialisation_pose(model, init_wrist)
    names = model.dof_names
    tau = speed * np.maximum(np.arange(num_frames) - hold_frames, 0) / fps
    # waypoints drawn one at a time (each with all its values), so a longer or faster
    # sequence of the same seed shares the same leading waypoints
    times, way = [0.0], [q0]
    lo = np.array([-0.08, -0.06, -0.06, -0.25, -0.25, -0.35])
    while times[-1] <= tau[-1] + 1.2:
        w = q0.copy()
        times.append(times[-1] + rng.uniform(0.6, 1.2))
        w[0:6] += rng.uniform(lo, -lo)
        for digit in ('index', 'middle', 'ring', 'little'):
            w[names.index(f'{digit}_mcp_abd')] += rng.uniform(-0.12, 0.12)
            pip = rng.uniform(0.0, 0.7)
            w[names.index(f'{digit}_mcp_flex')] = rng.uniform(0.0, 0.6)
            w[names.index(f'{digit}_pip_flex')] = pip
            w[names.index(f'{digit}_dip_flex')] = max(2.0 / 3.0 * pip + rng.uniform(-0.1, 0.1),
                                                      0.0)
        for name, (a, b) in (('thumb_cmc_abd', (0.0, 0.7)), ('thumb_cmc_flex', (-0.1, 0.4)),
                             ('thumb_mcp_flex', (0.0, 0.4)), ('thumb_ip_flex', (0.0, 0.5))):
            w[names.index(name)] = rng.uniform(a, b)
        way.append(w)
    times, way = np.array(times), np.array(way)
    Q = CubicSpline(times, way, axis=0, bc_type='clamped')(tau)
    Q[:, 6:] = np.clip(Q[:, 6:], model.lower_limits[6:], model.upper_limits[6:])
    if Q.shape != (num_frames, NUM_DOFS):
        raise BareHandError(f'motion has shape {Q.shape}')
    return Q


class BareHandSequence(SyntheticSequenceRenderer):
    """Frames of one bare-hand sequence (``bare_hand_motion``) under one set of conditions
    (``bare_hand_conditions`` for ``split``, drawn from the seed), with the glove sequence
    renderer's per-view motion blur (``shutter`` fraction of the frame interval) and
    deterministic per-frame noise. ``render(i)`` / ``render_views(i, cameras)`` as there;
    ``skin_tone`` None draws one of ``SKIN_TONES_SRGB`` from the seed; ``min_contrast``
    holds for the backgrounds of the first ``views`` cameras of a rig; ``poses`` (N, 26), if
    given, replaces the generated motion (e.g. a scripted 3-D mouse sequence)."""

    def __init__(self, camera: PinholeCamera, *, seed: int = 1, num_frames: int = 330,
                 fps: float = 30.0, speed: float = 1.0, hold_frames: int = 15,
                 hand_length_m: float = DEFAULT_HAND_LENGTH_M,
                 split: str = 'test', shutter: float = 0.5,
                 skin_tone: int | None = None, min_contrast: float = 0.25, views: int = 2,
                 init_wrist: Sequence[float] = DEFAULT_INIT_WRIST,
                 poses: np.ndarray | None = None) -> None:
        rng = np.random.default_rng([int(seed), 23])
        tone = int(rng.integers(len(SKIN_TONES_SRGB))) if skin_tone is None else skin_tone
        skin = skin_albedo(tone)
        cond = bare_hand_conditions(rng, skin, split, min_contrast, camera.width, camera.height,
                                    views)
        super().__init__(camera, seed=seed, num_frames=1, fps=fps, hand_length_m=hand_length_m,
                         split=split, shutter=shutter, conditions=cond)
        self.synth.release()
        self.synth = BareHandSynthesizer(skin, hand_length_m, seed=seed)
        self.skin_tone = tone
        self.speed = float(speed)
        self.hold_frames = int(hold_frames)
        if poses is None:
            poses = bare_hand_motion(seed, num_frames, self.synth.model, fps=fps, speed=speed,
                                     hold_frames=hold_frames, init_wrist=init_wrist)
        elif np.shape(poses)[1:] != (NUM_DOFS,) or len(poses) < 1:
            raise BareHandError(f'poses must be (N, {NUM_DOFS}), got {np.shape(poses)}')
        self.poses = np.asarray(poses, dtype=float)
        # the parent's blur follows these hand centres
        self._centres = self.synth.model.keypoints_batch(self.poses).mean(axis=1)

    def render_empty_views(self, cameras: Sequence[PinholeCamera]) -> list[np.ndarray]:
        """The scene without the hand, as each of ``cameras`` sees it (RGB uint8): what a user
        captures once to calibrate a background model (the same background, light, optics
        and sensor, its own noise; the hand and forearm moved beyond the far plane)."""
        q = self.poses[0].copy()
        q[0:3] = (0.0, 0.0, _OUT_OF_VIEW_M)
        rng = np.random.default_rng([self.seed, len(self.poses), 13])
        out = []
        for k, cam in enumerate(cameras):
            qk, cond = view_of_scene(q, self.conditions, cameras, k)
            frame = self.synth.render_frame(qk, cam, rng, replace(cond, blur_px=0.0))
            if frame.patch_ids.any():
                raise BareHandError('the hand is still in view in the empty scene')
            out.append(frame.image_rgb)
        return out

