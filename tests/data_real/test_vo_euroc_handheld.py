"""EuRoC MH_01 carried by hand, every 2nd frame (10 Hz, fast hand rotations, real motion blur):
the VO keeps one map and its Sim3 ATE stays within 1 % of the path (issue 9's target).

Before blurred frames could become the tracking reference, a blurred stretch was tracked from the
last sharp image across an ever wider baseline until PnP failed (frames 29-35 here); the run
split into two segments, and the Sim3 ATE was 1.7 % of the path (2.1 % and three segments before
the scaled relative pose)."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from amrvio.config import PipelineConfig
from amrvio.eval.evaluate import evaluate
from amrvio.frontend.tracking_types import TrackOutcome
from amrvio.io.dataset import open_dataset
from amrvio.io.trajectory import read_tum
from amrvio.pipeline.records import PoseStatus
from amrvio.pipeline.run import run_pipeline
from amrvio.types.trajectory import Trajectory


@pytest.mark.real_data
def test_mh01_handheld_every_2nd_frame_one_map(shared_data: Path) -> None:
    root = shared_data / "euroc_MH_01_handheld_0000-0299"
    ds = open_dataset(str(root))
    sub = dataclasses.replace(ds, frames=ds.frames[::2])
    cfg = PipelineConfig()
    out = run_pipeline(sub, dataclasses.replace(cfg, vio=dataclasses.replace(cfg.vio, enabled=False)))
    n = len(out.records)
    assert n == 150
    assert sum(r.status is PoseStatus.TRACKED for r in out.records) >= 0.97 * n
    assert len({r.segment for r in out.records if r.segment is not None}) == 1
    # blurred frames that PnP posed as well as a sharp one were tracked from
    kept = [r.index for r in out.records if r.blur.is_blurred and r.tracking is not None
            and r.tracking.outcome is TrackOutcome.BLURRED_REFERENCE]
    assert kept, "no blurred frame became the reference: the case no longer tests that"
    gt = read_tum(root / "gt" / "groundtruth_cam0_tum.txt")
    est = Trajectory.from_matrices(out.stamps_ns * 1e-9, out.T_world_cam)
    res = evaluate(est, gt, align="sim3")
    assert np.isfinite(res.ate.rmse) and res.ate.rmse < 0.01 * res.path_length_m
