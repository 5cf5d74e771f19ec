"""MAP refinement of the visual-inertial initialisation, and its marginal covariance.

A small batch problem over the window (the inertial optimisation of Campos et al. 2021, ORB-SLAM3,
section V-B, with the VO poses as noisy measurements instead of fixed). Unknowns: the scale s,
gravity ``G Exp(B w) g_dir`` (2 degrees of freedom on its sphere, re-anchored every iteration), per
keyframe the body rotation ``R_k`` (a right perturbation of the VO's), position ``p_k`` and velocity
``v_k`` (VO frame, metric) and accelerometer bias ``ba_k``, and one gyro bias. Residuals:

- VO rotation, per keyframe: ``Log(Rvo_k^T R_k)``;
- VO position, per keyframe, in VO units: ``(p_k + R_k t_body_cam) / s - c_k`` (the keyframe
  positions' noise is additive there and does not shrink the scale);
- IMU, per interval (Forster et al. 2017, eq. 45), at the biases (b_g, ba_k):
  ``Log(dR^T R_k^T R_{k+1})``, ``R_k^T (v_{k+1} - v_k - g T) - dv``,
  ``R_k^T (p_{k+1} - p_k - v_k T - g T^2 / 2) - dp``;
- accelerometer bias random walk, per interval: ``(ba_{k+1} - ba_k) / (sigma_w sqrt(T))``. A
  constant bias is not enough on real data: the EuRoC V1_01 ground truth's accelerometer bias
  wanders about 0.014 m/s^2 per sqrt(s) (4.7 times the datasheet's walk), and a synthetic IMU with
  that bias gives a scale 1 to 4 % low under a constant-bias model;
- Gaussian priors on the gyro bias and on the first keyframe's accelerometer bias.

The VO position noise is given (estimated beforehand from three-keyframe residuals, which the
IMU's slow errors do not reach: estimated jointly, it trades off against the accelerometer's noise
and the scale drifts with the trade). The other groups have unknown variances: VO rotation noise,
and factors (>= 1) on the IMU's preintegrated rotation covariance (gyro), velocity-position
covariance (accelerometer; the two are whitened apart) and on the accelerometer bias walk. They
are estimated from the residuals by variance component estimation (Forstner 1979: a group's
variance factor is its whitened residual square sum over its redundancy), re-solved until they
settle. Gauss-Newton; the covariance is the inverse of the whitened normal matrix.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray
from scipy import linalg, sparse

from amrvio.estimator.vi_init_linear import ViProblem, tangent_basis
from amrvio.types.lie import hat, so3_exp, so3_log

F64 = NDArray[np.float64]

MIN_ROTATION_VAR = (math.radians(0.001)) ** 2  # floors of the VO noise variances (rad^2, m^2 metric)
MIN_POSITION_VAR = (1e-5) ** 2


@dataclass(frozen=True, slots=True, eq=False)
class MapState:
    """A point of the MAP problem: scale, gravity (3,) m/s^2, body rotations (K, 3, 3), positions
    and velocities (K, 3) metric in the VO frame, gyro bias (3,), accelerometer biases (K, 3)."""

    scale: float
    gravity_vo: F64
    R_vo_body: F64
    p_vo: F64
    velocities_vo: F64
    gyro_bias: F64
    accel_bias: F64


@dataclass(frozen=True, slots=True)
class NoiseModel:
    """rotation_var (rad^2) and position_var (VO units^2) of a VO keyframe, per component, and the
    factors (>= 1) on the IMU's preintegrated rotation covariance (gyro), velocity-position
    covariance (accelerometer) and on the accelerometer bias walk's variance."""

    rotation_var: float
    position_var: float
    gyro_factor: float = 1.0
    accel_factor: float = 1.0
    walk_factor: float = 1.0


@dataclass(frozen=True, slots=True, eq=False)
class MapResult:
    """state; covariance (n, n) of [s, w, (theta_k, p_k, v_k, ba_k)..., b_g]; chi2_per_dof; noise:
    the settled variance components; iterations (Gauss-Newton, all rounds)."""

    state: MapState
    covariance: F64
    chi2_per_dof: float
    noise: NoiseModel
    iterations: int


@dataclass(frozen=True, slots=True, eq=False)
class BiasPriors:
    """Means and standard deviations (3,) of the bias priors (the accelerometer's on the first
    keyframe), and the accelerometer bias walk density (m/s^3/sqrt(Hz), the IMU's datasheet);
    ``scale``: (mean, std) of a prior on the scale from another sensor (wheel odometry), or None."""

    gyro_mean: F64
    gyro_std: F64
    accel_mean: F64
    accel_std: F64
    accel_walk: float
    scale: tuple[float, float] | None = None


