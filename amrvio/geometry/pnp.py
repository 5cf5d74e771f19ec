"""Camera pose from 3D-2D matches: PnP RANSAC, then robust (Huber) motion-only refinement."""

from __future__ import annotations

from dataclasses import dataclass
from enum import Enum

import cv2
import numpy as np

from amrvio.errors import ShapeError
from amrvio.geometry.checks import F64, check_matrix, check_points
from amrvio.geometry.projection import MIN_DEPTH, project, project_jacobian
from amrvio.types.lie import SE3, se3_matrix


class PnPStatus(Enum):
    """Outcome of a PnP solve."""

    OK = "ok"
    TOO_FEW_POINTS = "too_few_points"
    TOO_FEW_INLIERS = "too_few_inliers"
    FAILED = "failed"


@dataclass(frozen=True, slots=True)
class PnPResult:
    """``T_cam_world`` (4x4) and the (N,) inlier mask; identity guess when not OK."""

    status: PnPStatus
    T_cam_world: F64
    inliers: np.ndarray

    @property
    def ok(self) -> bool:
        return self.status is PnPStatus.OK


def refine_pose_huber(
    T_cam_world: F64,
    points_world: F64,
    pts_px: F64,
    K: F64,
    *,
    huber_px: float = 2.0,
    iterations: int = 10,
) -> F64:
    """Motion-only Gauss-Newton on reprojection error with Huber weights (IRLS).

    Left perturbation T <- exp(xi) T, xi = [rho, phi] (Jacobian: geometry.projection).
    """
    T = check_matrix("T_cam_world", T_cam_world, (4, 4)).copy()
    P = check_points("points_world", points_world, 3)
    u = check_points("pts_px", pts_px, 2)
    Km = check_matrix("K", K, (3, 3))
    n = len(P)
    for _ in range(iterations):
        proj = project(Km, T, P)[0]
        r = (proj - u).ravel()
        J = project_jacobian(Km, T, P)[0].reshape(2 * n, 6)
        en = np.linalg.norm((proj - u), axis=1)
        w = np.where(en <= huber_px, 1.0, huber_px / np.maximum(en, 1e-12))
        w2 = np.repeat(w, 2)
        H = J.T @ (J * w2[:, None])
        g = J.T @ (w2 * r)
        try:
            dx = -np.linalg.solve(H + 1e-9 * np.eye(6), g)
        except np.linalg.LinAlgError:
            break
        T = SE3.exp(dx).matrix() @ T
        if np.linalg.norm(dx) < 1e-10:
            break
    return T


def solve_pnp(
    points_world: F64,
    pts_px: F64,
    K: F64,
    *,
    T_guess: F64 | None = None,
    ransac_thresh_px: float = 2.0,
    min_inliers: int = 12,
    huber_px: float = 2.0,
    seed: int = 0,
) -> PnPResult:
    """PnP RANSAC (P3P/EPnP minimal solver, OpenCV) then Huber refinement on the inliers."""
    P = check_points("points_world", points_world, 3)
    u = check_points("pts_px", pts_px, 2)
    Km = check_matrix("K", K, (3, 3))
    if len(P) != len(u):
        raise ShapeError(f"points_world and pts_px differ in length: {len(P)} vs {len(u)}")
    n = len(P)
    none = np.zeros(n, dtype=bool)
    if n < max(6, min_inliers):
        return PnPResult(PnPStatus.TOO_FEW_POINTS, np.eye(4), none)
    cv2.setRNGSeed(seed)
    if T_guess is not None:
        rv0, _ = cv2.Rodrigues(T_guess[:3, :3])
        tv0 = T_guess[:3, 3].reshape(3, 1).copy()
        ok, rvec, tvec, idx = cv2.solvePnPRansac(
            P, u, Km, None, rvec=rv0, tvec=tv0, useExtrinsicGuess=True,
            iterationsCount=100, reprojectionError=ransac_thresh_px, confidence=0.999,
            flags=cv2.SOLVEPNP_ITERATIVE)
    else:
        ok, rvec, tvec, idx = cv2.solvePnPRansac(
            P, u, Km, None, iterationsCount=200, reprojectionError=ransac_thresh_px,
            confidence=0.999, flags=cv2.SOLVEPNP_EPNP)
    if not ok or idx is None:
        return PnPResult(PnPStatus.FAILED, np.eye(4), none)
    R, _ = cv2.Rodrigues(rvec)
    T = se3_matrix(R, tvec.ravel())
    inl = np.zeros(n, dtype=bool)
    inl[idx.ravel()] = True
    if int(inl.sum()) < min_inliers:
        return PnPResult(PnPStatus.TOO_FEW_INLIERS, T, inl)
    T = refine_pose_huber(T, P[inl], u[inl], Km, huber_px=huber_px)
    proj, z = project(Km, T, P)
    err = np.linalg.norm(proj - u, axis=1)
    inl = (err < ransac_thresh_px * 1.5) & (z > MIN_DEPTH)
    if int(inl.sum()) < min_inliers:
        return PnPResult(PnPStatus.TOO_FEW_INLIERS, T, inl)
    return PnPResult(PnPStatus.OK, T, inl)


__all__ = ["PnPResult", "PnPStatus", "refine_pose_huber", "solve_pnp"]
