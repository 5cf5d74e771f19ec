"""Local BA (GTSAM back-end, SciPy back-end as a cross-check) and camera-height scale."""

from __future__ import annotations

import numpy as np

from amrvio.estimator.camera_height import HeightEstimate, estimate_height, smooth_scales
from amrvio.estimator.local_ba import BAProblem, solve_ba_gtsam, solve_ba_scipy
from amrvio.geometry.ground_plane import PlaneStatus
from amrvio.geometry.projection import project
from amrvio.types.lie import SE3

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