BLOCK = 12
"""Unknowns per keyframe: theta (0:3), p (3:6), v (6:9), ba (9:12)."""


def index_gyro_bias(K: int) -> int:
    """Column of b_g in the unknowns (after s, w and the keyframe blocks)."""
    return 3 + BLOCK * K


def index_accel_bias(k: int) -> int:
    """Column of keyframe k's accelerometer bias."""
    return 3 + BLOCK * k + 9


def _imu_whiteners(problem: ViProblem, nm: NoiseModel) -> F64:
    """(M, 9, 9) block-diagonal: the rotation rows and the velocity-position rows are whitened
    apart (their cross-covariance dropped), each with its own factor."""
    out = np.zeros((len(problem.pre), 9, 9))
    for k, p in enumerate(problem.pre):
        C = np.asarray(p.covariance)
        out[k, 0:3, 0:3] = np.linalg.inv(np.linalg.cholesky(nm.gyro_factor * C[0:3, 0:3] + np.eye(3) * 1e-18))
        out[k, 3:9, 3:9] = np.linalg.inv(np.linalg.cholesky(nm.accel_factor * C[3:9, 3:9] + np.eye(6) * 1e-18))
    return out


def _linearise(problem: ViProblem, st: MapState) -> tuple[F64, F64, F64, F64, F64]:
    """Unwhitened residuals and Jacobians: VO rotation (K, 3) with Jacobian blocks implicit (I at
    theta_k), VO position (K, 3) and (K, 3, n), IMU (M, 9) and (M, 9, n)."""
    K = problem.n_keyframes
    n = 3 + BLOCK * K + 3
    ig = index_gyro_bias(K)
    s, g, R, P, V = st.scale, st.gravity_vo, st.R_vo_body, st.p_vo, st.velocities_vo
    G = float(np.linalg.norm(g))
    g_dir = g / G
    dg_dw = -G * hat(g_dir) @ tangent_basis(g_dir)
    r_rot = so3_log(np.einsum("nji,njk->nik", problem.R_vo_body, R))
    cam = P + np.einsum("nij,j->ni", R, problem.t_body_cam)
    r_pos = cam / s - problem.c_vo
    J_pos = np.zeros((K, 3, n))
    J_pos[:, :, 0] = -cam / (s * s)
    t_hat = hat(problem.t_body_cam)
    for k in range(K):
        c0 = 3 + BLOCK * k
        J_pos[k, :, c0:c0 + 3] = -R[k] @ t_hat / s
        J_pos[k, :, c0 + 3:c0 + 6] = np.eye(3) / s
    M = len(problem.pre)
    T = np.array([p.dt_s for p in problem.pre])
    T1 = T[:, None]
    dB = np.stack([p.d_bias for p in problem.pre])  # (M, 9, 6)
    db_g = st.gyro_bias - problem.pre[0].gyro_bias_rad_s
    db_a = st.accel_bias[:-1] - problem.pre[0].accel_bias_m_s2  # (M, 3): interval k at ba_k
    corr = dB[:, :, 0:3] @ db_g + np.einsum("mij,mj->mi", dB[:, :, 3:6], db_a)  # Forster eq. 44
    dR = np.einsum("mij,mjk->mik", np.stack([p.delta_R for p in problem.pre]), so3_exp(corr[:, 0:3]))
    dv = np.stack([p.delta_v for p in problem.pre]) + corr[:, 3:6]
    dp = np.stack([p.delta_p for p in problem.pre]) + corr[:, 6:9]
    Rt = np.transpose(R[:-1], (0, 2, 1))
    rel = Rt @ R[1:]
    a_v = np.einsum("mij,mj->mi", Rt, V[1:] - V[:-1] - g * T1)
    a_p = np.einsum("mij,mj->mi", Rt, P[1:] - P[:-1] - V[:-1] * T1 - 0.5 * g * T1 * T1)
    r_imu = np.concatenate([so3_log(np.einsum("mji,mjk->mik", dR, rel)), a_v - dv, a_p - dp], axis=1)
    J_imu = np.zeros((M, 9, n))
    T3 = T[:, None, None]
    eye = np.broadcast_to(np.eye(3), (M, 3, 3))
    idx = 3 + BLOCK * np.arange(M)  # keyframe k's block; keyframe k+1's from + BLOCK
    rows = np.arange(M)[:, None, None]

    def put(r0: int, col0: NDArray[np.int64], block: F64) -> None:
        """J_imu[k, r0:r0+3, col0[k]:col0[k]+3] = block[k] for every interval k."""
        J_imu[rows, np.arange(r0, r0 + 3)[None, :, None], col0[:, None, None] + np.arange(3)[None, None, :]] = block

    put(0, idx, -np.transpose(rel, (0, 2, 1)))
    put(0, idx + BLOCK, eye)
    put(3, idx, hat(a_v))
    put(3, idx + 6, -Rt)
    put(3, idx + BLOCK + 6, Rt)
    put(6, idx, hat(a_p))
    put(6, idx + 3, -Rt)
    put(6, idx + BLOCK + 3, Rt)
    put(6, idx + 6, -Rt * T3)
    put(3, idx + 9, -dB[:, 3:6, 3:6])
    put(6, idx + 9, -dB[:, 6:9, 3:6])
    J_imu[:, 3:6, 1:3] = -(Rt @ dg_dw) * T3
    J_imu[:, 6:9, 1:3] = -0.5 * (Rt @ dg_dw) * T3 * T3
    J_imu[:, :, ig:ig + 3] = -dB[:, :, 0:3]
    return r_rot, r_pos, J_pos, r_imu, J_imu


