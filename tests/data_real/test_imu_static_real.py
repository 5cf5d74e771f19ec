"""Standstill on EuRoC V1_01 (../shared/data): its first seconds are static, and its ground truth
carries the gyro bias (state_groundtruth_estimate0, columns b_w)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from amrvio.imu.static import StandstillStatus, detect_standstill, initial_standstill
from amrvio.io.base import read_imu_csv
from tests.skip_policy import skip_shared_missing

pytestmark = pytest.mark.real_data

EUROC = "euroc_V1_01_easy_first95"


def _mav(shared_data: Path) -> Path:
    mav = shared_data / EUROC / "mav0"
    if not mav.is_dir():
        skip_shared_missing(mav)
    return mav


def _gt_gyro_bias(mav: Path, t0_ns: int, t1_ns: int) -> np.ndarray:
    """Mean ground-truth gyro bias (b_w, columns 11-13) over [t0, t1]."""
    lines = (mav / "state_groundtruth_estimate0" / "data.csv").read_text().splitlines()
    rows = [ln.split(",") for ln in lines if ln.strip() and not ln.startswith("#")]
    t = np.array([int(r[0]) for r in rows], dtype=np.int64)  # ns: beyond float64 precision
    b_w = np.array([[float(v) for v in r[11:14]] for r in rows])
    sel = (t >= t0_ns) & (t <= t1_ns)
    assert sel.sum() >= 20  # the ground truth here is at 20 Hz
    return b_w[sel].mean(axis=0)


def test_first_second_is_still_and_gives_the_ground_truth_gyro_bias(shared_data: Path) -> None:
    mav = _mav(shared_data)
    imu = read_imu_csv(mav / "imu0" / "data.csv")
    res = initial_standstill(imu)
    assert res.status is StandstillStatus.STILL
    assert res.n_samples == 201
    assert res.gyro_bias_rad_s is not None
    t0 = int(imu.stamps_ns[0])
    truth = _gt_gyro_bias(mav, t0, t0 + 1_000_000_000)  # (-0.0022, 0.0215, 0.0770) rad/s
    # Measured 2e-3 rad/s at most per axis: the 1 s mean of a vibrating drone on its stand.
    np.testing.assert_allclose(res.gyro_bias_rad_s, truth, atol=3e-3)
    assert abs(np.linalg.norm(res.mean_specific_force_m_s2) - 9.81) < 0.1


def test_flight_is_not_still(shared_data: Path) -> None:
    mav = _mav(shared_data)
    imu = read_imu_csv(mav / "imu0" / "data.csv")
    t0 = int(imu.stamps_ns[0]) + 30_000_000_000  # 30 s in: flying
    res = detect_standstill(imu.window(t0, t0 + 1_000_000_000))
    assert not res.still and res.gyro_bias_rad_s is None
