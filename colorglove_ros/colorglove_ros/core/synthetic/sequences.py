"""Seeded hand-motion sequences (natural finger shapes joined by minimum-jerk moves, the wrist on
splines through a desk capture volume) and their rendering as camera frames."""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace

import numpy as np
from scipy.interpolate import CubicSpline
from scipy.ndimage import gaussian_filter1d
from scipy.spatial.transform import Rotation, RotationSpline

from colorglove_ros.core.camera import PinholeCamera
from colorglove_ros.core.conventions import DEFAULT_HAND_LENGTH_M
from colorglove_ros.core.geometry import rotvec_to_matrix
from colorglove_ros.core.hand.glove import default_hand
from colorglove_ros.core.hand.model import NUM_DOFS, HandModel
from colorglove_ros.core.hand.poses import NAMED_SHAPES, finger_limits, sample_global_rotations
from colorglove_ros.core.synthetic.conditions import FrameConditions, SynthError, sample_conditions
from colorglove_ros.core.synthetic.frames import (
    Synthesizer,
    SyntheticFrame,
    default_camera,
    natural_finger_shapes,
    primary_to_camera,
    view_of_scene,
)

__all__ = [
    'CAPTURE_VOLUME_CENTER', 'CAPTURE_VOLUME_SIZE', 'min_jerk', 'generate_sequence',
    'SyntheticSequenceRenderer', 'BORDERS', 'border_crossing_sequence',
    'LEFT_SEED_OFFSET', 'two_hand_sequences',
]

CAPTURE_VOLUME_CENTER = np.array([0.0, 0.02, 0.55])   # metres, camera frame
CAPTURE_VOLUME_SIZE = np.array([0.60, 0.50, 0.30])    # x, y, z extent of the desk volume
LEFT_SEED_OFFSET = 50_000
"""The left hand of two-hand sequence ``S`` moves as the mirrored sequence ``S + 50000``."""


def min_jerk(s: np.ndarray) -> np.ndarray:
    """Minimum-jerk profile 0 -> 1 at normalised times ``s`` in 0..1."""
    return s**3 * (10.0 - 15.0 * s + 6.0 * s**2)


