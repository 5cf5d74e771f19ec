"""``amrvio run DATASET --out DIR``: the pipeline over a recording."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from amrvio.cli.args import MAX_FRAMES, SEED_RANGE, bounded, interval, max_frames_int, seed_int

CAMERA_HEIGHT_M = (0.01, 100.0)
WHEEL_FACTOR = (0.5, 2.0)
"""--camera-height range (m)."""

NAME = "run"
HELP = ("diagnostics, tracking, evaluation and report in one pass: trajectory, health record, "
        "events, advice, eval.json (with ground truth) and report.html")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("dataset", help="dataset folder or KIND:PATH (kitti:, euroc:, ...)")
    parser.add_argument("--out", type=Path, required=True,
                        help="output folder: created if missing, checked before any work; a "
                             "non-empty one needs --force")
    parser.add_argument("--force", action="store_true",
                        help="write into a non-empty --out (the files of an earlier run are "
                             "removed first; other files are left alone)")
    parser.add_argument("--calib", type=Path, default=None, help="override the calibration file")
    parser.add_argument("--gt", type=Path, default=None, metavar="FILE",
                        help="ground truth for eval.json (TUM, EuRoC CSV or KITTI poses), "
                             "replacing the dataset's own")
    parser.add_argument("--gt-frame", choices=("cam", "body"), default="cam",
                        help="--gt holds camera poses (default) or body poses (then times the "
                             "dataset's camera-body transform)")
    add_config_arguments(parser)
    parser.add_argument("--progress", action="store_true",
                        help="show the progress bar and the live health line on stderr even when "
                             "it is not a terminal (default: only on a terminal)")
    parser.add_argument("--no-report", action="store_true", help="do not write report.html")
    parser.add_argument("--bag-out", type=Path, default=None, metavar="FOLDER",
                        help="also write the trajectory as a ROS 2 bag (nav_msgs/Odometry on "
                             "/amrvio/odometry, rosbag2 format 8), a new folder")


def add_config_arguments(parser: argparse.ArgumentParser) -> None:
    """--config and the options that override it, and --max-frames (``run`` and ``batch``)."""
    parser.add_argument("--config", type=Path, default=None, metavar="FILE.yaml",
                        help="pipeline configuration (keys = field names; `amrvio config --dump` "
                             "prints the defaults); the options below override it")
    parser.add_argument("--camera-height", type=bounded(*CAMERA_HEIGHT_M), default=None,
                        metavar="H",
                        help="camera height above the ground (m, in "
                             f"{interval(*CAMERA_HEIGHT_M)}): metric scale from the ground "
                             "plane (config: scale.camera_height_m)")
    parser.add_argument("--max-frames", type=max_frames_int, default=None, metavar="N",
                        help=f"use the first N frames (N in {interval(1, MAX_FRAMES)})")
    parser.add_argument("--no-photometric", action="store_true",
                        help="no brightness compensation: KLT, anchor re-tracking and direct "
                             "alignment assume brightness constancy (ablation)")
    parser.add_argument("--no-blur-gating", action="store_true",
                        help="use blurred frames like sharp ones (ablation; config: blur_gating)")
    parser.add_argument("--no-imu", action="store_true",
                        help="ignore the recording's IMU: the monocular VO alone, up to scale "
                             "(default: visual-inertial odometry whenever the recording has an IMU "
                             "and a camera-IMU transform; config: vio.enabled)")
    parser.add_argument("--wheels", action="store_true",
                        help="a ground robot: use the recording's wheel odometry (forward speed, "
                             "no sideways or vertical motion) in the VIO, and as the VO's scale "
                             "source, which makes the scale metric even at constant velocity "
                             "(config: vio.wheel_sigma_m_s, scale.wheel.enabled)")
    parser.add_argument("--wheel-factor", type=bounded(*WHEEL_FACTOR), default=None, metavar="F",
                        help="the wheels' calibration: metres they read per metre driven, in "
                             f"{interval(*WHEEL_FACTOR)}; wheel readings are divided by it (a run without "
                             "--wheels measures it, see advice.txt; config: scale.wheel.factor)")
    parser.add_argument("--ba-backend", choices=("gtsam", "schur", "scipy"), default=None,
                        help="local bundle adjustment solver (default: gtsam, LM with "
                             "SEQUENTIAL_CHOLESKY; schur: the same LM in NumPy on the reduced "
                             "camera system, about 2x faster; config: mapping.mapper.ba_backend)")
    parser.add_argument("--seed", type=seed_int, default=None,
                        help=f"seed of every random choice, in {interval(*SEED_RANGE)} "
                             "(default 0; config: seed)")


def build_config(args: argparse.Namespace) -> object:
    """The PipelineConfig of the file (or the defaults) with the command-line overrides."""
    import dataclasses

    from amrvio.config import PipelineConfig, load_config, without_photometric

    cfg = load_config(args.config) if args.config is not None else PipelineConfig()
    if args.no_photometric:
        cfg = without_photometric(cfg)
    if args.no_blur_gating:
        cfg = dataclasses.replace(cfg, blur_gating=False)
    if getattr(args, "no_imu", False):
        cfg = dataclasses.replace(cfg, vio=dataclasses.replace(cfg.vio, enabled=False))
    if getattr(args, "wheels", False):
        if cfg.vio.wheel_sigma_m_s <= 0:
            cfg = dataclasses.replace(cfg, vio=dataclasses.replace(cfg.vio, wheel_sigma_m_s=0.05))
        cfg = dataclasses.replace(cfg, scale=dataclasses.replace(
            cfg.scale, wheel=dataclasses.replace(cfg.scale.wheel, enabled=True)))
    if getattr(args, "wheel_factor", None) is not None:
        cfg = dataclasses.replace(cfg, scale=dataclasses.replace(
            cfg.scale, wheel=dataclasses.replace(cfg.scale.wheel, factor=args.wheel_factor)))
    if args.camera_height is not None:
        cfg = dataclasses.replace(cfg, scale=dataclasses.replace(
            cfg.scale, camera_height_m=args.camera_height))
    if args.ba_backend is not None:
        mp = cfg.mapping
        cfg = dataclasses.replace(cfg, mapping=dataclasses.replace(
            mp, mapper=dataclasses.replace(mp.mapper, ba_backend=args.ba_backend)))
    if args.seed is not None:
        cfg = dataclasses.replace(cfg, seed=args.seed)
    return cfg


def show_progress(args: argparse.Namespace) -> bool:
    """The progress bar: with --progress, or when stderr is a terminal."""
    import sys

    return bool(args.progress) or sys.stderr.isatty()


def run(args: argparse.Namespace) -> int:
    import sys

    from amrvio.app.run import run as run_recording
    from amrvio.cli.interrupt import StopRequest
    from amrvio.config import PipelineConfig
    from amrvio.pipeline.threads import run_settings

    cfg = build_config(args)
    if not isinstance(cfg, PipelineConfig):
        raise TypeError("build_config returned no PipelineConfig")
    # one thread for OpenCV and OpenBLAS (measured faster for the VO's small solves); a long
    # run's freed arrays go back to the system (amrvio.pipeline.heap)
    run_settings()
    with StopRequest() as stop:
        res = run_recording(args.dataset, cfg, out=args.out, calib=args.calib,
                            max_frames=args.max_frames, force=args.force,
                            progress=show_progress(args), report=not args.no_report,
                            bag_out=args.bag_out, gt=args.gt, gt_frame=args.gt_frame,
                            stop=stop)
    summary = res.summary
    if res.interrupted:
        print(f"amrvio run: interrupted after {summary['n_frames']} frames; partial outputs in "
              f"{args.out} (summary.json: \"interrupted\": true)", file=sys.stderr)
        return 130
    print(format_summary(summary, res.eval_summary, args.out))
    return 0


def format_summary(summary: dict[str, Any], ev: dict[str, Any] | None, out: Path) -> str:
    """The lines ``amrvio run`` prints at the end."""
    counts = summary["status_counts"]
    n_skipped = summary["n_skipped"]
    skipped = f", {n_skipped} skipped (see summary.json)" if n_skipped else ""
    lines = [f"{summary['n_frames']} frames {counts}{skipped}, {summary['n_keyframes']} keyframes, "
             f"{summary['n_map_points']} map points -> {out}"]
    if ev is not None:
        ya = ev.get("yaw_aligned")
        if ev.get("error") and ya:
            lines.append(f"evaluation: {ev['error']}; aligned about gravity instead: metric ATE "
                         f"{ya['ate_m']:.3f} m, scale error {ya['scale_error_pct']:.2f} %")
        elif ev.get("error"):
            lines.append(f"evaluation: not possible: {ev['error']}")
        else:
            text = (f"evaluation: ATE {ev['ate_sim3_m']:.3f} m Sim3 = "
                    f"{ev['ate_sim3_pct_of_path']:.2f} % of {ev['path_length_m']:.1f} m")
            if ev.get("ate_metric_m") is not None:
                text += (f"; metric ATE {ev['ate_metric_m']:.3f} m, scale error "
                         f"{ev['scale_error_pct']:.2f} %")
            lines.append(text)
    report = out / "report.html"
    if report.is_file():
        lines.append(f"report: {report}")
    return "\n".join(lines)
