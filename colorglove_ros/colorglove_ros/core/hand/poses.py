"""Natural finger configurations (alphabet, gestures, transitions, jiggling) and hand orientations.

The collection stands in for the paper's 18,000 recorded configurations: named hand
shapes (approximate one-hand finger-spelling letters A-Z and common gestures; optionally
``PINCH_SHAPES``, the thumb on the middle, ring or little fingertip), noisy
copies of them, interpolations between random pairs of them, and random finger jiggling
within the joint limits with the DIP ~ 2/3 PIP coupling. Finger vectors have 20 entries
in ``FINGER_DOF_NAMES`` order (radians).

Orientation range (``sample_global_rotations``), used by both the database and the
synthetic sequences: ``R = Rz(roll) @ Ry(yaw) @ Rx(pitch)`` about the camera axes applied to
the canonical rest orientation (identity: palm toward the camera, fingers up), with
roll (in the image plane) uniform in +-90 deg, yaw (about the vertical image axis, turning
the palm sideways) in +-60 deg and pitch (tipping the fingers toward or away from the
camera) in +-45 deg. Optionally a fraction of samples shows the back of the hand
(yaw + 180 deg).
"""
from __future__ import annotations

import numpy as np

from colorglove_ros.core.errors import ColorGloveError
from colorglove_ros.core.geometry import matrix_to_rotvec
from colorglove_ros.core.hand.mesh import HandMesh, skin_batch
from colorglove_ros.core.hand.model import (
    DIP_PIP_RATIO,
    FINGER_DOF_NAMES,
    NUM_DOFS,
    NUM_FINGER_DOFS,
    HandModel,
)

__all__ = [
    'PosesError', 'NAMED_SHAPES', 'LETTER_SHAPES', 'GESTURE_SHAPES', 'PINCH_SHAPES',
    'named_shapes', 'ROLL_RANGE', 'YAW_RANGE',
    'PITCH_RANGE', 'pose_collection', 'named_neighbourhood_rows', 'full_pose',
    'sample_global_rotations', 'finger_limits', 'skin_fingers', 'pose_features', 'pose_distance',
]

ROLL_RANGE = (-np.pi / 2, np.pi / 2)
YAW_RANGE = (-np.pi / 3, np.pi / 3)
PITCH_RANGE = (-np.pi / 4, np.pi / 4)


class PosesError(ColorGloveError):
    """Bad finger-configuration shapes or sizes."""


def _deg(*v: float) -> tuple[float, ...]:
    return tuple(np.deg2rad(v))


# finger templates (abd, mcp, pip, dip) in degrees; abduction + = toward the thumb
_STRAIGHT = (0, 0, 0, 0)
_FIST = (0, 85, 100, 65)
_CURL = (0, 50, 80, 50)
_HALF = (0, 35, 50, 33)
_HOOK = (0, 15, 95, 60)
# thumb templates (cmc_abd, cmc_flex, mcp, ip) in degrees
_T_FLAT = (0, 0, 0, 0)
_T_OUT = (45, -5, 0, 0)          # abducted, as in L
_T_SIDE = (-10, 10, 10, 5)        # along the side of the index, as in A
_T_ACROSS = (-15, 55, 35, 25)     # folded across the palm, as in B
_T_OVER = (-5, 45, 45, 35)        # over the curled fingers, as in S or a fist
_T_UNDER = (-10, 50, 40, 35)      # tucked under fingers, as in M, N
_T_OPPOSE = (25, 40, 25, 30)      # opposed to the fingertips, as in O


def _shape(thumb: tuple, index: tuple, middle: tuple, ring: tuple, little: tuple,
           spread: float = 0.0) -> np.ndarray:
    """Build a 20-vector from degree templates; ``spread`` adds a spread of the fingers."""
    fingers = [list(index), list(middle), list(ring), list(little)]
    for f, s in zip(fingers, (1.0, 0.0, -0.7, -1.0), strict=True):
        f[0] += s * spread
    return np.array(_deg(*thumb, *(v for f in fingers for v in f)))


