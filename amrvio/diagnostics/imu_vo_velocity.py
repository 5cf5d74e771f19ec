"""The camera's velocity in the VO's units from its recent poses and the IMU (issue 13).

A velocity differenced from poses at the frame rate lags any motion faster than a few frame
intervals (a hand shaking at 2-2.5 Hz, filmed at 10 Hz). The accelerometer follows it, but it
is metric and the VO is not. The translational smear needs only velocity over depth, so the
velocity is wanted in the VO's units, and the scale ``mu`` (VO units per metre) enters only as a
factor on the IMU's part. Over a window of poses ``c_i`` (camera centres, VO world) at ``t_i``:

    c_i - c_0 = u_0 dt_i + h dt_i^2 / 2 + mu (S(t_i) + (R_wb(t_i) - R_wb(t_0)) p_bc)

with ``dt_i = t_i - t_0``; ``S(t) = int_t0^t int_t0^s R_wb a_m``, the accelerometer's specific
force rotated into the VO's world by the gyro-propagated attitude (anchored at the last pose's
rotation) and integrated twice; ``p_bc`` the camera centre in the body frame (lever arm). The
unknowns, linear: ``u_0`` the body's velocity at ``t_0`` and ``h = mu g`` gravity, both in VO
units, and ``mu``. ``h`` free in three axes also takes up a constant accelerometer bias while the
attitude changes little. The camera's velocity at ``t`` is then

    v_c(t) = u_0 + h (t - t_0) + mu (V(t) + R_wb(t) (omega(t) x p_bc)),   V = dS/dt.

Without excitation (constant velocity) ``mu S`` and ``h dt^2/2`` cancel for any ``mu``: ``mu``
is unobservable, but so is its effect on ``v_c`` (the fit is a quadratic through the poses, the
IMU adds nothing); with excitation ``mu`` is determined by it. Either way the velocity in VO
units is, which the full visual-inertial initialisation does not give before it passes.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray

from amrvio.diagnostics.smear import rotations_at
from amrvio.types.sensors import ImuData

F64 = NDArray[np.float64]

MIN_POSES = 5  # poses in the window for the fit (7 unknowns, 3 equations per pose after the first)
MAX_IMU_GAP_S = 0.05  # the IMU must cover the window without a longer gap


def imu_vo_velocity(poses: list[tuple[int, F64]], t_ns: int, imu: ImuData, R_cam_body: F64,
                    p_body_cam: F64, gyro_bias_rad_s: F64 | None = None) -> F64 | None:
    """Velocity (3,) of the camera centre at ``t_ns`` in the camera frame at ``t_ns``, VO units
    per second, from ``poses`` ``(t_ns, T_cam_world)`` (time order, one map segment) and ``imu``
    (see the module docstring). ``R_cam_body``: the camera-IMU rotation; ``p_body_cam`` (3,): the
    camera centre in the body frame (m). None when there are fewer than ``MIN_POSES`` poses or
    the IMU does not cover ``[t_0, max(t_last, t_ns)]``."""
    if len(poses) < MIN_POSES:
        return None
    t_pose = np.array([t for t, _ in poses], dtype=np.int64)
    t_end = max(int(t_pose[-1]), int(t_ns))
    ts = np.asarray(imu.stamps_ns, dtype=np.int64)
    inside = ts[(ts >= t_pose[0]) & (ts <= t_end)]
    if ts.size < 2 or ts[0] > t_pose[0] or ts[-1] < t_end - int(MAX_IMU_GAP_S * 1e9):
        return None
    grid = np.unique(np.concatenate([inside, t_pose, [t_ns]]))
    if np.max(np.diff(np.concatenate([[t_pose[0]], inside, [t_end]]))) > MAX_IMU_GAP_S * 1e9:
        return None
    rel = (grid - grid[0]) * 1e-9
    ts_rel = (ts - grid[0]) * 1e-9
    g = np.asarray(imu.gyro_rad_s, dtype=np.float64)
    if gyro_bias_rad_s is not None:
        g = g - np.asarray(gyro_bias_rad_s, dtype=np.float64).reshape(1, 3)
    a = np.asarray(imu.accel_m_s2, dtype=np.float64)
    w = np.stack([np.interp(rel, ts_rel, g[:, k]) for k in range(3)], axis=1)
    f = np.stack([np.interp(rel, ts_rel, a[:, k]) for k in range(3)], axis=1)
    # attitude Q_k = R_b0_bk by the gyro (midpoint rate, exact exponential per step)
    Q = rotations_at(ts, g, grid, None, None)
    dt = np.diff(rel)
    idx = np.searchsorted(grid, t_pose)
    i_now = int(np.searchsorted(grid, t_ns))
    T_last = np.asarray(poses[-1][1], dtype=np.float64)
    R_wb_last = T_last[:3, :3].T @ np.asarray(R_cam_body, dtype=np.float64)
    R_wb = np.einsum("ij,njk->nik", R_wb_last @ Q[idx[-1]].T, Q)
    f_w = np.einsum("nij,nj->ni", R_wb, f)
    V = np.concatenate([np.zeros((1, 3)), np.cumsum(0.5 * (f_w[1:] + f_w[:-1]) * dt[:, None], 0)])
    S = np.concatenate([np.zeros((1, 3)), np.cumsum(0.5 * (V[1:] + V[:-1]) * dt[:, None], 0)])
    p_bc = np.asarray(p_body_cam, dtype=np.float64).reshape(3)
    c = np.array([-T[:3, :3].T @ T[:3, 3] for _, T in poses])
    dti = rel[idx[1:]]
    lever = np.einsum("nij,j->ni", R_wb[idx[1:]] - R_wb[idx[0]], p_bc)
    n = dti.size
    A = np.zeros((3 * n, 7))
    eye = np.eye(3)
    for i in range(n):
        A[3 * i:3 * i + 3, 0:3] = dti[i] * eye
        A[3 * i:3 * i + 3, 3:6] = 0.5 * dti[i] ** 2 * eye
        A[3 * i:3 * i + 3, 6] = S[idx[i + 1]] + lever[i]
    b = (c[1:] - c[0]).reshape(-1)
    norms = np.linalg.norm(A, axis=0)
    norms[norms == 0] = 1.0
    x = np.linalg.lstsq(A / norms, b, rcond=1e-9)[0] / norms
    u0, h, mu = x[0:3], x[3:6], float(x[6])
    t_rel = rel[i_now]
    v_w = u0 + h * t_rel + mu * (V[i_now] + R_wb[i_now] @ np.cross(w[i_now], p_bc))
    R_wc = R_wb[i_now] @ np.asarray(R_cam_body, dtype=np.float64).T
    out: F64 = R_wc.T @ v_w
    return out


def imu_velocity(imu: ImuData, R_cam_body: F64 | None, p_body_cam: F64 | None,
                 gyro_bias_rad_s: F64 | None = None,
                 ) -> Callable[[list[tuple[int, F64]], int], F64 | None] | None:
    """:func:`imu_vo_velocity` on ``imu`` as a function of ``(poses, t_ns)`` (what
    :meth:`~amrvio.diagnostics.vo_motion.MotionHistory.camera_motion` takes), or None without an
    extrinsic or with fewer than two samples."""
    if R_cam_body is None or p_body_cam is None or len(imu) < 2:
        return None
    R, p = R_cam_body, p_body_cam
    return lambda poses, t_ns: imu_vo_velocity(poses, t_ns, imu, R, p, gyro_bias_rad_s)


__all__ = ["MIN_POSES", "imu_velocity", "imu_vo_velocity"]
