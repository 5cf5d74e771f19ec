"""`amrvio run` outputs agree with each other frame by frame: health.csv (the records), the
trajectory, the keyframes and the summary; the same input and seed give the same files."""

from __future__ import annotations

import csv
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from amrvio.io.dataset import open_dataset


def _cli(*args: str) -> None:
    r = subprocess.run([sys.executable, "-m", "amrvio.cli.main", *args], capture_output=True,
                       text=True, check=False)
    assert r.returncode == 0, r.stderr


@pytest.fixture(scope="module")
def runs(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path, Path]:
    root = tmp_path_factory.mktemp("consistency")
    seq = root / "seq"
    # a 0.4 s blackout in the middle: some frames are not tracked
    _cli("simulate", "--scene", "corridor", "--motion", "forward-stop-turn", "--seconds", "4",
         "--resolution", "376x240", "--blur", "off", "--ev-steps", "2.0:-9,2.4:+9",
         "--out", str(seq))
    a, b = root / "a", root / "b"
    _cli("run", str(seq), "--out", str(a), "--camera-height", "1.0")
    _cli("run", str(seq), "--out", str(b), "--camera-height", "1.0")
    return seq, a, b


def _rows(path: Path) -> list[dict[str, str]]:
    with path.open(newline="", encoding="utf-8") as fh:
        return list(csv.DictReader(fh))


def test_records_trajectory_and_summary_agree(runs: tuple[Path, Path, Path]) -> None:
    seq, out, _ = runs
    ds = open_dataset(str(seq))
    rows = _rows(out / "health.csv")
    traj = np.loadtxt(out / "trajectory.tum", ndmin=2)
    kfs = np.loadtxt(out / "keyframes.tum", ndmin=2)
    summary = json.loads((out / "summary.json").read_text(encoding="utf-8"))
    n = len(ds.frames)
    assert len(rows) == n == summary["n_frames"]
    # the trajectory: every frame not LOST, at its stamp, in order (a LOST frame has no pose)
    posed = [r for r in rows if r["status"] != "lost"]
    assert traj.shape == (len(posed), 8) and summary["n_in_trajectory"] == len(posed)
    assert [int(r["frame"]) for r in rows] == list(range(n))
    stamps = np.array([f.t_ns for f in ds.frames]) * 1e-9
    np.testing.assert_allclose([float(r["t_s"]) for r in posed], traj[:, 0], atol=1e-9)
    np.testing.assert_allclose([float(r["t_s"]) for r in rows], stamps, atol=1e-9)
    # status counts and keyframes
    counts: dict[str, int] = {}
    for r in rows:
        counts[r["status"]] = counts.get(r["status"], 0) + 1
    assert {k: v for k, v in summary["status_counts"].items() if v} == counts
    is_kf = [r["is_keyframe"] == "1" for r in posed]
    assert sum(is_kf) == summary["n_keyframes"] == kfs.shape[0]
    np.testing.assert_allclose(kfs[:, 0], traj[np.array(is_kf), 0])
    np.testing.assert_allclose(kfs[:, 1:], traj[np.array(is_kf), 1:])
    # events of the summary are those of the rows
    ev = [[int(r["frame"]), e] for r in rows for e in r["events"].split(";") if e]
    assert ev == summary["events"]
    # the blackout is visible: some frames were not tracked on their own
    assert any(r["tracking"] not in ("tracked", "init_tracked", "started") for r in rows)
    # the online (causal) trajectory: the frames with an online pose (health.csv's online
    # position), at the same stamps and positions
    online = np.loadtxt(out / "trajectory_online.tum", ndmin=2)
    with_online = [r for r in rows if r["online_x"] != ""]
    np.testing.assert_allclose(online[:, 0], [float(r["t_s"]) for r in with_online], atol=1e-9)
    np.testing.assert_allclose([float(r["online_x"]) for r in with_online], online[:, 1], atol=2e-6)
    # quaternions are unit
    np.testing.assert_allclose(np.linalg.norm(traj[:, 4:], axis=1), 1.0, atol=1e-6)
    # the configuration used is recorded
    assert summary["config"]["scale"]["camera_height_m"] == 1.0


def test_same_input_same_outputs(runs: tuple[Path, Path, Path]) -> None:
    _, a, b = runs
    for name in ("trajectory.tum", "trajectory_online.tum", "keyframes.tum", "health.csv", "advice.txt", "map.ply", "scale_drift.csv"):
        assert (a / name).read_bytes() == (b / name).read_bytes(), name
    # summary.json has no wall-clock figure (those are in timings.json): byte-identical
    assert (a / "summary.json").read_bytes() == (b / "summary.json").read_bytes()
    assert "timings_s" in json.loads((a / "timings.json").read_text(encoding="utf-8"))
