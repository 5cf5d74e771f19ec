"""GTSAM linear solvers and orderings on monocular bundle adjustment (task H10).

Checks the brief's claim "MULTIFRONTAL is 20-40x slower than SEQUENTIAL_CHOLESKY on BA" on the
installed gtsam wheel. Problems mimic the VO's local BA (amrvio/estimator/local_ba.py): KITTI
pinhole, forward motion ~1 m per keyframe, points 5-50 m ahead, 1 px noise, 5 % outliers,
Huber(2 px) GenericProjectionFactorCal3_S2, first two poses held by NonlinearEqualityPose3.
Every (size, optimizer, solver, ordering) is timed on one core (median of repeats) and its final
error is compared with the best one found for that problem (all must reach the same optimum).

Run alone: ``.venv/bin/python -m bench.bench_ba_solvers [--quick]``.
"""

from __future__ import annotations

import os
import statistics
import sys
import time
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

F64 = NDArray[np.float64]
Row = dict[str, object]

# KITTI 00 left camera (seq 00 calib), image 1241 x 376.
FX, FY, CX, CY, W, H = 718.856, 718.856, 607.1928, 185.2157, 1241, 376
SOLVERS = ("MULTIFRONTAL_CHOLESKY", "MULTIFRONTAL_QR", "SEQUENTIAL_CHOLESKY", "SEQUENTIAL_QR",
           "CHOLMOD")
ORDERINGS = ("COLAMD", "METIS")
OPTIMIZERS = ("LM", "GN")


@dataclass(frozen=True, slots=True)
class Problem:
    """Synthetic BA window: true/initial poses T_world_cam (K, 4, 4), points (P, 3), observations."""

    name: str
    T_world_cam_true: F64
    T_world_cam_init: F64
    points_true: F64
    points_init: F64
    obs_cam: NDArray[np.int64]
    obs_point: NDArray[np.int64]
    obs_px: F64


def _rot(rng: np.random.Generator, sigma_rad: float) -> F64:
    w = rng.normal(0.0, sigma_rad, 3)
    th = float(np.linalg.norm(w))
    k = np.array([[0, -w[2], w[1]], [w[2], 0, -w[0]], [-w[1], w[0], 0]])
    if th < 1e-12:
        return np.eye(3) + k
    k /= th
    return np.eye(3) + np.sin(th) * k + (1 - np.cos(th)) * (k @ k)  # Rodrigues


def _project(T_world_cam: F64, X: F64) -> tuple[F64, F64]:
    R, t = T_world_cam[:3, :3], T_world_cam[:3, 3]
    pc = (X - t) @ R  # R^T (X - t)
    z = pc[:, 2]
    zs = np.where(np.abs(z) < 1e-9, 1e-9, z)
    return np.column_stack([FX * pc[:, 0] / zs + CX, FY * pc[:, 1] / zs + CY]), z


