"""Synthetic IMU: integration back to the ground truth (own RK4 and GTSAM), noise statistics."""

from __future__ import annotations

import gtsam
import numpy as np
import pytest

from amrvio.sim.imu_synth import GRAVITY_WORLD, ideal_imu, imu_times, synthesize_imu
from amrvio.sim.motion import MOTION_KINDS, BlurBurst, MotionLayout, make_motion
from amrvio.sim.replay import make_replay_motion
from amrvio.types.lie import hat, matrix_to_quat_wxyz
from amrvio.types.sensors import ImuNoise

CORRIDOR = MotionLayout(start_xy=(1.0, 0.0), free_length_m=35.0)


def _rk4_integrate(R0, v0, p0, gyro, accel, dt):
    """RK4 over steps of 2 dt using samples k, k+1 (midpoint), k+2 of the IMU stream.

    Independent of the library: R' = R hat(w), v' = R f + g, p' = v.
    Returns positions (M,3) at samples 0, 2, 4, ...
    """
    g = GRAVITY_WORLD
    R, v, p = R0.copy(), v0.copy(), p0.copy()
    out = [p.copy()]
    h = 2 * dt

    def f(R, v, w, a):
        return R @ hat(w), R @ a + g, v

    for k in range(0, gyro.shape[0] - 2, 2):
        w0, w1, w2 = gyro[k], gyro[k + 1], gyro[k + 2]
        a0, a1, a2 = accel[k], accel[k + 1], accel[k + 2]
        k1 = f(R, v, w0, a0)
        k2 = f(R + h / 2 * k1[0], v + h / 2 * k1[1], w1, a1)
        k2 = (k2[0], k2[1], v + h / 2 * k1[1])
        k3 = f(R + h / 2 * k2[0], v + h / 2 * k2[1], w1, a1)
        k3 = (k3[0], k3[1], v + h / 2 * k2[1])
        k4 = f(R + h * k3[0], v + h * k3[1], w2, a2)
        k4 = (k4[0], k4[1], v + h * k3[1])
        R = R + h / 6 * (k1[0] + 2 * k2[0] + 2 * k3[0] + k4[0])
        v_new = v + h / 6 * (k1[1] + 2 * k2[1] + 2 * k3[1] + k4[1])
        p = p + h / 6 * (k1[2] + 2 * k2[2] + 2 * k3[2] + k4[2])
        v = v_new
        U, _, Vt = np.linalg.svd(R)
        R = U @ Vt
        out.append(p.copy())
    return np.array(out)


def _replay_of(kind: str):
    """A replay motion splined through 20 Hz samples of an analytic motion (like EuRoC GT)."""
    src = make_motion(kind, 12.0, CORRIDOR, seed=5)
    t = np.arange(0.0, 12.0 + 1e-9, 0.05)
    s = src.states(t)
    ns = 10**18 + np.round(t * 1e9).astype(np.int64)
    return make_replay_motion(ns, s.p_world, matrix_to_quat_wxyz(s.R_world_body), 1.0, 10.0)


@pytest.mark.parametrize("kind", [*MOTION_KINDS, "replay"])
def test_noise_free_imu_integrates_to_ground_truth_after_10s(kind: str) -> None:
    if kind == "replay":
        m = _replay_of("handheld")
    else:
        m = make_motion(kind, 10.0, CORRIDOR, seed=5, blur_bursts=(BlurBurst(4.0, 0.5, 3.0),))
    syn = synthesize_imu(m, rate_hz=200.0, noise=None)
    s0 = m.states(np.array([0.0]))
    pos = _rk4_integrate(s0.R_world_body[0], s0.v_world[0], s0.p_world[0],
                         syn.imu.gyro_rad_s, syn.imu.accel_m_s2, 1.0 / 200.0)
    gt = m.states(syn.t_s[::2]).p_world
    err = np.linalg.norm(pos - gt[: len(pos)], axis=1)
    assert syn.t_s[-1] == pytest.approx(10.0)
    assert err.max() < 0.01, f"{kind}: max position error {err.max():.4f} m after 10 s"


