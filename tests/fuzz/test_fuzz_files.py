"""Fuzz, classes 6 and 8 of issue 14: absurd but finite numbers (and other broken values) in the
text files every command reads: trajectories for ``eval``, times, poses, IMU, ground truth and
calibration files of a recording, ``simulate --motion replay`` inputs and configuration files.
Each gives one line naming the file and, where the problem sits on a line, that line.
"""

from __future__ import annotations

import subprocess
import sys
from collections.abc import Callable
from pathlib import Path

import pytest

from amrvio.eval.example import EXAMPLE_EST, EXAMPLE_GT
from tests.fuzz.helpers import cli, copy_of, expect_error, make_folder, make_synth_euroc, make_synth_kitti

REPO = Path(__file__).resolve().parents[2]


def _set_line(path: Path, line: int, text: str) -> None:
    lines = path.read_text().splitlines()
    lines[line - 1] = text
    path.write_text("\n".join(lines) + "\n")


def _field(path: Path, line: int, col: int, value: str, sep: str | None = None) -> None:
    lines = path.read_text().splitlines()
    fields = lines[line - 1].split(sep)
    fields[col] = value
    lines[line - 1] = (sep or " ").join(fields)
    path.write_text("\n".join(lines) + "\n")


def _zero_quaternion(path: Path, line: int) -> None:
    for col in (4, 5, 6, 7):
        _field(path, line, col, "0")


def _folder_instead(path: Path) -> None:
    path.unlink()
    path.mkdir()


def _gt_with(tmp: Path, line: int, col: int, value: str) -> Path:
    p = _gt(tmp)
    _field(p, line, col, value)
    return p


def _text(path: Path, text: str) -> Path:
    path.write_text(text)
    return path


# ------------------------------------------------------------------ eval: trajectory files
# (name, how to break a TUM file, the line named (None: none), words)
TumBreaker = Callable[[Path], object]
TUM: list[tuple[str, TumBreaker, int | None, str]] = [
    ("position_1e300", lambda p: _field(p, 5, 1, "1e300"), 5, "position [m] 1e+300 is beyond"),
    ("position_-1e300", lambda p: _field(p, 5, 3, "-1e300"), 5, "column 4"),
    ("position_1e12", lambda p: _field(p, 9, 2, "1e12"), 9, "beyond +-1e+09"),
    ("stamp_1e300", lambda p: _field(p, 5, 0, "1e300"), 5, "timestamp [s]"),
    ("stamp_1e20", lambda p: _field(p, 7, 0, "1e20"), 7, "timestamp [s]"),
    ("nan_position", lambda p: _field(p, 5, 2, "nan"), 5, "not finite"),
    ("inf_quaternion", lambda p: _field(p, 6, 7, "inf"), 6, "not finite"),
    ("underscore_stamp", lambda p: _field(p, 5, 0, "4_0"), 5, "cannot read '4_0'"),
    ("seven_columns", lambda p: _set_line(p, 8, "1 2 3 4 5 6 7"), 8, "found 7"),
    ("zero_quaternion", lambda p: _zero_quaternion(p, 5), 5, "quaternion norm"),
    ("stamp_backwards", lambda p: _field(p, 6, 0, "-5"), 6, "goes backwards"),
    ("a_word", lambda p: _field(p, 4, 3, "abc"), 4, "cannot read 'abc'"),
    ("binary", lambda p: p.write_bytes(bytes(range(256)) * 4), None, "not a text file"),
    ("empty", lambda p: p.write_text(""), None, "contains no poses"),
    ("comments_only", lambda p: p.write_text("# nothing\n# here\n"), None, "contains no poses"),
    ("a_folder", lambda p: _folder_instead(p), None, "is a directory"),
    ("missing", lambda p: p.unlink(), None, "file not found"),
]
EVAL_CASES = [(which, name) for which in ("est", "gt") for name, _, _, _ in TUM]


@pytest.mark.parametrize(("which", "name"), EVAL_CASES,
                         ids=[f"c6-eval-{w}-tum-{n}" for w, n in EVAL_CASES])
