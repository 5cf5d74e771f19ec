"""Two-view initialisation: essential matrix (USAC/RANSAC), recoverPose, triangulation.

Failure is data: ``TwoViewResult.status`` says why (too few points or inliers, low parallax,
pure rotation) so that the caller can retry on a later frame.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import Enum

import cv2
import numpy as np

from amrvio.errors import ShapeError
from amrvio.geometry.checks import F64, check_matrix, check_points
from amrvio.geometry.projection import normalized_to_bearings, pixels_to_normalized
from amrvio.geometry.triangulation import triangulate
from amrvio.types.lie import se3_matrix


class TwoViewStatus(Enum):
    """Outcome of a two-view initialisation attempt."""

    OK = "ok"
    TOO_FEW_POINTS = "too_few_points"
    TOO_FEW_INLIERS = "too_few_inliers"
    LOW_PARALLAX = "low_parallax"
    PURE_ROTATION = "pure_rotation"
    TOO_FEW_POINTS_TRIANGULATED = "too_few_points_triangulated"


@dataclass(frozen=True, slots=True)
class TwoViewResult:
    """Relative pose of view 2 w.r.t. view 1 and the triangulated points.

    ``T_c2_c1``: 4x4, translation of unit norm (scale is unobservable). ``inliers``: (N,) bool
    of essential-matrix inliers. ``points_c1``: (N, 3) points in camera-1 frame (valid where
    ``point_valid``). ``median_parallax_deg``: rotation-compensated ray angle of the inliers.
    """

    status: TwoViewStatus
    T_c2_c1: F64
    inliers: np.ndarray
    points_c1: F64
    point_valid: np.ndarray
    median_parallax_deg: float
    median_flow_px: float

    @property
    def ok(self) -> bool:
        return self.status is TwoViewStatus.OK


@dataclass(frozen=True, slots=True)
class TwoViewConfig:
    """Gates of the two-view initialiser (angles in degrees, distances in pixels)."""

    min_points: int = 50
    min_inliers: int = 40
    min_flow_px: float = 8.0
    min_parallax_deg: float = 1.0
    min_point_parallax_deg: float = 0.5
    ransac_thresh_px: float = 1.0
    max_reproj_px: float = 2.0
    min_triangulated: int = 40
    seed: int = 0


def _rotation_parallax_deg(b1: F64, b2: F64, R_2_1: F64) -> F64:
    """(N,) angle between b2 and the rotated b1: parallax left after removing rotation."""
    c = np.sum(b2 * (b1 @ R_2_1.T), axis=1)
    return np.asarray(np.degrees(np.arccos(np.clip(c, -1.0, 1.0))), dtype=np.float64)


def best_rotation(b1: F64, b2: F64) -> F64:
    """Rotation R minimising sum |b2 - R b1|^2 (Kabsch/Wahba, closed form via SVD)."""
    H = b1.T @ b2
    U, _, Vt = np.linalg.svd(H)
    d = np.sign(np.linalg.det(Vt.T @ U.T))
    D = np.diag([1.0, 1.0, d])
    R: F64 = Vt.T @ D @ U.T
    return R


def two_view_init(
    pts1_px: F64, pts2_px: F64, K: F64, config: TwoViewConfig | None = None
) -> TwoViewResult:
    """Relative pose and structure from (N, 2) pixel matches of two views with pinhole ``K``."""
    cfg = config or TwoViewConfig()
    p1 = check_points("pts1_px", pts1_px, 2)
    p2 = check_points("pts2_px", pts2_px, 2)
    Km = check_matrix("K", K, (3, 3))
    if len(p1) != len(p2):
        raise ShapeError(f"pts1_px and pts2_px differ in length: {len(p1)} vs {len(p2)}")
    n = len(p1)
    empty = np.zeros(n, dtype=bool)

    def fail(status: TwoViewStatus, par: float = 0.0, flow: float = 0.0,
             inl: np.ndarray | None = None) -> TwoViewResult:
        return TwoViewResult(status, np.eye(4), empty if inl is None else inl,
                             np.zeros((n, 3)), empty, par, flow)

    if n < cfg.min_points:
        return fail(TwoViewStatus.TOO_FEW_POINTS)
    flow = float(np.median(np.linalg.norm(p2 - p1, axis=1)))
    x1 = pixels_to_normalized(p1, Km)
    x2 = pixels_to_normalized(p2, Km)
    b1 = normalized_to_bearings(x1)
    b2 = normalized_to_bearings(x2)
    # pure-rotation test: best rotation alone explains the rays (Wahba problem)
    R_rot = best_rotation(b1, b2)
    rot_par = float(np.median(_rotation_parallax_deg(b1, b2, R_rot)))
    if rot_par < cfg.min_parallax_deg:
        status = (TwoViewStatus.LOW_PARALLAX if flow < cfg.min_flow_px
                  else TwoViewStatus.PURE_ROTATION)
        return fail(status, rot_par, flow)
    focal = 0.5 * (Km[0, 0] + Km[1, 1])
    cv2.setRNGSeed(cfg.seed)
    E, mask = cv2.findEssentialMat(
        x1, x2, np.eye(3), method=cv2.RANSAC, prob=0.999,
        threshold=cfg.ransac_thresh_px / focal,
    )
    if E is None or E.shape != (3, 3):
        return fail(TwoViewStatus.TOO_FEW_INLIERS, rot_par, flow)
    inl = mask.ravel().astype(bool)
    if int(inl.sum()) < cfg.min_inliers:
        return fail(TwoViewStatus.TOO_FEW_INLIERS, rot_par, flow, inl)
    _, R, t, mask2 = cv2.recoverPose(E, x1[inl], x2[inl], np.eye(3))
    t = t.ravel() / (np.linalg.norm(t) + 1e-300)
    par_in = float(np.median(_rotation_parallax_deg(b1[inl], b2[inl], R)))
    if par_in < cfg.min_parallax_deg:
        return fail(TwoViewStatus.LOW_PARALLAX, par_in, flow, inl)
    T21 = se3_matrix(R, t)
    tri = triangulate(np.eye(4), T21, x1, x2, min_parallax_deg=cfg.min_point_parallax_deg,
                      max_reproj_px=cfg.max_reproj_px, focal_px=focal)
    valid = tri.valid & inl
    if int(valid.sum()) < cfg.min_triangulated:
        return TwoViewResult(TwoViewStatus.TOO_FEW_POINTS_TRIANGULATED, T21, inl,
                             tri.points_world, valid, par_in, flow)
    return TwoViewResult(TwoViewStatus.OK, T21, inl, tri.points_world, valid, par_in, flow)


__all__ = ["TwoViewConfig", "TwoViewResult", "TwoViewStatus", "best_rotation", "two_view_init"]
