"""An IMU synthesised from ground-truth poses (amrvio.sim.imu_from_gt) against the closed form of a
body driving a circle, and the recording folder it writes."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from amrvio.errors import ConfigError, DatasetFormatError
from amrvio.sim.imu_from_gt import synthesize_imu_from_groundtruth, write_with_synthetic_imu
from amrvio.types.sensors import ImuNoise

R_M, OMEGA = 2.0, 0.5  # circle radius (m) and yaw rate (rad/s)


def _circle(n_s: float = 6.0, rate: float = 200.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Ground truth of a body on a circle, x along the path, z up: stamps_ns, positions, quats_wxyz."""
    t = np.arange(0.0, n_s, 1.0 / rate)
    p = np.stack([R_M * np.cos(OMEGA * t), R_M * np.sin(OMEGA * t), np.ones_like(t)], axis=1)
    yaw = OMEGA * t + np.pi / 2
    q = np.stack([np.cos(yaw / 2), np.zeros_like(t), np.zeros_like(t), np.sin(yaw / 2)], axis=1)
    return (1_000_000_000 + np.round(t * 1e9)).astype(np.int64), p, q


def test_exact_samples_match_the_closed_form() -> None:
    ns, p, q = _circle()
    syn = synthesize_imu_from_groundtruth(ns, p, q, None)
    imu = syn.imu
    # gyro = (0, 0, w); specific force in the body = (0, r w^2 towards the centre, g)
    assert np.allclose(imu.gyro_rad_s, [0.0, 0.0, OMEGA], atol=1e-4)
    assert np.allclose(imu.accel_m_s2, [0.0, R_M * OMEGA**2, 9.81], atol=2e-3)
    # the ends of the spline are left out: the samples lie inside the ground truth's span
    assert imu.stamps_ns[0] >= ns[0] + 400_000_000 and imu.stamps_ns[-1] <= ns[-1] - 400_000_000


def test_noise_follows_the_densities_and_is_reproducible() -> None:
    ns, p, q = _circle(20.0)
    noise = ImuNoise(1e-3, 1e-6, 1e-2, 1e-6, 200.0)
    a = synthesize_imu_from_groundtruth(ns, p, q, noise, seed=4)
    b = synthesize_imu_from_groundtruth(ns, p, q, noise, seed=4)
    assert np.array_equal(a.imu.accel_m_s2, b.imu.accel_m_s2)
    exact = synthesize_imu_from_groundtruth(ns, p, q, None)
    err = a.imu.accel_m_s2 - exact.imu.accel_m_s2 - a.accel_bias
    # discrete white noise: density * sqrt(rate)
    assert np.std(err) == pytest.approx(1e-2 * np.sqrt(200.0), rel=0.05)


def test_too_short_a_ground_truth_is_refused() -> None:
    ns, p, q = _circle(0.5)
    with pytest.raises(ConfigError, match="margin"):
        synthesize_imu_from_groundtruth(ns, p, q, None)


def test_recording_folder_with_the_synthetic_imu(tmp_path: Path) -> None:
    from amrvio.io.trajectory import write_tum
    from amrvio.types.trajectory import Trajectory

    src = tmp_path / "src"
    (src / "mav0" / "cam0" / "data").mkdir(parents=True)
    ns, p, q = _circle(3.0)
    gt = tmp_path / "gt.tum"
    write_tum(gt, Trajectory(ns * 1e-9, p, q), "# circle")
    out = tmp_path / "out"
    imu = write_with_synthetic_imu(src, gt, out, ImuNoise.euroc_adis16448(), seed=1)
    assert (out / "mav0" / "cam0").resolve() == (src / "mav0" / "cam0").resolve()
    text = (out / "mav0" / "imu0" / "data.csv").read_text(encoding="utf-8").splitlines()
    assert len(text) == len(imu) + 1
    assert (out / "mav0" / "state_groundtruth_estimate0" / "data.csv").is_file()
    with pytest.raises(DatasetFormatError, match="cam0"):
        write_with_synthetic_imu(tmp_path / "nothing", gt, tmp_path / "o2", ImuNoise.euroc_adis16448())
