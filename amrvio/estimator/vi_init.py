"""Dynamic visual-inertial initialisation from up-to-scale VO keyframes and the IMU.

:func:`initialize_vi` takes the keyframe poses ``T_vo_cam`` of a monocular VO (any scale, any
world frame) with their stamps, the IMU samples that cover them and ``T_body_cam``, and returns a
:class:`ViInitResult`. Steps and checks, in order (the first failed check is the status):

1. enough keyframes over enough time (TOO_FEW_KEYFRAMES); the IMU covers them without gaps
   (IMU_MISSING);
2. preintegration (amrvio.imu.preintegration) and the gyro bias from the rotations, then a second
   pass at that bias; VO and gyro rotations must agree (ROTATION_MISMATCH) and the bias be
   plausible (IMPLAUSIBLE_BIAS);
3. the excitation figures, BEFORE solving: enough acceleration change, and a VO camera that
   translates (INSUFFICIENT_EXCITATION);
4. scale, gravity and velocities by linear least squares (ILL_CONDITIONED, NEGATIVE_SCALE,
   BAD_GRAVITY_NORM);
5. gravity refined on its sphere, then the accelerometer bias with its prior
   (amrvio.estimator.vi_init_linear);
6. the VO's scale drift across the window (:func:`amrvio.estimator.vi_init_linear.scale_drift`):
   SCALE_DRIFT when the scale at the window's end differs from its start's by more than
   ``max_scale_drift``, by 3 of its standard deviations at least;
7. MAP refinement with bias priors and the marginal covariance (amrvio.estimator.vi_init_map):
   NEGATIVE_SCALE, IMPLAUSIBLE_BIAS, SCALE_UNCERTAIN when the scale's standard deviation is
   above ``max_scale_rel_std``, GRAVITY_UNCERTAIN when the gravity direction's is above
   ``max_gravity_std_deg``.

What is observable: the gyro bias from any rotation history; scale, gravity direction and
velocities only when the acceleration changes (not at rest or constant velocity); the
accelerometer bias only when the body also turns (without rotation it reads as a gravity tilt; the
prior holds it then, and the advice asks for a turn); yaw never (``R_world_vo`` sets it to 0).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

from amrvio.errors import ShapeError
from amrvio.estimator.vi_init_advice import advice, measure_excitation
from amrvio.estimator.vi_init_linear import (
    ViProblem,
    rotation_errors,
    rotation_range,
    scale_drift,
    solve_free_gravity,
    solve_gyro_bias,
    solve_inverse_scale,
    vo_position_var,
    whiteners,
)
from amrvio.estimator.vi_init_map import (
    MIN_POSITION_VAR,
    BiasPriors,
    MapResult,
    MapState,
    NoiseModel,
    index_accel_bias,
    index_gyro_bias,
    refine_map,
)
from amrvio.estimator.vi_init_types import (
    ViBiasPrior,
    ViExcitation,
    ViInitConfig,
    ViInitFigures,
    ViInitResult,
    ViInitState,
    ViInitStatus,
)
from amrvio.imu.preintegration import preintegrate_between
from amrvio.imu.static_init import StaticInitResult, gravity_aligned_rotation
from amrvio.types.lie import SE3
from amrvio.types.sensors import ImuData, ImuNoise

F64 = NDArray[np.float64]
I64 = NDArray[np.int64]

__all__ = ["ViBiasPrior", "ViExcitation", "ViInitConfig", "ViInitFigures", "ViInitResult", "ViInitState",
           "ViInitStatus", "bias_prior_from_static", "initialize_vi", "next_window_start"]

LINEAR_POSITION_SIGMA_M = 0.01
"""Keyframe position noise assumed by the first linear solve; later steps estimate it."""


def _ro(a: ArrayLike) -> F64:
    out = np.array(a, dtype=np.float64)
    out.setflags(write=False)
    return out


def _checked(stamps_ns: ArrayLike, T_vo_cam: ArrayLike) -> tuple[I64, F64]:
    st = np.asarray(stamps_ns)
    T = np.asarray(T_vo_cam, dtype=np.float64)
    if st.ndim != 1 or not np.issubdtype(st.dtype, np.integer):
        raise ShapeError(f"keyframe stamps_ns must be a (K,) integer array, got {st.dtype} {st.shape}")
    if T.shape != (st.shape[0], 4, 4):
        raise ShapeError(f"T_vo_cam must be ({st.shape[0]}, 4, 4) for {st.shape[0]} stamps, got {T.shape}")
    if not np.all(np.isfinite(T)):
        raise ShapeError("T_vo_cam contains non-finite values")
    if st.shape[0] > 1 and np.any(np.diff(st) <= 0):
        raise ShapeError("keyframe stamps_ns are not strictly increasing")
    R = T[:, :3, :3]
    if np.max(np.abs(np.einsum("nji,njk->nik", R, R) - np.eye(3)), initial=0.0) > 1e-6:
        raise ShapeError("T_vo_cam rotations are not orthonormal")
    return st.astype(np.int64), T


def _imu_gap(imu: ImuData, t0: int, t1: int) -> str:
    """Why ``imu`` cannot serve [t0, t1] ("" when it can): it starts late, ends early, or has a gap
    longer than 10 sample periods (and 20 ms) between the samples around the span."""
    if len(imu) < 2 or int(imu.stamps_ns[0]) > t0 or int(imu.stamps_ns[-1]) < t1:
        span = f"[{int(imu.stamps_ns[0])}, {int(imu.stamps_ns[-1])}] ns" if len(imu) else "nothing"
        return f"the IMU covers {span}, the keyframes [{t0}, {t1}] ns: give the IMU samples up to the last keyframe"
    lo = max(int(np.searchsorted(imu.stamps_ns, t0, side="right")) - 1, 0)
    hi = int(np.searchsorted(imu.stamps_ns, t1, side="left"))
    worst = int(np.diff(imu.stamps_ns[lo:hi + 1]).max())
    period = float(np.median(np.diff(imu.stamps_ns[: min(len(imu), 1000)])))
    if worst > max(10.0 * period, 2e7):
        return f"the IMU has a gap of {worst * 1e-9:.3f} s inside the keyframes' span"
    return ""


def _priors(cfg: ViInitConfig, prior: ViBiasPrior | None, noise: ImuNoise) -> BiasPriors:
    walk = max(noise.accel_random_walk, 1e-6)
    if prior is None:
        z = np.zeros(3)
        return BiasPriors(z, np.full(3, cfg.gyro_bias_sigma_rad_s), z, np.full(3, cfg.accel_bias_sigma_m_s2), walk)
    return BiasPriors(np.asarray(prior.gyro_bias_rad_s, dtype=np.float64),
                      np.maximum(np.asarray(prior.gyro_bias_std_rad_s, dtype=np.float64), 1e-6),
                      np.asarray(prior.accel_bias_m_s2, dtype=np.float64),
                      np.maximum(np.asarray(prior.accel_bias_std_m_s2, dtype=np.float64), 1e-6), walk)


def bias_prior_from_static(static: StaticInitResult, config: ViInitConfig | None = None) -> ViBiasPrior | None:
    """The bias prior a static initialisation gives (None unless it is OK): its gyro bias and std;
    for the accelerometer, the bias along gravity it measured (across gravity it sees none), with
    the config's per-axis sigma (the prior is per axis, so the measured axis is not tightened)."""
    cfg = ViInitConfig() if config is None else config
    if not static.ok or static.gyro_bias_rad_s is None or static.gyro_bias_std_rad_s is None:
        return None
    if static.gravity_body is None:
        return None
    up = -np.asarray(static.gravity_body, dtype=np.float64)
    return ViBiasPrior(np.asarray(static.gyro_bias_rad_s, dtype=np.float64),
                       np.asarray(static.gyro_bias_std_rad_s, dtype=np.float64),
                       up * static.accel_bias_up_m_s2, np.full(3, cfg.accel_bias_sigma_m_s2))


