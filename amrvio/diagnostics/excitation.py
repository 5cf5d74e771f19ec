"""Motion excitation over a sliding IMU window (seed section 3: scale/gravity/bias observability).

Monocular VIO needs changes in acceleration (and rotation) to make scale, gravity and the
accelerometer bias observable; near-constant velocity is the degenerate case. This module
summarises a window of IMU samples:

- acceleration variance (after a 0.1 s boxcar low-pass that removes vibration): of the
  gravity-removed world acceleration ``R_world_body a + g`` when the
  attitude is known, else of the raw specific force (then rotation also moves gravity between
  axes and inflates it: a conservative-in-the-wrong-direction number, flagged by
  ``gravity_removed=False``);
- change of acceleration direction: the largest angle between the mean acceleration of the
  window's quarters (ignoring quarters whose mean is below ``min_accel_m_s2``);
- angular rate: mean and max norm, and its dominant axes from the SVD of the (N, 3) rates;
- a degenerate flag: acceleration standard deviation below a threshold (constant velocity or rest).

The VIO initialiser adds the condition number of its initialisation system to this record
(``condition_number``, None here).
"""

from __future__ import annotations

import enum
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray

from amrvio.errors import ShapeError
from amrvio.types.sensors import ImuData

F64 = NDArray[np.float64]
GRAVITY_WORLD_M_S2 = np.array([0.0, 0.0, -9.81])


class ExcitationStatus(enum.Enum):
    OK = "ok"
    LOW_ACCELERATION = "low_acceleration"  # constant velocity or rest: scale not observable
    TOO_FEW_SAMPLES = "too_few_samples"


@dataclass(frozen=True, slots=True)
class ExcitationConfig:
    """Thresholds: ``min_accel_std_m_s2`` below which the window is degenerate,
    ``min_accel_m_s2`` for a quarter's mean to count in the direction change. ``lowpass_s``: the
    acceleration is averaged over bins of this length first, so that vibration (rotors, rough
    floor; tens of Hz) does not count as excitation; 0 disables."""

    min_accel_std_m_s2: float = 0.15
    min_accel_m_s2: float = 0.1
    min_samples: int = 10
    lowpass_s: float = 0.1


@dataclass(frozen=True, slots=True)
class Excitation:
    """Excitation of one IMU window ``[t0_s, t1_s]``.

    ``accel_var_m2_s4``: trace of the acceleration covariance; ``accel_std_m_s2`` its square root;
    ``accel_dir_change_rad``; ``gyro_mean_rad_s`` / ``gyro_max_rad_s``: norms;
    ``gyro_axes`` (3, 3): rows are the principal rotation axes (body frame), strongest first,
    ``gyro_axis_rms_rad_s`` (3,): RMS rate about each; ``degenerate`` and ``status``;
    ``condition_number``: filled by the VIO initialiser.
    """

    t0_s: float
    t1_s: float
    n_samples: int
    gravity_removed: bool
    accel_var_m2_s4: float
    accel_dir_change_rad: float
    gyro_mean_rad_s: float
    gyro_max_rad_s: float
    gyro_axes: F64
    gyro_axis_rms_rad_s: F64
    status: ExcitationStatus
    condition_number: float | None = None

    @property
    def accel_std_m_s2(self) -> float:
        return float(np.sqrt(max(self.accel_var_m2_s4, 0.0)))

    @property
    def degenerate(self) -> bool:
        """Scale is not observable in this window (too little acceleration, or too few samples)."""
        return self.status is not ExcitationStatus.OK

    def with_condition_number(self, value: float) -> Excitation:
        return replace(self, condition_number=float(value))


def _bin_means(stamps_ns: NDArray[np.int64], acc: F64, bin_s: float) -> F64:
    """Mean of the samples in consecutive ``bin_s`` bins (a boxcar low-pass, decimated)."""
    t = (np.asarray(stamps_ns, dtype=np.int64) - int(stamps_ns[0])).astype(np.float64) * 1e-9
    idx = np.floor(t / bin_s).astype(np.intp)
    counts = np.bincount(idx)
    keep = counts > 0
    sums = np.stack([np.bincount(idx, weights=acc[:, k]) for k in range(3)], axis=1)
    return np.asarray(sums[keep] / counts[keep, None])


