"""The visual-inertial initialiser along the whole real EuRoC V1_01 flight (issue 10, "Done when").

Each window (``WINDOW_S`` long, starting every second) feeds :func:`initialize_vi` the
ground-truth camera poses at 10 Hz (every other 20 Hz ground-truth pose), with seeded noise
(``POS_SIGMA_M`` per axis on positions, ``ROT_SIGMA_DEG`` per axis on rotations), expressed in the
first keyframe's camera frame and divided by ``SCALE``, and the real recorded IMU. Truth: scale
``SCALE``; gravity: the vector the ground truth implies (bench/euroc_v101.py), in that frame.

Why 8 s: the recorded IMU is far noisier than its datasheet on the flying MAV (the MAP step finds
the accelerometer's white noise 5 to 8 times the datasheet's, and its bias wandering), so a 3 s
window gives a scale standard deviation of 1.5 to 3 % whatever the VO noise, and 8 s windows get
0.7 to 1 %. ``--window 3`` shows it.

The recorded accelerometer also reads about 1 % less acceleration than the ground truth shows (a
regression of one on the other over the flight gives 0.992, 0.991-0.994 along each world axis;
with the IMU's stamps shifted by -30 to +30 ms it is 0.993 at most, at +5 ms: no time offset
explains it): the scale errors average -1 %, a bias no window can see. ``--imu synthetic`` is
the control: the same windows with an IMU synthesised from the ground truth (its own
time-varying biases, the datasheet's white noise).

The table has one row per window: start, excitation (acceleration spread per camera axis, rotation
range), status, condition number, scale error and std, gravity error and std. Every window is
solved (``solve_degenerate``) so that the windows not called OK have a scale to compare. The
summary: the worst errors of the windows called OK, the median scale error of the others, the RMS
scale error of each group (issue 10 asks that the windows the report calls degenerate really give
worse scale), the mean error, and how often the error lies within 3 reported standard deviations.
On the recorded IMU the two RMS figures come out alike: the accelerometer's gain error is common
to every window, and the OK gate (the scale's reported standard deviation) sees only the noise
part. With 4 s windows (``--window 4``) none is OK, and the 2 windows called
``insufficient_excitation`` (the MAV standing before take-off) err by 29 % and 8 197 %.

First, the static initialisation on the flight's first seconds (the MAV stands still 5.2 s):
its gravity direction and gyro bias against the ground truth's (issue 10: 0.5 deg, 2e-3 rad/s).

Run alone: ``.venv/bin/python -m bench.bench_vi_init [--quick] [--window S] [--pos-sigma M]
[--rot-sigma DEG]`` (prints the table and the summary).
"""

from __future__ import annotations

import math
import sys
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray

from amrvio.estimator.vi_init import ViInitConfig, ViInitResult, ViInitStatus, initialize_vi
from amrvio.types.lie import so3_exp
from bench.euroc_v101 import (
    V101,
    EurocFlight,
    accel_gain,
    accel_gain_bracket,
    angle_deg,
    load_flight,
    static_init_check,
    synthetic_flight,
)

F64 = NDArray[np.float64]
Row = dict[str, object]

SCALE = 3.7
WINDOW_S = 8.0
POS_SIGMA_M = 0.0003
ROT_SIGMA_DEG = 0.02


@dataclass(frozen=True, slots=True)
class WindowCase:
    """One window: start (s from the flight's first ground-truth pose), stamps_ns (K,), T_vo_cam
    (K, 4, 4) up-to-scale and noisy, gravity_vo (3,) the true gravity in the VO frame."""

    start_s: float
    stamps_ns: NDArray[np.int64]
    T_vo_cam: F64
    gravity_vo: F64


@dataclass(frozen=True, slots=True)
class WindowOutcome:
    case: WindowCase
    result: ViInitResult
    scale_err: float  # relative, signed
    gravity_err_deg: float