def _done(status: ViInitStatus, cfg: ViInitConfig, ex: ViExcitation | None, fig: ViInitFigures | None,
          state: ViInitState | None = None, detail: str = "") -> ViInitResult:
    return ViInitResult(status, advice(status, cfg, ex, fig, state, detail), ex, fig, state)


def initialize_vi(
    stamps_ns: ArrayLike,
    T_vo_cam: ArrayLike,
    imu: ImuData,
    T_body_cam: SE3,
    noise: ImuNoise,
    config: ViInitConfig | None = None,
    prior: ViBiasPrior | None = None,
    scale_prior: tuple[float, float] | None = None,
) -> ViInitResult:
    """Initialise from K keyframes: ``stamps_ns`` (K,) int, ``T_vo_cam`` (K, 4, 4) up-to-scale
    camera poses, ``imu`` covering [stamps_ns[0], stamps_ns[-1]], ``T_body_cam`` the camera pose in
    the IMU frame (metric), ``noise`` the IMU's densities. ``prior``: bias prior (for example from
    a static initialisation); without it, zero-mean priors of the config's sigmas.
    ``scale_prior``: (mean, std) of the scale from another sensor (wheel odometry), a prior of
    every solve from step 4 on: where the IMU cannot see the scale (constant velocity) it holds
    the scale, so that gravity, velocities and biases are solved at a metric one (the status
    still says what the IMU saw). Raises ShapeError for malformed arrays and a scale prior that
    is not two positive finite numbers; every estimation failure is a status (module docstring)."""
    cfg = ViInitConfig() if config is None else config
    S = ViInitStatus
    st, T = _checked(stamps_ns, T_vo_cam)
    if scale_prior is not None and not (len(scale_prior) == 2 and all(0.0 < float(v) < math.inf for v in scale_prior)):
        raise ShapeError(f"initialize_vi: scale_prior must be (mean, std), both positive and finite, got {scale_prior}")
    K = st.shape[0]
    duration = (int(st[-1]) - int(st[0])) * 1e-9 if K else 0.0
    if K < max(cfg.min_keyframes, 3) or duration < cfg.min_duration_s:
        return _done(S.TOO_FEW_KEYFRAMES, cfg, None, None, detail=(
            f"{K} keyframes over {duration:.2f} s; need at least {max(cfg.min_keyframes, 3)} over "
            f"{cfg.min_duration_s:g} s: keep the VO running longer before initialising"))
    gap = _imu_gap(imu, int(st[0]), int(st[-1]))
    if gap:
        return _done(S.IMU_MISSING, cfg, None, None, detail=gap)
    pri = dataclasses.replace(_priors(cfg, prior, noise), scale=scale_prior)
    R_vo_body = np.einsum("nij,jk->nik", T[:, :3, :3], T_body_cam.inverse().R)
    pre = preintegrate_between(imu, st, pri.gyro_mean, pri.accel_mean, None)
    problem = ViProblem(R_vo_body, T[:, :3, 3].copy(), np.asarray(T_body_cam.t, dtype=np.float64), pre)
    bg = solve_gyro_bias(problem)
    # a second pass re-integrates at that bias (with the covariance now), and refines it
    problem = dataclasses.replace(problem, pre=preintegrate_between(imu, st, bg, pri.accel_mean, None))
    bg = solve_gyro_bias(problem)
    problem = dataclasses.replace(problem, pre=preintegrate_between(imu, st, bg, pri.accel_mean, noise))
    rot_err = rotation_errors(problem, bg)
    fig = ViInitFigures(rotation_rms_deg=math.degrees(math.sqrt(float(np.mean(np.sum(rot_err**2, axis=1))))))
    ex = measure_excitation(imu, st, R_vo_body, T_body_cam.R, bg, pri.accel_mean, cfg.lowpass_s,
                            rotation_range(T[:, :3, :3]), T[:, :3, 3])
    if fig.rotation_rms_deg > cfg.gates.max_rotation_rms_deg:
        return _done(S.ROTATION_MISMATCH, cfg, ex, fig)
    if float(np.max(np.abs(bg))) > cfg.gates.max_gyro_bias_rad_s:
        return _done(S.IMPLAUSIBLE_BIAS, cfg, ex, fig, detail=(
            f"gyro bias {np.array2string(bg, precision=3)} rad/s beyond {cfg.gates.max_gyro_bias_rad_s:g}"))
    status = S.OK
    if ex.accel_std_m_s2 < cfg.gates.min_accel_std_m_s2 or ex.translation_snr < cfg.gates.min_translation_snr:
        status = S.INSUFFICIENT_EXCITATION
        if not cfg.solve_degenerate:
            return _done(status, cfg, ex, fig)
    return _solve(problem, cfg, pri, bg, rot_err, status, ex, fig, st)


