"""Wheel-radius calibration against the VIO (amrvio.estimator.wheel_calibration): straight
stretches, the factor as a ratio of distances, and what the run writes. Synthetic trajectories
and wheels with a known factor (closed form), then one simulated drive whose wheels read 2 % long."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from amrvio.app.run import run
from amrvio.errors import ConfigError
from amrvio.estimator.wheel_calibration import (
    WheelCalibrationConfig,
    WheelCalibrationStatus,
    calibrate_wheel,
    straight_stretches,
)
from amrvio.estimator.wheel_scale import WheelScaleConfig
from amrvio.sim.simulate import SimConfig, simulate
from amrvio.types.lie import SE3, SO3
from amrvio.types.sensors import WheelData

FPS, WHEEL_HZ = 20.0, 50.0


def _drive(speed: np.ndarray, yaw_rate: np.ndarray, t: np.ndarray) -> np.ndarray:
    """(N, 4, 4) body poses of a planar drive integrated at the fine times ``t``."""
    yaw = np.concatenate([[0.0], np.cumsum(0.5 * (yaw_rate[1:] + yaw_rate[:-1]) * np.diff(t))])
    v = speed[:, None] * np.stack([np.cos(yaw), np.sin(yaw)], axis=1)
    xy = np.concatenate([[[0.0, 0.0]], np.cumsum(0.5 * (v[1:] + v[:-1]) * np.diff(t)[:, None], axis=0)])
    return np.stack([SE3(SO3.exp([0.0, 0.0, a]), np.array([x, y, 0.0])).matrix()
                     for (x, y), a in zip(xy, yaw, strict=True)])


def _case(factor: float, noise: float = 0.0, seed: int = 0) -> tuple[np.ndarray, np.ndarray, WheelData]:
    """10 s: rest 1 s, 1 m/s for 3 s, stop 1 s, a 90 degree turn in place over 2 s, 0.5 m/s for
    3 s. The VIO's poses are the truth at 20 fps; the wheels at 50 Hz read ``factor`` times the
    speed and yaw rate, with white noise on the speed."""
    t = np.arange(0.0, 10.0 + 1e-9, 1e-3)
    speed = np.where((t >= 1) & (t < 4), 1.0, 0.0) + np.where(t >= 7, 0.5, 0.0)
    yaw_rate = np.where((t >= 5) & (t < 7), (math.pi / 2) / 2.0, 0.0)
    poses = _drive(speed, yaw_rate, t)
    frames = np.round(np.arange(0.0, 10.0 + 1e-9, 1 / FPS) * 1000).astype(int)
    stamps = (t[frames] * 1e9).astype(np.int64)
    wt = np.round(np.arange(0.0, 10.0 + 1e-9, 1 / WHEEL_HZ) * 1000).astype(int)
    rng = np.random.default_rng(seed)
    wheel = WheelData((t[wt] * 1e9).astype(np.int64), factor * speed[wt] + noise * rng.standard_normal(len(wt)),
                      factor * yaw_rate[wt])
    return stamps, poses[frames], wheel


def test_the_factor_is_the_wheels_distance_over_the_vios_on_the_straight_stretches() -> None:
    stamps, T, wheel = _case(1.03)
    cal = calibrate_wheel(stamps, T, 0, wheel)
    assert cal.status is WheelCalibrationStatus.OK
    assert cal.factor == pytest.approx(1.03, rel=1e-3)
    # the turn in place splits the drive: 3 m before it and 1.5 m after it
    assert len(cal.stretches) == 2
    assert [s.vio_m for s in cal.stretches] == pytest.approx([3.0, 1.5], rel=1e-3)
    assert cal.wheel_m == pytest.approx(1.03 * 4.5, rel=1e-3)
    assert "+3.00 %" in cal.advice() and "--wheel-factor 1.0300" in cal.advice()


def test_the_wheels_noise_at_a_standstill_does_not_lengthen_the_drive() -> None:
    """The speed's noise (5 cm/s) over the rests averages out in the signed integral; summed
    as a path length it would add about 4 cm per second of rest."""
    stamps, T, wheel = _case(1.0, noise=0.05)
    cal = calibrate_wheel(stamps, T, 0, wheel)
    assert cal.factor == pytest.approx(1.0, abs=0.003)


def test_the_displacement_nets_out_a_reversal_and_the_distance_does_not() -> None:
    t = np.arange(0, 2001, 10, dtype=np.int64) * 1_000_000  # 2 s at 100 Hz
    v = np.where(t < 1_000_000_000, 1.0, -1.0)
    w = WheelData(t, v, np.zeros_like(v))
    assert w.distance_m(0, int(t[-1])) == pytest.approx(2.0, abs=0.011)
    assert w.displacement_m(0, int(t[-1])) == pytest.approx(0.0, abs=0.011)
    assert w.displacement_m(0, 500_000_000) == pytest.approx(0.5)
    assert math.isnan(w.displacement_m(0, int(t[-1]) + 1))  # not covered


def test_a_factor_already_applied_is_part_of_the_reported_one() -> None:
    stamps, T, wheel = _case(1.03)
    cal = calibrate_wheel(stamps, T, 0, wheel.divided(1.01), applied=1.01)
    assert cal.factor == pytest.approx(1.03, rel=1e-3)
    assert wheel.divided(1.01).yaw_rate_rad_s == pytest.approx(wheel.yaw_rate_rad_s / 1.01)


def test_no_factor_without_enough_straight_driving_before_or_with_the_wheels_fused() -> None:
    stamps, T, wheel = _case(1.03)
    start = int(np.searchsorted(stamps, 7.2e9))  # the VIO started late: 1.4 m of driving left
    late = calibrate_wheel(stamps, T, start, wheel)
    assert late.status is WheelCalibrationStatus.TOO_LITTLE_STRAIGHT_DRIVING and math.isnan(late.factor)
    assert "too little" in late.advice()
    fused = calibrate_wheel(stamps, T, 0, wheel, wheels_used=True)
    assert fused.status is WheelCalibrationStatus.WHEELS_USED and "without --wheels" in fused.advice()
    T_gap = T.copy()
    T_gap[50] = np.nan  # a frame without a pose (at 2.5 s, mid-drive) ends a stretch
    stretches = straight_stretches(stamps, T_gap, 0, wheel, WheelCalibrationConfig())
    assert stretches[0].last == 49 and stretches[1].first == 51


def test_the_factor_setting_is_bounded() -> None:
    for bad in (0.4, 2.5, float("nan")):
        with pytest.raises(ConfigError, match="scale.wheel.factor"):
            WheelScaleConfig(factor=bad)


def test_a_simulated_drive_calibrates_its_wheels(tmp_path: Path) -> None:
    """Forward-stop-turn (4.5 s at 10 fps; the simulated wheels read 2 % long): the run without
    --wheels writes the factor (1.0235 on this drive: the VIO's scale over the 2.5 m of the
    drive is its error) into summary.json and advice.txt."""
    seq = tmp_path / "fst"
    simulate(SimConfig(motion="forward-stop-turn", seconds=4.5, width=376, height=240, fps=10.0, seed=3), seq)
    res = run(str(seq), out=tmp_path / "out", report=False)
    cal = json.loads((tmp_path / "out" / "summary.json").read_text())["wheel_calibration"]
    assert cal["status"] == "ok" and cal["applied"] == 1.0
    assert cal["factor"] == pytest.approx(1.02, abs=0.006)
    advice = (tmp_path / "out" / "advice.txt").read_text()
    assert f"--wheel-factor {cal['factor']:.4f}" in advice
    assert res.output.wheel_calibration is not None
