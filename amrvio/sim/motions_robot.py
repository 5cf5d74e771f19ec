"""Wheeled-robot motions that follow their heading (no side slip): start-in-turn and turn-in-place.

A differential-drive robot moves along its heading psi(t) at speed v(t) (body origin = IMU = the
axle centre):

    p' = v (cos psi, sin psi, 0),   p'' = v' (cos psi, sin psi, 0) + v psi' (-sin psi, cos psi, 0).

Speed and heading are closed-form signals (amrvio.sim.kinematics), so velocity and acceleration,
hence the synthetic IMU, are exact. A turning path has no closed-form position: it is the integral
of the velocity by Gauss-Legendre quadrature (12 nodes) on cells that end at every knot of the
signals, where the integrand is analytic, so the position is exact to rounding. Turning in place
(v = 0) leaves the axle centre fixed; the camera, mounted ahead of it (default_T_body_cam), moves on
a small circle, as on a real robot.

Both motions are laid out in the layout frame (along / left of the heading) and then fitted into
the layout's free rectangle: shifted sideways or forwards when that suffices, else driven slower
(the path scales with the speed; the timing and the turns stay).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from amrvio.sim.kinematics import (
    BlurBurst,
    Combo,
    MinJerkPath,
    MotionLayout,
    MotionState,
    Polynomial,
    RateProfile,
    Signal,
    _MotionBase,
    _times,
    euler_zyx_body_rate,
    euler_zyx_matrix,
    with_bursts,
)

F64 = NDArray[np.float64]

ROBOT_MOTION_KINDS: tuple[str, ...] = ("start-in-turn", "turn-in-place")

_GL_NODES, _GL_WEIGHTS = np.polynomial.legendre.leggauss(12)
_CELL_S = 0.25  # longest quadrature cell (s)
_MARGIN_M = 0.05  # kept free between the path and the edge of the free rectangle

# turn-in-place: cruise speed, speed ramps, turn duration and angle (peak rate 1.875 angle / time)
TIP_SPEED_M_S = 0.5
TIP_RAMP_S = 1.25
TIP_TURN_S = 2.0
TIP_TURN_RAD = math.radians(30.0)
TIP_CRUISE_S = 2.0
# start-in-turn: speed from 0.3 to 0.5 m/s over 3 s; yaw rate 0.4 rad/s held 2 s, faded over 2 s
SIT_SPEED0_M_S = 0.3
SIT_SPEED_M_S = 0.5
SIT_SPEED_RAMP_S = 3.0
SIT_RATE_RAD_S = 0.4
SIT_HOLD_S = 2.0
SIT_FADE_S = 2.0
SIT_STRAIGHT_S = 1.0  # loops (rooms): straight between the 90 deg corners


@dataclass(frozen=True, slots=True, eq=False)
class UnicycleMotion(_MotionBase):
    """A ground robot at constant height ``z_m`` following ``heading`` at ``speed``.

    ``yaw`` is the body yaw (the heading, plus any fast oscillation of the body that does not move
    the path, e.g. blur bursts); pitch and roll are zero. ``breaks``: every knot of ``speed`` and
    ``heading`` (quadrature cells end there). Positions start at ``start_xy`` at t = 0.
    """

    name: str
    start_xy: tuple[float, float]
    z_m: float
    speed: Signal
    heading: Signal
    yaw: Signal
    breaks: tuple[float, ...]
    duration: float
    _grid: F64 = field(init=False, repr=False)
    _cum: F64 = field(init=False, repr=False)

    def __post_init__(self) -> None:
        lo, hi = -1.0, self.duration + 1.0
        n = max(1, math.ceil((hi - lo) / _CELL_S))
        pts = np.concatenate([np.linspace(lo, hi, n + 1),
                              [b for b in self.breaks if lo < b < hi]])
        grid = np.unique(pts)
        # cumulative position at the cell ends, relative to the cell that holds t = 0
        steps = self._integral(grid[:-1], grid[1:])
        cum = np.concatenate([np.zeros((1, 2)), np.cumsum(steps, axis=0)])
        k0 = int(np.clip(np.searchsorted(grid, 0.0, side="right") - 1, 0, grid.size - 2))
        at0 = cum[k0] + self._integral(grid[k0:k0 + 1], np.zeros(1))[0]
        object.__setattr__(self, "_grid", grid)
        object.__setattr__(self, "_cum", cum - at0)

    @property
    def duration_s(self) -> float:
        return self.duration

    def _velocity_xy(self, t: F64) -> F64:
        v = self.speed.eval(t)[0]
        psi = self.heading.eval(t)[0]
        return np.stack([v * np.cos(psi), v * np.sin(psi)], axis=-1)

    def _integral(self, a: F64, b: F64) -> F64:
        """(N, 2) integral of the horizontal velocity over [a_i, b_i] (12-node Gauss-Legendre)."""
        half = 0.5 * (b - a)
        u = (0.5 * (a + b))[:, None] + half[:, None] * _GL_NODES[None, :]
        vel = self._velocity_xy(u.ravel()).reshape(u.shape + (2,))
        return np.asarray(half[:, None] * np.einsum("j,njk->nk", _GL_WEIGHTS, vel), dtype=np.float64)

    def positions_xy(self, t: F64) -> F64:
        """(N, 2) horizontal body position at times t (N,)."""
        k = np.clip(np.searchsorted(self._grid, t, side="right") - 1, 0, self._grid.size - 2)
        rel = self._cum[k] + self._integral(self._grid[k], t)
        return np.asarray(np.asarray(self.start_xy)[None, :] + rel, dtype=np.float64)

    def states(self, t_s: ArrayLike) -> MotionState:
        t = _times(t_s)
        v, dv, _ = self.speed.eval(t)
        psi, dpsi, _ = self.heading.eval(t)
        yaw, dyaw, _ = self.yaw.eval(t)
        c, s = np.cos(psi), np.sin(psi)
        zero = np.zeros_like(t)
        xy = self.positions_xy(t)
        return MotionState(
            t_s=t,
            R_world_body=euler_zyx_matrix(yaw, zero, zero),
            p_world=np.stack([xy[:, 0], xy[:, 1], np.full_like(t, self.z_m)], axis=-1),
            v_world=np.stack([v * c, v * s, zero], axis=-1),
            a_world=np.stack([dv * c - v * dpsi * s, dv * s + v * dpsi * c, zero], axis=-1),
            omega_body=euler_zyx_body_rate(zero, zero, dyaw, zero, zero),
        )


@dataclass(frozen=True, slots=True)
class _Plan:
    """A robot motion in the layout frame before fitting: speed knots (m/s, min-jerk between
    them) and the heading relative to the layout heading."""

    speed_t: tuple[float, ...]
    speed_v: tuple[float, ...]
    heading: Signal
    heading_breaks: tuple[float, ...]


def _unicycle(name: str, plan: _Plan, layout: MotionLayout, duration: float, scale: float,
              offset: tuple[float, float], bursts: Sequence[BlurBurst]) -> UnicycleMotion:
    h = layout.heading_rad
    ch, sh = math.cos(h), math.sin(h)
    start = (layout.start_xy[0] + ch * offset[0] - sh * offset[1],
             layout.start_xy[1] + sh * offset[0] + ch * offset[1])
    heading: Signal = Combo(((1.0, Polynomial(h)), (1.0, plan.heading)))
    speed = MinJerkPath(plan.speed_t, tuple(scale * v for v in plan.speed_v))
    breaks = tuple(sorted({*plan.speed_t, *plan.heading_breaks}))
    return UnicycleMotion(name, start, layout.body_height_m, speed, heading,
                          with_bursts(heading, bursts), breaks, float(duration))


def _fit_offset(lo: float, hi: float, box_lo: float, box_hi: float) -> float:
    """Smallest shift that moves [lo, hi] inside [box_lo, box_hi] (0 when it is already inside)."""
    return float(min(max(0.0, box_lo - lo), box_hi - hi))


def _fitted(name: str, plan: _Plan, layout: MotionLayout, duration: float,
            bursts: Sequence[BlurBurst]) -> UnicycleMotion:
    """The plan driven inside the layout's free rectangle (see the module docstring)."""
    flat = MotionLayout(start_xy=(0.0, 0.0), heading_rad=0.0, body_height_m=layout.body_height_m)
    probe = _unicycle(name, plan, flat, duration, 1.0, (0.0, 0.0), ())
    xy = probe.positions_xy(np.linspace(0.0, duration, max(200, math.ceil(40 * duration)) + 1))
    # the start itself is free: the margin only keeps the path off the far edges
    along = (min(0.0, _MARGIN_M - layout.free_behind_m), max(0.0, layout.free_length_m - _MARGIN_M))
    cross = (min(0.0, _MARGIN_M - layout.free_right_m), max(0.0, layout.free_left_m - _MARGIN_M))
    ext = xy.max(axis=0) - xy.min(axis=0)
    scale = 1.0
    for e, (b0, b1) in zip(ext, (along, cross), strict=True):
        if e > 0.0:
            scale = min(scale, (b1 - b0) / e)
    scale = max(scale, 1e-3)
    lo, hi = scale * xy.min(axis=0), scale * xy.max(axis=0)
    offset = (_fit_offset(lo[0], hi[0], *along), _fit_offset(lo[1], hi[1], *cross))
    return _unicycle(name, plan, layout, duration, scale, offset, bursts)


