"""`amrvio run` on every recording in ../shared/data (skipped when absent), a few frames each:
health.csv has one row per frame, the report holds its plots, eval.json is written when there is
ground truth (KITTI's own, MH_01's camera poses through --gt) and says why when it cannot be
computed (V1_01's frames are static)."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import pytest

from amrvio.cli.main import main
from tests.skip_policy import skip_shared_missing

pytestmark = pytest.mark.real_data


def _folder(shared_data: Path, name: str) -> Path:
    path = shared_data / name
    if not path.is_dir():
        skip_shared_missing(path)
    return path


CASES = [
    # folder, frames, extra options, plots expected (excitation needs an IMU), eval: the largest
    # Sim3 ATE in % of the path (measured: KITTI 20 frames ~1 %, MH_01 30 hand-held frames over
    # 0.44 m 6.4 %), "static" (no motion: no map, an error in eval.json) or None (no GT)
    ("kitti00_0000-0199", 20, [], 6, 5.0),
    ("euroc_MH_01_handheld_0000-0299", 30, ["--gt", "{root}/gt/groundtruth_cam0_tum.txt"], 6, 10.0),
    ("euroc_V1_01_easy_first95", 20, ["--no-imu"], 7, "static"),
    # with its IMU: the static initialisation poses the MAV at rest (VIO), nothing to align
    ("euroc_V1_01_easy_first95", 20, [], 7, "static_vio"),
    ("phone_handheld_blur_0450-0549", 6, ["--calib", "{root}/calib_claimed/live.yaml"], 6, None),
]


@pytest.mark.parametrize(("name", "n", "extra", "n_plots", "evaluation"), CASES,
                         ids=[c[0] + ("_vo" if "--no-imu" in c[2] else "") for c in CASES])
def test_run_on_every_recording(name: str, n: int, extra: list[str], n_plots: int,
                                evaluation: float | str | None, shared_data: Path, tmp_path: Path,
                                capsys: pytest.CaptureFixture[str]) -> None:
    root = _folder(shared_data, name)
    out = tmp_path / "out"
    argv = ["run", str(root), "--out", str(out), "--max-frames", str(n),
            *(a.format(root=root) for a in extra)]
    assert main(argv) == 0, capsys.readouterr().err
    with (out / "health.csv").open(newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == n and [int(r["frame"]) for r in rows] == list(range(n))
    summary = json.loads((out / "summary.json").read_text())
    assert summary["n_frames"] == n and summary["state"] == "finished"
    html = (out / "report.html").read_text()
    assert html.count("data:image/png;base64,") == n_plots
    events = [json.loads(ln) for ln in (out / "events.jsonl").read_text().splitlines()]
    maps = [e for e in events if e["type"] == "init_ok"]
    if evaluation is None:
        assert maps and not (out / "eval.json").exists()
        return
    ev = json.loads((out / "eval.json").read_text())
    if evaluation == "static_vio":
        assert not maps and summary["status_counts"]["lost"] == 0
        assert any(e["type"] == "static_init" and e["status"] == "ok" for e in events)
        assert ev["frame"] == "body" and ev["sim3"] is None and "does not move" in ev["error"]
        return
    if evaluation == "static":
        assert not maps and summary["status_counts"]["lost"] == n
        assert ev["sim3"] is None and ev["error"].startswith("no frame has a pose")
        assert [e["type"] for e in events].count("dropped") == 1
        return
    assert maps and ev["error"] is None and ev["n_evaluated"] == summary["n_in_trajectory"]
    assert isinstance(evaluation, float)
    assert 0 < ev["ate_sim3_pct_of_path"] < evaluation