def make_problem(name: str, n_kf: int, n_pts: int, seed: int, clean: bool = True) -> Problem:
    """Forward-moving camera (z forward, 1 m +- 0.1 per keyframe, small yaw), tracks of 5-8
    consecutive keyframes, points 5-50 m ahead of the track's middle keyframe.

    ``clean=False`` gives a degenerate variant (no parallax check, independent outliers, coarse
    isotropic initial guess) in which a few low-parallax points cross behind a camera."""
    rng = np.random.default_rng(seed)
    T = np.tile(np.eye(4), (n_kf, 1, 1))
    yaw = 0.0
    for i in range(1, n_kf):
        yaw += rng.normal(0.0, 0.01)
        c, s = np.cos(yaw), np.sin(yaw)
        T[i, :3, :3] = np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])  # yaw about camera y (down)
        step = rng.normal(1.0, 0.1)
        T[i, :3, 3] = T[i - 1, :3, 3] + T[i, :3, :3] @ np.array([0.0, 0.0, step])
    pts: list[F64] = []
    cams: list[NDArray[np.int64]] = []
    pids: list[NDArray[np.int64]] = []
    uvs: list[F64] = []
    j = 0
    while j < n_pts:
        L = int(rng.integers(5, 9)) if n_kf > 5 else n_kf
        L = min(L, n_kf)
        s0 = int(rng.integers(0, n_kf - L + 1))
        mid = s0 + L // 2
        uv0 = rng.uniform([0, 0], [W, H])
        depth = rng.uniform(5.0, 50.0)
        pc = np.array([(uv0[0] - CX) / FX, (uv0[1] - CY) / FY, 1.0]) * depth
        X = T[mid, :3, :3] @ pc + T[mid, :3, 3]
        frames = np.arange(s0, s0 + L)
        uv = np.empty((L, 2))
        ok = True
        for a, f in enumerate(frames):
            p, z = _project(T[f], X[None])
            ok = ok and bool(z[0] > 2.0 and 0 <= p[0, 0] < W and 0 <= p[0, 1] < H)
            uv[a] = p[0]
        r0, r1 = X - T[s0, :3, 3], X - T[s0 + L - 1, :3, 3]
        cos_par = r0 @ r1 / (np.linalg.norm(r0) * np.linalg.norm(r1))
        if not ok or (clean and cos_par > np.cos(np.deg2rad(1.0))):  # a VO keeps only >= 1 deg parallax
            continue
        uv += rng.normal(0.0, 1.0, uv.shape)  # 1 px noise
        if not clean:  # 5 % outliers, independent
            out = rng.random(L) < 0.05
            ang, mag = rng.uniform(0, 2 * np.pi, L), rng.uniform(10.0, 50.0, L)
            uv[out] += (mag[:, None] * np.column_stack([np.cos(ang), np.sin(ang)]))[out]
        elif rng.random() < 0.05 * L:  # 5 % of observations are outliers, <= 1 per track,
            a = int(rng.integers(0, L))  # 10-50 px off
            a_ang, a_mag = float(rng.uniform(0, 2 * np.pi)), float(rng.uniform(10.0, 50.0))
            uv[a] += a_mag * np.array([np.cos(a_ang), np.sin(a_ang)])
        pts.append(X)
        cams.append(frames.astype(np.int64))
        pids.append(np.full(L, j, dtype=np.int64))
        uvs.append(uv)
        j += 1
    Xt = np.array(pts)
    T0 = T.copy()
    s_rot, s_t = (0.2, 0.02) if clean else (0.5, 0.05)
    for i in range(2, n_kf):  # VO-like initial guess: ~0.2 deg, ~2 cm off
        T0[i, :3, :3] = _rot(rng, np.deg2rad(s_rot)) @ T[i, :3, :3]
        T0[i, :3, 3] += rng.normal(0.0, s_t, 3)
    # triangulation-like point error: 3 % along the ray from the first observing keyframe,
    # ~1 px across it
    first = np.array([c[0] for c in cams])
    ray = Xt - T[first, :3, 3]
    d = np.linalg.norm(ray, axis=1, keepdims=True)
    X0 = (Xt + ray * rng.normal(0.0, 0.03, (len(Xt), 1))
          + rng.normal(0.0, 1.0, Xt.shape) * d / FX)
    if not clean:  # isotropic 3 % of the range from keyframe 0
        d0 = np.linalg.norm(Xt - T[0, :3, 3], axis=1)
        X0 = Xt + rng.normal(0.0, 1.0, Xt.shape) * (0.03 * d0)[:, None]
    return Problem(name, T, T0, Xt, X0, np.concatenate(cams), np.concatenate(pids),
                   np.concatenate(uvs))


