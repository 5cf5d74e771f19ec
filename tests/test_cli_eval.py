"""``amrvio eval`` end to end: in-process through amrvio.cli.main and as a subprocess."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from amrvio.cli.main import main
from amrvio.eval import evaluate
from amrvio.eval.example import EXAMPLE_EST, EXAMPLE_GT, make_example_pair
from amrvio.io.trajectory import read_trajectory, write_euroc_csv, write_kitti, write_tum

REPO = Path(__file__).resolve().parents[1]


def test_builtin_example_files_match_generator() -> None:
    est, gt = make_example_pair(seed=0)
    r_est, r_gt = read_trajectory(EXAMPLE_EST), read_trajectory(EXAMPLE_GT)
    np.testing.assert_array_equal(r_est.positions_m, est.positions_m)
    np.testing.assert_array_equal(r_gt.stamps_s, gt.stamps_s)
    # a few ulp: the generator's rotation-to-quaternion rounds differently on another processor
    # (up to 5.6e-16 on an AMD EPYC against the files written on a Xeon)
    np.testing.assert_allclose(r_est.quats_wxyz, est.quats_wxyz, rtol=0, atol=1e-15)


def test_cli_eval_json_and_plot(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out_json, out_png = tmp_path / "r.json", tmp_path / "r.png"
    rc = main(["eval", str(EXAMPLE_EST), str(EXAMPLE_GT), "--align", "sim3", "--delta", "2",
               "--json", str(out_json), "--plot", str(out_png)])
    assert rc == 0
    table = capsys.readouterr().out
    assert "ATE rmse [m]" in table and "Sim3 scale" in table
    js = json.loads(out_json.read_text())
    ref = evaluate(read_trajectory(EXAMPLE_EST), read_trajectory(EXAMPLE_GT), delta=2)
    assert js["ate_rmse_m"] == pytest.approx(ref.ate.rmse, abs=1e-12)
    assert js["rpe_trans_rmse_m"] == pytest.approx(ref.rpe.trans.rmse, abs=1e-12)
    assert js["rpe_delta"] == 2.0 and js["align"] == "sim3"
    assert f"{js['ate_rmse_m']:.6f}" in table
    assert out_png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert out_png.stat().st_size > 10_000


def test_cli_eval_kitti_with_times_and_metres(tmp_path: Path) -> None:
    est, gt = make_example_pair(seed=1)
    gt = gt.select(np.arange(0, len(gt), 2))
    # KITTI files carry no stamps: give both trajectories the same times file.
    est = est.with_stamps(gt.stamps_s[: len(est)])
    write_kitti(tmp_path / "gt.txt", gt, tmp_path / "times.txt")
    write_kitti(tmp_path / "est.txt", est)
    out = tmp_path / "k.json"
    rc = main(["eval", str(tmp_path / "est.txt"), str(tmp_path / "gt.txt"),
               "--gt-times", str(tmp_path / "times.txt"), "--est-times", str(tmp_path / "times.txt"),
               "--align", "se3", "--delta", "1.5", "--delta-unit", "m", "--n-align", "50",
               "--max-diff", "0.001", "--json", str(out)])
    assert rc == 0
    js = json.loads(out.read_text())
    assert js["matched_poses"] == len(est)
    assert js["n_align"] == 50 and js["rpe_delta_unit"] == "m"


def test_cli_eval_bad_file_is_one_line(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    bad = tmp_path / "bad.tum"
    bad.write_text("1.0 0 0 0 0 0 0 1\n0.5 0 0 0 0 0 0 1\n")
    rc = main(["eval", str(bad), str(EXAMPLE_GT)])
    assert rc == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1
    assert f"{bad}:2:" in err and "backwards" in err


def test_cli_eval_no_overlap_is_one_line(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    est, gt = make_example_pair(seed=0)
    write_tum(tmp_path / "late.tum", est.with_stamps(est.stamps_s + 500.0))
    rc = main(["eval", str(tmp_path / "late.tum"), str(EXAMPLE_GT)])
    assert rc == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "no timestamps match" in err


def test_cli_eval_subprocess_bad_file(tmp_path: Path) -> None:
    bad = tmp_path / "broken.txt"
    bad.write_text("# t x y z qx qy qz qw\n1.0 0 0 0 0 0 0 1\n2.0 0 0 0 0 0 1\n")
    exe = Path(sys.executable).with_name("amrvio")
    cmd = [str(exe)] if exe.exists() else [sys.executable, "-m", "amrvio.cli.main"]
    proc = subprocess.run([*cmd, "eval", str(bad), str(EXAMPLE_GT)], capture_output=True,
                          text=True, timeout=60, cwd=REPO)
    assert proc.returncode == 1
    assert proc.stdout == ""
    lines = proc.stderr.splitlines()
    assert len(lines) == 1, proc.stderr
    assert f"{bad}:3:" in lines[0] and "expected 8 columns" in lines[0]
    assert "Traceback" not in proc.stderr


def test_cli_eval_euroc_csv_ground_truth(tmp_path: Path) -> None:
    est, gt = make_example_pair(seed=2)
    # EuRoC-like nanosecond clock: the CSV holds integer ns, the TUM estimate decimal seconds.
    t0 = 1403715273.262142976
    gt = gt.with_stamps(gt.stamps_s + t0)
    est = est.with_stamps(est.stamps_s + t0)
    gt_csv = tmp_path / "data.csv"
    write_euroc_csv(gt_csv, gt)
    write_tum(tmp_path / "est.txt", est)
    out = tmp_path / "e.json"
    rc = main(["eval", str(tmp_path / "est.txt"), str(gt_csv), "--align", "se3", "--json", str(out)])
    assert rc == 0
    js = json.loads(out.read_text())
    ref = evaluate(est, gt, align="se3")
    assert js["matched_poses"] == ref.matched_poses == len(est)
    assert js["ate_rmse_m"] == pytest.approx(ref.ate.rmse, rel=1e-9)
    assert js["rpe_rot_rmse_deg"] == pytest.approx(ref.rpe.rot_deg.rmse, rel=1e-9)
    assert js["scale"] == pytest.approx(ref.scale, rel=1e-9)


@pytest.mark.parametrize(("option", "value", "words"), [
    ("--delta", "0", "must be in (0, 1e6]"), ("--delta", "x", "expected a number"),
    ("--delta", "inf", "must be a finite number in (0, 1e6]"),
    ("--max-diff", "-1", "must be in [0, 3600]"), ("--n-align", "2.5", "expected an integer"),
    ("--n-align", "0", "must be in [1, 10000000]"),
])
def test_cli_eval_rejects_bad_option_values(option: str, value: str, words: str,
                                            capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["eval", str(EXAMPLE_EST), str(EXAMPLE_GT), option, value]) == 1
    err = capsys.readouterr().err
    assert words in err and err.count("\n") == 1 and err.startswith(f"amrvio eval: error: "
                                                                    f"argument {option}: ")
