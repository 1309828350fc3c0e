"""The temporal IK tracker: one frame's lookup prior and blobs of N cameras -> a refined pose."""
from __future__ import annotations

import math
import time
from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from colorglove_ros.core.camera import Calibration, PinholeCamera
from colorglove_ros.core.geometry import align_rotation_vector
from colorglove_ros.core.hand.glove import default_hand
from colorglove_ros.core.hand.mesh import build_hand_mesh
from colorglove_ros.core.hand.model import NUM_DOFS, HandModel, calibrated_hand_model
from colorglove_ros.core.tracking.config import IKConfig, IKCovariances
from colorglove_ros.core.tracking.kinematics import FastKinematics
from colorglove_ros.core.tracking.line_constraints import ExtraConstraints, line_constraints
from colorglove_ros.core.tracking.matching import (
    explained_blob_share,
    match_extra_camera,
    match_primary,
)
from colorglove_ros.core.tracking.patch_surface import PatchSurface
from colorglove_ros.core.tracking.projection import (
    estimate_translation,
    pixel_scale,
    reprojection_errors,
)
from colorglove_ros.core.tracking.solver import IKSolution, solve_ik
from colorglove_ros.core.tracking.types import (
    Blobs,
    CameraObservation,
    Correspondences,
    IKError,
    MeshLike,
    PosePrior,
)

__all__ = ['IKResult', 'HandTracker', 'away_from_border']


@dataclass(frozen=True)
class IKResult:
    """One tracker output. ``reprojection_error_px`` is the mean pixel distance of the
    matched constraints at the output pose (NaN when none); ``q`` is None when no hand.
    ``q_blend`` is the lookup's blended pose as given, ``q_prior`` the IK prior q_b (the
    blend with its translation refitted to the constraints)."""

    found: bool
    stamp: float
    q: np.ndarray | None = None
    q_blend: np.ndarray | None = None
    reprojection_error_px: float = math.nan
    reprojection_error_per_camera: tuple[float, ...] = ()
    iterations: int = 0
    time_ms: float = 0.0
    num_constraints: int = 0
    constraints_per_camera: tuple[int, ...] = ()
    smoothed: bool = False
    reset: bool = False
    correspondences: Correspondences | None = None
    num_rejected: int = 0
    q_prior: np.ndarray | None = None
    # share of the primary camera's blobs the fit's correspondences explain
    # (``matching.explained_blob_share``; NaN when there was no usable blob)
    explained_blob_share: float = math.nan
    # tracked from the last pose without the lookup (:meth:`HandTracker.follow`)
    followed: bool = False


def _local_vertex_normals(mesh: MeshLike) -> np.ndarray | None:
    """Area-weighted vertex normals in the link frames, or None if the mesh has no faces
    (then no back-facing test is made for the other cameras)."""
    faces = getattr(mesh, 'faces', None)
    if faces is None:
        return None
    faces = np.asarray(faces, dtype=np.int64)
    links = np.asarray(mesh.vertex_link)
    if faces.ndim != 2 or faces.shape[1] != 3 or np.any(links[faces[:, 0]] != links[faces[:, 1]]) \
            or np.any(links[faces[:, 0]] != links[faces[:, 2]]):
        return None
    v = np.asarray(mesh.local_vertices, float)
    fn = np.cross(v[faces[:, 1]] - v[faces[:, 0]], v[faces[:, 2]] - v[faces[:, 0]])
    n = np.zeros_like(v)
    for k in range(3):
        np.add.at(n, faces[:, k], fn)
    norm = np.linalg.norm(n, axis=1, keepdims=True)
    return n / np.where(norm > 0, norm, 1.0)


@dataclass(frozen=True)
class _FramePriors:
    """The priors of one frame's IK: the translation-refitted blend q_b, the previous pose
    (None without smoothing) and the covariances."""

    q_b: np.ndarray
    q_prev: np.ndarray | None
    covariances: IKCovariances
    lines: ExtraConstraints | None = None   # line features (IKConfig.line_features)


@dataclass
class _FrameFit:
    """One frame's IK so far: pose, correspondences, their pixel errors at the pose (None
    until a solve or the final check), linear solves made and correspondences dropped."""

    q: np.ndarray
    corr: Correspondences
    err: np.ndarray | None = None
    iterations: int = 0
    rejected: int = 0