def build_graph(prob: Problem) -> tuple[Any, Any, list[int], list[int]]:
    """Graph as in local_ba.solve_ba_gtsam: robust projection factors + equality on poses 0, 1."""
    import gtsam

    cal = gtsam.Cal3_S2(FX, FY, 0.0, CX, CY)
    noise = gtsam.noiseModel.Robust.Create(gtsam.noiseModel.mEstimator.Huber.Create(2.0),
                                           gtsam.noiseModel.Isotropic.Sigma(2, 1.0))
    graph = gtsam.NonlinearFactorGraph()
    values = gtsam.Values()
    xk = [gtsam.symbol("x", i) for i in range(len(prob.T_world_cam_init))]
    lk = [gtsam.symbol("l", j) for j in range(len(prob.points_init))]
    for i, Ti in enumerate(prob.T_world_cam_init):
        pose = gtsam.Pose3(Ti)
        values.insert(xk[i], pose)
        if i < 2:
            graph.add(gtsam.NonlinearEqualityPose3(xk[i], pose))
    for j, X in enumerate(prob.points_init):
        values.insert(lk[j], X)
    for c, p, uv in zip(prob.obs_cam.tolist(), prob.obs_point.tolist(), prob.obs_px, strict=True):
        graph.add(gtsam.GenericProjectionFactorCal3_S2(uv, noise, xk[c], lk[p], cal))
    return graph, values, xk, lk


def solve_once(graph: Any, values: Any, optimizer: str, solver: str, ordering: str,
               max_iterations: int = 100) -> tuple[float, int, float, Any]:
    """(seconds, iterations, final error, result Values) for one configuration."""
    import gtsam

    params: Any
    if optimizer == "LM":
        params = gtsam.LevenbergMarquardtParams()
    else:
        params = gtsam.GaussNewtonParams()
    params.setLinearSolverType(solver)
    params.setOrderingType(ordering)
    params.setMaxIterations(max_iterations)
    params.setRelativeErrorTol(1e-9)
    params.setAbsoluteErrorTol(1e-9)
    t0 = time.perf_counter()
    opt = (gtsam.LevenbergMarquardtOptimizer(graph, values, params) if optimizer == "LM"
           else gtsam.GaussNewtonOptimizer(graph, values, params))
    out = opt.optimize()
    dt = time.perf_counter() - t0
    return dt, int(opt.iterations()), float(graph.error(out)), out


def _pose_err_m(prob: Problem, out: Any, xk: list[int]) -> float:
    """Max camera-centre error (m) against ground truth (gauge fixed by poses 0, 1 up to scale)."""
    c = np.array([out.atPose3(k).translation() for k in xk])
    return float(np.max(np.linalg.norm(c - prob.T_world_cam_true[:, :3, 3], axis=1)))


def _row(name: str, value: float, unit: str, note: str) -> Row:
    return {"name": name, "value": float(value), "unit": unit, "note": note}


VO_ITERATIONS = 10  # local_ba.solve_ba_gtsam's default cap


def _ratio_rows(sname: str, res: dict[tuple[str, str, str], tuple[float, int, float, float]]
                ) -> list[Row]:
    rows: list[Row] = []
    for opt_name in OPTIMIZERS:
        for ordering in ORDERINGS:
            seq = res.get((opt_name, "SEQUENTIAL_CHOLESKY", ordering))
            for solver in ("MULTIFRONTAL_CHOLESKY", "MULTIFRONTAL_QR", "SEQUENTIAL_QR", "CHOLMOD"):
                other = res.get((opt_name, solver, ordering))
                if seq and other:
                    rows.append(_row(f"{sname}/{opt_name}/{ordering}/{solver}_over_SEQ_CHOL",
                                     other[0] / seq[0], "ratio",
                                     "time ratio; >1 means SEQUENTIAL_CHOLESKY is faster"))
        for solver in SOLVERS:
            c, me = res.get((opt_name, solver, "COLAMD")), res.get((opt_name, solver, "METIS"))
            if c and me:
                rows.append(_row(f"{sname}/{opt_name}/{solver}/METIS_over_COLAMD", me[0] / c[0],
                                 "ratio", "time ratio; >1 means COLAMD is faster"))
    return rows


