"""26-DOF kinematic right-hand model: forward kinematics, limits, keypoints, analytic Jacobians.

Hand frame (link ``palm``, origin at the wrist joint centre), for a right hand:

* ``+x`` toward the thumb side (radial),
* ``+y`` toward the forearm, so the extended fingers point along ``-y``,
* ``+z`` out of the back of the hand (dorsal); the palm faces ``-z``.

With the identity rotation (``q[3:6] = 0``) the hand frame is parallel to the camera
(OpenCV optical) frame: the palm faces the camera, the fingers point up in the image and
the thumb is on the image right. Every phalanx link has its origin at its proximal joint
centre and extends along its own ``-y`` axis; its flexion axis is its local ``+x``
(positive flexion curls toward the palm, ``-z``). Finger abduction rotates about the
palm normal ``+z``: positive abduction moves a finger toward the thumb side for every
finger (so spreading the hand is ``+`` for the index, ``-`` for the ring and little).
The thumb (after DigitEyes / Rijpkema-Girard) has a carpometacarpal joint with two
skewed axes (abduction, then flexion across the palm), then MCP and IP flexion.

Pose vector ``q`` (26): ``q[0:3]`` wrist position in the camera frame (m), ``q[3:6]``
rotation vector of the hand frame in the camera frame, ``q[6:26]`` finger DOFs named
``FINGER_DOF_NAMES`` (see docs/DESIGN.md).

Proportions: nominal (``_FINGER_GEOMETRY``, ``_THUMB_LENGTHS``), each digit's phalanges
optionally lengthened by a per-user factor (``finger_length_factors``, thumb..little), then the
whole hand scaled so that ``hand_length_m`` stays the wrist-to-middle-fingertip distance of the
flat rest pose.
"""
from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from colorglove_ros.core.conventions import (
    DEFAULT_HAND_LENGTH_M,
    FINGER_LENGTH_FACTOR_RANGE,
    MODEL_HAND_LENGTH_RANGE_M,
)
from colorglove_ros.core.errors import ColorGloveError
from colorglove_ros.core.geometry import rotvec_to_matrix, so3_left_jacobian, vector_to_skew

if TYPE_CHECKING:   # core.camera imports this module
    from colorglove_ros.core.camera import Calibration

__all__ = [
    'DIGITS', 'DOF_NAMES', 'FINGER_DOF_NAMES', 'GLOBAL_DOF_NAMES', 'NUM_DOFS',
    'NUM_FINGER_DOFS', 'KEYPOINT_NAMES', 'LINK_NAMES', 'DIP_PIP_RATIO',
    'HandModelError', 'HandModel', 'digit_link_index', 'JointSpec',
    'NOMINAL_FINGER_LENGTH_FACTORS', 'KNUCKLE_TO_TIP_SEGMENTS', 'check_finger_length_factors',
    'finger_length_factors_for', 'calibrated_hand_model',
]

DIGITS: tuple[str, ...] = ('thumb', 'index', 'middle', 'ring', 'little')
GLOBAL_DOF_NAMES: tuple[str, ...] = (
    'wrist_tx', 'wrist_ty', 'wrist_tz', 'wrist_rx', 'wrist_ry', 'wrist_rz')
FINGER_DOF_NAMES: tuple[str, ...] = (
    'thumb_cmc_abd', 'thumb_cmc_flex', 'thumb_mcp_flex', 'thumb_ip_flex',
    *(f'{d}_{j}' for d in DIGITS[1:] for j in ('mcp_abd', 'mcp_flex', 'pip_flex', 'dip_flex')),
)
DOF_NAMES: tuple[str, ...] = GLOBAL_DOF_NAMES + FINGER_DOF_NAMES
NUM_DOFS = 26
NUM_FINGER_DOFS = 20
_SEGMENTS = {'thumb': ('metacarpal', 'proximal', 'distal')}
LINK_NAMES: tuple[str, ...] = ('palm', *(
    f'{d}_{s}' for d in DIGITS for s in _SEGMENTS.get(d, ('proximal', 'middle', 'distal'))))