def away_from_border(observation: CameraObservation | None, camera: PinholeCamera
                     ) -> CameraObservation | None:
    """``observation`` without the blobs whose centroid lies nearer to the image border than
    their side (the square root of their pixel count): a patch the border cuts shows only
    its inner part, whose centroid is not the patch's (the IK would pull the hand inward)."""
    if observation is None or not observation.hand_found or not len(observation.blobs):
        return observation
    blobs = observation.blobs
    x, y = blobs.centroid_px[:, 0], blobs.centroid_px[:, 1]
    margin = np.minimum(np.minimum(x, camera.width - x), np.minimum(y, camera.height - y))
    keep = margin >= np.sqrt(blobs.pixel_count)
    return replace(observation, blobs=Blobs(blobs.color[keep], blobs.centroid_px[keep],
                                            blobs.pixel_count[keep]))


def _check_primary(camera: PinholeCamera) -> None:
    if not (np.allclose(camera.rotation, np.eye(3)) and np.allclose(camera.translation, 0.0)):
        raise IKError('cameras[0] (primary) must have identity extrinsics')


class HandTracker:
    """Temporal IK tracker: blended lookup pose -> refined pose, several cameras.

    The world frame is the primary camera's optical frame (``cameras[0]`` must have
    identity extrinsics); poses are expressed in it. With ``constraint_model: patch`` the
    tracker needs the glove's patch of every mesh face: ``glove`` (a ``core.hand.glove.Glove``),
    or else the standard glove (``default_hand(hand length)``), which must have been made on
    the same mesh. Callers tracking with a pose database pass the glove of the database's
    build record (``core.lookup.database.DatabaseBuild``).
    """

    def __init__(self, model: HandModel, mesh: MeshLike, cameras: Sequence[PinholeCamera],
                 config: IKConfig | None = None, glove: Any = None) -> None:
        if not cameras:
            raise IKError('the tracker needs at least one camera')
        _check_primary(cameras[0])
        if len(mesh.vertex_link) != len(mesh.local_vertices):
            raise IKError('mesh vertex_link and local_vertices differ in length')
        self.model = model
        self.kin = FastKinematics(model)
        self.mesh = mesh
        self.cameras = tuple(cameras)
        self.config = config or IKConfig()
        self._q_prev: np.ndarray | None = None
        self._stamp_prev: float | None = None
        self._constraints_prev: Any = None     # the last lookup's constraints (follow)
        self._local_normals = _local_vertex_normals(mesh)
        self._glove = glove
        self._patches = (PatchSurface(self.kin, mesh, self._glove_or_default().face_patch)
                         if self.config.constraint_model == 'patch' else None)

    @property
    def patch_surface(self) -> PatchSurface:
        """The glove's patches on this tracker's mesh (the patch constraint model's, else made
        on first use): what the evidence gates predict the image shows at a pose."""
        if self._patches is None:
            self._patches = PatchSurface(self.kin, self.mesh, self._glove_or_default().face_patch)
        return self._patches

    @property
    def patch_color(self) -> np.ndarray:
        """(num_patches,) colour label (1..10) of every glove patch."""
        return np.asarray(self._glove_or_default().patch_color)

    def _glove_or_default(self) -> Any:
        """The glove given at construction, else the standard glove of the standard mesh
        (made once; :class:`IKError` when this tracker's mesh is another one)."""
        if self._glove is None:
            _, std_mesh, glove = default_hand(
                self.model.hand_length_m, finger_length_factors=self.model.finger_length_factors)
            faces = getattr(self.mesh, 'faces', None)
            if faces is None or not np.array_equal(np.asarray(faces), std_mesh.faces):
                raise IKError("this tracker's mesh is not the standard mesh: pass glove= (the "
                              'glove made on this mesh)')
            self._glove = glove
        return self._glove

    def _with_patch_points(self, corr: Correspondences, q: np.ndarray) -> Correspondences:
        """``corr`` with each constraint moved from its vertex to the predicted centroid of
        the patch's visible part at pose ``q`` (rows whose patch faces away keep the
        vertex)."""
        if self._patches is None or not len(corr):
            return corr
        s = self._patches.max_links
        link = np.zeros((len(corr), s), np.int64)
        local = np.zeros((len(corr), s, 3))
        weight = np.zeros((len(corr), s))
        link[:, 0], local[:, 0], weight[:, 0] = corr.link[:, 0], corr.local[:, 0], 1.0
        used, cam_index = np.unique(corr.camera, return_inverse=True)
        lk, lc, wt, seen = self._patches.points_by_camera(
            q, [self.cameras[int(c)] for c in used], cam_index.reshape(-1), corr.patch_id)
        link[seen], local[seen], weight[seen] = lk[seen], lc[seen], wt[seen]
        return replace(corr, link=link, local=local, weight=weight)

    @classmethod
    def from_calibration(cls, calibration: Calibration, config: IKConfig | None = None,
                         mesh: MeshLike | None = None) -> HandTracker:
        """A tracker for a calibrated rig: the hand model (and, if not given, the mesh) is
        the user's (``calibrated_hand_model``: ``hand_length_m`` and finger length
        factors)."""
        model = calibrated_hand_model(calibration)
        if mesh is None:
            mesh = build_hand_mesh(model)
        mesh_length = getattr(mesh, 'hand_length_m', None)
        if mesh_length is not None and abs(float(mesh_length) - model.hand_length_m) > 1e-9:
            raise IKError(f'mesh is for a {mesh_length} m hand, calibration says '
                          f'{model.hand_length_m} m')
        mesh_factors = getattr(mesh, 'finger_length_factors', None)
        if mesh_factors is not None and not np.allclose(mesh_factors,
                                                        model.finger_length_factors):
            raise IKError(f'mesh is for finger length factors {tuple(mesh_factors)}, '
                          f'calibration says {model.finger_length_factors}')
        return cls(model, mesh, calibration.cameras, config)

    def set_camera(self, index: int, camera: PinholeCamera) -> None:
        """Use ``camera`` as camera ``index`` from now on (new intrinsics or image size of the
        same, fixed camera, e.g. from its CameraInfo, with its calibrated extrinsics). The
        track restarts: the previous pose was fitted with the old model."""
        if not 0 <= index < len(self.cameras):
            raise IKError(f'camera index {index} outside [0, {len(self.cameras)})')
        if index == 0:
            _check_primary(camera)
        cameras = list(self.cameras)
        cameras[index] = camera
        self.cameras = tuple(cameras)
        self.reset()

    def _pixel_scale(self, index: int) -> float:
        """Camera ``index``'s pixels per pixel of the configuration's reference focal
        length (the factor on its pixel gates; areas take the square)."""
        return pixel_scale(self.cameras[index], self.config.reference_focal_px)

    def _min_blob_pixels(self, index: int) -> float:
        """The smallest blob camera ``index`` matches: ``min_blob_pixels`` (an area at the
        reference focal length) in its own pixels."""
        return self.config.min_blob_pixels * self._pixel_scale(index) ** 2

    def reset(self) -> None:
        """Forget the previous pose (hand lost, long gap, new sequence)."""
        self._q_prev = None
        self._stamp_prev = None
        self._constraints_prev = None

    @property
    def previous_pose(self) -> np.ndarray | None:
        """The last output pose, or None after a reset."""
        return None if self._q_prev is None else self._q_prev.copy()

    def _match_extras(self, prior: PosePrior, observations: Sequence[CameraObservation],
                      q: np.ndarray, patch_points: bool = True, first_camera: int = 1
                      ) -> Correspondences:
        """The correspondences of cameras ``first_camera`` on (the other cameras; 0: every
        camera) matched at pose ``q`` without a lookup (``match_extra_camera``), constraints
        moved to the patch points at ``q`` unless ``patch_points`` is false."""
        cfg = self.config
        cons = prior.constraints
        v = cons.vertices
        if np.any((v < 0) | (v >= len(self.mesh.vertex_link))):
            raise IKError('constraint vertex index out of range of the mesh')
        links = np.asarray(self.mesh.vertex_link)[v]
        pw, _ = self.kin.points(q, links, np.asarray(self.mesh.local_vertices, float)[v])
        normals = None
        if self._local_normals is not None:
            Rs, _, _ = self.kin.frames(q)
            normals = (Rs[self.kin.link_frame[links]] @ self._local_normals[v][:, :, None])[..., 0]
        out = []
        for ci in range(first_camera, len(self.cameras)):
            obs = observations[ci] if ci < len(observations) else None
            if obs is None or not obs.hand_found or len(obs.blobs) == 0:
                continue
            s = self._pixel_scale(ci)
            out.append(match_extra_camera(
                ci, self.cameras[ci], cons, pw, obs.blobs, self.mesh, cfg.extra_gate_px * s,
                cfg.extra_shift_max_px * s, cfg.extra_inlier_px * s,
                self._min_blob_pixels(ci), cfg.min_depth_m, normals))
        out = Correspondences.concat(out)
        return self._with_patch_points(out, q) if patch_points else out

    def _solve(self, corr: Correspondences, q_init: np.ndarray, iterations: int,
               priors: _FramePriors) -> IKSolution:
        cfg = self.config
        return solve_ik(self.kin, self.cameras, corr, q_init, priors.q_b, priors.covariances,
                        priors.q_prev, iterations, cfg.lambda_init, cfg.step_tol,
                        cfg.min_depth_m, cfg.cost_tol, cfg.reference_focal_px, priors.lines)

    def _solve_into(self, fit: _FrameFit, corr: Correspondences, q_init: np.ndarray,
                    iterations: int, priors: _FramePriors) -> None:
        """Solve on ``corr`` from ``q_init`` and make it the frame's fit."""
        sol = self._solve(corr, q_init, iterations, priors)
        fit.corr, fit.q, fit.err = corr, sol.q, sol.errors_px
        fit.iterations += sol.iterations

    def update(self, prior: PosePrior | Any | None, observations: Sequence[CameraObservation],
               stamp: float) -> IKResult:
        """Track one frame: ``prior`` from the lookup on the primary camera (a
        :class:`PosePrior` or a ``core.lookup.types.LookupResult``; None if the lookup found
        nothing), one observation per camera (primary first), time in seconds."""
        t0 = time.perf_counter()
        cfg = self.config
        if prior is not None and not isinstance(prior, PosePrior):
            prior = PosePrior.from_lookup(prior)
        primary = observations[0] if observations else None
        if prior is None or primary is None or not primary.hand_found:
            return self._lost(stamp, t0)
        was_reset = self._reset_after_gap(stamp)
        q_blend = self._blend_start(prior)
        corr0, tracked = self._match_start(prior, observations, q_blend)
        q_b = self._fit_translation(corr0, q_blend)
        q_prev = self._q_prev if (cfg.enable_smoothing and self._q_prev is not None) else None
        lines = line_constraints(
            self.kin, self.cameras, [o.edge_image if o is not None and o.hand_found else None
                                     for o in observations[:len(self.cameras)]],
            q_b if self._q_prev is None else self._q_prev, cfg.line_std_px) \
            if cfg.line_features and cfg.enable_ik else None
        priors = _FramePriors(q_b, q_prev, cfg.prior_covariances(prior.finger_std), lines)
        fit = self._fit_frame(prior, observations, corr0, tracked, priors)
        self._constraints_prev = prior.constraints
        return self._finish(fit, stamp, t0, q_blend, priors, was_reset, primary.blobs)

    def follow(self, observations: Sequence[CameraObservation], stamp: float) -> IKResult:
        """Track one frame from the last pose alone, without a lookup: every camera's blobs
        (the primary's too) are matched to the last lookup's constraints predicted at the
        last pose, as the other cameras' always are (``match_extra_camera``), and the IK
        starts from the last pose, which is both its prior and its smoothing anchor. For a
        hand the primary image's border cuts, whose lookup normalises the visible part as if
        it were the whole hand (``core.pipeline.track``). No hand (and a reset) without a
        last pose, after a gap, without IK or with fewer than ``min_constraints`` matches."""
        t0 = time.perf_counter()
        cfg = self.config
        primary = observations[0] if observations else None
        was_reset = self._reset_after_gap(stamp)
        if (was_reset or self._q_prev is None or self._constraints_prev is None
                or primary is None or not primary.hand_found or not cfg.enable_ik):
            return self._lost(stamp, t0)
        q_last = self._q_prev.copy()
        last = PosePrior(q_last, self._constraints_prev)
        inner = [away_from_border(obs, camera) for obs, camera in
                 zip(observations, self.cameras, strict=False)]
        corr = self._match_extras(last, inner, q_last, first_camera=0)
        if len(corr) < cfg.min_constraints:
            return self._lost(stamp, t0)
        priors = _FramePriors(q_last, q_last if cfg.enable_smoothing else None,
                              cfg.prior_covariances(None))
        fit = _FrameFit(q_last, corr)
        iterations = cfg.multi_camera_iterations if len(self.cameras) > 1 \
            else cfg.max_iterations
        self._solve_into(fit, corr, q_last, max(iterations, 1), priors)
        self._drop_outliers(fit, priors)
        return replace(self._finish(fit, stamp, t0, q_last, priors, False, inner[0].blobs),
                       followed=True)

    def _lost(self, stamp: float, t0: float) -> IKResult:
        """No hand on this frame (begun at ``perf_counter`` ``t0``): the track is forgotten."""
        self.reset()
        return IKResult(False, stamp, reset=True, time_ms=1e3 * (time.perf_counter() - t0))

    def _reset_after_gap(self, stamp: float) -> bool:
        """Reset when the time since the last frame is not in (0, ``max_gap_s``]."""
        if self._stamp_prev is not None:
            gap = stamp - self._stamp_prev
            if not 0.0 < gap <= self.config.max_gap_s:
                self.reset()
                return True
        return False

    def _blend_start(self, prior: PosePrior) -> np.ndarray:
        """The lookup's blended pose inside the joint limits, its rotation vector taken
        closest to the last pose's."""
        q_blend = self.kin.clamp(np.asarray(prior.q_blend, dtype=float).reshape(NUM_DOFS))
        if self._q_prev is not None:
            q_blend[3:6] = align_rotation_vector(q_blend[3:6], self._q_prev[3:6])
        return q_blend

    def _match_start(self, prior: PosePrior, observations: Sequence[CameraObservation],
                     q_blend: np.ndarray) -> tuple[Correspondences, Correspondences | None]:
        """The primary camera's correspondences, and while tracking with several cameras all
        cameras' correspondences matched at the last pose (else None)."""
        cfg = self.config
        primary = observations[0]
        s = self._pixel_scale(0)
        corr0 = match_primary(prior.constraints, primary.blobs, primary.crop, self.cameras[0],
                              self.mesh, cfg.gate_tiny_px, cfg.gate_min_px * s,
                              self._min_blob_pixels(0), cfg.max_blob_ratio,
                              cfg.min_constraints)
        # IK on several cameras, tracking: the other cameras are matched at the last pose and
        # every camera's visible patches predicted there, in one pass (the blend is the
        # coarser guess)
        if len(self.cameras) > 1 and cfg.enable_ik and self._q_prev is not None:
            tracked = self._with_patch_points(Correspondences.concat(
                [corr0, self._match_extras(prior, observations, self._q_prev, False)]),
                self._q_prev)
            return tracked.select(tracked.camera == 0), tracked
        return self._with_patch_points(corr0, self._shape_source(q_blend)), None

    def _shape_source(self, q_blend: np.ndarray) -> np.ndarray:
        """The pose whose rotation and fingers the frame's set-up assumes (the visible part
        of each patch, the translation refit): the previous output while tracking with
        ``shape_at_previous_pose`` and smoothing, else the blend."""
        cfg = self.config
        if cfg.shape_at_previous_pose and cfg.enable_smoothing and self._q_prev is not None:
            return self._q_prev
        return q_blend

    def _fit_translation(self, corr0: Correspondences, q_blend: np.ndarray) -> np.ndarray:
        """The IK prior q_b: the blend with its wrist translation refitted to the primary
        camera's correspondences (the blend itself if disabled, too few or the fit fails).

        The refit holds the hand's rotation and fingers fixed, and the depth it finds is the
        one at which that hand spans its matched blobs (a hand with straighter fingers must
        be farther to span the same pixels). It holds those of :meth:`_shape_source`: while
        tracking, the previous output's, since the nearest database images of a close match
        can share the image yet differ in shape, and their shape would then set a depth the
        image does not. The rotation and fingers of q_b stay the blend's."""
        cfg = self.config
        if not (cfg.init_translation and len(corr0) >= 3):
            return q_blend
        shape = q_blend.copy()
        shape[3:] = self._shape_source(q_blend)[3:]
        try:
            fitted = estimate_translation(
                self.kin, self.cameras, corr0, shape, cfg.min_depth_m,
                cfg.covariances.q_var[0:3], float(cfg.covariances.r_var_px2.mean()),
                cfg.outlier_px, cfg.reference_focal_px)
        except IKError:
            return q_blend
        out = q_blend.copy()
        out[0:3] = fitted[0:3]
        return out

    def _fit_frame(self, prior: PosePrior, observations: Sequence[CameraObservation],
                   corr0: Correspondences, tracked: Correspondences | None,
                   priors: _FramePriors) -> _FrameFit:
        """The frame's pose: IK on the primary camera or on all cameras, then once more
        without the outliers; without IK (or too few correspondences) the prior q_b."""
        cfg = self.config
        multi = len(self.cameras) > 1
        fit = _FrameFit(priors.q_b, corr0)
        if cfg.enable_ik and (len(corr0) >= cfg.min_constraints or multi):
            if not multi:
                self._solve_into(fit, corr0, priors.q_b, cfg.max_iterations, priors)
            else:
                self._solve_all_cameras(fit, prior, observations, corr0, tracked, priors)
            self._drop_outliers(fit, priors)
        elif multi:
            fit.corr = Correspondences.concat(
                [corr0, self._match_extras(prior, observations, fit.q)])
        return fit

    def _solve_all_cameras(self, fit: _FrameFit, prior: PosePrior,
                           observations: Sequence[CameraObservation], corr0: Correspondences,
                           tracked: Correspondences | None, priors: _FramePriors) -> None:
        """Several cameras: predict the other cameras' patches from the last pose while
        tracking, else from a short primary-camera solve; then solve on all cameras together
        (a patch seen by one camera only still counts), optionally re-matching the other
        cameras at the solved pose once."""
        cfg = self.config
        q_start = priors.q_b
        if tracked is not None:
            fit.corr = tracked
        else:
            if len(corr0) >= cfg.min_constraints:
                sol = self._solve(corr0, priors.q_b, cfg.refine_iterations, priors)
                q_start = fit.q = sol.q
                fit.iterations += sol.iterations
            fit.corr = Correspondences.concat(
                [corr0, self._match_extras(prior, observations, q_start)])
        if len(fit.corr) < cfg.min_constraints:
            return
        self._solve_into(fit, fit.corr, q_start, cfg.multi_camera_iterations, priors)
        if cfg.extra_rematch and len(fit.corr) > len(corr0):
            again = Correspondences.concat(
                [corr0, self._match_extras(prior, observations, fit.q)])
            if not again.same_as(fit.corr) and len(again) >= cfg.min_constraints:
                self._solve_into(fit, again, fit.q, cfg.refine_iterations, priors)

    def _drop_outliers(self, fit: _FrameFit, priors: _FramePriors) -> None:
        """Solve once more without the correspondences farther than ``outlier_px``, if
        enough remain."""
        cfg = self.config
        if cfg.outlier_px > 0 and fit.err is not None:
            scale = np.array([self._pixel_scale(c) for c in range(len(self.cameras))])
            bad = fit.err > cfg.outlier_px * scale[fit.corr.camera]
            if bad.any() and int((~bad).sum()) >= cfg.min_constraints:
                fit.rejected = int(bad.sum())
                self._solve_into(fit, fit.corr.select(~bad), fit.q, cfg.refine_iterations,
                                 priors)

    def _finish(self, fit: _FrameFit, stamp: float, t0: float, q_blend: np.ndarray,
                priors: _FramePriors, was_reset: bool, primary_blobs: Blobs) -> IKResult:
        """Remember the pose (rotation angle in [0, pi]) and build the tracker output (the
        errors of a fit that made no solve are measured here, and the share of the primary
        camera's blobs it explains)."""
        corr = fit.corr
        err = (fit.err if fit.err is not None
               else reprojection_errors(self.kin, self.cameras, corr, fit.q))
        q = fit.q.copy()
        q[3:6] = align_rotation_vector(q[3:6], np.zeros(3))      # angle in [0, pi]
        n_cam = len(self.cameras)
        per_cam = tuple(float(err[corr.camera == c].mean()) if np.any(corr.camera == c)
                        else math.nan for c in range(n_cam))
        self._q_prev = q.copy()
        self._stamp_prev = stamp
        return IKResult(
            True, stamp, q.copy(), q_blend, float(err.mean()) if len(err) else math.nan,
            per_cam, fit.iterations, 1e3 * (time.perf_counter() - t0), len(corr),
            corr.counts(n_cam), priors.q_prev is not None and fit.iterations > 0, was_reset,
            corr, fit.rejected, priors.q_b.copy(),
            explained_blob_share(corr, primary_blobs, self.cameras[0],
                                 self._min_blob_pixels(0)))