def generate_sequence(seed: int, num_frames: int, fps: float = 30.0, *,
                      camera: PinholeCamera | None = None,
                      model: HandModel | None = None) -> np.ndarray:
    """(num_frames, 26) smooth hand motion, deterministic from ``seed``.

    Fingers move between natural shapes (named letters/gestures and pose-collection
    entries), holding each 0.15-0.6 s and moving with minimum-jerk profiles over 0.4-1.0 s
    (longer for large changes, so no joint exceeds ~4 rad/s),
    plus a small smooth jiggle (~1.5 deg). The wrist follows a C2 cubic spline through
    waypoints 0.7-1.6 s apart inside the ``CAPTURE_VOLUME_*`` desk volume (60 x 50 x 30 cm,
    depth 0.4-0.7 m), chosen so the hand centre projects inside ``camera``'s image
    (default 640x480, f = 600); orientation follows a rotation spline through waypoints
    from ``sample_global_rotations`` (each the nearest of 6 candidates to the previous,
    so the hand turns at natural speeds)."""
    if num_frames < 1 or fps <= 0:
        raise SynthError(f'need num_frames >= 1 and fps > 0, got {num_frames}, {fps}')
    rng = np.random.default_rng(seed)
    camera = default_camera() if camera is None else camera
    model = default_hand()[0] if model is None else model
    lo, hi = finger_limits(model)
    t = np.arange(num_frames) / fps
    duration = t[-1] + 1e-9
    # ---- fingers: holds and minimum-jerk transitions between natural shapes
    named = np.clip(np.stack(list(NAMED_SHAPES.values())), lo, hi)
    coll = natural_finger_shapes(0)

    def shape() -> np.ndarray:
        return named[rng.integers(len(named))] if rng.uniform() < 0.6 \
            else coll[rng.integers(len(coll))]

    fingers = np.empty((num_frames, 20))
    cur, time = shape(), -rng.uniform(0.0, 0.5)
    segments = []          # (start, end, from, to): holds and moves
    while time <= duration:
        hold, nxt = rng.uniform(0.15, 0.6), shape()
        # minimum-jerk peak speed 1.875 * delta / move: keep it under ~4 rad/s per joint
        move = max(rng.uniform(0.4, 1.0), 0.5 * float(np.abs(nxt - cur).max()))
        segments.append((time, time + hold, cur, cur))
        segments.append((time + hold, time + hold + move, cur, nxt))
        cur, time = nxt, time + hold + move
    for t0, t1, a, b in segments:
        sel = (t >= t0) & (t < t1)
        fingers[sel] = a + min_jerk((t[sel] - t0) / (t1 - t0))[:, None] * (b - a)
    jiggle = gaussian_filter1d(rng.normal(0.0, 1.0, (num_frames + 20, 20)), 0.12 * fps,
                               axis=0, mode='reflect')[10:10 + num_frames]
    jiggle *= np.deg2rad(1.5) / max(float(jiggle.std()), 1e-9)
    fingers = np.clip(fingers + jiggle, lo, hi)
    # ---- global motion: waypoints in the capture volume, C2 splines
    half = CAPTURE_VOLUME_SIZE / 2.0
    centre_local = np.array([0.0, -0.45 * model.hand_length_m, 0.0])  # hand centre, hand frame
    n_way = int(np.ceil(duration / 0.7)) + 3
    times = np.concatenate([[-0.5], np.cumsum(rng.uniform(0.7, 1.6, n_way)) - 0.5])
    rotations = [sample_global_rotations(rng, 1)[0]]
    positions = []
    for k in range(len(times)):
        if k > 0:
            cands = sample_global_rotations(rng, 6)
            prev = Rotation.from_rotvec(rotations[-1])
            ang = [(Rotation.from_rotvec(c) * prev.inv()).magnitude() for c in cands]
            rotations.append(cands[int(np.argmin(ang))])
        R = rotvec_to_matrix(rotations[-1])
        for _attempt in range(200):
            p = CAPTURE_VOLUME_CENTER + rng.uniform(-half, half)
            if positions and np.linalg.norm(p - positions[-1]) > 0.22:
                continue
            c = p + R @ centre_local
            u, v = camera.project(c)
            if 0.15 * camera.width < u < 0.85 * camera.width \
                    and 0.15 * camera.height < v < 0.85 * camera.height:
                break
        positions.append(p)
    pos = CubicSpline(times, np.array(positions), axis=0, bc_type='natural')(t)
    rot = RotationSpline(times, Rotation.from_rotvec(np.array(rotations)))(t).as_rotvec()
    Q = np.zeros((num_frames, NUM_DOFS))
    Q[:, 0:3] = pos
    Q[:, 3:6] = rot
    Q[:, 6:] = fingers
    return Q


def two_hand_sequences(seed: int, num_frames: int, fps: float = 30.0, *,
                       camera: PinholeCamera | None = None, model: HandModel | None = None,
                       apart: bool = True, squeeze: float = 0.35, offset: float = 0.22
                       ) -> dict[str, np.ndarray]:
    """Two hands moving together: {'right': poses, 'left': poses} (each ``(num_frames, 26)``
    in its own hand's terms). The right hand moves as ``generate_sequence(seed)``, the left as
    the mirror image (``core.hand.handedness.mirror_pose``) of sequence ``seed +
    LEFT_SEED_OFFSET``. ``apart``: each hand keeps to its own side, as a user facing the camera
    holds them (right hand on the image's left): the image point ``(u, v)`` of the hand centre
    becomes ``(cx + squeeze (u - cx) -+ offset * width, cy + squeeze (v - cy))`` by moving the
    wrist parallel to the image plane at its depth, so the hands meet only at a sequence's
    extremes. Without
    ``apart`` the two move independently over the whole image (crossing and occluding
    often)."""
    from colorglove_ros.core.hand.handedness import mirror_pose

    camera = default_camera() if camera is None else camera
    model = default_hand()[0] if model is None else model
    out = {}
    for hand, s in (('right', seed), ('left', seed + LEFT_SEED_OFFSET)):
        q = generate_sequence(s, num_frames, fps, camera=camera, model=model)
        if apart:       # the right-hand poses to the image left; the mirror moves a left one
            centre_local = np.array([0.0, -0.45 * model.hand_length_m, 0.0])
            c = q[:, 0:3] + np.einsum('nij,j->ni', rotvec_to_matrix(q[:, 3:6]), centre_local)
            u = camera.fx * c[:, 0] / c[:, 2] + camera.cx
            v = camera.fy * c[:, 1] / c[:, 2] + camera.cy
            q[:, 0] += ((squeeze - 1.0) * (u - camera.cx) - offset * camera.width) \
                * c[:, 2] / camera.fx
            q[:, 1] += (squeeze - 1.0) * (v - camera.cy) * c[:, 2] / camera.fy
        out[hand] = np.stack([mirror_pose(p) for p in q]) if hand == 'left' else q
    return out


