"""The DigitEyes 3-D mouse on a scripted synthetic sequence: click precision/recall, cursor error.

The script (per seed, 30 Hz): the hand lies on the table (camera 45 degrees above it, as in
DigitEyes), fingers relaxed with the index fingertip touching the table; the palm glides
between random points of a 30 x 20 cm area; the index finger straightens now and then
(cursor height); the thumb and the little finger abduct for 0.25-0.6 s at random times
(clicks, ``clicks`` per button), sometimes during cursor moves. The poses reach the mouse as a
tracker would deliver them: with Gaussian errors (``--joint-noise-deg`` on finger joints,
``--position-noise-mm`` on the wrist, ``--rotation-noise-deg``) and a fraction of frames
dropped (``--drop``). A detected click (button going down) is correct if it falls within a
scripted click (widened by ``--tolerance-frames``), each scripted click counting once.
Cursor error: distance between the mouse's cursor and the noise-free mapping of the true pose.
The thresholds were fixed before this evaluation (no tuning seeds); seeds 0-4 are reported.

``--source edges`` feeds the mouse the DigitEyes edge tracker's actual output instead of the
noise model: each scripted sequence is rendered as a bare hand (core.synthetic.bare_hand,
the primary camera of ``--calibration`` looking down at the table at 45 degrees; with
``--cameras 2`` also its second camera, e.g. ``config/calibration_table_stereo.yaml``'s
camera facing the user from the far side of the table, and the tracker fits both), the edge
tracker starts from the first pose (a pose given to it, as from the glove tracker) and,
after a loss, again from the pose of the frame it was lost on (counted as
``reinitialisations``); frames without a published pose reach the mouse as gaps. That pose
(``--reinit``, :func:`reinitialisation_pose`) is by default (``rest``) the true pose with the
joints the buttons read (``core.tracking.mouse.BUTTON_DOFS``) at the scripted hand's rest
angles, as a user's system would re-initialise it (it does not know that a click is under
way): a click must be followed by the tracker itself. ``--reinit truth`` (earlier passes'
figures, for comparison) gives the tracker the true pose itself, so a loss during a click
hands it the click's angle;
``correct_at_reinit`` counts the correct clicks with a re-initialisation between the click's
start and the press (with ``truth``: the clicks the truth, not the tracker, put through). With
``--background empty`` the tracker also has the silhouettes against one frame of the empty
table scene (``BareHandSequence.render_empty_views``); ``none`` (default): edges only (the
silhouettes did not raise the click figures on tuning seeds 5-7, docs/RESULTS.md);
with them the tracker's ``finger_refit`` and ``silhouette_palm`` act (on, as in
``EdgeTrackerConfig``; ``--no-finger-refit``, ``--no-silhouette-palm`` turn them off);
``--retry-dofs`` sets its ``retry_dofs`` (off by default), with
``--retry-max-wrist-move-mm`` and ``--retry-rest-margin-px`` its retry guards;
``--measurement-rounds``, ``--fault-round`` and ``--min-camera-found-fraction`` its rounds per
frame, its extra round on a faulted frame, its per-camera coverage check,
``--round-min-move-px`` the move below which it makes no further round,
``--finger-refit-dofs``, ``--finger-refit-abduction`` and ``--finger-refit-spread-deg`` its
finger re-fits' DOFs and abduction starts (default ``EdgeTrackerConfig``'s). The mouse is
fed each pose's edge residual (as ``edge_tracker_node``'s status line gives it to
``mouse_node``), so ``--press-max-residual-ratio`` sets its press gate
(``core.tracking.mouse``).

``--source glove`` feeds it the colour-glove tracker's output (segmentation, lookup, IK with
smoothing, as ``ik_node`` runs) on the same script rendered with the glove
(``core.evaluation.scripted_tracking.ScriptedTracker``, the primary camera of
``--calibration``, the largest pose database under data/ unless ``--database``; the tracked
poses are cached in data/scripted_tracking/); frames it did not track reach the mouse as gaps.
"""
from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from colorglove_ros.core.camera import PinholeCamera, load_calibration
from colorglove_ros.core.errors import ColorGloveError
from colorglove_ros.core.evaluation.scripted_hands import ScriptedSequence
from colorglove_ros.core.evaluation.scripted_tracking import ScriptedTracker
from colorglove_ros.core.evaluation.sequences import find_database
from colorglove_ros.core.evaluation.targets import target_row
from colorglove_ros.core.geometry import matrix_to_rotvec
from colorglove_ros.core.hand.model import DOF_NAMES, KEYPOINT_NAMES, HandModel
from colorglove_ros.core.opencv_threads import use_opencv_threads
from colorglove_ros.core.report import print_table, write_json
from colorglove_ros.core.synthetic.bare_hand import BareHandSequence
from colorglove_ros.core.tracking.edge_fit import EdgeTrackerConfig
from colorglove_ros.core.tracking.edge_tracker import EdgeTracker, EdgeTrackResult
from colorglove_ros.core.tracking.mouse import (
    BUTTON_DOFS,
    BUTTON_NAMES,
    Mouse3D,
    MouseConfig,
    raw_mouse_values,
)
from colorglove_ros.core.tracking.silhouette import BackgroundModel
from colorglove_ros.paths import data_dir, resolve_path, share_dir
from colorglove_ros.tools._cli import add_opencv_threads_argument, run_tool, tool_parser
from colorglove_ros.tools.eval_edges import FIT_SETTINGS, add_fit_arguments, fit_settings

