"""Projecting the constrained points into the cameras (pixels, pixel Jacobians, reprojection
errors) and the linear fit of the wrist translation to the matched blobs."""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from colorglove_ros.core.camera import PinholeCamera
from colorglove_ros.core.hand.model import NUM_DOFS
from colorglove_ros.core.tracking.kinematics import FastKinematics
from colorglove_ros.core.tracking.types import Correspondences, IKError

__all__ = [
    'PerPointCameras', 'per_point_cameras', 'pixel_scale', 'constraint_points',
    'project_correspondences', 'reprojection_errors', 'estimate_translation',
]


def pixel_scale(camera: PinholeCamera, reference_focal_px: float | None) -> float:
    """How many of ``camera``'s pixels span what one pixel spans for a camera of focal
    length ``reference_focal_px``: sqrt(fx fy) / reference_focal_px (1 for None). A pixel
    distance set for the reference camera is this many times longer in ``camera``'s image
    (an area the square), so a frame and its upscale with scaled intrinsics are treated
    alike."""
    if reference_focal_px is None:
        return 1.0
    return float(np.sqrt(camera.fx * camera.fy)) / float(reference_focal_px)


@dataclass(frozen=True)
class PerPointCameras:
    """Camera parameters repeated per correspondence, so all cameras project in one pass."""

    R: np.ndarray       # (K, 3, 3)
    t: np.ndarray       # (K, 3)
    f: np.ndarray       # (K, 2)
    c: np.ndarray       # (K, 2)

    def axis_scale(self, reference_focal_px: float | None) -> np.ndarray:
        """(K, 2) each point's camera's pixels per reference pixel along x and y (focal
        length over ``reference_focal_px``; ones for None)."""
        if reference_focal_px is None:
            return np.ones_like(self.f)
        return self.f / float(reference_focal_px)


def per_point_cameras(cameras: Sequence[PinholeCamera], corr: Correspondences) -> PerPointCameras:
    if len(corr) and (corr.camera.min() < 0 or corr.camera.max() >= len(cameras)):
        raise IKError(f'correspondence camera index outside [0, {len(cameras)})')
    Rs = np.stack([c.rotation for c in cameras]).astype(float, copy=False)
    ts = np.stack([c.translation for c in cameras]).astype(float, copy=False)
    fs = np.array([[c.fx, c.fy] for c in cameras], dtype=float)
    cs = np.array([[c.cx, c.cy] for c in cameras], dtype=float)
    k = corr.camera
    return PerPointCameras(Rs[k], ts[k], fs[k], cs[k])


def constraint_points(kin: FastKinematics, corr: Correspondences, q: np.ndarray,
                      jacobian: bool = False) -> tuple[np.ndarray, np.ndarray | None]:
    """Primary-frame constrained points (K, 3) at pose ``q`` (each the weighted mean of its
    link-fixed points) and optionally d/dq (K, 3, 26), the same weighted mean of the point
    Jacobians."""
    link, local, mix = corr.point_mix
    p, Jp = kin.points(q, link, local, jacobian)
    if mix is None:
        return p, Jp
    if Jp is not None:
        Jp = (mix @ Jp.reshape(len(p), -1)).reshape(len(mix), 3, NUM_DOFS)
    return mix @ p, Jp


def project_correspondences(kin: FastKinematics, cameras: Sequence[PinholeCamera],
                            corr: Correspondences, q: np.ndarray, jacobian: bool = False,
                            per_point: PerPointCameras | None = None
                            ) -> tuple[np.ndarray, np.ndarray | None, np.ndarray]:
    """Predicted pixels f(q) (K, 2), optionally df/dq (2K, 26) (rows x0, y0, x1, ...) and
    the depth of every point in its camera (K,). Pinhole projection without distortion
    (targets are undistorted); each camera's rotation is chained into the Jacobian."""
    pp = per_point if per_point is not None else per_point_cameras(cameras, corr)
    link, local, weight = corr.point_slots
    return kin.projected_points(q, link, local, weight, pp.R, pp.t, pp.f, pp.c, jacobian)


def reprojection_errors(kin: FastKinematics, cameras: Sequence[PinholeCamera],
                        corr: Correspondences, q: np.ndarray) -> np.ndarray:
    """Euclidean pixel distance between each constraint's projection and its target."""
    if len(corr) == 0:
        return np.zeros(0)
    pix, _, _ = project_correspondences(kin, cameras, corr, q)
    return np.linalg.norm(pix - corr.target_px, axis=1)


def estimate_translation(kin: FastKinematics, cameras: Sequence[PinholeCamera],
                         corr: Correspondences, q: np.ndarray,
                         min_depth_m: float = 0.05, prior_var: np.ndarray | None = None,
                         r_var_px2: float = 9.0, outlier_px: float = 0.0,
                         reference_focal_px: float | None = None) -> np.ndarray:
    """Keep rotation and fingers of ``q`` and solve the wrist translation that best
    projects the constraint points onto their targets: linear least squares on the
    cross-multiplied projection equations of all cameras, each row weighted as a pixel
    residual of variance ``r_var_px2``, optionally regularised toward ``q[0:3]`` with
    per-axis variances ``prior_var`` (m^2), and refitted once without the constraints
    farther than ``outlier_px`` (0 = no trimming). ``r_var_px2`` and ``outlier_px`` are
    pixels of a camera of focal length ``reference_focal_px`` (:func:`pixel_scale`; None:
    each camera's own pixels). Returns the new pose; raises
    :class:`IKError` if the points are too few or the solution is behind a camera."""
    if len(corr) < 2:
        raise IKError('translation needs at least 2 correspondences')
    p, _ = constraint_points(kin, corr, q)
    pp = per_point_cameras(cameras, corr)
    # per correspondence and pixel axis i: (R_i - a_i R_2) (p + dt) + t_i - a_i t_2 = 0 with
    # a the target's normalised image coordinates; a row's residual in reference pixels is
    # (f / scale) / z times its value (kin.kernels.translation_fit)
    reg = np.zeros((3, 3)) if prior_var is None else np.diag(1.0 / np.asarray(prior_var, float))
    dt, outcome = kin.kernels.translation_fit(
        np.ascontiguousarray(p), pp.R, pp.t, pp.f, pp.c,
        np.ascontiguousarray(corr.target_px, dtype=float),
        np.ascontiguousarray(pp.axis_scale(reference_focal_px)), reg, float(min_depth_m),
        float(r_var_px2), float(outlier_px))
    if outcome == kin.kernels.SINGULAR:
        raise IKError('translation is not determined by the correspondences')
    if outcome == kin.kernels.BEHIND:
        raise IKError('translation estimate puts the hand behind a camera')
    out = np.array(q, dtype=float)
    out[0:3] = q[0:3] + dt
    return kin.clamp(out)
