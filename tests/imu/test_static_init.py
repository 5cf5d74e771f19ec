"""Static initialisation on synthetic still IMU windows: closed forms, the accelerometer bias that
reads as tilt, calibrated standard deviations, and windows that are not still."""

from __future__ import annotations

import math

import numpy as np
import pytest

from amrvio.imu.static import StandstillStatus
from amrvio.imu.static_init import (
    StaticInitConfig,
    StaticInitStatus,
    gravity_aligned_rotation,
    initial_static_init,
    static_init,
)
from amrvio.types.lie import so3_exp
from amrvio.types.sensors import ImuData, ImuNoise

NOISE = ImuNoise.euroc_adis16448()
G = 9.81


def _still(R_world_body: np.ndarray, seconds: float, bg: np.ndarray, ba: np.ndarray, seed: int | None,
           rate: float = 200.0) -> ImuData:
    n = int(seconds * rate) + 1
    t = 5_000_000_000 + np.round(np.arange(n) * 1e9 / rate).astype(np.int64)
    f = R_world_body.T @ np.array([0.0, 0.0, G])
    gyro = np.tile(bg, (n, 1))
    accel = np.tile(f + ba, (n, 1))
    if seed is not None:
        rng = np.random.default_rng(seed)
        sg, sa = NOISE.discrete_sigmas()
        gyro = gyro + sg * rng.standard_normal((n, 3))
        accel = accel + sa * rng.standard_normal((n, 3))
    return ImuData(t, gyro, accel)


def _angle_deg(a: np.ndarray, b: np.ndarray) -> float:
    return math.degrees(math.acos(float(np.clip(a @ b / np.linalg.norm(a) / np.linalg.norm(b), -1, 1))))


R_TILTED = so3_exp(np.array([0.3, -0.5, 1.2]))


def test_noise_free_window_gives_attitude_and_bias_exactly() -> None:
    bg = np.array([0.01, -0.02, 0.005])
    res = static_init(_still(R_TILTED, 2.0, bg, np.zeros(3), None))
    assert res.status is StaticInitStatus.OK
    assert res.gravity_body is not None and res.R_world_body is not None and res.gyro_bias_rad_s is not None
    np.testing.assert_allclose(res.gravity_body, R_TILTED.T @ np.array([0.0, 0.0, -1.0]), atol=1e-12)
    np.testing.assert_allclose(res.gyro_bias_rad_s, bg, atol=1e-15)
    # gravity-aligned: same gravity direction as the truth, and yaw-free
    np.testing.assert_allclose(res.R_world_body @ res.gravity_body, [0.0, 0.0, -1.0], atol=1e-12)
    assert res.accel_bias_up_m_s2 == pytest.approx(0.0, abs=1e-12)
    roll, pitch = res.roll_pitch_deg
    R_rp = gravity_aligned_rotation(-res.gravity_body)
    np.testing.assert_allclose(R_rp, res.R_world_body)
    cr, sr = math.cos(math.radians(roll)), math.sin(math.radians(roll))
    cp, sp = math.cos(math.radians(pitch)), math.sin(math.radians(pitch))
    np.testing.assert_allclose(R_rp, np.array([[cp, 0, sp], [0, 1, 0], [-sp, 0, cp]])
                               @ np.array([[1, 0, 0], [0, cr, -sr], [0, sr, cr]]), atol=1e-12)


def test_accel_bias_across_gravity_reads_as_tilt_and_along_gravity_as_bias() -> None:
    up_body = R_TILTED.T @ np.array([0.0, 0.0, 1.0])
    across = np.cross(up_body, [1.0, 0.0, 0.0])
    across = 0.05 * across / np.linalg.norm(across)
    res = static_init(_still(R_TILTED, 2.0, np.zeros(3), across + 0.03 * up_body, None))
    assert res.gravity_body is not None
    tilt = _angle_deg(res.gravity_body, -up_body)
    assert tilt == pytest.approx(math.degrees(math.atan2(0.05, G + 0.03)), rel=1e-9)  # unobservable part
    assert res.accel_bias_up_m_s2 == pytest.approx(math.hypot(G + 0.03, 0.05) - G, rel=1e-9)
    # the reported std includes the 0.05 m/s^2 prior, so it covers this tilt
    assert tilt < res.tilt_std_deg


def test_standard_deviations_match_the_spread_over_seeds() -> None:
    errs_g, errs_t, std_g, std_t = [], [], [], []
    bg = np.array([0.003, 0.001, -0.002])
    for seed in range(60):
        res = static_init(_still(R_TILTED, 2.0, bg, np.zeros(3), seed), StaticInitConfig(accel_bias_sigma_m_s2=0.0))
        assert res.gyro_bias_rad_s is not None and res.gyro_bias_std_rad_s is not None
        assert res.gravity_body is not None
        errs_g.append(res.gyro_bias_rad_s - bg)
        std_g.append(res.gyro_bias_std_rad_s)
        errs_t.append(_angle_deg(res.gravity_body, R_TILTED.T @ np.array([0.0, 0.0, -1.0])))
        std_t.append(res.tilt_std_deg)
    rms_g = np.sqrt(np.mean(np.square(errs_g), axis=0))
    np.testing.assert_allclose(np.mean(std_g, axis=0), rms_g, rtol=0.35)
    assert np.mean(std_t) == pytest.approx(np.sqrt(np.mean(np.square(errs_t))), rel=0.35)


def test_moving_window_is_not_still() -> None:
    imu = _still(R_TILTED, 2.0, np.zeros(3), np.zeros(3), 0)
    accel = np.array(imu.accel_m_s2)
    accel[len(imu) // 2:] += np.array([2.0, 0.0, 0.0])  # a push halfway
    res = static_init(ImuData(imu.stamps_ns, imu.gyro_rad_s, accel))
    assert res.status is StaticInitStatus.NOT_STILL
    assert res.standstill.status is StandstillStatus.GRAVITY_DIRECTION_MOVES
    assert res.gyro_bias_rad_s is None and res.R_world_body is None and math.isnan(res.tilt_std_deg)
    assert all(math.isnan(v) for v in res.roll_pitch_deg)


def test_initial_window_grows_until_motion() -> None:
    still = _still(R_TILTED, 10.0, np.zeros(3), np.zeros(3), 1)
    accel = np.array(still.accel_m_s2)
    t_rel = (still.stamps_ns - still.stamps_ns[0]) * 1e-9
    accel[t_rel > 3.2] += np.array([0.0, 3.0, 0.0])  # starts moving at 3.2 s
    res = initial_static_init(ImuData(still.stamps_ns, still.gyro_rad_s, accel),
                              StaticInitConfig(max_window_s=8.0), NOISE)
    assert res.status is StaticInitStatus.OK
    assert res.duration_s == pytest.approx(3.0, abs=1e-9)
    res_cap = initial_static_init(still, StaticInitConfig(max_window_s=2.0), NOISE)
    assert res_cap.duration_s == pytest.approx(2.0, abs=1e-9)


def test_too_short_and_empty_windows() -> None:
    imu = _still(R_TILTED, 0.004, np.zeros(3), np.zeros(3), None)
    assert len(imu) == 1
    res = static_init(imu)
    assert res.status is StaticInitStatus.NOT_STILL
    assert res.standstill.status is StandstillStatus.TOO_FEW_SAMPLES
    empty = ImuData(np.zeros(0, dtype=np.int64), np.zeros((0, 3)), np.zeros((0, 3)))
    assert initial_static_init(empty).status is StaticInitStatus.NOT_STILL
