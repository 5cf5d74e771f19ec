"""The VIO back-end with a real IMU: EuRoC V1_01 (../shared/data), whose recorded ADIS16448 stream
and IMU-consistent ground truth (vicon2gt: pose, velocity, biases) cover the whole 145 s flight.
Its images are static, so the landmark observations are synthetic: random points on the walls of
a box around the flown path, projected with the ground-truth camera poses (cam0 extrinsics of the
sequence) plus 0.5 px noise."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from amrvio.estimator.vio_backend import VioBackend
from amrvio.estimator.vio_types import VioConfig, VioInitialState, VisualObservations
from amrvio.geometry.align import umeyama
from amrvio.imu.propagation import (
    ImuBias,
    ImuBuffer,
    InertialState,
    Preintegrator,
    preintegration_params,
    world_position_velocity_sigma,
)
from amrvio.io.base import read_imu_csv
from amrvio.io.calib import read_euroc_imu, read_euroc_sensor_T_BS
from amrvio.io.trajectory import EurocGroundTruth, read_euroc_csv
from amrvio.sim.vio_scenario import K_EUROC, box_points, observe_points
from amrvio.types.lie import SE3
from amrvio.types.sensors import ImuData, ImuNoise
from tests.skip_policy import skip_shared_missing

pytestmark = pytest.mark.real_data

SEQ = "euroc_V1_01_easy_first95"


class Flight:
    def __init__(self, mav: Path) -> None:
        self.gt: EurocGroundTruth = read_euroc_csv(mav / "state_groundtruth_estimate0" / "data.csv")
        self.imu: ImuData = read_imu_csv(mav / "imu0" / "data.csv")
        self.noise: ImuNoise = read_euroc_imu(mav / "imu0" / "sensor.yaml")
        self.T_body_cam: SE3 = read_euroc_sensor_T_BS(mav / "cam0" / "sensor.yaml")

    def state(self, i: int) -> InertialState:
        gt = self.gt
        if gt.velocities_m_s is None or gt.gyro_bias is None or gt.accel_bias is None:
            raise AssertionError("the V1_01 ground truth carries velocities and biases")
        T = SE3.from_quat_wxyz(gt.trajectory.quats_wxyz[i], gt.trajectory.positions_m[i])
        return InertialState(int(gt.stamps_ns[i]), T, gt.velocities_m_s[i], ImuBias(gt.gyro_bias[i], gt.accel_bias[i]))


@pytest.fixture(scope="module")
def flight(shared_data: Path) -> Flight:
    mav = shared_data / SEQ / "mav0"
    for part in ("state_groundtruth_estimate0/data.csv", "imu0/data.csv", "imu0/sensor.yaml", "cam0/sensor.yaml"):
        if not (mav / part).is_file():
            skip_shared_missing(mav / part)
    return Flight(mav)


def _z_scores(flight: Flight, scale: float, horizon_s: float) -> tuple[np.ndarray, np.ndarray]:
    """IMU-only propagation from the ground-truth state over ``horizon_s``, every 23rd ground-truth
    stamp from 20 s on: (N, 6) errors / predicted sigmas (position, velocity) and (N,) position
    errors (m)."""
    buf = ImuBuffer()
    buf.add(flight.imu)
    pre = Preintegrator(preintegration_params(VioConfig(imu=flight.noise, imu_noise_scale=scale).imu_model()), buf)
    step = int(round(horizon_s / 0.05))
    z, err = [], []
    for i in range(400, len(flight.gt.stamps_ns) - step, 23):
        s0, s1 = flight.state(i), flight.state(i + step)
        pre.reset(s0.t_ns, s0.bias)
        assert pre.advance(s1.t_ns).ok
        p, P = pre.predict(s0)
        ps, vs = world_position_velocity_sigma(p, P)
        e = p.T_world_body.t - s1.T_world_body.t
        z.append(np.r_[e / ps, (p.v_world_m_s - s1.v_world_m_s) / vs])
        err.append(float(np.linalg.norm(e)))
    return np.array(z), np.array(err)


def test_the_calibrated_noise_is_ten_times_too_optimistic_in_flight(flight: Flight) -> None:
    """Over 0.5 s the IMU-only prediction misses the ground truth by 8.5 (position) and 9.5
    (velocity) of its sigmas with imu0/sensor.yaml's densities (RMS over 105 windows), and by 0.9
    with imu_noise_scale = 10, the setting the back-end test below uses."""
    z1, err = _z_scores(flight, 1.0, 0.5)
    z10, _ = _z_scores(flight, 10.0, 0.5)
    assert len(z1) > 100
    assert np.sqrt(np.mean(z1**2)) > 5.0
    assert 0.6 < np.sqrt(np.mean(z10**2)) < 1.5
    assert np.median(err) < 0.01  # 0.6 cm


def test_bridging_one_second_with_the_real_imu(flight: Flight) -> None:
    """1 s of IMU alone from the true state: median position error 2.3 cm (90 % below 3.2 cm),
    and with imu_noise_scale = 10 every window lies within 3 sigma on every axis."""
    z, err = _z_scores(flight, 10.0, 1.0)
    assert np.median(err) < 0.04 and np.percentile(err, 90) < 0.05
    assert np.mean(np.all(np.abs(z[:, :3]) < 3.0, axis=1)) > 0.95


def _observe(flight: Flight, points: np.ndarray, i: int, rng: np.random.Generator) -> VisualObservations:
    return observe_points(flight.state(i).T_world_body @ flight.T_body_cam, points, rng)


def test_the_backend_follows_the_flight_with_the_real_imu(flight: Flight) -> None:
    """20 s of flight (40-60 s, 7 m of path) at 10 frames/s, from the true state with the
    initialiser's landmarks (2 cm noise). Measured: SE3 ATE 1.0 cm, largest error 3.0 cm, gyro
    bias within 1.2e-4 rad/s of the ground truth's, no failed check (other 20 s segments: 0.8-3.0 cm)."""
    gt = flight.gt
    t0 = int(gt.stamps_ns[0]) + 40_000_000_000
    i0 = int(np.searchsorted(gt.stamps_ns, t0))
    i1 = int(np.searchsorted(gt.stamps_ns, t0 + 20_000_000_000))
    idx = np.arange(i0, i1, 2)
    rng = np.random.default_rng(0)
    path = gt.trajectory.positions_m[i0:i1]
    points = box_points(path.min(0) - 3.0, path.max(0) + 3.0, 4000, rng)
    be = VioBackend(VioConfig(imu=flight.noise, imu_noise_scale=10.0), K_EUROC, flight.T_body_cam)
    s0 = flight.state(int(idx[0]))
    obs0 = _observe(flight, points, int(idx[0]), rng)
    seeds = points[obs0.ids] + rng.normal(0.0, 0.02, (obs0.ids.size, 3))
    assert be.initialise(VioInitialState(s0, landmark_ids=obs0.ids, landmarks_world=seeds),
                         flight.imu.window(s0.t_ns - 20_000_000, s0.t_ns + 20_000_000), obs0).ok
    est, truth, failed = [], [], []
    for a, b in zip(idx[:-1], idx[1:], strict=True):
        window = flight.imu.window(int(gt.stamps_ns[a]) - 10_000_000, int(gt.stamps_ns[b]) + 10_000_000)
        res = be.add_frame(int(gt.stamps_ns[b]), window, _observe(flight, points, int(b), rng))
        assert res.estimate.ok and res.estimate.state is not None and res.checks is not None
        est.append(res.estimate.state)
        truth.append(flight.state(int(b)))
        if not res.checks.ok:
            failed.append(res.checks.summary())
    assert failed == []
    P = np.array([s.T_world_body.t for s in est])
    G = np.array([s.T_world_body.t for s in truth])
    S = umeyama(P, G, with_scale=False)
    ate = float(np.sqrt(np.mean(np.sum((S.act(P) - G) ** 2, axis=1))))
    assert ate < 0.025
    assert np.linalg.norm(P - G, axis=1).max() < 0.06
    np.testing.assert_allclose(est[-1].bias.gyro_rad_s, truth[-1].bias.gyro_rad_s, atol=1e-3)
    np.testing.assert_allclose(est[-1].bias.accel_m_s2, truth[-1].bias.accel_m_s2, atol=0.1)
