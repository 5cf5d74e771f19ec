"""The recent IMU samples of the frame loop, kept for the VIO stage's initialisations and for
frames that come without samples of their own."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from amrvio.diagnostics.smear import integrate_gyro
from amrvio.types.sensors import ImuData

F64 = NDArray[np.float64]
I64 = NDArray[np.int64]


class ImuLog:
    """The recent IMU samples (``keep_s`` seconds), for the initialisations and the gyro's
    rotation over the frames the tracker skipped."""

    def __init__(self, keep_s: float) -> None:
        self.keep_ns = int(keep_s * 1e9)
        self.t: list[I64] = []
        self.g: list[F64] = []
        self.a: list[F64] = []
        self.last = -(2**62)
        self.first = -1

    def add(self, imu: ImuData) -> None:
        new = np.asarray(imu.stamps_ns) > self.last
        if not np.any(new):
            return
        self.t.append(np.asarray(imu.stamps_ns)[new])
        self.g.append(np.asarray(imu.gyro_rad_s)[new])
        self.a.append(np.asarray(imu.accel_m_s2)[new])
        self.last = int(self.t[-1][-1])
        if self.first < 0:
            self.first = int(self.t[0][0])
        while len(self.t) > 1 and int(self.t[1][0]) < self.last - self.keep_ns:
            del self.t[0], self.g[0], self.a[0]

    def rotation(self, t0: int, t1: int, R_cam_body: F64, gyro_bias: F64 | None) -> F64 | None:
        """``R_cam1_cam0`` (3, 3): the camera's rotation from ``t0`` to ``t1`` by the gyro (rates
        less ``gyro_bias``, rotated by ``R_cam_body``); None when the log does not cover
        [t0, t1 - 20 ms]."""
        span = self.span(t0 - 20_000_000, t1 + 20_000_000)
        t = np.asarray(span.stamps_ns)
        if t.size < 2 or t[0] > t0 or t[-1] < t1 - 20_000_000:
            return None
        R_c0_c1 = integrate_gyro(t, np.asarray(span.gyro_rad_s), t0, t1, R_cam_body, gyro_bias)
        return np.asarray(R_c0_c1.T)

    def span(self, t0: int, t1: int) -> ImuData:
        if not self.t:
            return ImuData(np.zeros(0, dtype=np.int64), np.zeros((0, 3)), np.zeros((0, 3)))
        return ImuData(np.concatenate(self.t), np.vstack(self.g), np.vstack(self.a)).window(t0, t1)


__all__ = ["ImuLog"]
