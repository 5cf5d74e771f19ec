"""Wheel odometry of a ground robot: forward speed along the body x axis and yaw rate about the
body z axis, at their own stamps (the layout ``amrvio simulate`` writes as ``wheel_odometry.csv``
beside ``mav0/``: ``timestamp_ns,v_forward_m_s,yaw_rate_rad_s[,...]``; further columns, such as
the simulator's true values, are ignored)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from amrvio.errors import DatasetFormatError

F64 = NDArray[np.float64]
I64 = NDArray[np.int64]

WHEEL_FILE = "wheel_odometry.csv"
"""The file name the readers look for, beside ``mav0/``."""


@dataclass(frozen=True, slots=True, eq=False)
class WheelData:
    """``stamps_ns`` (N,) increasing, ``v_forward_m_s`` (N,) and ``yaw_rate_rad_s`` (N,)."""

    stamps_ns: I64
    v_forward_m_s: F64
    yaw_rate_rad_s: F64

    def __len__(self) -> int:
        return int(self.stamps_ns.shape[0])

    def distance_m(self, t0_ns: int, t1_ns: int) -> float:
        """Distance travelled over [t0, t1] (trapezoidal integral of the forward speed, linear
        between readings; NaN when the readings do not cover the interval)."""
        t = self.stamps_ns
        if len(t) < 2 or t0_ns < int(t[0]) or t1_ns > int(t[-1]) or t1_ns <= t0_ns:
            return float("nan")
        grid = np.concatenate([[t0_ns], t[(t > t0_ns) & (t < t1_ns)], [t1_ns]]).astype(np.int64)
        v = np.interp(grid.astype(np.float64), t.astype(np.float64), self.v_forward_m_s)
        dt = np.diff(grid).astype(np.float64) * 1e-9
        return float(np.sum(0.5 * (v[1:] + v[:-1]) * dt))

    def speed_at(self, t_ns: int) -> float:
        """The forward speed at ``t_ns`` (linear between readings; NaN outside them)."""
        t = self.stamps_ns
        if len(t) < 2 or t_ns < int(t[0]) or t_ns > int(t[-1]):
            return float("nan")
        return float(np.interp(float(t_ns), t.astype(np.float64), self.v_forward_m_s))


def read_wheel_csv(path: Path) -> WheelData:
    """Read a wheel-odometry CSV (module docstring); a bad line is a DatasetFormatError naming it."""
    stamps: list[int] = []
    v: list[float] = []
    w: list[float] = []
    for i, line in enumerate(path.read_text(encoding="utf-8").splitlines(), start=1):
        text = line.strip()
        if not text or text.startswith("#") or text.startswith("timestamp"):
            continue
        parts = text.split(",")
        try:
            t, vf, yr = int(parts[0]), float(parts[1]), float(parts[2])
        except (ValueError, IndexError):
            raise DatasetFormatError(path, "expected timestamp_ns,v_forward_m_s,yaw_rate_rad_s", line=i) from None
        if not (np.isfinite(vf) and np.isfinite(yr)):
            raise DatasetFormatError(path, "speed and yaw rate must be finite", line=i)
        if stamps and t <= stamps[-1]:
            raise DatasetFormatError(path, f"timestamps must increase ({t} after {stamps[-1]})", line=i)
        stamps.append(t)
        v.append(vf)
        w.append(yr)
    return WheelData(np.array(stamps, dtype=np.int64), np.array(v), np.array(w))


__all__ = ["WHEEL_FILE", "WheelData", "read_wheel_csv"]
