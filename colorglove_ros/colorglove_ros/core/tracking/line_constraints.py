"""DigitEyes line features as extra constraints of the glove IK (issue 17, item 6).

Each camera's link axes and fingertips (:mod:`edge_fit`: predicted at a pose, measured by the
local edge searches of :mod:`edge_features`) are measured once per frame near the pose the
IK starts from, on the camera's edge image (the glove tracker uses its glove mask, brighter
than the background). :func:`line_constraints` then gives the paper's residuals (signed
distances of the predicted axis end points from the measured lines, tip differences) and
their Jacobians at any pose, in the solver's sign convention (target minus prediction) with
constant weights ``1 / std_px^2``, for :func:`solver.solve_ik` to add to the patch
constraints.
"""
from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from colorglove_ros.core.camera import PinholeCamera
from colorglove_ros.core.tracking.edge_features import to_grey
from colorglove_ros.core.tracking.edge_fit import (
    EdgeMeasurement,
    EdgeTrackerConfig,
    feature_points,
    measure_features,
    predict_features,
    stack_residuals,
)
from colorglove_ros.core.tracking.kinematics import FastKinematics

__all__ = ['ExtraConstraints', 'LINE_FEATURE_CONFIG', 'glove_edge_image', 'line_constraints']

# the glove mask is brighter than the background; no Huber weights (the solver's weights
# are constant over its iterations); the link and tip features only, every camera weighted
# alike, no palm occluder
LINE_FEATURE_CONFIG = EdgeTrackerConfig(polarity=1, huber_px=0.0, palm_sides=(),
                                        camera_weights=(), palm_occlusion_px=0.0)


def glove_edge_image(labels: np.ndarray | None) -> np.ndarray | None:
    """The edge image of a glove label image (0 background, 1.. glove colours): the glove
    mask as float32 grey levels 255 on 0 (None for None)."""
    if labels is None:
        return None
    return np.where(np.asarray(labels) > 0, np.float32(255.0), np.float32(0.0))


@dataclass(frozen=True)
class ExtraConstraints:
    """Residual rows beyond the patch constraints: ``residuals(q, jacobian)`` gives (M,)
    target-minus-prediction residuals and their (M, 26) Jacobian of the prediction (None
    without ``jacobian``); ``weights`` (M,) are their constant inverse variances."""

    residuals: Callable[[np.ndarray, bool], tuple[np.ndarray, np.ndarray | None]]
    weights: np.ndarray

    def __len__(self) -> int:
        return len(self.weights)


def line_constraints(kin: FastKinematics, cameras: Sequence[PinholeCamera],
                     images: Sequence[np.ndarray | None], q: np.ndarray, std_px: float,
                     config: EdgeTrackerConfig = LINE_FEATURE_CONFIG
                     ) -> ExtraConstraints | None:
    """Measure every camera's line features near pose ``q`` (``images[c]`` camera c's edge
    image, None if it has none) and return them as :class:`ExtraConstraints` with standard
    deviation ``std_px``, or None when nothing was found."""
    points = feature_points(kin.model, config.tracked_links, config.use_tips)
    world = kin.points(q, points.point_link, points.point_local, True)
    measured: list[EdgeMeasurement | None] = []
    for cam, image in zip(cameras, list(images) + [None] * (len(cameras) - len(images)),
                          strict=True):
        if image is None:
            measured.append(None)
            continue
        pred = predict_features(kin, points, cam, q, config, world)
        measured.append(measure_features(to_grey(image), pred, config, points.tip_row))
    rows = sum(int(2 * m.link_found.sum() + 2 * m.tip_found.sum())
               for m in measured if m is not None)
    if rows == 0:
        return None

    def residuals(qq: np.ndarray, jacobian: bool) -> tuple[np.ndarray, np.ndarray | None]:
        at = kin.points(qq, points.point_link, points.point_local, jacobian)
        r, J, _ = stack_residuals(points, cameras, measured, at, config, jacobian)
        return -r, J

    return ExtraConstraints(residuals, np.full(rows, 1.0 / std_px**2))