KEYPOINT_NAMES: tuple[str, ...] = ('wrist', *(
    f'{d}_{k}' for d in DIGITS
    for k in (('cmc', 'mcp', 'ip', 'tip') if d == 'thumb' else ('mcp', 'pip', 'dip', 'tip'))))
DIP_PIP_RATIO = 2.0 / 3.0
NOMINAL_FINGER_LENGTH_FACTORS: tuple[float, ...] = (1.0,) * len(DIGITS)
"""Finger length factors of the model's own proportions (thumb, index, middle, ring, little)."""
KNUCKLE_TO_TIP_SEGMENTS: tuple[tuple[int, ...], ...] = ((1, 2), *((0, 1, 2),) * 4)
"""Segments (0..2, proximal to distal) of each digit from its base knuckle (MCP joint) to its
tip: a finger's three phalanges; the thumb's proximal and distal phalanx (its metacarpal lies in
the palm). Their summed lengths are a digit's measurable length (``HandModel.digit_lengths_m``)."""

assert len(DOF_NAMES) == NUM_DOFS and len(FINGER_DOF_NAMES) == NUM_FINGER_DOFS
assert len(LINK_NAMES) == 16 and len(KEYPOINT_NAMES) == 21


class HandModelError(ColorGloveError):
    """Invalid hand-model input (shape of a pose, unknown link, bad hand length or finger
    length factors)."""


def check_finger_length_factors(name: str, value: Any,
                                error: type[Exception] = HandModelError) -> tuple[float, ...]:
    """``value`` as five finite finger length factors (thumb, index, middle, ring, little)
    within ``FINGER_LENGTH_FACTOR_RANGE``; raise ``error`` naming ``name`` and the value."""
    if isinstance(value, (str, bytes)) or not isinstance(value, (Sequence, np.ndarray)) \
            or len(value) != len(DIGITS):
        raise error(f'{name} must be a list of {len(DIGITS)} numbers ({", ".join(DIGITS)}), '
                    f'got {value!r}')
    low, high = FINGER_LENGTH_FACTOR_RANGE
    factors = []
    for digit, item in zip(DIGITS, value, strict=True):
        if isinstance(item, (bool, np.bool_)) or not isinstance(
                item, (int, float, np.integer, np.floating)):
            raise error(f'{name}: the {digit} factor must be a number, got {item!r}')
        factor = float(item)
        if not math.isfinite(factor) or not low <= factor <= high:
            raise error(f'{name}: the {digit} factor {item!r} is outside [{low}, {high}] '
                        '(a digit this much longer or shorter than the model\'s is a '
                        'measurement error)')
        factors.append(factor)
    return tuple(factors)


def digit_link_index(digit: int, segment: int) -> int:
    """Index in ``LINK_NAMES`` of segment 0..2 (proximal to distal) of digit 0..4."""
    return 1 + 3 * digit + segment


def _rot_axis(axis: np.ndarray, angles: np.ndarray) -> np.ndarray:
    """Rotations about one fixed unit axis by (B,) angles -> (B, 3, 3)."""
    K = vector_to_skew(axis)
    s = np.sin(angles)[:, None, None]
    c = np.cos(angles)[:, None, None]
    return np.eye(3) + s * K + (1.0 - c) * (K @ K)


def _rz(a: float) -> np.ndarray:
    return _rot_axis(np.array([0.0, 0.0, 1.0]), np.array([a]))[0]


def _ry(a: float) -> np.ndarray:
    return _rot_axis(np.array([0.0, 1.0, 0.0]), np.array([a]))[0]


