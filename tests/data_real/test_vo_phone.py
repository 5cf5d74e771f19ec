"""The hand-held phone (1080p, heavy real blur, 100-300 px of motion per frame, no ground truth):
how much of it the VO tracks in one map, and that its fallbacks keep the chain of tracks.

Issue 9 asks for 90 % of the frames in one segment; the VO reaches about 70 %. Before the direct
fallback kept the tracks without a map point that KLT had found, each fallback left only the
map's tracks, the map died after 2-5 such frames, and the largest segment held 53 % (27 % before
the scaled relative pose and the blurred reference). This guards the measured step."""

from __future__ import annotations

import dataclasses
from collections import Counter
from pathlib import Path

import pytest

from amrvio.config import PipelineConfig
from amrvio.frontend.tracking_types import TrackOutcome
from amrvio.io.dataset import open_dataset
from amrvio.pipeline.records import PoseStatus
from amrvio.pipeline.run import run_pipeline


@pytest.mark.real_data
def test_phone_largest_segment(shared_data: Path) -> None:
    root = shared_data / "phone_handheld_blur_0450-0549"
    ds = open_dataset(str(root), root / "calib_claimed" / "live.yaml")
    cfg = PipelineConfig()
    out = run_pipeline(ds, dataclasses.replace(cfg, vio=dataclasses.replace(cfg.vio, enabled=False)))
    n = len(out.records)
    tracked = Counter(r.segment for r in out.records if r.status is PoseStatus.TRACKED)
    assert max(tracked.values()) >= 0.65 * n, tracked
    direct = [r for r in out.records
              if r.tracking is not None and r.tracking.outcome is TrackOutcome.DIRECT]
    assert direct, "no direct fallback: the case no longer tests what it guards"
