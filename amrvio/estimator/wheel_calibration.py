"""Wheel-radius calibration from a visual-inertial run: how far the wheels say the robot drove per
metre that the VIO says it drove, on straight stretches.

A wheel-radius error (tyre wear, pressure, load) scales every wheel reading alike, and at constant
velocity, where the IMU cannot see the scale, that error goes straight into the trajectory's
scale. Where the robot accelerates, the IMU gives the VIO a metric scale of its own, independent
of the wheels as long as they are not fused (no ``--wheels``). So one run over an excited drive
(start, stop, turn) calibrates the wheels for later runs of the same robot
(``scale.wheel.factor``).

The comparison uses straight stretches only: the body's heading stays within ``max_turn_deg`` of
the stretch's first pose, so the straight line between the VIO's end positions is the path the
wheels drove (at 3 degrees the chord is at least cos 3 deg = 99.86 % of the path), and the wheels'
distance is the integral of their signed speed. The factor is the sum of the wheel distances over
the sum of the VIO's, so that long stretches weigh most; it is reported only when the stretches
add up to ``min_total_m`` of driving, and it is as good as the VIO's scale over them.
"""

from __future__ import annotations

import dataclasses
import enum
import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from amrvio.types.lie import so3_log
from amrvio.types.sensors import WheelData

F64 = NDArray[np.float64]
I64 = NDArray[np.int64]


@dataclass(frozen=True, slots=True)
class WheelCalibrationConfig:
    """``max_turn_deg``: largest heading change within a straight stretch; ``min_stretch_m``:
    shorter stretches (wheel distance) are left out, their end positions' noise is too large a
    part of them; ``min_total_m``: straight driving needed for a factor."""

    max_turn_deg: float = 3.0
    min_stretch_m: float = 0.5
    min_total_m: float = 2.0


class WheelCalibrationStatus(enum.Enum):
    OK = "ok"
    TOO_LITTLE_STRAIGHT_DRIVING = "too_little_straight_driving"
    WHEELS_USED = "wheels_used"


@dataclass(frozen=True, slots=True)
class Stretch:
    """A straight stretch: its first and last record, the wheels' distance and the VIO's (m)."""

    first: int
    last: int
    wheel_m: float
    vio_m: float


@dataclass(frozen=True, slots=True)
class WheelCalibration:
    """``factor``: metres the wheels read per metre driven (NaN unless OK), already including the
    ``applied`` factor the run's wheel readings were divided by; ``stretches``: those used."""

    status: WheelCalibrationStatus
    factor: float
    applied: float
    stretches: tuple[Stretch, ...]

    @property
    def wheel_m(self) -> float:
        return float(sum(s.wheel_m for s in self.stretches))

    @property
    def vio_m(self) -> float:
        return float(sum(s.vio_m for s in self.stretches))

    def advice(self) -> str:
        """One line for advice.txt."""
        if self.status is WheelCalibrationStatus.WHEELS_USED:
            return ("wheel calibration: not measured, the wheels were used in this run; run once "
                    "without --wheels over a drive that starts, stops and turns to calibrate them")
        if self.status is not WheelCalibrationStatus.OK:
            return (f"wheel calibration: only {self.wheel_m:.2f} m of straight driving after the VIO "
                    f"started, too little; drive straight for a few metres, with starts and stops")
        return (f"wheel calibration: the wheels read {100.0 * (self.factor - 1.0):+.2f} % against the VIO over "
                f"{self.wheel_m:.2f} m of straight driving ({len(self.stretches)} stretches); for later runs "
                f"of this robot with --wheels, pass --wheel-factor {self.factor:.4f}")

    def as_dict(self) -> dict[str, Any]:
        return {"status": self.status.value, "factor": self.factor if math.isfinite(self.factor) else None,
                "applied": self.applied, "wheel_m": round(self.wheel_m, 6), "vio_m": round(self.vio_m, 6),
                "stretches": [[s.first, s.last, round(s.wheel_m, 6), round(s.vio_m, 6)] for s in self.stretches]}


def straight_stretches(stamps_ns: I64, T_world_body: F64, first: int, wheel: WheelData,
                       config: WheelCalibrationConfig) -> list[Stretch]:
    """The straight stretches of the body trajectory from record ``first`` on (records without a
    pose, NaN, end a stretch) that the wheel readings cover and that moved at least
    ``min_stretch_m`` by the wheels."""
    n = len(stamps_ns)
    ok = np.all(np.isfinite(T_world_body.reshape(n, -1)), axis=1)
    max_turn = math.radians(config.max_turn_deg)
    out: list[Stretch] = []
    i = first
    while i < n - 1:
        if not ok[i]:
            i += 1
            continue
        R0 = T_world_body[i, :3, :3]
        j = i
        while j + 1 < n and ok[j + 1] and np.linalg.norm(so3_log(R0.T @ T_world_body[j + 1, :3, :3])) <= max_turn:
            j += 1
        if j > i:
            along = abs(wheel.displacement_m(int(stamps_ns[i]), int(stamps_ns[j])))
            if along >= config.min_stretch_m:  # False for NaN: the readings do not cover it
                vio = float(np.linalg.norm(T_world_body[j, :3, 3] - T_world_body[i, :3, 3]))
                out.append(Stretch(i, j, along, vio))
        i = j + 1 if j > i else i + 1
    return out


def calibrate_wheel(stamps_ns: I64, T_world_body: F64, first: int, wheel: WheelData, *,
                    applied: float = 1.0, wheels_used: bool = False,
                    config: WheelCalibrationConfig | None = None) -> WheelCalibration:
    """The wheel factor from the VIO's body trajectory (``T_world_body`` (N, 4, 4) at
    ``stamps_ns``, visual-inertial from record ``first`` on) and the run's wheel readings, which
    were divided by ``applied``. ``wheels_used``: the VIO fused the wheels, so its scale is not
    independent of them and no factor is given."""
    if wheels_used:
        return WheelCalibration(WheelCalibrationStatus.WHEELS_USED, float("nan"), applied, ())
    cfg = config or WheelCalibrationConfig()
    stretches = tuple(straight_stretches(np.asarray(stamps_ns, dtype=np.int64), T_world_body, first, wheel, cfg))
    cal = WheelCalibration(WheelCalibrationStatus.TOO_LITTLE_STRAIGHT_DRIVING, float("nan"), applied, stretches)
    if cal.wheel_m < cfg.min_total_m or cal.vio_m <= 0:
        return cal
    return dataclasses.replace(cal, status=WheelCalibrationStatus.OK, factor=applied * cal.wheel_m / cal.vio_m)


__all__ = ["Stretch", "WheelCalibration", "WheelCalibrationConfig", "WheelCalibrationStatus", "calibrate_wheel",
           "straight_stretches"]