@dataclass(frozen=True)
class JointSpec:
    """A revolute joint: frame = parent frame * [fixed_rot, fixed_trans] * Rot(axis, q[dof])."""

    name: str
    parent_frame: int       # index into frames (0 = palm)
    fixed_rot: np.ndarray     # (3, 3)
    fixed_trans: np.ndarray     # (3,)
    axis: np.ndarray        # (3,) unit, in the joint's own frame
    dof: int                # index into q


# Nominal proportions for a hand of DEFAULT_HAND_LENGTH_M (metres), rescaled to the requested
# hand length.
# anchor (x, y, z) of the base joint in the palm frame, rest splay about +z (rad),
# phalanx lengths (proximal, middle, distal incl. the fingertip) and radii.
_FINGER_GEOMETRY = {
    'index': ((0.0275, -0.0890, 0.0), 0.10, (0.0420, 0.0250, 0.0215), (0.0095, 0.0085, 0.0078)),
    'middle': ((0.0060, -0.0930, 0.0), 0.0, (0.0460, 0.0285, 0.0225), (0.0098, 0.0088, 0.0080)),
    'ring': ((-0.0150, -0.0890, 0.0), -0.08, (0.0430, 0.0270, 0.0215), (0.0092, 0.0083, 0.0075)),
    'little': ((-0.0330, -0.0790, 0.0), -0.18, (0.0340, 0.0205, 0.0195), (0.0082, 0.0074, 0.0068)),
}
_THUMB_ANCHOR = (0.0230, -0.0200, -0.0080)
_THUMB_REST_YAW = 0.65      # rest direction: rotated from -y toward +x (rad)
_THUMB_PRONATION = 0.85     # rotation about the thumb's long axis (rad)
_THUMB_LENGTHS = (0.0440, 0.0320, 0.0290)
_THUMB_RADII = (0.0125, 0.0105, 0.0092)
_THUMB_ABD_AXIS = (0.0, 0.25, 1.0)    # skewed: mostly the thumb's palm normal
_THUMB_FLEX_AXIS = (1.0, 0.0, -0.15)  # skewed: mostly the thumb's flexion axis
_NOMINAL_LENGTH = DEFAULT_HAND_LENGTH_M

_DEG = np.pi / 180.0
_FINGER_LIMITS = ((-15 * _DEG, 15 * _DEG), (0.0, 90 * _DEG), (0.0, 110 * _DEG), (0.0, 90 * _DEG))
_THUMB_LIMITS = ((-20 * _DEG, 50 * _DEG), (-15 * _DEG, 60 * _DEG), (-10 * _DEG, 60 * _DEG),
                 (-15 * _DEG, 80 * _DEG))
_TRANSLATION_LIMITS = ((-1.5, 1.5), (-1.5, 1.5), (0.05, 3.0))