__all__ = ['main', 'scripted_sequence', 'evaluate_seed', 'noisy_poses', 'edge_tracked_poses',
           'glove_tracked_poses', 'reinitialisation_pose', 'track_scripted', 'REINIT_MODES',
           'DEFAULT_REINIT',
           'RELAXED_FINGERS_DEG']

FPS = 30.0
# relaxed hand on a table: (mcp, pip, dip) flexion of the four fingers, degrees
RELAXED_FINGERS_DEG = (35.0, 40.0, 27.0)
_INDEX_MCP = DOF_NAMES.index('index_mcp_flex')
_INDEX_PIP = DOF_NAMES.index('index_pip_flex')
_INDEX_DIP = DOF_NAMES.index('index_dip_flex')
# the joints the mouse's buttons read, their scripted angles at rest and added at the top of
# a click (degrees; the little finger's abduction away from the hand is negative)
_BUTTONS = [DOF_NAMES.index(n) for n in BUTTON_DOFS]
_BUTTON_REST_DEG = np.array([5.0, -1.0])
_BUTTON_CLICK_DEG = np.array([35.0, -14.0])
REINIT_MODES: tuple[str, ...] = ('rest', 'truth')
#: How the evaluation (re-)initialises the edge tracker by default (:func:`reinitialisation_pose`).
DEFAULT_REINIT = REINIT_MODES[0]


def _smooth_step(n: int) -> np.ndarray:
    s = np.linspace(0.0, 1.0, n)
    return s**3 * (10 - 15 * s + 6 * s**2)


def _pulses(rng: np.random.Generator, num_frames: int, count: int
            ) -> tuple[np.ndarray, list[tuple[int, int]]]:
    """A 0..1 profile with ``count`` separated pulses (ramps of 0.1 s) and their spans."""
    profile = np.zeros(num_frames)
    spans: list[tuple[int, int]] = []
    slots = np.linspace(30, num_frames - 40, count + 1).astype(int)
    ramp = _smooth_step(int(0.1 * FPS))
    for a, b in zip(slots[:-1], slots[1:], strict=True):
        hold = int(rng.uniform(0.25, 0.6) * FPS)
        start = int(rng.integers(a, max(a + 1, b - hold - 2 * len(ramp) - 10)))
        up, top, down = start, start + len(ramp), start + len(ramp) + hold
        profile[up:top] = ramp
        profile[top:down] = 1.0
        profile[down:down + len(ramp)] = ramp[::-1]
        spans.append((up, down + len(ramp)))
    return profile, spans