def _dir_change(acc: F64, min_norm: float) -> float:
    parts = np.array_split(acc, 4)
    means = [p.mean(axis=0) for p in parts if p.shape[0] > 0]
    dirs = [m / np.linalg.norm(m) for m in means if np.linalg.norm(m) >= min_norm]
    best = 0.0
    for i in range(len(dirs)):
        for j in range(i + 1, len(dirs)):
            best = max(best, float(np.arccos(np.clip(dirs[i] @ dirs[j], -1.0, 1.0))))
    return best


def compute_excitation(
    imu: ImuData,
    R_world_body: F64 | None = None,
    config: ExcitationConfig | None = None,
    gyro_bias_rad_s: F64 | None = None,
    accel_bias_m_s2: F64 | None = None,
) -> Excitation:
    """Excitation of the samples in ``imu`` (one window). ``R_world_body``: (N, 3, 3) attitude at
    each sample (gravity is then removed, world z up, g = 9.81)."""
    cfg = config or ExcitationConfig()
    n = len(imu)
    t0 = float(imu.stamps_ns[0]) * 1e-9 if n else float("nan")
    t1 = float(imu.stamps_ns[-1]) * 1e-9 if n else float("nan")
    gyro = np.asarray(imu.gyro_rad_s, dtype=np.float64)
    acc = np.asarray(imu.accel_m_s2, dtype=np.float64)
    if gyro_bias_rad_s is not None:
        gyro = gyro - np.asarray(gyro_bias_rad_s, dtype=np.float64).reshape(1, 3)
    if accel_bias_m_s2 is not None:
        acc = acc - np.asarray(accel_bias_m_s2, dtype=np.float64).reshape(1, 3)
    if n < cfg.min_samples:
        nan = float("nan")
        return Excitation(t0, t1, n, R_world_body is not None, nan, nan, nan, nan,
                          np.eye(3), np.zeros(3), ExcitationStatus.TOO_FEW_SAMPLES)
    removed = R_world_body is not None
    if R_world_body is not None:
        R = np.asarray(R_world_body, dtype=np.float64)
        if R.shape != (n, 3, 3):
            raise ShapeError(f"R_world_body must be ({n},3,3), got {R.shape}")
        acc = np.einsum("nij,nj->ni", R, acc) + GRAVITY_WORLD_M_S2  # a_w = R f + g
    if cfg.lowpass_s > 0:
        acc = _bin_means(imu.stamps_ns, acc, cfg.lowpass_s)
    if acc.shape[0] < 2:
        acc = np.vstack([acc, acc])
    cov = np.cov(acc.T, bias=True)
    var = float(np.trace(cov))
    std = float(np.sqrt(max(var, 0.0)))
    norms = np.linalg.norm(gyro, axis=1)
    _, s, vt = np.linalg.svd(gyro, full_matrices=False)
    rms_axes = s / np.sqrt(n)
    dir_change = _dir_change(acc if removed else acc - acc.mean(axis=0), cfg.min_accel_m_s2)
    degenerate = std < cfg.min_accel_std_m_s2
    return Excitation(
        t0_s=t0,
        t1_s=t1,
        n_samples=n,
        gravity_removed=removed,
        accel_var_m2_s4=var,
        accel_dir_change_rad=dir_change,
        gyro_mean_rad_s=float(norms.mean()),
        gyro_max_rad_s=float(norms.max()),
        gyro_axes=np.asarray(vt, dtype=np.float64),
        gyro_axis_rms_rad_s=np.asarray(rms_axes, dtype=np.float64),
        status=ExcitationStatus.LOW_ACCELERATION if degenerate else ExcitationStatus.OK,
    )