def test_eval_broken_tum(which: str, name: str, tmp_path: Path,
                         capsys: pytest.CaptureFixture[str]) -> None:
    est, gt = tmp_path / "est.tum", tmp_path / "gt.tum"
    est.write_bytes(EXAMPLE_EST.read_bytes())
    gt.write_bytes(EXAMPLE_GT.read_bytes())
    _, brk, line, words = next(c for c in TUM if c[0] == name)
    bad = est if which == "est" else gt
    brk(bad)
    o = cli(["eval", est, gt, "--json", tmp_path / "e.json"], capsys)
    expect_error(o, "eval", bad, line, words)
    assert not (tmp_path / "e.json").exists()


def _kitti_traj(tmp: Path) -> Path:
    p = tmp / "poses.kitti"
    p.write_text("".join(f"1 0 0 {0.1 * k} 0 1 0 0 0 0 1 {0.2 * k}\n" for k in range(20)))
    return p


def _euroc_traj(tmp: Path) -> Path:
    p = tmp / "gt.csv"
    p.write_text("#t,x,y,z,qw,qx,qy,qz,vx,vy,vz\n" + "".join(
        f"{1000000000 + 50000000 * k},{0.1 * k},0,0,1,0,0,0,0.5,0,0\n" for k in range(20)))
    return p


OTHER: list[tuple[str, Callable[[Path], Path], Callable[[Path], None], int, str]] = [
    ("kitti_translation_1e300", _kitti_traj, lambda p: _field(p, 3, 3, "1e300"), 3, "translation"),
    ("kitti_translation_-1e15", _kitti_traj, lambda p: _field(p, 4, 11, "-1e15"), 4, "column 12"),
    ("kitti_not_a_rotation", _kitti_traj, lambda p: _field(p, 5, 0, "5"), 5, "not a rotation"),
    ("kitti_nan", _kitti_traj, lambda p: _field(p, 6, 5, "nan"), 6, "not finite"),
    ("euroc_position_1e300", _euroc_traj, lambda p: _field(p, 4, 1, "1e300", ","), 4, "position"),
    ("euroc_velocity_1e300", _euroc_traj, lambda p: _field(p, 4, 8, "1e300", ","), 4,
     "velocity or bias"),
    ("euroc_stamp_overflow", _euroc_traj,
     lambda p: _field(p, 5, 0, "99999999999999999999", ","), 5, "not an integer"),
    ("euroc_stamp_float", _euroc_traj, lambda p: _field(p, 5, 0, "1e300", ","), 5,
     "not an integer"),
]


@pytest.mark.parametrize("name", [c[0] for c in OTHER], ids=[f"c6-eval-{c[0]}" for c in OTHER])
def test_eval_broken_kitti_and_euroc(name: str, tmp_path: Path,
                                     capsys: pytest.CaptureFixture[str]) -> None:
    _, make, brk, line, words = next(c for c in OTHER if c[0] == name)
    bad = make(tmp_path)
    brk(bad)
    expect_error(cli(["eval", bad, EXAMPLE_GT], capsys), "eval", bad, line, words)