def next_window_start(result: ViInitResult, n_keyframes: int) -> int:
    """Where the next attempt's window should start among this attempt's ``n_keyframes``: past
    the older half when the VO's scale drifted across the window (SCALE_DRIFT: growing the window
    cannot fix it, a newer one may not drift), else at the first (more keyframes may be what it
    lacked)."""
    return n_keyframes // 2 if result.status is ViInitStatus.SCALE_DRIFT else 0


def _solve(problem: ViProblem, cfg: ViInitConfig, pri: BiasPriors, bg: F64, rot_err: F64, status: ViInitStatus,
           ex: ViExcitation, fig: ViInitFigures, stamps_ns: I64) -> ViInitResult:
    """Steps 4 to 7 of the module docstring."""
    S = ViInitStatus
    imu_rot = float(np.mean([np.trace(p.covariance[0:3, 0:3]) / 3.0 for p in problem.pre]))
    imu_pos = float(np.mean([np.trace(p.covariance[6:9, 6:9]) / 3.0 for p in problem.pre]))
    # metric solve for a first scale and the keyframes' position noise, then the inverse-scale one
    sp = pri.scale
    first = solve_free_gravity(problem, bg, whiteners(problem, LINEAR_POSITION_SIGMA_M**2), sp)
    pos_var = max(MIN_POSITION_VAR, first.position_rms_m**2 - imu_pos)
    W = whiteners(problem, pos_var)
    lin = solve_inverse_scale(problem, bg, W, first.scale, first.gravity_vo, None, scale_prior=sp) \
        if first.scale > 0 else first
    G = cfg.gravity_m_s2
    g_norm = float(np.linalg.norm(lin.gravity_vo))
    fig = dataclasses.replace(fig, condition_number=lin.condition_number, gravity_norm_residual_m_s2=g_norm - G,
                              linear_scale=lin.scale)
    if status is S.OK and lin.condition_number > cfg.gates.max_condition_number:
        status = S.ILL_CONDITIONED
    if not 0.0 < lin.scale < math.inf:
        return _done(S.NEGATIVE_SCALE if status is S.OK else status, cfg, ex, fig)
    if status is S.OK and abs(g_norm - G) > cfg.gates.max_gravity_norm_error * G:
        status = S.BAD_GRAVITY_NORM
    if status is not S.OK and not cfg.solve_degenerate:
        return _done(status, cfg, ex, fig)

    sphere = solve_inverse_scale(problem, bg, W, lin.scale, lin.gravity_vo, G, scale_prior=sp)
    with_ba = solve_inverse_scale(problem, bg, W, sphere.scale, sphere.gravity_vo, G, (pri.accel_mean, pri.accel_std),
                                  scale_prior=sp)
    if not 0.0 < with_ba.scale < math.inf:
        return _done(S.NEGATIVE_SCALE if status is S.OK else status, cfg, ex, fig)
    drift, drift_std = scale_drift(problem, bg, W, (pri.accel_mean, pri.accel_std))
    fig = dataclasses.replace(fig, scale_drift=drift, scale_drift_std=drift_std)
    if status is S.OK and abs(drift) > cfg.gates.max_scale_drift and abs(drift) > 3.0 * drift_std:
        status = S.SCALE_DRIFT
        if not cfg.solve_degenerate:
            return _done(status, cfg, ex, fig)
    # VO rotation noise: a first guess (an interval's residual holds two keyframes' noise);
    # VO position noise: from three-keyframe residuals, kept
    noise0 = NoiseModel(rotation_var=max(0.0, float(np.mean(rot_err**2)) - imu_rot) / 2.0,
                        position_var=max(MIN_POSITION_VAR / with_ba.scale**2, vo_position_var(
                            problem, bg, with_ba.accel_bias, with_ba.scale, with_ba.gravity_vo)))
    start = MapState(with_ba.scale, with_ba.gravity_vo, problem.R_vo_body,
                     with_ba.scale * problem.c_vo + problem.lever_vo, with_ba.velocities_vo, bg,
                     np.tile(with_ba.accel_bias, (problem.n_keyframes, 1)))
    mp = refine_map(problem, start, pri, noise0)
    state = _state(mp, stamps_ns)
    fig = dataclasses.replace(fig, vo_position_sigma_m=math.sqrt(mp.noise.position_var) * mp.state.scale,
                              vo_rotation_sigma_deg=math.degrees(math.sqrt(mp.noise.rotation_var)),
                              accel_noise_factor=mp.noise.accel_factor, chi2_per_dof=mp.chi2_per_dof,
                              iterations=mp.iterations)
    g = cfg.gates
    if status is S.OK:
        if state.scale <= 0.0:
            status = S.NEGATIVE_SCALE
        elif float(np.max(np.abs(state.accel_bias_m_s2))) > g.max_accel_bias_m_s2:
            return _done(S.IMPLAUSIBLE_BIAS, cfg, ex, fig, state, detail=(
                f"accelerometer bias {np.array2string(state.accel_bias_m_s2, precision=3)} m/s^2 beyond "
                f"{g.max_accel_bias_m_s2:g}"))
        elif state.scale_std > g.max_scale_rel_std * state.scale:
            status = S.SCALE_UNCERTAIN
        elif state.gravity_std_deg > g.max_gravity_std_deg:
            status = S.GRAVITY_UNCERTAIN
    return _done(status, cfg, ex, fig, state)


def _state(mp: MapResult, stamps_ns: I64) -> ViInitState:
    s, cov = mp.state, mp.covariance
    K = s.velocities_vo.shape[0]
    ig, ia = index_gyro_bias(K), index_accel_bias(K - 1)
    sd = np.sqrt(np.maximum(np.diag(cov), 0.0))
    g_dir = s.gravity_vo / np.linalg.norm(s.gravity_vo)
    return ViInitState(
        scale=s.scale,
        scale_std=float(sd[0]),
        gravity_vo=_ro(s.gravity_vo),
        gravity_std_deg=math.degrees(math.sqrt(max(float(cov[1, 1] + cov[2, 2]), 0.0))),
        gyro_bias_rad_s=_ro(s.gyro_bias),
        gyro_bias_std_rad_s=_ro(sd[ig:ig + 3]),
        accel_bias_m_s2=_ro(s.accel_bias[-1]),
        accel_bias_std_m_s2=_ro(sd[ia:ia + 3]),
        velocities_vo=_ro(s.velocities_vo),
        R_world_vo=_ro(gravity_aligned_rotation(-g_dir)),
        stamps_ns=np.array(stamps_ns, copy=True),
    )
