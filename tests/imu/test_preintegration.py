"""Preintegration against gtsam (an independent implementation), finite differences for the bias
Jacobians, the exact kinematics of a synthetic motion, and bad input."""

from __future__ import annotations

import gtsam
import numpy as np
import pytest

from amrvio.errors import ShapeError
from amrvio.imu.preintegration import preintegrate, preintegrate_between
from amrvio.sim.imu_synth import GRAVITY_WORLD, synthesize_imu
from amrvio.sim.motion import MotionLayout, make_motion
from amrvio.types.lie import so3_log
from amrvio.types.sensors import ImuData, ImuNoise

NOISE = ImuNoise.euroc_adis16448()


def _random_imu(n: int = 41, seed: int = 3) -> ImuData:
    rng = np.random.default_rng(seed)
    t = 10_000_000_000 + 5_000_000 * np.arange(n, dtype=np.int64)
    gyro = 0.8 * rng.standard_normal((n, 3))
    accel = np.array([0.5, -0.3, 9.81]) + 2.0 * rng.standard_normal((n, 3))
    return ImuData(t, gyro, accel)


def test_deltas_and_covariance_match_gtsam_on_the_same_steps() -> None:
    imu = _random_imu()
    bg, ba = np.array([0.01, -0.02, 0.03]), np.array([0.1, 0.05, -0.08])
    pre = preintegrate(imu, int(imu.stamps_ns[0]), int(imu.stamps_ns[-1]), bg, ba, NOISE)
    params = gtsam.PreintegrationParams.MakeSharedU(9.81)
    params.setGyroscopeCovariance(np.eye(3) * NOISE.gyro_noise_density**2)
    params.setAccelerometerCovariance(np.eye(3) * NOISE.accel_noise_density**2)
    params.setIntegrationCovariance(np.zeros((3, 3)))
    pim = gtsam.PreintegratedImuMeasurements(params, gtsam.imuBias.ConstantBias(ba, bg))
    # our step: the mean of two samples, held over the step; gtsam integrates the same held
    # measurement in SUB sub-steps (its zero-order hold then converges to the exact integral)
    g_mid = 0.5 * (imu.gyro_rad_s[1:] + imu.gyro_rad_s[:-1])
    a_mid = 0.5 * (imu.accel_m_s2[1:] + imu.accel_m_s2[:-1])
    sub = 50
    for w, a in zip(g_mid, a_mid, strict=True):
        for _ in range(sub):
            pim.integrateMeasurement(a, w, 0.005 / sub)
    assert pre.dt_s == pytest.approx(pim.deltaTij(), abs=1e-12)
    assert np.linalg.norm(so3_log(pre.delta_R.T @ pim.deltaRij().matrix())) < 1e-7
    # gtsam's sub-step error w |f| (dt / SUB) T / 2 ~ 1e-4 m/s dominates
    np.testing.assert_allclose(pre.delta_v, pim.deltaVij(), atol=2e-4)
    np.testing.assert_allclose(pre.delta_p, pim.deltaPij(), atol=2e-5)
    # gtsam orders [rot, pos, vel]; ours [rot, vel, pos]
    perm = [0, 1, 2, 6, 7, 8, 3, 4, 5]
    ref = pim.preintMeasCov()[np.ix_(perm, perm)]
    # variances to 0.1 %; correlations to 0.01 (the two differ at second order in the step)
    np.testing.assert_allclose(np.diag(pre.covariance), np.diag(ref), rtol=1e-3)
    d = np.sqrt(np.diag(ref))
    np.testing.assert_allclose(pre.covariance / np.outer(d, d), ref / np.outer(d, d), atol=1e-2)
    assert np.all(np.linalg.eigvalsh(pre.covariance) > 0)


def test_bias_jacobians_match_reintegration() -> None:
    imu = _random_imu(61, seed=5)
    t0, t1 = int(imu.stamps_ns[0]), int(imu.stamps_ns[-1])
    base = preintegrate(imu, t0, t1)
    for k in range(6):
        db = np.zeros(6)
        db[k] = 1e-3
        again = preintegrate(imu, t0, t1, db[:3], db[3:])
        R1, v1, p1 = base.corrected(db[:3], db[3:])
        err_first = np.concatenate([so3_log(R1.T @ again.delta_R), v1 - again.delta_v, p1 - again.delta_p])
        err_zero = np.concatenate([so3_log(base.delta_R.T @ again.delta_R), base.delta_v - again.delta_v,
                                   base.delta_p - again.delta_p])
        # first-order correction: residual O(db^2), far below the uncorrected change O(db)
        assert np.linalg.norm(err_first) < 1e-3 * np.linalg.norm(err_zero) + 1e-9


def test_exact_imu_of_a_synthetic_motion_gives_its_kinematics() -> None:
    motion = make_motion("handheld", 4.0, MotionLayout(free_length_m=10.0), seed=1)
    syn = synthesize_imu(motion, 1000.0)
    stamps = syn.imu.stamps_ns[::100]  # 10 Hz keyframes
    pres = preintegrate_between(syn.imu, stamps)
    st = motion.states(syn.t_s[::100])
    g = GRAVITY_WORLD
    for k, pre in enumerate(pres):
        R0, R1 = st.R_world_body[k], st.R_world_body[k + 1]
        T = pre.dt_s
        assert np.linalg.norm(so3_log(pre.delta_R.T @ R0.T @ R1)) < 1e-5
        dv_true = R0.T @ (st.v_world[k + 1] - st.v_world[k] - g * T)
        dp_true = R0.T @ (st.p_world[k + 1] - st.p_world[k] - st.v_world[k] * T - 0.5 * g * T * T)
        np.testing.assert_allclose(pre.delta_v, dv_true, atol=2e-5)  # measured 6e-6
        np.testing.assert_allclose(pre.delta_p, dp_true, atol=2e-6)  # measured 6e-7


def test_interval_between_samples_is_interpolated() -> None:
    n = 11
    t = 1_000_000_000 + 10_000_000 * np.arange(n, dtype=np.int64)
    accel = np.zeros((n, 3))
    accel[:, 0] = np.arange(n, dtype=np.float64)  # a ramp: a(t) = 100 t (t in s from the first sample)
    imu = ImuData(t, np.zeros((n, 3)), accel)
    pre = preintegrate(imu, int(t[0]) + 2_500_000, int(t[-1]) - 7_500_000)
    # integral of 100 t over [0.0025, 0.0925] s (the midpoint rule is exact for a ramp)
    assert pre.delta_v[0] == pytest.approx(50.0 * (0.0925**2 - 0.0025**2), rel=1e-12)
    assert pre.dt_s == pytest.approx(0.09, abs=1e-12)


def test_bad_intervals_raise() -> None:
    imu = _random_imu()
    with pytest.raises(ShapeError, match="cover"):
        preintegrate(imu, int(imu.stamps_ns[0]) - 1, int(imu.stamps_ns[-1]))
    with pytest.raises(ShapeError, match="t1 > t0"):
        preintegrate(imu, int(imu.stamps_ns[5]), int(imu.stamps_ns[5]))
    empty = ImuData(np.zeros(0, dtype=np.int64), np.zeros((0, 3)), np.zeros((0, 3)))
    with pytest.raises(ShapeError, match="cover"):
        preintegrate(empty, 0, 1)
