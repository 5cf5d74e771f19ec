"""`amrvio run` as one pass (issue 12): events.jsonl, eval.json, report.html, the ROS 2 bag, the
progress line and the Python API, on one small simulated recording with IMU and ground truth.

Each output is checked against an independent source: eval.json against evo on the ground truth
built here from the simulator's files, events.jsonl against the records' event strings and
summary.json, the bag read back with rosbags against trajectory.tum, the report's images decoded
with OpenCV and its configuration read back with the config loader.
"""

from __future__ import annotations

import base64
import csv
import json
import math
import os
import subprocess
import sys
from html.parser import HTMLParser
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pytest
import yaml

import amrvio
from amrvio.config import PipelineConfig, config_from_dict, config_to_dict
from amrvio.io.bag_out import TOPIC, read_odometry_bag
from amrvio.io.dataset import open_dataset
from amrvio.report.run_report import PLOTS

REPO = Path(__file__).resolve().parents[1]
HEIGHT = 1.2  # any height: it only sets the metric scale source


#: variables that choose the numeric kernels of the BLAS libraries (OPENBLAS_CORETYPE=Haswell on
#: one of our machines): the CLI subprocess keeps the test process's, or its solves differ from an
#: in-process run in the last bits, and the events that test_python_api_gives_the_cli_run compares
#: exactly hold such figures
_KERNEL_ENV = ("OPENBLAS_", "OMP_", "MKL_", "NPY_")


def _blas_kernels() -> str | None:
    """The kernels this process's OpenBLAS runs (threadpoolctl's "architecture", e.g. SkylakeX)."""
    import numpy  # noqa: F401  (loads its OpenBLAS)
    from threadpoolctl import threadpool_info

    names = [str(i["architecture"]) for i in threadpool_info()
             if i.get("internal_api") == "openblas" and i.get("architecture")]
    return names[0] if names else None


def _amrvio(*args: str | Path) -> subprocess.CompletedProcess[str]:
    env = {"PYTHONPATH": str(REPO), "PATH": "/usr/bin:/bin"}
    env.update({k: v for k, v in os.environ.items() if k.startswith(_KERNEL_ENV)})
    # `amrvio run` pins OpenBLAS to its AVX2 kernels unless told otherwise (amrvio.cli.reproducible);
    # the Python API that test_python_api_gives_the_cli_run compares with runs in this process,
    # with the kernels OpenBLAS chose for this CPU: the CLI gets the same ones
    kernels = _blas_kernels()
    if kernels is not None:
        env.setdefault("OPENBLAS_CORETYPE", kernels)
    return subprocess.run([sys.executable, "-m", "amrvio.cli.main", *map(str, args)],
                          capture_output=True, text=True, check=False, cwd=REPO, env=env)


