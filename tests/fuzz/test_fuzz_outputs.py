"""Fuzz, classes 3, 4, 9 and 10 of issue 14: output folders and files that cannot be used (checked
before any work), Ctrl-C (valid partial outputs, exit 130, one line), LOST frames kept out of
trajectory.tum, and summary.json the same for the same input (timings apart, in timings.json).
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import cv2
import numpy as np
import pytest

from amrvio.eval.example import EXAMPLE_EST, EXAMPLE_GT
from tests.fuzz.helpers import (
    N_SYNTH,
    check_diagnose_dir,
    check_run_dir,
    check_tum,
    cli,
    copy_of,
    csv_rows,
    expect_error,
    images_of,
    make_real_kitti,
    make_synth_euroc,
    make_synth_kitti,
    strict_json,
)

REPO = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def synth(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return make_synth_kitti(tmp_path_factory.mktemp("synth") / "seq")


def _argv(cmd: str, data: Path, out: Path, *extra: str) -> list[str]:
    if cmd == "simulate":
        return ["simulate", "--seconds", "0.2", "--resolution", "64x48", "--out", str(out), *extra]
    if cmd == "diagnose":
        return ["diagnose", str(data), "--out", str(out), "--no-plots", *extra]
    return ["run", str(data), "--out", str(out), *extra]


def _check_outputs(cmd: str, out: Path) -> None:
    if cmd == "run":
        check_run_dir(out, n_frames=N_SYNTH)
    elif cmd == "diagnose":
        check_diagnose_dir(out, N_SYNTH)
    else:
        assert (out / "mav0" / "cam0" / "data.csv").is_file()
        assert len(list((out / "mav0" / "cam0" / "data").iterdir())) == 4


def _unwritable(monkeypatch: pytest.MonkeyPatch) -> None:
    """As root no folder is read-only: refuse the write probe instead."""
    def mkstemp(*args: object, **kwargs: object) -> tuple[int, str]:
        raise PermissionError(13, "Permission denied")

    monkeypatch.setattr(tempfile, "mkstemp", mkstemp)


# (what, make the --out path from tmp, words in the error; None: a run that must succeed)
OutMaker = Callable[[Path, pytest.MonkeyPatch], Path]


def _a_file(tmp: Path, _: object) -> Path:
    (tmp / "f").write_text("x")
    return tmp / "f"


def _under_a_file(tmp: Path, _: pytest.MonkeyPatch) -> Path:
    (tmp / "f").write_text("x")
    return tmp / "f" / "sub" / "out"


def _non_empty(tmp: Path, _: pytest.MonkeyPatch) -> Path:
    (tmp / "out").mkdir()
    (tmp / "out" / "mine.txt").write_text("keep me")
    return tmp / "out"


def _read_only(tmp: Path, mp: pytest.MonkeyPatch) -> Path:
    _unwritable(mp)
    return tmp / "out"


OUT_CASES: list[tuple[str, OutMaker, str]] = [
    ("is_a_file", _a_file, "exists and is not a folder"),
    ("under_a_file", _under_a_file, "is a file, not a folder"),
    ("name_of_300_chars", lambda t, _: t / ("n" * 300), "a folder or file name of 300 bytes"),
    ("path_of_5000_chars", lambda t, _: t / "/".join(["d" * 200] * 25), "path of"),
    ("cannot_be_created", lambda t, _: Path("/proc/amrvio-fuzz/out"), "cannot create the folder"),
    ("not_empty", _non_empty, "output folder is not empty; use --force to overwrite"),
    ("read_only", _read_only, "cannot write in the folder: Permission denied"),
]
OUT_PARAMS = [(c, name) for c in ("run", "diagnose", "simulate") for name, _, _ in OUT_CASES]


@pytest.mark.parametrize(("cmd", "what"), OUT_PARAMS, ids=[f"c3-{c}-out-{w}" for c, w in OUT_PARAMS])
def test_an_unusable_output_folder_is_refused_before_any_work(
        cmd: str, what: str, synth: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str]) -> None:
    _, make, words = next(c for c in OUT_CASES if c[0] == what)
    out = make(tmp_path, monkeypatch)
    started = []
    import amrvio.io.dataset as ds_mod
    import amrvio.sim.simulate as sim_mod

    monkeypatch.setattr(ds_mod, "open_dataset", lambda *a, **k: started.append(1))
    monkeypatch.setattr(sim_mod, "simulate", lambda *a, **k: started.append(1))
    line = expect_error(cli(_argv(cmd, synth, out), capsys), cmd, words=words)
    assert str(out)[:60] in line
    assert not started, "work began before the output folder was checked"
    if what == "not_empty":
        assert (out / "mine.txt").read_text() == "keep me"


FORCE = ("run", "diagnose", "simulate")


@pytest.mark.parametrize("cmd", FORCE, ids=[f"c3-{c}-force-replaces-stale-outputs" for c in FORCE])
def test_force_replaces_earlier_outputs_and_keeps_other_files(
        cmd: str, synth: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "out"
    out.mkdir()
    (out / "mine.txt").write_text("keep me")
    stale = {"run": "map.ply", "diagnose": "health.png", "simulate": "wheel_odometry.csv"}[cmd]
    (out / stale).write_text("from an earlier run")
    o = cli(_argv(cmd, synth, out, "--force"), capsys)
    assert o.rc == 0, o.err
    _check_outputs(cmd, out)
    assert (out / "mine.txt").read_text() == "keep me"
    assert not (out / stale).exists() or (out / stale).read_text() != "from an earlier run"


FILE_CASES: list[tuple[str, Callable[[Path], Path], str]] = [
    ("is_a_folder", lambda t: t, "is a folder, expected a file name"),
    ("folder_missing", lambda t: t / "no" / "such" / "x.json", "does not exist"),
    ("under_a_file", lambda t: _a_file(t, None) / "x.json", "is a file, not a folder"),
    ("name_of_300_chars", lambda t: t / ("j" * 300 + ".json"), "name of 305 bytes"),
]
FILE_PARAMS = [(c, w) for c in ("info --json", "eval --json", "eval --plot") for w, _, _ in FILE_CASES]


@pytest.mark.parametrize(("cmd", "what"), FILE_PARAMS,
                         ids=[f"c3-{c.replace(' --', '-')}-{w}" for c, w in FILE_PARAMS])
def test_an_unusable_output_file_is_refused_before_any_work(
        cmd: str, what: str, synth: Path, tmp_path: Path,
        capsys: pytest.CaptureFixture[str]) -> None:
    _, make, words = next(c for c in FILE_CASES if c[0] == what)
    path = make(tmp_path)
    command, option = cmd.split()
    if command == "info":
        argv = ["info", str(synth), option, str(path)]
    else:
        argv = ["eval", str(EXAMPLE_EST), str(EXAMPLE_GT), option, str(path)]
    o = cli(argv, capsys)
    line = expect_error(o, command, words=words)
    assert option in line and o.out == "", "the figures were computed before the check"


# ------------------------------------------------------------------------------- class 4: Ctrl-C
def _interrupt_at(monkeypatch: pytest.MonkeyPatch, frame: int, again_in_finish: bool = False
                  ) -> None:
    """Send SIGINT to this process while frame ``frame`` is processed (as a user's Ctrl-C)."""
    from amrvio.pipeline.pipeline import Pipeline
    from amrvio.pipeline.run_output import RunWriter

    real = Pipeline.process

    def process(self: Pipeline, *args: object, **kwargs: object) -> object:
        if len(self.records) == frame:
            os.kill(os.getpid(), signal.SIGINT)
        return real(self, *args, **kwargs)  # type: ignore[arg-type]

    monkeypatch.setattr(Pipeline, "process", process)
    if again_in_finish:
        def finish(self: RunWriter, *args: object, **kwargs: object) -> object:
            os.kill(os.getpid(), signal.SIGINT)
            raise AssertionError("the second Ctrl-C did not stop the run")

        monkeypatch.setattr(RunWriter, "finish", finish)


CTRL_C = [("run", 0), ("run", 2), ("run", 5), ("diagnose", 0), ("diagnose", 3)]


@pytest.mark.parametrize(("cmd", "frame"), CTRL_C, ids=[f"c4-ctrl-c-{c}-at-frame-{k}" for c, k in CTRL_C])
def test_ctrl_c_leaves_valid_partial_outputs(cmd: str, frame: int, synth: Path, tmp_path: Path,
                                             monkeypatch: pytest.MonkeyPatch,
                                             capsys: pytest.CaptureFixture[str]) -> None:
    before = signal.getsignal(signal.SIGINT)  # the default, or SIG_IGN in a background job
    _interrupt_at(monkeypatch, frame)
    out = tmp_path / "out"
    o = cli(_argv(cmd, synth, out), capsys)
    assert o.rc == 130 and len(o.err.splitlines()) == 1, o.err
    assert o.err.startswith(f"amrvio {cmd}: interrupted after {frame + 1} ")
    if cmd == "run":
        check_run_dir(out, n_frames=frame + 1, interrupted=True)
    else:
        check_diagnose_dir(out, frame + 1)
    assert signal.getsignal(signal.SIGINT) is before  # the handler is given back


def test_a_second_ctrl_c_stops_at_once_and_keeps_the_partial_files(
        synth: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str]) -> None:
    """c4: the second Ctrl-C arrives while the outputs are composed."""
    _interrupt_at(monkeypatch, 2, again_in_finish=True)
    out = tmp_path / "out"
    o = cli(_argv("run", synth, out), capsys)
    assert o.rc == 130 and o.err == "amrvio run: interrupted\n", o.err
    summary = strict_json(out / "summary.json")
    assert summary["state"] == "interrupted" and summary["interrupted"] is True
    assert summary["n_frames"] == 3 == len(csv_rows(out / "health.csv"))
    check_tum(out / "trajectory_online.tum")


