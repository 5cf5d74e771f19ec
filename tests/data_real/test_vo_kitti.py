"""KITTI 00: `amrvio run` on the first 60 frames, and the VO on every 3rd frame of 0-199 (from
frames 0, 1 and 2); every frame has a pose, ATE bound vs GT."""

from __future__ import annotations

import csv
import dataclasses
from pathlib import Path

import numpy as np
import pytest

from amrvio.cli.main import main
from amrvio.config import PipelineConfig
from amrvio.eval.evaluate import evaluate
from amrvio.frontend.tracking_types import TrackOutcome
from amrvio.io.dataset import open_dataset
from amrvio.io.trajectory import read_kitti, read_tum
from amrvio.pipeline.records import PoseStatus
from amrvio.pipeline.run import run_pipeline
from amrvio.types.trajectory import Trajectory

N = 60


@pytest.mark.real_data
def test_vo_kitti_first_60_frames(shared_data: Path, tmp_path: Path) -> None:
    seq = shared_data / "kitti00_0000-0199"
    out = tmp_path / "out"
    rc = main(["run", f"kitti:{seq}", "--out", str(out), "--max-frames", str(N),
               "--camera-height", "1.65"])
    assert rc == 0
    est = read_tum(out / "trajectory.tum")
    assert len(est) == N
    assert np.all(np.isfinite(est.positions_m))
    with (out / "health.csv").open() as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == N
    assert all(r["status"] in ("tracked", "interpolated") for r in rows)
    assert sum(r["status"] == "tracked" for r in rows) >= N - 2
    gt = read_kitti(seq / "poses.txt", seq / "times.txt").select(np.arange(N))
    res = evaluate(est, gt, align="sim3")
    # 55 m path: a 1 % bound (ORB-SLAM3 reaches 0.65 % over 200 frames)
    assert res.ate.rmse < 0.01 * res.path_length_m
    # metric scale from the camera height: within 5 % on this short stretch
    assert res.scale is not None and abs(1.0 - res.scale) < 0.05
    assert (out / "keyframes.tum").is_file() and (out / "map.ply").is_file()
    assert (out / "scale_drift.csv").is_file()


@pytest.mark.real_data
def test_vo_kitti_every_3rd_frame_keeps_one_map(shared_data: Path) -> None:
    """Every 3rd frame (3 m and up to 11 degrees per step): in the turn the map points die
    faster than KLT tracks them, PnP gets too few inliers, and before the scaled relative pose
    (essential matrix of all tracks, step length from the few map points) the run split into two
    segments with a guessed scale (Sim3 ATE 1.58 % of the path).

    Three draws, every 3rd frame from frames 0, 1 and 2. One draw's ATE is chaotic: the NumPy
    Schur BA, whose final costs are within 0.13 % of GTSAM's, moves each draw by up to half
    (0.61 / 0.99 / 1.36 % with GTSAM's, 1.09 / 0.57 / 0.97 % with it). So each draw must keep one
    map with every frame tracked, and the median ATE must be within issue 9's 1 %
    (bench_protocol reports each draw)."""
    ds = open_dataset(f"kitti:{shared_data / 'kitti00_0000-0199'}")
    assert ds.groundtruth is not None
    cfg = PipelineConfig()
    cfg = dataclasses.replace(cfg, vio=dataclasses.replace(cfg.vio, enabled=False))
    ate_pct, used = [], []
    for first in (0, 1, 2):
        out = run_pipeline(dataclasses.replace(ds, frames=ds.frames[first::3]), cfg)
        assert all(r.status is PoseStatus.TRACKED for r in out.records), first
        assert {r.segment for r in out.records} == {0}, first
        used += [r.index for r in out.records if r.tracking is not None
                 and r.tracking.outcome is TrackOutcome.SCALED_RELATIVE]
        est = Trajectory.from_matrices(out.stamps_ns * 1e-9, out.T_world_cam)
        res = evaluate(est, ds.groundtruth, align="sim3")
        ate_pct.append(100.0 * res.ate.rmse / res.path_length_m)
    assert used, "the case no longer needs the fallback: find one that does"
    assert float(np.median(ate_pct)) < 1.0, ate_pct
