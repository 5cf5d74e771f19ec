"""``amrvio info``: the summary of small recordings written here, and every bad-input case of
issue 2 run as a real subprocess (exit 1, exactly one stderr line naming file and line)."""

from __future__ import annotations

import json
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from amrvio.cli.main import main
from amrvio.io.dataset import open_dataset
from amrvio.io.info import check_images, dataset_summary
from tests.test_io_datasets import (
    FRAME_DT,
    IMU_DT,
    T0,
    H,
    W,
    _image,
    _replace_line,
    _write_png,
    make_euroc,
    make_kitti,
    make_tum_mono,
    make_tumvi,
)
from tests.test_io_rosbag import write_bag

REPO = Path(__file__).resolve().parents[1]


def _amrvio(*args: str) -> subprocess.CompletedProcess[str]:
    exe = Path(sys.executable).with_name("amrvio")
    cmd = [str(exe)] if exe.exists() else [sys.executable, "-m", "amrvio.cli.main"]
    return subprocess.run([*cmd, *args], capture_output=True, text=True, timeout=120, cwd=REPO)


def test_info_euroc_summary_and_json(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    root = make_euroc(tmp_path / "seq", n_frames=5, n_imu=60)
    lines = [f"{k:05d} {(T0 + k * FRAME_DT) // 10**9}.{(T0 + k * FRAME_DT) % 10**9:09d} {6.0 + k}"
             for k in range(5)]
    (root / "times.txt").write_text("\n".join(lines) + "\n")
    out = tmp_path / "info.json"
    assert main(["info", f"euroc:{root}", "--json", str(out), "--check-images"]) == 0
    text = capsys.readouterr().out
    js = json.loads(out.read_text())
    assert js["kind"] == "euroc"
    fr = js["frames"]
    assert fr["count"] == 5 and (fr["width"], fr["height"]) == (W, H)
    assert fr["first_t_ns"] == T0 and fr["last_t_ns"] == T0 + 4 * FRAME_DT
    assert fr["duration_s"] == pytest.approx(4 * FRAME_DT * 1e-9)
    assert fr["rate_hz"] == pytest.approx(20.0)
    assert js["camera"]["distortion_model"] == "radtan"
    assert [js["camera"][k] for k in ("fx", "fy", "cx", "cy")] == [50.0, 51.0, 31.5, 23.5]
    assert js["camera"]["distortion"][:4] == [-0.1, 0.01, 0.001, 0.002]
    np.testing.assert_allclose(js["T_body_cam"]["t_m"], [0.1, -0.2, 0.3])
    assert js["T_body_cam"]["angle_deg"] == pytest.approx(90.0)
    assert js["imu"]["samples"] == 60 and js["imu"]["rate_hz"] == pytest.approx(1e9 / IMU_DT)
    assert js["imu_noise"]["gyro_noise_density"] == 1.6968e-04
    assert js["imu_noise"]["accel_random_walk"] == 3.0e-3
    gt = js["groundtruth"]
    assert gt["poses"] == 3 and gt["frame"] == "body" and gt["path_length_m"] == pytest.approx(0.2)
    assert js["exposure"] == {"frames_with": 5, "min_s": 0.006, "max_s": 0.010}
    assert js["photometric"] == {"inverse_response": False, "vignette": False}
    assert js["images_checked"] == 5
    # The printed table carries the same figures.
    for needle in ("euroc", "5 at 20.000 Hz", f"{W}x{H}", "60 samples at 200.000 Hz",
                   "3 poses (T_world_body), path 0.200 m", "6.000 .. 10.000 ms", "5 decoded"):
        assert needle in text, needle


def test_info_kitti_tum_mono_and_folder_without_imu(tmp_path: Path) -> None:
    seq = make_kitti(tmp_path / "00")
    s = dataset_summary(open_dataset(seq))  # bare PATH: detected
    assert s["kind"] == "kitti" and s["frames"]["count"] == 5 and s["imu"] is None
    assert s["frames"]["rate_hz"] == pytest.approx(1 / 0.1037359)
    assert s["camera"]["class"] == "PinholeCamera" and s["T_body_cam"] is None
    assert s["groundtruth"]["frame"] == "cam"
    assert s["groundtruth"]["path_length_m"] == pytest.approx(4 * np.hypot(np.hypot(0.01, 0.002), 0.8))
    mono = make_tum_mono(tmp_path / "mono", zipped=True)
    s = dataset_summary(open_dataset(f"tum-mono:{mono}"))
    assert s["photometric"] == {"inverse_response": True, "vignette": True}
    assert s["exposure"]["frames_with"] == 4 and s["exposure"]["max_s"] == pytest.approx(0.0135)
    assert s["groundtruth"] is None and s["imu_noise"] is None


def test_check_images_reports_a_frame_of_another_size(tmp_path: Path) -> None:
    root = make_euroc(tmp_path / "seq")
    odd = root / "mav0" / "cam0" / "data" / f"{T0 + 3 * FRAME_DT}.png"
    _write_png(odd, np.zeros((H, W + 4), dtype=np.uint8))
    ds = open_dataset(root)
    seen: list[int] = []
    checked = check_images(ds, seen.append)
    assert seen == [0, 1, 2, 3] and checked.n_checked == 4 and checked.n_usable == 3
    (bad,) = checked.skipped
    assert bad.index == 3 and bad.file == str(odd)
    assert bad.problem == f"image is {W + 4}x{H} but the recording's images are {W}x{H}"
    _write_png(odd, _image(3))
    assert check_images(ds).skipped == ()


# Every bad input the issue lists, each as one broken copy of a small EuRoC recording:
# (what, how to break the recording, the file named, its line (None: no line), words in the message)
Breaker = Callable[[Path], object]


def _cam_csv(root: Path) -> Path:
    return root / "mav0" / "cam0" / "data.csv"


def _imu_csv(root: Path) -> Path:
    return root / "mav0" / "imu0" / "data.csv"


def _bad_image(root: Path) -> Path:
    return root / "mav0" / "cam0" / "data" / f"{T0 + 2 * FRAME_DT}.png"


BAD_CASES: list[tuple[str, Breaker, Callable[[Path], Path], int | None, str]] = [
    ("malformed line", lambda r: _replace_line(_cam_csv(r), 3, f"12x4,{T0 + FRAME_DT}.png"),
     _cam_csv, 3, "not an integer"),
    ("missing column", lambda r: _replace_line(_imu_csv(r), 9, f"{T0 + 7 * IMU_DT},0.1,0.2,0.3,9.8,0"),
     _imu_csv, 9, "expected at least 7 columns, found 6"),
    ("time backwards", lambda r: _replace_line(_cam_csv(r), 4, f"{T0 - 5},{T0 + 2 * FRAME_DT}.png"),
     _cam_csv, 4, "goes backwards"),
    ("NaN", lambda r: _replace_line(_imu_csv(r), 6, f"{T0 + 4 * IMU_DT},0.1,0.2,nan,9.8,0,0"),
     _imu_csv, 6, "NaN"),
    ("undecodable image", lambda r: _bad_image(r).write_bytes(b"\x89PNG not really an image"),
     _bad_image, None, "cannot be decoded"),
    ("calibration size", lambda r: (r / "mav0" / "cam0" / "sensor.yaml").write_text(
        (r / "mav0" / "cam0" / "sensor.yaml").read_text().replace(f"[{W}, {H}]", "[640, 480]")),
     lambda r: r / "mav0" / "cam0" / "sensor.yaml", 12, "for 640x480 images but"),
]


@pytest.mark.parametrize("case", BAD_CASES, ids=[c[0] for c in BAD_CASES])
def test_info_subprocess_bad_input_is_one_line(
    tmp_path: Path, case: tuple[str, Breaker, Callable[[Path], Path], int | None, str]
) -> None:
    _, brk, named, line, words = case
    root = make_euroc(tmp_path / "seq")
    brk(root)
    proc = _amrvio("info", f"euroc:{root}", "--check-images")
    assert proc.returncode == 1, proc.stdout + proc.stderr
    # a file the reader needs stops it before any output; an unusable image is listed (stdout)
    assert (proc.stdout == "") == (named is not _bad_image), proc.stdout
    lines = proc.stderr.splitlines()
    assert len(lines) == 1, proc.stderr
    where = f"{named(root)}:{line}:" if line is not None else f"{named(root)}:"
    assert lines[0].startswith(f"amrvio info: error: {where}"), lines[0]
    assert words in lines[0]
    assert "Traceback" not in proc.stderr


def test_info_without_check_images_does_not_decode_every_frame(tmp_path: Path) -> None:
    root = make_euroc(tmp_path / "seq")
    _bad_image(root).write_bytes(b"garbage")
    assert main(["info", str(root)]) == 0


def test_info_unwritable_json_is_one_line(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    root = make_kitti(tmp_path / "00")
    rc = main(["info", f"kitti:{root}", "--json", str(tmp_path / "no" / "dir" / "x.json")])
    assert rc == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "--json" in err and "cannot write" in err


def _make_folder(root: Path) -> Path:
    for k in range(3):
        _write_png(root / "images" / f"f{k}.png", _image(k))
    (root / "timestamps.csv").write_text(
        "t_s,filename\n" + "".join(f"{1.0 + 0.1 * k:.1f},f{k}.png\n" for k in range(3)))
    return root


@pytest.mark.parametrize("kind", ["euroc", "tumvi", "tum-mono", "kitti", "bag", "folder"])
def test_info_every_dataset_spec_of_the_issue(tmp_path: Path, kind: str,
                                             capsys: pytest.CaptureFixture[str]) -> None:
    """``KIND:PATH`` and the bare PATH (format detected) name the same recording."""
    root = {
        "euroc": lambda p: make_euroc(p),
        "tumvi": lambda p: make_tumvi(p)[0],
        "tum-mono": lambda p: make_tum_mono(p),
        "kitti": lambda p: make_kitti(p),
        "bag": lambda p: write_bag(p.with_suffix(".bag"), 1),
        "folder": _make_folder,
    }[kind](tmp_path / "rec")
    extra = ["--image-topic", "/cam/image_raw", "--imu-topic", "/imu"] if kind == "bag" else []
    out = tmp_path / "info.json"
    for spec in (f"{kind}:{root}", str(root)):
        assert main(["info", spec, *extra, "--json", str(out), "--check-images"]) == 0, spec
        js = json.loads(out.read_text())
        assert js["kind"] == kind and js["frames"]["count"] >= 3
        assert js["images_checked"] == js["frames"]["count"]
    assert (js["imu"] is not None) == (kind in ("euroc", "tumvi", "bag"))
    # A prefix that does not fit the folder is one error line, not a traceback.
    wrong = "kitti" if kind != "kitti" else "tum-mono"
    capsys.readouterr()
    assert main(["info", f"{wrong}:{root}"]) == 1
    assert capsys.readouterr().err.count("\n") == 1


def test_info_subprocess_missing_images_one_counting_warning(tmp_path: Path) -> None:
    root = make_euroc(tmp_path / "seq", n_frames=6)
    for k in (1, 4):
        (root / "mav0" / "cam0" / "data" / f"{T0 + k * FRAME_DT}.png").unlink()
    proc = _amrvio("info", str(root))
    assert proc.returncode == 0, proc.stderr
    lines = proc.stderr.splitlines()
    assert len(lines) == 1 and "skipped 2 of 6 rows whose image file is missing" in lines[0]
    # Frames 0, 2, 3, 5 remain: intervals 100, 50, 100 ms, median 100 ms.
    assert "4 at 10.000 Hz" in proc.stdout


# The same bad inputs in the other text formats the readers parse (one line, file and line named).
OTHER_BAD: list[tuple[str, str, str, int, str, str]] = [
    # (kind, file relative to the recording, new text of the line, line, words, description)
    ("kitti", "times.txt", "2.07x-01", 3, "not a finite time", "malformed"),
    ("kitti", "times.txt", "nan", 3, "not a finite time", "NaN"),
    ("kitti", "times.txt", "5.0e-02", 3, "goes backwards", "backwards"),
    ("kitti", "poses.txt", "1 0 0 0 0 1 0 0 0 0 1", 2, "expected 12 columns", "missing column"),
    ("kitti", "poses.txt", "1 0 0 0 0 1 0 nan 0 0 1 0", 2, "not finite", "NaN pose"),
    ("folder", "timestamps.csv", "1.1x,f1.png", 3, "not a finite time", "malformed"),
    ("folder", "timestamps.csv", "nan,f1.png", 3, "not a finite time", "NaN"),
    ("folder", "timestamps.csv", "0.5,f1.png", 3, "goes backwards", "backwards"),
    ("folder", "timestamps.csv", "1.1", 3, "expected at least 2 columns", "missing column"),
    ("tumvi", "dso/cam0/times.txt", f"{T0 + FRAME_DT} 1403715273.312142976 nan", 3, "NaN", "NaN exposure"),
    ("tumvi", "mav0/mocap0/data.csv", f"{T0 - 1},1.1,2.0,3.0,1.0,0.0,0.0,0.0", 3, "goes backwards",
     "backwards gt"),
]


@pytest.mark.parametrize("case", OTHER_BAD, ids=[f"{c[0]}-{c[5]}" for c in OTHER_BAD])
def test_info_bad_lines_in_every_reader(tmp_path: Path, case: tuple[str, str, str, int, str, str],
                                        capsys: pytest.CaptureFixture[str]) -> None:
    kind, rel, text, line, words, _ = case
    makers: dict[str, Callable[[Path], Path]] = {
        "kitti": make_kitti, "folder": _make_folder, "tumvi": lambda p: make_tumvi(p)[0]}
    make = makers[kind]
    root = make(tmp_path / "rec")
    _replace_line(root / rel, line, text)
    assert main(["info", f"{kind}:{root}"]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err
    assert err.startswith(f"amrvio info: error: {root / rel}:{line}:"), err
    assert words in err, err


def test_unknown_kind_prefix_is_named(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    root = make_kitti(tmp_path / "00")
    assert main(["info", f"kiti:{root}"]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "unknown dataset kind 'kiti'" in err and "kitti" in err


@pytest.mark.parametrize("suffix", [".jpg", ".png"])
def test_info_subprocess_broken_image_prints_no_native_noise(tmp_path: Path, suffix: str) -> None:
    """libjpeg ("Premature end of JPEG file") and OpenCV's PNG reader print on fd 2 by themselves;
    the user still sees exactly one line."""
    import cv2

    root = tmp_path / "rec"
    root.mkdir()
    for k in range(3):
        ok, buf = cv2.imencode(suffix, _image(k))
        assert ok
        data = buf.tobytes()
        if k == 1:  # JPEG cut short; PNG with a bad first chunk
            data = data[:300] if suffix == ".jpg" else data[:8] + b"garbage" * 10
        (root / f"f{k}{suffix}").write_bytes(data)
    (root / "timestamps.csv").write_text("t_s,filename\n" + "".join(
        f"{1.0 + 0.1 * k:.1f},f{k}{suffix}\n" for k in range(3)))
    assert _amrvio("info", f"folder:{root}").returncode == 0  # only the first image is decoded
    proc = _amrvio("info", f"folder:{root}", "--check-images")
    assert proc.returncode == 1
    problem = ("truncated JPEG: the file ends before the image data" if suffix == ".jpg"
               else "incomplete PNG: no IEND chunk (the file was cut short or is corrupt)")
    assert proc.stderr.splitlines() == [
        f"amrvio info: error: {root / f'f1{suffix}'}: {problem} (1 of 3 images unusable; "
        "listed above)"], proc.stderr
    assert f"frame 1: {root / f'f1{suffix}'}: {problem}" in proc.stdout
