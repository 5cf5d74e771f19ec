"""The VIO consistency checks (amrvio.estimator.vio_checks) on hand-made keyframe histories: a
clean one passes, each injected fault fails its own check, and too little data is SKIPPED."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from amrvio.errors import ConfigError
from amrvio.estimator.vio_checks import (
    CheckConfig,
    CheckName,
    CheckStatus,
    KeyframeCheckInput,
    check_bias_drift,
    check_keyframe,
    check_scale,
    scale_ratio,
)
from amrvio.imu.propagation import ImuBias, InertialState
from amrvio.types.lie import SE3, SO3
from amrvio.types.sensors import ImuNoise

NOISE = ImuNoise.euroc_adis16448()
CFG = CheckConfig()
BG = np.array([0.002, -0.003, 0.01])
BA = np.array([0.05, -0.02, 0.1])


def _state(t_s: float, p: np.ndarray, v: np.ndarray, bg: np.ndarray = BG, ba: np.ndarray = BA) -> InertialState:
    return InertialState(int(round(t_s * 1e9)), SE3(SO3.exp([0.0, 0.0, 0.1 * t_s]), p), v, ImuBias(bg, ba))


def _history(n: int = 11, dt: float = 0.1, speed: float = 1.0, scale: float = 1.0, start_s: float = 0.0,
             bias_rate: tuple[np.ndarray, np.ndarray] = (np.zeros(3), np.zeros(3))) -> list[KeyframeCheckInput]:
    """Frames moving at ``speed`` m/s along x. The IMU prediction of each displacement is exact;
    the optimised one is ``scale`` times it. Sigmas: 1 cm position, 2 cm/s velocity, 2 mm
    displacement, biases 1e-4 rad/s and 5e-3 m/s^2."""
    out = []
    p_opt = np.zeros(3)
    v = np.array([speed, 0.0, 0.0])
    for k in range(n):
        t = start_s + k * dt
        bg, ba = BG + bias_rate[0] * k * dt, BA + bias_rate[1] * k * dt
        p_pred = p_opt + v * dt if k else p_opt
        p_new = p_opt + scale * v * dt if k else p_opt
        out.append(KeyframeCheckInput(_state(t, p_pred, v, bg, ba), np.full(3, 0.01), np.full(3, 0.02), 0.002,
                                      _state(t, p_new, v, bg, ba), np.full(3, 1e-4), np.full(3, 5e-3), 0.7))
        p_opt = p_new
    return out


def test_clean_history_passes_every_check() -> None:
    report = check_keyframe(_history(), NOISE, CFG)
    assert report.ok and report.failed == () and report.summary() == "ok"
    assert all(r.status is CheckStatus.PASS for r in report.results)
    assert [r.name for r in report.results] == list(CheckName)


def test_a_position_jump_fails_state_jump_only() -> None:
    h = _history()
    cur = h[-1]
    moved = dataclasses.replace(cur.optimised, T_world_body=SE3(cur.optimised.T_world_body.rot,
                                                                cur.optimised.T_world_body.t + [0.0, 0.08, 0.0]))
    h[-1] = dataclasses.replace(cur, optimised=moved)
    report = check_keyframe(h, NOISE, CFG)
    # 8 cm sideways against max(5 cm, 6 * 1.7 cm): 0.08 / 0.104 -> passes; a 15 cm jump fails
    assert report.ok
    moved = dataclasses.replace(moved, T_world_body=SE3(moved.T_world_body.rot, moved.T_world_body.t + [0.0, 0.07, 0.0]))
    h[-1] = dataclasses.replace(cur, optimised=moved)
    report = check_keyframe(h, NOISE, CFG)
    assert report.failed == (CheckName.STATE_JUMP,)
    assert "optimised - IMU prediction" in report.summary()


def test_a_velocity_jump_fails_state_jump() -> None:
    """0.3 m/s against max(0.1, 6 * 3.5 cm/s)."""
    h = _history()
    cur = h[-1]
    h[-1] = dataclasses.replace(cur, optimised=dataclasses.replace(cur.optimised, v_world_m_s=cur.optimised.v_world_m_s
                                                                   + [0.0, 0.0, 0.3]))
    assert check_keyframe(h, NOISE, CFG).failed == (CheckName.STATE_JUMP,)


@pytest.mark.parametrize("scale", [1.2, 0.8])
def test_a_scale_error_fails_the_scale_check(scale: float) -> None:
    h = _history(scale=scale)
    r = scale_ratio(h)
    assert r.s == pytest.approx(scale) and r.path_m == pytest.approx(1.0)
    assert r.along_m == pytest.approx(scale - 1.0)
    assert r.sigma_m == pytest.approx(0.02)
    assert check_keyframe(h, NOISE, CFG).failed == (CheckName.SCALE,)


def test_a_small_correction_on_a_short_path_is_not_a_scale_error() -> None:
    """A slow platform (0.25 m/s) whose estimate vision moves by 5 mm per frame: |s - 1| = 0.2,
    but 5 cm over the window is within 3 sums of displacement sigmas (3 * 10 * 2 mm = 6 cm)."""
    h = _history(speed=0.25, scale=1.2)
    res = check_scale(h, CFG)
    assert res.status is CheckStatus.PASS
    assert res.value < 1.0


def test_the_scale_check_needs_a_path() -> None:
    res = check_scale(_history(speed=0.05, scale=1.5), CFG)  # 5 cm of path
    assert res.status is CheckStatus.SKIPPED and np.isnan(res.value)
    assert check_scale(_history(n=1), CFG).status is CheckStatus.SKIPPED


def test_the_checks_look_back_window_s_only() -> None:
    """A scale error in frames older than window_s does not count."""
    old = _history(n=11, scale=1.3)
    new = _history(n=11, start_s=2.0)
    shift = old[-1].optimised.T_world_body.t
    new = [dataclasses.replace(h, predicted=dataclasses.replace(
        h.predicted, T_world_body=SE3(h.predicted.T_world_body.rot, h.predicted.T_world_body.t + shift)),
        optimised=dataclasses.replace(h.optimised, T_world_body=SE3(h.optimised.T_world_body.rot,
                                                                    h.optimised.T_world_body.t + shift)))
        for h in new]
    assert check_scale(old, CFG).failed
    assert not check_scale(old + new, CFG).failed


def test_bias_beyond_the_specification_fails() -> None:
    h = _history()
    cur = h[-1]
    for bg, ba in [([0.0, 0.2, 0.0], BA), (BG, [0.0, 0.0, -0.7])]:
        st = dataclasses.replace(cur.optimised, bias=ImuBias(np.asarray(bg, float), np.asarray(ba, float)))
        h2 = h[:-1] + [dataclasses.replace(cur, optimised=st)]
        # the jump from the previous bias also breaks its random walk
        assert CheckName.BIAS_MAGNITUDE in check_keyframe(h2, NOISE, CFG).failed


def test_bias_moving_faster_than_its_random_walk_fails() -> None:
    """Over 1 s the ADIS16448 gyro bias walks 1.9e-5 rad/s (1 sigma) and both estimates compared
    are known to 1e-4: 6 sigma allow 8.6e-4 rad/s. A drift of 2e-4 rad/s per second passes, 2e-3
    fails."""
    slow = _history(bias_rate=(np.array([0.0, 0.0, 2e-4]), np.zeros(3)))
    fast = _history(bias_rate=(np.array([0.0, 0.0, 2e-3]), np.zeros(3)))
    assert check_bias_drift(slow, NOISE, CFG).status is CheckStatus.PASS
    res = check_bias_drift(fast, NOISE, CFG)
    assert res.status is CheckStatus.FAIL and res.value == pytest.approx(2e-3 / (6 * np.sqrt(1.9393e-5**2 + 2 * 1e-4**2)), rel=1e-3)
    accel = _history(bias_rate=(np.zeros(3), np.array([0.1, 0.0, 0.0])))
    assert check_bias_drift(accel, NOISE, CFG).status is CheckStatus.FAIL
    assert check_bias_drift(fast[:1], NOISE, CFG).status is CheckStatus.SKIPPED


@pytest.mark.parametrize(("rate", "status"), [(2e-3, CheckStatus.PASS), (4e-3, CheckStatus.FAIL)])
def test_a_bias_change_within_the_newest_estimates_uncertainty_is_no_drift(rate: float, status: CheckStatus) -> None:
    """The first estimate known to 1e-4 rad/s, the newest only to 5e-4 (a window that says little
    of the bias): 6 sigma of the difference allow 3.06e-3 rad/s in 1 s (6.1e-4 with the first's
    sigma alone), so 2e-3 passes and 4e-3 fails."""
    h = _history(bias_rate=(np.array([0.0, 0.0, rate]), np.zeros(3)))
    h[-1] = dataclasses.replace(h[-1], gyro_bias_sigma_rad_s=np.full(3, 5e-4))
    res = check_bias_drift(h, NOISE, CFG)
    assert res.status is status
    assert res.value == pytest.approx(rate / (6 * np.sqrt(1.9393e-5**2 + 1e-4**2 + 5e-4**2)), rel=1e-3)


def test_reprojection_rms_over_the_limit_fails_and_none_is_skipped() -> None:
    h = _history()
    h[-1] = dataclasses.replace(h[-1], reprojection_rms_px=4.5)
    assert check_keyframe(h, NOISE, CFG).failed == (CheckName.REPROJECTION,)
    h[-1] = dataclasses.replace(h[-1], reprojection_rms_px=None)
    rep = check_keyframe(h, NOISE, CFG)
    assert rep.ok and rep.result(CheckName.REPROJECTION).status is CheckStatus.SKIPPED


def test_check_config_rejects_nonsense() -> None:
    with pytest.raises(ConfigError, match="jump_sigma"):
        CheckConfig(jump_sigma=0.0)
    with pytest.raises(ConfigError, match="window_s"):
        CheckConfig(window_s=float("nan"))
    with pytest.raises(ValueError):
        check_keyframe([], NOISE, CFG)
