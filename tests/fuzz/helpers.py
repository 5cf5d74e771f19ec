"""The fuzz suite's tools: small recordings to corrupt, the CLI called in-process, and the two
outcomes every case must end in (issue 14):

- exit 1 with exactly one stderr line, ``amrvio CMD: error: ...``, naming the file (and the line
  where one applies), and no traceback: :func:`expect_error`;
- exit 0 with outputs that pass the validators: finite values everywhere, TUM files of 8 columns
  with unit quaternions and increasing stamps, strict JSON, row counts that agree:
  :func:`check_run_dir`, :func:`check_diagnose_dir`, :func:`strict_json`.

The CLI runs in-process (``amrvio.cli.main.main(argv)`` with pytest's captured stderr), which is
what keeps several hundred cases within the test budget; the Ctrl-C cases use subprocesses.
"""

from __future__ import annotations

import csv
import json
import math
import shutil
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pytest

from amrvio.cli.main import main
from tests.test_io_datasets import make_euroc, make_kitti

KITTI_REAL = "kitti00_0000-0199"
N_SYNTH = 6


@dataclass(frozen=True, slots=True)
class Outcome:
    rc: int
    out: str
    err: str


def cli(argv: Sequence[str | Path], capsys: pytest.CaptureFixture[str]) -> Outcome:
    """``amrvio ARGV`` in-process; its exit code, stdout and stderr."""
    capsys.readouterr()
    rc = main([str(a) for a in argv])
    cap = capsys.readouterr()
    return Outcome(rc, cap.out, cap.err)


def expect_error(o: Outcome, command: str, names: str | Path | None = None,
                 line: int | None = None, words: str | None = None) -> str:
    """Exit 1, one stderr line ``amrvio COMMAND: error: ...`` naming ``names`` (``names:line:``
    when ``line`` is given) and holding ``words``; no traceback. Returns the line."""
    assert "Traceback" not in o.err, o.err
    lines = o.err.splitlines()
    assert o.rc == 1, (o.rc, o.err, o.out[-300:])
    assert len(lines) == 1, o.err
    assert lines[0].startswith(f"amrvio {command}: error: "), lines[0]
    if names is not None:
        where = f"{names}:{line}:" if line is not None else f"{names}"
        assert where in lines[0], (where, lines[0])
    if words is not None:
        assert words in lines[0], (words, lines[0])
    return lines[0]


# ---------------------------------------------------------------------------------- validators
def _no_constant(name: str) -> float:
    raise AssertionError(f"non-finite JSON constant {name}")


def strict_json(path: Path) -> dict[str, Any]:
    """The JSON file, which must have no NaN or Infinity and only finite numbers."""
    data = json.loads(path.read_text(encoding="utf-8"), parse_constant=_no_constant)
    assert isinstance(data, dict)

    def walk(v: object) -> None:
        if isinstance(v, float):
            assert math.isfinite(v)
        elif isinstance(v, dict):
            for x in v.values():
                walk(x)
        elif isinstance(v, list):
            for x in v:
                walk(x)

    walk(data)
    return data


def check_tum(path: Path) -> np.ndarray:
    """A TUM file: a ``#`` header, 8 finite columns, unit quaternions, increasing stamps."""
    text = path.read_text(encoding="utf-8")
    assert text.startswith("#"), path
    rows = [ln.split() for ln in text.splitlines() if ln.strip() and not ln.startswith("#")]
    assert all(len(r) == 8 for r in rows), path
    a = np.array([[float(v) for v in r] for r in rows], dtype=np.float64).reshape(-1, 8)
    assert np.all(np.isfinite(a)), path
    np.testing.assert_allclose(np.linalg.norm(a[:, 4:], axis=1), 1.0, atol=1e-6)
    assert np.all(np.diff(a[:, 0]) > 0), path
    return a


def csv_rows(path: Path) -> list[dict[str, str]]:
    """The rows of a CSV output; no cell may say nan or inf."""
    with path.open(newline="", encoding="utf-8") as fh:
        rows = list(csv.DictReader(fh))
    for r in rows:
        for v in r.values():
            assert (v or "").strip().lower() not in ("nan", "inf", "-inf", "infinity"), (path, r)
    return rows


def check_run_dir(out: Path, n_frames: int | None = None, n_skipped: int | None = None,
                  interrupted: bool = False) -> dict[str, Any]:
    """Every output of ``amrvio run`` in ``out``, cross-checked; returns the summary."""
    summary = strict_json(out / "summary.json")
    strict_json(out / "timings.json")
    assert summary["interrupted"] is interrupted
    assert summary["state"] == ("interrupted" if interrupted else "finished")
    assert not list(out.glob(".*.partial")), "a half-written file was left"
    rows = csv_rows(out / "health.csv")
    assert len(rows) == summary["n_frames"]
    if n_frames is not None:
        assert summary["n_frames"] == n_frames
    if n_skipped is not None:
        assert summary["n_skipped"] == n_skipped == len(summary["skipped_frames"])
    traj = check_tum(out / "trajectory.tum")
    kfs = check_tum(out / "keyframes.tum")
    online = check_tum(out / "trajectory_online.tum")
    with_online = [r for r in rows if r["online_x"] != ""]
    np.testing.assert_allclose(online[:, 0], [float(r["t_s"]) for r in with_online], atol=1e-6)
    # LOST frames are left out of the trajectory; the others are there, at their stamps
    kept = [r for r in rows if r["status"] != "lost"]
    assert traj.shape[0] == len(kept) == summary["n_in_trajectory"]
    np.testing.assert_allclose(traj[:, 0], [float(r["t_s"]) for r in kept], atol=1e-6)
    counts = summary["status_counts"]
    assert isinstance(counts, dict)
    assert sum(counts.values()) == len(rows)
    for status, n in counts.items():
        assert n == sum(r["status"] == status for r in rows)
    assert set(np.round(kfs[:, 0], 6)) <= set(np.round(traj[:, 0], 6))
    assert "timings_s" not in summary
    csv_rows(out / "scale_drift.csv")
    return summary


