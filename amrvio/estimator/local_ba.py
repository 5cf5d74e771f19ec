"""Local sliding-window bundle adjustment with a Huber loss.

Two interchangeable back-ends on the same problem (chosen by measured speed, bench/bench_vo.py):
- ``solve_ba_scipy``: SciPy ``least_squares`` (TRF, Huber, analytic sparse Jacobian, LSMR);
- ``solve_ba_gtsam``: GTSAM Levenberg-Marquardt, SEQUENTIAL_CHOLESKY, robust projection factors.
Gauge: poses flagged ``fixed`` are held constant (fix two poses in monocular BA: 7 DoF).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from amrvio.errors import ShapeError
from amrvio.geometry._common import F64, se3_exp

I64 = NDArray[np.int64]


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
    """Optimised poses (K, 4, 4) and points (P, 3); ``residual_px`` (M,) final pixel errors."""

    T_cam_world: F64
    points: F64
    residual_px: F64
    iterations: int


def reprojection_errors(prob: BAProblem, T: F64, X: F64) -> tuple[F64, F64]:
    """(M, 2) residuals (projection - measurement) and (M,) depths."""
    R = T[prob.obs_cam, :3, :3]
    t = T[prob.obs_cam, :3, 3]
    pc = np.einsum("mij,mj->mi", R, X[prob.obs_point]) + t
    z = pc[:, 2]
    zs = np.where(np.abs(z) < 1e-9, 1e-9, z)
    K = prob.K
    u = K[0, 0] * pc[:, 0] / zs + K[0, 2]
    v = K[1, 1] * pc[:, 1] / zs + K[1, 2]
    return np.column_stack([u, v]) - prob.obs_px, z


def solve_ba_scipy(prob: BAProblem, max_iterations: int = 10) -> BAResult:
    """SciPy TRF with Huber loss; pose update T = exp(xi) T0 (left), analytic sparse Jacobian."""
    from scipy.optimize import least_squares
    from scipy.sparse import csr_matrix

    k = prob.T_cam_world.shape[0]
    free = np.flatnonzero(~prob.fixed)
    pose_col = -np.ones(k, dtype=np.int64)
    pose_col[free] = np.arange(len(free)) * 6
    n_pose = 6 * len(free)
    n_pts = len(prob.points)
    m = len(prob.obs_cam)
    T0 = prob.T_cam_world.copy()
    fx, fy = prob.K[0, 0], prob.K[1, 1]

    def unpack(x: F64) -> tuple[F64, F64]:
        T = T0.copy()
        for i, c in zip(free, pose_col[free], strict=True):
            T[i] = se3_exp(x[c : c + 6]) @ T0[i]
        return T, x[n_pose:].reshape(n_pts, 3)

    def fun(x: F64) -> F64:
        T, X = unpack(x)
        r, _ = reprojection_errors(prob, T, X)
        return r.ravel()

    rows = np.repeat(np.arange(2 * m).reshape(m, 2), 3, axis=1)  # (M, 2*3) pattern per block

    def jac(x: F64) -> csr_matrix:
        T, X = unpack(x)
        R = T[prob.obs_cam, :3, :3]
        pc = np.einsum("mij,mj->mi", R, X[prob.obs_point]) + T[prob.obs_cam, :3, 3]
        z = np.where(np.abs(pc[:, 2]) < 1e-9, 1e-9, pc[:, 2])
        iz = 1.0 / z
        Jp = np.zeros((m, 2, 3))
        Jp[:, 0, 0] = fx * iz
        Jp[:, 0, 2] = -fx * pc[:, 0] * iz * iz
        Jp[:, 1, 1] = fy * iz
        Jp[:, 1, 2] = -fy * pc[:, 1] * iz * iz
        Jx = Jp @ R  # d/d(point)
        Xc, Yc, Zc = pc[:, 0], pc[:, 1], pc[:, 2]
        Sk = np.zeros((m, 3, 3))  # -[pc]x
        Sk[:, 0, 1], Sk[:, 0, 2] = Zc, -Yc
        Sk[:, 1, 0], Sk[:, 1, 2] = -Zc, Xc
        Sk[:, 2, 0], Sk[:, 2, 1] = Yc, -Xc
        Jxi = np.concatenate([Jp, Jp @ Sk], axis=2)  # (M, 2, 6)
        pcol = pose_col[prob.obs_cam]
        has = pcol >= 0
        r_pose = np.repeat(np.arange(2 * m).reshape(m, 2)[has], 6, axis=1)
        c_pose = (pcol[has][:, None, None] + np.arange(6)[None, None, :]).repeat(2, axis=1)
        c_pt = (n_pose + 3 * prob.obs_point[:, None, None] + np.arange(3)[None, None, :]).repeat(
            2, axis=1)
        data = np.concatenate([Jxi[has].ravel(), Jx.ravel()])
        rr = np.concatenate([r_pose.ravel(), rows.ravel()])
        cc = np.concatenate([c_pose.ravel(), c_pt.ravel()])
        return csr_matrix((data, (rr, cc)), shape=(2 * m, n_pose + 3 * n_pts))

    x0 = np.concatenate([np.zeros(n_pose), prob.points.ravel()])
    res = least_squares(fun, x0, jac=jac, method="trf", loss="huber", f_scale=prob.huber_px,
                        tr_solver="lsmr", max_nfev=max_iterations, x_scale=1.0,
                        xtol=1e-10, ftol=1e-6)
    T, X = unpack(res.x)
    r, _ = reprojection_errors(prob, T, X)
    return BAResult(T, X, np.linalg.norm(r, axis=1), int(res.nfev))


def solve_ba_gtsam(prob: BAProblem, max_iterations: int = 10) -> BAResult:
    """GTSAM LM with SEQUENTIAL_CHOLESKY; Huber-robust GenericProjectionFactorCal3_S2."""
    import gtsam

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
    xk = [gtsam.symbol("x", i) for i in range(k)]
    lk = [gtsam.symbol("l", j) for j in range(n_pts)]
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
        values.insert(lk[j], prob.points[j])
    for c, p, uv in zip(prob.obs_cam.tolist(), prob.obs_point.tolist(), prob.obs_px,
                        strict=True):
        graph.add(gtsam.GenericProjectionFactorCal3_S2(uv, noise, xk[c], lk[p], cal))
    params = gtsam.LevenbergMarquardtParams()
    params.setLinearSolverType("SEQUENTIAL_CHOLESKY")
    params.setMaxIterations(max_iterations)
    params.setRelativeErrorTol(1e-6)
    opt = gtsam.LevenbergMarquardtOptimizer(graph, values, params)
    out = opt.optimize()
    T = np.empty_like(prob.T_cam_world)
    for i in range(k):
        Twc = out.atPose3(xk[i]).matrix()
        T[i] = np.eye(4)
        T[i, :3, :3] = Twc[:3, :3].T
        T[i, :3, 3] = -Twc[:3, :3].T @ Twc[:3, 3]
    X = np.array([out.atPoint3(lk[j]) for j in range(n_pts)]).reshape(n_pts, 3)
    r, _ = reprojection_errors(prob, T, X)
    return BAResult(T, X, np.linalg.norm(r, axis=1), int(opt.iterations()))


__all__ = ["BAProblem", "BAResult", "reprojection_errors", "solve_ba_gtsam", "solve_ba_scipy"]