class HandModel:
    """Right hand, 16 rigid links (palm + 3 per digit), 26 DOF, scaled to a hand length.

    ``hand_length_m`` is the wrist-to-middle-fingertip distance of the flat rest pose.
    ``finger_length_factors`` (thumb, index, middle, ring, little; default all 1, the nominal
    proportions) multiply each digit's phalanx lengths before the whole hand is scaled to
    ``hand_length_m``; radii and the palm follow the overall scale only.
    """

    def __init__(self, hand_length_m: float = DEFAULT_HAND_LENGTH_M,
                 finger_length_factors: Sequence[float] | None = None) -> None:
        low, high = MODEL_HAND_LENGTH_RANGE_M
        if not (low <= hand_length_m <= high):
            raise HandModelError(f'hand_length_m {hand_length_m!r} outside [{low}, {high}]')
        self.hand_length_m = float(hand_length_m)
        self.finger_length_factors: tuple[float, ...] = (
            NOMINAL_FINGER_LENGTH_FACTORS if finger_length_factors is None else
            check_finger_length_factors('finger_length_factors', finger_length_factors))
        self.dof_names: tuple[str, ...] = DOF_NAMES
        self.link_names: tuple[str, ...] = LINK_NAMES
        self.keypoint_names: tuple[str, ...] = KEYPOINT_NAMES
        self.link_parent = np.array(
            [-1] + [0 if s == 0 else digit_link_index(d, s - 1)
                    for d in range(5) for s in range(3)], dtype=np.int64)
        lower = np.empty(NUM_DOFS)
        upper = np.empty(NUM_DOFS)
        lower[:3], upper[:3] = np.array(_TRANSLATION_LIMITS).T
        lower[3:6], upper[3:6] = -np.inf, np.inf
        for d in range(5):
            lims = _THUMB_LIMITS if d == 0 else _FINGER_LIMITS
            for k in range(4):
                lower[6 + 4 * d + k], upper[6 + 4 * d + k] = lims[k]
        self.lower_limits = lower
        self.upper_limits = upper
        self._build(1.0)
        tip = self.keypoints(self.rest_pose(centered=False))
        middle_tip = tip[KEYPOINT_NAMES.index('middle_tip')] - tip[0]
        self.scale = self.hand_length_m / float(np.linalg.norm(middle_tip))
        self._build(self.scale)

    # ------------------------------------------------------------------ construction
    def _build(self, s: float) -> None:
        joints: list[JointSpec] = []
        link_frame: list[int] = [0]          # frame index of each link (frame 0 = palm)
        lengths = np.zeros(16)
        radii = np.zeros(16)
        eye = np.eye(3)
        for d, digit in enumerate(DIGITS):
            base = 6 + 4 * d
            factor = self.finger_length_factors[d]
            if digit == 'thumb':
                anchor = np.array(_THUMB_ANCHOR) * s
                R0 = _rz(_THUMB_REST_YAW) @ _ry(_THUMB_PRONATION)
                seg_len, seg_rad = _THUMB_LENGTHS, _THUMB_RADII
                a1 = np.array(_THUMB_ABD_AXIS) / np.linalg.norm(_THUMB_ABD_AXIS)
                a2 = np.array(_THUMB_FLEX_AXIS) / np.linalg.norm(_THUMB_FLEX_AXIS)
            else:
                anc, splay, seg_len, seg_rad = _FINGER_GEOMETRY[digit]
                anchor = np.array(anc) * s
                R0 = _rz(splay)
                a1 = np.array([0.0, 0.0, 1.0])
                a2 = np.array([1.0, 0.0, 0.0])
            seg_len = tuple(length * factor for length in seg_len)   # exact when factor is 1
            ex = np.array([1.0, 0.0, 0.0])
            zero = np.zeros(3)
            f0 = len(joints) + 1
            joints.append(JointSpec(FINGER_DOF_NAMES[4 * d], 0, R0, anchor, a1, base))
            joints.append(JointSpec(FINGER_DOF_NAMES[4 * d + 1], f0, eye, zero, a2, base + 1))
            joints.append(JointSpec(FINGER_DOF_NAMES[4 * d + 2], f0 + 1, eye,
                                 np.array([0.0, -seg_len[0] * s, 0.0]), ex, base + 2))
            joints.append(JointSpec(FINGER_DOF_NAMES[4 * d + 3], f0 + 2, eye,
                                 np.array([0.0, -seg_len[1] * s, 0.0]), ex, base + 3))
            for k in range(3):
                li = digit_link_index(d, k)
                link_frame.append(f0 + 1 + k)
                lengths[li] = seg_len[k] * s
                radii[li] = seg_rad[k] * s
        self._joints = joints
        self._joint_consts = [
            (j.fixed_rot, j.fixed_rot @ vector_to_skew(j.axis),
             j.fixed_rot @ np.outer(j.axis, j.axis))
            for j in joints]
        self._num_frames = len(joints) + 1
        self._link_frame = np.array(link_frame, dtype=np.int64)
        self.link_lengths = lengths
        self.link_radii = radii
        self.finger_anchors = np.array([j.fixed_trans for j in joints[::4]])
        # ancestor mask: link x dof (1 if the dof moves the link)
        frame_dofs: list[set[int]] = [set()]
        for j in joints:
            frame_dofs.append(frame_dofs[j.parent_frame] | {j.dof})
        mask = np.zeros((16, NUM_DOFS))
        for li, fi in enumerate(self._link_frame):
            for dof in frame_dofs[fi]:
                mask[li, dof] = 1.0
        self._link_dof_mask = mask
        # keypoints: (link, local point)
        kp_link = [0]
        kp_local = [np.zeros(3)]
        for d in range(5):
            for k in range(3):
                kp_link.append(digit_link_index(d, k))
                kp_local.append(np.zeros(3))
            li = digit_link_index(d, 2)
            kp_link.append(li)
            kp_local.append(np.array([0.0, -lengths[li], 0.0]))
        self.keypoint_link = np.array(kp_link, dtype=np.int64)
        self.keypoint_local = np.array(kp_local)

    @property
    def digit_lengths_m(self) -> np.ndarray:
        """(5,) each digit's length from its base knuckle (MCP joint centre) to its tip,
        straight (``KNUCKLE_TO_TIP_SEGMENTS``), thumb..little, metres."""
        return np.array([sum(self.link_lengths[digit_link_index(d, k)] for k in segments)
                         for d, segments in enumerate(KNUCKLE_TO_TIP_SEGMENTS)])

    @property
    def joints(self) -> tuple[JointSpec, ...]:
        """The 20 revolute joints (fixed transform from parent frame, local axis, dof)."""
        return tuple(self._joints)

    # ------------------------------------------------------------------ poses
    def rest_pose(self, centered: bool = True) -> np.ndarray:
        """Flat hand, palm toward the camera, fingers up (-y), 0.5 m in front of the camera.

        With ``centered`` the wrist sits ``hand_length/2`` below the optical axis so the
        hand's middle is roughly on it; otherwise the wrist is on the optical axis.
        """
        q = np.zeros(NUM_DOFS)
        q[2] = 0.5
        if centered:
            q[1] = 0.5 * self.hand_length_m
        return q

    def clamp(self, q: np.ndarray) -> np.ndarray:
        """Clip (..., 26) poses into the joint limits (rotation left free)."""
        q = self._check(q, batch_ok=True)
        return np.clip(q, self.lower_limits, self.upper_limits)

    def within_limits(self, q: np.ndarray, tol: float = 1e-9) -> np.ndarray:
        """Bool per pose (..., 26): every DOF inside its limits."""
        q = self._check(q, batch_ok=True)
        return np.all((q >= self.lower_limits - tol) & (q <= self.upper_limits + tol), axis=-1)

    def coupling_prior(self) -> np.ndarray:
        """(4, 26) matrix C with residual ``C @ q = dip - DIP_PIP_RATIO * pip`` for the
        index, middle, ring and little fingers; an IK prior penalises ``|C q|^2``."""
        C = np.zeros((4, NUM_DOFS))
        for i, digit in enumerate(DIGITS[1:]):
            C[i, DOF_NAMES.index(f'{digit}_dip_flex')] = 1.0
            C[i, DOF_NAMES.index(f'{digit}_pip_flex')] = -DIP_PIP_RATIO
        return C

    # ------------------------------------------------------------------ kinematics
    def _check(self, q: np.ndarray, batch_ok: bool = False) -> np.ndarray:
        q = np.asarray(q, dtype=float)
        if q.shape[-1:] != (NUM_DOFS,) or (not batch_ok and q.ndim != 1):
            raise HandModelError(f'pose must have shape (26,), got {q.shape}')
        return q

    def _frames_batch(self, Q: np.ndarray, dtype: type = np.float64
                      ) -> tuple[np.ndarray, list[np.ndarray], list[np.ndarray]]:
        """(B, 16, 4, 4) link transforms plus views of every frame's rotation (B, 3, 3) and
        translation (B, 3) in the camera (link frames are views into the first array)."""
        B = Q.shape[0]
        T = np.zeros((B, 16, 4, 4), dtype=dtype)
        T[:, :, 3, 3] = 1.0
        frame_link = {int(f): li for li, f in enumerate(self._link_frame)}
        Rs: list[np.ndarray] = []
        ts: list[np.ndarray] = []
        for f in range(self._num_frames):
            if f in frame_link:
                Rs.append(T[:, frame_link[f], :3, :3])
                ts.append(T[:, frame_link[f], :3, 3])
            else:
                Rs.append(np.empty((B, 3, 3), dtype=dtype))
                ts.append(np.empty((B, 3), dtype=dtype))
        Rs[0][...] = rotvec_to_matrix(Q[:, 3:6])
        ts[0][...] = Q[:, 0:3]
        for f, j in enumerate(self._joints, start=1):
            Rp = Rs[j.parent_frame]
            np.add(ts[j.parent_frame], Rp @ j.fixed_trans.astype(dtype), out=ts[f])
            # fixed_rot @ Rot(a, th) = c (F - F a a^T) + s F [a]_x + F a a^T
            F, FK, Faa = self._joint_consts[f - 1]
            th = Q[:, j.dof].astype(dtype)
            local = np.cos(th)[:, None, None] * (F - Faa).astype(dtype)
            local += np.sin(th)[:, None, None] * FK.astype(dtype)
            local += Faa.astype(dtype)
            np.matmul(Rp, local, out=Rs[f])
        return T, Rs, ts

    def link_transforms_batch(self, Q: np.ndarray, dtype: type = np.float64) -> np.ndarray:
        """(B, 26) poses -> (B, 16, 4, 4) link-to-camera transforms (``dtype`` float32 halves
        the memory for large batches)."""
        Q = np.asarray(Q, dtype=float)
        if Q.ndim != 2 or Q.shape[1] != NUM_DOFS:
            raise HandModelError(f'poses must have shape (B, 26), got {Q.shape}')
        return self._frames_batch(Q, dtype)[0]

    def link_transforms(self, q: np.ndarray) -> np.ndarray:
        """(26,) pose -> (16, 4, 4) link-to-camera transforms."""
        return self.link_transforms_batch(self._check(q)[None])[0]

    def transform_points(self, q: np.ndarray, link_index: np.ndarray,
                         local_points: np.ndarray) -> np.ndarray:
        """Points given in their links' frames -> (N, 3) camera-frame points."""
        T = self.link_transforms(q)
        link_index = np.asarray(link_index, dtype=np.int64)
        P = np.asarray(local_points, dtype=float)
        Ti = T[link_index]
        return np.einsum('nij,nj->ni', Ti[:, :3, :3], P) + Ti[:, :3, 3]

    def point_jacobian(self, q: np.ndarray, link_index: np.ndarray,
                       local_points: np.ndarray) -> np.ndarray:
        """Analytic d(camera point)/dq, (N, 3, 26), for points fixed on links.

        Translation columns are the identity; rotation-vector columns are
        ``-[p - t]_x J_l(r)`` (left Jacobian of SO(3)); revolute columns ``w_j x (p - d_j)``.
        """
        q = self._check(q)
        link_index = np.asarray(link_index, dtype=np.int64)
        P = np.asarray(local_points, dtype=float)
        if P.ndim != 2 or P.shape[1] != 3 or len(P) != len(link_index):
            raise HandModelError('local_points must be (N, 3) matching link_index (N,)')
        _, Rl, tl = self._frames_batch(q[None])
        Rs = np.stack([r[0] for r in Rl])
        ts = np.stack([t[0] for t in tl])
        fr = self._link_frame[link_index]
        p = np.einsum('nij,nj->ni', Rs[fr], P) + ts[fr]
        J = np.zeros((len(P), 3, NUM_DOFS))
        J[:, 0, 0] = J[:, 1, 1] = J[:, 2, 2] = 1.0
        J[:, :, 3:6] = -vector_to_skew(p - ts[0]) @ so3_left_jacobian(q[3:6])
        mask = self._link_dof_mask[link_index]
        for f, j in enumerate(self._joints, start=1):
            w = Rs[f] @ j.axis
            J[:, :, j.dof] = np.cross(w, p - ts[f]) * mask[:, j.dof:j.dof + 1]
        return J

    def keypoints(self, q: np.ndarray) -> np.ndarray:
        """(21, 3) camera-frame keypoints in ``KEYPOINT_NAMES`` order."""
        return self.transform_points(q, self.keypoint_link, self.keypoint_local)

    def keypoints_batch(self, Q: np.ndarray) -> np.ndarray:
        """(B, 26) -> (B, 21, 3) keypoints."""
        T = self.link_transforms_batch(Q)[:, self.keypoint_link]
        return np.einsum('bnij,nj->bni', T[..., :3, :3], self.keypoint_local) + T[..., :3, 3]

    def keypoint_jacobian(self, q: np.ndarray) -> np.ndarray:
        """(21, 3, 26) analytic Jacobian of the keypoints."""
        return self.point_jacobian(q, self.keypoint_link, self.keypoint_local)


