"""Static initialisation: attitude and gyro bias from an IMU window at rest, with uncertainty.

At rest ``gyro = b_g + n_g`` and ``accel = R_world_body^T (0, 0, g) + b_a + n_a`` (the specific
force points up). Over a still window (:func:`amrvio.imu.static.detect_standstill`):

- gyro bias: the mean gyro. Observable, all three axes.
- gravity direction in the body frame (roll and pitch): the direction of the mean specific force.
  Its error is the noise of the mean plus the accelerometer bias across gravity, which a single
  attitude cannot tell from a tilt (b_a / g rad, 0.3 deg for 0.05 m/s^2). The reported tilt
  standard deviation includes a prior on that bias (``accel_bias_sigma_m_s2``).
- accelerometer bias along gravity: ``|mean accel| - g``, observable only as far as the local
  gravity magnitude is known (``gravity_sigma_m_s2``: 9.78 to 9.83 m/s^2 on Earth's surface).
- accelerometer bias across gravity and yaw: not observable. ``R_world_body`` has yaw 0.

Standard deviations of the means come from batch means (the window in ``n_batches`` contiguous
batches), which counts vibration and correlated noise that a white-noise formula would miss; with
an :class:`ImuNoise` the white-noise value is a floor.
"""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from amrvio.imu.static import Standstill, StandstillConfig, detect_standstill
from amrvio.types.sensors import ImuData, ImuNoise

F64 = NDArray[np.float64]

UNOBSERVABLE_AT_REST = ("yaw", "accelerometer bias across gravity (it reads as tilt)")


class StaticInitStatus(enum.Enum):
    OK = "ok"
    NOT_STILL = "not_still"  # the standstill test failed: see ``standstill.status``


@dataclass(frozen=True, slots=True)
class StaticInitConfig:
    """``standstill``: the test the window must pass (its ``gravity_m_s2`` is the local gravity).
    ``accel_bias_sigma_m_s2``: prior standard deviation of each accelerometer bias component
    (5 mg: a factory-calibrated MEMS); ``gravity_sigma_m_s2``: uncertainty of the local gravity
    magnitude; ``n_batches``: batches for the standard deviations of the means.
    ``max_window_s``: :func:`initial_static_init` grows its window up to this length."""

    standstill: StandstillConfig = field(default_factory=StandstillConfig)
    max_window_s: float = 5.0
    accel_bias_sigma_m_s2: float = 0.05
    gravity_sigma_m_s2: float = 0.02
    n_batches: int = 10


@dataclass(frozen=True, slots=True, eq=False)
class StaticInitResult:
    """Static initialisation of one window. Values are None unless ``status`` is OK.

    R_world_body (3, 3): gravity-aligned attitude (world z up, yaw 0). gravity_body (3,): unit
    direction of gravity (down) in the body frame. tilt_std_deg: standard deviation of the
    gravity direction (RMS of the 2-D tilt error), noise and accelerometer-bias prior together;
    tilt_noise_std_deg: noise alone. gyro_bias_rad_s, gyro_bias_std_rad_s (3,).
    accel_bias_up_m_s2: accelerometer bias along the up direction, and its std.
    duration_s: the window's length.
    """

    status: StaticInitStatus
    standstill: Standstill
    duration_s: float
    R_world_body: F64 | None = None
    gravity_body: F64 | None = None
    tilt_std_deg: float = float("nan")
    tilt_noise_std_deg: float = float("nan")
    gyro_bias_rad_s: F64 | None = None
    gyro_bias_std_rad_s: F64 | None = None
    accel_bias_up_m_s2: float = float("nan")
    accel_bias_up_std_m_s2: float = float("nan")

    @property
    def ok(self) -> bool:
        return self.status is StaticInitStatus.OK

    @property
    def roll_pitch_deg(self) -> tuple[float, float]:
        """(roll, pitch) of ``R_world_body`` = Ry(pitch) Rx(roll), degrees (NaN when not OK)."""
        if self.gravity_body is None:
            return float("nan"), float("nan")
        up = -self.gravity_body
        roll = math.atan2(float(up[1]), float(up[2]))
        pitch = math.atan2(-float(up[0]), math.hypot(float(up[1]), float(up[2])))
        return math.degrees(roll), math.degrees(pitch)


def _ro(a: F64) -> F64:
    out = np.array(a, dtype=np.float64)
    out.setflags(write=False)
    return out