def run(quick: bool) -> list[Row]:
    """Time every solver/ordering/optimizer on the BA sizes; one core, median of repeats.

    Timed runs use the VO's cap of 10 iterations (same iterates for every exact solver, so the
    final errors must agree); one extra LM run per size and solver family goes to convergence.
    """
    sizes = [("a_8kf", 8, 1000, True), ("b_20kf", 20, 3000, True), ("c_50kf", 50, 8000, True),
             ("d_8kf_degenerate", 8, 1000, False)]
    repeats = 1 if quick else 5
    if quick:
        sizes = [sizes[0], sizes[3]]
    pinned = hasattr(os, "sched_setaffinity")
    old_aff = os.sched_getaffinity(0) if pinned else set()
    if pinned:
        os.sched_setaffinity(0, {min(old_aff)})  # one core (gtsam/TBB threads inherit it)
    rows: list[Row] = []
    try:
        for sname, n_kf, n_pts, clean in sizes:
            prob = make_problem(sname, n_kf, n_pts, seed=10 + n_kf, clean=clean)
            graph, values, xk, _ = build_graph(prob)
            m = len(prob.obs_cam)
            rows.append(_row(f"{sname}/observations", m, "count",
                             f"{n_kf} keyframes, {n_pts} points, 5 % outliers, initial error "
                             f"{graph.error(values):.6g}"))
            res: dict[tuple[str, str, str], tuple[float, int, float, float]] = {}
            for opt_name in OPTIMIZERS:
                for solver in SOLVERS:
                    for ordering in ORDERINGS:
                        try:
                            times, it, err, out = [], 0, 0.0, None
                            for _ in range(repeats):
                                dt, it, err, out = solve_once(graph, values, opt_name, solver,
                                                              ordering, VO_ITERATIONS)
                                times.append(dt)
                            res[(opt_name, solver, ordering)] = (
                                statistics.median(times), it, err, _pose_err_m(prob, out, xk))
                        except Exception as exc:  # CHOLMOD not compiled in; GN on a singular system
                            msg = " ".join(str(exc).split())[:100]
                            rows.append(_row(f"{sname}/{opt_name}/{solver}/{ordering}/failed", 1.0,
                                             "flag", f"{type(exc).__name__}: {msg}"))
            best = min(v[2] for v in res.values())
            for (opt_name, solver, ordering), (t, it, err, perr) in res.items():
                key = f"{sname}/{opt_name}/{solver}/{ordering}"
                rows.append(_row(f"{key}/time", t * 1e3, "ms",
                                 f"median of {repeats}, one core; {it} iterations "
                                 f"({t * 1e3 / max(it, 1):.0f} ms/iter)"))
                rows.append(_row(f"{key}/final_error_rel", (err - best) / best, "ratio",
                                 f"(error - best)/best, best={best:.8g}; max camera error "
                                 f"{perr:.3f} m"))
            rows += _ratio_rows(sname, res)
            for solver in ("SEQUENTIAL_CHOLESKY", "MULTIFRONTAL_CHOLESKY"):  # to convergence
                t, it, err, out = solve_once(graph, values, "LM", solver, "COLAMD", 100)
                rows.append(_row(f"{sname}/LM/{solver}/COLAMD/converged_error", err, "error",
                                 f"{it} iterations, {t:.2f} s (1 run); max camera error "
                                 f"{_pose_err_m(prob, out, xk):.3f} m"))
            print(f"{sname}: done ({m} obs)", file=sys.stderr)
    finally:
        if pinned:
            os.sched_setaffinity(0, old_aff)
    return rows


if __name__ == "__main__":
    for r in run("--quick" in sys.argv):
        print(f"{r['name']:<60} {r['value']:>12.4g} {r['unit']:<6} {r['note']}")
