"""Small private helpers shared by the geometry modules (shape checks, pinhole maths)."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from amrvio.errors import ShapeError
from amrvio.types.lie import SE3, hat, so3_exp

F64 = NDArray[np.float64]


def check_points(name: str, arr: NDArray[np.floating], dim: int) -> F64:
    """Return ``arr`` as float64 ``(N, dim)``; raise ShapeError on a wrong shape or NaN/inf."""
    a = np.asarray(arr, dtype=np.float64)
    if a.ndim != 2 or a.shape[1] != dim:
        raise ShapeError(f"{name} must have shape (N, {dim}), got {a.shape}")
    if not np.all(np.isfinite(a)):
        raise ShapeError(f"{name} contains NaN or inf")
    return a


def check_matrix(name: str, arr: NDArray[np.floating], shape: tuple[int, int]) -> F64:
    """Return ``arr`` as a finite float64 matrix of ``shape``; raise ShapeError otherwise."""
    a = np.asarray(arr, dtype=np.float64)
    if a.shape != shape:
        raise ShapeError(f"{name} must have shape {shape}, got {a.shape}")
    if not np.all(np.isfinite(a)):
        raise ShapeError(f"{name} contains NaN or inf")
    return a


def pixels_to_normalized(pts_px: F64, K: F64) -> F64:
    """(N, 2) pixel coordinates -> (N, 2) normalized image coordinates (pinhole K)."""
    fx, fy, cx, cy = K[0, 0], K[1, 1], K[0, 2], K[1, 2]
    return np.column_stack([(pts_px[:, 0] - cx) / fx, (pts_px[:, 1] - cy) / fy])


def normalized_to_bearings(xn: F64) -> F64:
    """(N, 2) normalized coordinates -> (N, 3) unit bearing vectors."""
    b = np.column_stack([xn, np.ones(len(xn))])
    return b / np.linalg.norm(b, axis=1, keepdims=True)


def transform(T: F64, p: F64) -> F64:
    """Apply a 4x4 rigid transform to (N, 3) points."""
    return p @ T[:3, :3].T + T[:3, 3]


def project(K: F64, T_cam_world: F64, p_world: F64) -> tuple[F64, F64]:
    """Project (N, 3) world points; return ((N, 2) pixels, (N,) depths)."""
    pc = transform(T_cam_world, p_world)
    z = pc[:, 2]
    zs = np.where(np.abs(z) < 1e-12, 1e-12, z)
    u = K[0, 0] * pc[:, 0] / zs + K[0, 2]
    v = K[1, 1] * pc[:, 1] / zs + K[1, 2]
    return np.column_stack([u, v]), z


def rt_to_T(R: F64, t: F64) -> F64:
    """Stack a rotation and translation into a 4x4 transform."""
    T = np.eye(4)
    T[:3, :3] = R
    T[:3, 3] = np.asarray(t, dtype=np.float64).reshape(3)
    return T


def invert_T(T: F64) -> F64:
    """Inverse of a 4x4 rigid transform."""
    Ti = np.eye(4)
    Ti[:3, :3] = T[:3, :3].T
    Ti[:3, 3] = -T[:3, :3].T @ T[:3, 3]
    return Ti


def skew(v: F64) -> F64:
    """3x3 cross-product matrix of a 3-vector (amrvio.types.lie.hat)."""
    return hat(v)


def so3_exp_small(w: F64) -> F64:
    """Rotation matrix of a rotation vector; exact for tiny angles (amrvio.types.lie.so3_exp)."""
    return so3_exp(np.asarray(w, dtype=np.float64))


def se3_exp(xi: F64) -> F64:
    """4x4 SE(3) exponential of xi = [rho, phi] (amrvio.types.lie.SE3.exp)."""
    return SE3.exp(xi).matrix()
