"""Standstill detection against the simulator's IMU, whose true biases and motion are known."""

from __future__ import annotations

import numpy as np
import pytest

from amrvio.imu.static import (
    StandstillConfig,
    StandstillStatus,
    detect_standstill,
    initial_standstill,
)
from amrvio.sim.imu_synth import synthesize_imu
from amrvio.sim.kinematics import EulerMotion, Polynomial, euler_zyx_matrix
from amrvio.types.sensors import ImuData, ImuNoise

G = 9.81
RATE_HZ = 200.0
# EuRoC's ADIS16448 noise (sensor.yaml), a realistic MEMS IMU.
NOISE = ImuNoise(1.6968e-4, 1.9393e-5, 2.0e-3, 3.0e-3, RATE_HZ)
GYRO_BIAS = np.array([-0.0023, 0.0215, 0.0770])
ACCEL_BIAS = np.array([-0.018, 0.066, 0.031])


ZERO = Polynomial()
PITCHED = Polynomial(0.05)


def _motion(
    x: Polynomial = ZERO, yaw: Polynomial = ZERO, roll: Polynomial = ZERO,
    pitch: Polynomial = PITCHED, duration: float = 1.0,
) -> EulerMotion:
    """Body at the origin, pitched 0.05 rad unless told; ``x``, yaw and roll as given."""
    return EulerMotion("test", x, ZERO, ZERO, yaw, pitch, roll, duration)


def _imu(
    motion: EulerMotion, seed: int = 3, noise: ImuNoise | None = NOISE
) -> tuple[ImuData, np.ndarray]:
    syn = synthesize_imu(motion, RATE_HZ, noise, np.random.default_rng(seed), start_ns=10**18,
                         initial_gyro_bias=GYRO_BIAS, initial_accel_bias=ACCEL_BIAS)
    return syn.imu, syn.gyro_bias


def test_still_window_gives_the_true_gyro_bias_and_gravity() -> None:
    imu, true_bg = _imu(_motion())
    res = detect_standstill(imu)
    assert res.status is StandstillStatus.STILL and res.still
    assert res.n_samples == len(imu) == 201
    assert res.gyro_bias_rad_s is not None
    # Mean of 201 samples: white noise sigma_d / sqrt(N) = 1.7e-4 rad/s per axis, plus a bias
    # walk of 1.9e-5 rad/s over 1 s. 5 sigma:
    np.testing.assert_allclose(res.gyro_bias_rad_s, true_bg.mean(axis=0), atol=5 * 1.7e-4)
    np.testing.assert_allclose(res.gyro_bias_rad_s, GYRO_BIAS, atol=5 * 1.7e-4 + 1e-4)
    # Specific force at rest: R_world_body^T (0, 0, g) + b_a.
    R = euler_zyx_matrix(np.zeros(1), np.full(1, 0.05), np.zeros(1))[0]
    expected_f = R.T @ np.array([0.0, 0.0, G]) + ACCEL_BIAS
    np.testing.assert_allclose(res.mean_specific_force_m_s2, expected_f, atol=5 * 2e-3 + 3e-3)
    assert res.gravity_tilt_deg < 0.1


def test_noise_free_still_window_is_exact() -> None:
    imu, _ = _imu(_motion(), noise=None)
    res = detect_standstill(imu)
    assert res.still and res.gyro_bias_rad_s is not None
    np.testing.assert_allclose(res.gyro_bias_rad_s, GYRO_BIAS, atol=1e-12)
    assert res.gravity_tilt_deg == pytest.approx(0.0, abs=1e-5)


def test_yaw_at_constant_rate_about_gravity_is_rotating() -> None:
    # Gravity direction and |f| stay exact (vertical yaw axis, no pitch); only the rate shows it.
    imu, _ = _imu(_motion(yaw=Polynomial(0.0, 0.3), pitch=ZERO), noise=None)
    res = detect_standstill(imu)
    assert res.status is StandstillStatus.ROTATING and not res.still
    assert res.gyro_bias_rad_s is None
    np.testing.assert_allclose(res.mean_gyro_rad_s, GYRO_BIAS + [0.0, 0.0, 0.3], atol=1e-12)


def test_slow_roll_moves_the_gravity_direction() -> None:
    # Roll grows by 0.1 rad/s: the half-window means differ by ~0.05 rad = 2.9 deg > 1 deg.
    imu, _ = _imu(_motion(roll=Polynomial(0.0, 0.1)))
    res = detect_standstill(imu)
    assert res.status is StandstillStatus.GRAVITY_DIRECTION_MOVES
    assert res.gravity_tilt_deg == pytest.approx(np.degrees(0.05), abs=0.2)
    assert res.gyro_bias_rad_s is None