def _system(problem: ViProblem, st: MapState, nm: NoiseModel, W_imu: F64,
            pri: BiasPriors) -> tuple[F64, F64, list[slice]]:
    """Whitened residual (m,), Jacobian (m, n) and the row slices of the groups [VO rotation, VO
    position, IMU rotation, IMU velocity-position, accelerometer bias walk, priors]."""
    r_rot, r_pos, J_pos, r_imu, J_imu = _linearise(problem, st)
    K, n = problem.n_keyframes, J_pos.shape[2]
    M = r_imu.shape[0]
    J_rot = np.zeros((3 * K, n))
    for k in range(K):
        J_rot[3 * k:3 * k + 3, 3 + BLOCK * k:6 + BLOCK * k] = np.eye(3)
    a, b = 1.0 / math.sqrt(nm.rotation_var), 1.0 / math.sqrt(nm.position_var)
    ri = np.einsum("mij,mj->mi", W_imu, r_imu)
    Ji = np.einsum("mij,mjn->min", W_imu, J_imu)
    # bias walk: (ba_{k+1} - ba_k) / (sigma_w sqrt(T_k))
    T = np.array([p.dt_s for p in problem.pre])
    w = 1.0 / (math.sqrt(nm.walk_factor) * pri.accel_walk * np.sqrt(T))
    r_walk = ((st.accel_bias[1:] - st.accel_bias[:-1]) * w[:, None]).reshape(-1)
    J_walk = np.zeros((3 * M, n))
    for k in range(M):
        c0, c1 = index_accel_bias(k), index_accel_bias(k + 1)
        J_walk[3 * k:3 * k + 3, c0:c0 + 3] = -np.eye(3) * w[k]
        J_walk[3 * k:3 * k + 3, c1:c1 + 3] = np.eye(3) * w[k]
    ig, ia = index_gyro_bias(K), index_accel_bias(0)
    n_pri = 6 if pri.scale is None else 7
    Jp = np.zeros((n_pri, n))
    Jp[0:3, ig:ig + 3] = np.diag(1.0 / pri.gyro_std)
    Jp[3:6, ia:ia + 3] = np.diag(1.0 / pri.accel_std)
    rp = np.concatenate([(st.gyro_bias - pri.gyro_mean) / pri.gyro_std,
                         (st.accel_bias[0] - pri.accel_mean) / pri.accel_std])
    if pri.scale is not None:
        Jp[6, 0] = 1.0 / pri.scale[1]
        rp = np.append(rp, (st.scale - pri.scale[0]) / pri.scale[1])
    r = np.concatenate([a * r_rot.reshape(-1), b * r_pos.reshape(-1), ri[:, 0:3].reshape(-1),
                        ri[:, 3:9].reshape(-1), r_walk, rp])
    J = np.vstack([a * J_rot, b * J_pos.reshape(-1, n), Ji[:, 0:3].reshape(-1, n), Ji[:, 3:9].reshape(-1, n),
                   J_walk, Jp])
    edges = np.cumsum([0, 3 * K, 3 * K, 3 * M, 6 * M, 3 * M, n_pri])
    return r, J, [slice(int(edges[i]), int(edges[i + 1])) for i in range(6)]


def _step(st: MapState, dx: F64) -> MapState:
    K = st.velocities_vo.shape[0]
    G = float(np.linalg.norm(st.gravity_vo))
    g_dir = st.gravity_vo / G
    blocks = dx[3:3 + BLOCK * K].reshape(K, BLOCK)
    ig = index_gyro_bias(K)
    return MapState(
        scale=st.scale + float(dx[0]),
        gravity_vo=G * (so3_exp(tangent_basis(g_dir) @ dx[1:3]) @ g_dir),
        R_vo_body=np.einsum("nij,njk->nik", st.R_vo_body, so3_exp(blocks[:, 0:3])),
        p_vo=st.p_vo + blocks[:, 3:6],
        velocities_vo=st.velocities_vo + blocks[:, 6:9],
        gyro_bias=st.gyro_bias + dx[ig:ig + 3],
        accel_bias=st.accel_bias + blocks[:, 9:12],
    )


