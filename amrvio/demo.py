"""``make demo``: the main job on an embedded default, end to end.

1. ``amrvio simulate``: a 10 s AMR corridor drive (forward-stop-turn) with three exposure steps
   and two motion-blur bursts, with exact ground truth;
2. ``amrvio diagnose``: the per-frame health record and advice;
3. ``amrvio run --camera-height H``: monocular VO made metric by the known camera height;
4. ``amrvio eval``: the VO trajectory against the ground-truth camera poses, with no scale
   alignment (SE3) and with Sim3.

Everything is written under ``--out`` (default ``demo_out/``); a short summary is printed.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from amrvio.cli.main import main as amrvio_main
from amrvio.errors import AmrvioError

SIM_ARGS = [
    "--scene", "corridor", "--motion", "forward-stop-turn", "--seconds", "10", "--seed", "0",
    "--ev-steps", "2:+1,4.5:-1.5,7:+1", "--blur-bursts", "3:0.5:3,6:0.5:3",
]


def _step(title: str, argv: list[str]) -> None:
    print(f"\n== {title}: amrvio {' '.join(argv)}", file=sys.stderr)
    rc = amrvio_main(argv)
    if rc != 0:
        raise AmrvioError(f"demo step '{title}' failed with exit code {rc}")


def _camera_ground_truth(sim_dir: Path, out_tum: Path) -> float:
    """Write the ground-truth camera poses at the image times; return the camera height (m)."""
    import numpy as np

    from amrvio.io.dataset import open_dataset
    from amrvio.io.trajectory import write_tum

    ds = open_dataset(f"euroc:{sim_dir}")
    if ds.groundtruth is None or ds.T_body_cam is None:
        raise AmrvioError(f"{sim_dir}: simulated sequence lacks ground truth or T_body_cam")
    frame_t = np.array([f.t_s for f in ds.frames])  # mid-exposure stamps, between IMU-rate GT samples
    cam = ds.groundtruth.interpolated_at(frame_t).right_multiplied(ds.T_body_cam)
    write_tum(out_tum, cam)
    return float(cam.positions_m[0, 2])  # the floor is z = 0 in the simulator's world


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description="Run amrvio end to end on a simulated AMR corridor drive.")
    ap.add_argument("--out", type=Path, default=Path("demo_out"))
    args = ap.parse_args(argv)
    out: Path = args.out
    out.mkdir(parents=True, exist_ok=True)
    sim, diag, run = out / "sim", out / "diagnose", out / "run"
    try:
        _step("simulate", ["simulate", *SIM_ARGS, "--out", str(sim), "--force"])
        _step("diagnose", ["diagnose", f"euroc:{sim}", "--out", str(diag)])
        height = _camera_ground_truth(sim, out / "gt_camera.tum")
        _step("run", ["run", f"euroc:{sim}", "--out", str(run), "--camera-height", f"{height:.4f}"])
        traj, gt = str(run / "trajectory.tum"), str(out / "gt_camera.tum")
        _step("eval (metric, no scale alignment)",
              ["eval", traj, gt, "--align", "se3", "--json", str(out / "eval_se3.json"),
               "--plot", str(out / "eval_se3.png")])
        _step("eval (Sim3)", ["eval", traj, gt, "--align", "sim3", "--json", str(out / "eval_sim3.json")])
    except AmrvioError as err:
        print(f"amrvio demo: error: {err}", file=sys.stderr)
        return 1
    se3 = json.loads((out / "eval_se3.json").read_text())
    sim3 = json.loads((out / "eval_sim3.json").read_text())
    summary = json.loads((run / "summary.json").read_text())
    advice = (diag / "advice.txt").read_text().splitlines()
    print("\namrvio demo summary")
    print(f"  frames: {summary.get('n_frames')} {summary.get('status_counts')}")
    print(f"  camera height used for metric scale: {height:.3f} m")
    print(f"  path {se3['path_length_m']:.2f} m; ATE (SE3, metric) {se3['ate_rmse_m']:.3f} m; "
          f"scale error {se3['scale_error_pct']:.2f} %; ATE (Sim3) {sim3['ate_rmse_m']:.3f} m "
          f"= {100 * sim3['ate_rmse_m'] / se3['path_length_m']:.2f} % of the path")
    print(f"  health record: {diag / 'health.csv'}; advice ({len(advice)} lines), first ones:")
    for line in advice[:5]:
        print(f"    {line}")
    print(f"  outputs under {out}/")
    return 0


if __name__ == "__main__":
    sys.exit(main())