def _turn_in_place_plan(layout: MotionLayout, duration: float) -> _Plan:
    """Already driving at t = 0; stop, turn in place by TIP_TURN_RAD in TIP_TURN_S (min-jerk), drive
    on; repeated. Straight layouts alternate the turns (headings 0, +a, 0, -a, ...: the path
    zig-zags along the free length), loops (rooms) always turn left (a 12-gon)."""
    v, ramp = TIP_SPEED_M_S, TIP_RAMP_S
    first = min(max(0.5 * (duration - TIP_TURN_S) - 0.5, ramp), 2.5)  # first drive, with its stop
    side = 1.0 if layout.free_left_m >= layout.free_right_m or layout.loop_side_m is not None else -1.0
    pattern = (1.0,) if layout.loop_side_m is not None else (1.0, -1.0, -1.0, 1.0)
    st, sv = [0.0], [v]
    if first > ramp:
        st.append(first - ramp)
        sv.append(v)
    ht, hv = [0.0], [0.0]
    t, psi, k = first, 0.0, 0
    while True:
        st.append(t)
        sv.append(0.0)
        ht.append(t)
        hv.append(psi)
        if t > duration + 1.0:
            break
        psi += side * pattern[k % len(pattern)] * TIP_TURN_RAD
        k += 1
        t += TIP_TURN_S
        ht.append(t)
        hv.append(psi)
        st.append(t)
        sv.append(0.0)
        for dt, vv in ((ramp, v), (TIP_CRUISE_S, v)):
            t += dt
            st.append(t)
            sv.append(vv)
        t += ramp
    return _Plan(tuple(st), tuple(sv), MinJerkPath(tuple(ht), tuple(hv)), tuple(ht))


