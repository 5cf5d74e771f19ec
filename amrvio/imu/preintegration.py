"""IMU preintegration between two instants (Forster et al. 2017, "On-manifold preintegration").

Between ``t0`` and ``t1`` the body rotation, velocity and position changes are, with
``f = accel - b_a`` and ``w = gyro - b_g`` (body frame, gravity not included):

    dR = prod_j Exp(w_j dt_j)
    dv = sum_j dR_j f_j dt_j
    dp = sum_j dv_j dt_j + 1/2 dR_j f_j dt_j^2                      (Forster eq. 35-37)

and the states they constrain (world frame, ``g_world`` the gravity vector):

    R_1 = R_0 dR
    v_1 = v_0 + g_world T + R_0 dv
    p_1 = p_0 + v_0 T + 1/2 g_world T^2 + R_0 dp                    (Forster eq. 38)

The samples are resampled at ``t0`` and ``t1`` (linear interpolation) and each step uses the
mean of its two end samples, rotated by the rotation at mid-step (midpoint rule: without it, a
rate w turning the 9.81 m/s^2 of gravity costs an error of w g dt / 2 per unit time, 0.025 m/s^2
at 1 rad/s and 200 Hz). :class:`Preintegrated` keeps the Jacobians of the
deltas with respect to the biases (Forster eq. 44, to correct for a new bias without
re-integrating) and, when a noise model is given, the covariance of the deltas (eq. 62-63).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from amrvio.errors import ShapeError
from amrvio.types.lie import hat, so3_exp
from amrvio.types.sensors import ImuData, ImuNoise

F64 = NDArray[np.float64]


def _ro(a: ArrayLike) -> F64:
    out = np.array(a, dtype=np.float64)
    out.setflags(write=False)
    return out


def so3_right_jacobians(phis: F64) -> F64:
    """Right Jacobians J_r(phi) of SO3 (Forster eq. 8), batched: (N, 3) -> (N, 3, 3).
    Exp(phi + d) ~ Exp(phi) Exp(J_r d)."""
    phi = np.asarray(phis, dtype=np.float64).reshape(-1, 3)
    t = np.linalg.norm(phi, axis=1)
    small = t < 1e-4
    ts = np.where(small, 1.0, t)
    t2 = t * t
    b = np.where(small, 0.5 - t2 / 24.0, (1.0 - np.cos(ts)) / ts**2)
    c = np.where(small, 1.0 / 6.0 - t2 / 120.0, (ts - np.sin(ts)) / ts**3)
    W = hat(phi)
    return np.asarray(np.eye(3) - b[:, None, None] * W + c[:, None, None] * (W @ W))


@dataclass(frozen=True, slots=True, eq=False)
class Preintegrated:
    """Preintegrated IMU deltas over ``[t0_ns, t1_ns]`` at the bias linearisation point.

    delta_R (3, 3), delta_v (3,), delta_p (3,): the deltas of the module docstring.
    gyro_bias_rad_s, accel_bias_m_s2 (3,): the biases they were integrated with.
    d_bias (9, 6): Jacobian of [dR (as a right perturbation), dv, dp] (rows) with respect to
    [b_g, b_a] (columns). covariance (9, 9): of [dR, dv, dp], zeros when no noise was given.
    """

    t0_ns: int
    t1_ns: int
    delta_R: F64
    delta_v: F64
    delta_p: F64
    gyro_bias_rad_s: F64
    accel_bias_m_s2: F64
    d_bias: F64
    covariance: F64

    @property
    def dt_s(self) -> float:
        return (self.t1_ns - self.t0_ns) * 1e-9

    def corrected(self, gyro_bias_rad_s: ArrayLike, accel_bias_m_s2: ArrayLike) -> tuple[F64, F64, F64]:
        """First-order (dR, dv, dp) for other biases (Forster eq. 44)."""
        db = np.concatenate([np.asarray(gyro_bias_rad_s, dtype=np.float64) - self.gyro_bias_rad_s,
                             np.asarray(accel_bias_m_s2, dtype=np.float64) - self.accel_bias_m_s2])
        d = self.d_bias @ db
        return self.delta_R @ so3_exp(d[0:3]), self.delta_v + d[3:6], self.delta_p + d[6:9]


def _resampled(imu: ImuData, t0_ns: int, t1_ns: int) -> tuple[F64, F64, F64]:
    """(stamps_s relative to t0 (M,), gyro (M, 3), accel (M, 3)) on [t0, t1], ends interpolated."""
    st = imu.stamps_ns
    if len(imu) < 2 or t0_ns < int(st[0]) or t1_ns > int(st[-1]):
        lo, hi = (int(st[0]), int(st[-1])) if len(imu) else (0, -1)
        raise ShapeError(f"IMU samples cover [{lo}, {hi}] ns, not the interval [{t0_ns}, {t1_ns}] ns")
    if t1_ns <= t0_ns:
        raise ShapeError(f"preintegration interval must have t1 > t0, got [{t0_ns}, {t1_ns}] ns")
    lo = int(np.searchsorted(st, t0_ns, side="right"))
    hi = int(np.searchsorted(st, t1_ns, side="left"))
    rel = (st.astype(np.int64) - t0_ns).astype(np.float64) * 1e-9
    t_end = (t1_ns - t0_ns) * 1e-9
    t = np.concatenate([[0.0], rel[lo:hi], [t_end]])
    # Stamps are relative to t0 so that the float interpolation keeps ns resolution.
    gyro = np.stack([np.interp(t, rel, imu.gyro_rad_s[:, k]) for k in range(3)], axis=1)
    accel = np.stack([np.interp(t, rel, imu.accel_m_s2[:, k]) for k in range(3)], axis=1)
    return t, gyro, accel


def preintegrate(
    imu: ImuData,
    t0_ns: int,
    t1_ns: int,
    gyro_bias_rad_s: ArrayLike = (0.0, 0.0, 0.0),
    accel_bias_m_s2: ArrayLike = (0.0, 0.0, 0.0),
    noise: ImuNoise | None = None,
) -> Preintegrated:
    """Preintegrate ``imu`` over ``[t0_ns, t1_ns]`` (it must cover the interval; ShapeError if not).

    ``noise``: continuous-time densities; the covariance of a step of length dt is then
    density^2 / dt per axis (as gtsam's PreintegrationParams).
    """
    bg = np.asarray(gyro_bias_rad_s, dtype=np.float64).reshape(3)
    ba = np.asarray(accel_bias_m_s2, dtype=np.float64).reshape(3)
    t, gyro, accel = _resampled(imu, int(t0_ns), int(t1_ns))
    dts = np.diff(t)
    keep = dts > 0.0
    dts = dts[keep]
    w = (0.5 * (gyro[1:] + gyro[:-1]) - bg)[keep]
    f = (0.5 * (accel[1:] + accel[:-1]) - ba)[keep]
    n = dts.shape[0]
    steps = so3_exp(w * dts[:, None])
    halves = so3_exp(0.5 * w * dts[:, None])
    Rs = np.empty((n + 1, 3, 3))  # Rs[j]: the rotation before step j
    Rs[0] = np.eye(3)
    for j in range(n):
        Rs[j + 1] = Rs[j] @ steps[j]
    R_mid = Rs[:-1] @ halves  # the rotation at mid-step: second order in the step
    acc = np.einsum("nij,nj->ni", R_mid, f)
    dt1, dt2 = dts[:, None], (dts * dts)[:, None]
    dv_before = np.cumsum(acc * dt1, axis=0) - acc * dt1
    dv = dv_before[-1] + acc[-1] * dts[-1]
    dp = np.sum(dv_before * dt1 + 0.5 * acc * dt2, axis=0)
    # Bias Jacobians (Forster appendix B) in closed form: before step j,
    # dR/db_g = -R_j^T sum_{k<j} R_{k+1} J_r,k dt_k, and dv, dp by sums over the steps.
    Jr = so3_right_jacobians(w * dts[:, None])
    terms = np.einsum("nij,njk->nik", Rs[1:], Jr) * dts[:, None, None]
    S_before = np.cumsum(terms, axis=0) - terms
    jR_before = -np.einsum("nji,njk->nik", Rs[:-1], S_before)
    jR_g = -Rs[-1].T @ np.sum(terms, axis=0)
    jR_mid = (np.einsum("nji,njk->nik", halves, jR_before)
              - so3_right_jacobians(0.5 * w * dts[:, None]) * (0.5 * dts)[:, None, None])
    Rf_hat = R_mid @ hat(f)
    Mg = Rf_hat @ jR_mid
    d3 = dts[:, None, None]
    jv_g_before = -(np.cumsum(Mg * d3, axis=0) - Mg * d3)
    jv_a_before = -(np.cumsum(R_mid * d3, axis=0) - R_mid * d3)
    d_bias = np.zeros((9, 6))
    d_bias[0:3, 0:3] = jR_g
    d_bias[3:6, 0:3] = jv_g_before[-1] - Mg[-1] * dts[-1]
    d_bias[3:6, 3:6] = jv_a_before[-1] - R_mid[-1] * dts[-1]
    d_bias[6:9, 0:3] = np.sum(jv_g_before * d3 - 0.5 * Mg * d3 * d3, axis=0)
    d_bias[6:9, 3:6] = np.sum(jv_a_before * d3 - 0.5 * R_mid * d3 * d3, axis=0)
    cov = np.zeros((9, 9))
    if noise is not None:  # Forster eq. 63, state [dphi, dv, dp]; per-step noise density^2 / dt
        A = np.tile(np.eye(9), (n, 1, 1))
        A[:, 0:3, 0:3] = np.transpose(steps, (0, 2, 1))
        A[:, 3:6, 0:3] = -Rf_hat * d3
        A[:, 6:9, 0:3] = -0.5 * Rf_hat * d3 * d3
        A[:, 6:9, 3:6] = np.eye(3) * d3
        Bg = Jr * d3  # rows 0:3
        Ba = np.concatenate([R_mid * d3, 0.5 * R_mid * d3 * d3], axis=1)  # rows 3:9
        Q = np.zeros((n, 9, 9))
        Q[:, 0:3, 0:3] = np.einsum("nij,nkj->nik", Bg, Bg) * (noise.gyro_noise_density**2 / d3)
        Q[:, 3:9, 3:9] = np.einsum("nij,nkj->nik", Ba, Ba) * (noise.accel_noise_density**2 / d3)
        for j in range(n):
            cov = A[j] @ cov @ A[j].T + Q[j]
    return Preintegrated(int(t0_ns), int(t1_ns), _ro(Rs[-1]), _ro(dv), _ro(dp), _ro(bg), _ro(ba),
                         _ro(d_bias), _ro(cov))


def preintegrate_between(
    imu: ImuData,
    stamps_ns: Sequence[int] | NDArray[np.int64],
    gyro_bias_rad_s: ArrayLike = (0.0, 0.0, 0.0),
    accel_bias_m_s2: ArrayLike = (0.0, 0.0, 0.0),
    noise: ImuNoise | None = None,
) -> tuple[Preintegrated, ...]:
    """:func:`preintegrate` over each pair of consecutive ``stamps_ns`` (K stamps -> K-1 intervals)."""
    st = [int(s) for s in stamps_ns]
    return tuple(preintegrate(imu, a, b, gyro_bias_rad_s, accel_bias_m_s2, noise)
                 for a, b in zip(st[:-1], st[1:], strict=True))