def scripted_sequence(model: HandModel, config: MouseConfig, seed: int, seconds: float = 30.0,
                      clicks: int = 10) -> tuple[np.ndarray, list[list[tuple[int, int]]]]:
    """(N, 26) true poses and, per button, the scripted click spans (first, end) frames."""
    rng = np.random.default_rng([seed, 31])
    n = int(seconds * FPS)
    plane = config.plane
    up = plane.normal
    y_hand = -np.asarray(plane.y_axis, float)           # fingers point away from the camera
    x_hand = np.cross(y_hand, up)
    R = np.stack([x_hand, y_hand, up], axis=1)
    q0 = np.zeros(26)
    q0[3:6] = matrix_to_rotvec(R)
    mcp, pip, dip = np.radians(RELAXED_FINGERS_DEG)
    for digit in ('index', 'middle', 'ring', 'little'):
        q0[DOF_NAMES.index(f'{digit}_mcp_flex')] = mcp
        q0[DOF_NAMES.index(f'{digit}_pip_flex')] = pip
        q0[DOF_NAMES.index(f'{digit}_dip_flex')] = dip
    kp = model.keypoints(q0)
    tip_drop = float((kp[KEYPOINT_NAMES.index('index_tip')] - kp[0]) @ up)
    lift = -tip_drop                                   # wrist height putting the tip on the table
    # palm path: waypoints every 1-2.5 s, smooth steps between them
    path = np.zeros((n, 2))
    t, cur = 0, rng.uniform([-0.15, -0.1], [0.15, 0.1])
    while t < n:
        hold, move = int(rng.uniform(0.3, 1.0) * FPS), int(rng.uniform(0.7, 1.5) * FPS)
        nxt = rng.uniform([-0.15, -0.1], [0.15, 0.1])
        path[t:t + hold] = cur
        seg = _smooth_step(move)[:, None] * (nxt - cur) + cur
        path[t + hold:t + hold + move] = seg[:max(0, min(move, n - t - hold))]
        cur, t = nxt, t + hold + move
    Q = np.repeat(q0[None], n, axis=0)
    origin = np.asarray(plane.origin, float)
    Q[:, 0:3] = origin + path[:, :1] * np.asarray(plane.x_axis) \
        + path[:, 1:] * np.asarray(plane.y_axis) + lift * up
    index_lift, _ = _pulses(rng, n, 6)
    Q[:, _INDEX_MCP] = mcp * (1 - index_lift)
    Q[:, _INDEX_PIP] = pip * (1 - index_lift)
    Q[:, _INDEX_DIP] = dip * (1 - index_lift)
    thumb, thumb_spans = _pulses(rng, n, clicks)
    little, little_spans = _pulses(rng, n, clicks)
    Q[:, _BUTTONS] = np.radians(_BUTTON_REST_DEG + np.stack([thumb, little], axis=1)
                                * _BUTTON_CLICK_DEG)
    return model.clamp(Q), [thumb_spans, little_spans]


def reinitialisation_pose(q: np.ndarray, reinit: str = DEFAULT_REINIT) -> np.ndarray:
    """The pose the evaluation (re-)initialises the edge tracker from at a frame whose true
    pose is ``q``: with ``reinit`` 'rest' ``q`` with the buttons' joints (``BUTTON_DOFS``) at
    the scripted hand's rest angles (no button down, whatever the frame's click), with
    'truth' ``q`` itself."""
    if reinit not in REINIT_MODES:
        raise ColorGloveError(f'reinit must be one of {REINIT_MODES}, got {reinit!r}')
    out = np.array(q, dtype=float)
    if reinit == 'rest':
        out[_BUTTONS] = np.radians(_BUTTON_REST_DEG)
    return out