def test_steady_acceleration_is_not_gravity() -> None:
    # a = 3 m/s^2 along x: |f| = sqrt(g^2 + 9) = 10.26 m/s^2, 0.45 from g, direction steady.
    imu, _ = _imu(_motion(x=Polynomial(0.0, 0.0, 1.5), pitch=ZERO))
    res = detect_standstill(imu)
    assert res.status is StandstillStatus.SPECIFIC_FORCE_NOT_GRAVITY
    # Body axes = world axes: f = (3, 0, g) + b_a; 5 sigma of the 201-sample mean noise.
    expected_f = np.array([3.0, 0.0, G]) + ACCEL_BIAS
    np.testing.assert_allclose(res.mean_specific_force_m_s2, expected_f, atol=5 * 2e-3 + 3e-3)


def test_thresholds_come_from_the_config() -> None:
    imu, _ = _imu(_motion(x=Polynomial(0.0, 0.0, 1.5), pitch=ZERO))
    loose = StandstillConfig(max_gravity_error_m_s2=0.6)
    assert detect_standstill(imu, loose).still


def test_too_few_samples_and_empty_window() -> None:
    imu, _ = _imu(_motion())
    one = imu.window(int(imu.stamps_ns[0]), int(imu.stamps_ns[0]))
    assert len(one) == 1
    for window in (one, imu.window(0, 1)):
        res = detect_standstill(window)
        assert res.status is StandstillStatus.TOO_FEW_SAMPLES and res.gyro_bias_rad_s is None
        assert np.all(np.isnan(res.mean_gyro_rad_s)) and np.isnan(res.gravity_tilt_deg)


def test_initial_standstill_uses_the_first_second_only() -> None:
    # Still for 1 s, then a yaw ramp: a still start with motion later is still.
    n = int(3 * RATE_HZ) + 1
    still, _ = _imu(_motion(duration=3.0))
    turning, _ = _imu(_motion(yaw=Polynomial(0.0, 0.5), duration=3.0))
    t = still.stamps_ns
    moving_after = t >= t[0] + 1_100_000_000
    gyro = np.where(moving_after[:, None], turning.gyro_rad_s, still.gyro_rad_s)
    imu = ImuData(t, gyro, still.accel_m_s2)
    assert len(imu) == n
    res = initial_standstill(imu)
    assert res.still and res.n_samples == 201  # [t0, t0 + 1 s], both ends included
    assert not detect_standstill(imu).still


def test_initial_standstill_needs_min_stream_samples() -> None:
    imu, _ = _imu(_motion())
    assert initial_standstill(imu.window(0, int(imu.stamps_ns[49]))).status is (
        StandstillStatus.TOO_FEW_SAMPLES
    )
    assert initial_standstill(imu.window(0, int(imu.stamps_ns[50]))).still


def _old_cmd_diagnose_rule(imu: ImuData) -> np.ndarray | None:
    """The inline rule amrvio diagnose had before amrvio.imu.static (kept to pin behaviour)."""
    if len(imu) <= 50:
        return None
    first = imu.window(int(imu.stamps_ns[0]), int(imu.stamps_ns[0]) + 1_000_000_000)
    g, a = np.asarray(first.gyro_rad_s), np.asarray(first.accel_m_s2)
    h = a.shape[0] // 2
    d0, d1 = a[:h].mean(axis=0), a[h:].mean(axis=0)
    cosang = float(d0 @ d1 / (np.linalg.norm(d0) * np.linalg.norm(d1)))
    if (cosang > np.cos(np.radians(1.0)) and abs(np.linalg.norm(a.mean(axis=0)) - 9.81) < 0.3
            and np.linalg.norm(g.mean(axis=0)) < 0.15):
        return g.mean(axis=0)
    return None


@pytest.mark.parametrize("seed", range(8))
def test_same_verdict_and_bias_as_the_old_diagnose_rule(seed: int) -> None:
    rng = np.random.default_rng(seed)
    # Near the thresholds: small roll rates, accelerations and yaw rates chosen at random.
    motion = _motion(x=Polynomial(0.0, 0.0, rng.uniform(0.0, 2.0)),
                     yaw=Polynomial(0.0, rng.uniform(0.0, 0.3)),
                     roll=Polynomial(0.0, rng.uniform(0.0, 0.06)))
    imu, _ = _imu(motion, seed=seed)
    old = _old_cmd_diagnose_rule(imu)
    new = initial_standstill(imu).gyro_bias_rad_s
    assert (old is None) == (new is None)
    if old is not None and new is not None:
        assert np.array_equal(old, new)
