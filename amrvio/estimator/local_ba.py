"""Local sliding-window bundle adjustment with a Huber loss.

Interchangeable back-ends on the same problem (chosen by measured speed, bench/bench_vo.py):
- ``solve_ba_scipy``: SciPy ``least_squares`` (TRF, Huber, analytic sparse Jacobian, LSMR);
- ``solve_ba_gtsam``: GTSAM Levenberg-Marquardt, SEQUENTIAL_CHOLESKY (points, then cameras newest first),
  robust projection factors;
- ``estimator.ba_schur.solve_ba_schur``: the same LM in NumPy, points eliminated first.
Gauge: poses flagged ``fixed`` are held constant (fix two poses in monocular BA: 7 DoF).
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import Enum
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from amrvio.errors import ShapeError
from amrvio.geometry.projection import project, project_jacobian
from amrvio.types.lie import SE3

if TYPE_CHECKING:
    import gtsam

F64 = NDArray[np.float64]
I64 = NDArray[np.int64]


class BAStatus(Enum):
    """Outcome of one local bundle adjustment."""

    OK = "ok"
    TOO_FEW_POINTS = "too_few_points"  # fewer than the minimum points seen twice in the window
    TOO_FEW_KEYFRAMES = "too_few_keyframes"  # fewer than two keyframes observe those points
    SOLVER_FAILED = "solver_failed"  # the back-end raised (e.g. GTSAM indeterminant system)


@dataclass(frozen=True, slots=True)
class BAReport:
    """What one local BA did. Sizes of the problem, the solver's iterations, the RMS
    reprojection error (pixels, no robust loss) before and after (None when it did not run),
    and ``n_outliers``: points culled afterwards (large residual or behind a camera)."""

    status: BAStatus
    n_keyframes: int
    n_points: int
    n_observations: int = 0
    iterations: int = 0
    initial_rms_px: float | None = None
    final_rms_px: float | None = None
    n_outliers: int = 0

    @property
    def ok(self) -> bool:
        return self.status is BAStatus.OK


@dataclass(frozen=True, slots=True)
class BAProblem:
    """Poses ``T_cam_world`` (K, 4, 4), ``fixed`` (K,) bool, points (P, 3) world, observations
    ``obs_cam`` (M,) / ``obs_point`` (M,) indices with ``obs_px`` (M, 2) pinhole pixels."""

    T_cam_world: F64
    fixed: NDArray[np.bool_]
    points: F64
    obs_cam: I64
    obs_point: I64
    obs_px: F64
    K: F64
    huber_px: float = 2.0

    def __post_init__(self) -> None:
        k = self.T_cam_world.shape[0]
        if self.T_cam_world.shape != (k, 4, 4) or self.fixed.shape != (k,):
            raise ShapeError("T_cam_world must be (K, 4, 4) and fixed (K,)")
        m = self.obs_cam.shape[0]
        if self.obs_point.shape != (m,) or self.obs_px.shape != (m, 2):
            raise ShapeError("observation arrays must be (M,), (M,), (M, 2)")
        if m and (self.obs_cam.max() >= k or self.obs_point.max() >= len(self.points)):
            raise ShapeError("observation index out of range")


@dataclass(frozen=True, slots=True)
class BAResult:
    """Optimised poses (K, 4, 4) and points (P, 3); ``residual_px`` (M,) final pixel errors,
    ``initial_residual_px`` (M,) those of the starting point."""

    T_cam_world: F64
    points: F64
    residual_px: F64
    iterations: int
    initial_residual_px: F64


def reprojection_errors(prob: BAProblem, T: F64, X: F64) -> tuple[F64, F64]:
    """(M, 2) residuals (projection - measurement) and (M,) depths."""
    uv, z = project(prob.K, T[prob.obs_cam], X[prob.obs_point])
    return uv - prob.obs_px, z


def _pixel_errors(prob: BAProblem, T: F64, X: F64) -> F64:
    r, _ = reprojection_errors(prob, T, X)
    return np.asarray(np.linalg.norm(r, axis=1), dtype=np.float64)


def solve_ba_scipy(prob: BAProblem, max_iterations: int = 10) -> BAResult:
    """SciPy TRF with Huber loss; pose update T = exp(xi) T0 (left), analytic sparse Jacobian."""
    from scipy.optimize import least_squares
    from scipy.sparse import csr_matrix

    k = prob.T_cam_world.shape[0]
    free = np.flatnonzero(~prob.fixed)
    pose_col = np.zeros(k, dtype=np.int64)  # first column of each free pose
    pose_col[free] = np.arange(len(free)) * 6
    n_pose = 6 * len(free)
    n_pts = len(prob.points)
    m = len(prob.obs_cam)
    T0 = prob.T_cam_world.copy()

    def unpack(x: F64) -> tuple[F64, F64]:
        T = T0.copy()
        for i, c in zip(free, pose_col[free], strict=True):
            T[i] = SE3.exp(x[c : c + 6]).matrix() @ T0[i]
        return T, x[n_pose:].reshape(n_pts, 3)

    def fun(x: F64) -> F64:
        T, X = unpack(x)
        r, _ = reprojection_errors(prob, T, X)
        return r.ravel()

    rows = np.repeat(np.arange(2 * m).reshape(m, 2), 3, axis=1)  # (M, 2*3) pattern per block

    def jac(x: F64) -> csr_matrix:
        T, X = unpack(x)
        Jxi, Jx = project_jacobian(prob.K, T[prob.obs_cam], X[prob.obs_point])
        pcol = pose_col[prob.obs_cam]
        has = ~prob.fixed[prob.obs_cam]
        r_pose = np.repeat(np.arange(2 * m).reshape(m, 2)[has], 6, axis=1)
        c_pose = (pcol[has][:, None, None] + np.arange(6)[None, None, :]).repeat(2, axis=1)
        c_pt = (n_pose + 3 * prob.obs_point[:, None, None] + np.arange(3)[None, None, :]).repeat(
            2, axis=1)
        data = np.concatenate([Jxi[has].ravel(), Jx.ravel()])
        rr = np.concatenate([r_pose.ravel(), rows.ravel()])
        cc = np.concatenate([c_pose.ravel(), c_pt.ravel()])
        return csr_matrix((data, (rr, cc)), shape=(2 * m, n_pose + 3 * n_pts))

    initial = _pixel_errors(prob, prob.T_cam_world, prob.points)
    x0 = np.concatenate([np.zeros(n_pose), prob.points.ravel()])
    res = least_squares(fun, x0, jac=jac, method="trf", loss="huber", f_scale=prob.huber_px,
                        tr_solver="lsmr", max_nfev=max_iterations, x_scale=1.0,
                        xtol=1e-10, ftol=1e-6)
    T, X = unpack(res.x)
    return BAResult(T, X, _pixel_errors(prob, T, X), int(res.nfev), initial)


def points_then_newest_cameras(graph: gtsam.NonlinearFactorGraph, n_pts: int) -> gtsam.Ordering:
    """The elimination ordering of a BA graph whose keys below ``n_pts`` are points and the rest
    cameras, oldest first: every point in index order, then the cameras newest first.

    Eliminating a point leaves a dense factor over the cameras that see it; eliminating a camera
    before its points joins all of them. GTSAM's COLAMD (its default) took a camera that sees few
    points (a fixed one, or the newest) early now and then: at frames 443, 698 and 700 of
    bench_speed's 5 min drive its fill peaked 6-14 MiB above the resident set, at 2.5-4x the time,
    and those steps set the memory peak's growth. COLAMD with the cameras constrained last took
    them out, but ordered the cameras by its own rule, and where the oldest, fixed cameras see only
    7-28 of the points (frames 1526-1532 of the 20 min drive) it took those first and peaked 4-15
    MiB. This ordering, the one COLAMD itself chooses on most windows, peaked 0.0-1.2 MiB on all
    seven of those windows and 0.8 MiB at most over the 557 problems of the 5 min drive, at the
    same median time (dev runs, each heavy window in a fresh process)."""
    import gtsam

    ordering = gtsam.Ordering()
    keys = list(graph.keyVector())
    for key in keys:
        if key < n_pts:
            ordering.push_back(key)
    for key in reversed(keys):
        if key >= n_pts:
            ordering.push_back(key)
    return ordering


def solve_ba_gtsam(prob: BAProblem, max_iterations: int = 10) -> BAResult:
    """GTSAM LM with SEQUENTIAL_CHOLESKY (points, then cameras newest first); Huber-robust
    GenericProjectionFactorCal3_S2."""
    import gtsam

    initial = _pixel_errors(prob, prob.T_cam_world, prob.points)
    K = prob.K
    cal = gtsam.Cal3_S2(K[0, 0], K[1, 1], 0.0, K[0, 2], K[1, 2])
    noise = gtsam.noiseModel.Robust.Create(
        gtsam.noiseModel.mEstimator.Huber.Create(prob.huber_px),
        gtsam.noiseModel.Isotropic.Sigma(2, 1.0),
    )
    graph = gtsam.NonlinearFactorGraph()
    values = gtsam.Values()
    k = prob.T_cam_world.shape[0]
    n_pts = len(prob.points)
    # plain integer keys, points first then poses (the order symbols l* < x* had): they pass
    # gtsam.utilities' float64 key arrays exactly (< 2^53), so that the factors of a camera are
    # added in one C++ call
    xk = [n_pts + i for i in range(k)]
    for i in range(k):
        Ti = prob.T_cam_world[i]
        Twc = np.eye(4)
        Twc[:3, :3] = Ti[:3, :3].T
        Twc[:3, 3] = -Ti[:3, :3].T @ Ti[:3, 3]
        pose = gtsam.Pose3(Twc)
        values.insert(xk[i], pose)
        if prob.fixed[i]:
            graph.add(gtsam.NonlinearEqualityPose3(xk[i], pose))
    for j in range(n_pts):
        values.insert(j, prob.points[j])
    cam = prob.obs_cam
    starts = np.flatnonzero(np.r_[True, cam[1:] != cam[:-1]])
    for a, b in zip(starts, np.r_[starts[1:], len(cam)], strict=True):
        gtsam.utilities.insertProjectionFactors(
            graph, xk[int(cam[a])], prob.obs_point[a:b].astype(np.float64).reshape(-1, 1),
            np.ascontiguousarray(prob.obs_px[a:b].T), noise, cal)
    params = gtsam.LevenbergMarquardtParams()
    params.setLinearSolverType("SEQUENTIAL_CHOLESKY")
    params.setMaxIterations(max_iterations)
    params.setRelativeErrorTol(1e-6)
    params.setOrdering(points_then_newest_cameras(graph, n_pts))
    opt = gtsam.LevenbergMarquardtOptimizer(graph, values, params)
    out = opt.optimize()
    T = np.empty_like(prob.T_cam_world)
    for i in range(k):
        Twc = out.atPose3(xk[i]).matrix()
        T[i] = np.eye(4)
        T[i, :3, :3] = Twc[:3, :3].T
        T[i, :3, 3] = -Twc[:3, :3].T @ Twc[:3, 3]
    X = np.asarray(gtsam.utilities.extractPoint3(out), dtype=np.float64).reshape(n_pts, 3)
    return BAResult(T, X, _pixel_errors(prob, T, X), int(opt.iterations()), initial)


__all__ = ["BAProblem", "BAReport", "BAResult", "BAStatus", "points_then_newest_cameras", "reprojection_errors",
           "solve_ba_gtsam", "solve_ba_scipy"]
