"""The real EuRoC V1_01 flight in ../shared/data (recorded IMU, ground truth with velocities and
biases), and the gravity its ground truth implies; shared by bench_vi_init and the real-data tests.

Ground-truth gravity. The ground truth's world frame (Vicon) is not exactly level: over the
whole flight the recorded specific force, rotated into that frame with the ground-truth
attitude and accelerometer bias, averages to a gravity vector 0.24 deg away from -z
(:func:`gravity_world_from_flight`; the mean acceleration over 145 s is (v_end - v_0) / T, close
to zero). That vector is the ground-truth gravity here: on the first (static) seconds it agrees
with ``-(accel - b_a_gt)`` to 0.01 deg, while -z would be off by 0.24 deg.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from amrvio.imu.static_init import StaticInitResult, initial_static_init
from amrvio.io.base import read_imu_csv
from amrvio.io.calib import read_euroc_sensor_T_BS
from amrvio.io.trajectory import EurocGroundTruth, read_euroc_csv
from amrvio.types.lie import SE3, quat_wxyz_to_matrix, so3_exp, so3_log
from amrvio.types.sensors import ImuData, ImuNoise

F64 = NDArray[np.float64]
I64 = NDArray[np.int64]

V101 = Path(__file__).resolve().parents[1] / ".." / "shared" / "data" / "euroc_V1_01_easy_first95"


@dataclass(frozen=True, slots=True, eq=False)
class EurocFlight:
    """imu: the whole recorded stream; gt: ground truth (20 Hz, at the camera stamps); R_world_body
    (N, 3, 3) and p_world_body (N, 3) of gt; T_body_cam; noise: imu0/sensor.yaml; gravity_world
    (3,): the gravity the ground truth implies (module docstring)."""

    imu: ImuData
    gt: EurocGroundTruth
    R_world_body: F64
    p_world_body: F64
    T_body_cam: SE3
    noise: ImuNoise
    gravity_world: F64


def angle_deg(a: F64, b: F64) -> float:
    """The angle between two (3,) vectors, degrees."""
    cos = float(a @ b / (np.linalg.norm(a) * np.linalg.norm(b)))
    return math.degrees(math.acos(min(1.0, max(-1.0, cos))))


def gt_rotations_at(gt_ns: I64, R: F64, t_ns: I64) -> F64:
    """Ground-truth rotations (M, 3, 3) at ``t_ns`` (inside the ground truth), geodesic interpolation."""
    idx = np.clip(np.searchsorted(gt_ns, t_ns, side="right") - 1, 0, len(gt_ns) - 2)
    alpha = (t_ns - gt_ns[idx]).astype(np.float64) / (gt_ns[idx + 1] - gt_ns[idx]).astype(np.float64)
    d = so3_log(np.einsum("nji,njk->nik", R[idx], R[idx + 1]))
    return np.asarray(np.einsum("nij,njk->nik", R[idx], so3_exp(d * alpha[:, None])))


def gravity_world_from_flight(imu: ImuData, gt: EurocGroundTruth, R_world_body: F64) -> F64:
    """g_world = mean(a_world) - mean(R_world_body (accel - b_a)) over the ground truth's span,
    with mean(a_world) = (v_end - v_0) / T (see the module docstring)."""
    if gt.velocities_m_s is None or gt.accel_bias is None:
        raise ValueError("the ground truth has no velocities or accelerometer biases")
    gt_ns = gt.stamps_ns
    sel = (imu.stamps_ns >= gt_ns[0]) & (imu.stamps_ns <= gt_ns[-1])
    t = imu.stamps_ns[sel]
    R = gt_rotations_at(gt_ns, R_world_body, t)
    idx = np.clip(np.searchsorted(gt_ns, t, side="right") - 1, 0, len(gt_ns) - 1)
    f_world = np.einsum("nij,nj->ni", R, imu.accel_m_s2[sel] - gt.accel_bias[idx])
    k0, k1 = int(idx[0]), int(idx[-1])
    mean_acc = (gt.velocities_m_s[k1] - gt.velocities_m_s[k0]) / ((int(gt_ns[k1]) - int(gt_ns[k0])) * 1e-9)
    return np.asarray(mean_acc - f_world.mean(axis=0))


def _accel_series(flight: EurocFlight, shift_s: float, average_s: float) -> tuple[F64, F64]:
    """(N, 3) ground-truth acceleration plus gravity and (N, 3) recorded specific force in the
    world, averaged over ``average_s`` and their means removed (see :func:`accel_gain`)."""
    from scipy.interpolate import CubicSpline

    gt = flight.gt
    if gt.accel_bias is None:
        raise ValueError("the ground truth has no accelerometer biases")
    gt_ns = gt.stamps_ns
    t_gt = (gt_ns - gt_ns[0]).astype(np.float64) * 1e-9
    imu = flight.imu
    t = (imu.stamps_ns - gt_ns[0]).astype(np.float64) * 1e-9 + shift_s
    sel = (t > t_gt[0] + 1.0) & (t < t_gt[-1] - 1.0)
    t = t[sel]
    t_ns = gt_ns[0] + np.round(t * 1e9).astype(np.int64)
    R = gt_rotations_at(gt_ns, flight.R_world_body, t_ns)
    bias = CubicSpline(t_gt, gt.accel_bias)(t)
    f_world = np.einsum("nij,nj->ni", R, imu.accel_m_s2[sel] - bias)
    a_world = CubicSpline(t_gt, flight.p_world_body)(t, 2) - flight.gravity_world
    n = max(1, int(round(average_s / float(np.median(np.diff(t))))))
    kernel = np.ones(n) / n

    def smooth(x: F64) -> F64:
        y = np.stack([np.convolve(x[:, j], kernel, mode="valid") for j in range(3)], axis=1)
        return np.asarray(y - y.mean(axis=0))

    return smooth(a_world), smooth(f_world)


def accel_gain(flight: EurocFlight, shift_s: float = 0.0, average_s: float = 0.2) -> tuple[float, F64]:
    """How much acceleration the accelerometer reads for what the ground truth shows: per world
    axis, the least-squares slope of the recorded specific force (less the ground-truth bias,
    rotated into the world with the ground-truth attitude) on the ground truth's acceleration
    (second derivative of a cubic spline through its positions) plus gravity, both averaged over
    ``average_s`` and their means removed, over the flight less 1 s at either end. ``shift_s``
    moves the IMU's stamps (a time offset would lower every slope). The slope over all three axes
    together, and the (3,) per axis; 1 for a true IMU."""
    x, y = _accel_series(flight, shift_s, average_s)
    return float(np.sum(x * y) / np.sum(x * x)), np.asarray(np.sum(x * y, axis=0) / np.sum(x * x, axis=0))


def accel_gain_bracket(flight: EurocFlight, average_s: float) -> tuple[float, float]:
    """(low, high) bounds of the accelerometer's gain over ``average_s`` averages, whatever noise
    either side carries: noise in the ground truth's differentiated acceleration (the regressor)
    lowers :func:`accel_gain`'s slope below the gain, noise in the accelerometer raises the
    inverse of the reverse slope (ground truth on accelerometer) above it, so the gain lies
    between the two (noise independent of the motion). All axes pooled."""
    x, y = _accel_series(flight, 0.0, average_s)
    xy = float(np.sum(x * y))
    return xy / float(np.sum(x * x)), float(np.sum(y * y)) / xy


def load_flight(root: Path = V101) -> EurocFlight:
    """Read the flight (raises the reader's errors when files are missing or malformed)."""
    from amrvio.io.calib import read_euroc_imu

    mav = root / "mav0"
    imu = read_imu_csv(mav / "imu0" / "data.csv")
    gt = read_euroc_csv(mav / "state_groundtruth_estimate0" / "data.csv")
    R = quat_wxyz_to_matrix(gt.trajectory.quats_wxyz)
    g = gravity_world_from_flight(imu, gt, R)
    return EurocFlight(imu, gt, R, np.asarray(gt.trajectory.positions_m),
                       read_euroc_sensor_T_BS(mav / "cam0" / "sensor.yaml"),
                       read_euroc_imu(mav / "imu0" / "sensor.yaml"), g)


def synthetic_flight(flight: EurocFlight, seed: int = 0) -> EurocFlight:
    """The same flight with the recorded IMU replaced by a synthetic one: the exact angular rate and
    specific force of the ground truth (amrvio.sim.replay spline, which passes through every
    ground-truth pose), plus the ground truth's own time-varying biases and the datasheet's white
    noise (seeded). Gravity is then exactly (0, 0, -9.81). A control: the recorded IMU against its
    model, everything else equal."""
    from amrvio.sim.imu_synth import GRAVITY_WORLD, ideal_imu
    from amrvio.sim.replay import make_replay_motion

    gt = flight.gt
    ns = gt.stamps_ns
    motion = make_replay_motion(ns, gt.trajectory.positions_m, gt.trajectory.quats_wxyz, 0.0, None, 0.0,
                                gt.gyro_bias, gt.accel_bias, margin_s=0.0)
    sel = (flight.imu.stamps_ns >= ns[0]) & (flight.imu.stamps_ns <= ns[-1])
    stamps = flight.imu.stamps_ns[sel]
    t = (stamps - motion.t0_ns).astype(np.float64) * 1e-9
    gyro, accel = ideal_imu(motion.states(t))
    bg, ba = motion.gyro_bias_at(t), motion.accel_bias_at(t)
    rng = np.random.default_rng(seed)
    sg, sa = flight.noise.discrete_sigmas()
    gyro = gyro + (0.0 if bg is None else bg) + sg * rng.standard_normal(gyro.shape)
    accel = accel + (0.0 if ba is None else ba) + sa * rng.standard_normal(accel.shape)
    from dataclasses import replace

    return replace(flight, imu=ImuData(stamps, gyro, accel), gravity_world=np.array(GRAVITY_WORLD, dtype=np.float64))


@dataclass(frozen=True, slots=True, eq=False)
class StaticCheck:
    """The static initialisation on the flight's first (still) seconds against the ground truth:
    ``result``; ``tilt_err_deg``: the angle between its gravity direction and the one the ground
    truth implies (its rotations applied to ``gravity_world``, averaged over the window);
    ``gyro_bias_err_rad_s`` (3,): its gyro bias less the ground truth's mean ``b_w`` over the
    window; ``accel_bias_up_err_m_s2``: its accelerometer bias along gravity (the observable part)
    less the ground truth's."""

    result: StaticInitResult
    tilt_err_deg: float
    gyro_bias_err_rad_s: F64
    accel_bias_up_err_m_s2: float


def static_init_check(flight: EurocFlight) -> StaticCheck:
    """:func:`amrvio.imu.static_init.initial_static_init` on ``flight`` and its errors
    (:class:`StaticCheck`). Raises ValueError when it does not return a result to compare."""
    res = initial_static_init(flight.imu, noise=flight.noise)
    if res.gravity_body is None or res.gyro_bias_rad_s is None or flight.gt.gyro_bias is None \
            or flight.gt.accel_bias is None:
        raise ValueError(f"static initialisation gave no gravity or gyro bias ({res.status.value}), or the ground "
                         "truth has no biases")
    t0 = int(flight.imu.stamps_ns[0])
    window = flight.imu.window(t0, t0 + round(res.duration_s * 1e9))
    R = gt_rotations_at(flight.gt.stamps_ns, flight.R_world_body, window.stamps_ns)
    g_body = np.einsum("nji,j->ni", R, flight.gravity_world).mean(axis=0)
    tilt = angle_deg(g_body, res.gravity_body)
    sel = (flight.gt.stamps_ns >= t0) & (flight.gt.stamps_ns <= int(window.stamps_ns[-1]))
    bg_err = np.asarray(res.gyro_bias_rad_s) - flight.gt.gyro_bias[sel].mean(axis=0)
    ba_up_true = float(flight.gt.accel_bias[sel].mean(axis=0) @ (-g_body / np.linalg.norm(g_body)))
    return StaticCheck(res, tilt, bg_err, float(res.accel_bias_up_m_s2) - ba_up_true)
