"""Sensor value types: camera frames (lazily loaded), IMU samples and IMU noise specifications."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike, NDArray

from amrvio.errors import DatasetFormatError, ShapeError

F64 = NDArray[np.float64]
U8 = NDArray[np.uint8]


def _ro(a: ArrayLike, dtype: type) -> NDArray[np.generic]:
    out: NDArray[np.generic] = np.array(a, dtype=dtype, copy=True)
    out.setflags(write=False)
    return out


@dataclass(frozen=True, slots=True, eq=False)
class ImuSample:
    """One IMU reading at ``t_ns``: angular rate (rad/s) and specific force (m/s^2), body frame."""

    t_ns: int
    gyro_rad_s: F64
    accel_m_s2: F64


@dataclass(frozen=True, slots=True, eq=False)
class ImuData:
    """A stream of IMU readings. stamps_ns: (N,) int64 increasing; gyro/accel: (N, 3)."""

    stamps_ns: NDArray[np.int64]
    gyro_rad_s: F64
    accel_m_s2: F64

    def __post_init__(self) -> None:
        t = np.asarray(self.stamps_ns)
        g = np.asarray(self.gyro_rad_s, dtype=np.float64)
        a = np.asarray(self.accel_m_s2, dtype=np.float64)
        n = t.shape[0] if t.ndim == 1 else -1
        if t.ndim != 1 or g.shape != (n, 3) or a.shape != (n, 3):
            raise ShapeError(f"IMU arrays must be (N,), (N,3), (N,3); got {t.shape}, {g.shape}, {a.shape}")
        if not (np.all(np.isfinite(g)) and np.all(np.isfinite(a))):
            raise ShapeError("IMU data contain non-finite values")
        if n > 1 and np.any(np.diff(t) <= 0):
            raise ShapeError("IMU stamps are not strictly increasing")
        object.__setattr__(self, "stamps_ns", _ro(t, np.int64))
        object.__setattr__(self, "gyro_rad_s", _ro(g, np.float64))
        object.__setattr__(self, "accel_m_s2", _ro(a, np.float64))

    def __len__(self) -> int:
        return int(self.stamps_ns.shape[0])

    def sample(self, i: int) -> ImuSample:
        return ImuSample(int(self.stamps_ns[i]), self.gyro_rad_s[i], self.accel_m_s2[i])

    def window(self, t0_ns: int, t1_ns: int) -> ImuData:
        """Samples with t0_ns <= t <= t1_ns."""
        lo = int(np.searchsorted(self.stamps_ns, t0_ns, side="left"))
        hi = int(np.searchsorted(self.stamps_ns, t1_ns, side="right"))
        return ImuData(self.stamps_ns[lo:hi], self.gyro_rad_s[lo:hi], self.accel_m_s2[lo:hi])

    @property
    def stamps_s(self) -> F64:
        return self.stamps_ns.astype(np.float64) * 1e-9


@dataclass(frozen=True, slots=True, eq=False)
class WheelData:
    """Wheel odometry of a ground robot: stamps_ns (N,) int64 strictly increasing, the forward
    speed of the base (m/s) and its yaw rate (rad/s), both (N,)."""

    stamps_ns: NDArray[np.int64]
    v_forward_m_s: F64
    yaw_rate_rad_s: F64

    def __post_init__(self) -> None:
        t = np.asarray(self.stamps_ns)
        v = np.asarray(self.v_forward_m_s, dtype=np.float64)
        w = np.asarray(self.yaw_rate_rad_s, dtype=np.float64)
        if t.ndim != 1 or v.shape != t.shape or w.shape != t.shape:
            raise ShapeError(f"wheel arrays must all be (N,); got {t.shape}, {v.shape}, {w.shape}")
        if not (np.all(np.isfinite(v)) and np.all(np.isfinite(w))):
            raise ShapeError("wheel odometry contains non-finite values")
        if t.shape[0] > 1 and np.any(np.diff(t) <= 0):
            raise ShapeError("wheel odometry stamps are not strictly increasing")
        object.__setattr__(self, "stamps_ns", _ro(t, np.int64))
        object.__setattr__(self, "v_forward_m_s", _ro(v, np.float64))
        object.__setattr__(self, "yaw_rate_rad_s", _ro(w, np.float64))

    def __len__(self) -> int:
        return int(self.stamps_ns.shape[0])

    def divided(self, factor: float) -> WheelData:
        """The readings divided by ``factor`` (a wheel-radius calibration: metres read per metre
        driven scale the speed and the yaw rate of a differential drive alike)."""
        return WheelData(self.stamps_ns, self.v_forward_m_s / factor, self.yaw_rate_rad_s / factor)

    def distance_m(self, t0_ns: int, t1_ns: int) -> float:
        """Path length (m) driven in [t0_ns, t1_ns]: the integral of |speed|, linear between
        readings (trapezoids; the speed at t0 and t1 interpolated). NaN when the readings do not
        cover the interval."""
        return self._integral(t0_ns, t1_ns, signed=False)

    def displacement_m(self, t0_ns: int, t1_ns: int) -> float:
        """The integral of the signed forward speed over [t0_ns, t1_ns], as :meth:`distance_m`:
        on a straight line the displacement, whatever the stops and reversals (the speed's noise
        at a standstill averages out instead of adding up)."""
        return self._integral(t0_ns, t1_ns, signed=True)

    def _integral(self, t0_ns: int, t1_ns: int, signed: bool) -> float:
        t = self.stamps_ns
        if len(self) < 2 or t0_ns < t[0] or t1_ns > t[-1] or t1_ns < t0_ns:
            return float("nan")
        lo = int(np.searchsorted(t, t0_ns, side="right"))
        hi = int(np.searchsorted(t, t1_ns, side="left"))
        ts = np.concatenate([[t0_ns], t[lo:hi], [t1_ns]]).astype(np.float64) * 1e-9
        speed = np.interp(ts, t.astype(np.float64) * 1e-9, self.v_forward_m_s)
        speed = speed if signed else np.abs(speed)
        return float(np.sum(0.5 * (speed[1:] + speed[:-1]) * np.diff(ts)))


@dataclass(frozen=True, slots=True)
class ImuNoise:
    """Continuous-time IMU noise (Kalibr/EuRoC convention).

    gyro_noise_density [rad/s/sqrt(Hz)], gyro_random_walk [rad/s^2/sqrt(Hz)],
    accel_noise_density [m/s^2/sqrt(Hz)], accel_random_walk [m/s^3/sqrt(Hz)], rate_hz [Hz].
    """

    gyro_noise_density: float
    gyro_random_walk: float
    accel_noise_density: float
    accel_random_walk: float
    rate_hz: float = 200.0

    def __post_init__(self) -> None:
        for name in ("gyro_noise_density", "gyro_random_walk", "accel_noise_density",
                     "accel_random_walk", "rate_hz"):
            v = float(getattr(self, name))
            if not np.isfinite(v) or v < 0 or (name == "rate_hz" and v <= 0):
                raise ShapeError(f"IMU noise {name} must be finite and non-negative, got {v}")

    @staticmethod
    def euroc_adis16448() -> ImuNoise:
        """The ADIS16448 densities of the EuRoC MAV dataset (imu0/sensor.yaml)."""
        return ImuNoise(1.6968e-04, 1.9393e-05, 2.0000e-3, 3.0000e-3, 200.0)

    def discrete_sigmas(self) -> tuple[float, float]:
        """Per-sample white-noise sigmas (gyro, accel) = density * sqrt(rate)."""
        r = np.sqrt(self.rate_hz)
        return float(self.gyro_noise_density * r), float(self.accel_noise_density * r)


def _read_grey(path: Path) -> U8:
    import cv2

    img = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    if img is None:
        if not path.exists():
            raise DatasetFormatError(path, "image file is missing")
        raise DatasetFormatError(path, "image cannot be decoded")
    if img.ndim == 3:
        code = cv2.COLOR_BGRA2GRAY if img.shape[2] == 4 else cv2.COLOR_BGR2GRAY
        img = cv2.cvtColor(img, code)
    if img.dtype == np.uint16:
        img = (img >> 8).astype(np.uint8)
    if img.dtype != np.uint8:
        raise DatasetFormatError(path, f"unsupported image depth {img.dtype}")
    return np.asarray(img, dtype=np.uint8)


@dataclass(frozen=True, slots=True)
class Frame:
    """One camera frame at ``t_ns``; the image is read only when :meth:`load` is called.

    ``loader`` (optional) reads images that are not plain files (zip members, bag messages).
    ``exposure_s`` is the exposure time when the dataset records it.
    """

    t_ns: int
    index: int
    path: Path | None = None
    exposure_s: float | None = None
    loader: Callable[[], U8] | None = field(default=None, compare=False, repr=False)

    @property
    def t_s(self) -> float:
        return self.t_ns * 1e-9

    def load(self) -> U8:
        """The (H, W) uint8 grey image. Raises DatasetFormatError if it cannot be read."""
        if self.loader is not None:
            return self.loader()
        if self.path is None:
            raise DatasetFormatError("<frame>", f"frame {self.index} has neither a path nor a loader")
        return _read_grey(self.path)
