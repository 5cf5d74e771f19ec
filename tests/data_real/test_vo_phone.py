"""The hand-held phone (1080p, heavy real blur, 100-300 px of motion per frame, no ground truth):
how much of it the VO tracks in one map, and that its fallbacks keep the chain of tracks.

Issue 9 asks for 90 % of the frames in one segment. In this process the VO reaches 71 % with
OpenBLAS's AVX2 kernels (an AMD EPYC, or any x86-64 with ``OPENBLAS_CORETYPE=Haswell``, as
``amrvio run`` and ``make bench`` set it) and 49 % with its AVX-512 kernels (an Intel Xeon): this
recording sits at the edge of what the VO tracks, and the kernels' different rounding moves a
tracking loss and splits the map elsewhere (amrvio.cli.reproducible). pytest does not pin the
kernels. Before the direct fallback kept the tracks without a map point that KLT had found, each
fallback left only the map's tracks, the map died after 2-5 such frames, and the largest segment
held 27-53 %. This guards the lower of the two measured figures, and that the fallback runs."""

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
    assert max(tracked.values()) >= 0.45 * n, tracked  # 49 % (Xeon) and 71 % (EPYC) measured
    direct = [r for r in out.records
              if r.tracking is not None and r.tracking.outcome is TrackOutcome.DIRECT]
    assert direct, "no direct fallback: the case no longer tests what it guards"
