"""``make demo``: the main job on an embedded default, end to end.

1. ``amrvio simulate``: a 30 s AMR corridor drive (forward-stop-turn: stops and turns, the
   manoeuvre that excites an IMU) with three exposure steps and two motion-blur bursts, exact
   ground truth and a 200 Hz IMU, 376x240 at 10 frames/s;
2. ``amrvio run --camera-height H``: in one pass the per-frame diagnostics, the monocular VO
   (metric by the known camera height) that the visual-inertial odometry initialises from and
   then takes over with the IMU, the evaluation against the ground-truth body poses (eval.json),
   the events, the advice and report.html.

Everything is written under ``--out`` (default ``demo_out/``); a short summary table and the path
of report.html are printed at the end.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path
from typing import Any

from amrvio.cli.main import main as amrvio_main
from amrvio.errors import AmrvioError

SECONDS = 30.0
SIM_ARGS = [
    "--scene", "corridor", "--motion", "forward-stop-turn", "--seconds", f"{SECONDS:g}",
    "--seed", "0", "--resolution", "376x240", "--fps", "10",
    "--ev-steps", "6:-1,14:+1.5,22:-1", "--blur-bursts", "9:0.5:3,18:0.5:3",
]


def _step(title: str, argv: list[str]) -> float:
    """Run ``amrvio ARGV``; its wall time (s)."""
    print(f"\n== {title}: amrvio {' '.join(argv)}", file=sys.stderr, flush=True)
    t0 = time.perf_counter()
    rc = amrvio_main(argv)
    if rc != 0:
        raise AmrvioError(f"demo step '{title}' failed with exit code {rc}")
    return time.perf_counter() - t0


def camera_height_m(sim_dir: Path) -> float:
    """The camera's height above the floor (z = 0 in the simulator's world) at the first frame,
    from the ground truth: what a robot's mounting drawing gives."""
    from amrvio.io.dataset import open_dataset

    ds = open_dataset(f"euroc:{sim_dir}")
    if ds.groundtruth is None or ds.T_body_cam is None:
        raise AmrvioError(f"{sim_dir}: simulated sequence lacks ground truth or T_body_cam")
    cam = ds.groundtruth.interpolated_at([ds.frames[0].t_s]).right_multiplied(ds.T_body_cam)
    return float(cam.positions_m[0, 2])


def _fmt(v: Any, unit: str = "", nd: int = 3) -> str:
    return "n/a" if v is None else f"{v:.{nd}f}{unit}"


def summary_table(summary: dict[str, Any], ev: dict[str, Any] | None, height: float,
                  t_sim: float, t_run: float) -> list[tuple[str, str]]:
    """The rows printed at the end of the demo."""
    n = summary["n_frames"]
    c = summary["status_counts"]
    ranges = summary.get("flagged_ranges", {})
    rows = [
        ("frames", f"{n} ({summary['n_in_trajectory']} with a pose: {c['tracked']} tracked, "
                   f"{c.get('bridged', 0)} bridged by the IMU, {c['interpolated']} interpolated; "
                   f"{c['lost']} lost)"),
        ("keyframes / map points", f"{summary['n_keyframes']} / {summary['n_map_points']}"),
        ("flagged ranges", ", ".join(f"{k.replace('_', ' ')} {len(v)}"
                                     for k, v in ranges.items() if k != "lost")),
        ("camera height (scale)", f"{height:.3f} m"),
    ]
    yaw = ev.get("yaw_aligned") if ev else None
    if ev is not None and ev.get("error") and isinstance(yaw, dict):
        # a path whose positions lie on a line (turns on the spot) has no Sim3 alignment
        rows += [
            ("estimate", f"{ev.get('frame', 'cam')} poses, metric scale from "
                         f"{ev.get('metric_scale_source') or 'none'}"),
            ("ATE, gravity-aligned", f"{_fmt(yaw.get('ate_m'), ' m')} (the path is straight: "
                                     "no Sim3 alignment)"),
            ("scale error", _fmt(yaw.get("scale_error_pct"), " %", 2)),
        ]
    elif ev is None or ev.get("error"):
        rows.append(("evaluation", "not possible: " + str(ev.get("error") if ev else "no GT")))
    else:
        rows += [
            ("estimate", f"{ev.get('frame', 'cam')} poses, metric scale from "
                         f"{ev.get('metric_scale_source') or 'none'}"),
            ("ground-truth path", _fmt(ev["path_length_m"], " m", 2)),
            ("ATE, Sim3 aligned", f"{_fmt(ev['ate_sim3_m'], ' m')} = "
                                  f"{_fmt(ev['ate_sim3_pct_of_path'], ' % of the path', 2)}"),
            ("ATE, metric (SE3)", _fmt(ev.get("ate_metric_m"), " m")),
            ("scale error", _fmt(ev.get("scale_error_pct"), " %", 2)),
        ]
    rows.append(("wall time", f"simulate {t_sim:.0f} s, run {t_run:.0f} s "
                              f"({n / t_run:.1f} frames/s)" if t_run > 0 else ""))
    return rows


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description="Run amrvio end to end on a simulated AMR corridor drive.")
    ap.add_argument("--out", type=Path, default=Path("demo_out"))
    args = ap.parse_args(argv)
    out: Path = args.out
    sim, run = out / "sim", out / "run"
    try:
        out.mkdir(parents=True, exist_ok=True)
        t_sim = _step("simulate", ["simulate", *SIM_ARGS, "--out", str(sim), "--force"])
        height = camera_height_m(sim)
        t_run = _step("run", ["run", f"euroc:{sim}", "--out", str(run), "--force",
                              "--camera-height", f"{height:.4f}"])
    except (AmrvioError, OSError) as err:
        print(f"amrvio demo: error: {err}", file=sys.stderr)
        return 1
    summary = json.loads((run / "summary.json").read_text(encoding="utf-8"))
    ev_path = run / "eval.json"
    ev = json.loads(ev_path.read_text(encoding="utf-8")) if ev_path.is_file() else None
    advice = (run / "advice.txt").read_text(encoding="utf-8").splitlines()
    rows = summary_table(summary, ev, height, t_sim, t_run)
    width = max(len(k) for k, _ in rows)
    print(f"\namrvio demo: {SECONDS:g} s simulated AMR corridor drive (stops and turns, 3 exposure "
          "steps, 2 blur bursts), visual-inertial odometry")
    for k, v in rows:
        print(f"  {k:<{width}}  {v}")
    print(f"  advice ({len(advice)} lines), first ones:")
    for line in advice[:3]:
        print(f"    {line}")
    print(f"\nreport: {(run / 'report.html').resolve()}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