def make_case(flight: EurocFlight, start_s: float, window_s: float = WINDOW_S, kf_hz: float = 10.0,
              pos_sigma_m: float = POS_SIGMA_M, rot_sigma_deg: float = ROT_SIGMA_DEG,
              seed: int = 0) -> WindowCase:
    """The keyframes of the window at ``start_s`` (noise seeded by ``seed`` and the start)."""
    gt_ns = flight.gt.stamps_ns
    t = (gt_ns - gt_ns[0]).astype(np.float64) * 1e-9
    stride = max(1, round(20.0 / kf_hz))
    idx = np.flatnonzero((t >= start_s - 1e-6) & (t <= start_s + window_s + 1e-6))[::stride]
    rng = np.random.default_rng([seed, round(start_s * 1000)])
    T_body_cam = flight.T_body_cam.matrix()
    T_wc = np.empty((idx.shape[0], 4, 4))
    for j, i in enumerate(idx):
        T_wb = np.eye(4)
        T_wb[:3, :3], T_wb[:3, 3] = flight.R_world_body[i], flight.p_world_body[i]
        T_wc[j] = T_wb @ T_body_cam
        T_wc[j, :3, :3] = T_wc[j, :3, :3] @ so3_exp(np.radians(rot_sigma_deg) * rng.standard_normal(3))
        T_wc[j, :3, 3] += pos_sigma_m * rng.standard_normal(3)
    T0_inv = np.linalg.inv(T_wc[0])
    T_vo = np.einsum("ij,njk->nik", T0_inv, T_wc)
    T_vo[:, :3, 3] /= SCALE
    g_vo = T_wc[0, :3, :3].T @ flight.gravity_world
    return WindowCase(float(start_s), gt_ns[idx].astype(np.int64), T_vo, g_vo)


def run_case(flight: EurocFlight, case: WindowCase, config: ViInitConfig | None = None) -> WindowOutcome:
    cfg = replace(config or ViInitConfig(), solve_degenerate=True)
    res = initialize_vi(case.stamps_ns, case.T_vo_cam, flight.imu, flight.T_body_cam, flight.noise, cfg)
    if res.state is None:
        return WindowOutcome(case, res, float("nan"), float("nan"))
    return WindowOutcome(case, res, res.state.scale / SCALE - 1.0, angle_deg(res.state.gravity_vo, case.gravity_vo))


def window_starts(flight: EurocFlight, window_s: float, step_s: float) -> list[float]:
    span = (int(flight.gt.stamps_ns[-1]) - int(flight.gt.stamps_ns[0])) * 1e-9
    return [float(s) for s in np.arange(0.0, span - window_s + 1e-9, step_s)]


def sweep(flight: EurocFlight, starts: list[float], window_s: float = WINDOW_S, seed: int = 0,
          pos_sigma_m: float = POS_SIGMA_M, rot_sigma_deg: float = ROT_SIGMA_DEG,
          config: ViInitConfig | None = None) -> list[WindowOutcome]:
    return [run_case(flight, make_case(flight, s, window_s, 10.0, pos_sigma_m, rot_sigma_deg, seed), config)
            for s in starts]


def table(outcomes: list[WindowOutcome]) -> list[str]:
    """Markdown table, one row per window."""
    lines = ["| start s | acc x | acc y | acc z | rot deg | travel/jitter | status | cond | scale err % | scale std % "
             "| grav err deg | grav std deg |",
             "|---:|---:|---:|---:|---:|---:|---|---:|---:|---:|---:|---:|"]
    for o in outcomes:
        ex, fig, st = o.result.excitation, o.result.figures, o.result.state
        acc = ex.accel_std_cam_m_s2 if ex is not None else np.full(3, np.nan)
        lines.append(
            f"| {o.case.start_s:.0f} | {acc[0]:.2f} | {acc[1]:.2f} | {acc[2]:.2f} | "
            f"{ex.rotation_range_deg if ex else float('nan'):.0f} | {ex.translation_snr if ex else float('nan'):.0f} | "
            f"{o.result.status.value} | "
            f"{fig.condition_number if fig else float('nan'):.0f} | {100 * o.scale_err:+.2f} | "
            f"{100 * st.scale_std / st.scale if st else float('nan'):.2f} | {o.gravity_err_deg:.2f} | "
            f"{st.gravity_std_deg if st else float('nan'):.2f} |")
    return lines


