"""Continuous-time body trajectories with exact first and second derivatives: the building blocks.

World frame: z up, floor at z = 0, gravity (0, 0, -9.81). Body frame = IMU frame, x forward,
y left, z up. Every motion is built from scalar signals whose value, first and second
derivatives are closed forms, so the synthetic IMU (amrvio.sim.imu_synth) is exact.

Attitude is R_world_body = Rz(yaw) Ry(pitch) Rx(roll) (ZYX Euler angles); the body angular
rate follows from the exact Euler-rate map (e.g. Titterton & Weston, eq. 3.52).

The motions themselves are made in amrvio.sim.motion (make_motion) and, for the wheeled-robot
paths that follow their heading, amrvio.sim.motions_robot.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Protocol, runtime_checkable

import numpy as np
from numpy.typing import ArrayLike, NDArray

from amrvio.errors import ShapeError
from amrvio.types.lie import SE3, SO3

F64 = NDArray[np.float64]
Triple = tuple[F64, F64, F64]


def _times(t_s: ArrayLike) -> F64:
    t = np.asarray(t_s, dtype=np.float64)
    if t.ndim != 1 or not np.all(np.isfinite(t)):
        raise ShapeError(f"times must be a finite (N,) array, got shape {t.shape}")
    return t


@dataclass(frozen=True, slots=True, eq=False)
class MotionState:
    """Exact kinematic state at N times (all in SI units).

    t_s (N,); R_world_body (N,3,3); p_world (N,3) body origin; v_world (N,3); a_world (N,3)
    (second derivative of p_world, gravity NOT included); omega_body (N,3) angular rate in the
    body frame, R^T dR/dt = hat(omega_body).
    """

    t_s: F64
    R_world_body: F64
    p_world: F64
    v_world: F64
    a_world: F64
    omega_body: F64


@runtime_checkable
class Motion(Protocol):
    """A body trajectory in continuous time, valid on [0, duration_s]."""

    @property
    def duration_s(self) -> float: ...

    def states(self, t_s: ArrayLike) -> MotionState: ...

    def T_world_body(self, t: float) -> SE3: ...

    def velocity_world(self, t: float) -> F64: ...

    def accel_world(self, t: float) -> F64: ...

    def omega_body(self, t: float) -> F64: ...


class _MotionBase:
    """Scalar accessors implemented on top of the vectorised ``states``."""

    def states(self, t_s: ArrayLike) -> MotionState:  # pragma: no cover - overridden
        raise NotImplementedError

    def _one(self, t: float) -> MotionState:
        return self.states(np.array([float(t)]))

    def T_world_body(self, t: float) -> SE3:
        s = self._one(t)
        return SE3(SO3.from_matrix(s.R_world_body[0]), s.p_world[0])

    def velocity_world(self, t: float) -> F64:
        return np.array(self._one(t).v_world[0])

    def accel_world(self, t: float) -> F64:
        return np.array(self._one(t).a_world[0])

    def omega_body(self, t: float) -> F64:
        return np.array(self._one(t).omega_body[0])


# ----------------------------------------------------------------------------------------------
# Scalar signals: value, first and second derivative in closed form.


class Signal(Protocol):
    def eval(self, t: F64) -> Triple:
        """(value, d/dt, d2/dt2) at times t (N,)."""
        ...


@dataclass(frozen=True, slots=True)
class Polynomial:
    """c0 + c1 t + c2 t^2."""

    c0: float = 0.0
    c1: float = 0.0
    c2: float = 0.0

    def eval(self, t: F64) -> Triple:
        return (
            self.c0 + self.c1 * t + self.c2 * t * t,
            self.c1 + 2.0 * self.c2 * t,
            np.full_like(t, 2.0 * self.c2),
        )


@dataclass(frozen=True, slots=True)
class Sines:
    """sum_i a_i sin(2 pi f_i t + phase_i)."""

    amps: tuple[float, ...]
    freqs_hz: tuple[float, ...]
    phases: tuple[float, ...]

    def eval(self, t: F64) -> Triple:
        v = np.zeros_like(t)
        d1 = np.zeros_like(t)
        d2 = np.zeros_like(t)
        for a, f, ph in zip(self.amps, self.freqs_hz, self.phases, strict=True):
            w = 2.0 * math.pi * f
            s, c = np.sin(w * t + ph), np.cos(w * t + ph)
            v += a * s
            d1 += a * w * c
            d2 -= a * w * w * s
        return v, d1, d2


def _min_jerk(tau: F64) -> Triple:
    """Quintic 10t^3 - 15t^4 + 6t^5 on [0,1] and its derivatives (Flash & Hogan 1985)."""
    t2 = tau * tau
    return (
        t2 * tau * (10.0 - 15.0 * tau + 6.0 * t2),
        30.0 * t2 * (1.0 - 2.0 * tau + t2),
        60.0 * tau * (1.0 - 3.0 * tau + 2.0 * t2),
    )


@dataclass(frozen=True, slots=True)
class MinJerkPath:
    """Rest-to-rest minimum-jerk moves between (knot_t[i], value[i]); constant outside.

    Velocity and acceleration are zero at every knot, so the signal is C2.
    """

    knots_t: tuple[float, ...]
    values: tuple[float, ...]

    def eval(self, t: F64) -> Triple:
        kt = np.asarray(self.knots_t)
        kv = np.asarray(self.values)
        i = np.clip(np.searchsorted(kt, t, side="right") - 1, 0, len(kt) - 2)
        h = kt[i + 1] - kt[i]
        tau = np.clip((t - kt[i]) / h, 0.0, 1.0)
        s, ds, dds = _min_jerk(tau)
        dv = kv[i + 1] - kv[i]
        return kv[i] + dv * s, dv * ds / h, dv * dds / (h * h)


def _min_jerk_integral(tau: F64) -> F64:
    """Integral of the min-jerk quintic over [0, tau]: 2.5 t^4 - 3 t^5 + t^6 (1/2 at tau = 1)."""
    t4 = tau**4
    return np.asarray(t4 * (2.5 - 3.0 * tau + tau * tau), dtype=np.float64)


@dataclass(frozen=True, slots=True)
class RateProfile:
    """The integral of a rate that moves rest-to-rest (min-jerk) between (knots_t[i], rates[i]).

    eval gives (value0 + integral of the rate from knots_t[0], rate, d rate / dt), all closed forms:
    on a segment of length h, rate = r_i + (r_i+1 - r_i) s(tau) with the min-jerk s, and the value
    grows by h (r_i tau + (r_i+1 - r_i) S(tau)), S = integral of s. Outside the knots the rate stays
    at its end value (the value grows linearly). The rate is C2, so the value is C3. Used for a
    heading from a yaw-rate profile and for a distance from a speed profile.
    """

    knots_t: tuple[float, ...]
    rates: tuple[float, ...]
    value0: float = 0.0

    def __post_init__(self) -> None:
        kt = np.asarray(self.knots_t, dtype=np.float64)
        if kt.ndim != 1 or kt.size < 2 or len(self.rates) != kt.size or np.any(np.diff(kt) <= 0):
            raise ShapeError("RateProfile needs >= 2 increasing knots and one rate per knot")

    def eval(self, t: F64) -> Triple:
        kt = np.asarray(self.knots_t, dtype=np.float64)
        kr = np.asarray(self.rates, dtype=np.float64)
        h_all = np.diff(kt)
        # value at each knot: a segment adds h (r_i + r_i+1) / 2 (S(1) = 1/2)
        kv = self.value0 + np.concatenate([[0.0], np.cumsum(h_all * 0.5 * (kr[:-1] + kr[1:]))])
        i = np.clip(np.searchsorted(kt, t, side="right") - 1, 0, kt.size - 2)
        h = h_all[i]
        tau_raw = (t - kt[i]) / h
        tau = np.clip(tau_raw, 0.0, 1.0)
        s, ds, _ = _min_jerk(tau)
        dr = kr[i + 1] - kr[i]
        value = kv[i] + h * (kr[i] * tau + dr * _min_jerk_integral(tau))
        # outside [knots_t[0], knots_t[-1]] the rate is constant: extend the value linearly
        value = value + np.where(tau_raw < 0.0, kr[0] * (t - kt[0]), 0.0)
        value = value + np.where(tau_raw > 1.0, kr[-1] * (t - kt[-1]), 0.0)
        return value, kr[i] + dr * s, dr * ds / h


@dataclass(frozen=True, slots=True)
class Burst:
    """A windowed oscillation: amp * sin^2(pi u / dur) * sin(2 pi f u), u = t - t0 in [0, dur]."""

    t0_s: float
    dur_s: float
    amp: float
    freq_hz: float

    def eval(self, t: F64) -> Triple:
        u = t - self.t0_s
        inside = (u >= 0.0) & (u <= self.dur_s)
        k = math.pi / self.dur_s
        w = 2.0 * math.pi * self.freq_hz
        win, dwin, ddwin = np.sin(k * u) ** 2, k * np.sin(2 * k * u), 2 * k * k * np.cos(2 * k * u)
        s, ds, dds = np.sin(w * u), w * np.cos(w * u), -w * w * np.sin(w * u)
        v = self.amp * win * s
        d1 = self.amp * (dwin * s + win * ds)
        d2 = self.amp * (ddwin * s + 2 * dwin * ds + win * dds)
        z = np.zeros_like(t)
        return np.where(inside, v, z), np.where(inside, d1, z), np.where(inside, d2, z)


@dataclass(frozen=True, slots=True)
class Combo:
    """sum_i w_i * signal_i."""

    parts: tuple[tuple[float, Signal], ...]

    def eval(self, t: F64) -> Triple:
        out = [np.zeros_like(t), np.zeros_like(t), np.zeros_like(t)]
        for w, sig in self.parts:
            for k, x in enumerate(sig.eval(t)):
                out[k] = out[k] + w * x
        return out[0], out[1], out[2]


def euler_zyx_matrix(yaw: F64, pitch: F64, roll: F64) -> F64:
    """R = Rz(yaw) Ry(pitch) Rx(roll) for arrays (N,) -> (N,3,3)."""
    cy, sy = np.cos(yaw), np.sin(yaw)
    cp, sp = np.cos(pitch), np.sin(pitch)
    cr, sr = np.cos(roll), np.sin(roll)
    R = np.empty(yaw.shape + (3, 3))
    R[..., 0, 0] = cy * cp
    R[..., 0, 1] = cy * sp * sr - sy * cr
    R[..., 0, 2] = cy * sp * cr + sy * sr
    R[..., 1, 0] = sy * cp
    R[..., 1, 1] = sy * sp * sr + cy * cr
    R[..., 1, 2] = sy * sp * cr - cy * sr
    R[..., 2, 0] = -sp
    R[..., 2, 1] = cp * sr
    R[..., 2, 2] = cp * cr
    return R


def euler_zyx_body_rate(pitch: F64, roll: F64, dyaw: F64, dpitch: F64, droll: F64) -> F64:
    """Body angular rate from ZYX Euler rates (exact), (N,3)."""
    cp, sp = np.cos(pitch), np.sin(pitch)
    cr, sr = np.cos(roll), np.sin(roll)
    return np.stack(
        [droll - dyaw * sp, dpitch * cr + dyaw * cp * sr, -dpitch * sr + dyaw * cp * cr], axis=-1
    )


@dataclass(frozen=True, slots=True, eq=False)
class EulerMotion(_MotionBase):
    """Position from three signals (world x, y, z) and attitude from yaw/pitch/roll signals."""

    name: str
    x: Signal
    y: Signal
    z: Signal
    yaw: Signal
    pitch: Signal
    roll: Signal
    duration: float

    @property
    def duration_s(self) -> float:
        return self.duration

    def states(self, t_s: ArrayLike) -> MotionState:
        t = _times(t_s)
        px, py, pz = self.x.eval(t), self.y.eval(t), self.z.eval(t)
        yaw, pitch, roll = self.yaw.eval(t), self.pitch.eval(t), self.roll.eval(t)
        return MotionState(
            t_s=t,
            R_world_body=euler_zyx_matrix(yaw[0], pitch[0], roll[0]),
            p_world=np.stack([px[0], py[0], pz[0]], axis=-1),
            v_world=np.stack([px[1], py[1], pz[1]], axis=-1),
            a_world=np.stack([px[2], py[2], pz[2]], axis=-1),
            omega_body=euler_zyx_body_rate(pitch[0], roll[0], yaw[1], pitch[1], roll[1]),
        )


# ----------------------------------------------------------------------------------------------
# Where a motion may go, and the yaw bursts added to it.


@dataclass(frozen=True, slots=True)
class MotionLayout:
    """Where a motion may go inside a scene.

    start_xy: body start position on the floor plan; heading_rad: initial heading (yaw);
    free_length_m: free straight path ahead of the start along the heading; loop_side_m: when
    set (rooms), forward-stop-turn drives a square loop of that side (left turns) instead of
    going straight; body_height_m: IMU height above the floor. free_left_m / free_right_m /
    free_behind_m: free floor to the left of, to the right of and behind the start (measured
    across and along the heading); the motions that turn away from the heading
    (amrvio.sim.motions_robot, wall-scan) stay inside the rectangle these and free_length_m span.
    """

    start_xy: tuple[float, float] = (0.0, 0.0)
    heading_rad: float = 0.0
    free_length_m: float = 30.0
    loop_side_m: float | None = None
    body_height_m: float = 0.5
    free_left_m: float = 0.5
    free_right_m: float = 0.5
    free_behind_m: float = 0.0


@dataclass(frozen=True, slots=True)
class BlurBurst:
    """A fast yaw oscillation added to the motion: start t0_s, duration dur_s, peak rate (rad/s)."""

    t0_s: float
    dur_s: float
    omega_rad_s: float
    freq_hz: float = 4.0


def layout_xy(layout: MotionLayout, s: Signal, c: Signal) -> tuple[Signal, Signal]:
    """World x, y from along-track s and cross-track c (left) signals."""
    ch, sh = math.cos(layout.heading_rad), math.sin(layout.heading_rad)
    x = Combo(((1.0, Polynomial(layout.start_xy[0])), (ch, s), (-sh, c)))
    y = Combo(((1.0, Polynomial(layout.start_xy[1])), (sh, s), (ch, c)))
    return x, y


def with_bursts(yaw: Signal, bursts: Sequence[BlurBurst]) -> Signal:
    """``yaw`` plus the fast yaw oscillations ``bursts`` (they are part of the trajectory)."""
    if not bursts:
        return yaw
    parts: list[tuple[float, Signal]] = [(1.0, yaw)]
    for b in bursts:
        # peak yaw rate of amp * sin(2 pi f u) is amp * 2 pi f
        amp = b.omega_rad_s / (2.0 * math.pi * b.freq_hz)
        parts.append((1.0, Burst(b.t0_s, b.dur_s, amp, b.freq_hz)))
    return Combo(tuple(parts))
