"""Evaluation: Umeyama, association, alignment, ATE/RPE, scale and scale drift.

Closed forms (a known Sim3 is recovered exactly, a known offset gives a known ATE) and evo as an
independent implementation (evo.core.sync / metrics / trajectory.align) on synthetic data.
"""

from __future__ import annotations

import copy
from pathlib import Path

import numpy as np
import pytest
from evo.core import metrics as evo_metrics
from evo.core import sync as evo_sync
from evo.core.metrics import PoseRelation, Unit
from evo.tools import file_interface as evo_files
from hypothesis import given, settings
from hypothesis import strategies as st

from amrvio.errors import ShapeError
from amrvio.eval import (
    AlignMethod,
    EvaluationError,
    WindowStatus,
    align_trajectory,
    associate,
    ate,
    evaluate,
    rpe,
    rpe_pairs,
    scale_windows,
)
from amrvio.eval.example import make_example_pair
from amrvio.geometry.align import umeyama
from amrvio.io.trajectory import write_tum
from amrvio.types.lie import SO3, Sim3, matrix_to_quat_wxyz, so3_exp
from amrvio.types.trajectory import Trajectory

EVO_TOL_M = 1e-6


def _random_traj(n: int = 120, seed: int = 0, dt: float = 0.05) -> Trajectory:
    rng = np.random.default_rng(seed)
    t = np.asarray(100.0 + dt * np.arange(n), dtype=np.float64)
    pos = np.cumsum(rng.normal(0, 0.2, (n, 3)), axis=0)
    R = so3_exp(np.cumsum(rng.normal(0, 0.1, (n, 3)), axis=0))
    return Trajectory(t, pos, matrix_to_quat_wxyz(R))


S_KNOWN = Sim3(SO3.exp([0.3, -1.2, 0.7]), np.array([4.0, -2.0, 1.5]), 0.37)


# ------------------------------------------------------------------------------------ Umeyama


def test_umeyama_recovers_known_sim3_exactly() -> None:
    src = np.random.default_rng(1).normal(0, 3, (50, 3))
    dst = S_KNOWN.act(src)
    S = umeyama(src, dst, with_scale=True)
    np.testing.assert_allclose(S.matrix(), S_KNOWN.matrix(), atol=1e-12)
    rigid = Sim3(S_KNOWN.rot, S_KNOWN.t, 1.0)
    S2 = umeyama(src, rigid.act(src), with_scale=False)
    np.testing.assert_allclose(S2.matrix(), rigid.matrix(), atol=1e-12)
    assert S2.s == 1.0


def test_umeyama_weights_ignore_zero_weight_outlier() -> None:
    src = np.random.default_rng(2).normal(0, 1, (20, 3))
    dst = S_KNOWN.act(src)
    dst[5] += 100.0
    w = np.ones(20)
    w[5] = 0.0
    np.testing.assert_allclose(umeyama(src, dst, True, w).matrix(), S_KNOWN.matrix(), atol=1e-11)


def test_umeyama_planar_points_keep_a_proper_rotation() -> None:
    rng = np.random.default_rng(3)
    src = np.c_[rng.normal(0, 1, (30, 2)), np.zeros(30)]
    S = umeyama(src, S_KNOWN.act(src), True)
    np.testing.assert_allclose(S.matrix(), S_KNOWN.matrix(), atol=1e-11)
    assert np.linalg.det(S.R) == pytest.approx(1.0)


@pytest.mark.parametrize(
    ("src", "needle"),
    [
        (np.zeros((2, 3)) + [[0, 0, 0], [1, 0, 0]], "at least 3"),
        (np.ones((5, 3)), "zero variance"),
        (np.outer(np.arange(6.0), [1.0, 2.0, -1.0]), "collinear"),
    ],
)
def test_umeyama_degenerate_input(src: np.ndarray, needle: str) -> None:
    with pytest.raises(ShapeError, match=needle):
        umeyama(src, src + 1.0, with_scale=True)


def test_umeyama_bad_shapes_and_values() -> None:
    a = np.random.default_rng(0).normal(size=(5, 3))
    with pytest.raises(ShapeError, match="same shape"):
        umeyama(a, a[:4], True)
    with pytest.raises(ShapeError, match=r"\(N, 3\)"):
        umeyama(a[:, :2], a[:, :2], True)
    b = a.copy()
    b[0, 0] = np.nan
    with pytest.raises(ShapeError, match="non-finite"):
        umeyama(a, b, True)
    with pytest.raises(ShapeError, match="weights"):
        umeyama(a, a, True, weights=-np.ones(5))