def test_ctrl_c_while_opening_the_dataset(synth: Path, tmp_path: Path,
                                          monkeypatch: pytest.MonkeyPatch,
                                          capsys: pytest.CaptureFixture[str]) -> None:
    """c4: before the first frame there is nothing to keep: one line, exit 130."""
    import amrvio.io.dataset as ds_mod

    def interrupted(*a: object, **k: object) -> None:
        raise KeyboardInterrupt

    monkeypatch.setattr(ds_mod, "open_dataset", interrupted)
    o = cli(_argv("run", synth, tmp_path / "out"), capsys)
    assert (o.rc, o.err) == (130, "amrvio run: interrupted\n")


def test_ctrl_c_on_a_real_run_in_a_subprocess(shared_data: Path, tmp_path: Path) -> None:
    """c4: ``amrvio run`` on 60 KITTI frames, SIGINT once a few frames are done."""
    n = 60
    seq = make_real_kitti(shared_data, tmp_path / "seq", n, ext=".png")
    out = tmp_path / "out"
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    proc = subprocess.Popen([sys.executable, "-m", "amrvio.cli.main", "run", str(seq), "--out",
                             str(out)], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, cwd=REPO, env=env)
    health = out / "health.csv"
    deadline = time.monotonic() + 90
    while time.monotonic() < deadline and proc.poll() is None:
        if health.is_file() and len(health.read_text().splitlines()) >= 6:
            break
        time.sleep(0.05)
    assert proc.poll() is None, "the run ended before it could be interrupted"
    proc.send_signal(signal.SIGINT)
    stdout, stderr = proc.communicate(timeout=120)
    assert proc.returncode == 130, stderr
    assert len(stderr.splitlines()) == 1 and "interrupted after" in stderr, stderr
    summary = check_run_dir(out, interrupted=True)
    assert 5 <= summary["n_frames"] < n
    assert stdout == ""