def gravity_aligned_rotation(up_body: F64) -> F64:
    """R_world_body = Ry(pitch) Rx(roll) with R @ up_body = z (yaw 0). up_body: (3,) any norm."""
    u = np.asarray(up_body, dtype=np.float64) / float(np.linalg.norm(up_body))
    roll = math.atan2(float(u[1]), float(u[2]))
    pitch = math.atan2(-float(u[0]), math.hypot(float(u[1]), float(u[2])))
    cr, sr, cp, sp = math.cos(roll), math.sin(roll), math.cos(pitch), math.sin(pitch)
    Rx = np.array([[1.0, 0.0, 0.0], [0.0, cr, -sr], [0.0, sr, cr]])
    Ry = np.array([[cp, 0.0, sp], [0.0, 1.0, 0.0], [-sp, 0.0, cp]])
    return Ry @ Rx


def _mean_cov(x: F64, n_batches: int) -> F64:
    """(3, 3) covariance of the mean of ``x`` (N, 3) from the means of contiguous batches."""
    k = max(2, min(n_batches, x.shape[0] // 2))
    means = np.stack([b.mean(axis=0) for b in np.array_split(x, k)])
    return np.asarray(np.cov(means.T, ddof=1) / k)


def static_init(
    window: ImuData,
    config: StaticInitConfig | None = None,
    noise: ImuNoise | None = None,
) -> StaticInitResult:
    """Static initialisation from ``window`` (IMU samples of a platform at rest; see module doc)."""
    cfg = StaticInitConfig() if config is None else config
    still = detect_standstill(window, cfg.standstill)
    n = len(window)
    duration = (int(window.stamps_ns[-1]) - int(window.stamps_ns[0])) * 1e-9 if n else 0.0
    if not still.still:
        return StaticInitResult(StaticInitStatus.NOT_STILL, still, duration)
    gyro = np.asarray(window.gyro_rad_s)
    accel = np.asarray(window.accel_m_s2)
    g_cov = _mean_cov(gyro, cfg.n_batches)
    a_cov = _mean_cov(accel, cfg.n_batches)
    if noise is not None:  # white noise of the mean: sigma_d^2 / N per axis
        sg, sa = noise.discrete_sigmas()
        g_cov = g_cov + np.diag(np.maximum(0.0, sg * sg / n - np.diag(g_cov)))
        a_cov = a_cov + np.diag(np.maximum(0.0, sa * sa / n - np.diag(a_cov)))
    f = accel.mean(axis=0)
    f_norm = float(np.linalg.norm(f))
    up = f / f_norm
    P = np.eye(3) - np.outer(up, up)  # across gravity
    tilt_noise_var = float(np.trace(P @ a_cov @ P)) / f_norm**2  # both tilt components
    tilt_var = tilt_noise_var + 2.0 * (cfg.accel_bias_sigma_m_s2 / f_norm) ** 2
    up_var = float(up @ a_cov @ up) + cfg.gravity_sigma_m_s2**2
    return StaticInitResult(
        status=StaticInitStatus.OK,
        standstill=still,
        duration_s=duration,
        R_world_body=_ro(gravity_aligned_rotation(up)),
        gravity_body=_ro(-up),
        tilt_std_deg=math.degrees(math.sqrt(tilt_var)),
        tilt_noise_std_deg=math.degrees(math.sqrt(tilt_noise_var)),
        gyro_bias_rad_s=_ro(gyro.mean(axis=0)),
        gyro_bias_std_rad_s=_ro(np.sqrt(np.diag(g_cov))),
        accel_bias_up_m_s2=f_norm - cfg.standstill.gravity_m_s2,
        accel_bias_up_std_m_s2=math.sqrt(up_var),
    )


GROW_STEP_NS = 500_000_000
""":func:`initial_static_init` grows its window by this much at a time."""


def initial_static_init(
    imu: ImuData,
    config: StaticInitConfig | None = None,
    noise: ImuNoise | None = None,
) -> StaticInitResult:
    """:func:`static_init` on the longest still stretch at the start of ``imu``.

    The first ``standstill.window_s`` must be still; the window then grows by 0.5 s while the
    new half second is still on its own and the grown window stays still, up to
    ``max_window_s``.
    """
    cfg = StaticInitConfig() if config is None else config
    if len(imu) == 0:
        return static_init(imu, cfg, noise)
    t0 = int(imu.stamps_ns[0])
    t1 = t0 + int(round(cfg.standstill.window_s * 1e9))
    t_max = min(t0 + int(round(cfg.max_window_s * 1e9)), int(imu.stamps_ns[-1]))
    if not detect_standstill(imu.window(t0, t1), cfg.standstill).still:
        return static_init(imu.window(t0, t1), cfg, noise)
    while t1 + GROW_STEP_NS <= t_max:
        chunk = imu.window(t1, t1 + GROW_STEP_NS)
        grown = imu.window(t0, t1 + GROW_STEP_NS)
        if not (detect_standstill(chunk, cfg.standstill).still and detect_standstill(grown, cfg.standstill).still):
            break
        t1 += GROW_STEP_NS
    return static_init(imu.window(t0, t1), cfg, noise)