def _nominal_digit_lengths() -> np.ndarray:
    """(5,) knuckle-to-tip lengths of the nominal proportions before any scaling."""
    segments = [_THUMB_LENGTHS, *(_FINGER_GEOMETRY[digit][2] for digit in DIGITS[1:])]
    return np.array([sum(seg[k] for k in keep)
                     for seg, keep in zip(segments, KNUCKLE_TO_TIP_SEGMENTS, strict=True)])


def finger_length_factors_for(hand_length_m: float,
                              digit_lengths_m: Sequence[float]) -> tuple[float, ...]:
    """The finger length factors with which ``HandModel(hand_length_m, factors)`` has the
    knuckle-to-tip lengths ``digit_lengths_m`` (thumb..little, metres; see
    ``HandModel.digit_lengths_m``). Not range-checked (``check_finger_length_factors``).

    The overall scale s depends on the middle finger only: its flat tip is at
    ``s a + u d`` (``a`` its base anchor, ``d`` its rest direction, ``u`` its measured length),
    whose distance from the wrist must be the hand length; the factors follow from s.
    """
    lengths = np.asarray(digit_lengths_m, dtype=float)
    if lengths.shape != (len(DIGITS),) or not np.all(np.isfinite(lengths)) \
            or np.any(lengths <= 0.0):
        raise HandModelError(f'digit lengths must be {len(DIGITS)} positive finite numbers '
                             f'(m), got {digit_lengths_m!r}')
    if not math.isfinite(hand_length_m) or hand_length_m <= 0.0:
        raise HandModelError(f'hand length must be a positive number (m), got {hand_length_m!r}')
    middle = DIGITS.index('middle')
    anchor, splay = np.array(_FINGER_GEOMETRY['middle'][0]), _FINGER_GEOMETRY['middle'][1]
    direction = _rz(splay) @ np.array([0.0, -1.0, 0.0])
    u = float(lengths[middle])
    if u >= hand_length_m:
        raise HandModelError(f'the middle finger ({u} m) must be shorter than the hand '
                             f'({hand_length_m} m), which runs from the wrist to its tip')
    ad, aa = float(anchor @ direction), float(anchor @ anchor)
    scale = (-u * ad + math.sqrt((u * ad) ** 2 - aa * (u * u - hand_length_m ** 2))) / aa
    return tuple(float(f) for f in lengths / (_nominal_digit_lengths() * scale))


def calibrated_hand_model(calibration: Calibration) -> HandModel:
    """The user's hand model from a calibration (``core.camera.Calibration``): its hand
    length and finger length factors. Every place that builds the user's hand uses this."""
    return HandModel(calibration.hand_length_m, calibration.finger_length_factors)
