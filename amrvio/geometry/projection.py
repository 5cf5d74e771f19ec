"""The pinhole projection of amrvio, its Jacobian, and pixel <-> normalised coordinates.

``uv = pi(K, T_cam_world p_world)`` with ``pi(P) = (fx X / Z + cx, fy Y / Z + cy)``.

Near-zero depth, the one rule used everywhere: the division uses ``max(Z, MIN_DEPTH)``. A point
at or behind the camera therefore projects to a finite pixel far outside the image (never to a
plausible measurement, so a robust loss gives it no weight) instead of to a mirrored image point.
Every function also returns or accepts the true depth ``Z``: a caller that needs visible points
keeps those with ``Z > MIN_DEPTH``.

Pose Jacobians use the SE3 tangent of :mod:`amrvio.types.lie`, ``xi = [rho, phi]`` (translation
first), as a LEFT perturbation of ``T_cam_world``: ``T <- SE3.exp(xi) @ T``, for which
``d(P_cam)/d(xi) = [I, -[P_cam]x]`` (Barfoot 2017, eq. 7.189 with the left update).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from amrvio.errors import ShapeError
from amrvio.types.lie import transform_points

F64 = NDArray[np.float64]

MIN_DEPTH = 1e-6
"""Depths below this (including negative ones) are clamped to it in the perspective division."""


def _poses(T_cam_world: F64, n: int) -> F64:
    T = np.asarray(T_cam_world, dtype=np.float64)
    if T.shape != (4, 4) and T.shape != (n, 4, 4):
        raise ShapeError(f"T_cam_world must be (4, 4) or ({n}, 4, 4), got {T.shape}")
    return T


def _points(p_world: F64) -> F64:
    p = np.asarray(p_world, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != 3:
        raise ShapeError(f"points must have shape (N, 3), got {p.shape}")
    return p


def project(K: F64, T_cam_world: F64, p_world: F64) -> tuple[F64, F64]:
    """Project (N, 3) world points with one (4, 4) pose or (N, 4, 4) poses, one per point.

    Returns ((N, 2) pixels, (N,) depths Z in the camera; see MIN_DEPTH for Z <= MIN_DEPTH).
    """
    p = _points(p_world)
    pc = transform_points(_poses(T_cam_world, len(p)), p)
    iz = 1.0 / np.maximum(pc[:, 2], MIN_DEPTH)
    uv = np.column_stack([K[0, 0] * pc[:, 0] * iz + K[0, 2], K[1, 1] * pc[:, 1] * iz + K[1, 2]])
    return uv, pc[:, 2]


def project_jacobian(K: F64, T_cam_world: F64, p_world: F64) -> tuple[F64, F64]:
    """Jacobians of :func:`project` at (N, 3) world points, pose (4, 4) or (N, 4, 4).

    Returns ``(J_pose, J_point)``: (N, 2, 6) d(uv)/d(xi), xi = [rho, phi] the left SE3
    perturbation of ``T_cam_world``, and (N, 2, 3) d(uv)/d(p_world).
    """
    p = _points(p_world)
    T = _poses(T_cam_world, len(p))
    pc = transform_points(T, p)
    n = len(p)
    fx, fy = K[0, 0], K[1, 1]
    iz = 1.0 / np.maximum(pc[:, 2], MIN_DEPTH)
    # d(uv)/d(P_cam)
    Jp = np.zeros((n, 2, 3))
    Jp[:, 0, 0] = fx * iz
    Jp[:, 0, 2] = -fx * pc[:, 0] * iz * iz
    Jp[:, 1, 1] = fy * iz
    Jp[:, 1, 2] = -fy * pc[:, 1] * iz * iz
    # d(P_cam)/d(phi) = -[P_cam]x
    X, Y, Z = pc[:, 0], pc[:, 1], pc[:, 2]
    Jr = np.zeros((n, 3, 3))
    Jr[:, 0, 1], Jr[:, 0, 2] = Z, -Y
    Jr[:, 1, 0], Jr[:, 1, 2] = -Z, X
    Jr[:, 2, 0], Jr[:, 2, 1] = Y, -X
    J_pose = np.concatenate([Jp, Jp @ Jr], axis=2)
    J_point = Jp @ T[..., :3, :3]
    return J_pose, J_point


def pixels_to_normalized(pts_px: F64, K: F64) -> F64:
    """(N, 2) pixel coordinates -> (N, 2) normalized image coordinates (pinhole K)."""
    fx, fy, cx, cy = K[0, 0], K[1, 1], K[0, 2], K[1, 2]
    return np.column_stack([(pts_px[:, 0] - cx) / fx, (pts_px[:, 1] - cy) / fy])


def normalized_to_pixels(xn: F64, K: F64) -> F64:
    """(N, 2) normalized image coordinates -> (N, 2) pixel coordinates (pinhole K)."""
    return np.column_stack([K[0, 0] * xn[:, 0] + K[0, 2], K[1, 1] * xn[:, 1] + K[1, 2]])


def normalized_to_bearings(xn: F64) -> F64:
    """(N, 2) normalized coordinates -> (N, 3) unit bearing vectors."""
    b = np.column_stack([xn, np.ones(len(xn))])
    return b / np.linalg.norm(b, axis=1, keepdims=True)


__all__ = [
    "MIN_DEPTH",
    "normalized_to_bearings",
    "normalized_to_pixels",
    "pixels_to_normalized",
    "project",
    "project_jacobian",
]