LETTER_SHAPES: dict[str, np.ndarray] = {
    'A': _shape(_T_SIDE, _FIST, _FIST, _FIST, _FIST),
    'B': _shape(_T_ACROSS, _STRAIGHT, _STRAIGHT, _STRAIGHT, _STRAIGHT),
    'C': _shape((20, 25, 15, 15), (0, 30, 45, 30), (0, 30, 45, 30), (0, 30, 45, 30),
                (0, 30, 45, 30)),
    'D': _shape((0, 45, 35, 30), _STRAIGHT, _CURL, _CURL, _CURL),
    'E': _shape(_T_UNDER, (0, 60, 105, 80), (0, 60, 105, 80), (0, 60, 105, 80),
                (0, 60, 105, 80)),
    'F': _shape((10, 35, 20, 20), (5, 40, 60, 40), (0, 0, 0, 0), (-6, 0, 0, 0),
                (-12, 0, 0, 0)),
    'G': _shape((-5, 15, 0, 0), (0, 10, 0, 0), _FIST, _FIST, _FIST),
    'H': _shape(_T_OVER, (-3, 5, 0, 0), (3, 5, 0, 0), _FIST, _FIST),
    'I': _shape(_T_OVER, _FIST, _FIST, _FIST, (-5, 0, 0, 0)),
    'J': _shape(_T_OVER, _FIST, _FIST, _FIST, (-12, 10, 5, 5)),
    'K': _shape((0, 35, 15, 0), (10, 0, 0, 0), (-5, 30, 10, 5), _FIST, _FIST),
    'L': _shape(_T_OUT, _STRAIGHT, _FIST, _FIST, _FIST),
    'M': _shape(_T_UNDER, (0, 70, 90, 60), (0, 70, 90, 60), (0, 70, 90, 60), _FIST),
    'N': _shape(_T_UNDER, (0, 70, 90, 60), (0, 70, 90, 60), _FIST, _FIST),
    'O': _shape(_T_OPPOSE, (0, 40, 70, 45), (0, 40, 70, 45), (0, 40, 70, 45),
                (0, 40, 70, 45)),
    'P': _shape((0, 35, 15, 0), (10, 20, 0, 0), (-5, 50, 15, 10), _FIST, _FIST),
    'Q': _shape((5, 20, 10, 10), (0, 40, 10, 5), _FIST, _FIST, _FIST),
    'R': _shape(_T_OVER, (-12, 5, 0, 0), (12, 5, 0, 0), _FIST, _FIST),
    'S': _shape(_T_OVER, _FIST, _FIST, _FIST, _FIST),
    'T': _shape((0, 40, 30, 10), (0, 70, 90, 50), _FIST, _FIST, _FIST),
    'U': _shape(_T_OVER, (-3, 0, 0, 0), (3, 0, 0, 0), _FIST, _FIST),
    'V': _shape(_T_OVER, (12, 0, 0, 0), (-10, 0, 0, 0), _FIST, _FIST),
    'W': _shape((-5, 50, 45, 40), (12, 0, 0, 0), (0, 0, 0, 0), (-10, 0, 0, 0), _FIST),
    'X': _shape(_T_OVER, _HOOK, _FIST, _FIST, _FIST),
    'Y': _shape(_T_OUT, _FIST, _FIST, _FIST, (-15, 0, 0, 0)),
    'Z': _shape((0, 40, 35, 30), (0, 5, 5, 0), _FIST, _FIST, _FIST),
}

