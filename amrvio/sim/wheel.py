"""Synthetic wheel odometry: forward speed (body x) and yaw rate (body z) at a fixed rate.

measured = (1 + scale_error) * true * slip + white noise. A wheel-radius error scales both
readings of a differential drive alike; during a slip episode the wheels turn faster than the
robot moves (factor 1 + slip).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from amrvio.errors import ConfigError
from amrvio.sim.kinematics import Motion

F64 = NDArray[np.float64]

WHEEL_CSV_HEADER = (
    "timestamp_ns,v_forward_m_s,yaw_rate_rad_s,v_forward_true_m_s,yaw_rate_true_rad_s,slipping"
)


@dataclass(frozen=True, slots=True)
class SlipEpisode:
    """Wheels spin (1 + slip) times faster than the ground motion for t in [t0_s, t0_s + dur_s]."""

    t0_s: float
    dur_s: float
    slip: float = 0.3


@dataclass(frozen=True, slots=True)
class WheelConfig:
    rate_hz: float = 50.0
    scale_error: float = 0.02
    speed_noise_m_s: float = 0.01
    yaw_rate_noise_rad_s: float = 0.005
    slips: tuple[SlipEpisode, ...] = ()

    def __post_init__(self) -> None:
        if not (self.rate_hz > 0 and math.isfinite(self.rate_hz)):
            raise ConfigError(f"wheel odometry rate must be > 0 Hz, got {self.rate_hz}")
        if self.speed_noise_m_s < 0 or self.yaw_rate_noise_rad_s < 0:
            raise ConfigError("wheel odometry noise sigmas must be >= 0")


@dataclass(frozen=True, slots=True, eq=False)
class WheelOdometry:
    """(N,) arrays: stamps_ns int64, measured and true forward speed / yaw rate, slip flag."""

    stamps_ns: NDArray[np.int64]
    v_forward_m_s: F64
    yaw_rate_rad_s: F64
    v_forward_true_m_s: F64
    yaw_rate_true_rad_s: F64
    slipping: NDArray[np.bool_]


def synthesize_wheel(
    motion: Motion, config: WheelConfig, rng: np.random.Generator, start_ns: int = 0
) -> WheelOdometry:
    """Sample wheel odometry of ``motion`` over [0, duration]."""
    n = int(np.floor(motion.duration_s * config.rate_hz + 1e-9)) + 1
    offs_ns = np.round(np.arange(n) * (1e9 / config.rate_hz)).astype(np.int64)
    t = offs_ns.astype(np.float64) * 1e-9
    s = motion.states(t)
    v_body = np.einsum("nji,nj->ni", s.R_world_body, s.v_world)  # R^T v
    v_true = v_body[:, 0]
    w_true = s.omega_body[:, 2]
    slip = np.ones(n)
    for ep in config.slips:
        inside = (t >= ep.t0_s) & (t <= ep.t0_s + ep.dur_s)
        slip[inside] *= 1.0 + ep.slip
    k = 1.0 + config.scale_error
    v_meas = k * slip * v_true + rng.standard_normal(n) * config.speed_noise_m_s
    w_meas = k * slip * w_true + rng.standard_normal(n) * config.yaw_rate_noise_rad_s
    return WheelOdometry(int(start_ns) + offs_ns, v_meas, w_meas, v_true, w_true, slip != 1.0)


def write_wheel_csv(path: Path, wheel: WheelOdometry) -> None:
    """CSV with header ``WHEEL_CSV_HEADER``; fixed float formatting (byte-reproducible)."""
    lines = [WHEEL_CSV_HEADER]
    for i in range(wheel.stamps_ns.shape[0]):
        lines.append(
            f"{int(wheel.stamps_ns[i])},{wheel.v_forward_m_s[i]:.9f},{wheel.yaw_rate_rad_s[i]:.9f},"
            f"{wheel.v_forward_true_m_s[i]:.9f},{wheel.yaw_rate_true_rad_s[i]:.9f},"
            f"{int(wheel.slipping[i])}"
        )
    path.write_text("\n".join(lines) + "\n")
