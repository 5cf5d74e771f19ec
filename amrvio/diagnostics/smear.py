"""Gyro-predicted motion-blur smear and exposure advice (seed section 5, Problem 5).

The seed's rule of thumb is ``L_px ~= f * |omega| * T`` at the image centre. Here the full field is
computed: the camera rotation over the exposure window is integrated from the gyro (exact SO3
exponential on each interval, rates rotated into the camera frame by the camera-IMU extrinsic), and
every point of a grid over the image is moved by that rotation through ``camera.unproject`` /
``camera.project``, so lens distortion and the off-axis growth of the smear count. The smear of a
pixel is the distance between its position at the start and at the end of the exposure (for the
sub-10 ms exposures of interest the rotation is nearly uniform, so this equals the streak length).
Translation is ignored (negligible for distant scenes; it is a lower bound near walls).
This needs only the IMU and the exposure time: it works before the image is decoded.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from amrvio.errors import ShapeError
from amrvio.types.camera import CameraModel
from amrvio.types.lie import so3_exp, so3_log

F64 = NDArray[np.float64]


@dataclass(frozen=True, slots=True)
class SmearPrediction:
    """Predicted rotational smear of one exposure.

    ``max_px`` / ``mean_px``: over a grid covering the image; ``center_px``: at the principal
    point; ``omega_cam_rad_s`` (3,): mean angular rate in the camera frame over the window;
    ``exposure_s``: the exposure used; ``n_imu``: gyro samples inside the window.
    """

    max_px: float
    mean_px: float
    center_px: float
    omega_cam_rad_s: F64
    exposure_s: float
    n_imu: int


def integrate_gyro(
    stamps_ns: NDArray[np.int64],
    gyro_rad_s: F64,
    t0_ns: int,
    t1_ns: int,
    R_cam_body: F64 | None = None,
    gyro_bias_rad_s: F64 | None = None,
) -> F64:
    """Rotation ``R_c0_c1`` (3, 3) of the camera (or body if ``R_cam_body`` is None) over [t0, t1].

    Rates are linearly interpolated at the window ends (held constant beyond the data) and
    integrated interval by interval with the exact exponential of the midpoint rate. Rates are
    rotated into the camera frame: ``omega_cam = R_cam_body (omega_body - bias)``.
    """
    t = np.asarray(stamps_ns, dtype=np.int64)
    g = np.asarray(gyro_rad_s, dtype=np.float64)
    if t.ndim != 1 or g.shape != (t.shape[0], 3):
        raise ShapeError(f"gyro arrays must be (N,) and (N,3), got {t.shape} and {g.shape}")
    if t.shape[0] == 0:
        raise ShapeError("integrate_gyro needs at least one gyro sample")
    if t1_ns < t0_ns:
        raise ShapeError(f"window end {t1_ns} is before its start {t0_ns}")
    if gyro_bias_rad_s is not None:
        g = g - np.asarray(gyro_bias_rad_s, dtype=np.float64).reshape(1, 3)
    if R_cam_body is not None:
        g = g @ np.asarray(R_cam_body, dtype=np.float64).T
    inside = t[(t > t0_ns) & (t < t1_ns)]
    knots = np.concatenate([[t0_ns], inside, [t1_ns]]).astype(np.int64)
    rel = (knots - t0_ns).astype(np.float64) * 1e-9
    ts = (t - t0_ns).astype(np.float64) * 1e-9
    w = np.stack([np.interp(rel, ts, g[:, k]) for k in range(3)], axis=1)
    dt = np.diff(rel)
    steps = 0.5 * (w[1:] + w[:-1]) * dt[:, None]
    R = np.eye(3)
    for Rk in so3_exp(steps) if steps.shape[0] else ():
        R = R @ Rk
    return R


def _grid(camera: CameraModel, grid: tuple[int, int]) -> F64:
    nx, ny = grid
    us = np.linspace(0.0, camera.width - 1.0, nx)
    vs = np.linspace(0.0, camera.height - 1.0, ny)
    uu, vv = np.meshgrid(us, vs)
    return np.stack([uu.ravel(), vv.ravel()], axis=1)


def smear_field(
    camera: CameraModel, R_c0_c1: F64, grid: tuple[int, int] = (16, 12)
) -> tuple[F64, F64]:
    """Pixel displacement of a rotation ``R_c0_c1`` over a grid spanning the image.

    Returns ``(uv0 (M, 2), disp_px (M,))``; points that leave the valid projection get NaN.
    A direction d0 in camera 0 is seen along ``d1 = R_c0_c1^T d0`` in camera 1.
    """
    uv0 = _grid(camera, grid)
    return uv0, smear_at_pixels(camera, R_c0_c1, uv0)


def smear_at_pixels(camera: CameraModel, R_c0_c1: F64, uv0: F64) -> F64:
    """(M,) displacement (px) of the rotation ``R_c0_c1`` at (M, 2) pixels ``uv0`` (NaN where the
    projection is invalid)."""
    R = np.asarray(R_c0_c1, dtype=np.float64)
    if R.shape != (3, 3):
        raise ShapeError(f"R_c0_c1 must be (3,3), got {R.shape}")
    rays0 = camera.unproject(uv0)
    ok = np.all(np.isfinite(rays0), axis=1)
    disp = np.full(uv0.shape[0], np.nan)
    if np.any(ok):
        uv1 = camera.project(rays0[ok] @ R)  # (R^T d0)^T = d0^T R
        disp[ok] = np.linalg.norm(uv1 - uv0[ok], axis=1)
    return disp


def _centre_smear(camera: CameraModel, R: F64) -> float:
    uv0 = np.array([[camera.cx, camera.cy]])
    uv1 = camera.project(camera.unproject(uv0) @ R)
    return float(np.linalg.norm(uv1 - uv0))


def predict_smear(
    camera: CameraModel,
    stamps_ns: NDArray[np.int64],
    gyro_rad_s: F64,
    t_mid_ns: int,
    exposure_s: float,
    R_cam_body: F64 | None = None,
    gyro_bias_rad_s: F64 | None = None,
    grid: tuple[int, int] = (16, 12),
) -> SmearPrediction:
    """Predicted smear of the exposure ``[t_mid - T/2, t_mid + T/2]`` from gyro samples."""
    if not np.isfinite(exposure_s) or exposure_s < 0:
        raise ShapeError(f"exposure_s must be finite and >= 0, got {exposure_s}")
    half = int(round(exposure_s * 0.5e9))
    t0, t1 = int(t_mid_ns) - half, int(t_mid_ns) + half
    R = integrate_gyro(stamps_ns, gyro_rad_s, t0, t1, R_cam_body, gyro_bias_rad_s)
    _, disp = smear_field(camera, R, grid)
    finite = disp[np.isfinite(disp)]
    t = np.asarray(stamps_ns)
    n_imu = int(np.count_nonzero((t >= t0) & (t <= t1)))
    omega = so3_log(R) / exposure_s if exposure_s > 0 else np.zeros(3)
    return SmearPrediction(
        max_px=float(finite.max()) if finite.size else float("nan"),
        mean_px=float(finite.mean()) if finite.size else float("nan"),
        center_px=_centre_smear(camera, R),
        omega_cam_rad_s=omega,
        exposure_s=float(exposure_s),
        n_imu=n_imu,
    )


def max_exposure_for_smear(
    camera: CameraModel,
    omega_cam_rad_s: F64,
    bound_px: float = 2.0,
    grid: tuple[int, int] = (16, 12),
    max_exposure_s: float = 1.0,
) -> float:
    """Longest exposure (s) whose predicted max smear stays <= ``bound_px`` at a constant rate.

    Smear grows almost linearly with T, so the fixed point ``T <- T * bound / smear(T)`` converges
    in a few steps; the result is capped at ``max_exposure_s`` (also returned for a zero rate).
    """
    w = np.asarray(omega_cam_rad_s, dtype=np.float64)
    if w.shape != (3,) or not np.all(np.isfinite(w)):
        raise ShapeError(f"omega_cam_rad_s must be finite (3,), got {w.shape}")
    if bound_px <= 0:
        raise ShapeError(f"bound_px must be > 0, got {bound_px}")
    if float(np.linalg.norm(w)) < 1e-12:
        return max_exposure_s
    T = 1e-3
    for _ in range(6):
        _, disp = smear_field(camera, so3_exp(w * T), grid)
        s = float(np.nanmax(disp))
        if not np.isfinite(s) or s <= 0:
            return max_exposure_s
        T_new = T * bound_px / s
        if abs(T_new - T) <= 1e-6 * T:
            T = T_new
            break
        T = T_new
        if T >= max_exposure_s:
            return max_exposure_s
    return float(min(T, max_exposure_s))
