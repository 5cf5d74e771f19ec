"""amrvio eval against evo on real ground truth (EuRoC V1_01 and KITTI 00), and the trajectory
readers on the real files. Skipped when ../shared/data is absent."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from evo.core.metrics import Unit
from evo.core.trajectory import PoseTrajectory3D
from evo.tools import file_interface as evo_files

from amrvio.cli.main import main
from amrvio.eval import evaluate
from amrvio.io.trajectory import (
    read_euroc_csv,
    read_kitti,
    read_kitti_times,
    read_trajectory,
    read_tum,
    write_kitti,
    write_tum,
)
from amrvio.types.trajectory import Trajectory
from tests.test_eval import EVO_TOL_M, compare_with_evo, evo_figures

pytestmark = pytest.mark.real_data

ALIGNS = ("none", "origin", "se3", "sim3")
# Every alignment x (RPE in frames, RPE in metres); plus all-pairs and first-N alignment.
REAL_CASES = [
    (align, delta, unit, None, False)
    for align in ALIGNS
    for delta, unit in ((1, "frames"), (10, "frames"), (1.0, "m"))
] + [("sim3", 5, "frames", 200, True), ("se3", 2.0, "m", 100, True)]


def _perturbed(gt: Trajectory, seed: int, keep_every: int, first: int) -> Trajectory:
    """Deterministic noise, a linear drift, jittered stamps and a Sim3 world change."""
    from amrvio.types.lie import SO3, Sim3, matrix_to_quat_wxyz, so3_exp

    rng = np.random.default_rng(seed)
    g = gt.select(np.arange(first, len(gt), keep_every))
    m = len(g)
    drift = np.linspace(0.0, 1.0, m)[:, None] * np.array([0.5, -0.3, 0.2])
    pos = g.positions_m + rng.normal(0.0, 0.02, (m, 3)) + drift
    R = g.rotations() @ so3_exp(rng.normal(0.0, 0.01, (m, 3)))
    jitter = rng.uniform(-0.004, 0.004, m)
    S = Sim3(SO3.exp([0.2, -0.4, 0.9]), np.array([3.0, -1.0, 0.5]), 0.6)
    return Trajectory(g.stamps_s + jitter, pos, matrix_to_quat_wxyz(R)).transformed(S)


def test_euroc_readers_agree(shared_data: Path) -> None:
    root = shared_data / "euroc_V1_01_easy_first95"
    csv = read_euroc_csv(root / "mav0" / "state_groundtruth_estimate0" / "data.csv")
    tum = read_tum(root / "gt" / "V1_01_easy_vicon2gt_openvins_tum.txt")
    assert len(csv.trajectory) == len(tum) == 2895
    assert csv.velocities_m_s is not None and csv.gyro_bias is not None
    assert csv.accel_bias is not None and csv.accel_bias.shape == (2895, 3)
    assert csv.stamps_ns[0] == 1403715273262142976
    np.testing.assert_allclose(csv.trajectory.stamps_s, tum.stamps_s, rtol=0, atol=1e-5)
    np.testing.assert_allclose(csv.trajectory.positions_m, tum.positions_m, atol=1e-6)
    np.testing.assert_allclose(csv.trajectory.quats_wxyz, tum.quats_wxyz, atol=1e-5)
    assert tum.path_length_m() == pytest.approx(58.35, abs=0.05)  # MANIFEST: 58.35 m path
    # The original 200 Hz GT reads too, and auto-detection picks TUM for it.
    orig = read_trajectory(root / "gt" / "V1_01_easy_original_tum.txt")
    assert len(orig) > 20_000


def test_euroc_equals_evo(shared_data: Path, tmp_path: Path) -> None:
    gt_path = shared_data / "euroc_V1_01_easy_first95" / "gt" / "V1_01_easy_vicon2gt_openvins_tum.txt"
    gt = read_tum(gt_path)
    est_path = tmp_path / "est.tum"
    write_tum(est_path, _perturbed(gt, seed=21, keep_every=2, first=15))
    est = read_tum(est_path)
    assert len(est) < len(gt)
    worst = compare_with_evo(
        est, gt, evo_files.read_tum_trajectory_file(str(est_path)),
        evo_files.read_tum_trajectory_file(str(gt_path)), REAL_CASES,
    )
    assert worst < EVO_TOL_M
    # The copy was scaled by 0.6: the Sim3 scale back is ~1/0.6, in every drift window too.
    res = evaluate(est, gt)
    assert res.scale == pytest.approx(1 / 0.6, rel=0.01)
    assert len(res.drift_windows) >= 9
    assert all(w.scale == pytest.approx(1 / 0.6, rel=0.05) for w in res.drift_windows)


def _evo_kitti(poses_path: Path, times_path: Path, orthonormalise: bool) -> PoseTrajectory3D:
    poses = evo_files.read_kitti_poses_file(str(poses_path)).poses_se3
    if orthonormalise:
        fixed = []
        for T in poses:
            U, _, Vt = np.linalg.svd(T[:3, :3])
            M = np.array(T, dtype=float)
            M[:3, :3] = U @ Vt
            fixed.append(M)
        poses = fixed
    return PoseTrajectory3D(poses_se3=poses, timestamps=np.loadtxt(times_path))


def test_kitti_equals_evo(shared_data: Path, tmp_path: Path) -> None:
    root = shared_data / "kitti00_0000-0199"
    gt = read_kitti(root / "poses.txt", root / "times.txt")
    assert len(gt) == 200
    assert gt.path_length_m() == pytest.approx(145.0, abs=3.0)  # README: 145 m path
    np.testing.assert_array_equal(gt.stamps_s, read_kitti_times(root / "times.txt"))
    auto = read_trajectory(root / "poses.txt", times=root / "times.txt")  # detected as KITTI
    np.testing.assert_array_equal(auto.positions_m, gt.positions_m)
    noisy = _perturbed(gt, seed=22, keep_every=1, first=0)
    est = noisy.with_stamps(gt.stamps_s)  # KITTI: one shared times file
    est_path, est_times = tmp_path / "est_poses.txt", tmp_path / "est_times.txt"
    write_kitti(est_path, est, est_times)
    est = read_kitti(est_path, est_times)
    # The KITTI file stores rotations rounded to 7 digits (|R R^T - I| ~ 1e-7). amrvio projects
    # them onto SO(3); evo uses them as they are. Fed the same projected rotations, evo agrees
    # within 1e-6 m on every figure ...
    worst = compare_with_evo(
        est, gt, _evo_kitti(est_path, est_times, True),
        _evo_kitti(root / "poses.txt", root / "times.txt", True), REAL_CASES,
    )
    assert worst < EVO_TOL_M
    # ... and evo on the raw file differs only by that rounding (origin alignment multiplies the
    # positions by the non-orthonormal first GT rotation: up to ~6e-6 m on 145 m of path).
    raw_est = _evo_kitti(est_path, est_times, False)
    raw_gt = _evo_kitti(root / "poses.txt", root / "times.txt", False)
    for align in ALIGNS:
        case = [(align, 1, "frames", None, False), (align, 2.0, "m", None, False)]
        tol = 1e-5 if align == "origin" else EVO_TOL_M
        compare_with_evo(est, gt, raw_est, raw_gt, case, tol=tol)


# ``amrvio eval`` itself (the CLI, its file detection and its --json) against evo: EuRoC CSV ground
# truth, and KITTI files with times files on both sides.
CLI_CASES = [(align, d, u) for align in ALIGNS for d, u in ((1, "frames"), (2.0, "m"))]


def _cli_worst(tmp_path: Path, files: list[str], evo_est: PoseTrajectory3D,
               evo_ref: PoseTrajectory3D) -> float:
    worst = 0.0
    out = tmp_path / "cli.json"
    for align, delta, unit in CLI_CASES:
        assert main(["eval", *files, "--align", align, "--delta", str(delta), "--delta-unit", unit,
                     "--json", str(out)]) == 0
        js = json.loads(out.read_text())
        ref = evo_figures(evo_ref, evo_est, align, delta, Unit.frames if unit == "frames" else Unit.meters)
        assert set(ref) - set(js) == set()
        for key, v in ref.items():
            worst = max(worst, abs(float(js[key]) - v))
            assert abs(float(js[key]) - v) <= EVO_TOL_M, (align, delta, unit, key, js[key], v)
    return worst


def test_cli_eval_euroc_csv_gt_equals_evo(shared_data: Path, tmp_path: Path,
                                          capsys: pytest.CaptureFixture[str]) -> None:
    gt_csv = shared_data / "euroc_V1_01_easy_first95" / "mav0" / "state_groundtruth_estimate0" / "data.csv"
    gt = read_euroc_csv(gt_csv).trajectory
    est_path = tmp_path / "est.txt"  # no extension: detected as TUM by its 8 columns
    write_tum(est_path, _perturbed(gt, seed=23, keep_every=3, first=7))
    worst = _cli_worst(tmp_path, [str(est_path), str(gt_csv)],
                       evo_files.read_tum_trajectory_file(str(est_path)),
                       evo_files.read_euroc_csv_trajectory(str(gt_csv)))
    assert worst < EVO_TOL_M
    assert "ATE rmse [m]" in capsys.readouterr().out


def test_cli_eval_kitti_both_sides_with_times_equals_evo(shared_data: Path, tmp_path: Path) -> None:
    root = shared_data / "kitti00_0000-0199"
    gt = read_kitti(root / "poses.txt", root / "times.txt")
    # The estimate misses its first 10 frames and has its own times file.
    est = _perturbed(gt, seed=24, keep_every=1, first=10).with_stamps(gt.stamps_s[10:])
    est_path, est_times = tmp_path / "est_poses.txt", tmp_path / "est_times.txt"
    write_kitti(est_path, est, est_times)
    files = [str(est_path), str(root / "poses.txt"), "--est-times", str(est_times),
             "--gt-times", str(root / "times.txt")]
    # evo fed the same SO(3)-projected rotations (see test_kitti_equals_evo for the raw file).
    worst = _cli_worst(tmp_path, files, _evo_kitti(est_path, est_times, True),
                       _evo_kitti(root / "poses.txt", root / "times.txt", True))
    assert worst < EVO_TOL_M
