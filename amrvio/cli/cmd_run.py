"""``amrvio run DATASET --out DIR``: monocular VO over a recording."""

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
    parser.add_argument("--camera-height", type=positive_float, default=None, metavar="H",
                        help="camera height above the ground (m): metric scale from the ground "
                             "plane")
    parser.add_argument("--max-frames", type=int, default=None, help="use the first N frames")
    parser.add_argument("--no-photometric", action="store_true",
                        help="disable the affine brightness compensation before KLT (ablation)")
    parser.add_argument("--no-blur-gating", action="store_true",
                        help="use blurred frames like sharp ones (ablation)")
    parser.add_argument("--ba-backend", choices=("gtsam", "scipy"), default="gtsam",
                        help="local bundle adjustment solver (default: gtsam, LM with "
                             "SEQUENTIAL_CHOLESKY; scipy converges more slowly, see bench_vo)")
    parser.add_argument("--seed", type=int, default=0, help="RANSAC seed (default 0)")


def run(args: argparse.Namespace) -> int:
    import dataclasses

    from amrvio.io.dataset import open_dataset
    from amrvio.pipeline.run import run_vo, write_outputs
    from amrvio.pipeline.threads import limit_native_threads
    from amrvio.pipeline.vo import VoConfig

    # one thread for OpenCV and OpenBLAS: measured faster for the VO's small solves
    limit_native_threads(1)
    ds = open_dataset(args.dataset, args.calib)
    base = VoConfig()
    cfg = dataclasses.replace(
        base,
        klt=dataclasses.replace(base.klt, photometric=not args.no_photometric, seed=args.seed),
        blur_gating=not args.no_blur_gating,
        camera_height_m=args.camera_height,
        ba_backend=args.ba_backend,
        seed=args.seed,
    )
    out = run_vo(ds, cfg, max_frames=args.max_frames, progress=True)
    summary = write_outputs(out, args.out)
    counts = summary["status_counts"]
    print(f"{summary['n_frames']} frames {counts}, {summary['n_keyframes']} keyframes, "
          f"{summary['n_map_points']} map points -> {args.out}")
    return 0