@settings(max_examples=30, deadline=None)
@given(
    seed=st.integers(0, 10_000),
    scale=st.floats(0.01, 100.0),
    rotvec=st.lists(st.floats(-3.0, 3.0), min_size=3, max_size=3),
)
def test_umeyama_property_recovers_any_sim3(seed: int, scale: float, rotvec: list[float]) -> None:
    src = np.random.default_rng(seed).normal(0, 2, (10, 3))
    S_true = Sim3(SO3.exp(rotvec), np.array([1.0, -2.0, 3.0]), scale)
    S = umeyama(src, S_true.act(src), True)
    np.testing.assert_allclose(S.act(src), S_true.act(src), atol=1e-9 * max(scale, 1.0))
    assert S.s == pytest.approx(scale, rel=1e-9)


# -------------------------------------------------------------------------------- association


@pytest.mark.parametrize("seed", range(6))
def test_associate_equals_evo(seed: int) -> None:
    rng = np.random.default_rng(seed)
    gt = np.cumsum(rng.uniform(0.001, 0.03, 300))
    est = np.sort(rng.choice(gt, 120, replace=False) + rng.uniform(-0.015, 0.015, 120))
    est = np.unique(est)
    for a, b in ((est, gt), (gt, est), (est, est + 0.003)):
        ie, ig = associate(a, b, max_diff_s=0.01)
        if a.size <= b.size:
            ref_i, ref_j = evo_sync.matching_time_indices(a, b, 0.01)
            np.testing.assert_array_equal(ie, ref_i)
            np.testing.assert_array_equal(ig, ref_j)
        else:
            ref_i, ref_j = evo_sync.matching_time_indices(b, a, 0.01)
            np.testing.assert_array_equal(ig, ref_i)
            np.testing.assert_array_equal(ie, ref_j)
        assert np.all(np.abs(a[ie] - b[ig]) <= 0.01)


def test_associate_closed_form() -> None:
    est = np.array([0.0, 1.0, 2.004, 3.5, 10.0])
    gt = np.array([0.005, 0.999, 2.0, 2.009, 3.0, 4.0, 9.0])
    ie, ig = associate(est, gt, 0.01)
    np.testing.assert_array_equal(ie, [0, 1, 2])
    np.testing.assert_array_equal(ig, [0, 1, 2])
    ie, ig = associate(est, gt, 0.0)
    assert ie.size == 0
    # A stamp exactly halfway between two: the earlier one wins (as evo).
    ie, ig = associate(np.array([1.5]), np.array([1.0, 2.0, 3.0]), 0.5)
    np.testing.assert_array_equal(ig, [0])


# ----------------------------------------------------------------------------- closed forms


@pytest.mark.parametrize("method", ["sim3", "se3", "origin", "none"])
def test_known_transform_is_recovered_and_ate_is_zero(method: str) -> None:
    gt = _random_traj()
    S = S_KNOWN if method == "sim3" else Sim3(S_KNOWN.rot, S_KNOWN.t, 1.0)
    if method == "none":
        S = Sim3.identity()
    est = gt.transformed(S.inverse())
    res = evaluate(est, gt, align=method)
    assert res.matched_poses == len(gt)
    assert res.ate.rmse < 1e-9
    assert res.ate.max < 1e-9
    assert res.rpe.trans.rmse < 1e-9
    assert res.rpe.rot_deg.rmse < 1e-6
    np.testing.assert_allclose(res.alignment.matrix(), S.matrix(), atol=1e-9)
    assert res.scale == pytest.approx(S.s, rel=1e-12)
    assert res.scale_error_pct == pytest.approx(abs(1 - S.s) * 100, rel=1e-9)
    for w in res.drift_windows:
        assert w.status is WindowStatus.OK
        assert w.scale == pytest.approx(S.s, rel=1e-9)
    assert res.scale_drift_pct == pytest.approx(0.0, abs=1e-7)


def test_constant_offset_gives_known_ate_and_zero_rpe() -> None:
    gt = _random_traj(seed=5)
    offset = np.array([0.3, -0.4, 0.0])  # |offset| = 0.5 m
    est = Trajectory(gt.stamps_s, gt.positions_m + offset, gt.quats_wxyz)
    res = evaluate(est, gt, align="none", delta=3)
    for v in (res.ate.rmse, res.ate.mean, res.ate.median, res.ate.max, res.ate.min):
        assert v == pytest.approx(0.5, abs=1e-12)
    assert res.ate.std == pytest.approx(0.0, abs=1e-12)
    # A world translation does not change relative motion.
    assert res.rpe.trans.max < 1e-12
    # SE3 alignment removes the offset entirely.
    assert evaluate(est, gt, align="se3").ate.rmse < 1e-12