def track_scripted(tracker: EdgeTracker, Q: np.ndarray,
                   views: Callable[[int], Sequence[np.ndarray | None]],
                   reinit: str = DEFAULT_REINIT
                   ) -> tuple[list[EdgeTrackResult], list[int]]:
    """``tracker`` over the frames ``views(i)`` (one image per camera) of the scripted poses
    ``Q``, started from :func:`reinitialisation_pose` of the first and, after a loss, of the
    frame it is re-initialised on; each frame's result and the re-initialised frames."""
    tracker.initialize(reinitialisation_pose(Q[0], reinit))
    results: list[EdgeTrackResult] = []
    restarts: list[int] = []
    for i in range(len(Q)):
        if tracker.state == 'waiting':
            tracker.initialize(reinitialisation_pose(Q[i], reinit))
            restarts.append(i)
        results.append(tracker.update(views(i)))
    return results, restarts


def noisy_poses(model: HandModel, Q: np.ndarray, seed: int, noise: dict[str, float]
                ) -> list[np.ndarray | None]:
    """The poses as a tracker would deliver them under the noise model: Gaussian errors and
    a fraction of frames dropped (None)."""
    rng = np.random.default_rng([seed, 37])
    out: list[np.ndarray | None] = []
    for q in Q:
        if rng.uniform() < noise['drop']:
            out.append(None)
            continue
        noisy = q.copy()
        noisy[0:3] += rng.normal(0.0, noise['position_mm'] / 1e3, 3)
        noisy[3:6] += rng.normal(0.0, math.radians(noise['rotation_deg']), 3)
        noisy[6:] += rng.normal(0.0, math.radians(noise['joint_deg']), 20)
        out.append(model.clamp(noisy))
    return out


def edge_tracked_poses(Q: np.ndarray, seed: int, cameras: Sequence[PinholeCamera],
                       hand_length_m: float, silhouettes: bool = False,
                       config: EdgeTrackerConfig | None = None,
                       reinit: str = DEFAULT_REINIT
                       ) -> tuple[list[np.ndarray | None], list[int], list[float]]:
    """The edge tracker's published poses on the bare-hand rendering of ``Q`` seen by
    ``cameras`` (the primary first; the poses are in its frame; None where it published
    none), the frames where it was re-initialised after a loss (:func:`track_scripted`,
    ``reinit``) and each frame's edge residual (px, NaN without a fit, as ``edge_tracker_node``
    puts it on its status line); ``silhouettes``: with a background model per camera from
    the empty scene; ``config``: the tracker's settings (default :class:`EdgeTrackerConfig`)."""
    cameras = list(cameras)
    seq = BareHandSequence(cameras[0], seed=seed, poses=Q, hand_length_m=hand_length_m,
                           views=len(cameras))
    try:
        backgrounds = [BackgroundModel.from_frames([e]) for e in
                       seq.render_empty_views(cameras)] if silhouettes else None
        tracker = EdgeTracker(seq.synth.model, cameras, config, backgrounds)
        results, restarts = track_scripted(
            tracker, Q, lambda i: [v.image_rgb for v in seq.render_views(i, cameras)], reinit)
        return ([r.q for r in results], restarts,
                [math.nan if r.fit is None else r.fit.rms_px for r in results])
    finally:
        seq.close()


def glove_tracked_poses(model: HandModel, Q: np.ndarray, seed: int, tracker: ScriptedTracker
                        ) -> list[np.ndarray | None]:
    """The glove tracker's poses on the glove rendering of ``Q`` (None where it found no
    hand), through ``tracker`` (cached as sequence 'mouse' of this seed)."""
    n = len(Q)
    truth = ScriptedSequence(np.asarray(Q, dtype=float), np.zeros(n, dtype=np.int64),
                             np.full(n, ''), np.zeros(n, dtype=bool), FPS)
    q_est, found = tracker.observe('mouse', seed, truth, model)
    return [q.copy() if ok else None for q, ok in zip(q_est, found, strict=True)]


#: Per-click lists in :func:`evaluate_seed`'s row (JSON and per-seed line, not the table).
_CLICK_LISTS = ('missed_clicks', 'false_presses')


