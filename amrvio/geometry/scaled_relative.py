"""Relative pose from many 2D-2D tracks, metric scale from few 2D-3D points.

When the camera moves fast, most tracks of a frame are young and have no map point yet, and the
few that have one can be too few for PnP; but the tracks still fix the rotation and the
direction of travel (the essential matrix), and a handful of map points then fix the one
unknown left, the length of the step. With the previous camera's points ``Y = R P_prev`` and
the unit direction ``t``, a point's normalised observation ``(u, v)`` in the current camera
gives two equations linear in the length ``s``:

    s (u t_z - t_x) = Y_x - u Y_z,    s (v t_z - t_y) = Y_y - v Y_z

Each point's least-squares ``s`` votes (weighted median, weight the sum of squared
coefficients: a point near the epipole says little about ``s``), the points that reproject
within the threshold with that ``s`` are its support, and ``s`` is re-fitted on them.

Failure is data: ``ScaledRelativeResult.status`` says why (too few tracks, no essential matrix,
too little translation to tell it from a rotation, too few points agreeing on a length).
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import Enum

import cv2
import numpy as np
from numpy.typing import NDArray
from scipy.optimize import least_squares

from amrvio.errors import ShapeError
from amrvio.geometry.checks import F64
from amrvio.geometry.projection import normalized_to_bearings
from amrvio.geometry.two_view import essential_ransac, robust_rotation
from amrvio.types.lie import hat, so3_exp

B = NDArray[np.bool_]


class ScaledRelativeStatus(Enum):
    OK = "ok"
    TOO_FEW_TRACKS = "too_few_tracks"
    NO_ESSENTIAL = "no_essential"
    LOW_PARALLAX = "low_parallax"
    TOO_FEW_SCALE_POINTS = "too_few_scale_points"


@dataclass(frozen=True, slots=True)
class ScaledRelativeConfig:
    """``enabled``: the caller uses it; ``min_tracks``: essential-matrix inliers needed;
    ``min_points``: map points that must agree on the step length; ``thresh_px``: the essential
    matrix's RANSAC threshold and ``point_thresh_px`` the map points' reprojection threshold
    (pixels, with ``focal_px``); ``min_flow_px``: median rotation-compensated flow of the inliers
    below which the translation's direction is noise (the caller's rotation-only update applies)."""

    enabled: bool = True
    min_tracks: int = 50
    min_points: int = 8
    thresh_px: float = 1.0
    point_thresh_px: float = 2.0
    min_flow_px: float = 2.0
    seed: int = 0


@dataclass(frozen=True, slots=True)
class ScaledRelativeResult:
    """``T_cur_prev`` (4x4, metric in the points' units; identity unless OK), the essential
    matrix's track inliers (N,), the points that agree on the length (N,; only tracks with a
    point), the length ``scale`` of the step and the median rotation-compensated flow."""

    status: ScaledRelativeStatus
    T_cur_prev: F64
    track_inliers: B
    point_inliers: B
    scale: float
    flow_px: float

    @property
    def ok(self) -> bool:
        return self.status is ScaledRelativeStatus.OK


def _length_equations(Y: F64, t: F64, x: F64) -> tuple[F64, F64]:
    """Per point, coefficients a (M, 2) and right-hand sides b (M, 2) of a s = b."""
    a = np.column_stack([x[:, 0] * t[2] - t[0], x[:, 1] * t[2] - t[1]])
    b = np.column_stack([Y[:, 0] - x[:, 0] * Y[:, 2], Y[:, 1] - x[:, 1] * Y[:, 2]])
    return a, b


def _weighted_median(values: F64, weights: F64) -> float:
    order = np.argsort(values)
    c = np.cumsum(weights[order])
    return float(values[order][int(np.searchsorted(c, 0.5 * c[-1]))])


def _sampson(R: F64, t: F64, x1: F64, x2: F64) -> F64:
    """(N,) signed Sampson distances (normalised units) of the pairs to E = [t]x R."""
    E = hat(t / np.linalg.norm(t)) @ R
    h1 = np.column_stack([x1, np.ones(len(x1))])
    h2 = np.column_stack([x2, np.ones(len(x2))])
    Ex1 = h1 @ E.T
    Etx2 = h2 @ E
    num = np.sum(h2 * Ex1, axis=1)
    den = np.sqrt(Ex1[:, 0] ** 2 + Ex1[:, 1] ** 2 + Etx2[:, 0] ** 2 + Etx2[:, 1] ** 2)
    return np.asarray(num / np.maximum(den, 1e-15), dtype=np.float64)


def _refine(R: F64, t: F64, x1: F64, x2: F64, P: F64, xp: F64, huber: float) -> tuple[F64, F64]:
    """Joint Huber least squares of the motion (R, metric t): the tracks' Sampson distances
    (which fix R and t's direction) and the agreeing points' reprojection errors (which also
    fix its length), all in normalised units, as is the Huber width ``huber``."""

    def resid(p: F64) -> F64:
        Rp = so3_exp(p[:3]) @ R
        tp = p[3:]
        Q = P @ Rp.T + tp
        rp = (Q[:, :2] / Q[:, 2:3] - xp).ravel()
        return np.concatenate([_sampson(Rp, tp, x1, x2), rp])

    sol = least_squares(resid, np.concatenate([np.zeros(3), t]), loss="huber", f_scale=huber,
                        method="trf", max_nfev=20, x_scale="jac")
    return so3_exp(sol.x[:3]) @ R, np.asarray(sol.x[3:], dtype=np.float64)


def scaled_relative_pose(x_prev: F64, x_cur: F64, has_point: B, points_prev: F64,
                         focal_px: float, config: ScaledRelativeConfig | None = None
                         ) -> ScaledRelativeResult:
    """``x_prev``, ``x_cur``: (N, 2) normalised coordinates of N tracks in the previous and the
    current camera; ``has_point`` (N,): tracks with a map point, whose (N, 3) ``points_prev`` are
    in the previous camera's frame (other rows ignored); ``focal_px`` converts pixel thresholds."""
    cfg = config or ScaledRelativeConfig()
    n = len(x_prev)
    if x_prev.shape != (n, 2) or x_cur.shape != (n, 2) or has_point.shape != (n,) or \
            points_prev.shape != (n, 3):
        raise ShapeError("scaled_relative_pose: x_prev, x_cur (N, 2), has_point (N,), "
                         "points_prev (N, 3)")
    none = np.zeros(n, dtype=bool)

    def fail(status: ScaledRelativeStatus, inl: B = none, flow: float = float("nan")
             ) -> ScaledRelativeResult:
        return ScaledRelativeResult(status, np.eye(4), inl, none, float("nan"), flow)

    if n < max(cfg.min_tracks, 8):
        return fail(ScaledRelativeStatus.TOO_FEW_TRACKS)
    x1 = np.ascontiguousarray(x_prev, dtype=np.float64)
    x2 = np.ascontiguousarray(x_cur, dtype=np.float64)
    # a rotation that explains the flow: t's direction would be noise
    _, resid_deg = robust_rotation(normalized_to_bearings(x1), normalized_to_bearings(x2))
    flow = float(np.median(np.radians(resid_deg))) * focal_px
    if flow < cfg.min_flow_px:
        return fail(ScaledRelativeStatus.LOW_PARALLAX, none, flow)
    cv2.setRNGSeed(cfg.seed)
    ess = essential_ransac(x1, x2, cfg.thresh_px, focal_px)
    if ess is None:
        return fail(ScaledRelativeStatus.NO_ESSENTIAL, none, flow)
    E, inl = ess
    _, R, t, pose_mask = cv2.recoverPose(E, x1, x2, np.eye(3),
                                         mask=inl.astype(np.uint8).reshape(-1, 1))
    inl &= pose_mask.ravel() > 0
    if int(inl.sum()) < cfg.min_tracks:
        return fail(ScaledRelativeStatus.TOO_FEW_TRACKS, inl, flow)
    R = np.asarray(R, np.float64)
    t = np.asarray(t, np.float64).ravel()
    t /= np.linalg.norm(t)
    cand = inl & has_point
    Y = points_prev[cand] @ R.T
    front = Y[:, 2] > 0
    idx = np.flatnonzero(cand)[front]
    Y = Y[front]
    if len(idx) < cfg.min_points:
        return fail(ScaledRelativeStatus.TOO_FEW_SCALE_POINTS, inl, flow)
    a, b = _length_equations(Y, t, x2[idx])
    w = (a * a).sum(axis=1)
    usable = w > 1e-12
    if int(usable.sum()) < cfg.min_points:
        return fail(ScaledRelativeStatus.TOO_FEW_SCALE_POINTS, inl, flow)
    s = _weighted_median((a * b).sum(axis=1)[usable] / w[usable], w[usable])
    agree = np.zeros(len(idx), dtype=bool)
    for _ in range(2):
        P = Y + s * t
        ok_z = P[:, 2] > 0
        err = np.full(len(idx), np.inf)
        err[ok_z] = np.linalg.norm(P[ok_z, :2] / P[ok_z, 2:3] - x2[idx][ok_z], axis=1)
        agree = err * focal_px <= cfg.point_thresh_px
        if int(agree.sum()) < cfg.min_points:
            return fail(ScaledRelativeStatus.TOO_FEW_SCALE_POINTS, inl, flow)
        s = float((a[agree] * b[agree]).sum() / (a[agree] ** 2).sum())
    if not s > 0:
        return fail(ScaledRelativeStatus.TOO_FEW_SCALE_POINTS, inl, flow)
    R, t_m = _refine(R, s * t, x1[inl], x2[inl], points_prev[idx[agree]], x2[idx[agree]],
                     cfg.thresh_px / focal_px)
    T = np.eye(4)
    T[:3, :3] = R
    T[:3, 3] = t_m
    pts = none.copy()
    pts[idx[agree]] = True
    return ScaledRelativeResult(ScaledRelativeStatus.OK, T, inl, pts, float(np.linalg.norm(t_m)),
                                flow)


__all__ = ["ScaledRelativeConfig", "ScaledRelativeResult", "ScaledRelativeStatus",
           "scaled_relative_pose"]
