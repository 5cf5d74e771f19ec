"""Local BA (GTSAM back-end, SciPy back-end as a cross-check) and camera-height scale."""

from __future__ import annotations

import dataclasses
import tracemalloc

import numpy as np
import pytest

from amrvio.estimator.camera_height import HeightEstimate, estimate_height, smooth_scales
from amrvio.estimator.local_ba import BAProblem, BAStatus, points_then_newest_cameras, solve_ba_gtsam, solve_ba_scipy
from amrvio.estimator.local_mapping import Segment
from amrvio.estimator.mapper import BAReport, Mapper, MapperConfig, TriangulationReport
from amrvio.estimator.vo_map import PointTable
from amrvio.frontend.tracking_types import Observations
from amrvio.geometry.ground_plane import PlaneStatus
from amrvio.geometry.projection import project
from amrvio.pipeline.composer import AnchorBook, AnchorKind, PoseAnchor, RefineGates, TrajectoryComposer
from amrvio.pipeline.records import PoseStatus
from amrvio.types.lie import SE3, Sim3, se3_matrix

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
    np.testing.assert_allclose(mp.map.xyz[np.arange(n_good)], P[:n_good], rtol=1e-8)


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
        return rep, np.stack([k.T_cam_world for k in mp.map.keyframes]), mp.map.all_points()[1]

    rep0, T0, X0 = ba(None)
    rep1, T1, X1 = ba(3)
    assert rep0 == rep1 and np.array_equal(T0, T1) and np.array_equal(X0, X1)
    rep2, _, _ = ba(2)
    assert rep2.n_keyframes == 2 and rep2.n_observations < rep0.n_observations
    m = _mapper_with_window(0.3)[0].map
    m.retire_tracks(3)
    m.retire_tracks(4)  # never restores what is gone
    assert [len(k.track_ids) for k in m.keyframes] == [0, 0, 150, 150, 150] and m.n_retired == 2


def test_settled_frames_keep_the_pose_the_end_would_give_them() -> None:
    """The composer refines, during the run, the frames whose keyframe has left the window, and
    drops their observations; with the map as it is, the pose is the one the end of the run would
    compute; what moves in the map afterwards no longer reaches them."""
    mp, X = _mapper_with_window(0.3)
    mp.local_ba()
    seg = Segment(mp, Sim3.identity())
    rng = np.random.default_rng(4)
    gates = RefineGates(enabled=True, min_points=10, huber_px=2.0, max_median_px=2.0)
    anchors = []
    for k, kf in enumerate(mp.map.keyframes):
        T_cam_ref = SE3.exp(np.r_[0.02, -0.01, 0.05, 0.001, 0.002, 0.0]).matrix()
        uv, _ = project(K, T_cam_ref @ kf.T_cam_world, X)
        obs = Observations(np.arange(len(X), dtype=np.int64), uv + rng.normal(0, 0.3, uv.shape))
        T_off = SE3.exp(rng.normal(0, 0.003, 6)).matrix()  # the pose tracking gave: a little off
        anchors.append(PoseAnchor(PoseStatus.TRACKED, AnchorKind.KEYFRAME, 0, k, T_off @ T_cam_ref, obs))

    def composer() -> TrajectoryComposer:
        c = TrajectoryComposer(K, gates)
        for a in anchors:
            c.add(a)
        return c

    c_end, c_run = composer(), composer()
    c_run.settle([seg], keep_keyframes=2)  # keyframes 0-2 are 2 or more behind the newest (4)
    assert [a.kind for a in c_run.anchors] == [AnchorKind.ABSOLUTE] * 3 + [AnchorKind.KEYFRAME] * 2
    assert all(a.observations is None for a in c_run.anchors[:3]) and c_run.anchors[3].observations is not None
    T_end = c_end.finish([seg]).T_world_cam
    assert np.array_equal(c_run.finish([seg]).T_world_cam, T_end)
    # refined: closer to the truth than the tracked pose it started from
    for k, kf in enumerate(mp.map.keyframes[:3]):
        T_true = np.linalg.inv(SE3.exp(np.r_[0.02, -0.01, 0.05, 0.001, 0.002, 0.0]).matrix() @ kf.T_cam_world)
        T_tracked = np.linalg.inv(anchors[k].T_cam_ref @ kf.T_cam_world)
        assert np.linalg.norm(T_end[k][:3, 3] - T_true[:3, 3]) < np.linalg.norm(T_tracked[:3, 3] - T_true[:3, 3])
    # the map moves afterwards: the frames still anchored follow it, the settled ones do not
    ids = np.arange(len(X))
    mp.map.xyz[ids] = mp.map.xyz[ids] + np.array([0.2, 0.0, 0.0])
    T_end2, T_run2 = c_end.finish([seg]).T_world_cam, c_run.finish([seg]).T_world_cam
    assert not np.allclose(T_end2[:3], T_end[:3], atol=1e-3)
    assert np.array_equal(T_run2[:3], T_end[:3]) and np.array_equal(T_run2[3:], T_end2[3:])
    # a frame re-anchored after it was passed (a new map's initialisation) is settled again
    c_run.replace(1, anchors[1])
    c_run.settle([seg], keep_keyframes=2)
    assert c_run.anchors[1].kind is AnchorKind.ABSOLUTE and c_run.anchors[1].observations is None