def evaluate_seed(model: HandModel, config: MouseConfig, seed: int,
                  poses: list[np.ndarray | None], tolerance: int,
                  Q: np.ndarray, spans: list[list[tuple[int, int]]],
                  reinitialised: Sequence[int] = (),
                  residuals: Sequence[float] | None = None) -> dict[str, Any]:
    """Run the mouse over one scripted sequence (true poses ``Q``, click ``spans``) fed with
    ``poses`` (one per frame, None = no pose that frame) and, if given, each pose's fit
    ``residuals`` (px, NaN = unknown; the mouse's ``press_max_residual_ratio``); counts and
    errors.
    ``reinitialised``: frames where the tracker was re-initialised (``reinitialisation_pose``);
    ``correct_at_reinit`` counts the correct clicks with one of them between the click's
    start (less ``tolerance``) and the press. ``missed_clicks`` lists the scripted clicks no
    press matched as (button, first frame, end frame), ``false_presses`` the presses outside
    every click as (button, frame), buttons named as ``BUTTON_NAMES``."""
    mouse = Mouse3D(model, config)
    rest = raw_mouse_values(model, Q[0], config)
    presses: list[list[int]] = [[], []]
    errors = []
    if residuals is None:
        residuals = [math.nan] * len(poses)
    for i, (q, tracked, residual) in enumerate(zip(Q, poses, residuals, strict=True)):
        if tracked is None:
            continue
        state = mouse.update(tracked, i / FPS, residual)
        for k in range(2):
            if state.pressed[k]:
                presses[k].append(i)
        errors.append(np.linalg.norm(state.cursor - raw_mouse_values(model, q, config)[:3]))
    out: dict[str, Any] = {'seed': seed, 'frames': len(Q),
                           'frames_with_pose': sum(p is not None for p in poses)}
    tp = fp = truth = at_reinit = 0
    restarts = np.asarray(sorted(reinitialised), dtype=np.int64)
    missed: list[tuple[str, int, int]] = []
    false: list[tuple[str, int]] = []
    for k in range(2):
        used = set()
        for frame in presses[k]:
            hit = next((j for j, (a, b) in enumerate(spans[k]) if j not in used
                        and a - tolerance <= frame < b + tolerance), None)
            if hit is None:
                fp += 1
                false.append((BUTTON_NAMES[k], frame))
            else:
                used.add(hit)
                tp += 1
                start = spans[k][hit][0] - tolerance
                at_reinit += bool(np.any((restarts >= start) & (restarts <= frame)))
        missed += [(BUTTON_NAMES[k], a, b) for j, (a, b) in enumerate(spans[k]) if j not in used]
        truth += len(spans[k])
    out.update({'scripted_clicks': truth, 'detected': tp + fp, 'correct': tp,
                'correct_at_reinit': at_reinit,
                'precision': tp / (tp + fp) if tp + fp else 0.0, 'recall': tp / truth,
                'cursor_error_mm': 1e3 * float(np.mean(errors)) if errors else math.nan,
                'cursor_p95_mm': 1e3 * float(np.percentile(errors, 95)) if errors else math.nan,
                'height_range_mm': 1e3 * float(np.ptp([raw_mouse_values(model, q, config)[2]
                                                       for q in Q[::5]])),
                'rest_height_mm': 1e3 * float(rest[2]),
                'missed_clicks': missed, 'false_presses': false})
    return out


