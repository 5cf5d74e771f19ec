"""Standstill in an IMU window, and the gyro bias it gives.

A platform at rest (vibration allowed) measures gyro = b_g + noise and accel = -R^T g_world +
b_a + noise. So when a window is still, its mean gyro estimates the gyro bias b_g, and its mean
specific force points against gravity with norm ~g. The test is three checks on the window:

- the gravity direction is steady: the mean specific force of the first half and of the second
  half of the window differ by less than ``max_gravity_tilt_deg``;
- the norm of the mean specific force is within ``max_gravity_error_m_s2`` of ``gravity_m_s2``;
- the norm of the mean rate is below ``max_mean_rate_rad_s`` (a rotation at constant rate would
  pass the first two checks only with the rate axis along gravity; this catches it when the rate
  exceeds any plausible bias).

:func:`detect_standstill` judges one window; :func:`initial_standstill` the first second of a
recording (what ``amrvio diagnose --gyro-bias auto`` uses).
"""

from __future__ import annotations

import enum
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from amrvio.types.sensors import ImuData

F64 = NDArray[np.float64]


class StandstillStatus(enum.Enum):
    """Why a window is (not) still; the first failing check, in the order of the module docstring."""

    STILL = "still"
    TOO_FEW_SAMPLES = "too_few_samples"
    GRAVITY_DIRECTION_MOVES = "gravity_direction_moves"
    SPECIFIC_FORCE_NOT_GRAVITY = "specific_force_not_gravity"
    ROTATING = "rotating"


@dataclass(frozen=True, slots=True)
class StandstillConfig:
    """Thresholds of the standstill test (defaults: those of ``amrvio diagnose``).

    min_stream_samples: :func:`initial_standstill` judges no stream with fewer samples.
    window_s: the length of the first window :func:`initial_standstill` looks at.
    """

    max_gravity_tilt_deg: float = 1.0
    gravity_m_s2: float = 9.81
    max_gravity_error_m_s2: float = 0.3
    max_mean_rate_rad_s: float = 0.15
    min_stream_samples: int = 51
    window_s: float = 1.0


@dataclass(frozen=True, slots=True, eq=False)
class Standstill:
    """The verdict on one IMU window.

    status: STILL or the first failed check. n_samples: samples in the window.
    gravity_tilt_deg: angle between the mean specific force of the two halves (NaN with fewer
    than 2 samples). mean_specific_force_m_s2, mean_gyro_rad_s: (3,) means over the window (NaN
    when it is empty). gyro_bias_rad_s: (3,) the mean gyro when still, else None.
    """

    status: StandstillStatus
    n_samples: int
    gravity_tilt_deg: float
    mean_specific_force_m_s2: F64
    mean_gyro_rad_s: F64
    gyro_bias_rad_s: F64 | None

    @property
    def still(self) -> bool:
        return self.status is StandstillStatus.STILL


def _readonly(a: F64) -> F64:
    out = np.array(a, dtype=np.float64)
    out.setflags(write=False)
    return out


def _not_judged(status: StandstillStatus, n: int) -> Standstill:
    nan3 = _readonly(np.full(3, np.nan))
    return Standstill(status, n, float("nan"), nan3, nan3, None)


def detect_standstill(window: ImuData, config: StandstillConfig | None = None) -> Standstill:
    """Is the platform still over ``window``? (the three checks of the module docstring)."""
    cfg = StandstillConfig() if config is None else config
    g, a = np.asarray(window.gyro_rad_s), np.asarray(window.accel_m_s2)
    n = a.shape[0]
    if n < 2:
        return _not_judged(StandstillStatus.TOO_FEW_SAMPLES, n)
    h = n // 2
    d0, d1 = a[:h].mean(axis=0), a[h:].mean(axis=0)
    cosang = float(d0 @ d1 / (np.linalg.norm(d0) * np.linalg.norm(d1)))
    tilt_deg = float(np.degrees(np.arccos(np.clip(cosang, -1.0, 1.0))))
    mean_a, mean_g = a.mean(axis=0), g.mean(axis=0)
    # Comparisons written as amrvio diagnose always made them (cosine, not angle), so that the
    # verdict on a window is bit-for-bit the one before this module existed.
    if not cosang > np.cos(np.radians(cfg.max_gravity_tilt_deg)):
        status = StandstillStatus.GRAVITY_DIRECTION_MOVES
    elif not abs(np.linalg.norm(mean_a) - cfg.gravity_m_s2) < cfg.max_gravity_error_m_s2:
        status = StandstillStatus.SPECIFIC_FORCE_NOT_GRAVITY
    elif not np.linalg.norm(mean_g) < cfg.max_mean_rate_rad_s:
        status = StandstillStatus.ROTATING
    else:
        status = StandstillStatus.STILL
    bias = _readonly(mean_g) if status is StandstillStatus.STILL else None
    return Standstill(status, n, tilt_deg, _readonly(mean_a), _readonly(mean_g), bias)


def initial_standstill(imu: ImuData, config: StandstillConfig | None = None) -> Standstill:
    """:func:`detect_standstill` on the first ``window_s`` of ``imu`` (both ends included).

    A stream of fewer than ``min_stream_samples`` samples is TOO_FEW_SAMPLES.
    """
    cfg = StandstillConfig() if config is None else config
    if len(imu) < cfg.min_stream_samples:
        return _not_judged(StandstillStatus.TOO_FEW_SAMPLES, len(imu))
    t0 = int(imu.stamps_ns[0])
    return detect_standstill(imu.window(t0, t0 + int(round(cfg.window_s * 1e9))), cfg)