def test_point_table_archive_reads_and_writes_as_a_dict_would() -> None:
    """PointTable against a plain dict over random writes, removals, reads and archivings; the
    archive keeps only ids with a point, and its memory is what those points take."""
    rng = np.random.default_rng(11)
    table, ref = PointTable(), {}
    for step in range(300):
        lo = max(0, 20 * step - 400)
        ids = np.unique(rng.integers(lo, 20 * step + 40, 30)).astype(np.int64)
        op = rng.integers(0, 4)
        if op == 0:
            X = rng.normal(size=(len(ids), 3))
            table.set(ids, X, True)
            ref.update({int(i): (x, True) for i, x in zip(ids, X, strict=True)})
        elif op == 1:
            table.set(ids, None, False)
            ref.update({int(i): (ref[int(i)][0], False) for i in ids if int(i) in ref})
        elif op == 2:
            table.archive_below(lo + int(rng.integers(0, 200)))
        q = np.unique(rng.integers(0, 20 * step + 60, 50)).astype(np.int64)
        want_has = np.array([int(i) in ref and ref[int(i)][1] for i in q])
        assert np.array_equal(table.has(q), want_has)
        got = table[q]
        for i, row, h in zip(q, got, want_has, strict=True):
            if h:
                assert np.array_equal(row, ref[int(i)][0])
    ids, X = table.all_points()
    want = sorted(i for i, (_, h) in ref.items() if h)
    assert ids.tolist() == want and np.array_equal(X, np.array([ref[i][0] for i in want]))
    assert table.base > 4000  # the archive took the old ids: the dense part is the recent ones
    n_old = int(np.sum(ids < table.base))
    assert table.nbytes < (table.end - table.base) * 25 + (n_old + 2000) * 33


def test_a_new_map_starts_at_its_first_track_and_a_finished_map_keeps_poses_and_points() -> None:
    """Track ids are global: a new map's table starts at its first track, not at id 0 (a lower id
    still reads and writes, in the archive). A finished map (``compact``) drops its keyframes'
    tracks and moves its points to the archive: every read is the same as before, and what it
    holds is the points (33 bytes each) and the poses."""
    t = PointTable()
    t.ensure_capacity(50_100, first=50_000)
    assert t.base == 50_000 and t.nbytes == 1024 * 25  # from 0 it would take 50 100 * 25 bytes
    t.set(np.array([49_990, 50_010]), np.array([[1.0, 2, 3], [4, 5, 6]]), True)
    assert np.array_equal(t[np.array([49_990, 50_010, 7])], [[1, 2, 3], [4, 5, 6], [0, 0, 0]])
    assert t.has(np.array([49_990, 50_010, 50_011])).tolist() == [True, True, False]
    t.ensure_capacity(70_000, first=60_000)  # no longer empty: where it starts stays
    assert t.base == 50_000
    m = _mapper_with_window(0.3)[0].map
    m.set_points(np.array([10_000]), np.array([[0.5, 0.5, 4.0]]))  # an id far past the others
    ids, X = m.all_points()
    q = np.arange(-5, 10_005, dtype=np.int64)
    has, got, poses = m.points_of(q), m.xyz[q], [k.T_cam_world.copy() for k in m.keyframes]
    assert len(m.keyframes[-1].track_ids) > 0 and m.xyz.end - m.xyz.base > 10_000
    m.compact()
    assert np.array_equal(m.points_of(q), has) and np.array_equal(m.xyz[q], got)
    ids2, X2 = m.all_points()
    assert np.array_equal(ids2, ids) and np.array_equal(X2, X)
    assert all(np.array_equal(k.T_cam_world, T) for k, T in zip(m.keyframes, poses, strict=True))
    assert all(len(k.track_ids) == 0 == len(k.uv) for k in m.keyframes)
    assert m.xyz.nbytes == 33 * len(ids)