class SyntheticSequenceRenderer:
    """Frames of one seeded sequence (``generate_sequence``) under one set of conditions
    (``sample_conditions`` for ``split``, drawn from the seed; the background's glove-like
    objects stay in place while the hand passes in front), with motion blur following
    the hand's image speed over a ``shutter`` fraction of the frame interval. ``render(i)``
    is deterministic and independent of the order frames are asked for."""

    def __init__(self, camera: PinholeCamera, *, seed: int = 1, num_frames: int = 300,
                 fps: float = 30.0, hand_length_m: float = DEFAULT_HAND_LENGTH_M,
                 split: str = 'test',
                 shutter: float = 0.5, glove_seed: int = 0,
                 conditions: FrameConditions | None = None) -> None:
        self.camera = camera
        self.seed = int(seed)
        self.synth = Synthesizer(hand_length_m, glove_seed)
        self.poses = generate_sequence(seed, num_frames, fps, camera=camera,
                                       model=self.synth.model)
        rng = np.random.default_rng([self.seed, 7])
        cond = sample_conditions(rng, split) if conditions is None else conditions
        self.conditions = replace(cond, distractors_avoid_hand=False)
        self.shutter = float(shutter)
        self.fps = float(fps)
        # hand centres (primary camera frame), whose image velocity sets each view's blur
        self._centres = self.synth.keypoints(self.poses).mean(axis=1)

    def __len__(self) -> int:
        return len(self.poses)

    def render(self, index: int) -> SyntheticFrame:
        """Frame ``index`` (0-based) of the sequence."""
        return self.render_views(index, (self.camera,))[0]

    def render_views(self, index: int, cameras: Sequence[PinholeCamera]) -> list[SyntheticFrame]:
        """Frame ``index`` as each of ``cameras`` sees it, primary (the sequence's camera, in
        whose frame the poses are) first; the others as in :func:`render_frames_multi`. Each
        view's motion blur follows the hand's velocity in that view's image; the noise of all
        views comes from the frame's seed, primary first, so view 0 is ``render(index)``."""
        if not 0 <= index < len(self.poses):
            raise SynthError(f'frame {index} outside 0..{len(self.poses) - 1}')
        if not cameras:
            raise SynthError('need at least one camera')
        nxt = min(index + 1, len(self.poses) - 1)
        prv = max(index - 1, 0)
        rng = np.random.default_rng([self.seed, index, 11])
        frames = []
        for k, cam in enumerate(cameras):
            q, cond = view_of_scene(self.poses[index], self.conditions, cameras, k)
            centres = self._centres[[prv, nxt]]
            extrinsics = primary_to_camera(cameras, k)
            if extrinsics is not None:
                centres = centres @ extrinsics[0].T + extrinsics[1]
            px = cam.project(centres)
            vel = (px[1] - px[0]) / max(nxt - prv, 1)
            cond = replace(cond, blur_px=float(np.hypot(*vel) * self.shutter),
                           blur_angle=float(np.arctan2(vel[1], vel[0])))
            frames.append(self.synth.render_frame(q, cam, rng, cond))
        return frames

    def close(self) -> None:
        """Free the GL contexts."""
        self.synth.release()