def summary(outcomes: list[WindowOutcome]) -> dict[str, float]:
    """Counts and error figures: of the windows called OK, of the others (solved anyway), and how
    often the error lies within 3 reported standard deviations."""
    ok = [o for o in outcomes if o.result.status is ViInitStatus.OK]
    bad = [o for o in outcomes if o.result.status is not ViInitStatus.OK and math.isfinite(o.scale_err)]
    solved = [o for o in outcomes if o.result.state is not None and o.result.state.scale > 0]
    nan = float("nan")
    z = [abs(o.scale_err) * SCALE / o.result.state.scale_std for o in solved if o.result.state is not None]
    return {
        "windows": float(len(outcomes)),
        "ok": float(len(ok)),
        "ok_max_scale_err": max((abs(o.scale_err) for o in ok), default=nan),
        "ok_max_gravity_err_deg": max((o.gravity_err_deg for o in ok), default=nan),
        "not_ok_median_scale_err": float(np.median([abs(o.scale_err) for o in bad])) if bad else nan,
        "ok_rms_scale_err": float(np.sqrt(np.mean([o.scale_err ** 2 for o in ok]))) if ok else nan,
        "not_ok_rms_scale_err": float(np.sqrt(np.mean([o.scale_err ** 2 for o in bad]))) if bad else nan,
        "not_ok_share_over_2pct": float(np.mean([abs(o.scale_err) > 0.02 for o in bad])) if bad else nan,
        "mean_scale_err": float(np.mean([o.scale_err for o in solved])) if solved else nan,
        "share_within_3_std": float(np.mean([v < 3.0 for v in z])) if z else nan,
    }


def _rows(tag: str, s: dict[str, float], note: str) -> list[Row]:
    return [
        {"name": f"vi_init {tag}: windows OK", "value": s["ok"], "unit": f"of {s['windows']:.0f}", "note": note},
        {"name": f"vi_init {tag}: OK, worst scale error", "value": 100 * s["ok_max_scale_err"], "unit": "%",
         "note": "goal <= 2"},
        {"name": f"vi_init {tag}: OK, worst gravity error", "value": s["ok_max_gravity_err_deg"], "unit": "deg",
         "note": "goal <= 1"},
        {"name": f"vi_init {tag}: not OK, median scale error", "value": 100 * s["not_ok_median_scale_err"],
         "unit": "%", "note": "solved anyway"},
        {"name": f"vi_init {tag}: OK, RMS scale error", "value": 100 * s["ok_rms_scale_err"], "unit": "%",
         "note": "against the not-OK windows' row below: does the gate pick the better windows"},
        {"name": f"vi_init {tag}: not OK, RMS scale error", "value": 100 * s["not_ok_rms_scale_err"], "unit": "%",
         "note": "solved anyway"},
        {"name": f"vi_init {tag}: mean scale error", "value": 100 * s["mean_scale_err"], "unit": "%",
         "note": "all windows solved"},
        {"name": f"vi_init {tag}: error within 3 reported std", "value": 100 * s["share_within_3_std"], "unit": "%",
         "note": "all windows solved"},
    ]


GAIN_SHIFTS_S = tuple(round(0.005 * k, 3) for k in range(-6, 7))


def _gain_rows(flight: EurocFlight, synthetic: EurocFlight) -> list[Row]:
    """The recorded accelerometer against the ground truth (:func:`bench.euroc_v101.accel_gain`),
    and the best it gets over time shifts of the IMU's stamps; ``synthetic`` (the flight with its
    IMU synthesised from the ground truth) for scale."""
    gains = {s: accel_gain(flight, s) for s in GAIN_SHIFTS_S}  # 0.0 among them: the unshifted one
    gain, per_axis = gains[0.0]
    shifted = {s: g[0] for s, g in gains.items()}
    best = max(shifted, key=lambda s: shifted[s])
    control, _ = accel_gain(synthetic)
    axes = " / ".join(f"{g:.4f}" for g in per_axis)
    low, high = accel_gain_bracket(flight, 1.0)
    short_low, short_high = accel_gain_bracket(flight, 0.2)
    c_low, c_high = accel_gain_bracket(synthetic, 1.0)
    return [
        {"name": "vi_init recorded IMU: accelerometer over ground-truth acceleration", "value": gain, "unit": "ratio",
         "note": f"least-squares slope over the flight, 0.2 s averages, world x / y / z {axes}; "
                 f"the IMU synthesised from the ground truth gives {control:.4f}"},
        {"name": "vi_init recorded IMU: same, best over IMU time shifts", "value": shifted[best], "unit": "ratio",
         "note": f"at {best * 1e3:+.0f} ms, shifts {GAIN_SHIFTS_S[0] * 1e3:+.0f} to {GAIN_SHIFTS_S[-1] * 1e3:+.0f} ms "
                 "in 5 ms steps: no time offset explains the shortfall"},
        {"name": "vi_init recorded IMU: accelerometer gain, upper bound over 1 s averages", "value": high,
         "unit": "ratio",
         "note": f"the gain lies between {low:.4f} (slope of the accelerometer on the ground truth) and {high:.4f} "
                 "(inverse slope of the ground truth on the accelerometer) whatever independent noise either side "
                 f"carries, so below 1: not the ground truth's differentiation noise; over 0.2 s averages "
                 f"{short_low:.4f}-{short_high:.4f}, which holds 1; the synthetic control {c_low:.4f}-{c_high:.4f}"},
    ]