GESTURE_SHAPES: dict[str, np.ndarray] = {
    'flat': _shape(_T_FLAT, _STRAIGHT, _STRAIGHT, _STRAIGHT, _STRAIGHT),
    'spread': _shape((40, 0, 0, 0), _STRAIGHT, _STRAIGHT, _STRAIGHT, _STRAIGHT, spread=13),
    'fist': _shape(_T_OVER, _FIST, _FIST, _FIST, _FIST),
    'relaxed': _shape((10, 15, 10, 10), (3, 20, 25, 15), (0, 22, 28, 18), (-3, 25, 30, 20),
                      (-6, 28, 32, 22)),
    'point': _shape(_T_OVER, _STRAIGHT, _FIST, _FIST, _FIST),
    'pinch': _shape((20, 35, 20, 25), (3, 45, 45, 25), (0, 20, 20, 13), (-4, 20, 20, 13),
                    (-8, 20, 20, 13)),
    'ok': _shape((15, 35, 25, 25), (5, 45, 60, 35), (0, 5, 5, 3), (-6, 5, 5, 3),
                 (-12, 5, 5, 3)),
    'thumbs_up': _shape((-5, 0, 0, 0), _FIST, _FIST, _FIST, _FIST),
    'victory': _shape(_T_OVER, (12, 0, 0, 0), (-10, 0, 0, 0), _CURL, _CURL),
    'rock': _shape(_T_OVER, (5, 0, 0, 0), _FIST, _FIST, (-12, 0, 0, 0)),
    'call_me': _shape(_T_OUT, _FIST, _FIST, _FIST, (-15, 5, 0, 0)),
    'claw': _shape((25, 20, 30, 35), (10, 10, 80, 60), (0, 10, 80, 60), (-7, 10, 80, 60),
                   (-14, 10, 80, 60)),
    'grasp': _shape((25, 30, 20, 20), (0, 45, 60, 40), (0, 45, 60, 40), (0, 45, 60, 40),
                    (0, 45, 60, 40)),
    'half_fist': _shape((5, 25, 20, 20), _HALF, _HALF, _HALF, _HALF),
    'three': _shape(_T_OUT, (10, 0, 0, 0), (-5, 0, 0, 0), _FIST, _FIST),
    'four': _shape(_T_ACROSS, (8, 0, 0, 0), (0, 0, 0, 0), (-6, 0, 0, 0), (-12, 0, 0, 0)),
    'gun': _shape((30, 0, 0, 0), _STRAIGHT, (0, 5, 0, 0), _FIST, _FIST),
    'hook': _shape(_T_OVER, _HOOK, _HOOK, _HOOK, _HOOK),
    'tabletop': _shape((15, 10, 0, 0), (0, 85, 0, 0), (0, 85, 0, 0), (0, 85, 0, 0),
                       (0, 85, 0, 0)),
    'middle_curl': _shape(_T_FLAT, _STRAIGHT, _CURL, _STRAIGHT, _STRAIGHT),
    'ring_curl': _shape(_T_FLAT, _STRAIGHT, _STRAIGHT, _CURL, _CURL),
    'thumb_tuck': _shape(_T_UNDER, _STRAIGHT, _STRAIGHT, _STRAIGHT, _STRAIGHT),
}

NAMED_SHAPES: dict[str, np.ndarray] = {**{f'letter_{k}': v for k, v in LETTER_SHAPES.items()},
                                       **GESTURE_SHAPES}

# the thumb tip on the middle, ring or little fingertip (6-7 % of the hand length away), that
# finger half bent, the other fingers as in a relaxed, flat or spread hand: the thumb and the
# finger solved as the gesture evaluation's pinches are (eval_gestures.pinch_shape) from the
# middle of its start range; 'pinch' (thumb on the index) and 'ok' are in GESTURE_SHAPES
_PINCH_THUMB_FINGER: dict[str, tuple[tuple, tuple]] = {
    'middle': ((26, 39, 21, 21), (0, 46, 52, 34)),
    'ring': ((25, 47, 25, 22), (0, 47, 52, 34)),
    'little': ((24, 55, 29, 24), (0, 47, 47, 31)),
}


def _pinch_on(background: str, finger: str) -> np.ndarray:
    out = GESTURE_SHAPES[background].copy()
    thumb, bent = _PINCH_THUMB_FINGER[finger]
    i = 4 + 4 * ('index', 'middle', 'ring', 'little').index(finger)
    out[0:4], out[i:i + 4] = _deg(*thumb), _deg(*bent)
    return out


PINCH_SHAPES: dict[str, np.ndarray] = {
    f'pinch_{finger}_{background}': _pinch_on(background, finger)
    for finger in _PINCH_THUMB_FINGER for background in ('relaxed', 'flat', 'spread')}
for _v in (*NAMED_SHAPES.values(), *PINCH_SHAPES.values()):
    _v.setflags(write=False)


def named_shapes(pinch_shapes: bool = False) -> dict[str, np.ndarray]:
    """The named shapes of the pose collection: ``NAMED_SHAPES``, then with ``pinch_shapes``
    the ``PINCH_SHAPES``."""
    return {**NAMED_SHAPES, **PINCH_SHAPES} if pinch_shapes else dict(NAMED_SHAPES)