@pytest.fixture(scope="module")
def run_dir(tiny_sim: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    root = tmp_path_factory.mktemp("app_run")
    out = root / "out"
    r = _amrvio("run", tiny_sim, "--out", out, "--camera-height", str(HEIGHT), "--bag-out",
                root / "odom_bag")
    assert r.returncode == 0, r.stderr
    # stderr is not a terminal and --progress is not given: no progress bar, nothing at all, but
    # the one line a kernel that refuses the reproducible restart causes (amrvio.cli.reproducible)
    lines = r.stderr.splitlines()
    assert lines == [] or (len(lines) == 1 and lines[0].endswith("the outputs may differ from run to run")), r.stderr
    assert f"report: {out / 'report.html'}" in r.stdout
    return out


def _jsonl(path: Path) -> list[dict[str, Any]]:
    lines = path.read_text(encoding="utf-8").splitlines()
    return [json.loads(ln, parse_constant=lambda c: pytest.fail(f"non-finite {c}")) for ln in lines]


def test_events_jsonl_holds_every_event_of_the_records(run_dir: Path) -> None:
    summary = json.loads((run_dir / "summary.json").read_text())
    events = _jsonl(run_dir / "events.jsonl")
    assert events, "a run that initialises has events"
    for e in events:
        assert {"type", "frame", "t_s"} <= set(e)
    # every event string of the records is one line of its frame, of its type
    from_strings = [e for e in events if e["type"] not in
                    ("init_attempt", "keyframe", "scale_reading", "vi_init", "static_init", "dropped",
                     "skipped")]
    assert [[e["frame"], e["type"]] for e in from_strings] == \
        [[i, s.partition(":")[0]] for i, s in summary["events"]]
    # the init report goes with init_ok; the reference it names is the one of the string
    ok = [e for e in events if e["type"] == "init_ok"]
    assert ok and ok[0]["init"]["status"] == "ok" and ok[0]["init"]["n_points"] > 0
    assert ok[0]["ref_frame"] == ok[0]["init"]["ref_index"] < ok[0]["frame"]
    # the frames before the first map made an attempt each, with its report
    attempts = [e for e in events if e["type"] == "init_attempt"]
    assert all(e["frame"] < ok[0]["frame"] and e["init"]["status"] != "ok" for e in attempts)
    # keyframes: as many lines as keyframes in summary.json, each with its reports
    kfs = [e for e in events if e["type"] == "keyframe"]
    assert len(kfs) == summary["n_keyframes"]
    assert any(e["ba"] is not None and e["ba"]["status"] == "ok" for e in kfs)
    # camera-height readings: those of scale_drift.csv
    with (run_dir / "scale_drift.csv").open() as fh:
        readings = list(csv.DictReader(fh))
    scale_lines = [e for e in events if e["type"] == "scale_reading"]
    assert [int(r["frame_index"]) for r in readings] == [e["frame_index"] for e in scale_lines]
    # in time order
    assert all(a["t_s"] <= b["t_s"] for a, b in zip(events, events[1:], strict=False))


def _camera_gt(seq: Path) -> tuple[np.ndarray, np.ndarray]:
    """Ground-truth camera positions and rotations at the image times, built from the
    simulator's files with numpy alone (body poses times T_BS from sensor.yaml)."""
    from scipy.spatial.transform import Rotation, Slerp

    gt = np.loadtxt(seq / "mav0/state_groundtruth_estimate0/data.csv", delimiter=",", comments="#")
    stamps = np.loadtxt(seq / "mav0/cam0/data.csv", delimiter=",", comments="#", usecols=0, dtype=np.int64)
    text = (seq / "mav0/cam0/sensor.yaml").read_text().replace("%YAML:1.0", "")
    T_bs = np.array(yaml.safe_load(text)["T_BS"]["data"]).reshape(4, 4)
    t = stamps * 1e-9
    tg = gt[:, 0] * 1e-9
    p = np.stack([np.interp(t, tg, gt[:, k]) for k in (1, 2, 3)], axis=1)
    rot = Slerp(tg, Rotation.from_quat(gt[:, [5, 6, 7, 4]]))(t)  # scipy: xyzw
    R = rot.as_matrix()
    return p + R @ T_bs[:3, 3], R @ T_bs[:3, :3]


def test_eval_json_agrees_with_evo(run_dir: Path, tiny_sim: Path) -> None:
    from evo.core import metrics, sync
    from evo.core.trajectory import PoseTrajectory3D
    from evo.tools import file_interface

    ev = json.loads((run_dir / "eval.json").read_text())
    assert ev["error"] is None and ev["metric_scale_source"] == "camera_height"
    est = file_interface.read_tum_trajectory_file(str(run_dir / "trajectory.tum"))
    p, R = _camera_gt(tiny_sim)
    stamps = np.loadtxt(tiny_sim / "mav0/cam0/data.csv", delimiter=",", comments="#", usecols=0) * 1e-9
    T = np.tile(np.eye(4), (len(p), 1, 1))
    T[:, :3, :3], T[:, :3, 3] = R, p
    gt = PoseTrajectory3D(poses_se3=list(T), timestamps=stamps)
    ref, est = sync.associate_trajectories(gt, est, max_diff=1e-6)
    assert ev["n_evaluated"] == est.num_poses == len(est.timestamps)
    est.align(ref, correct_scale=True)
    ape = metrics.APE(metrics.PoseRelation.translation_part)
    ape.process_data((ref, est))
    assert ev["ate_sim3_m"] == pytest.approx(ape.get_statistic(metrics.StatisticsType.rmse), abs=1e-9)
    assert ev["path_length_m"] == pytest.approx(ref.path_length, rel=1e-9)
    assert ev["ate_sim3_pct_of_path"] == pytest.approx(100 * ev["ate_sim3_m"] / ev["path_length_m"])
    # the figures are those of a good run (3 s, 30 frames, exact images)
    assert ev["ate_sim3_pct_of_path"] < 5.0


class _Page(HTMLParser):
    def __init__(self) -> None:
        super().__init__()
        self.imgs: list[dict[str, str | None]] = []
        self.pre: list[str] = []
        self.text: list[str] = []
        self.external: list[str] = []
        self._in_pre = False

    def handle_starttag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        a = dict(attrs)
        if tag == "img":
            self.imgs.append(a)
        if tag in ("script", "link", "iframe") or (tag != "img" and a.get("src")):
            self.external.append(tag)
        self._in_pre = tag == "pre"

    def handle_endtag(self, tag: str) -> None:
        if tag == "pre":
            self._in_pre = False

    def handle_data(self, data: str) -> None:
        (self.pre if self._in_pre else self.text).append(data)


def test_report_html_is_self_contained_with_every_plot(run_dir: Path) -> None:
    page = _Page()
    page.feed((run_dir / "report.html").read_text(encoding="utf-8"))
    assert page.external == []
    # the simulator records an IMU: every plot is there, once, in order
    assert [i["data-plot"] for i in page.imgs] == list(PLOTS)
    for img in page.imgs:
        src = img["src"] or ""
        head, _, b64 = src.partition(",")
        assert head == "data:image/png;base64"
        raw = base64.b64decode(b64, validate=True)
        assert raw.startswith(b"\x89PNG\r\n\x1a\n")
        pix = cv2.imdecode(np.frombuffer(raw, np.uint8), cv2.IMREAD_COLOR)
        assert pix is not None and pix.shape[0] > 100 and pix.shape[1] > 300
        # a plot, not a blank canvas: coloured lines drawn on it
        sat = cv2.cvtColor(pix, cv2.COLOR_BGR2HSV)[..., 1]
        assert (sat > 80).mean() > 0.002, img["data-plot"]
    text = " ".join(page.text)
    summary = json.loads((run_dir / "summary.json").read_text())
    assert "frames processed" in text and "First map at frame" in text
    assert f" {summary['n_frames']} " in f" {text} "
    # the full configuration used, read back: the one of summary.json
    cfg = config_from_dict(yaml.safe_load("".join(page.pre)))
    assert config_to_dict(cfg) == summary["config"]
    assert cfg.scale.camera_height_m == HEIGHT
    # where a Chromium is installed (Debian's chromium on developer machines): the browser
    # decodes every plot at the size of the PNG
    from tests.browser_check import find_browser, render

    browser = find_browser()
    if browser is not None:
        shown = render(run_dir / "report.html", browser)
        assert shown.n_ok == shown.n_images == len(PLOTS)
        sizes = {}
        for img in page.imgs:
            raw = base64.b64decode((img["src"] or "").partition(",")[2])
            pix = cv2.imdecode(np.frombuffer(raw, np.uint8), cv2.IMREAD_COLOR)
            assert pix is not None
            h, w = pix.shape[:2]
            sizes[img["data-plot"]] = (w, h)
        assert shown.plots == sizes


def test_bag_reads_back_as_the_trajectory(run_dir: Path) -> None:
    stamps, pos, quat, twist = read_odometry_bag(run_dir.parent / "odom_bag", TOPIC)
    traj = np.loadtxt(run_dir / "trajectory.tum", comments="#", ndmin=2)
    with (run_dir / "health.csv").open() as fh:
        rows = [r for r in csv.DictReader(fh) if r["status"] != "lost"]
    assert len(stamps) == len(traj) == len(rows)
    # header stamps to the nanosecond: those of the images
    np.testing.assert_allclose(stamps * 1e-9, [float(r["t_s"]) for r in rows], atol=1e-9)
    np.testing.assert_allclose(pos, traj[:, 1:4], atol=1e-6)
    q_tum = traj[:, [7, 4, 5, 6]]  # TUM: qx qy qz qw
    assert np.all(np.abs(np.sum(quat * q_tum, axis=1)) > 1 - 1e-9)
    # the twist of an inner frame: the central difference of its neighbours, in its own frame
    from scipy.spatial.transform import Rotation

    i = len(traj) // 2
    t = traj[:, 0]
    R = Rotation.from_quat(traj[:, 4:8])
    v = R[i].inv().apply((traj[i + 1, 1:4] - traj[i - 1, 1:4]) / (t[i + 1] - t[i - 1]))
    w = (R[i - 1].inv() * R[i + 1]).as_rotvec() / (t[i + 1] - t[i - 1])
    np.testing.assert_allclose(twist[i, :3], v, atol=1e-5)
    np.testing.assert_allclose(twist[i, 3:], w, atol=1e-5)


def test_python_api_gives_the_cli_run(run_dir: Path, tiny_sim: Path) -> None:
    from amrvio.pipeline.threads import limit_native_threads

    # the CLI runs BLAS on one thread; the VI initialiser's solves (eigh, pinv) differ in the
    # last bits with more, and the events hold their figures exactly
    limit_native_threads(1)
    res = amrvio.run(str(tiny_sim), {"scale": {"camera_height_m": HEIGHT}})
    assert isinstance(res, amrvio.RunResult) and res.out_dir is None
    summary = json.loads((run_dir / "summary.json").read_text())
    assert json.loads(json.dumps(res.summary)) == summary
    traj = np.loadtxt(run_dir / "trajectory.tum", comments="#", ndmin=2)
    np.testing.assert_allclose(res.trajectory.stamps_s, traj[:, 0], atol=1e-9)
    np.testing.assert_allclose(res.trajectory.positions_m, traj[:, 1:4], atol=1e-6)
    assert res.eval_summary is not None
    ev = json.loads((run_dir / "eval.json").read_text())
    assert res.eval_summary["ate_sim3_m"] == pytest.approx(ev["ate_sim3_m"], abs=1e-12)
    assert [json.loads(json.dumps(e)) for e in res.events] == _jsonl(run_dir / "events.jsonl")
    assert res.config == config_from_dict({"scale": {"camera_height_m": HEIGHT}})
    assert len(res.records) == summary["n_frames"]


def test_python_api_stop_interrupts_with_valid_outputs(tiny_sim: Path, tmp_path: Path) -> None:
    calls = {"n": 0}

    def stop() -> bool:
        calls["n"] += 1
        return calls["n"] > 12  # asked before each frame: 12 frames run

    out = tmp_path / "out"
    res = amrvio.run(tiny_sim, PipelineConfig(), out=out, stop=stop)
    assert res.interrupted and res.summary["n_frames"] == 12
    summary = json.loads((out / "summary.json").read_text())
    assert summary["state"] == "interrupted" and summary["n_frames"] == 12
    with (out / "health.csv").open() as fh:
        assert len(list(csv.DictReader(fh))) == 12
    _jsonl(out / "events.jsonl")
    assert "interrupted: the figures cover the frames done" in (out / "report.html").read_text()


def test_progress_line_only_when_asked(tiny_sim: Path, tmp_path: Path) -> None:
    r = _amrvio("run", tiny_sim, "--out", tmp_path / "out", "--max-frames", "15", "--progress",
                "--no-report")
    assert r.returncode == 0, r.stderr
    last = r.stderr.replace("\r", "\n").strip().splitlines()[-1]
    assert "15/15" in last and "frame/s" in last, last
    assert " kf " in last and "losses" in last and "blur" in last, last
    assert not (tmp_path / "out" / "report.html").exists()


def test_bag_out_is_checked_before_any_work(tiny_sim: Path, tmp_path: Path) -> None:
    (tmp_path / "taken").mkdir()
    r = _amrvio("run", tiny_sim, "--out", tmp_path / "out", "--bag-out", tmp_path / "taken")
    assert r.returncode == 1 and r.stderr.count("\n") == 1
    assert "--bag-out" in r.stderr and "exists already" in r.stderr
    assert not (tmp_path / "out" / "summary.json").exists()
    r = _amrvio("run", tiny_sim, "--out", tmp_path / "out2", "--bag-out", tmp_path / "no" / "bag")
    assert r.returncode == 1 and "does not exist" in r.stderr


def test_eval_json_says_why_without_a_usable_ground_truth(tmp_path: Path) -> None:
    from amrvio.pipeline.run_eval import camera_groundtruth
    from tests.test_io_datasets import make_euroc

    ds = open_dataset(str(make_euroc(tmp_path / "seq", n_frames=4, n_imu=20)))
    import dataclasses

    no_extrinsic = dataclasses.replace(ds, T_body_cam=None)
    gt, why = camera_groundtruth(no_extrinsic)
    assert gt is None and "T_body_cam" in why
    gt, _ = camera_groundtruth(ds)
    assert gt is not None and ds.groundtruth is not None and ds.T_body_cam is not None
    expect = ds.groundtruth.positions_m + np.einsum("nij,j->ni", ds.groundtruth.rotations(), ds.T_body_cam.t)
    np.testing.assert_allclose(gt.positions_m, expect, atol=1e-12)
    assert not math.isnan(float(gt.positions_m.sum()))


def test_demo_camera_height_and_table(run_dir: Path, tiny_sim: Path) -> None:
    from amrvio.demo import camera_height_m, summary_table

    p, _ = _camera_gt(tiny_sim)
    assert camera_height_m(tiny_sim) == pytest.approx(p[0, 2], abs=1e-9)  # the floor is z = 0
    summary = json.loads((run_dir / "summary.json").read_text())
    ev = json.loads((run_dir / "eval.json").read_text())
    rows = dict(summary_table(summary, ev, 0.7, 10.0, 20.0))
    assert rows["frames"].startswith(f"{summary['n_frames']} ({summary['n_in_trajectory']} with a pose")
    assert rows["ATE, Sim3 aligned"].startswith(f"{ev['ate_sim3_m']:.3f} m")
    assert rows["wall time"] == f"simulate 10 s, run 20 s ({summary['n_frames'] / 20:.1f} frames/s)"


@pytest.mark.parametrize("case", ["unknown key", "wrong type", "missing calibration"])
def test_bad_config_and_missing_calibration_are_one_line(case: str, tmp_path: Path) -> None:
    from tests.fuzz.helpers import make_folder

    seq = make_folder(tmp_path / "seq")
    cfg = tmp_path / "c.yaml"
    cfg.write_text({"unknown key": "tracking:\n  klt:\n    max_feature: 5\n",
                    "wrong type": "seed: [1, 2]\n",
                    "missing calibration": "seed: 1\n"}[case], encoding="utf-8")
    if case == "missing calibration":
        (seq / "camera.txt").unlink()
    out = tmp_path / "out"
    r = _amrvio("run", seq, "--out", out, "--config", cfg)
    assert r.returncode == 1 and r.stderr.count("\n") == 1, r.stderr
    assert r.stderr.startswith("amrvio run: error: ")
    expect = {"unknown key": "tracking.klt.max_feature", "wrong type": "seed",
              "missing calibration": "calib"}[case]
    assert expect in r.stderr, r.stderr
    assert not (out / "summary.json").exists() and not (out / "report.html").exists()


def test_health_csv_has_one_row_per_frame_and_no_repeated_column(run_dir: Path) -> None:
    with (run_dir / "health.csv").open(newline="") as fh:
        header = next(csv.reader(fh))
    assert len(header) == len(set(header)), sorted(h for h in header if header.count(h) > 1)
    assert {"n_tracks", "vo_tracks", "status", "blur_flag", "exposure_ev", "parallax_px",
            "accel_std_m_s2", "init_status", "events"} <= set(header)
    summary = json.loads((run_dir / "summary.json").read_text())
    with (run_dir / "health.csv").open(newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == summary["n_frames"]
    # the two track counts are different things: they differ somewhere
    assert any(r["vo_tracks"] != r["n_tracks"] for r in rows)
    assert all(int(r["vo_tracks"]) > 0 for r in rows if r["status"] == "tracked")
