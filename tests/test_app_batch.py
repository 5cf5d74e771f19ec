"""`amrvio batch` (issue 12): inputs from folders, globs and list files; three small simulated
recordings, one of them broken, on the local process pool and on a local Ray instance give the
same table; the broken one is a row with its error and stops nothing; a re-run skips the
recordings that finished."""

from __future__ import annotations

import csv
import json
import shutil
import subprocess
import sys
from html.parser import HTMLParser
from pathlib import Path

import pytest

from amrvio.app.batch import COLUMNS, Recording, expand_inputs, recordings, table_row
from amrvio.errors import ConfigError
from tests.conftest import make_tiny_sim

REPO = Path(__file__).resolve().parents[1]


def _amrvio(*args: str | Path) -> subprocess.CompletedProcess[str]:
    env = {"PYTHONPATH": str(REPO), "PATH": "/usr/bin:/bin", "HOME": str(Path.home()),
           "RAY_AUTH_MODE": "disabled"}
    return subprocess.run([sys.executable, "-m", "amrvio.cli.main", *map(str, args)],
                          capture_output=True, text=True, check=False, cwd=REPO, env=env)


@pytest.fixture(scope="module")
def fleet(tiny_sim: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """fleet/room_a (the session's tiny recording), fleet/corridor_b (another scene and
    motion), fleet/room_broken (a copy of room_a whose image list has a garbage line)."""
    root = tmp_path_factory.mktemp("fleet")
    shutil.copytree(tiny_sim, root / "room_a")
    make_tiny_sim(root / "corridor_b", scene="warehouse", motion="rough-floor", seed=1)
    shutil.copytree(tiny_sim, root / "room_broken")
    with (root / "room_broken/mav0/cam0/data.csv").open("a") as fh:
        fh.write("garbage,line.png\n")
    return root


def _csv(path: Path) -> list[dict[str, str]]:
    with path.open(newline="", encoding="utf-8") as fh:
        return list(csv.DictReader(fh))


def test_inputs_from_folders_globs_and_lists(tmp_path: Path) -> None:
    for name in ("a", "b", "c"):
        (tmp_path / "runs" / name).mkdir(parents=True)
    (tmp_path / "runs" / ".hidden").mkdir()
    other = tmp_path / "elsewhere" / "a"
    other.mkdir(parents=True)
    lst = tmp_path / "fleet.txt"
    lst.write_text("# recordings of robot 7\nruns/b\n\nkitti:runs/c  # a KITTI one\n"
                   f"{other}\n", encoding="utf-8")
    specs = expand_inputs([str(tmp_path / "runs" / "*"), str(lst), str(tmp_path / "runs" / "a")])
    assert specs == [str(tmp_path / "runs" / n) for n in ("a", "b", "c")] + [
        f"kitti:{tmp_path / 'runs' / 'c'}", str(other)]
    recs = recordings(specs)
    assert [r.name for r in recs] == ["a", "b", "c", "runs_c", "elsewhere_a"]
    assert len({r.name for r in recs}) == len(recs)
    with pytest.raises(ConfigError, match="no such file or folder"):
        expand_inputs([str(tmp_path / "nope")])
    with pytest.raises(ConfigError, match="no file or folder matches"):
        expand_inputs([str(tmp_path / "runs" / "z*")])
    empty = tmp_path / "empty.txt"
    empty.write_text("# nothing\n", encoding="utf-8")
    with pytest.raises(ConfigError, match="empty"):
        expand_inputs([str(empty)])


def _check_table(out: Path, fleet: Path) -> list[dict[str, str]]:
    rows = _csv(out / "batch.csv")
    assert list(rows[0]) == list(COLUMNS)
    assert [r["recording"] for r in rows] == ["corridor_b", "room_a", "room_broken"]
    by = {r["recording"]: r for r in rows}
    broken = by["room_broken"]
    assert broken["status"] == "failed"
    assert "room_broken/mav0/cam0/data.csv" in broken["error"] and "\n" not in broken["error"]
    assert (out / "room_broken" / "error.txt").is_file()
    for name in ("room_a", "corridor_b"):
        r = by[name]
        summary = json.loads((out / name / "summary.json").read_text())
        ev = json.loads((out / name / "eval.json").read_text())
        assert r["status"] == "finished" and r["error"] == ""
        assert int(r["frames"]) == summary["n_frames"] == 30
        assert int(r["in_trajectory"]) == summary["n_in_trajectory"]
        assert int(r["keyframes"]) == summary["n_keyframes"]
        for cause, ranges in summary["flagged_ranges"].items():
            assert int(r[f"ranges_{cause}"]) == len(ranges)
        assert float(r["ate_sim3_m"]) == pytest.approx(ev["ate_sim3_m"], abs=1e-4)
        assert (out / name / "report.html").is_file()
    # the exposure step at 1.5 s is flagged in room_a
    assert int(by["room_a"]["ranges_exposure"]) >= 1
    # the HTML table holds the same cells
    cells: list[str] = []

    class P(HTMLParser):
        def handle_data(self, data: str) -> None:
            cells.append(data)

    P().feed((out / "batch.html").read_text())
    for r in rows:
        assert r["recording"] in cells and r["status"] in cells
    return rows


def _inputs(fleet: Path, root: Path) -> list[Path]:
    """corridor_b as a folder, the two room recordings through a list file with a glob."""
    lst = root / "list.txt"
    lst.write_text(f"{fleet / 'room_*'}\n", encoding="utf-8")
    return [fleet / "corridor_b", lst]


@pytest.fixture(scope="module")
def local_batch(fleet: Path, tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, str]:
    root = tmp_path_factory.mktemp("local_batch")
    out = root / "batch"
    r = _amrvio("batch", *_inputs(fleet, root), "--out", out, "--jobs", "2")
    assert r.returncode == 2, r.stderr  # ran to the end, one recording failed
    return out, r.stdout


def test_local_pool_reports_the_broken_one(local_batch: tuple[Path, str], fleet: Path) -> None:
    out, stdout = local_batch
    assert "2 of 3 recordings finished, 1 failed" in stdout
    _check_table(out, fleet)


def test_a_rerun_skips_the_finished_recordings(local_batch: tuple[Path, str], fleet: Path,
                                               tmp_path: Path) -> None:
    out = tmp_path / "batch"
    shutil.copytree(local_batch[0], out)
    rows = _csv(out / "batch.csv")
    mtimes = {n: (out / n / "summary.json").stat().st_mtime_ns for n in ("room_a", "corridor_b")}
    r = _amrvio("batch", *_inputs(fleet, tmp_path), "--out", out)
    assert r.returncode == 2, r.stderr
    assert "2 finished earlier with the same configuration: skipped" in r.stdout
    assert "[1/1] room_broken: failed" in r.stdout  # a failed recording is tried again
    assert {n: (out / n / "summary.json").stat().st_mtime_ns for n in mtimes} == mtimes
    assert _csv(out / "batch.csv") == rows
    # other options are another run: nothing is skipped
    r = _amrvio("batch", fleet / "room_a", "--out", out, "--max-frames", "12")
    assert r.returncode == 0, r.stderr
    assert "skipped" not in r.stdout
    assert json.loads((out / "room_a" / "summary.json").read_text())["n_frames"] == 12
    r = _amrvio("batch", fleet / "room_a", "--out", out, "--max-frames", "12")
    assert "1 finished earlier" in r.stdout


def test_ray_gives_the_table_of_the_local_pool(local_batch: tuple[Path, str], fleet: Path,
                                               tmp_path: Path) -> None:
    """A local Ray instance (Ray is a dev dependency: this test always runs)."""
    local = local_batch[0]
    on_ray = tmp_path / "ray"
    r = _amrvio("batch", *_inputs(fleet, tmp_path), "--out", on_ray, "--ray")
    assert r.returncode == 2, r.stderr
    _check_table(on_ray, fleet)
    assert (on_ray / "batch.csv").read_bytes() == (local / "batch.csv").read_bytes()
    for name in ("room_a", "corridor_b"):
        assert (on_ray / name / "trajectory.tum").read_bytes() == \
            (local / name / "trajectory.tum").read_bytes()


def test_bad_batch_input_is_one_line_before_any_work(fleet: Path, tmp_path: Path) -> None:
    bad = tmp_path / "bad.yaml"
    bad.write_text("tracking:\n  no_such_key: 1\n", encoding="utf-8")
    out = tmp_path / "out"
    r = _amrvio("batch", fleet / "room_a", "--out", out, "--config", bad)
    assert r.returncode == 1 and r.stderr.count("\n") == 1, r.stderr
    assert "tracking.no_such_key" in r.stderr and not out.exists()
    r = _amrvio("batch", tmp_path / "missing", "--out", out)
    assert r.returncode == 1 and r.stderr.count("\n") == 1
    assert f"{tmp_path / 'missing'}: no such file or folder" in r.stderr


def test_a_folder_without_outputs_is_a_failed_row(tmp_path: Path) -> None:
    row = table_row(Recording("x", "euroc:/x"), tmp_path / "x")
    assert row["status"] == "failed" and "summary.json" in row["error"]
