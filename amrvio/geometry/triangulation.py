"""Two-view point triangulation (linear DLT) with cheirality, parallax and reprojection checks."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from amrvio.errors import ShapeError
from amrvio.geometry.checks import F64, check_matrix, check_points
from amrvio.geometry.projection import MIN_DEPTH, project


@dataclass(frozen=True, slots=True)
class TriangulationResult:
    """Triangulated points and why each one is (in)valid.

    ``points_world``: (N, 3); ``valid``: (N,) bool = in front of both cameras AND parallax angle
    above the threshold AND reprojection error below the threshold. The component masks say why.
    """

    points_world: F64
    valid: np.ndarray
    in_front: np.ndarray
    parallax_deg: F64
    reproj_err: F64  # (N,) max over both views, in normalized units times ``focal_px`` (pixels)


def triangulate(
    T_c1_world: F64,
    T_c2_world: F64,
    xn1: F64,
    xn2: F64,
    *,
    min_parallax_deg: float = 0.0,
    max_reproj_px: float = np.inf,
    focal_px: float = 1.0,
) -> TriangulationResult:
    """Triangulate matches given in normalized image coordinates (N, 2) of two posed cameras.

    Linear DLT per point (Hartley & Zisserman 12.2), solved in closed form as the smallest
    right singular vector of the 4x4 system; exact for noise-free data.
    """
    T1 = check_matrix("T_c1_world", T_c1_world, (4, 4))
    T2 = check_matrix("T_c2_world", T_c2_world, (4, 4))
    x1 = check_points("xn1", xn1, 2)
    x2 = check_points("xn2", xn2, 2)
    if len(x1) != len(x2):
        raise ShapeError(f"xn1 and xn2 differ in length: {len(x1)} vs {len(x2)}")
    n = len(x1)
    if n == 0:
        e = np.zeros((0,), dtype=bool)
        return TriangulationResult(np.zeros((0, 3)), e, e, np.zeros(0), np.zeros(0))
    P1, P2 = T1[:3, :], T2[:3, :]
    A = np.empty((n, 4, 4))
    A[:, 0] = x1[:, 0:1] * P1[2] - P1[0]
    A[:, 1] = x1[:, 1:2] * P1[2] - P1[1]
    A[:, 2] = x2[:, 0:1] * P2[2] - P2[0]
    A[:, 3] = x2[:, 1:2] * P2[2] - P2[1]
    A /= np.linalg.norm(A, axis=2, keepdims=True) + 1e-300
    _, _, vt = np.linalg.svd(A)
    Xh = vt[:, -1, :]
    w = Xh[:, 3]
    finite = np.abs(w) > 1e-12
    X = np.where(finite[:, None], Xh[:, :3] / np.where(finite, w, 1.0)[:, None], 0.0)
    # reprojection in normalized coordinates (K = I)
    xp1, z1 = project(np.eye(3), T1, X)
    xp2, z2 = project(np.eye(3), T2, X)
    in_front = finite & (z1 > MIN_DEPTH) & (z2 > MIN_DEPTH)
    # parallax angle between the two viewing rays at the point
    c1 = -T1[:3, :3].T @ T1[:3, 3]
    c2 = -T2[:3, :3].T @ T2[:3, 3]
    r1 = X - c1
    r2 = X - c2
    cosang = np.sum(r1 * r2, axis=1) / (
        np.linalg.norm(r1, axis=1) * np.linalg.norm(r2, axis=1) + 1e-300
    )
    parallax = np.degrees(np.arccos(np.clip(cosang, -1.0, 1.0)))
    e1 = np.linalg.norm(xp1 - x1, axis=1)
    e2 = np.linalg.norm(xp2 - x2, axis=1)
    err = np.maximum(e1, e2) * focal_px
    valid = in_front & (parallax >= min_parallax_deg) & (err <= max_reproj_px)
    return TriangulationResult(X, valid, in_front, parallax, err)


def camera_center(T_cam_world: F64) -> F64:
    """Camera centre in the world frame, (3,)."""
    T = check_matrix("T_cam_world", T_cam_world, (4, 4))
    c: F64 = -T[:3, :3].T @ T[:3, 3]
    return c


__all__ = ["TriangulationResult", "camera_center", "triangulate"]