# ------------------------------------------------------------------ class 9: LOST frames
def test_lost_frames_are_left_out_of_the_trajectory(shared_data: Path, tmp_path: Path,
                                                    capsys: pytest.CaptureFixture[str]) -> None:
    """c9: eight black frames at the end of a KITTI run lose the track (black frames in the
    middle are now bridged: relocalisation finds the map again after them); trajectory.tum holds
    the other frames only: no frozen or identity pose stands in for a LOST frame (before issue
    14 the last pose was repeated for each, and a run that never initialised wrote identities)."""
    n = 24
    seq = make_real_kitti(shared_data, tmp_path / "seq", n)
    black = images_of(seq)[16:24]
    for p in black:
        assert cv2.imwrite(str(p), np.zeros((376, 1241), np.uint8))
    out = tmp_path / "out"
    o = cli(["run", str(seq), "--out", str(out)], capsys)
    assert o.rc == 0, o.err
    s = check_run_dir(out, n_frames=n)
    rows = csv_rows(out / "health.csv")
    lost = [r for r in rows if r["status"] == "lost"]
    assert lost, "no frame was lost: the case tests nothing"
    traj = check_tum(out / "trajectory.tum")
    assert traj.shape[0] == n - len(lost) == s["n_in_trajectory"]
    for r in lost:
        assert not np.any(np.isclose(traj[:, 0], float(r["t_s"]), atol=1e-6))
    header = (out / "trajectory.tum").read_text().splitlines()[0]
    assert "T_world_cam" in header and "LOST frames are left out" in header