def test_rpe_closed_form_constant_body_error() -> None:
    # Each estimated step is the true step plus 0.1 m forward in the body frame and 2 deg yaw.
    n = 40
    steps_gt = [Sim3(SO3.exp([0, 0, 0.05]), np.array([1.0, 0, 0]), 1.0)] * n
    err = Sim3(SO3.exp([0, 0, np.radians(2.0)]), np.array([0.1, 0, 0]), 1.0)
    poses_gt, poses_est = [Sim3.identity()], [Sim3.identity()]
    for s in steps_gt[1:]:
        poses_gt.append(poses_gt[-1] @ s)
        poses_est.append(poses_est[-1] @ s @ err)

    def to_traj(ps: list[Sim3]) -> Trajectory:
        return Trajectory(np.arange(n, dtype=np.float64) / 10, np.array([p.t for p in ps]),
                          matrix_to_quat_wxyz(np.array([p.R for p in ps])))

    gt, est = to_traj(poses_gt), to_traj(poses_est)
    r = rpe(est, gt, delta=1)
    assert r.pairs.shape == (n - 1, 2)
    # E = (Q_rel)^-1 P_rel = err exactly for every pair.
    np.testing.assert_allclose(r.trans_errors_m, 0.1, atol=1e-12)
    np.testing.assert_allclose(r.rot_errors_deg, 2.0, atol=1e-9)


def test_rpe_pairs_rules() -> None:
    pos = np.c_[np.arange(10.0), np.zeros(10), np.zeros(10)]  # 1 m per step
    np.testing.assert_array_equal(rpe_pairs(pos, 3), [[0, 3], [3, 6], [6, 9]])
    np.testing.assert_array_equal(rpe_pairs(pos, 8, all_pairs=True), [[0, 8], [1, 9]])
    np.testing.assert_array_equal(rpe_pairs(pos, 2.5, "m"), [[0, 3], [3, 6], [6, 9]])
    np.testing.assert_array_equal(rpe_pairs(pos, 7.9, "m", all_pairs=True), [[0, 8], [1, 9]])
    assert rpe_pairs(pos, 20).shape == (0, 2)
    with pytest.raises(ShapeError, match="integer"):
        rpe_pairs(pos, 1.5, "frames")
    with pytest.raises(ShapeError, match="> 0"):
        rpe_pairs(pos, 0)


def test_scale_windows_closed_form_piecewise_scale() -> None:
    # Straight-ish path, the estimate's scale is 2 on the first half and 4 on the second half.
    n = 201
    rng = np.random.default_rng(0)
    x = np.linspace(0.0, 100.0, n)
    gt_pos = np.c_[x, np.sin(x / 5.0), 0.5 * np.cos(x / 7.0)]
    steps = np.diff(gt_pos, axis=0)
    factor = np.where(np.arange(n - 1) < 100, 2.0, 4.0)
    est_pos = np.vstack([gt_pos[:1], gt_pos[:1] + np.cumsum(steps * factor[:, None], axis=0)])
    q = matrix_to_quat_wxyz(so3_exp(rng.normal(0, 0.1, (n, 3))))
    stamps = np.arange(n, dtype=np.float64) / 10
    gt = Trajectory(stamps, gt_pos, q)
    est = Trajectory(stamps, est_pos, q)
    wins = scale_windows(est, gt, window_frames=25)
    assert len(wins) == 8
    assert [w.index_start for w in wins] == list(range(0, 200, 25))
    assert wins[-1].index_end == 200
    for w in wins:
        expected = 0.5 if w.index_end <= 100 else 0.25
        assert w.scale == pytest.approx(expected, rel=1e-12)
    wins_m = scale_windows(est, gt)  # default: 10 % of the path
    assert 9 <= len(wins_m) <= 10
    total = gt.path_length_m()
    assert sum(w.gt_length_m for w in wins_m) == pytest.approx(total, rel=1e-12)
    res = evaluate(est, gt, drift_window_frames=25)
    assert res.scale_drift_pct == pytest.approx(100.0, rel=1e-9)


def test_scale_window_on_a_line_is_degenerate_not_an_error() -> None:
    n = 30
    pos = np.c_[np.arange(n, dtype=float), np.zeros(n), np.zeros(n)]
    q = np.tile([1.0, 0, 0, 0], (n, 1))
    t = Trajectory(np.arange(n, dtype=float), pos, q)
    wins = scale_windows(t, t, window_frames=10)
    assert all(w.status is WindowStatus.DEGENERATE and w.scale is None for w in wins)
    assert "collinear" in wins[0].reason


