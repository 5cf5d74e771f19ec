"""Replay of a recorded trajectory as a continuous-time Motion (spline with analytic derivatives).

Positions: a cubic spline per axis (interpolating by default, so it passes through every recorded
pose; ``smoothing > 0`` uses a penalised smoothing spline, scipy ``make_smoothing_spline``).
Attitude: scipy ``RotationSpline`` (cubic in the rotation-vector increments, C2), whose first
derivative is the body-frame angular rate. Motion time 0 is the source stamp ``t0_ns``.

A recorded IMU CSV (EuRoC imu0 layout, read by amrvio.io.base.read_imu_csv) may replace the
synthetic IMU.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from amrvio.errors import ConfigError
from amrvio.sim.kinematics import MotionState, _MotionBase, _times
from amrvio.types.lie import quat_wxyz_to_matrix

F64 = NDArray[np.float64]
I64 = NDArray[np.int64]


@dataclass(frozen=True, slots=True, eq=False)
class ReplayMotion(_MotionBase):
    """A recorded trajectory T_world_body as a Motion on [0, duration_s]; t = (stamp - t0_ns) / 1e9.

    ``gyro_bias_at`` / ``accel_bias_at`` give the source's recorded biases (linear interpolation)
    when the source file has them.
    """

    t0_ns: int
    duration: float
    _pos: Any  # callable spline(t, nu) -> (N,3)
    _rot: Any  # scipy RotationSpline
    _knots_t: F64
    _gyro_bias: F64 | None
    _accel_bias: F64 | None

    @property
    def duration_s(self) -> float:
        return self.duration

    def states(self, t_s: ArrayLike) -> MotionState:
        t = _times(t_s)
        return MotionState(
            t_s=t,
            R_world_body=np.asarray(self._rot(t).as_matrix()).reshape(-1, 3, 3),
            p_world=np.asarray(self._pos(t, 0)).reshape(-1, 3),
            v_world=np.asarray(self._pos(t, 1)).reshape(-1, 3),
            a_world=np.asarray(self._pos(t, 2)).reshape(-1, 3),
            omega_body=np.asarray(self._rot(t, 1)).reshape(-1, 3),
        )

    def _interp(self, table: F64 | None, t_s: ArrayLike) -> F64 | None:
        if table is None:
            return None
        t = _times(t_s)
        return np.stack([np.interp(t, self._knots_t, table[:, k]) for k in range(3)], axis=-1)

    def gyro_bias_at(self, t_s: ArrayLike) -> F64 | None:
        return self._interp(self._gyro_bias, t_s)

    def accel_bias_at(self, t_s: ArrayLike) -> F64 | None:
        return self._interp(self._accel_bias, t_s)


class _SmoothingSpline3:
    """Three scipy smoothing splines behind the CubicSpline call signature f(t, nu)."""

    def __init__(self, t: F64, p: F64, lam: float) -> None:
        from scipy.interpolate import make_smoothing_spline

        self._s = [make_smoothing_spline(t, p[:, k], lam=lam) for k in range(3)]

    def __call__(self, t: F64, nu: int = 0) -> F64:
        return np.stack([s(t, nu) if nu == 0 else s.derivative(nu)(t) for s in self._s], axis=-1)


def load_groundtruth(path: Path) -> tuple[I64, F64, F64, F64 | None, F64 | None]:
    """(stamps_ns, positions (N,3), quats_wxyz (N,4), gyro_bias | None, accel_bias | None) from an
    EuRoC CSV or a TUM file (via amrvio.io.trajectory)."""
    from amrvio.io.trajectory import detect_format, read_euroc_csv, read_trajectory

    fmt = detect_format(path)
    if fmt == "euroc":
        gt = read_euroc_csv(path)
        tr = gt.trajectory
        return gt.stamps_ns, tr.positions_m, tr.quats_wxyz, gt.gyro_bias, gt.accel_bias
    if fmt == "tum":
        tr = read_trajectory(path, "tum")
        return np.round(tr.stamps_s * 1e9).astype(np.int64), tr.positions_m, tr.quats_wxyz, None, None
    raise ConfigError(f"{path}: replay needs an EuRoC CSV or a TUM trajectory, not {fmt}")


def make_replay_motion(
    stamps_ns: ArrayLike,
    positions_m: ArrayLike,
    quats_wxyz: ArrayLike,
    start_s: float = 0.0,
    duration_s: float | None = None,
    smoothing: float = 0.0,
    gyro_bias: ArrayLike | None = None,
    accel_bias: ArrayLike | None = None,
    margin_s: float = 1.0,
) -> ReplayMotion:
    """Spline the recorded poses. Motion time 0 is the first recorded stamp at or after
    ``stamps_ns[0] + start_s``; the duration is ``duration_s`` or what the record holds.
    Poses within ``margin_s`` outside the window also support the spline (no end effects)."""
    from scipy.interpolate import CubicSpline
    from scipy.spatial.transform import Rotation, RotationSpline

    ns = np.asarray(stamps_ns, dtype=np.int64)
    p = np.asarray(positions_m, dtype=np.float64)
    q = np.asarray(quats_wxyz, dtype=np.float64)
    if ns.ndim != 1 or ns.shape[0] < 4 or p.shape != (ns.shape[0], 3) or q.shape != (ns.shape[0], 4):
        raise ConfigError("replay needs at least 4 poses with (N,) stamps, (N,3) positions, (N,4) quats")
    i0 = int(np.searchsorted(ns, ns[0] + round(start_s * 1e9), side="left"))
    if i0 >= ns.shape[0] - 2:
        raise ConfigError(f"replay start {start_s} s is past the end of the recorded trajectory")
    t0_ns = int(ns[0 + i0])
    available = (int(ns[-1]) - t0_ns) * 1e-9
    dur = available if duration_s is None else float(duration_s)
    if not (dur > 0 and math.isfinite(dur)):
        raise ConfigError(f"replay duration must be > 0 s, got {duration_s}")
    if dur > available + 1e-9:
        raise ConfigError(
            f"replay asks for {dur:.3f} s from {start_s} s but the trajectory holds {available:.3f} s"
        )
    lo = int(np.searchsorted(ns, t0_ns - round(margin_s * 1e9), side="left"))
    hi = int(np.searchsorted(ns, t0_ns + round((dur + margin_s) * 1e9), side="right"))
    sel = slice(lo, hi)
    # exact integer differences, then seconds (no precision loss from 1e18 ns stamps)
    t_knots = (ns[sel] - t0_ns).astype(np.float64) * 1e-9
    pos: Any
    if smoothing > 0:
        pos = _SmoothingSpline3(t_knots, p[sel], smoothing)
    else:
        pos = CubicSpline(t_knots, p[sel], axis=0, bc_type="not-a-knot")
    R = quat_wxyz_to_matrix(q[sel])
    rot = RotationSpline(t_knots, Rotation.from_matrix(R))
    bg = None if gyro_bias is None else np.asarray(gyro_bias, dtype=np.float64)[sel]
    ba = None if accel_bias is None else np.asarray(accel_bias, dtype=np.float64)[sel]
    return ReplayMotion(t0_ns, dur, pos, rot, t_knots, bg, ba)
