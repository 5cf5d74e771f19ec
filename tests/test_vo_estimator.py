"""Local BA (GTSAM back-end, SciPy back-end as a cross-check) and camera-height scale."""

from __future__ import annotations

import numpy as np

from amrvio.estimator.camera_height import HeightEstimate, estimate_height, smooth_scales
from amrvio.estimator.local_ba import BAProblem, BAStatus, solve_ba_gtsam, solve_ba_scipy
from amrvio.estimator.mapper import BAReport, Mapper, MapperConfig, TriangulationReport
from amrvio.geometry.ground_plane import PlaneStatus
from amrvio.geometry.projection import project
from amrvio.types.lie import SE3, se3_matrix

K = np.array([[500.0, 0, 320.0], [0, 500.0, 240.0], [0, 0, 1]])


def _problem(noise_px: float, seed: int = 0) -> tuple[BAProblem, np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    nk = 5
    T = np.stack([np.linalg.inv(SE3.exp(np.r_[0.1 * i, 0, 0.5 * i, 0, 0.02 * i, 0]).matrix())
                  for i in range(nk)])
    X = rng.uniform([-4, -3, 6], [4, 3, 15], (150, 3))
    oc, op, ou = [], [], []
    for i in range(nk):
        uv, _ = project(K, T[i], X)
        oc += [i] * len(X)
        op += list(range(len(X)))
        ou.append(uv + rng.normal(0, noise_px, uv.shape) if noise_px else uv)
    Tn = T.copy()
    for i in range(2, nk):
        Tn[i] = SE3.exp(rng.normal(0, 0.01, 6)).matrix() @ T[i]
    fixed = np.zeros(nk, dtype=bool)
    fixed[:2] = True
    prob = BAProblem(Tn, fixed, X + rng.normal(0, 0.05, X.shape), np.array(oc), np.array(op),
                     np.vstack(ou), K, 2.0)
    return prob, T, X


def test_gtsam_ba_recovers_noise_free_truth_and_keeps_fixed_poses() -> None:
    prob, T, X = _problem(0.0)
    out = solve_ba_gtsam(prob, 20)
    assert np.allclose(out.T_cam_world[:2], prob.T_cam_world[:2])
    assert np.abs(out.T_cam_world - T).max() < 1e-5
    assert np.abs(out.points - X).max() < 1e-4
    assert np.max(out.residual_px) < 1e-3


def test_scipy_ba_agrees_with_gtsam_on_small_problem() -> None:
    prob, T, _ = _problem(0.5, seed=1)
    g = solve_ba_gtsam(prob, 20)
    s = solve_ba_scipy(prob, 50)
    assert np.median(g.residual_px) < 1.0
    assert np.abs(g.T_cam_world[:, :3, 3] - T[:, :3, 3]).max() < 0.02
    # SciPy TRF+LSMR converges more slowly (bench_vo): it agrees to a few centimetres
    assert np.abs(s.T_cam_world[:, :3, 3] - g.T_cam_world[:, :3, 3]).max() < 0.05


def test_schur_ba_recovers_noise_free_truth_and_keeps_fixed_poses() -> None:
    from amrvio.estimator.ba_schur import solve_ba_schur

    prob, T, X = _problem(0.0)
    out = solve_ba_schur(prob, 20)
    assert np.array_equal(out.T_cam_world[:2], prob.T_cam_world[:2])
    assert np.abs(out.T_cam_world - T).max() < 1e-6
    assert np.abs(out.points - X).max() < 1e-5
    assert np.max(out.residual_px) < 1e-3


def test_schur_ba_reaches_gtsam_minimum_with_outliers() -> None:
    """An independent implementation (GTSAM's LM) of the same Huber problem: the same cost and
    the same poses; 10 observations moved by 30 px exercise the robust weights."""
    from amrvio.estimator.ba_schur import huber_cost, solve_ba_schur

    prob, T, _ = _problem(0.5, seed=1)
    px = prob.obs_px.copy()
    px[::70] += 30.0
    prob = BAProblem(prob.T_cam_world, prob.fixed, prob.points, prob.obs_cam, prob.obs_point, px,
                     prob.K, prob.huber_px)
    g = solve_ba_gtsam(prob, 30)
    s = solve_ba_schur(prob, 30)
    cost_g, cost_s = huber_cost(g.residual_px, 2.0), huber_cost(s.residual_px, 2.0)
    assert cost_s < huber_cost(s.initial_residual_px, 2.0)
    assert abs(cost_s - cost_g) < 1e-6 * cost_g
    assert np.abs(s.T_cam_world - g.T_cam_world).max() < 1e-6
    assert np.abs(s.T_cam_world[:, :3, 3] - T[:, :3, 3]).max() < 0.02


def test_huber_cost_closed_form() -> None:
    from amrvio.estimator.ba_schur import huber_cost

    # inside: e^2 / 2; outside: k (|e| - k / 2)
    assert huber_cost(np.array([1.0, 3.0]), 2.0) == 0.5 + 2.0 * (3.0 - 1.0)
    assert huber_cost(np.zeros(0), 2.0) == 0.0


def test_camera_height_scale_from_ground_points() -> None:
    rng = np.random.default_rng(2)
    h_map = 0.5  # map units; true height 1.65 m -> scale 3.3
    G = np.column_stack([rng.uniform(-3, 3, 200), np.full(200, h_map), rng.uniform(1, 3.5, 200)])
    est = estimate_height(7, G, 1.65)
    assert est.status is PlaneStatus.OK
    assert abs(est.scale - 3.3) < 1e-6
    bad = estimate_height(8, G[:5], 1.65)
    assert not np.isfinite(bad.scale)
    s = smooth_scales([est, bad, HeightEstimate(20, PlaneStatus.OK, 0.5, 3.5, 100)], 30, 1)
    assert s.shape == (30,) and np.all(np.isfinite(s))
    assert abs(s[0] - 3.4) < 1e-9  # median of the window around the first keyframe


def _mapper_with_window(noise_px: float, n_bad: int = 0, seed: int = 3) -> tuple[Mapper, np.ndarray]:
    """Five keyframes seeing 150 points (world truth returned); the map starts perturbed and
    the first ``n_bad`` points have one observation moved by 30 px."""
    prob, T, X = _problem(noise_px, seed)
    mp = Mapper(K, MapperConfig())
    m = mp.map
    ids = np.arange(len(X), dtype=np.int64)
    for i in range(len(T)):
        uv = prob.obs_px[prob.obs_cam == i].copy()
        if i == 3:
            uv[:n_bad, 1] += 30.0
        m.add_keyframe(10 * i, prob.T_cam_world[i], ids, uv)
    m.set_points(ids, prob.points)
    return mp, X


def test_local_ba_reports_what_it_did() -> None:
    mp, X = _mapper_with_window(0.3, n_bad=6)
    rep = mp.local_ba()
    assert rep.status is BAStatus.OK and rep.ok
    assert (rep.n_keyframes, rep.n_points, rep.n_observations) == (5, 150, 750)
    assert rep.iterations >= 1
    assert rep.initial_rms_px is not None and rep.final_rms_px is not None
    assert rep.final_rms_px < rep.initial_rms_px
    # the six corrupted points are culled, and they are counted
    assert rep.n_outliers >= 6
    assert not mp.map.points_of(np.arange(6, dtype=np.int64)).any()
    kept = mp.map.points_of(np.arange(150, dtype=np.int64))
    assert rep.n_outliers == 150 - int(kept.sum())


def test_local_ba_failure_reasons() -> None:
    mp = Mapper(K, MapperConfig())
    ids = np.arange(5, dtype=np.int64)
    uv = np.full((5, 2), 100.0)
    mp.map.add_keyframe(0, np.eye(4), ids, uv)
    mp.map.add_keyframe(1, np.eye(4), ids, uv)
    mp.map.set_points(ids, np.tile([0.0, 0.0, 5.0], (5, 1)))
    rep = mp.local_ba()
    assert rep.status is BAStatus.TOO_FEW_POINTS and not rep.ok
    assert rep.n_points == 5 and rep.initial_rms_px is None and rep.final_rms_px is None
    # points seen by only one keyframe of the window: nothing to adjust
    mp1 = Mapper(K, MapperConfig())
    ids = np.arange(20, dtype=np.int64)
    mp1.map.add_keyframe(0, np.eye(4), ids, np.full((20, 2), 100.0))
    mp1.map.set_points(ids, np.tile([0.0, 0.0, 5.0], (20, 1)))
    assert mp1.local_ba().status is BAStatus.TOO_FEW_POINTS


def test_triangulate_new_counts_candidates_and_rejections_by_cause() -> None:
    rng = np.random.default_rng(9)
    T1 = se3_matrix(np.eye(3), np.array([-1.0, 0.0, 0.0]))  # camera 2 one unit right of camera 1
    n_good, n_far, n_bad, n_behind = 30, 7, 5, 4
    n = n_good + n_far + n_bad + n_behind
    depth = np.r_[rng.uniform(5, 10, n_good), np.full(n_far, 1000.0),
                  rng.uniform(5, 10, n_bad + n_behind)]
    P = np.column_stack([rng.uniform(-0.3, 0.3, n) * depth, rng.uniform(-0.2, 0.2, n) * depth,
                         depth])
    uv0, _ = project(K, np.eye(4), P)
    uv1, _ = project(K, T1, P)
    uv1[n_good + n_far: n_good + n_far + n_bad, 1] += 20.0  # off the epipolar line
    behind = slice(n - n_behind, n)
    uv1[behind, 0] = 2 * uv0[behind, 0] - uv1[behind, 0]  # flow the wrong way: rays meet behind
    # two more tracks that are no candidates: no earlier keyframe, and already a point
    ids = np.arange(n + 2, dtype=np.int64)
    first_kf = np.r_[np.zeros(n, dtype=np.int64), -1, 0]
    first_uv = np.vstack([uv0, uv0[:2]])
    uv = np.vstack([uv1, uv1[:2]])
    mp = Mapper(K, MapperConfig())
    mp.map.add_keyframe(0, np.eye(4), ids, first_uv)
    mp.map.add_keyframe(3, T1, ids, uv)
    mp.map.set_points(ids[-1:], np.zeros((1, 3)))
    rep = mp.triangulate_new(1, ids, first_kf, first_uv, uv, n + 2)
    assert rep == TriangulationReport(n_candidates=n, n_created=n_good, n_behind_camera=n_behind,
                                      n_low_parallax=n_far, n_large_reprojection=n_bad)
    made = mp.map.points_of(ids[:n])
    assert made[:n_good].all() and not made[n_good:].any()
    np.testing.assert_allclose(mp.map.xyz[:n_good], P[:n_good], rtol=1e-8)


def test_retired_keyframe_tracks_do_not_change_the_local_ba() -> None:
    """Tracks dropped from the keyframes that left the BA window (the memory bound of a long
    run) leave the BA's result exactly as it was; one keyframe fewer kept, and it changes."""
    cfg = MapperConfig(ba_window=2, ba_fixed=1)

    def ba(keep_last: int | None) -> tuple[BAReport, np.ndarray, np.ndarray]:
        mp0, _ = _mapper_with_window(0.3)
        mp = Mapper(K, cfg)
        mp.map = mp0.map
        if keep_last is not None:
            mp.map.retire_tracks(keep_last)
        rep = mp.local_ba()
        return rep, np.stack([k.T_cam_world for k in mp.map.keyframes]), mp.map.xyz.copy()

    rep0, T0, X0 = ba(None)
    rep1, T1, X1 = ba(3)
    assert rep0 == rep1 and np.array_equal(T0, T1) and np.array_equal(X0, X1)
    rep2, _, _ = ba(2)
    assert rep2.n_keyframes == 2 and rep2.n_observations < rep0.n_observations
    m = _mapper_with_window(0.3)[0].map
    m.retire_tracks(3)
    m.retire_tracks(4)  # never restores what is gone
    assert [len(k.track_ids) for k in m.keyframes] == [0, 0, 150, 150, 150] and m.n_retired == 2
