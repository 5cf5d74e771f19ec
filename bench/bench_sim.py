"""Simulator pipeline benchmark: IMU synthesis speed, end-to-end `simulate` cost per frame,
and the IMU integration accuracy (noise-free, RK4, 10 s) per motion.

Run alone: ``.venv/bin/python -m bench.bench_sim`` (add ``--quick`` for fewer repeats).
"""

from __future__ import annotations

import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from amrvio.sim.imu_synth import GRAVITY_WORLD, synthesize_imu
from amrvio.sim.motion import MOTION_KINDS, MotionLayout, make_motion
from amrvio.sim.simulate import SimConfig, simulate
from amrvio.types.lie import hat

F64 = NDArray[np.float64]


def _rk4_final_error(kind: str) -> float:
    """Max position error (m) of RK4 integration of the noise-free 200 Hz IMU over 10 s."""
    m = make_motion(kind, 10.0, MotionLayout(free_length_m=35.0), seed=5)
    syn = synthesize_imu(m, 200.0)
    s = m.states(syn.t_s)
    R, v, p = s.R_world_body[0].copy(), s.v_world[0].copy(), s.p_world[0].copy()
    h = 2.0 / 200.0
    gyro, acc = syn.imu.gyro_rad_s, syn.imu.accel_m_s2
    err = 0.0
    for k in range(0, len(gyro) - 2, 2):
        def f(R_: F64, v_: F64, i: int) -> tuple[F64, F64, F64]:
            return R_ @ hat(gyro[i]), R_ @ acc[i] + GRAVITY_WORLD, v_

        k1 = f(R, v, k)
        k2 = f(R + h / 2 * k1[0], v + h / 2 * k1[1], k + 1)
        k3 = f(R + h / 2 * k2[0], v + h / 2 * k2[1], k + 1)
        k4 = f(R + h * k3[0], v + h * k3[1], k + 2)
        R = R + h / 6 * (k1[0] + 2 * k2[0] + 2 * k3[0] + k4[0])
        p = p + h / 6 * (k1[2] + 2 * k2[2] + 2 * k3[2] + k4[2])
        v = v + h / 6 * (k1[1] + 2 * k2[1] + 2 * k3[1] + k4[1])
        U, _, Vt = np.linalg.svd(R)
        R = U @ Vt
        err = max(err, float(np.linalg.norm(p - s.p_world[k + 2])))
    return err


def run(quick: bool) -> list[dict[str, object]]:
    repeats = 1 if quick else 3
    out: list[dict[str, object]] = []

    m = make_motion("handheld", 60.0, seed=0)
    times = []
    for _ in range(repeats + 2):
        t0 = time.perf_counter()
        syn = synthesize_imu(m, 200.0)
        times.append(time.perf_counter() - t0)
    out.append({"name": "imu_synth_rate", "value": len(syn.imu) / float(np.median(times)),
                "unit": "samples/s", "note": "handheld, 60 s at 200 Hz, noise-free"})

    seconds = 1.0 if quick else 2.0
    for blur in (False, True):
        per_frame = []
        for _ in range(repeats):
            with tempfile.TemporaryDirectory() as tmp:
                cfg = SimConfig(scene="corridor", motion="forward-stop-turn", seconds=seconds,
                                blur=blur, blur_bursts="0.2:0.6:2.0", seed=1)
                t0 = time.perf_counter()
                summary = simulate(cfg, Path(tmp))
                per_frame.append((time.perf_counter() - t0) / summary.n_frames)
        out.append({
            "name": f"simulate_752x480_{'blur' if blur else 'noblur'}_ms_per_frame",
            "value": 1e3 * float(np.median(per_frame)), "unit": "ms",
            "note": f"wall clock / frames, end to end incl. the fixed scene build, IMU, wheel, "
                    f"PNG writes; corridor, {seconds:g} s at 20 fps, yaw burst 2 rad/s, "
                    f"max smear {summary.max_smear_px:.1f} px",
        })

    for kind in MOTION_KINDS:
        out.append({"name": f"imu_rk4_10s_max_pos_error_{kind}", "value": 1e3 * _rk4_final_error(kind),
                    "unit": "mm", "note": "noise-free 200 Hz IMU, RK4 from the GT initial state"})
    return out


if __name__ == "__main__":
    for row in run("--quick" in sys.argv):
        print(f"{row['name']:<50} {row['value']:>12.4g} {row['unit']:<10} {row['note']}")
