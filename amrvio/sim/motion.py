"""The synthetic motions (make_motion) and the camera mount (default_T_body_cam).

World frame: z up, floor at z = 0, gravity (0, 0, -9.81). Body frame = IMU frame, x forward,
y left, z up. Every motion is built from the closed-form signals of amrvio.sim.kinematics, so the
synthetic IMU (amrvio.sim.imu_synth) is exact; the wheeled-robot motions that follow their heading
(start-in-turn, turn-in-place) are in amrvio.sim.motions_robot.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike

from amrvio.errors import ConfigError
from amrvio.sim.kinematics import (
    BlurBurst,
    Combo,
    EulerMotion,
    MinJerkPath,
    Motion,
    MotionLayout,
    Polynomial,
    Signal,
    Sines,
    layout_xy,
    with_bursts,
)
from amrvio.sim.motions_robot import ROBOT_MOTION_KINDS, UnicycleMotion, make_robot_motion
from amrvio.types.lie import SE3, SO3

MOTION_KINDS: tuple[str, ...] = ("forward-stop-turn", "constant-velocity", "rough-floor", "handheld",
                                 "wall-scan", *ROBOT_MOTION_KINDS)

__all__ = ["MOTION_KINDS", "BlurBurst", "Motion", "MotionLayout", "default_T_body_cam", "make_motion",
           "parse_blur_bursts", "UnicycleMotion"]


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


def _wall_scan(lay: MotionLayout, rng: np.random.Generator) -> tuple[Signal, ...]:
    """x, y, z, yaw, pitch, roll of a hand-held camera scanning what lies ahead of the layout.

    Towards / away from it: a 14 s sine of up to 0.8 m amplitude inside the free length; sideways: an
    11 s sine of up to 1.2 m (80 % of the narrower side), starting in the middle; the camera turns
    by up to 12 deg towards the middle and is held level (body pitched up 8 deg against the
    camera's 10 deg mount); hand jitter of a few cm and deg at 0.3-2.5 Hz.
    """
    ph = rng.uniform(0, 2 * math.pi, size=10)
    f_along, f_cross = 1.0 / 14.0, 1.0 / 11.0
    a_amp = min(0.8, 0.45 * lay.free_length_m)
    a_mid = a_amp + min(0.1, 0.05 * lay.free_length_m)
    c_amp = min(1.2, 0.8 * min(lay.free_left_m, lay.free_right_m))
    along = Combo(((1.0, Polynomial(a_mid)), (a_amp, Sines((1.0,), (f_along,), (0.0,))),
                   (1.0, Sines((0.03, 0.01), (0.9, 2.2), (ph[0], ph[1])))))
    cross = Combo(((c_amp, Sines((1.0,), (f_cross,), (0.0,))),
                   (1.0, Sines((0.03, 0.01), (1.1, 2.5), (ph[2], ph[3])))))
    x, y = layout_xy(lay, along, cross)
    z = Combo(((1.0, Polynomial(max(lay.body_height_m, 1.3))),
               (1.0, Sines((0.05, 0.015), (0.3, 1.8), (ph[4], ph[5])))))
    yaw = Combo(((1.0, Polynomial(lay.heading_rad)),
                 (-math.radians(12.0), Sines((1.0,), (f_cross,), (0.0,))),
                 (1.0, Sines((math.radians(3.0), math.radians(1.0)), (0.6, 2.1), (ph[6], ph[7])))))
    pitch = Combo(((1.0, Polynomial(-math.radians(8.0))),
                   (1.0, Sines((math.radians(4.0), math.radians(1.5)), (0.25, 1.6), (ph[8], ph[9])))))
    roll = Sines((math.radians(4.0), math.radians(1.5)), (0.3, 1.9), (ph[9], ph[0]))
    return x, y, z, yaw, pitch, roll


def make_motion(
    kind: str,
    duration_s: float,
    layout: MotionLayout | None = None,
    seed: int = 0,
    blur_bursts: Sequence[BlurBurst] = (),
) -> EulerMotion | UnicycleMotion:
    """One of the synthetic motions (``MOTION_KINDS``) that stays inside ``layout``.

    forward-stop-turn: rest, then drive ~2.5 m, stop, turn in place +-35 deg and back (corridor) or a
    square loop with 90 deg turns (room). constant-velocity: straight, constant speed (degenerate
    for scale). rough-floor: forward at constant speed with 8-15 Hz pitch/roll vibration of
    1-2 deg and mm-level bounce. handheld: walking pace plus aggressive 6-DoF sinusoids.
    wall-scan: a hand-held camera in front of what lies ahead (the wall scene: a textured wall
    1.3-2.9 m away), swept sideways (+-1.2 m, 11 s period) and towards and away from it (14 s
    period), turned towards the middle, with hand jitter. start-in-turn, turn-in-place: wheeled
    robots that follow their heading (amrvio.sim.motions_robot.make_robot_motion).
    ``blur_bursts`` add fast yaw oscillations (they are part of the trajectory, so of the IMU).
    """
    if not (math.isfinite(duration_s) and duration_s > 0):
        raise ConfigError(f"motion duration must be > 0 s, got {duration_s}")
    lay = layout if layout is not None else MotionLayout()
    if kind in ROBOT_MOTION_KINDS:
        return make_robot_motion(kind, float(duration_s), lay, blur_bursts)
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
        x, y = layout_xy(lay, Polynomial(0.0, speed), zero)
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
        x, y = layout_xy(lay, along, cross)
        z = Combo(((1.0, Polynomial(max(h, 1.2))),
                   (1.0, Sines((0.06, 0.02), (0.5, 2.1), (ph[4], ph[5]))),))
        yaw = Combo(((1.0, Polynomial(lay.heading_rad)),
                     (1.0, Sines((math.radians(20), math.radians(4)), (0.25, 2.3), (ph[6], ph[7]))),))
        pitch = Sines((math.radians(10), math.radians(3)), (0.4, 1.7), (ph[8], ph[9]))
        roll = Sines((math.radians(8), math.radians(3)), (0.55, 2.0), (ph[10], ph[11]))
    elif kind == "wall-scan":
        x, y, z, yaw, pitch, roll = _wall_scan(lay, rng)
    else:
        raise ConfigError(f"unknown motion {kind!r}; choose one of {', '.join(MOTION_KINDS)}")
    return EulerMotion(kind, x, y, z, with_bursts(yaw, blur_bursts), pitch, roll, float(duration_s))


def default_T_body_cam(pitch_down_deg: float = 10.0, offset_m: ArrayLike = (0.1, 0.0, 0.2)) -> SE3:
    """Camera looking along body +x, pitched down; camera axes x right, y down, z forward."""
    # columns: camera x = -body y, camera y = -body z, camera z = body x
    R_level = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])
    a = math.radians(pitch_down_deg)
    # pitch down = Rx(-a) in the camera frame: the optical axis z tips towards +y (down)
    R_tilt = np.array([[1.0, 0.0, 0.0], [0.0, math.cos(a), math.sin(a)],
                       [0.0, -math.sin(a), math.cos(a)]])
    return SE3(SO3.from_matrix(R_level @ R_tilt), np.asarray(offset_m, dtype=np.float64))