def test_a_run_that_never_initialises_writes_an_empty_trajectory(
        synth: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """c9: every frame LOST (random images): a header and no pose; health.csv says why."""
    out = tmp_path / "out"
    o = cli(_argv("run", synth, out), capsys)
    assert o.rc == 0, o.err
    s = check_run_dir(out, n_frames=N_SYNTH)
    assert s["status_counts"]["lost"] == N_SYNTH and s["n_in_trajectory"] == 0
    assert check_tum(out / "trajectory.tum").shape == (0, 8)


# ------------------------------------------------------------------ class 10: determinism
def test_same_input_same_summary_on_real_frames(shared_data: Path, tmp_path: Path,
                                                capsys: pytest.CaptureFixture[str]) -> None:
    """c10: two runs of the same KITTI frames give byte-identical summary.json and outputs;
    the wall-clock timings are in timings.json only."""
    seq = make_real_kitti(shared_data, tmp_path / "seq", 12)
    a, b = tmp_path / "a", tmp_path / "b"
    assert cli(["run", str(seq), "--out", str(a)], capsys).rc == 0
    assert cli(["run", str(seq), "--out", str(b)], capsys).rc == 0
    for name in ("summary.json", "trajectory.tum", "trajectory_online.tum", "keyframes.tum",
                 "health.csv", "map.ply", "advice.txt", "scale_drift.csv"):
        assert (a / name).read_bytes() == (b / name).read_bytes(), name
    assert "timings_s" in strict_json(a / "timings.json")
    assert "timings" not in (a / "summary.json").read_text()


DET = ("run", "diagnose")


@pytest.mark.parametrize("cmd", DET, ids=[f"c10-same-input-same-output-{c}-synthetic" for c in DET])
def test_same_input_same_outputs_synthetic(cmd: str, tmp_path: Path,
                                           capsys: pytest.CaptureFixture[str]) -> None:
    seq = make_synth_euroc(tmp_path / "seq")
    a, b = tmp_path / "a", tmp_path / "b"
    assert cli(_argv(cmd, seq, a), capsys).rc == 0
    assert cli(_argv(cmd, seq, b), capsys).rc == 0
    names = ("summary.json", "health.csv", "trajectory.tum") if cmd == "run" else ("health.csv",)
    for name in names:
        assert (a / name).read_bytes() == (b / name).read_bytes(), name
    if cmd == "run":
        check_run_dir(a, n_frames=N_SYNTH)
        assert copy_of(a, tmp_path / "c").is_dir()