def check_diagnose_dir(out: Path, n_frames: int) -> list[dict[str, str]]:
    rows = csv_rows(out / "health.csv")
    assert len(rows) == n_frames
    assert (out / "advice.txt").is_file()
    return rows


# ---------------------------------------------------------------------------------- recordings
def texture(h: int, w: int, seed: int = 0) -> np.ndarray:
    """A smooth random texture (trackable corners at every scale)."""
    rng = np.random.default_rng(seed)
    img = np.zeros((h, w), np.float64)
    for s in (4, 8, 16):
        small = rng.random((h // s + 2, w // s + 2))
        img += cv2.resize(small, (w + 2 * s, h + 2 * s), interpolation=cv2.INTER_CUBIC)[:h, :w]
    img -= img.min()
    return np.asarray(255 * img / img.max(), dtype=np.uint8)


def make_synth_kitti(seq: Path, n: int = N_SYNTH, ext: str = ".png") -> Path:
    """A KITTI layout of ``n`` 64x48 frames (tests.test_io_datasets), images saved as ``ext``."""
    make_kitti(seq, n)
    if ext != ".png":
        for p in sorted((seq / "image_0").glob("*.png")):
            img = cv2.imread(str(p), cv2.IMREAD_UNCHANGED)
            assert cv2.imwrite(str(p.with_suffix(ext)), img)
            p.unlink()
    return seq


def make_synth_euroc(root: Path, n: int = N_SYNTH) -> Path:
    """An EuRoC layout with IMU and ground truth (tests.test_io_datasets), ``n`` frames."""
    return make_euroc(root, n_frames=n, n_imu=20 * n)


def make_folder(root: Path, n: int = N_SYNTH) -> Path:
    """A plain image folder: images/f<k>.png and timestamps.csv (no calibration: pass --calib)."""
    for k in range(n):
        (root / "images").mkdir(parents=True, exist_ok=True)
        assert cv2.imwrite(str(root / "images" / f"f{k}.png"), texture(48, 64, k))
    (root / "timestamps.csv").write_text(
        "t_s,filename\n" + "".join(f"{1.0 + 0.05 * k:.2f},f{k}.png\n" for k in range(n)))
    (root / "camera.txt").write_text("Pinhole 50 50 31.5 23.5 0\n64 48\n")
    return root


def make_real_kitti(shared: Path, seq: Path, n: int, ext: str = ".jpg") -> Path:
    """The first ``n`` frames of the KITTI 00 excerpt in ../shared/data (``ext``: .png keeps the
    files as links)."""
    src = shared / KITTI_REAL
    if not (src / "image_0").is_dir():
        from tests.skip_policy import skip_shared_missing

        skip_shared_missing(src)
    (seq / "image_0").mkdir(parents=True)
    for k in range(n):
        p = src / "image_0" / f"{k:06d}.png"
        if ext == ".png":
            (seq / "image_0" / p.name).symlink_to(p)
        else:
            img = cv2.imread(str(p), cv2.IMREAD_UNCHANGED)
            assert cv2.imwrite(str(seq / "image_0" / f"{k:06d}{ext}"), img)
    shutil.copy(src / "calib.txt", seq / "calib.txt")
    for name in ("times.txt", "poses.txt"):
        lines = (src / name).read_text().splitlines()[:n]
        (seq / name).write_text("\n".join(lines) + "\n")
    return seq


def copy_of(base: Path, dst: Path) -> Path:
    shutil.copytree(base, dst, symlinks=True)
    return dst


def images_of(root: Path) -> list[Path]:
    """The image files of a recording made above, in frame order."""
    for sub in ("image_0", "mav0/cam0/data", "images"):
        d = root / sub
        if d.is_dir():
            return sorted(p for p in d.iterdir() if p.suffix in (".png", ".jpg"))
    raise AssertionError(f"no images under {root}")


ImageBreaker = Callable[[Path], None]
"""Corrupts one image file in place."""


def _encoded(path: Path, img: np.ndarray) -> bytes:
    ok, buf = cv2.imencode(path.suffix, img)
    assert ok
    return buf.tobytes()


def _grey(path: Path) -> np.ndarray:
    img = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    assert img is not None
    return np.asarray(img)


__all__ = ["KITTI_REAL", "N_SYNTH", "ImageBreaker", "Outcome", "check_diagnose_dir", "check_run_dir",
           "check_tum", "cli", "copy_of", "csv_rows", "expect_error", "images_of", "make_folder",
           "make_real_kitti", "make_synth_euroc", "make_synth_kitti", "strict_json", "texture"]