def _start_in_turn_plan(layout: MotionLayout, duration: float) -> _Plan:
    """Moving slowly (SIT_SPEED0_M_S, speeding up to SIT_SPEED_M_S) and turning at SIT_RATE_RAD_S from
    t = 0; the turn fades out and the robot ends up along the layout heading. Straight layouts: it
    drives on straight (it pulled out of a side opening into the corridor or aisle). Loops (rooms):
    it goes on round a loop of short straights and 90 deg corners of the same yaw rate."""
    r = SIT_RATE_RAD_S
    turn_rad = r * (SIT_HOLD_S + 0.5 * SIT_FADE_S)
    side = 1.0 if layout.free_right_m >= layout.free_left_m else -1.0  # the curve drifts right
    if layout.loop_side_m is not None:
        side = 1.0  # left turns, as the square loop of forward-stop-turn
    kt, kr = [0.0, SIT_HOLD_S, SIT_HOLD_S + SIT_FADE_S], [r, r, 0.0]
    if layout.loop_side_m is not None:
        ramp = SIT_FADE_S
        hold = 0.5 * math.pi / r - ramp  # each corner turns exactly 90 deg
        t = kt[-1]
        while t < duration + 1.0:
            for dt, rate in ((SIT_STRAIGHT_S, 0.0), (ramp, r), (hold, r), (ramp, 0.0)):
                t += dt
                kt.append(t)
                kr.append(rate)
    heading = RateProfile(tuple(kt), tuple(side * x for x in kr), -side * turn_rad)
    speed_t = (0.0, SIT_SPEED_RAMP_S)
    return _Plan(speed_t, (SIT_SPEED0_M_S, SIT_SPEED_M_S), heading, tuple(kt))


_PLANS: dict[str, Callable[[MotionLayout, float], _Plan]] = {
    "start-in-turn": _start_in_turn_plan,
    "turn-in-place": _turn_in_place_plan,
}


def make_robot_motion(kind: str, duration_s: float, layout: MotionLayout,
                      blur_bursts: Sequence[BlurBurst] = ()) -> UnicycleMotion:
    """One of ``ROBOT_MOTION_KINDS`` inside ``layout`` (callers check ``kind`` and the duration).

    start-in-turn: from t = 0 the robot drives slowly (0.3 m/s, speeding up to 0.5 m/s over 3 s) and
    turns at 0.4 rad/s; after 2 s the turn fades out over 2 s (69 deg in all) and it drives on
    straight (corridor, aisle) or round a loop of 90 deg corners (room). turn-in-place: driving at
    0.5 m/s at t = 0, it stops (1.25 s), turns in place by 30 deg in 2 s (min-jerk, peak 0.49 rad/s),
    and drives on; in long runs it repeats every 6.5 s. ``blur_bursts`` shake the body yaw.
    """
    return _fitted(kind, _PLANS[kind](layout, duration_s), layout, duration_s, blur_bursts)