def _anchor_values(a: PoseAnchor) -> tuple[object, ...]:
    obs = None if a.observations is None else (a.observations.ids.tolist(), a.observations.uv.tolist())
    return (a.status, a.kind, a.segment, a.keyframe, a.T_cam_ref.tolist(), obs, a.ref_frame)


def test_anchor_book_gives_back_the_anchors_it_was_given() -> None:
    rng = np.random.default_rng(11)
    kinds = list(AnchorKind)
    given = []
    for i in range(300):  # past the first capacity (256): the columns grow once
        obs = Observations(rng.integers(0, 99, 4), rng.normal(size=(4, 2))) if i % 3 == 0 else None
        given.append(PoseAnchor(list(PoseStatus)[i % 4], kinds[i % len(kinds)],
                                None if i % 5 == 0 else i % 7, None if i % 2 else i // 2,
                                SE3.exp(rng.normal(size=6)).matrix(), obs, None if i % 4 else i + 1))
    book = AnchorBook()
    for a in given:
        book.append(a)
    assert len(book) == 300
    assert [_anchor_values(a) for a in book] == [_anchor_values(a) for a in given]
    assert _anchor_values(book[-1]) == _anchor_values(given[-1])
    assert [_anchor_values(a) for a in book[10:13]] == [_anchor_values(a) for a in given[10:13]]
    book[7] = given[3]  # replaced: its observations go, or come, with it
    assert _anchor_values(book[7]) == _anchor_values(given[3])
    book[3] = given[7]
    assert book[3].observations is None
    book[0].T_cam_ref[0, 3] = 99.0  # a value: changing the copy leaves the book alone
    assert book[0].T_cam_ref[0, 3] == given[0].T_cam_ref[0, 3]
    with pytest.raises(IndexError):
        book[300]
    with pytest.raises(ValueError, match="never negative"):
        book.append(dataclasses.replace(given[1], segment=-2))
    assert len(book) == 300  # nothing was added


def test_anchor_book_keeps_a_long_run_in_about_half_the_memory_of_a_list() -> None:
    """6000 settled frames (absolute poses, no observations), as a 20 min drive at 5 fps has:
    the list held a PoseAnchor and a 4x4 array a frame (2.1 MB), the book 168 bytes a frame (its
    columns grow by half: 6561 rows, 1.1 MB)."""
    T = SE3.exp(np.full(6, 0.1)).matrix()

    def held(store: list[PoseAnchor] | AnchorBook) -> int:
        tracemalloc.start()
        try:
            for _ in range(6000):
                store.append(PoseAnchor(PoseStatus.TRACKED, AnchorKind.ABSOLUTE, 0, None, T.copy()))
            return tracemalloc.get_traced_memory()[0]
        finally:
            tracemalloc.stop()

    as_list, as_book = held([]), held(AnchorBook())
    assert as_book < 0.6 * as_list
    assert as_book < 1.2e6


def test_gtsam_ba_eliminates_the_points_then_the_cameras_newest_first(monkeypatch: pytest.MonkeyPatch) -> None:
    # the fill of a camera eliminated before its points made the local BA's memory peak grow
    # in steps (amrvio.estimator.local_ba.points_then_newest_cameras); a window whose oldest,
    # fixed camera sees only a few of its points, as at those steps
    import gtsam

    from amrvio.estimator import local_ba

    prob, _, _ = _problem(0.3, seed=2)
    few = (prob.obs_cam != 0) | (prob.obs_point < 12)
    prob = dataclasses.replace(prob, obs_cam=prob.obs_cam[few], obs_point=prob.obs_point[few],
                               obs_px=prob.obs_px[few])

    used: list[list[int]] = []

    def spy(graph: gtsam.NonlinearFactorGraph, n: int) -> gtsam.Ordering:
        ordering = points_then_newest_cameras(graph, n)
        used.append([ordering.at(i) for i in range(ordering.size())])
        return ordering

    monkeypatch.setattr(local_ba, "points_then_newest_cameras", spy)
    out = solve_ba_gtsam(prob, 30)
    n_pts = len(prob.points)
    assert used == [list(range(n_pts)) + [n_pts + 4, n_pts + 3, n_pts + 2, n_pts + 1, n_pts]]
    # the same minimum as the independent NumPy Schur LM
    from amrvio.estimator.ba_schur import huber_cost, solve_ba_schur

    ref = solve_ba_schur(prob, 30)
    assert np.allclose(out.T_cam_world[:2], prob.T_cam_world[:2])
    assert abs(huber_cost(out.residual_px, 2.0) - huber_cost(ref.residual_px, 2.0)) < 1e-6 * huber_cost(ref.residual_px, 2.0)
    assert np.abs(out.T_cam_world - ref.T_cam_world).max() < 1e-6
