"""``amrvio run DATASET --out DIR``: the pipeline over a recording."""

from __future__ import annotations

import argparse
from pathlib import Path

from amrvio.cli.args import positive_float

NAME = "run"
HELP = "run monocular visual odometry on a dataset and write trajectory, keyframes, map, status"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("dataset", help="dataset folder or KIND:PATH (kitti:, euroc:, ...)")
    parser.add_argument("--out", type=Path, required=True, help="output folder")
    parser.add_argument("--calib", type=Path, default=None, help="override the calibration file")
    parser.add_argument("--config", type=Path, default=None, metavar="FILE.yaml",
                        help="pipeline configuration (keys = field names; `amrvio config --dump` "
                             "prints the defaults); the options below override it")
    parser.add_argument("--camera-height", type=positive_float, default=None, metavar="H",
                        help="camera height above the ground (m): metric scale from the ground "
                             "plane (config: scale.camera_height_m)")
    parser.add_argument("--max-frames", type=int, default=None, help="use the first N frames")
    parser.add_argument("--no-photometric", action="store_true",
                        help="no brightness compensation: KLT, anchor re-tracking and direct "
                             "alignment assume brightness constancy (ablation)")
    parser.add_argument("--no-blur-gating", action="store_true",
                        help="use blurred frames like sharp ones (ablation; config: blur_gating)")
    parser.add_argument("--ba-backend", choices=("gtsam", "scipy"), default=None,
                        help="local bundle adjustment solver (default: gtsam, LM with "
                             "SEQUENTIAL_CHOLESKY; config: mapping.mapper.ba_backend)")
    parser.add_argument("--seed", type=int, default=None, help="seed of every random choice "
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
    from amrvio.config import PipelineConfig
    from amrvio.io.dataset import open_dataset
    from amrvio.pipeline.diagnose import setup_diagnostics
    from amrvio.pipeline.run import run_pipeline, write_outputs
    from amrvio.pipeline.threads import limit_native_threads

    cfg = build_config(args)
    if not isinstance(cfg, PipelineConfig):
        raise TypeError("build_config returned no PipelineConfig")
    # one thread for OpenCV and OpenBLAS: measured faster for the VO's small solves
    limit_native_threads(1)
    ds = open_dataset(args.dataset, args.calib)
    setup = setup_diagnostics(ds, cfg.diagnostics) if cfg.diagnose else None
    out = run_pipeline(ds, cfg, max_frames=args.max_frames, progress=True, diagnostics=setup)
    summary = write_outputs(out, args.out, cfg, setup.notes if setup is not None else ())
    counts = summary["status_counts"]
    print(f"{summary['n_frames']} frames {counts}, {summary['n_keyframes']} keyframes, "
          f"{summary['n_map_points']} map points -> {args.out}")
    return 0