def test_est_with_fewer_poses_than_gt() -> None:
    gt = _random_traj(n=200, seed=7)
    idx = np.arange(10, 150, 3)
    est = gt.select(idx).transformed(S_KNOWN)
    res = evaluate(est, gt)
    assert res.matched_poses == idx.size
    np.testing.assert_array_equal(res.idx_gt, idx)
    ie, ig = associate(est, gt)  # trajectories or stamp arrays
    np.testing.assert_array_equal(ig, idx)
    np.testing.assert_array_equal(ie, np.arange(idx.size))
    assert res.ate.rmse < 1e-9
    assert res.path_length_m == pytest.approx(gt.select(idx).path_length_m())


def test_n_align_uses_first_poses_only() -> None:
    gt = _random_traj(n=100, seed=8)
    est = gt.transformed(S_KNOWN.inverse())
    pos = np.array(est.positions_m)
    pos[50:] += 1.0  # corrupt the second half: alignment on the first 50 is still exact
    est2 = Trajectory(est.stamps_s, pos, est.quats_wxyz)
    res = evaluate(est2, gt, align="sim3", n_align=50)
    np.testing.assert_allclose(res.alignment.matrix(), S_KNOWN.matrix(), atol=1e-9)
    assert res.ate_errors_m[:50].max() < 1e-9
    np.testing.assert_allclose(res.ate_errors_m[50:], S_KNOWN.s * np.sqrt(3.0), rtol=1e-9)


def test_evaluation_errors_are_explained() -> None:
    gt = _random_traj(n=50)
    far = gt.with_stamps(gt.stamps_s + 1000.0)
    with pytest.raises(EvaluationError, match="no timestamps match"):
        evaluate(far, gt)
    two = gt.select([0, 1])
    with pytest.raises(EvaluationError, match="at least 3"):
        evaluate(two, gt, align="se3")
    # Two poses are enough for origin alignment; the Sim3 scale is then undefined.
    res = evaluate(two, gt, align="origin")
    assert res.scale is None and res.scale_error_pct is None
    js = res.to_json_dict()
    assert js["scale"] is None and js["matched_poses"] == 2


def test_align_trajectory_requires_associated_pair() -> None:
    gt = _random_traj(n=20)
    with pytest.raises(ShapeError, match="same length"):
        align_trajectory(gt.select(np.arange(10)), gt, AlignMethod.SE3)
    with pytest.raises(ShapeError, match="same length"):
        ate(gt.select(np.arange(10)), gt)


def test_json_has_required_keys_and_is_deterministic() -> None:
    est, gt = make_example_pair(seed=0)
    est2, gt2 = make_example_pair(seed=0)
    np.testing.assert_array_equal(est.positions_m, est2.positions_m)
    js = evaluate(est, gt).to_json_dict()
    for key in ("ate_rmse_m", "ate_mean_m", "ate_median_m", "ate_max_m", "scale",
                "scale_error_pct", "rpe_trans_rmse_m", "rpe_rot_rmse_deg", "matched_poses",
                "path_length_m", "align", "scale_drift_windows"):
        assert key in js
    assert js == evaluate(est2, gt2).to_json_dict()
    # The example's estimate has scale ~1/0.45 and a drifting scale: the windows show it.
    assert js["scale"] == pytest.approx(1 / 0.45, rel=0.1)
    scales = [w["scale"] for w in js["scale_drift_windows"]]
    assert scales[0] > scales[-1]


# --------------------------------------------------------------------------------- evo oracle


def _perturbed(gt: Trajectory, seed: int, keep_every: int = 1) -> Trajectory:
    rng = np.random.default_rng(seed)
    g = gt.select(np.arange(0, len(gt), keep_every))
    m = len(g)
    drift = np.linspace(0.0, 1.0, m)[:, None] * np.array([0.4, -0.3, 0.2])
    pos = g.positions_m + rng.normal(0, 0.03, (m, 3)) + drift
    R = g.rotations() @ so3_exp(rng.normal(0, 0.02, (m, 3)))
    stamps = g.stamps_s + rng.uniform(-0.004, 0.004, m)
    return Trajectory(stamps, pos, matrix_to_quat_wxyz(R)).transformed(S_KNOWN)


