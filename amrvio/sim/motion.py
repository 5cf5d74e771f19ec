"""Continuous-time body trajectories with exact first and second derivatives.

World frame: z up, floor at z = 0, gravity (0, 0, -9.81). Body frame = IMU frame, x forward,
y left, z up. Every motion is built from scalar signals whose value, first and second
derivatives are closed forms, so the synthetic IMU (amrvio.sim.imu_synth) is exact.

Attitude is R_world_body = Rz(yaw) Ry(pitch) Rx(roll) (ZYX Euler angles); the body angular
rate follows from the exact Euler-rate map (e.g. Titterton & Weston, eq. 3.52).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Literal, Protocol, runtime_checkable

import numpy as np
from numpy.typing import ArrayLike, NDArray

from amrvio.errors import ConfigError, ShapeError
from amrvio.types.lie import SE3, SO3

F64 = NDArray[np.float64]
Triple = tuple[F64, F64, F64]

MotionKind = Literal["forward-stop-turn", "constant-velocity", "rough-floor", "handheld"]
MOTION_KINDS: tuple[str, ...] = ("forward-stop-turn", "constant-velocity", "rough-floor", "handheld")


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
# Motion factory.


@dataclass(frozen=True, slots=True)
class MotionLayout:
    """Where a motion may go inside a scene.

    start_xy: body start position on the floor plan; heading_rad: initial heading (yaw);
    free_length_m: free straight path ahead of the start along the heading; loop_side_m: when
    set (rooms), forward-stop-turn drives a square loop of that side (left turns) instead of
    going straight; body_height_m: IMU height above the floor.
    """

    start_xy: tuple[float, float] = (0.0, 0.0)
    heading_rad: float = 0.0
    free_length_m: float = 30.0
    loop_side_m: float | None = None
    body_height_m: float = 0.5


@dataclass(frozen=True, slots=True)
class BlurBurst:
    """A fast yaw oscillation added to the motion: start t0_s, duration dur_s, peak rate (rad/s)."""

    t0_s: float
    dur_s: float
    omega_rad_s: float
    freq_hz: float = 4.0


def parse_blur_bursts(spec: str) -> tuple[BlurBurst, ...]:
    """Parse ``"t0:dur:omega,..."`` (seconds, seconds, rad/s). Raises ConfigError."""
    out: list[BlurBurst] = []
    for item in (s.strip() for s in spec.split(",")):
        if not item:
            continue
        parts = item.split(":")
        try:
            if len(parts) != 3:
                raise ValueError
            t0, dur, om = (float(p) for p in parts)
        except ValueError:
            raise ConfigError(
                f"--blur-bursts item {item!r} is not 't0:dur:omega' (e.g. '3.0:0.5:2.0')"
            ) from None
        if not (math.isfinite(t0) and math.isfinite(dur) and math.isfinite(om)) or dur <= 0:
            raise ConfigError(f"--blur-bursts item {item!r}: need finite values and dur > 0")
        out.append(BlurBurst(t0, dur, om))
    return tuple(out)


def _along(layout: MotionLayout, s: Signal, c: Signal) -> tuple[Signal, Signal]:
    """World x, y from along-track s and cross-track c (left) signals."""
    ch, sh = math.cos(layout.heading_rad), math.sin(layout.heading_rad)
    x = Combo(((1.0, Polynomial(layout.start_xy[0])), (ch, s), (-sh, c)))
    y = Combo(((1.0, Polynomial(layout.start_xy[1])), (sh, s), (ch, c)))
    return x, y


def _with_bursts(yaw: Signal, bursts: Sequence[BlurBurst]) -> Signal:
    if not bursts:
        return yaw
    parts: list[tuple[float, Signal]] = [(1.0, yaw)]
    for b in bursts:
        # peak yaw rate of amp * sin(2 pi f u) is amp * 2 pi f
        amp = b.omega_rad_s / (2.0 * math.pi * b.freq_hz)
        parts.append((1.0, Burst(b.t0_s, b.dur_s, amp, b.freq_hz)))
    return Combo(tuple(parts))


def _forward_stop_turn(layout: MotionLayout, duration: float) -> tuple[Signal, Signal, Signal]:
    """Knots of x, y, yaw: dwell, then repeat [drive, dwell, turn, dwell]."""
    t, x, y, yaw = 0.0, layout.start_xy[0], layout.start_xy[1], layout.heading_rad
    kt, kx, ky, kyaw = [0.0], [x], [y], [yaw]

    def add(dt: float) -> None:
        nonlocal t
        t += dt
        kt.append(t)
        kx.append(x)
        ky.append(y)
        kyaw.append(yaw)

    add(0.5)  # start at rest: lets an estimator initialise
    if layout.loop_side_m is not None:
        side = layout.loop_side_m
        while t < duration + 1.0:
            x += side * math.cos(yaw)
            y += side * math.sin(yaw)
            add(max(2.5, side / 0.8))
            add(0.5)
            yaw += math.pi / 2
            add(2.0)
            add(0.5)
    else:
        cycle_s, step_m = 8.0, 2.5
        n_cycles = max(1, math.ceil((duration + 1.0) / cycle_s))
        step_m = min(step_m, 0.95 * layout.free_length_m / n_cycles)
        sign = 1.0
        while t < duration + 1.0:
            x += step_m * math.cos(yaw)
            y += step_m * math.sin(yaw)
            add(3.5)
            add(0.5)
            yaw += sign * math.radians(35.0)
            add(1.5)
            yaw -= sign * math.radians(35.0)
            add(1.5)
            add(0.5)
            sign = -sign
    kt_t = tuple(kt)
    return MinJerkPath(kt_t, tuple(kx)), MinJerkPath(kt_t, tuple(ky)), MinJerkPath(kt_t, tuple(kyaw))


def make_motion(
    kind: str,
    duration_s: float,
    layout: MotionLayout | None = None,
    seed: int = 0,
    blur_bursts: Sequence[BlurBurst] = (),
) -> EulerMotion:
    """One of the synthetic motions (``MOTION_KINDS``) that stays inside ``layout``.

    forward-stop-turn: rest, then drive ~2.5 m, stop, turn in place +-35 deg and back (corridor) or a
    square loop with 90 deg turns (room). constant-velocity: straight, constant speed (degenerate
    for scale). rough-floor: forward at constant speed with 8-15 Hz pitch/roll vibration of
    1-2 deg and mm-level bounce. handheld: walking pace plus aggressive 6-DoF sinusoids.
    ``blur_bursts`` add fast yaw oscillations (they are part of the trajectory, so of the IMU).
    """
    if not (math.isfinite(duration_s) and duration_s > 0):
        raise ConfigError(f"motion duration must be > 0 s, got {duration_s}")
    lay = layout if layout is not None else MotionLayout()
    rng = np.random.default_rng(seed)
    zero: Signal = Polynomial()
    x: Signal
    y: Signal
    z: Signal
    yaw: Signal
    pitch: Signal
    roll: Signal
    h = lay.body_height_m
    if kind == "forward-stop-turn":
        x, y, yaw = _forward_stop_turn(lay, duration_s)
        z, pitch, roll = Polynomial(h), zero, zero
    elif kind in ("constant-velocity", "rough-floor"):
        speed = min(1.0 if kind == "constant-velocity" else 0.8, 0.9 * lay.free_length_m / duration_s)
        x, y = _along(lay, Polynomial(0.0, speed), zero)
        yaw = Polynomial(lay.heading_rad)
        if kind == "constant-velocity":
            z, pitch, roll = Polynomial(h), zero, zero
        else:
            ph = rng.uniform(0, 2 * math.pi, size=5)
            pitch = Sines((math.radians(1.2), math.radians(0.6)), (9.3, 12.7), (ph[0], ph[1]))
            roll = Sines((math.radians(1.0), math.radians(0.5)), (8.1, 14.2), (ph[2], ph[3]))
            z = Combo(((1.0, Polynomial(h)), (1.0, Sines((0.0015,), (11.0,), (ph[4],)))))
    elif kind == "handheld":
        ph = rng.uniform(0, 2 * math.pi, size=12)
        speed = min(0.5, 0.7 * lay.free_length_m / duration_s)
        along = Combo(((1.0, Polynomial(0.0, speed)), (1.0, Sines((0.08, 0.03), (0.7, 1.9),
                                                                  (ph[0], ph[1])))))
        cross = Sines((0.15, 0.04), (0.35, 1.3), (ph[2], ph[3]))
        x, y = _along(lay, along, cross)
        z = Combo(((1.0, Polynomial(max(h, 1.2))),
                   (1.0, Sines((0.06, 0.02), (0.5, 2.1), (ph[4], ph[5]))),))
        yaw = Combo(((1.0, Polynomial(lay.heading_rad)),
                     (1.0, Sines((math.radians(20), math.radians(4)), (0.25, 2.3), (ph[6], ph[7]))),))
        pitch = Sines((math.radians(10), math.radians(3)), (0.4, 1.7), (ph[8], ph[9]))
        roll = Sines((math.radians(8), math.radians(3)), (0.55, 2.0), (ph[10], ph[11]))
    else:
        raise ConfigError(f"unknown motion {kind!r}; choose one of {', '.join(MOTION_KINDS)}")
    return EulerMotion(kind, x, y, z, _with_bursts(yaw, blur_bursts), pitch, roll, float(duration_s))


def default_T_body_cam(pitch_down_deg: float = 10.0, offset_m: ArrayLike = (0.1, 0.0, 0.2)) -> SE3:
    """Camera looking along body +x, pitched down; camera axes x right, y down, z forward."""
    # columns: camera x = -body y, camera y = -body z, camera z = body x
    R_level = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])
    a = math.radians(pitch_down_deg)
    # pitch down = Rx(-a) in the camera frame: the optical axis z tips towards +y (down)
    R_tilt = np.array([[1.0, 0.0, 0.0], [0.0, math.cos(a), math.sin(a)],
                       [0.0, -math.sin(a), math.cos(a)]])
    return SE3(SO3.from_matrix(R_level @ R_tilt), np.asarray(offset_m, dtype=np.float64))
