"""``amrvio eval EST GT``: ATE, RPE, scale error and scale drift of a trajectory against ground truth."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from amrvio.cli.args import MAX_FRAMES, bounded, interval

DELTA = (0.0, 1e6)
MAX_DIFF_S = (0.0, 3600.0)
DRIFT_WINDOW_M = (0.0, 1e7)

NAME = "eval"
HELP = "compare an estimated trajectory with ground truth (ATE, RPE, Sim3 scale, scale drift)"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("est", type=Path, help="estimated trajectory (TUM, KITTI or EuRoC CSV)")
    parser.add_argument("gt", type=Path, help="ground-truth trajectory (TUM, KITTI or EuRoC CSV)")
    parser.add_argument(
        "--align",
        choices=("none", "origin", "se3", "sim3"),
        default="sim3",
        help="alignment of the estimate before the errors (default: sim3, Umeyama with scale)",
    )
    parser.add_argument(
        "--delta", type=bounded(*DELTA, lo_open=True), default=1.0,
        help=f"RPE pair distance, in {interval(*DELTA, lo_open=True)} (default: 1)"
    )
    parser.add_argument(
        "--delta-unit",
        choices=("frames", "m"),
        default="frames",
        help="unit of --delta (default: frames)",
    )
    parser.add_argument(
        "--all-pairs",
        action="store_true",
        help="RPE over every pair (i, i+delta) instead of consecutive pairs (as evo_rpe --all_pairs)",
    )
    parser.add_argument(
        "--max-diff",
        type=bounded(*MAX_DIFF_S),
        default=0.01,
        metavar="S",
        help=f"largest stamp difference (s) to associate two poses, in {interval(*MAX_DIFF_S)} "
        "(default: 0.01)",
    )
    parser.add_argument(
        "--n-align",
        type=bounded(1, MAX_FRAMES, integer=True),
        default=None,
        metavar="N",
        help=f"align on the first N associated poses only, N in {interval(1, MAX_FRAMES)} "
        "(default: all)",
    )
    parser.add_argument(
        "--drift-window",
        type=bounded(*DRIFT_WINDOW_M, lo_open=True),
        default=None,
        metavar="M",
        help="scale-drift window length in metres of ground-truth path, in "
        f"{interval(*DRIFT_WINDOW_M, lo_open=True)} (default: 10%% of it)",
    )
    parser.add_argument("--gt-times", type=Path, default=None, help="times file for a KITTI GT")
    parser.add_argument("--est-times", type=Path, default=None, help="times file for a KITTI EST")
    parser.add_argument("--json", type=Path, default=None, metavar="OUT", help="write the figures")
    parser.add_argument(
        "--plot", type=Path, default=None, metavar="OUT.png", help="top view and error over time"
    )


def _fmt(v: float | None, digits: int = 4) -> str:
    return "n/a" if v is None else f"{v:.{digits}f}"


def format_table(summary: dict[str, Any]) -> str:
    """The compact text table printed by ``amrvio eval`` (from ``EvalResult.to_json_dict()``)."""
    unit = "frames" if summary["rpe_delta_unit"] == "frames" else "m"
    delta = summary["rpe_delta"]
    delta_txt = f"{delta:g} {unit}"
    n_align = summary["n_align"]
    align = summary["align"] + ("" if n_align is None else f" (first {n_align} poses)")
    rows = [
        ("alignment", align),
        ("matched poses", f"{summary['matched_poses']} (est {summary['est_poses']}, "
         f"gt {summary['gt_poses']})"),
        ("gt path length [m]", _fmt(summary["path_length_m"], 3)),
        ("ATE rmse [m]", _fmt(summary["ate_rmse_m"], 6)),
        ("ATE mean [m]", _fmt(summary["ate_mean_m"], 6)),
        ("ATE median [m]", _fmt(summary["ate_median_m"], 6)),
        ("ATE max [m]", _fmt(summary["ate_max_m"], 6)),
        (f"RPE trans rmse [m] / {delta_txt}", _fmt(summary["rpe_trans_rmse_m"], 6)),
        (f"RPE rot rmse [deg] / {delta_txt}", _fmt(summary["rpe_rot_rmse_deg"], 6)),
        ("RPE pairs", str(summary["rpe_pairs"])),
        ("Sim3 scale", _fmt(summary["scale"], 6)),
        ("scale error [%]", _fmt(summary["scale_error_pct"], 3)),
        ("scale drift [%] (max/min window)", _fmt(summary["scale_drift_pct"], 3)),
    ]
    width = max(len(k) for k, _ in rows)
    lines = [f"{k:<{width}}  {v}" for k, v in rows]
    windows = summary["scale_drift_windows"]
    if windows:
        scales = " ".join("-" if w["scale"] is None else f"{w['scale']:.4f}" for w in windows)
        lines.append(f"{'window scales':<{width}}  {scales}")
    return "\n".join(lines)


def run(args: argparse.Namespace) -> int:
    from amrvio.cli.args import check_output_file, write_json
    from amrvio.errors import ConfigError
    from amrvio.eval import evaluate
    from amrvio.io.trajectory import read_trajectory

    check_output_file(args.json, "--json")
    check_output_file(args.plot, "--plot")
    est = read_trajectory(args.est, times=args.est_times)
    gt = read_trajectory(args.gt, times=args.gt_times)
    result = evaluate(
        est,
        gt,
        align=args.align,
        delta=args.delta,
        delta_unit=args.delta_unit,
        max_diff_s=args.max_diff,
        n_align=args.n_align,
        drift_window_m=args.drift_window,
        all_pairs=args.all_pairs,
    )
    summary = result.to_json_dict()
    summary["est_file"] = str(args.est)
    summary["gt_file"] = str(args.gt)
    print(format_table(summary))
    if args.json is not None:
        write_json(args.json, summary)
    if args.plot is not None:
        from amrvio.report.plots import plot_eval

        try:
            plot_eval(result, args.plot, title=f"{args.est.name} vs {args.gt.name}")
        except OSError as err:
            raise ConfigError(f"--plot {args.plot}: cannot write: {err.strerror}") from None
    return 0
