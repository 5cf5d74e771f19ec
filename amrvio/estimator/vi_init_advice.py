"""Excitation of a visual-inertial initialisation window, measured before solving, and the plain
advice the initialiser gives for each status.

Gravity-free acceleration without knowing gravity: the VO rotations (between keyframes, the gyro
integrated from the last keyframe) carry the specific force into the VO frame, where
``R f = a - g`` and gravity is a constant; so the spread of ``R f`` over the window is the spread of
the acceleration. It is averaged over ``lowpass_s`` bins (vibration is not excitation) and each
deviation is expressed in the camera frame of its instant: the figures read "along the camera's
forward axis", which is what advice can ask a user to do.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

from amrvio.errors import ShapeError
from amrvio.estimator.vi_init_types import (
    ViExcitation,
    ViInitConfig,
    ViInitFigures,
    ViInitState,
    ViInitStatus,
    fmt_num,
)
from amrvio.types.lie import so3_exp
from amrvio.types.sensors import ImuData

F64 = NDArray[np.float64]
I64 = NDArray[np.int64]

CAMERA_AXES = ("sideways (camera x)", "up/down (camera y)", "forward (camera z)")


def sample_rotations(imu: ImuData, stamps_ns: I64, R_vo_body: F64, gyro_bias: F64) -> tuple[ImuData, F64]:
    """The samples inside the keyframes' span and R_vo_body (N, 3, 3) at each: the keyframe's
    rotation, then the bias-corrected gyro integrated from it."""
    win = imu.window(int(stamps_ns[0]), int(stamps_ns[-1]))
    st = win.stamps_ns
    k_of = np.clip(np.searchsorted(stamps_ns, st, side="right") - 1, 0, len(stamps_ns) - 1)
    dt = np.diff(st).astype(np.float64) * 1e-9
    w = 0.5 * (win.gyro_rad_s[1:] + win.gyro_rad_s[:-1]) - gyro_bias
    steps = so3_exp(w * dt[:, None]) if dt.shape[0] else np.zeros((0, 3, 3))
    out = np.empty((len(win), 3, 3))
    for i in range(len(win)):
        if i == 0 or k_of[i] != k_of[i - 1]:
            out[i] = R_vo_body[k_of[i]]  # the first sample at or after a keyframe
        else:
            out[i] = out[i - 1] @ steps[i - 1]
    return win, out


def measure_excitation(
    imu: ImuData,
    stamps_ns: I64,
    R_vo_body: F64,
    R_body_cam: F64,
    gyro_bias: F64,
    accel_bias: F64,
    lowpass_s: float,
    rotation_range: tuple[float, F64],
    c_vo: F64,
) -> ViExcitation:
    """The :class:`ViExcitation` of a window (module docstring); ``rotation_range`` from the VO;
    ``c_vo`` (K, 3) the VO camera positions."""
    win, R = sample_rotations(imu, stamps_ns, R_vo_body, gyro_bias)
    f_vo = np.einsum("nij,nj->ni", R, win.accel_m_s2 - accel_bias)
    dev = f_vo - f_vo.mean(axis=0)
    R_cam = np.einsum("nij,jk->nik", R, R_body_cam)
    e = np.einsum("nji,nj->ni", R_cam, dev)  # deviation in the camera frame of its instant
    t = (win.stamps_ns - win.stamps_ns[0]).astype(np.float64) * 1e-9
    if lowpass_s > 0.0:
        idx = np.floor(t / lowpass_s).astype(np.intp)
        counts = np.bincount(idx)
        keep = counts > 0
        e = np.stack([np.bincount(idx, weights=e[:, k])[keep] / counts[keep] for k in range(3)], axis=1)
    per_axis = np.sqrt(np.mean(e**2, axis=0))
    return ViExcitation(
        duration_s=(int(stamps_ns[-1]) - int(stamps_ns[0])) * 1e-9,
        n_keyframes=int(stamps_ns.shape[0]),
        accel_std_cam_m_s2=np.asarray(per_axis, dtype=np.float64),
        rotation_range_deg=rotation_range[0],
        rotation_range_cam_deg=np.asarray(rotation_range[1], dtype=np.float64),
        translation_snr=translation_snr(c_vo, (stamps_ns - stamps_ns[0]).astype(np.float64) * 1e-9),
    )


def translation_snr(c_vo: F64, t_s: ArrayLike | None = None) -> float:
    """Largest distance of the VO camera from its mean position over its jitter. The jitter is
    the smallest, over the orders n = 2, 3 and 4, of the RMS residual of a keyframe's position
    against the polynomial of degree n - 1 through its n neighbours (n + 1 consecutive
    keyframes; the one predicted is the (n // 2)-th), over that residual's white-noise gain
    (1 + the sum of the squared Lagrange weights): each is sigma for white noise of sigma per
    keyframe, whatever the keyframes' times ``t_s`` (K,) (None: evenly spaced). Evenly spaced,
    these are the differences of orders 2, 3 and 4 over sqrt(6), sqrt(20) and sqrt(70). A smooth
    motion's residual is its n-th derivative times the keyframe interval to the n-th, which the
    next order shrinks while that interval is short against the motion's period. With the second
    order alone the figure measured the motion itself as keyframes grew sparse: on EuRoC MH_01's
    exact ground truth over its first 3 s, 41 with a keyframe every 0.1 s, 10.5 every 0.2 s and
    4.8 every 0.3 s, under the gate of 10 (with orders 2-4: 221, 49 and 13); a still camera's
    white noise reads 1.7 (median), at most 4.8 over 1000 draws. Without the times, keyframes
    0.15 to 1.2 s apart (the VO's at 6.7 frames/s on MH_01 hand-held) read that ground truth as
    2.7-5.7 (13-84 evenly spaced over the same span): every VI initialisation failed there."""
    c = np.asarray(c_vo, dtype=np.float64)
    if c.shape[0] < 3:
        return 0.0
    t = np.arange(c.shape[0], dtype=np.float64) if t_s is None else np.asarray(t_s, dtype=np.float64)
    if t.shape != (c.shape[0],) or np.any(np.diff(t) <= 0.0):
        raise ShapeError(f"translation_snr: {t.shape} times for {c.shape[0]} positions, increasing")
    span = float(np.max(np.linalg.norm(c - c.mean(axis=0), axis=1)))
    jitter = math.inf
    for order in (2, 3, 4):
        if c.shape[0] > order:
            jitter = min(jitter, _lagrange_jitter(c, t, order))
    if jitter == 0.0:
        return math.inf if span > 0.0 else 0.0
    return span / jitter


def _lagrange_jitter(c: F64, t: F64, order: int) -> float:
    """RMS over the windows of ``order`` + 1 consecutive keyframes of the residual of the
    (order // 2)-th against the Lagrange polynomial through the others, each over its white-noise
    gain."""
    k = order // 2
    n = c.shape[0] - order
    win = np.arange(order + 1)[None, :] + np.arange(n)[:, None]  # (n, order + 1) keyframe indices
    tw = t[win]
    others = np.delete(np.arange(order + 1), k)
    x, nodes = tw[:, k], tw[:, others]  # (n,), (n, order)
    # Lagrange weights of each node at x: prod over the other nodes m of (x - t_m) / (t_j - t_m)
    w = np.ones((n, order))
    for j in range(order):
        for m in range(order):
            if m != j:
                w[:, j] *= (x - nodes[:, m]) / (nodes[:, j] - nodes[:, m])
    resid = c[win[:, k]] - np.einsum("nj,njd->nd", w, c[win[:, others]])
    gain = 1.0 + np.sum(w**2, axis=1)
    return float(np.sqrt(np.mean(np.sum(resid**2, axis=1) / gain)))


def _move_advice(ex: ViExcitation, cfg: ViInitConfig, needed_m_s2: float) -> str:
    """Accelerate and stop over the distance that gives ``needed_m_s2`` of acceleration spread (a
    move of distance d that accelerates then brakes over tau seconds has an acceleration RMS of
    about 4 d / tau^2), within at most 3 s, then turn when the window did not."""
    tau = min(max(ex.duration_s, cfg.min_duration_s), 3.0)
    d = max(0.5, math.ceil(2.0 * needed_m_s2 * tau * tau / 4.0) / 2.0)
    again = ", and repeat" if ex.duration_s > tau + 0.5 else ""
    turn = ", then turn about 90 degrees" if ex.rotation_range_deg < cfg.gates.min_rotation_deg else ""
    axes = ", ".join(f"{CAMERA_AXES[i].split(' ')[0]} {ex.accel_std_cam_m_s2[i]:.2f}" for i in range(3))
    return (f"accelerate forward about {d:g} m and stop within {tau:.0f} s{again}{turn} (acceleration spread "
            f"{ex.accel_std_m_s2:.2f} m/s^2 here, about {needed_m_s2:.2f} needed; {axes}; "
            f"rotation {ex.rotation_range_deg:.0f} deg)")


CHECK_SETUP = ("check T_body_cam (the camera pose in the IMU frame), the camera-IMU time offset, "
               "and that the poses are T_world_cam (camera to world)")


def advice(status: ViInitStatus, cfg: ViInitConfig, ex: ViExcitation | None,
           fig: ViInitFigures | None, state: ViInitState | None, detail: str = "") -> str:
    """Plain advice for ``status`` from what the window lacked ("" when OK)."""
    S = ViInitStatus
    g = cfg.gates
    if status is S.OK:
        return ""
    if status in (S.TOO_FEW_KEYFRAMES, S.IMU_MISSING):
        return detail
    if status is S.ROTATION_MISMATCH and fig is not None:
        return (f"VO and gyro rotations differ by {fmt_num(fig.rotation_rms_deg)} deg RMS per keyframe "
                f"interval (at most {g.max_rotation_rms_deg:g} allowed): {CHECK_SETUP}")
    if status is S.GRAVITY_UNCERTAIN and ex is not None and state is not None:
        return (f"gravity direction uncertain ({fmt_num(state.gravity_std_deg)} deg std, "
                f"{g.max_gravity_std_deg:g} allowed; scale is fine): turn about 90 degrees (the window "
                f"turned {ex.rotation_range_deg:.0f} deg) so that the accelerometer bias separates from gravity")
    if status is S.SCALE_UNCERTAIN and ex is not None:
        return (f"scale uncertain ({fmt_num(100 * _rel_std(state), 1)} % std, {100 * g.max_scale_rel_std:g} % "
                f"allowed): keep accelerating and braking for longer, or harder (acceleration spread "
                f"{ex.accel_std_m_s2:.2f} m/s^2 over {ex.duration_s:.0f} s here; rotation "
                f"{ex.rotation_range_deg:.0f} deg)")
    if status in (S.INSUFFICIENT_EXCITATION, S.ILL_CONDITIONED) and ex is not None:
        still = ex.translation_snr < g.min_translation_snr
        if status is S.ILL_CONDITIONED:
            why = (f"the accelerations do not pin scale and gravity apart (condition number "
                   f"{fmt_num(fig.condition_number if fig else math.nan, 0)})")
        elif still:
            why = (f"scale is not observable: the camera does not translate (travel {ex.translation_snr:.0f} "
                   "times its jitter)")
        else:
            why = "scale is not observable: too little acceleration change (constant velocity or rest)"
        return f"{why}; {_move_advice(ex, cfg, g.min_accel_std_m_s2)}"
    if status is S.SCALE_DRIFT and fig is not None:
        span = fmt_num(ex.duration_s if ex else math.nan, 1)
        return (f"the VO's scale changes by {fmt_num(100 * fig.scale_drift, 1)} % (+- "
                f"{fmt_num(100 * fig.scale_drift_std, 1)}) across the {span} s window "
                f"({100 * g.max_scale_drift:g} % allowed): one scale fits neither end; the next window "
                "starts later. Keep the scene textured and near, and avoid pure rotation")
    if status is S.NEGATIVE_SCALE:
        return ("the VO translation runs against what the accelerometer measured (negative scale): "
                + CHECK_SETUP)
    if status is S.BAD_GRAVITY_NORM and fig is not None:
        return (f"gravity came out at {fmt_num(cfg.gravity_m_s2 + fig.gravity_norm_residual_m_s2)} m/s^2 "
                f"(expected {cfg.gravity_m_s2:g}): VO and IMU disagree; {CHECK_SETUP}, the IMU units "
                "(m/s^2, rad/s), and VO scale drift inside the window")
    if status is S.IMPLAUSIBLE_BIAS:
        turn = ("; turn about 90 degrees to separate the accelerometer bias from gravity"
                if ex is not None and ex.rotation_range_deg < g.min_rotation_deg else "")
        return f"{detail}: the VO and the IMU disagree; {CHECK_SETUP}{turn}"
    return detail


def _rel_std(state: ViInitState | None) -> float:
    if state is None or state.scale == 0.0:
        return math.nan
    return state.scale_std / abs(state.scale)