BORDERS: tuple[str, ...] = ('left', 'right', 'top', 'bottom')


def _beyond_border(border: str, along: float, camera: PinholeCamera, depth: float,
                   margin_px: float) -> np.ndarray:
    """The 3-D point at ``depth`` whose projection lies ``margin_px`` beyond ``border`` of the
    image, at relative position ``along`` (0..1) along that border."""
    w, h = camera.width, camera.height
    u, v = {'left': (-margin_px, along * h), 'right': (w + margin_px, along * h),
            'top': (along * w, -margin_px), 'bottom': (along * w, h + margin_px)}[border]
    return np.array([(u - camera.cx) * depth / camera.fx, (v - camera.cy) * depth / camera.fy,
                     depth])


def border_crossing_sequence(seed: int, num_frames: int, fps: float = 30.0, *,
                             camera: PinholeCamera | None = None,
                             model: HandModel | None = None) -> tuple[np.ndarray, list[str]]:
    """(num_frames, 26) motion of a hand that repeatedly enters the image across a border,
    moves inside it and leaves across another, with a short stretch fully out of view between
    visits; and the borders it enters across, in order.

    Fingers and wrist orientation are those of :func:`generate_sequence` (same seed); the hand
    centre moves with minimum-jerk profiles between a point one hand size beyond the entry
    border, two inside points (the middle 60 % of the image, depth 0.45-0.7 m) and a point
    beyond the exit border (0.8-1.6 s for a move across a border, 0.5-0.9 s inside) and stays
    0.1-0.4 s out of view. The borders cycle
    so that every border is crossed; the first one is chosen by ``seed``."""
    camera = default_camera() if camera is None else camera
    model = default_hand()[0] if model is None else model
    base = generate_sequence(seed, num_frames, fps, camera=camera, model=model)
    rng = np.random.default_rng([seed, 23])
    centre_local = np.array([0.0, -0.45 * model.hand_length_m, 0.0])
    order = list(BORDERS)
    start = int(rng.integers(len(order)))
    order = order[start:] + order[:start]
    t = np.arange(num_frames) / fps
    segments: list[tuple[float, float, np.ndarray, np.ndarray]] = []   # (t0, t1, from, to)
    entered: list[str] = []
    time_now = 0.0

    def outside(border: str, depth: float) -> np.ndarray:
        size_px = camera.fx * 1.2 * model.hand_length_m / depth
        return _beyond_border(border, rng.uniform(0.25, 0.75), camera, depth, size_px)

    while time_now <= t[-1] + 1e-9:
        depth = float(rng.uniform(0.45, 0.7))
        visit = len(entered)
        entry = order[visit % 4]
        exit_border = order[(visit + 1 + int(rng.integers(3))) % 4]
        entered.append(entry)
        inside = [np.array(
            [(rng.uniform(0.2, 0.8) * camera.width - camera.cx) * depth / camera.fx,
             (rng.uniform(0.2, 0.8) * camera.height - camera.cy) * depth / camera.fy, depth])
            for _ in range(2)]
        points = [outside(entry, depth), *inside, outside(exit_border, depth)]
        for k, (a, b) in enumerate(zip(points[:-1], points[1:], strict=True)):
            # crossing a border slowly, as a hand reaching into view does
            move = float(rng.uniform(0.5, 0.9) if k == 1 else rng.uniform(0.8, 1.6))
            segments.append((time_now, time_now + move, a, b))
            time_now += move
        gap = float(rng.uniform(0.1, 0.4))      # out of view beyond the exit border
        segments.append((time_now, time_now + gap, points[-1], points[-1]))
        time_now += gap
    centres = np.empty((num_frames, 3))
    for t0, t1, a, b in segments:
        sel = (t >= t0) & (t < t1)
        centres[sel] = a + min_jerk((t[sel] - t0) / (t1 - t0))[:, None] * (b - a)
    Q = base.copy()
    R = np.stack([rotvec_to_matrix(r) for r in Q[:, 3:6]])
    Q[:, 0:3] = centres - R @ centre_local
    return Q, entered