def main(argv: list[str] | None = None) -> int:
    """Entry point of ``colorglove_eval_mouse``."""
    parser = tool_parser(__doc__.split('\n\n')[0])
    parser.add_argument('--seeds', type=int, nargs='+', default=[0, 1, 2, 3, 4])
    parser.add_argument('--joint-noise-deg', type=float, default=3.0)
    parser.add_argument('--position-noise-mm', type=float, default=3.0)
    parser.add_argument('--rotation-noise-deg', type=float, default=1.5)
    parser.add_argument('--drop', type=float, default=0.05, help='fraction of frames lost')
    parser.add_argument('--tolerance-frames', type=int, default=3)
    parser.add_argument('--source', choices=('noise', 'edges', 'glove'), default='noise',
                        help='poses from the noise model, or the edge / glove tracker on '
                        'rendered frames')
    parser.add_argument('--database', type=Path,
                        help='with --source glove: pose database (default: the largest under '
                        'data/)')
    parser.add_argument('--seconds', type=float, default=30.0, help='length of each sequence')
    parser.add_argument('--background', choices=('empty', 'none'), default='none',
                        help='with --source edges: silhouettes against the empty scene, or '
                        'edges only')
    parser.add_argument('--calibration', default='config/calibration.yaml',
                        help='cameras (the first --cameras of them) for --source edges')
    parser.add_argument('--cameras', type=int, default=1, choices=(1, 2),
                        help='with --source edges: cameras of --calibration the edge tracker '
                        'fits (2: e.g. config/calibration_table_stereo.yaml)')
    parser.add_argument('--camera-weights', type=float, nargs='+',
                        help='with --source edges: the edge tracker\'s camera_weights '
                        '(default: EdgeTrackerConfig\'s)')
    add_fit_arguments(parser, applies='with --source edges: ')
    add_opencv_threads_argument(parser)
    parser.add_argument('--reinit', choices=REINIT_MODES, default=DEFAULT_REINIT,
                        help='with --source edges: (re-)initialise the edge tracker from the '
                        'true pose with the buttons\' joints at rest (default), or from the '
                        'true pose itself (truth: a loss during a click hands it the click)')
    parser.add_argument('--retry-dofs', nargs='+', default=[],
                        help='with --source edges: the edge tracker\'s retry_dofs (e.g. '
                        'thumb_cmc_abd)')
    parser.add_argument('--retry-max-wrist-move-mm', type=float,
                        help='with --retry-dofs: the tracker\'s retry_max_wrist_move_m, in mm '
                        '(default: EdgeTrackerConfig\'s, off)')
    parser.add_argument('--retry-rest-margin-px', type=float,
                        help='with --retry-dofs: the tracker\'s retry_rest_margin_px (default: '
                        'EdgeTrackerConfig\'s, off)')
    parser.add_argument('--press-max-residual-ratio', type=float,
                        help='with --source edges: the mouse\'s press_max_residual_ratio (a '
                        'press needs an edge residual at most this many times the recent '
                        'median; 0: off, as mouse_node reads it; default: MouseConfig\'s)')
    args = parser.parse_args(argv)
    return run_tool('colorglove_eval_mouse', lambda: _run(args))


def _run(args: Any) -> int:
    use_opencv_threads(args.opencv_threads)
    calibration = load_calibration(resolve_path(args.calibration))
    if args.source == 'edges' and len(calibration.cameras) < args.cameras:
        raise ColorGloveError(f'{args.calibration} has {len(calibration.cameras)} camera(s), '
                              f'--cameras asks for {args.cameras}')
    cameras = calibration.cameras[:args.cameras]
    model = HandModel(calibration.hand_length_m) if args.source != 'noise' else HandModel()
    config = MouseConfig()
    if args.press_max_residual_ratio is not None:
        ratio = args.press_max_residual_ratio
        config = replace(config, press_max_residual_ratio=ratio if ratio > 0 else math.inf)
    noise = {'joint_deg': args.joint_noise_deg, 'position_mm': args.position_noise_mm,
             'rotation_deg': args.rotation_noise_deg, 'drop': args.drop}
    glove: ScriptedTracker | None = None
    if args.source == 'glove':
        database = args.database or find_database(data_dir())
        if database is None:
            raise ColorGloveError(f'no pose database under {data_dir()}; pass --database')
        glove = ScriptedTracker(database, share_dir() / 'config' / 'ik.yaml',
                                resolve_path(args.calibration), data_dir() / 'scripted_tracking')
    try:
        return _evaluate_all(args, model, config, noise, cameras, calibration.hand_length_m,
                             glove)
    finally:
        if glove is not None:
            glove.close()