def _static_rows(flight: EurocFlight) -> list[Row]:
    """The static initialisation on the flight's first seconds (the MAV stands 5.2 s before take
    off) against the ground truth (:func:`bench.euroc_v101.static_init_check`)."""
    check = static_init_check(flight)
    res = check.result
    err = check.gyro_bias_err_rad_s
    std = res.gyro_bias_std_rad_s if res.gyro_bias_std_rad_s is not None else np.full(3, np.nan)
    note = (f"{res.status.value} over the first {res.duration_s:g} s; reported tilt std {res.tilt_std_deg:.2f} deg; "
            f"gyro bias error x / y / z {' / '.join(f'{1e3 * e:+.2f}' for e in err)} mrad/s (reported std "
            f"{' / '.join(f'{1e3 * e:.2f}' for e in std)}); accelerometer bias along gravity off by "
            f"{check.accel_bias_up_err_m_s2:+.3f} m/s^2 (reported std {res.accel_bias_up_std_m_s2:.3f})")
    return [
        {"name": "static init V1_01 first seconds: gravity direction error", "value": check.tilt_err_deg,
         "unit": "deg", "note": note, "target": "<= 0.5 deg", "pass": bool(check.tilt_err_deg <= 0.5)},
        {"name": "static init V1_01 first seconds: gyro bias error, largest axis",
         "value": 1e3 * float(np.max(np.abs(err))), "unit": "mrad/s", "note": note, "target": "<= 2 mrad/s",
         "pass": bool(np.max(np.abs(err)) <= 2e-3)},
    ]


def run(quick: bool) -> list[Row]:
    if not V101.is_dir():
        return []
    flight = load_flight()
    static = _static_rows(flight)
    note = (f"{WINDOW_S:g} s windows every {5 if quick else 1} s, 10 Hz keyframes, pose noise "
            f"{POS_SIGMA_M * 1e3:g} mm / {ROT_SIGMA_DEG:g} deg, scale {SCALE}")
    rows = _rows("recorded IMU", summary(sweep(flight, window_starts(flight, WINDOW_S, 5.0 if quick else 1.0))), note)
    control = synthetic_flight(flight)
    rows += _gain_rows(flight, control)
    return static + rows + _rows("synthetic IMU", summary(sweep(control, window_starts(control, WINDOW_S, 5.0))),
                                 note.replace("every 1 s", "every 5 s") + "; IMU synthesised from the ground truth")


def main(argv: list[str]) -> int:
    import argparse

    ap = argparse.ArgumentParser(description="VI initialiser along the real EuRoC V1_01 flight")
    ap.add_argument("--quick", action="store_true", help="windows every 5 s instead of 1 s")
    ap.add_argument("--window", type=float, default=WINDOW_S, help="window length, s")
    ap.add_argument("--pos-sigma", type=float, default=POS_SIGMA_M, help="keyframe position noise, m")
    ap.add_argument("--rot-sigma", type=float, default=ROT_SIGMA_DEG, help="keyframe rotation noise, deg")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--imu", choices=("recorded", "synthetic"), default="recorded",
                    help="the recorded IMU, or one synthesised from the ground truth (a control)")
    args = ap.parse_args(argv)
    flight = load_flight() if args.imu == "recorded" else synthetic_flight(load_flight(), args.seed)
    outs = sweep(flight, window_starts(flight, args.window, 5.0 if args.quick else 1.0), args.window, args.seed,
                 args.pos_sigma, args.rot_sigma)
    print("\n".join(table(outs)))
    for k, v in summary(outs).items():
        print(f"{k}: {v:.4g}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