# ------------------------------------------------------------------ recordings
@pytest.fixture(scope="module")
def bases(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    root = tmp_path_factory.mktemp("files")
    return {"kitti": make_synth_kitti(root / "kitti"), "euroc": make_synth_euroc(root / "euroc"),
            "folder": make_folder(root / "folder")}


REC: list[tuple[str, str, str, Callable[[Path], None], int | None, str]] = [
    # (name, layout, file, breaker, line, words)
    ("times_underscore", "kitti", "times.txt", lambda p: _set_line(p, 3, "4_0.0"), 3,
     "not a finite time"),
    ("times_1e300", "kitti", "times.txt", lambda p: _set_line(p, 4, "1e300"), 4, "not a finite"),
    ("times_1e10", "kitti", "times.txt", lambda p: _set_line(p, 6, "1e10"), 6, "not a finite"),
    ("times_nan", "kitti", "times.txt", lambda p: _set_line(p, 2, "nan"), 2, "not a finite"),
    ("times_-inf", "kitti", "times.txt", lambda p: _set_line(p, 2, "-inf"), 2, "not a finite"),
    ("times_hex", "kitti", "times.txt", lambda p: _set_line(p, 2, "0x10"), 2, "not a finite"),
    ("times_huge_integer", "kitti", "times.txt", lambda p: _set_line(p, 5, "9" * 30), 5,
     "not a finite"),
    ("poses_1e300", "kitti", "poses.txt", lambda p: _field(p, 2, 3, "1e300"), 2, "translation"),
    ("poses_inf", "kitti", "poses.txt", lambda p: _field(p, 3, 7, "inf"), 3, "not finite"),
    ("camera_stamp_overflow", "euroc", "mav0/cam0/data.csv",
     lambda p: _field(p, 3, 0, "99999999999999999999", ","), 3, "not an integer"),
    ("camera_stamp_underscore", "euroc", "mav0/cam0/data.csv",
     lambda p: _field(p, 3, 0, "1_403_715_273_312_142_976", ","), 3, "not an integer"),
    ("imu_gyro_1e300", "euroc", "mav0/imu0/data.csv", lambda p: _field(p, 6, 1, "1e300", ","), 6,
     "IMU angular rate [rad/s]: 1e+300 is beyond +-100"),
    ("imu_gyro_-1e300", "euroc", "mav0/imu0/data.csv", lambda p: _field(p, 7, 3, "-1e300", ","),
     7, "beyond +-100"),
    ("imu_gyro_1000", "euroc", "mav0/imu0/data.csv", lambda p: _field(p, 8, 2, "1000", ","), 8,
     "beyond +-100"),
    ("imu_accel_1e300", "euroc", "mav0/imu0/data.csv", lambda p: _field(p, 9, 4, "1e300", ","),
     9, "IMU acceleration [m/s^2]"),
    ("imu_accel_1e5", "euroc", "mav0/imu0/data.csv", lambda p: _field(p, 10, 6, "1e5", ","), 10,
     "beyond +-2000"),
    ("imu_nan", "euroc", "mav0/imu0/data.csv", lambda p: _field(p, 11, 5, "nan", ","), 11,
     "non-finite"),
    ("imu_underscore", "euroc", "mav0/imu0/data.csv", lambda p: _field(p, 12, 1, "1_0", ","),
     12, "not a number"),
    ("imu_stamp_overflow", "euroc", "mav0/imu0/data.csv",
     lambda p: _field(p, 13, 0, "9" * 25, ","), 13, "not an integer"),
    ("groundtruth_1e300", "euroc", "mav0/state_groundtruth_estimate0/data.csv",
     lambda p: _field(p, 3, 2, "1e300", ","), 3, "position"),
    ("groundtruth_bias_1e300", "euroc", "mav0/state_groundtruth_estimate0/data.csv",
     lambda p: _field(p, 3, 12, "1e300", ","), 3, "velocity or bias"),
    ("folder_times_underscore", "folder", "timestamps.csv",
     lambda p: _field(p, 3, 0, "1_0.5", ","), 3, "not a finite time"),
    ("folder_times_1e300", "folder", "timestamps.csv",
     lambda p: _field(p, 4, 0, "1e300", ","), 4, "not a finite time"),
]
REC_CMDS = ("info", "run", "diagnose")
REC_CASES = [(c[0], cmd) for c in REC for cmd in REC_CMDS]


@pytest.mark.parametrize(("name", "cmd"), REC_CASES, ids=[f"c6-{n}-{c}" for n, c in REC_CASES])
def test_broken_numbers_in_a_recording(name: str, cmd: str, bases: dict[str, Path],
                                       tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    _, layout, rel, brk, line, words = next(c for c in REC if c[0] == name)
    root = copy_of(bases[layout], tmp_path / "rec")
    brk(root / rel)
    argvs: dict[str, list[str | Path]] = {"info": ["info", root],
                              "run": ["run", root, "--out", tmp_path / "out"],
                              "diagnose": ["diagnose", root, "--out", tmp_path / "out",
                                           "--no-plots"]}
    expect_error(cli(argvs[cmd], capsys), cmd, root / rel, line, words)
    assert not (tmp_path / "out" / "health.csv").exists()


# ORB-SLAM3 settings given with --calib: a bad intrinsic names its line
ORB = """%YAML:1.0
Camera.type: "PinHole"
Camera1.fx: 50.0
Camera1.fy: 51.0
Camera1.cx: 31.5
Camera1.cy: 23.5
Camera1.k1: 0.0
Camera1.k2: 0.0
Camera1.p1: 0.0
Camera1.p2: 0.0
Camera.width: 64
Camera.height: 48
Camera.fps: 20
"""
ORB_CASES: list[tuple[str, str, str, int, str]] = [
    ("fx_negative", "Camera1.fx: 50.0", "Camera1.fx: -50.0", 3, "Camera1.fx must be in (0"),
    ("fx_1e300", "Camera1.fx: 50.0", "Camera1.fx: 1.0e+300", 3, "Camera1.fx must be in (0"),
    ("fy_zero", "Camera1.fy: 51.0", "Camera1.fy: 0.0", 4, "Camera1.fy must be"),
    ("cx_nan", "Camera1.cx: 31.5", "Camera1.cx: .nan", 5, "not finite"),
    ("cy_1e300", "Camera1.cy: 23.5", "Camera1.cy: 1.0e+300", 6, "Camera1.cy must be"),
    ("width_zero", "Camera.width: 64", "Camera.width: 0", 11, "Camera.width must be an integer"),
    ("width_1e300", "Camera.width: 64", "Camera.width: 1.0e+300", 11, "Camera.width must be"),
    ("width_fraction", "Camera.width: 64", "Camera.width: 64.5", 11, "an integer in [8, 16384]"),
    ("height_word", "Camera.height: 48", "Camera.height: tall", 12, "must be a number"),
    ("type_unknown", 'Camera.type: "PinHole"', 'Camera.type: "Fisheye9"', 2, "not supported"),
]
ORB_CMDS = ("info", "run")
ORB_PARAMS = [(c[0], cmd) for c in ORB_CASES for cmd in ORB_CMDS]


@pytest.mark.parametrize(("name", "cmd"), ORB_PARAMS, ids=[f"c8-orbslam-{n}-{c}" for n, c in ORB_PARAMS])
def test_orbslam_settings_errors_name_the_line(name: str, cmd: str, bases: dict[str, Path],
                                               tmp_path: Path,
                                               capsys: pytest.CaptureFixture[str]) -> None:
    _, old, new, line, words = next(c for c in ORB_CASES if c[0] == name)
    calib = tmp_path / "orbslam.yaml"
    calib.write_text(ORB.replace(old, new))
    argv: list[str | Path] = ["info", bases["euroc"], "--calib", calib] if cmd == "info" else [
        "run", bases["euroc"], "--calib", calib, "--out", tmp_path / "out"]
    expect_error(cli(argv, capsys), cmd, calib, line, words)


# ------------------------------------------------------------------ simulate --motion replay
def _gt(tmp: Path, n: int = 40, pos: str = "0.1*k") -> Path:
    p = tmp / "gt.tum"
    p.write_text("".join(f"{0.05 * k:.2f} {eval(pos, {'k': k})} 0 1 0 0 0 1\n" for k in range(n)))
    return p


REPLAY: list[tuple[str, Callable[[Path], Path], list[str], int | None, str]] = [
    ("missing_file", lambda t: t / "none.tum", [], None, "file not found"),
    ("three_poses", lambda t: _gt(t, 3), [], None, "at least 4 poses"),
    ("position_1e300", lambda t: _gt_with(t, 7, 1, "1e300"), [], 7, "position [m]"),
    ("start_past_the_end", lambda t: _gt(t), ["--replay-start", "100"], None,
     "past the end of the recorded trajectory"),
    ("longer_than_recorded", lambda t: _gt(t), ["--seconds", "30"], None,
     "but the trajectory holds"),
    ("not_a_trajectory", lambda t: _text(t / "x.txt", "1 2 3\n"), [], 1,
     "cannot tell the trajectory format"),
]


@pytest.mark.parametrize("name", [c[0] for c in REPLAY], ids=[f"c8-replay-{c[0]}" for c in REPLAY])
def test_replay_errors_name_the_trajectory(name: str, tmp_path: Path,
                                           capsys: pytest.CaptureFixture[str]) -> None:
    _, make, extra, line, words = next(c for c in REPLAY if c[0] == name)
    gt = make(tmp_path)
    seconds = [] if "--seconds" in extra else ["--seconds", "1"]
    argv: list[str | Path] = ["simulate", "--motion", "replay", "--trajectory", gt, *seconds,
                              *extra, "--out", tmp_path / "out"]
    expect_error(cli(argv, capsys), "simulate", gt, line, words)


# ------------------------------------------------------------------ configuration files
CONFIGS: list[tuple[str, str | bytes | None, str]] = [
    ("seed_overflow", "seed: 99999999999999999999\n", "key 'seed' must be in [0, 4294967295]"),
    ("seed_negative", "seed: -1\n", "key 'seed' must be in [0, 4294967295]"),
    ("seed_nan", "seed: .nan\n", "key 'seed' must be an integer"),
    ("height_1e300", "scale: {camera_height_m: 1.0e+300}\n", "must be in [0.01, 100]"),
    ("height_negative", "scale: {camera_height_m: -1.0}\n", "must be in [0.01, 100]"),
    ("height_inf", "scale: {camera_height_m: .inf}\n", "must be finite"),
    ("corners_1e12", "tracking: {klt: {detector: {max_corners: 1000000000000}}}\n",
     "must be in [-1000000000, 1000000000]"),
    ("unknown_key", "sede: 3\n", "unknown key 'sede'"),
    ("not_a_mapping", "- 1\n- 2\n", "mapping"),
    ("binary", bytes(range(256)), ""),
    ("tabs", "scale:\n\tcamera_height_m: 1.0\n", "not valid YAML"),
    ("a_folder", None, ""),
]
CONFIG_CMDS = ("config", "run", "diagnose")
CONFIG_PARAMS = [(c[0], cmd) for c in CONFIGS for cmd in CONFIG_CMDS]


@pytest.mark.parametrize(("name", "cmd"), CONFIG_PARAMS,
                         ids=[f"c6-config-{n}-{c}" for n, c in CONFIG_PARAMS])
def test_broken_configuration_files(name: str, cmd: str, bases: dict[str, Path], tmp_path: Path,
                                    capsys: pytest.CaptureFixture[str]) -> None:
    _, text, words = next(c for c in CONFIGS if c[0] == name)
    path = tmp_path / "c.yaml"
    if text is None:
        path.mkdir()
    elif isinstance(text, bytes):
        path.write_bytes(text)
    else:
        path.write_text(text)
    argvs: dict[str, list[str | Path]] = {"config": ["config", "--check", path],
                              "run": ["run", bases["kitti"], "--config", path, "--out",
                                      tmp_path / "out"],
                              "diagnose": ["diagnose", bases["kitti"], "--config", path,
                                           "--out", tmp_path / "out"]}
    expect_error(cli(argvs[cmd], capsys), cmd, path, words=words or None)


# ------------------------------------------------------------------ one line, as a user sees it
SUB = [("euroc", "mav0/cam0/data.csv"), ("folder", "timestamps.csv")]


@pytest.mark.parametrize(("layout", "csv_name"), SUB, ids=[f"c8-every-image-missing-{s[0]}" for s in SUB])
def test_every_image_missing_is_one_line(layout: str, csv_name: str, bases: dict[str, Path],
                                         tmp_path: Path) -> None:
    """A subprocess, so that the reader's warnings reach stderr as they would for a user."""
    root = copy_of(bases[layout], tmp_path / "rec")
    for p in list((root / csv_name).parent.rglob("*.png")):
        p.unlink()
    proc = subprocess.run([sys.executable, "-m", "amrvio.cli.main", "info", str(root)],
                          capture_output=True, text=True, cwd=REPO, timeout=120)
    assert proc.returncode == 1
    lines = proc.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"amrvio info: error: {root / csv_name}: "), lines
