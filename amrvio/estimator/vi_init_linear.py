"""The closed-form steps of the visual-inertial initialisation: gyro bias, then scale, gravity and
velocities by linear least squares, gravity refined on its sphere, then the accelerometer bias.

Unknowns: the scale ``s`` (metric = s x VO units), gravity ``g`` in the VO frame, the body
velocities ``v_k`` (VO frame, metric) and the biases. The body position at keyframe k is
``p_k = s c_k + l_k``: ``c_k`` the up-to-scale camera position and ``l_k = R_vo_cam_k t_cam_body``
the metric lever arm. With the preintegrated deltas of interval k (length T, amrvio.imu.preintegration)
the equations, in body frame k (R_k = R_vo_body_k), are

    R_k^T (v_{k+1} - v_k - g T)                      = dv_k              (Qin et al. 2018, eq. 10)
    R_k^T (s (c_{k+1} - c_k) - v_k T - g T^2 / 2)    = dp_k - R_k^T (l_{k+1} - l_k)

and each interval's 6 rows are whitened with the covariance of (dv_k, dp_k) plus the VO position
noise. The gyro bias comes first from the rotations alone (Qin et al. 2018, eq. 6); the
accelerometer bias enters through the bias Jacobians of the deltas (Mur-Artal and Tardos 2017,
section IV-C), with a prior that keeps it bounded when the motion cannot separate it from gravity.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from amrvio.imu.preintegration import Preintegrated
from amrvio.types.lie import so3_log

F64 = NDArray[np.float64]


@dataclass(frozen=True, slots=True, eq=False)
class ViProblem:
    """Fixed inputs. R_vo_body (K, 3, 3) from the VO; c_vo (K, 3) up-to-scale camera positions;
    t_body_cam (3,) the camera's position in the body frame (metric); pre: K-1 preintegrated
    intervals (all at the same biases)."""

    R_vo_body: F64
    c_vo: F64
    t_body_cam: F64
    pre: tuple[Preintegrated, ...]

    @property
    def lever_vo(self) -> F64:
        """(K, 3) l_k = -R_vo_body_k t_body_cam: body position = s c_k + l_k."""
        return np.asarray(-np.einsum("nij,j->ni", self.R_vo_body, self.t_body_cam))

    @property
    def n_keyframes(self) -> int:
        return int(self.R_vo_body.shape[0])


def rotation_errors(problem: ViProblem, gyro_bias: F64) -> F64:
    """(K-1, 3) Log(dR(b_g)^T R_k^T R_{k+1}): what the gyro misses of each VO rotation (first-order
    bias correction)."""
    out = np.empty((len(problem.pre), 3))
    R = problem.R_vo_body
    for k, p in enumerate(problem.pre):
        dR, _, _ = p.corrected(gyro_bias, p.accel_bias_m_s2)
        out[k] = so3_log(dR.T @ R[k].T @ R[k + 1])
    return out


def solve_gyro_bias(problem: ViProblem) -> F64:
    """Gyro bias minimising sum_k |Log(dR_k(b_g)^T R_k^T R_{k+1})|^2, linearised at the
    preintegration bias (Qin et al. 2018, eq. 6): J_k db = e_k stacked, least squares."""
    e = rotation_errors(problem, problem.pre[0].gyro_bias_rad_s)
    J = np.concatenate([p.d_bias[0:3, 0:3] for p in problem.pre])
    db, *_ = np.linalg.lstsq(J, e.reshape(-1), rcond=None)
    return np.asarray(problem.pre[0].gyro_bias_rad_s + db)


def whiteners(problem: ViProblem, position_var_m2: float) -> F64:
    """(K-1, 6, 6) L^-1 with L L^T = Cov(dv, dp) + position_var_m2 on the dp block."""
    out = np.empty((len(problem.pre), 6, 6))
    for k, p in enumerate(problem.pre):
        C = np.array(p.covariance[3:9, 3:9])
        C[3:6, 3:6] += np.eye(3) * position_var_m2
        C += np.eye(6) * 1e-12 * max(1.0, float(np.trace(C)))  # noise-free input stays solvable
        out[k] = np.linalg.inv(np.linalg.cholesky(C))
    return out


@dataclass(frozen=True, slots=True, eq=False)
class LinearSolution:
    """scale, gravity_vo (3,), velocities_vo (K, 3), accel_bias (3,) (the preintegration's when not
    solved), condition_number of the column-equilibrated whitened system, position_rms_m: RMS of
    the unwhitened position rows (metric, per component)."""

    scale: float
    gravity_vo: F64
    velocities_vo: F64
    accel_bias: F64
    condition_number: float
    position_rms_m: float


def _rows(problem: ViProblem, gyro_bias: F64, accel_bias: F64) -> tuple[F64, F64, F64, F64, F64]:
    """Per interval (M = K-1): coefficient blocks of s (M, 6), g (M, 6, 3), v_k (M, 6, 3),
    v_{k+1} (M, 6, 3) and the right-hand side (M, 6), rows [velocity, position]."""
    M = len(problem.pre)
    R, dc = problem.R_vo_body, np.diff(problem.c_vo, axis=0)
    dl = np.diff(problem.lever_vo, axis=0)
    a_s, a_g = np.zeros((M, 6)), np.zeros((M, 6, 3))
    a_v0, a_v1, rhs = np.zeros((M, 6, 3)), np.zeros((M, 6, 3)), np.zeros((M, 6))
    for k, p in enumerate(problem.pre):
        T, Rt = p.dt_s, R[k].T
        _, dv, dp = p.corrected(gyro_bias, accel_bias)
        a_g[k, 0:3], a_v0[k, 0:3], a_v1[k, 0:3], rhs[k, 0:3] = -Rt * T, -Rt, Rt, dv
        a_s[k, 3:6], a_g[k, 3:6], a_v0[k, 3:6] = Rt @ dc[k], -0.5 * Rt * T * T, -Rt * T
        rhs[k, 3:6] = dp - Rt @ dl[k]
    return a_s, a_g, a_v0, a_v1, rhs


def tangent_basis(g_dir: F64) -> F64:
    """(3, 2) orthonormal columns perpendicular to the unit vector ``g_dir``."""
    a = np.array([1.0, 0.0, 0.0]) if abs(g_dir[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    b1 = np.cross(g_dir, a)
    b1 /= np.linalg.norm(b1)
    return np.stack([b1, np.cross(g_dir, b1)], axis=1)


def _whiten(A_raw: F64, b_raw: F64, W: F64, extra_rows: F64 | None = None,
            extra_rhs: F64 | None = None) -> tuple[F64, F64]:
    """The per-interval system A_raw (M, 6, n) x = b_raw (M, 6) whitened with W (M, 6, 6) and
    stacked, with the (already whitened) ``extra_rows`` appended."""
    M = A_raw.shape[0]
    A = np.einsum("mij,mjn->min", W, A_raw).reshape(M * 6, -1)
    b = np.einsum("mij,mj->mi", W, b_raw).reshape(M * 6)
    if extra_rows is not None and extra_rhs is not None:
        A, b = np.vstack([A, extra_rows]), np.concatenate([b, extra_rhs])
    return A, b


def _equilibrated(A: F64, b: F64) -> tuple[F64, float, F64, F64]:
    """Solve the whitened A x = b by the column-equilibrated normal equations; returns (x, the
    condition number, the equilibrated normal matrix N, the column norms: cov(x) = N^-1 / (norms
    norms^T) for unit-variance rows)."""
    norms = np.linalg.norm(A, axis=0)
    norms[norms == 0.0] = 1.0
    An = A / norms
    N = An.T @ An
    eig = np.linalg.eigvalsh(N)
    cond = float(np.sqrt(eig[-1] / eig[0])) if eig[0] > 0 else float("inf")
    y, *_ = np.linalg.lstsq(N, An.T @ b, rcond=None)
    return y / norms, cond, N, norms


def _solve(A_raw: F64, b_raw: F64, W: F64, extra_rows: F64 | None = None,
           extra_rhs: F64 | None = None) -> tuple[F64, float, F64]:
    """Whiten the per-interval system (:func:`_whiten`) and solve it (:func:`_equilibrated`);
    returns (x, condition number of the equilibrated system, unwhitened residual (M, 6))."""
    x, cond, _, _ = _equilibrated(*_whiten(A_raw, b_raw, W, extra_rows, extra_rhs))
    resid = b_raw - np.einsum("min,n->mi", A_raw, x)
    return x, cond, resid


def _layout(a_s: F64, a_g: F64, a_v0: F64, a_v1: F64, extra: F64 | None) -> F64:
    """(M, 6, n) design blocks for unknowns [s, g-part (a_g's columns), v_0..v_{K-1}, extra]."""
    M = a_s.shape[0]
    K = M + 1
    n_g = a_g.shape[2]
    n_x = 0 if extra is None else extra.shape[2]
    out = np.zeros((M, 6, 1 + n_g + 3 * K + n_x))
    out[:, :, 0] = a_s
    out[:, :, 1:1 + n_g] = a_g
    for k in range(M):
        c = 1 + n_g + 3 * k
        out[k, :, c:c + 3] = a_v0[k]
        out[k, :, c + 3:c + 6] = a_v1[k]
    if extra is not None:
        out[:, :, 1 + n_g + 3 * K:] = extra
    return out


def _scale_row(n: int, value: float, std: float) -> tuple[F64, F64]:
    """One whitened prior row on the first unknown of ``n``: (x[0] - value) / std."""
    row = np.zeros((1, n))
    row[0, 0] = 1.0 / std
    return row, np.array([value / std])


def solve_free_gravity(problem: ViProblem, gyro_bias: F64, W: F64,
                       scale_prior: tuple[float, float] | None = None) -> LinearSolution:
    """Scale, gravity (3 free components) and velocities; accelerometer bias at the
    preintegration's (Qin et al. 2018, eq. 11). ``scale_prior``: (mean, std) of the scale from
    another sensor, as one more row."""
    ba = np.asarray(problem.pre[0].accel_bias_m_s2)
    a_s, a_g, a_v0, a_v1, rhs = _rows(problem, gyro_bias, ba)
    layout = _layout(a_s, a_g, a_v0, a_v1, None)
    rows, prhs = (None, None) if scale_prior is None else _scale_row(layout.shape[2], *scale_prior)
    x, cond, resid = _solve(layout, rhs, W, rows, prhs)
    K = problem.n_keyframes
    return LinearSolution(float(x[0]), x[1:4], x[4:4 + 3 * K].reshape(K, 3), ba, cond,
                          float(np.sqrt(np.mean(resid[:, 3:6] ** 2))))


def solve_inverse_scale(
    problem: ViProblem,
    gyro_bias: F64,
    W: F64,
    scale0: float,
    gravity_vo: F64,
    gravity_m_s2: float | None,
    accel_prior: tuple[F64, F64] | None = None,
    iterations: int = 4,
    scale_prior: tuple[float, float] | None = None,
) -> LinearSolution:
    """The same equations multiplied by the inverse scale lam = 1/s, in the unknowns lam,
    gam = lam g and u_k = lam v_k (VO units): the keyframe positions, the noisiest input, then
    stand alone on the right-hand side instead of multiplying the unknown scale, which would
    shrink it (errors in variables). ``scale0`` (from :func:`solve_free_gravity`) scales the
    whitening so that the rows are in VO units.

    ``gravity_m_s2`` None: gravity free (3 components). Else gravity has that norm and 2 degrees
    of freedom in the tangent plane at the current direction, iterated ``iterations`` times
    (Qin et al. 2018, eq. 13-14; with lam, gam = lam G g_dir + G B w', w' = lam w).
    ``accel_prior`` = (mean (3,), std (3,)): the accelerometer bias is solved too, as
    beta = lam (b_a - b_a0) through the bias Jacobians, with the prior as extra rows.
    ``scale_prior`` = (mean, std) of the scale from another sensor: a row on lam = 1/s (std
    std / mean^2, to first order).
    """
    g_dir = gravity_vo / np.linalg.norm(gravity_vo)
    ba0 = np.asarray(problem.pre[0].accel_bias_m_s2)
    K = problem.n_keyframes
    lam0 = 1.0 / scale0
    Wv = W / lam0
    a_s, a_g, a_v0, a_v1, rhs = _rows(problem, gyro_bias, ba0)
    J_ba = np.stack([p.d_bias[3:9, 3:6] for p in problem.pre])
    n_g = 3 if gravity_m_s2 is None else 2
    n_b = 3 if accel_prior is not None else 0
    sol = LinearSolution(scale0, gravity_vo, np.zeros((K, 3)), ba0, float("nan"), float("nan"))
    for _ in range(1 if gravity_m_s2 is None else iterations):
        # columns: [lam, gravity part, u_0..u_{K-1}, beta]; right-hand side -a_s
        if gravity_m_s2 is None:
            lam_col, g_cols = -rhs, a_g
        else:
            lam_col = np.einsum("mij,j->mi", a_g, gravity_m_s2 * g_dir) - rhs
            g_cols = gravity_m_s2 * np.einsum("mij,jk->mik", a_g, tangent_basis(g_dir))
        layout = _layout(lam_col, g_cols, a_v0, a_v1, -J_ba if n_b else None)
        rows = prhs = None
        if accel_prior is not None:
            n = layout.shape[2]
            rows = np.zeros((3, n))
            rows[:, n - 3:] = np.diag(1.0 / (lam0 * accel_prior[1]))
            rows[:, 0] = -(accel_prior[0] - ba0) / (lam0 * accel_prior[1])
            prhs = np.zeros(3)
        if scale_prior is not None:
            m, sd = scale_prior
            srow, srhs = _scale_row(layout.shape[2], 1.0 / m, sd / m**2)
            rows = srow if rows is None else np.vstack([rows, srow])
            prhs = srhs if prhs is None else np.concatenate([prhs, srhs])
        x, cond, resid = _solve(layout, -a_s, Wv, rows, prhs)
        lam = float(x[0])
        if lam == 0.0:
            return LinearSolution(float("inf"), gravity_vo, np.zeros((K, 3)), ba0, cond, float("nan"))
        if gravity_m_s2 is None:
            g_vec = x[1:4] / lam
        else:
            g_vec = gravity_m_s2 * (g_dir + tangent_basis(g_dir) @ x[1:3] / lam)
            g_vec *= gravity_m_s2 / np.linalg.norm(g_vec)
            g_dir = g_vec / gravity_m_s2
        v = x[1 + n_g:1 + n_g + 3 * K].reshape(K, 3) / lam
        ba = ba0 + x[1 + n_g + 3 * K:] / lam if n_b else ba0
        pos_rms = float(np.sqrt(np.mean(resid[:, 3:6] ** 2))) / abs(lam)  # metric
        sol = LinearSolution(1.0 / lam, g_vec, v, ba, cond, pos_rms)
    return sol


def scale_drift(problem: ViProblem, gyro_bias: F64, W: F64, accel_prior: tuple[F64, F64]) -> tuple[float, float]:
    """How much the VO's scale changes across the window: the free-gravity system of
    :func:`solve_free_gravity`, with the accelerometer bias and its prior (mean (3,), std (3,)) as
    in :func:`solve_inverse_scale`, and the scale linear in time: s(t) = s0 (1 + d tau), tau from
    -1/2 at the first keyframe to +1/2 at the last (each interval's VO step at its midpoint's
    scale). Returns (d, its standard deviation): d = 0.1 is a VO whose metres per unit grew by
    10 % from the window's start to its end; a single scale then fits neither end. The standard
    deviation is from the whitened normal equations, scaled by the residual's chi2 per degree of
    freedom when that is above 1."""
    ba0 = np.asarray(problem.pre[0].accel_bias_m_s2)
    a_s, a_g, a_v0, a_v1, rhs = _rows(problem, gyro_bias, ba0)
    dt = np.array([p.dt_s for p in problem.pre])
    total = float(dt.sum())
    if total <= 0.0:
        return float("nan"), float("nan")
    tau = (np.cumsum(dt) - 0.5 * dt) / total - 0.5
    J_ba = np.stack([p.d_bias[3:9, 3:6] for p in problem.pre])
    layout = _layout(a_s, a_g, a_v0, a_v1, np.concatenate([-J_ba, (a_s * tau[:, None])[:, :, None]], axis=2))
    n = layout.shape[2]
    prior_rows = np.zeros((3, n))
    prior_rows[:, n - 4:n - 1] = np.diag(1.0 / accel_prior[1])
    prior_rhs = (accel_prior[0] - ba0) / accel_prior[1]
    A, b = _whiten(layout, rhs, W, prior_rows, prior_rhs)
    x, _, N, norms = _equilibrated(A, b)
    r = b - A @ x
    dof = A.shape[0] - n
    if dof <= 0 or not 0.0 < x[0] < math.inf:
        return float("nan"), float("nan")
    cov = np.linalg.pinv(N) / np.outer(norms, norms) * max(float(r @ r) / dof, 1.0)
    # d = x_d / x_0, to first order in both
    J = np.array([-x[-1] / x[0] ** 2, 1.0 / x[0]])
    C = cov[np.ix_([0, n - 1], [0, n - 1])]
    return float(x[-1] / x[0]), float(np.sqrt(max(float(J @ C @ J), 0.0)))


def vo_position_var(problem: ViProblem, gyro_bias: F64, accel_bias: F64, scale: float, gravity_vo: F64) -> float:
    """The VO keyframes' position noise variance (per component, VO units) from three consecutive
    keyframes, with the velocities eliminated (Mur-Artal and Tardos 2017, eq. 19): the residual

        e_k = (s dc_k + dl_k - g T_k^2/2 - R_k dp_k) / T_k
              - (s dc_{k-1} + dl_{k-1} - g T_{k-1}^2/2 - R_{k-1} dp_{k-1}) / T_{k-1}
              - g T_{k-1} - R_{k-1} dv_{k-1}

    holds the VO noise as s (n_{k+1} - n_k) / T_k - s (n_k - n_{k-1}) / T_{k-1} and the IMU's
    error over two intervals only, which is small beside it: unlike a residual of the full window,
    it does not depend on how noisy the IMU is over seconds. Its spread about its mean (a wrong
    gravity or bias is nearly constant) gives the variance."""
    M = len(problem.pre)
    if M < 3:
        return 0.0
    R, dc, dl = problem.R_vo_body, np.diff(problem.c_vo, axis=0), np.diff(problem.lever_vo, axis=0)
    T = np.array([p.dt_s for p in problem.pre])
    dv = np.empty((M, 3))
    dp = np.empty((M, 3))
    for k, p in enumerate(problem.pre):
        _, dv[k], dp[k] = p.corrected(gyro_bias, accel_bias)
    disp = (scale * dc + dl - 0.5 * gravity_vo * (T * T)[:, None] - np.einsum("mij,mj->mi", R[:-1], dp)) / T[:, None]
    e = disp[1:] - disp[:-1] - gravity_vo * T[:-1, None] - np.einsum("mij,mj->mi", R[:-2], dv[:-1])
    gain = 1.0 / T[1:] ** 2 + (1.0 / T[1:] + 1.0 / T[:-1]) ** 2 + 1.0 / T[:-1] ** 2
    dev = e - e.mean(axis=0)
    n = dev.shape[0]
    return float(np.mean(dev**2 / gain[:, None]) * n / max(n - 1, 1)) / scale**2


def rotation_range(R_vo_cam: F64) -> tuple[float, F64]:
    """(largest angle between two orientations in degrees, (3,) range of the rotation vector of
    R_cam0^T R_camk about the first camera's axes in degrees)."""
    R = np.asarray(R_vo_cam)
    rel = np.einsum("ji,njk->nik", R[0], R)
    rv = so3_log(rel)
    per_axis = np.degrees(rv.max(axis=0) - rv.min(axis=0))
    pair = np.einsum("aji,bjk->abik", R, R)
    cos = np.clip((np.trace(pair, axis1=2, axis2=3) - 1.0) / 2.0, -1.0, 1.0)
    return float(np.degrees(np.arccos(cos.min()))), per_axis

