"""``amrvio run DATASET --out DIR``: the pipeline over a recording."""

from __future__ import annotations

import argparse
from pathlib import Path

from amrvio.cli.args import MAX_FRAMES, SEED_RANGE, bounded, interval, max_frames_int, seed_int

CAMERA_HEIGHT_M = (0.01, 100.0)
"""--camera-height range (m)."""

NAME = "run"
HELP = "run monocular visual odometry on a dataset and write trajectory, keyframes, map, status"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("dataset", help="dataset folder or KIND:PATH (kitti:, euroc:, ...)")
    parser.add_argument("--out", type=Path, required=True,
                        help="output folder: created if missing, checked before any work; a "
                             "non-empty one needs --force")
    parser.add_argument("--force", action="store_true",
                        help="write into a non-empty --out (the files of an earlier run are "
                             "removed first; other files are left alone)")
    parser.add_argument("--calib", type=Path, default=None, help="override the calibration file")
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
    parser.add_argument("--ba-backend", choices=("gtsam", "scipy"), default=None,
                        help="local bundle adjustment solver (default: gtsam, LM with "
                             "SEQUENTIAL_CHOLESKY; config: mapping.mapper.ba_backend)")
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


def run(args: argparse.Namespace) -> int:
    import sys

    from amrvio.cli.interrupt import StopRequest
    from amrvio.config import PipelineConfig
    from amrvio.io.dataset import open_dataset
    from amrvio.io.outdir import prepare_output_dir
    from amrvio.pipeline.diagnose import setup_diagnostics
    from amrvio.pipeline.run import run_pipeline
    from amrvio.pipeline.run_output import RUN_OUTPUTS, RunWriter
    from amrvio.pipeline.threads import limit_native_threads

    cfg = build_config(args)
    if not isinstance(cfg, PipelineConfig):
        raise TypeError("build_config returned no PipelineConfig")
    prepare_output_dir(args.out, args.force, RUN_OUTPUTS)
    # one thread for OpenCV and OpenBLAS: measured faster for the VO's small solves
    limit_native_threads(1)
    ds = open_dataset(args.dataset, args.calib)
    setup = setup_diagnostics(ds, cfg.diagnostics) if cfg.diagnose else None
    n_planned = min(len(ds.frames), args.max_frames or len(ds.frames))
    writer = RunWriter(args.out, cfg, setup.notes if setup is not None else (), n_planned)
    writer.begin()
    try:
        with StopRequest() as stop:
            out = run_pipeline(ds, cfg, max_frames=args.max_frames, progress=True,
                               diagnostics=setup, sink=writer, stop=stop)
            summary = writer.finish(out, interrupted=stop.requested)
    except KeyboardInterrupt:  # a second Ctrl-C: keep the partial files as they are
        writer.abandon()
        raise
    if stop.requested:
        print(f"amrvio run: interrupted after {summary['n_frames']} of {n_planned} frames; "
              f"partial outputs in {args.out} (summary.json: \"interrupted\": true)",
              file=sys.stderr)
        return 130
    counts = summary["status_counts"]
    skipped = f", {summary['n_skipped']} skipped (see summary.json)" if summary["n_skipped"] else ""
    print(f"{summary['n_frames']} frames {counts}{skipped}, {summary['n_keyframes']} keyframes, "
          f"{summary['n_map_points']} map points -> {args.out}")
    return 0