@pytest.mark.parametrize("kind", ["forward-stop-turn", "handheld", "rough-floor"])
def test_gtsam_preintegration_predicts_ground_truth(kind: str) -> None:
    m = make_motion(kind, 4.0, CORRIDOR, seed=7)
    rate = 1000.0  # GTSAM holds each reading constant over dt (first order): use a dense stream
    syn = synthesize_imu(m, rate_hz=rate, noise=None)
    i0, i1 = int(1.0 * rate), int(3.0 * rate)  # predict 1 s -> 3 s
    params = gtsam.PreintegrationParams.MakeSharedU(9.81)
    params.setAccelerometerCovariance(np.eye(3) * 1e-6)
    params.setGyroscopeCovariance(np.eye(3) * 1e-8)
    params.setIntegrationCovariance(np.eye(3) * 1e-8)
    pim = gtsam.PreintegratedImuMeasurements(params, gtsam.imuBias.ConstantBias())
    for k in range(i0, i1):
        # midpoint readings make GTSAM's piecewise-constant integration second-order
        a = 0.5 * (syn.imu.accel_m_s2[k] + syn.imu.accel_m_s2[k + 1])
        w = 0.5 * (syn.imu.gyro_rad_s[k] + syn.imu.gyro_rad_s[k + 1])
        pim.integrateMeasurement(a, w, 1.0 / rate)
    s = m.states(syn.t_s[[i0, i1]])
    state0 = gtsam.NavState(gtsam.Rot3(s.R_world_body[0]), s.p_world[0], s.v_world[0])
    pred = pim.predict(state0, gtsam.imuBias.ConstantBias())
    assert np.linalg.norm(pred.position() - s.p_world[1]) < 0.01
    assert np.linalg.norm(pred.velocity() - s.v_world[1]) < 0.01
    dR = pred.attitude().matrix().T @ s.R_world_body[1]
    assert np.degrees(np.arccos(np.clip((np.trace(dR) - 1) / 2, -1, 1))) < 0.05


def test_static_imu_reads_gravity_reaction() -> None:
    m = make_motion("forward-stop-turn", 2.0, CORRIDOR)
    g, a = ideal_imu(m.states(np.array([0.1])))  # at rest, level
    np.testing.assert_allclose(g[0], 0.0, atol=1e-15)
    np.testing.assert_allclose(a[0], [0.0, 0.0, 9.81], atol=1e-12)


def test_noise_statistics_and_bias_walk() -> None:
    m = make_motion("constant-velocity", 100.0, CORRIDOR)
    noise = ImuNoise.euroc_adis16448()
    syn = synthesize_imu(m, 200.0, noise, np.random.default_rng(0),
                         initial_gyro_bias=(0.01, -0.02, 0.03), initial_accel_bias=(0.1, 0, -0.1))
    g_ideal, a_ideal = ideal_imu(m.states(syn.t_s))
    white_g = syn.imu.gyro_rad_s - g_ideal - syn.gyro_bias
    white_a = syn.imu.accel_m_s2 - a_ideal - syn.accel_bias
    sg, sa = noise.discrete_sigmas()
    np.testing.assert_allclose(white_g.std(axis=0), sg, rtol=0.03)
    np.testing.assert_allclose(white_a.std(axis=0), sa, rtol=0.03)
    np.testing.assert_allclose(syn.gyro_bias[0], [0.01, -0.02, 0.03])
    # bias increments: sigma = random_walk * sqrt(dt)
    dbg = np.diff(syn.gyro_bias, axis=0)
    np.testing.assert_allclose(dbg.std(axis=0), noise.gyro_random_walk * np.sqrt(1 / 200), rtol=0.03)
    dba = np.diff(syn.accel_bias, axis=0)
    np.testing.assert_allclose(dba.std(axis=0), noise.accel_random_walk * np.sqrt(1 / 200), rtol=0.03)


def test_same_seed_same_imu_and_stamps() -> None:
    m = make_motion("handheld", 3.0, CORRIDOR, seed=1)
    noise = ImuNoise.euroc_adis16448()
    a = synthesize_imu(m, 200.0, noise, np.random.default_rng(42), start_ns=10**9)
    b = synthesize_imu(m, 200.0, noise, np.random.default_rng(42), start_ns=10**9)
    np.testing.assert_array_equal(a.imu.gyro_rad_s, b.imu.gyro_rad_s)
    np.testing.assert_array_equal(a.imu.accel_m_s2, b.imu.accel_m_s2)
    assert a.imu.stamps_ns[0] == 10**9 and a.imu.stamps_ns[1] - a.imu.stamps_ns[0] == 5_000_000
    assert len(a.imu) == 601


def test_imu_times_exact_ns() -> None:
    offs, t = imu_times(1.0, 300.0)
    assert offs.dtype == np.int64 and len(offs) == 301 and offs[-1] == 10**9
    np.testing.assert_array_equal(t, offs * 1e-9)
