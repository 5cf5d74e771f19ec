"""Synthetic inputs for the VI initialiser: keyframes of a simulator motion (amrvio.sim) as a
monocular VO would give them (first camera's frame, divided by a scale, optional seeded pose noise)
and the synthetic IMU of the same motion."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from amrvio.sim.imu_synth import GRAVITY_WORLD, synthesize_imu
from amrvio.sim.kinematics import Motion
from amrvio.sim.motion import MotionLayout, default_T_body_cam, make_motion
from amrvio.types.lie import SE3, so3_exp
from amrvio.types.sensors import ImuData, ImuNoise

NOISE = ImuNoise.euroc_adis16448()
GYRO_BIAS = np.array([0.01, -0.02, 0.015])
ACCEL_BIAS = np.array([0.05, -0.08, 0.1])
START_NS = 1_000_000_000


@dataclass(frozen=True)
class ViCase:
    stamps_ns: NDArray[np.int64]
    T_vo_cam: NDArray[np.float64]
    imu: ImuData
    T_body_cam: SE3
    scale: float
    gravity_vo: NDArray[np.float64]  # true gravity in the VO frame
    velocities_vo: NDArray[np.float64]  # true body velocities in the VO frame (K, 3)


def case_from_motion(motion: Motion, t0: float, t1: float, scale: float = 3.7, pos_sigma_m: float = 0.0,
                     rot_sigma_deg: float = 0.0, imu_noise: bool = True, seed: int = 0,
                     kf_hz: float = 10.0) -> ViCase:
    rng = np.random.default_rng(seed)
    syn = synthesize_imu(motion, 200.0, NOISE if imu_noise else None, rng if imu_noise else None, START_NS,
                         GYRO_BIAS, ACCEL_BIAS)
    T_bc = default_T_body_cam()
    tk = np.arange(round((t1 - t0) * kf_hz) + 1) / kf_hz + t0
    st = motion.states(tk)
    T_wc = np.empty((tk.shape[0], 4, 4))
    for i in range(tk.shape[0]):
        T_wb = np.eye(4)
        T_wb[:3, :3], T_wb[:3, 3] = st.R_world_body[i], st.p_world[i]
        T_wc[i] = T_wb @ T_bc.matrix()
        T_wc[i, :3, :3] = T_wc[i, :3, :3] @ so3_exp(np.radians(rot_sigma_deg) * rng.standard_normal(3))
        T_wc[i, :3, 3] += pos_sigma_m * rng.standard_normal(3)
    T_vo = np.einsum("ij,njk->nik", np.linalg.inv(T_wc[0]), T_wc)
    T_vo[:, :3, 3] /= scale
    R_vo_w = T_wc[0, :3, :3].T
    return ViCase(START_NS + np.round(tk * 1e9).astype(np.int64), T_vo, syn.imu, T_bc, scale,
                  R_vo_w @ GRAVITY_WORLD, st.v_world @ R_vo_w.T)


def motion_case(kind: str, t0: float, t1: float, layout: MotionLayout | None = None, scale: float = 3.7,
                pos_sigma_m: float = 0.0, rot_sigma_deg: float = 0.0, imu_noise: bool = True,
                seed: int = 0) -> ViCase:
    lay = layout or MotionLayout(free_length_m=30.0, free_left_m=2.0, free_right_m=2.0)
    return case_from_motion(make_motion(kind, t1 + 1.0, lay, seed=0), t0, t1, scale, pos_sigma_m, rot_sigma_deg,
                            imu_noise, seed)
