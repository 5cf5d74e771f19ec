"""An IMU synthesised from a recorded ground truth, for real images that come without one.

:func:`synthesize_imu_from_groundtruth` splines the ground-truth body poses
(:func:`amrvio.sim.replay.make_replay_motion`: cubic positions, C2 rotation spline) and samples
the exact angular rate and specific force with the Kalibr noise model of
:func:`amrvio.sim.imu_synth.synthesize_imu` (white noise and bias random walk at the given
densities). :func:`write_with_synthetic_imu` writes a recording folder (EuRoC layout) that takes the
images of another one (a symbolic link) and adds ``imu0`` and the ground truth as
``state_groundtruth_estimate0``, so that ``amrvio run`` sees a camera with an IMU.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike

from amrvio.errors import ConfigError, DatasetFormatError
from amrvio.sim.imu_synth import SyntheticImu, synthesize_imu
from amrvio.sim.replay import load_groundtruth, make_replay_motion
from amrvio.types.sensors import ImuData, ImuNoise


def synthesize_imu_from_groundtruth(
    stamps_ns: ArrayLike, positions_m: ArrayLike, quats_wxyz: ArrayLike, noise: ImuNoise | None,
    rate_hz: float = 200.0, seed: int = 0, initial_gyro_bias: ArrayLike = (0.0, 0.0, 0.0),
    initial_accel_bias: ArrayLike = (0.0, 0.0, 0.0), margin_s: float = 0.5,
) -> SyntheticImu:
    """IMU samples of the body whose poses ``T_world_body`` are (stamps_ns (N,), positions_m
    (N, 3), quats_wxyz (N, 4)), at ``rate_hz`` from ``margin_s`` after the first pose to
    ``margin_s`` before the last (the spline's ends are left out). ``noise=None``: exact samples
    (the biases stay at their initial values). The stamps are the ground truth's clock."""
    ns = np.asarray(stamps_ns, dtype=np.int64)
    if ns.ndim != 1 or ns.shape[0] < 4:
        raise ConfigError("an IMU from ground truth needs at least 4 poses")
    span = (int(ns[-1]) - int(ns[0])) * 1e-9 - 2.0 * margin_s
    if span <= 0:
        raise ConfigError(f"the ground truth spans {(int(ns[-1]) - int(ns[0])) * 1e-9:.3f} s, "
                          f"less than twice the {margin_s} s margin")
    motion = make_replay_motion(ns, positions_m, quats_wxyz, start_s=margin_s, duration_s=span,
                                margin_s=margin_s)
    rng = np.random.default_rng(seed) if noise is not None else None
    return synthesize_imu(motion, rate_hz, noise, rng, start_ns=motion.t0_ns,
                          initial_gyro_bias=initial_gyro_bias, initial_accel_bias=initial_accel_bias)


def write_with_synthetic_imu(source: Path, groundtruth: Path, out: Path, noise: ImuNoise, seed: int = 0,
                             rate_hz: float = 200.0) -> ImuData:
    """``out``/mav0 with ``cam0`` linked to ``source``/mav0/cam0, ``imu0`` synthesised from
    ``groundtruth`` (TUM or EuRoC CSV of the body), and that ground truth as
    ``state_groundtruth_estimate0/data.csv``. Returns the IMU written."""
    from amrvio.io.calib import write_euroc_imu
    from amrvio.io.trajectory import write_euroc_csv
    from amrvio.sim.writer import write_imu_csv
    from amrvio.types.trajectory import Trajectory

    cam0 = source / "mav0" / "cam0"
    if not cam0.is_dir():
        raise DatasetFormatError(source, "no mav0/cam0 folder (EuRoC layout expected)")
    ns, p, q, _, _ = load_groundtruth(groundtruth)
    syn = synthesize_imu_from_groundtruth(ns, p, q, noise, rate_hz, seed)
    mav = out / "mav0"
    (mav / "imu0").mkdir(parents=True, exist_ok=True)
    (mav / "state_groundtruth_estimate0").mkdir(parents=True, exist_ok=True)
    link = mav / "cam0"
    if not link.exists():
        link.symlink_to(cam0.resolve(), target_is_directory=True)
    write_imu_csv(mav / "imu0" / "data.csv", syn.imu)
    write_euroc_imu(mav / "imu0" / "sensor.yaml", noise,
                    comment=f"amrvio IMU synthesised from {groundtruth.name} (seed {seed})")
    traj = Trajectory(ns.astype(np.float64) * 1e-9, p, q)
    write_euroc_csv(mav / "state_groundtruth_estimate0" / "data.csv", traj, ns)
    return syn.imu


__all__ = ["synthesize_imu_from_groundtruth", "write_with_synthetic_imu"]
