"""Metric scale from wheel odometry (seed section 6.1): the distance the wheels drove between two
keyframes against the distance the camera moved in the map.

A ground robot's wheels give the path length at any speed, including the constant velocity at
which an IMU cannot tell scale. For each pair of consecutive keyframes of a map segment the
reading is ``scale = d_wheel / d_map``: ``d_wheel`` the integral of the signed wheel speed between
the keyframes' times (a displacement, as ``d_map``; the speed's noise over a stop between two
keyframes nets out, where its absolute value adds 0.8 cm per second at the simulator's 1 cm/s),
``d_map`` the distance between their (bundle-adjusted) camera centres in global
units. Pairs are left out when the robot barely moved (``min_distance_m``; the map distance is
then mostly noise) or turned by more than ``max_turn_deg`` (the camera, mounted off the axle,
then moves along a different path from the wheels). The readings are combined by a running
median over keyframes of the same segment (a wheel slip is an outlier), interpolated to frames.
A wheel-radius error scales every reading alike: calibrate it, or expect that error in the scale.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from amrvio.errors import ConfigError
from amrvio.estimator.camera_height import HeightEstimate
from amrvio.estimator.local_mapping import Segment
from amrvio.types.lie import se3_matrix_inverse, so3_log
from amrvio.types.sensors import WheelData

F64 = NDArray[np.float64]
I64 = NDArray[np.int64]


@dataclass(frozen=True, slots=True)
class WheelScaleConfig:
    """``enabled``: use the recording's wheel odometry (it then replaces the camera height as the
    scale source). Off by default: a wheel file does not say that the camera rides on a
    non-holonomic ground robot (the simulator writes one for hand-held motions too), and only
    then is the wheel distance the camera's path; ``min_distance_m``: wheel distance between keyframes below which
    a pair gives no reading; ``max_turn_deg``: a larger rotation between the keyframes gives none
    either; ``half_window``: keyframe readings on each side of the running median; ``factor``:
    metres the wheels read per metre driven, a wheel-radius calibration (``wheel_calibration``
    in summary.json of a run without wheels, :mod:`amrvio.estimator.wheel_calibration`): every
    wheel reading is divided by it, here and in the VIO."""

    enabled: bool = False
    min_distance_m: float = 0.05
    max_turn_deg: float = 10.0
    half_window: int = 10
    factor: float = 1.0

    def __post_init__(self) -> None:
        if not (math.isfinite(self.factor) and 0.5 <= self.factor <= 2.0):
            raise ConfigError(f"scale.wheel.factor must be in [0.5, 2], got {self.factor}")


@dataclass(frozen=True, slots=True)
class WheelReading:
    """One keyframe pair: the later keyframe's frame index, its segment, the wheel and map
    distances (m, global units) and ``scale = wheel_m / map_units`` (NaN when left out)."""

    frame_index: int
    segment: int
    wheel_m: float
    map_units: float
    scale: float


class WheelScale:
    """Scale source from wheel odometry; keyframes are read at the end, with their final poses."""

    def __init__(self, wheel: WheelData, config: WheelScaleConfig) -> None:
        self.wheel = wheel
        self.cfg = config
        self.readings: list[HeightEstimate] = []  # none: this source reads no ground plane
        self.wheel_readings: list[WheelReading] = []
        self.timings: dict[str, float] = {}
        self._segments: list[Segment] = []

    @property
    def active(self) -> bool:
        return True

    def observe_keyframe(self, segment: Segment, kf_id: int) -> HeightEstimate | None:
        """Remember the segment (its keyframes are read by :meth:`frame_scales`)."""
        if all(s is not segment for s in self._segments):
            self._segments.append(segment)
        return None

    def frame_scales(self, n_frames: int, stamps_ns: I64 | None = None) -> F64:
        """(n_frames,) metric scale per frame from the keyframe pairs of every segment seen
        (ones without a valid reading); ``stamps_ns`` (n_frames,) the frame times."""
        t0 = time.perf_counter()
        if stamps_ns is None or len(stamps_ns) != n_frames:
            return np.ones(n_frames)
        self.wheel_readings = [r for k, sg in enumerate(self._segments)
                               for r in _pair_readings(sg, k, self.wheel, stamps_ns, self.cfg)]
        out = _smooth(self.wheel_readings, n_frames, self.cfg.half_window)
        self.timings["scale"] = self.timings.get("scale", 0.0) + time.perf_counter() - t0
        return out


def _pair_readings(segment: Segment, seg_id: int, wheel: WheelData, stamps_ns: I64,
                   cfg: WheelScaleConfig) -> list[WheelReading]:
    kfs = segment.mapper.map.keyframes
    s = segment.world_from_segment.s
    out = []
    for a, b in zip(kfs[:-1], kfs[1:], strict=True):
        if b.frame_index >= len(stamps_ns):
            continue
        # the signed integral: the map distance is the straight line between the keyframes, and the
        # speed's noise over a stop between them averages out instead of adding up
        d_wheel = abs(wheel.displacement_m(int(stamps_ns[a.frame_index]), int(stamps_ns[b.frame_index])))
        T_ba = b.T_cam_world @ se3_matrix_inverse(a.T_cam_world)
        d_map = s * float(np.linalg.norm(T_ba[:3, 3]))  # |c_b - c_a| = |t_ba|
        turn = math.degrees(float(np.linalg.norm(so3_log(T_ba[:3, :3]))))
        ok = (math.isfinite(d_wheel) and d_wheel >= cfg.min_distance_m and d_map > 0
              and turn <= cfg.max_turn_deg)
        out.append(WheelReading(b.frame_index, seg_id, d_wheel, d_map,
                                d_wheel / d_map if ok else float("nan")))
    return out


def _smooth(readings: list[WheelReading], n_frames: int, half_window: int) -> F64:
    """Running median of the valid readings over keyframes of the same segment, linearly
    interpolated between keyframes and held at the ends (ones when there is none)."""
    valid = sorted((r for r in readings if math.isfinite(r.scale)), key=lambda r: r.frame_index)
    if not valid:
        return np.ones(n_frames)
    seg = np.array([r.segment for r in valid])
    s = np.array([r.scale for r in valid])
    sm = []
    for i in range(len(valid)):
        same = np.flatnonzero(seg == seg[i])
        j = int(np.searchsorted(same, i))
        sm.append(float(np.median(s[same[max(0, j - half_window): j + half_window + 1]])))
    idx = np.array([r.frame_index for r in valid], dtype=np.float64)
    return np.asarray(np.interp(np.arange(n_frames, dtype=np.float64), idx, np.array(sm)),
                      dtype=np.float64)


__all__ = ["WheelReading", "WheelScale", "WheelScaleConfig"]
