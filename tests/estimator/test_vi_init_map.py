"""The MAP step of the VI initialisation: analytic Jacobians against finite differences of the
residuals along the state's own update (manifold steps), and Gauss-Newton on exact data."""

from __future__ import annotations

import numpy as np

from amrvio.estimator.vi_init_linear import ViProblem
from amrvio.estimator.vi_init_map import BLOCK, BiasPriors, MapState, NoiseModel, _linearise, _step, refine_map
from amrvio.imu.preintegration import preintegrate_between
from amrvio.sim.imu_synth import synthesize_imu
from amrvio.sim.motion import MotionLayout, default_T_body_cam, make_motion
from amrvio.types.lie import so3_exp
from amrvio.types.sensors import ImuNoise

NOISE = ImuNoise.euroc_adis16448()
SCALE = 2.5


def _problem(seed: int = 0) -> tuple[ViProblem, MapState]:
    """Exact synthetic hand-held motion, 10 keyframes at 10 Hz, VO = camera poses / SCALE; the
    true state."""
    motion = make_motion("handheld", 2.0, MotionLayout(free_length_m=10.0), seed=seed)
    bg, ba = np.array([0.01, -0.02, 0.03]), np.array([0.05, 0.1, -0.08])
    syn = synthesize_imu(motion, 200.0, None, None, 0, bg, ba)
    t = np.arange(10) * 0.1
    st = motion.states(t)
    stamps = np.round(t * 1e9).astype(np.int64)
    T_bc = default_T_body_cam()
    R_wc = st.R_world_body @ T_bc.R
    c = (st.p_world + np.einsum("nij,j->ni", st.R_world_body, T_bc.t)) / SCALE
    pre = preintegrate_between(syn.imu, stamps, np.zeros(3), np.zeros(3), NOISE)
    problem = ViProblem(st.R_world_body, c, np.asarray(T_bc.t), pre)
    truth = MapState(SCALE, np.array([0.0, 0.0, -9.81]), st.R_world_body, st.p_world, st.v_world, bg,
                     np.tile(ba, (10, 1)))
    assert R_wc.shape == (10, 3, 3)
    return problem, truth


def _stacked(problem: ViProblem, st: MapState) -> np.ndarray:
    r_rot, r_pos, _, r_imu, _ = _linearise(problem, st)
    return np.concatenate([r_rot.reshape(-1), r_pos.reshape(-1), r_imu.reshape(-1)])


def test_jacobians_match_finite_differences() -> None:
    problem, truth = _problem()
    rng = np.random.default_rng(1)
    K = problem.n_keyframes
    # a point away from the truth, so that no residual is zero
    st = MapState(truth.scale * 1.05, so3_exp(np.array([0.02, -0.01, 0.0])) @ truth.gravity_vo,
                  np.einsum("nij,njk->nik", truth.R_vo_body, so3_exp(0.01 * rng.standard_normal((K, 3)))),
                  truth.p_vo + 0.01 * rng.standard_normal((K, 3)), truth.velocities_vo + 0.02 * rng.standard_normal((K, 3)),
                  truth.gyro_bias + 0.003, truth.accel_bias - 0.02 + 0.01 * rng.standard_normal((K, 3)))
    _, _, J_pos, _, J_imu = _linearise(problem, st)
    n = J_pos.shape[2]
    J_rot = np.zeros((3 * K, n))
    for k in range(K):
        J_rot[3 * k:3 * k + 3, 3 + BLOCK * k:6 + BLOCK * k] = np.eye(3)
    J = np.vstack([J_rot, J_pos.reshape(-1, n), J_imu.reshape(-1, n)])
    r0 = _stacked(problem, st)
    eps = 1e-6
    J_num = np.empty_like(J)
    for i in range(n):
        dx = np.zeros(n)
        dx[i] = eps
        J_num[:, i] = (_stacked(problem, _step(st, dx)) - _stacked(problem, _step(st, -dx))) / (2 * eps)
    # residuals are small: Jr^-1(r) ~ I and the first-order bias correction leave O(r) errors
    scale = np.maximum(np.abs(J_num).max(axis=0), 1e-9)
    assert np.max(np.abs(J - J_num) / scale) < 2e-2
    assert r0.shape[0] == J.shape[0]


def test_gauss_newton_returns_to_the_truth_on_exact_data() -> None:
    problem, truth = _problem(seed=2)
    K = problem.n_keyframes
    start = MapState(truth.scale * 0.9, so3_exp(np.array([0.03, 0.02, 0.0])) @ truth.gravity_vo,
                     problem.R_vo_body, truth.p_vo * 0.9, truth.velocities_vo * 0.9, np.zeros(3), np.zeros((K, 3)))
    pri = BiasPriors(np.zeros(3), np.full(3, 0.1), np.zeros(3), np.full(3, 0.5), NOISE.accel_random_walk)
    res = refine_map(problem, start, pri, NoiseModel(1e-10, 1e-10))
    assert abs(res.state.scale / SCALE - 1.0) < 1e-3
    np.testing.assert_allclose(res.state.gravity_vo, truth.gravity_vo, atol=5e-3)
    np.testing.assert_allclose(res.state.velocities_vo, truth.velocities_vo, atol=5e-3)
    np.testing.assert_allclose(res.state.gyro_bias, truth.gyro_bias, atol=1e-4)
    np.testing.assert_allclose(res.state.accel_bias, truth.accel_bias, atol=1e-2)  # measured 4e-3
    assert res.covariance.shape == (3 + BLOCK * K + 3,) * 2