def evo_figures(ref, est, align: str, delta: float, unit: Unit, n_align: int = -1,
                all_pairs: bool = False) -> dict[str, float]:
    """evo's numbers, computed as evo_ape / evo_rpe do it (ref, est: evo trajectories)."""
    ref, est = evo_sync.associate_trajectories(ref, est, max_diff=0.01)
    est = copy.deepcopy(est)
    scale: dict[str, float] = {}
    if align == "origin":
        est.align_origin(ref)
    elif align in ("se3", "sim3"):
        _, _, s = est.align(ref, correct_scale=align == "sim3", n=n_align)
        if align == "sim3":
            scale["scale"] = float(s)
    ape = evo_metrics.APE(PoseRelation.translation_part)
    ape.process_data((ref, est))
    rt = evo_metrics.RPE(PoseRelation.translation_part, delta, unit, all_pairs=all_pairs)
    rt.process_data((ref, est))
    rr = evo_metrics.RPE(PoseRelation.rotation_angle_deg, delta, unit, all_pairs=all_pairs)
    rr.process_data((ref, est))
    a, t, r = ape.get_all_statistics(), rt.get_all_statistics(), rr.get_all_statistics()
    return {
        "ate_rmse_m": a["rmse"], "ate_mean_m": a["mean"], "ate_median_m": a["median"],
        "ate_max_m": a["max"], "ate_std_m": a["std"], "rpe_trans_rmse_m": t["rmse"],
        "rpe_trans_mean_m": t["mean"], "rpe_trans_max_m": t["max"], "rpe_rot_rmse_deg": r["rmse"],
        "rpe_rot_max_deg": r["max"], "matched_poses": float(ref.num_poses),
        "rpe_pairs": float(len(rt.error)), **scale,
    }


def compare_with_evo(est: Trajectory, gt: Trajectory, evo_est, evo_ref, cases,
                     tol: float = EVO_TOL_M) -> float:
    """Max |amrvio - evo| over every figure and case; asserts each figure within ``tol``."""
    worst = 0.0
    for align, delta, unit, n_align, all_pairs in cases:
        evo_unit = Unit.frames if unit == "frames" else Unit.meters
        ref_fig = evo_figures(evo_ref, evo_est, align, delta, evo_unit, n_align or -1, all_pairs)
        js = evaluate(est, gt, align=align, delta=delta, delta_unit=unit, n_align=n_align,
                      all_pairs=all_pairs).to_json_dict()
        for key, v in ref_fig.items():
            diff = abs(float(js[key]) - v)
            worst = max(worst, diff)
            assert diff <= tol, (align, delta, unit, key, js[key], v)
    return worst


CASES = [
    (align, delta, unit, None, all_pairs)
    for align in ("none", "origin", "se3", "sim3")
    for delta, unit, all_pairs in ((1, "frames", False), (4, "frames", True), (1.5, "m", False))
] + [("sim3", 2.0, "m", 40, True), ("se3", 1, "frames", 25, False)]


def test_equals_evo_on_synthetic_tum_files(tmp_path: Path) -> None:
    gt = _random_traj(n=400, seed=11, dt=0.02)
    est = _perturbed(gt, seed=12, keep_every=3)  # fewer poses than gt, jittered stamps
    gp, ep = tmp_path / "gt.tum", tmp_path / "est.tum"
    write_tum(gp, gt)
    write_tum(ep, est)
    from amrvio.io.trajectory import read_tum

    worst = compare_with_evo(read_tum(ep), read_tum(gp), evo_files.read_tum_trajectory_file(str(ep)),
                             evo_files.read_tum_trajectory_file(str(gp)), CASES)
    assert worst < EVO_TOL_M


def test_large_max_diff_repeats_a_gt_pose_like_evo(tmp_path: Path) -> None:
    gt = _random_traj(n=60, seed=13, dt=0.5)
    est = _perturbed(_random_traj(n=60, seed=13, dt=0.5), seed=14).select(np.arange(0, 60, 2))
    # Estimate stamps 0.1 s apart in pairs: two estimate poses share their nearest gt pose.
    stamps = np.repeat(gt.stamps_s[::4], 2)[: len(est)] + np.tile([0.0, 0.1], len(est))[: len(est)]
    est = est.with_stamps(stamps)
    res = evaluate(est, gt, max_diff_s=0.3)
    assert np.any(np.diff(res.idx_gt) == 0)
    ep, gp = tmp_path / "est.tum", tmp_path / "gt.tum"
    write_tum(ep, est)
    write_tum(gp, gt)
    ref, est_evo = evo_sync.associate_trajectories(
        evo_files.read_tum_trajectory_file(str(gp)), evo_files.read_tum_trajectory_file(str(ep)),
        max_diff=0.3,
    )
    est_evo.align(ref, correct_scale=True)
    ape = evo_metrics.APE(PoseRelation.translation_part)
    ape.process_data((ref, est_evo))
    assert res.matched_poses == ref.num_poses
    assert abs(res.ate.rmse - ape.get_statistic(evo_metrics.StatisticsType.rmse)) < EVO_TOL_M
