"""Synthetic IMU: exact angular rate and specific force of a Motion, plus noise and bias walks.

gyro  = omega_body + b_g + n_g
accel = R_world_body^T (a_world - g_world) + b_a + n_a,  g_world = (0, 0, -9.81)
White noise per sample: sigma_d = density * sqrt(rate); bias random walk per step:
sigma = random_walk * sqrt(dt) (Kalibr IMU noise model, discrete form).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from amrvio.errors import ConfigError
from amrvio.sim.kinematics import Motion, MotionState
from amrvio.types.sensors import ImuData, ImuNoise

F64 = NDArray[np.float64]

GRAVITY_WORLD = np.array([0.0, 0.0, -9.81])


@dataclass(frozen=True, slots=True, eq=False)
class SyntheticImu:
    """IMU readings and the TRUE biases at every stamp (gyro_bias/accel_bias: (N,3)).

    stamps_ns are ``start_ns + round(t_s * 1e9)`` where t_s is motion time; ``t_s`` (N,) keeps
    the motion times used.
    """

    imu: ImuData
    t_s: F64
    gyro_bias: F64
    accel_bias: F64


def imu_times(duration_s: float, rate_hz: float) -> tuple[NDArray[np.int64], F64]:
    """Sample instants on [0, duration]: (offsets in ns (N,) int64, motion times in s (N,))."""
    if not (rate_hz > 0 and np.isfinite(rate_hz)):
        raise ConfigError(f"IMU rate must be > 0 Hz, got {rate_hz}")
    n = int(np.floor(duration_s * rate_hz + 1e-9)) + 1
    offs_ns = np.round(np.arange(n) * (1e9 / rate_hz)).astype(np.int64)
    return offs_ns, offs_ns.astype(np.float64) * 1e-9


def ideal_imu(state: MotionState, gravity_world: ArrayLike = GRAVITY_WORLD) -> tuple[F64, F64]:
    """Noise-free (gyro (N,3) rad/s, specific force (N,3) m/s^2) in the body frame."""
    g = np.asarray(gravity_world, dtype=np.float64)
    f_world = state.a_world - g
    accel = np.einsum("nji,nj->ni", state.R_world_body, f_world)  # R^T f
    return np.array(state.omega_body), accel


def synthesize_imu(
    motion: Motion,
    rate_hz: float = 200.0,
    noise: ImuNoise | None = None,
    rng: np.random.Generator | None = None,
    start_ns: int = 0,
    initial_gyro_bias: ArrayLike = (0.0, 0.0, 0.0),
    initial_accel_bias: ArrayLike = (0.0, 0.0, 0.0),
) -> SyntheticImu:
    """Sample ``motion`` at ``rate_hz`` over [0, duration]. ``noise=None`` gives exact data
    (biases stay at their initial values). The noise densities are taken from ``noise`` and the
    discrete sigmas from the actual ``rate_hz``.
    """
    offs_ns, t = imu_times(motion.duration_s, rate_hz)
    gyro, accel = ideal_imu(motion.states(t))
    n = t.shape[0]
    bg = np.tile(np.asarray(initial_gyro_bias, dtype=np.float64), (n, 1))
    ba = np.tile(np.asarray(initial_accel_bias, dtype=np.float64), (n, 1))
    if noise is not None:
        if rng is None:
            raise ConfigError("synthesize_imu: a noisy IMU needs an rng (numpy Generator)")
        dt = 1.0 / rate_hz
        sq_rate = np.sqrt(rate_hz)
        # one draw order for reproducibility: bias walks, then white noise
        walk_g = rng.standard_normal((n, 3)) * (noise.gyro_random_walk * np.sqrt(dt))
        walk_a = rng.standard_normal((n, 3)) * (noise.accel_random_walk * np.sqrt(dt))
        walk_g[0] = 0.0
        walk_a[0] = 0.0
        bg = bg + np.cumsum(walk_g, axis=0)
        ba = ba + np.cumsum(walk_a, axis=0)
        n_g = rng.standard_normal((n, 3)) * (noise.gyro_noise_density * sq_rate)
        n_a = rng.standard_normal((n, 3)) * (noise.accel_noise_density * sq_rate)
        gyro = gyro + bg + n_g
        accel = accel + ba + n_a
    else:
        gyro = gyro + bg
        accel = accel + ba
    imu = ImuData(int(start_ns) + offs_ns, gyro, accel)
    return SyntheticImu(imu, t, bg, ba)