def _gauss_newton(problem: ViProblem, st: MapState, nm: NoiseModel, pri: BiasPriors,
                  max_iter: int) -> tuple[MapState, F64, F64, list[slice], int]:
    """Returns (state, whitened residual, whitened Jacobian at the state, groups, iterations)."""
    W_imu = _imu_whiteners(problem, nm)
    r, J, groups = _system(problem, st, nm, W_imu, pri)
    cost = float(r @ r)
    it = 0
    for _ in range(max_iter):
        it += 1
        dx = _normal_solve(J, r)
        step, accepted = 1.0, False
        while step > 1e-3:
            cand = _step(st, step * dx)
            r_c, J_c, _ = _system(problem, cand, nm, W_imu, pri)
            if float(r_c @ r_c) <= cost:
                accepted = True
                break
            step *= 0.5
        if not accepted:
            break  # no decrease along the Gauss-Newton direction: at the minimum to noise level
        gain = cost - float(r_c @ r_c)
        st, r, J, cost = cand, r_c, J_c, float(r_c @ r_c)
        if gain < 1e-10 * max(cost, 1.0):
            break
    return st, r, J, groups, it


def _normal_matrix(J: F64) -> F64:
    """J^T J through a sparse product (J is mostly zeros: each row touches two keyframes)."""
    Js = sparse.csr_matrix(J)
    return np.asarray((Js.T @ Js).toarray())


def _normal_solve(J: F64, r: F64) -> F64:
    """The Gauss-Newton step: argmin |J dx + r|, by the column-equilibrated normal equations."""
    N = _normal_matrix(J)
    d = np.sqrt(np.maximum(np.diag(N), 1e-300))
    Ns = N / np.outer(d, d)
    g = -(J.T @ r) / d
    try:
        y = linalg.cho_solve(linalg.cho_factor(Ns), g)
    except linalg.LinAlgError:  # singular: the minimum-norm step
        y = np.linalg.lstsq(Ns, g, rcond=None)[0]
    return np.asarray(y / d)


def covariance(J: F64) -> F64:
    """(J^T J)^-1 (pseudo-inverse when singular), column-equilibrated."""
    N = _normal_matrix(J)
    d = np.sqrt(np.maximum(np.diag(N), 1e-300))
    return np.asarray(np.linalg.pinv(N / np.outer(d, d), hermitian=True) / np.outer(d, d))


def _redundancies(J: F64, groups: list[slice]) -> list[float]:
    """Sum of (1 - leverage) over each group's rows: the group's share of the redundancy."""
    Ninv = covariance(J)
    h = np.sum((sparse.csr_matrix(J) @ Ninv) * J, axis=1)
    return [float(np.sum(1.0 - h[g])) for g in groups]


def refine_map(problem: ViProblem, start: MapState, pri: BiasPriors, noise: NoiseModel,
               rounds: int = 6, max_iter: int = 15) -> MapResult:
    """Gauss-Newton from ``start``; between rounds the variance components are re-estimated
    (module docstring), until every factor is within 10 % of 1."""
    nm = replace(noise, rotation_var=max(noise.rotation_var, MIN_ROTATION_VAR),
                 position_var=max(noise.position_var, MIN_POSITION_VAR / start.scale**2),
                 gyro_factor=max(noise.gyro_factor, 1.0), accel_factor=max(noise.accel_factor, 1.0),
                 walk_factor=max(noise.walk_factor, 1.0))
    st, total = start, 0
    settled = False
    for rnd in range(rounds + 1):
        st, r, J, groups, it = _gauss_newton(problem, st, nm, pri, max_iter)
        total += it
        if settled or rnd == rounds:
            break
        red = _redundancies(J, groups)
        f = [float(r[g] @ r[g]) / max(u, 1e-9) for g, u in zip(groups[:5], red[:5], strict=True)]
        f[1] = 1.0  # the VO position noise is given (vi_init_linear.vo_position_var), not re-estimated
        settled = all(abs(math.log(max(x, 1e-12))) < 0.1 for x in f)
        nm = NoiseModel(max(MIN_ROTATION_VAR, nm.rotation_var * f[0]), nm.position_var,
                        max(1.0, nm.gyro_factor * f[2]), max(1.0, nm.accel_factor * f[3]),
                        max(1.0, nm.walk_factor * f[4]))
    dof = max(r.shape[0] - J.shape[1], 1)
    chi2 = float(r @ r) / dof
    cov = covariance(J) * max(1.0, chi2)
    return MapResult(st, cov, chi2, nm, total)