def _evaluate_all(args: Any, model: HandModel, config: MouseConfig, noise: dict[str, float],
                  cameras: Sequence[PinholeCamera], hand_length_m: float,
                  glove: ScriptedTracker | None) -> int:
    edge_config = EdgeTrackerConfig(retry_dofs=tuple(args.retry_dofs), **fit_settings(args))
    if args.camera_weights is not None:
        edge_config = replace(edge_config, camera_weights=tuple(args.camera_weights))
    if args.retry_max_wrist_move_mm is not None:
        edge_config = replace(edge_config,
                              retry_max_wrist_move_m=args.retry_max_wrist_move_mm / 1e3)
    if args.retry_rest_margin_px is not None:
        edge_config = replace(edge_config, retry_rest_margin_px=args.retry_rest_margin_px)
    rows = []
    for seed in args.seeds:
        Q, spans = scripted_sequence(model, config, seed, args.seconds)
        extra: dict[str, Any] = {}
        restarts: list[int] = []
        residuals: list[float] | None = None
        if args.source == 'edges':
            poses, restarts, residuals = edge_tracked_poses(
                Q, seed, cameras, hand_length_m, args.background == 'empty', edge_config,
                args.reinit)
            extra['reinitialisations'] = len(restarts)
        elif glove is not None:
            poses = glove_tracked_poses(model, Q, seed, glove)
        else:
            poses = noisy_poses(model, Q, seed, noise)
        rows.append({**evaluate_seed(model, config, seed, poses, args.tolerance_frames, Q,
                                     spans, restarts, residuals), **extra})
        print(f'seed {seed}: {rows[-1]}', flush=True)
    tp = sum(r['correct'] for r in rows)
    det = sum(r['detected'] for r in rows)
    truth = sum(r['scripted_clicks'] for r in rows)
    total = {'precision': tp / det if det else 0.0, 'recall': tp / truth,
             'correct_at_reinit': sum(r['correct_at_reinit'] for r in rows),
             'cursor_error_mm': float(np.mean([r['cursor_error_mm'] for r in rows]))}
    source = {'noise': f'noise {noise}',
              'edges': f'the edge tracker ({len(cameras)} camera(s): '
                       f'{", ".join(c.name for c in cameras)})',
              'glove': 'the glove tracker (1 camera)'}[args.source]
    print_table([{k: v for k, v in r.items() if k not in _CLICK_LISTS} for r in rows],
                f'3-D mouse, scripted sequences, poses from {source}')
    targets = [target_row('click precision >= 95 %', 100 * total['precision'], 95.0, '>='),
               target_row('click recall >= 95 %', 100 * total['recall'], 95.0, '>=')]
    print_table([{**total}], 'all seeds')
    print_table(targets, 'targets')
    if args.json:
        write_json(args.json, {'settings': {'seeds': args.seeds, **noise,
                                            'tolerance_frames': args.tolerance_frames,
                                            'source': args.source, 'seconds': args.seconds,
                                            'background': args.background,
                                            'reinit': args.reinit,
                                            'opencv_threads': args.opencv_threads,
                                            'calibration': args.calibration,
                                            'cameras': [c.name for c in cameras],
                                            'camera_weights': list(edge_config.camera_weights),
                                            **{name: getattr(edge_config, name)
                                               for name in FIT_SETTINGS},
                                            'retry_dofs': list(edge_config.retry_dofs),
                                            **{name: value if math.isfinite(value) else None
                                               for name, value in (
                                                   ('press_max_residual_ratio',
                                                    config.press_max_residual_ratio),
                                                   ('retry_max_wrist_move_m',
                                                    edge_config.retry_max_wrist_move_m),
                                                   ('retry_rest_margin_px',
                                                    edge_config.retry_rest_margin_px))}},
                               'rows': rows, 'total': total, 'targets': targets})
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