def finger_limits(model: HandModel | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Lower and upper limits (20,) of the finger DOFs."""
    model = HandModel() if model is None else model
    return model.lower_limits[6:].copy(), model.upper_limits[6:].copy()


def full_pose(model: HandModel, fingers: np.ndarray,
              global_pose: np.ndarray | None = None) -> np.ndarray:
    """26-vector: ``global_pose`` (6,) or the rest pose's, plus the finger DOFs (20,)."""
    fingers = np.asarray(fingers, dtype=float)
    if fingers.shape != (NUM_FINGER_DOFS,):
        raise PosesError(f'fingers must have shape (20,), got {fingers.shape}')
    q = model.rest_pose()
    if global_pose is not None:
        q[:6] = global_pose
    q[6:] = fingers
    return q


def _jiggle(rng: np.random.Generator, n: int, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """Random finger jiggling: independent per-finger curls within the limits, DIP ~ 2/3 PIP,
    abduction narrowing as the finger flexes; the thumb uniform within its limits."""
    out = np.empty((n, NUM_FINGER_DOFS))
    out[:, 0:4] = rng.uniform(lo[0:4], hi[0:4], (n, 4))
    # a per-pose "global curl" correlates the fingers as real hands do
    base = rng.uniform(0.0, 1.0, (n, 1))
    for f in range(4):
        i = 4 + 4 * f
        curl = np.clip(base + rng.normal(0.0, 0.35, (n, 1)), 0.0, 1.0)[:, 0]
        mcp = np.clip(curl * hi[i + 1] + rng.normal(0.0, 0.25, n), lo[i + 1], hi[i + 1])
        pip = np.clip(curl * hi[i + 2] + rng.normal(0.0, 0.3, n), lo[i + 2], hi[i + 2])
        dip = DIP_PIP_RATIO * pip + rng.normal(0.0, np.deg2rad(8.0), n)
        abd = rng.uniform(lo[i], hi[i], n) * (1.0 - 0.7 * mcp / hi[i + 1])
        out[:, i:i + 4] = np.stack([abd, mcp, pip, dip], axis=1)
    return np.clip(out, lo, hi)


def pose_collection(seed: int = 0, size: int = 18000,
                    model: HandModel | None = None, pinch_shapes: bool = False) -> np.ndarray:
    """(size, 20) natural finger configurations, deterministic from ``seed``.

    Rows: every named shape (:func:`named_shapes` of ``pinch_shapes``) once, then ~25% noisy
    named shapes (5 deg noise), ~35% transitions (a random pair of named shapes at a random
    blend, 3 deg noise) and the rest random jiggling; all clipped into the joint limits.
    """
    lo, hi = finger_limits(model)
    rng = np.random.default_rng(seed)
    shapes = np.clip(np.stack(list(named_shapes(pinch_shapes).values())), lo, hi)
    k = len(shapes)
    rest = size - k
    n_noisy = named_neighbourhood_rows(size, pinch_shapes) - k
    n_trans = (rest * 35) // 100
    n_jig = rest - n_noisy - n_trans
    noisy = shapes[rng.integers(0, k, n_noisy)] + rng.normal(0.0, np.deg2rad(5.0),
                                                             (n_noisy, NUM_FINGER_DOFS))
    a = shapes[rng.integers(0, k, n_trans)]
    b = shapes[rng.integers(0, k, n_trans)]
    t = rng.uniform(0.0, 1.0, (n_trans, 1))
    trans = (1.0 - t) * a + t * b + rng.normal(0.0, np.deg2rad(3.0), (n_trans, NUM_FINGER_DOFS))
    jig = _jiggle(rng, n_jig, lo, hi)
    out = np.clip(np.concatenate([shapes, noisy, trans, jig]), lo, hi)
    return out


def named_neighbourhood_rows(size: int, pinch_shapes: bool = False) -> int:
    """How many leading rows of ``pose_collection(seed, size, pinch_shapes=pinch_shapes)``
    are the named shapes and their noisy copies (the rest are transitions and jiggling)."""
    k = len(named_shapes(pinch_shapes))
    if size < k:
        raise PosesError(f'size must be >= {k}, got {size}')
    return k + (size - k) // 4


def sample_global_rotations(rng: np.random.Generator, n: int,
                            back_fraction: float = 0.0) -> np.ndarray:
    """(n, 3) rotation vectors in the tracker's working range (see module docstring)."""
    from scipy.spatial.transform import Rotation

    roll = rng.uniform(*ROLL_RANGE, n)
    yaw = rng.uniform(*YAW_RANGE, n)
    pitch = rng.uniform(*PITCH_RANGE, n)
    if back_fraction > 0.0:
        yaw = yaw + np.pi * (rng.uniform(0.0, 1.0, n) < back_fraction)
    R = Rotation.from_euler('ZYX', np.stack([roll, yaw, pitch], axis=1)).as_matrix()
    return matrix_to_rotvec(R)


def _fixed_global(model: HandModel, n: int) -> np.ndarray:
    Q = np.zeros((n, NUM_DOFS))
    Q[:, 2] = 0.5
    return Q


def skin_fingers(mesh: HandMesh, model: HandModel, fingers: np.ndarray,
                 dtype: type = np.float32) -> np.ndarray:
    """(N, V, 3) mesh vertices for finger configurations (N, 20) under one fixed global pose."""
    fingers = np.atleast_2d(np.asarray(fingers, dtype=float))
    if fingers.shape[1] != NUM_FINGER_DOFS:
        raise PosesError(f'fingers must have shape (N, 20), got {fingers.shape}')
    Q = _fixed_global(model, len(fingers))
    Q[:, 6:] = fingers
    return skin_batch(mesh, model, Q, dtype=dtype)


def pose_features(mesh: HandMesh, model: HandModel, fingers: np.ndarray,
                  chunk: int = 2048, max_vertices: int | None = None) -> np.ndarray:
    """(N, D) float32 features whose Euclidean distances equal ``pose_distance``.

    Palm vertices never move with the fingers and are left out (the scaling keeps the RMS
    over all V vertices). With ``max_vertices`` only that many evenly spaced finger
    vertices are used: a cheaper approximation (D = 3 * max_vertices) for large searches.
    """
    fingers = np.atleast_2d(np.asarray(fingers, dtype=float))
    moving = np.flatnonzero(mesh.vertex_link != 0)
    n_moving = len(moving)
    if max_vertices is not None and max_vertices < n_moving:
        if max_vertices < 1:
            raise PosesError(f'max_vertices must be >= 1, got {max_vertices}')
        moving = moving[np.linspace(0, n_moving - 1, max_vertices).round().astype(np.int64)]
    scale = np.float32(np.sqrt(n_moving / (mesh.num_vertices * len(moving))))
    out = np.empty((len(fingers), len(moving) * 3), dtype=np.float32)
    for s in range(0, len(fingers), chunk):
        v = skin_fingers(mesh, model, fingers[s:s + chunk])[:, moving]
        out[s:s + chunk] = v.reshape(len(v), -1) * scale
    return out


def pose_distance(mesh: HandMesh, model: HandModel, fingers_a: np.ndarray,
                  fingers_b: np.ndarray, chunk: int = 1024) -> float | np.ndarray:
    """RMS distance (m) between skinned mesh vertices, global pose fixed (the paper's metric).

    ``fingers_a`` (20,); ``fingers_b`` (20,) -> float, or (M, 20) -> (M,) distances.
    """
    a = np.asarray(fingers_a, dtype=float)
    b = np.asarray(fingers_b, dtype=float)
    if a.shape != (NUM_FINGER_DOFS,) or b.shape[-1] != NUM_FINGER_DOFS or b.ndim > 2:
        raise PosesError(f'bad shapes {a.shape} and {b.shape}')
    fa = pose_features(mesh, model, a[None]).astype(np.float64)[0]
    bb = np.atleast_2d(b)
    out = np.empty(len(bb))
    for s in range(0, len(bb), chunk):
        fb = pose_features(mesh, model, bb[s:s + chunk])
        out[s:s + chunk] = np.sqrt(np.sum((fb - fa) ** 2, axis=1))
    return float(out[0]) if b.ndim == 1 else out


assert len(FINGER_DOF_NAMES) == NUM_FINGER_DOFS
