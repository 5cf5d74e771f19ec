"""The sliding-window VIO back-end (amrvio.estimator.vio_backend) on the simulator: exact motion,
an IMU with the ADIS16448's noise and bias walks (and biases of 0.01-0.02 rad/s, 0.05-0.1 m/s^2),
and landmark observations made by projecting random points on the walls of a box with the
ground-truth camera poses (0.5 px noise). Every test starts from the true state, as the VI
initialiser would hand it over."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable

import numpy as np
import pytest
from numpy.typing import NDArray

from amrvio.errors import ConfigError, ShapeError
from amrvio.estimator.vio_backend import VioBackend
from amrvio.estimator.vio_checks import CheckName
from amrvio.estimator.vio_types import (
    EstimateKind,
    VioConfig,
    VioInitialState,
    VioStatus,
    VisualConfig,
    VisualObservations,
)
from amrvio.imu.propagation import InertialState
from amrvio.sim.vio_scenario import K_EUROC, START_NS, RunLog, Scenario, make_scenario, run_frames, start
from amrvio.types.sensors import ImuData, ImuNoise

F64 = NDArray[np.float64]
NOISE = ImuNoise.euroc_adis16448()
GYRO_BIAS = (0.01, -0.02, 0.015)
ACCEL_BIAS = (0.05, -0.1, 0.08)


def _scenario(kind: str, seconds: float, seed: int = 1) -> Scenario:
    return make_scenario(kind, seconds, seed=seed, noise=NOISE, gyro_bias=GYRO_BIAS, accel_bias=ACCEL_BIAS)


@pytest.fixture(scope="module")
def handheld() -> tuple[Scenario, RunLog]:
    sc = _scenario("handheld", 12.0)
    return sc, run_frames(sc, start(sc), 0.0, 12.0)


@pytest.fixture(scope="module")
def forward_stop_turn() -> tuple[Scenario, RunLog]:
    """Without the initialiser's landmarks: the first ones need parallax, so the start (0.5 s at
    rest) is held by the IMU alone."""
    sc = _scenario("forward-stop-turn", 12.0)
    return sc, run_frames(sc, start(sc, seed_sigma_m=None), 0.0, 12.0)


def test_handheld_follows_the_ground_truth_and_recovers_the_biases(handheld: tuple[Scenario, RunLog]) -> None:
    """Measured: SE3 ATE 0.4 cm, largest error 0.9 cm; biases within 6e-5 rad/s and 0.012 m/s^2."""
    _, log = handheld
    assert all(r.estimate.status is VioStatus.OK and r.estimate.kind is EstimateKind.SMOOTHED for r in log.results)
    assert log.se3_ate_m() < 0.02
    assert log.position_errors_m().max() < 0.03
    end, truth = log.states[-1], log.truth[-1]
    np.testing.assert_allclose(end.bias.gyro_rad_s, truth.bias.gyro_rad_s, atol=1e-3)
    np.testing.assert_allclose(end.bias.accel_m_s2, truth.bias.accel_m_s2, atol=0.03)
    assert np.linalg.norm(end.v_world_m_s - truth.v_world_m_s) < 0.03
    assert (end.T_world_body.rot.inverse() @ truth.T_world_body.rot).angle() < np.radians(0.5)


def test_clean_data_passes_the_consistency_checks(handheld: tuple[Scenario, RunLog],
                                                  forward_stop_turn: tuple[Scenario, RunLog]) -> None:
    for _, log in (handheld, forward_stop_turn):
        assert log.failed_checks() == []
        rms = [r.visual.rms_px for r in log.results if r.visual.rms_px is not None]
        assert len(rms) > 0.9 * len(log.results) and max(rms) < 1.5  # 0.5 px noise: ~0.6 px


def test_the_reported_sigma_covers_the_error(handheld: tuple[Scenario, RunLog],
                                             forward_stop_turn: tuple[Scenario, RunLog]) -> None:
    for _, log in (handheld, forward_stop_turn):
        z = [np.abs(s.T_world_body.t - g.T_world_body.t) / r.estimate.position_sigma_m
             for s, g, r in zip(log.states, log.truth, log.results, strict=True)
             if r.estimate.position_sigma_m is not None]
        assert len(z) == len(log.results)
        assert np.mean(np.array(z) < 3.0) > 0.95


def test_forward_stop_turn_keeps_its_keyframes_while_standing(forward_stop_turn: tuple[Scenario, RunLog]) -> None:
    """Measured: RMS error 0.67 cm (the path is a straight line, so no SE3 alignment), largest
    1.5 cm; 37 of 120 frames become keyframes, one while at rest: in the turn, when the landmarks
    in view fell to 27 (tracks that ended their landmarks at ``max_log_scale`` are not yet
    landmarks again); without that limit, 0.69 cm, 1.4 cm, 37 keyframes and none at rest."""
    sc, log = forward_stop_turn
    assert np.sqrt(np.mean(log.position_errors_m() ** 2)) < 0.02
    assert log.position_errors_m().max() < 0.06
    speed = np.array([np.linalg.norm(g.v_world_m_s) for g in log.truth])
    kf = np.array([r.keyframe for r in log.results])
    still = (speed < 1e-3) & (np.array(log.t_s) > 2.0)  # at rest after the first drive
    assert still.sum() > 20
    # no parallax keyframe at rest: one there only when too few landmarks are left in view
    seen = np.array([r.visual.n_used - r.visual.n_new_landmarks for r in log.results])
    assert (seen[still & kf] < VisualConfig().min_tracked_landmarks).all()
    assert kf[still].sum() <= 2
    assert 0.2 < kf.mean() < 0.8
    # landmarks keep holding the platform while it stands and turns
    used = np.array([r.visual.n_used for r in log.results])
    assert used[still].min() > 30


def test_window_holds_the_smoothed_keyframes() -> None:
    sc = _scenario("handheld", 4.0, seed=2)
    be = start(sc)
    run_frames(sc, be, 0.0, 3.0)
    win = be.window()
    assert 2 <= len(win) <= be.cfg.window_keyframes
    assert all(kf for _, kf in win[:-1])
    for st, _ in win:
        truth = sc.true_state((st.t_ns - sc.t_ns(0.0)) * 1e-9)
        assert np.linalg.norm(st.T_world_body.t - truth.T_world_body.t) < 0.02


def test_landmarks_agreeing_drops_those_a_track_puts_beyond_the_gate() -> None:
    """The smear's depths (issue 13) come from the window's landmarks less those a live track
    contradicts: with the true camera and noiseless pixels every observed landmark agrees; a
    track moved 15 px (beyond the 10 px gate) removes its landmark and only it; one moved 5 px
    does not; landmarks without a track stay."""
    sc = _scenario("handheld", 3.0, seed=2)
    be = start(sc)
    run_frames(sc, be, 0.0, 2.0)
    ids, X = be.landmarks()
    assert len(ids) > 20
    T_wc = sc.true_state(2.0).T_world_body @ sc.T_body_cam
    pc = (X - T_wc.t) @ T_wc.R
    uv = pc[:, :2] / pc[:, 2:] @ K_EUROC[:2, :2].T + K_EUROC[:2, 2]
    kept = be.landmarks_agreeing(T_wc, ids, uv)
    np.testing.assert_array_equal(kept, X)
    moved = uv.copy()
    moved[3] += (15.0, 0.0)
    moved[7] += (0.0, 5.0)
    kept = be.landmarks_agreeing(T_wc, ids, moved)
    np.testing.assert_array_equal(kept, np.delete(X, 3, axis=0))
    untracked = be.landmarks_agreeing(T_wc, ids[5:], moved[5:])  # landmark 3 has no track now
    np.testing.assert_array_equal(untracked, X)


# ------------------------------------------------------------------ bridging


def test_bridging_a_one_second_gap_with_the_imu() -> None:
    """Frames 6-7 s are lost: propagate() poses them from the IMU (BRIDGED), their error stays
    within 3 sigma of the propagated covariance and grows by less than 1.5 cm (measured: 0.2 ->
    0.8 cm, per-axis sigma 0.7-0.9 cm); afterwards the window picks up new landmarks and follows the truth again
    (largest error 0.3 cm)."""
    sc = _scenario("handheld", 10.0)
    be = start(sc)
    before = run_frames(sc, be, 0.0, 6.0)
    err0 = before.position_errors_m()[-1]
    for j in range(1, 21):
        t = 6.0 + 0.05 * j
        est = be.propagate(sc.t_ns(t), sc.imu_between(t - 0.05, t), bridged=True)
        assert est.ok and est.kind is EstimateKind.BRIDGED and est.state is not None
        assert est.since_smoothed_s == pytest.approx(0.05 * j)
        assert est.position_sigma_m is not None
        err = est.state.T_world_body.t - sc.true_state(t).T_world_body.t
        assert np.all(np.abs(err) < 3.0 * est.position_sigma_m)
    assert np.linalg.norm(err) - err0 < 0.015
    after = run_frames(sc, be, 7.0, 10.0)
    assert after.failed_checks() == []
    assert after.position_errors_m().max() < 0.03


def test_propagated_frames_between_smoothed_ones() -> None:
    """Frames that are not given to add_frame are PROPAGATED; a later add_frame still integrates
    from the newest smoothed frame."""
    sc = _scenario("forward-stop-turn", 5.0)
    be = start(sc)
    run_frames(sc, be, 0.0, 2.0)
    for t in (2.05, 2.1, 2.15):
        est = be.propagate(sc.t_ns(t), sc.imu_between(t - 0.05, t))
        assert est.kind is EstimateKind.PROPAGATED and est.state is not None
        assert np.linalg.norm(est.state.T_world_body.t - sc.true_state(t).T_world_body.t) < 0.03
    log = run_frames(sc, be, 2.0, 3.0, dt_s=0.2)
    assert log.position_errors_m().max() < 0.03


# ------------------------------------------------------------------ faults


def _with_imu(sc: Scenario, t_from_s: float, gyro: tuple[float, float, float] = (0.0, 0.0, 0.0),
              accel: tuple[float, float, float] = (0.0, 0.0, 0.0)) -> Scenario:
    imu = sc.syn.imu
    after = (imu.stamps_ns >= sc.t_ns(t_from_s))[:, None]
    new = ImuData(imu.stamps_ns, imu.gyro_rad_s + after * np.asarray(gyro), imu.accel_m_s2 + after * np.asarray(accel))
    return dataclasses.replace(sc, syn=dataclasses.replace(sc.syn, imu=new))


@pytest.mark.parametrize(("kind", "gyro", "accel"), [
    ("handheld", (0.0, 0.0, 0.0), (0.3, 0.0, 0.0)),
    ("forward-stop-turn", (0.0, 0.0, 0.02), (0.0, 0.0, 0.0)),
])
def test_an_injected_bias_jump_is_flagged(kind: str, gyro: tuple[float, float, float],
                                          accel: tuple[float, float, float]) -> None:
    """A step of 0.3 m/s^2 (100 sigma of the accel bias walk over 1 s) or 0.02 rad/s at 6 s:
    flagged within 1.5 s, by the bias-drift or scale check too, never before the step (measured:
    the accel step 1.3 s by the scale check, 1.4 s by the bias drift; the gyro step 1.0 s by the
    reprojection, 1.3 s by the bias drift)."""
    sc = _with_imu(_scenario(kind, 9.0), 6.0, gyro, accel)
    log = run_frames(sc, start(sc), 0.0, 8.5)
    flagged = [t for t, _ in log.failed_checks()]
    assert flagged, "the bias jump went unnoticed"
    assert min(flagged) > 6.0 and min(flagged) < 7.5
    drift = [t for t, r in zip(log.t_s, log.results, strict=True)
             if r.checks is not None and {CheckName.BIAS_DRIFT, CheckName.SCALE} & set(r.checks.failed)]
    assert drift and min(drift) < 7.5


@pytest.mark.parametrize("scale", [1.15, 0.85])
def test_an_initialiser_with_the_wrong_scale_is_flagged(scale: float) -> None:
    """The initialiser's landmarks and velocity scaled by 15 % about the camera: the IMU disagrees,
    and the checks say so within 3 s (measured 1.4-1.5 s; 1.7 s for 10 %), the scale check among
    them."""
    sc = _scenario("handheld", 6.0)
    t0 = 2.0
    truth = sc.true_state(t0)
    obs = sc.observe(t0)
    c0 = (truth.T_world_body @ sc.T_body_cam).t
    init = VioInitialState(InertialState(truth.t_ns, truth.T_world_body, scale * truth.v_world_m_s, truth.bias),
                           landmark_ids=obs.ids, landmarks_world=c0 + scale * (sc.points[obs.ids] - c0))
    log = run_frames(sc, start(sc, t0, init=init), t0, t0 + 3.0)
    flagged = log.failed_checks()
    assert flagged and flagged[0][0] < t0 + 3.0
    assert any("scale" in summary for _, summary in flagged)


def test_outlier_observations_are_gated_and_harmless() -> None:
    """5 % of the observations replaced by random pixels: they are gated out or down-weighted,
    and the trajectory stays within 2 cm (measured: 323 gated, 0.4 cm SE3 ATE)."""
    sc = _scenario("handheld", 6.0, seed=4)
    rng = np.random.default_rng(9)

    def observe(t: float) -> VisualObservations:
        obs = sc.observe(t)
        uv = obs.uv_px.copy()
        bad = rng.random(len(obs)) < 0.05
        uv[bad] = rng.uniform([0, 0], [752, 480], size=(int(bad.sum()), 2))
        return VisualObservations(obs.ids, uv)

    log = run_frames(sc, start(sc), 0.0, 6.0, observe=observe)
    assert sum(r.visual.n_gated for r in log.results) > 50
    assert log.se3_ate_m() < 0.02


def test_an_imu_gap_stops_the_backend_until_it_is_initialised_again() -> None:
    sc = _scenario("handheld", 5.0)
    be = start(sc)
    run_frames(sc, be, 0.0, 2.0)
    imu = sc.syn.imu
    keep = (imu.stamps_ns < sc.t_ns(2.02)) | (imu.stamps_ns > sc.t_ns(2.3))
    holed = ImuData(imu.stamps_ns[keep], imu.gyro_rad_s[keep], imu.accel_m_s2[keep])
    res = be.add_frame(sc.t_ns(2.5), holed.window(sc.t_ns(1.99), sc.t_ns(2.51)), sc.observe(2.5))
    assert res.estimate.status is VioStatus.IMU_GAP and res.estimate.state is None and res.checks is None
    assert not be.initialised
    assert be.propagate(sc.t_ns(2.6), sc.imu_between(2.5, 2.6)).status is VioStatus.NOT_INITIALISED
    assert be.add_frame(sc.t_ns(2.7), sc.imu_between(2.6, 2.7), sc.observe(2.7)).estimate.status \
        is VioStatus.NOT_INITIALISED
    assert be.initialise(sc.initial(3.0, 0.02), sc.imu_between(3.0, 3.1), sc.observe(3.0)).ok
    log = run_frames(sc, be, 3.0, 5.0)
    assert log.position_errors_m().max() < 0.02


# ------------------------------------------------------------------ determinism and input


def test_two_runs_give_identical_states() -> None:
    outs = []
    for _ in range(2):
        sc = _scenario("handheld", 2.5, seed=5)
        log = run_frames(sc, start(sc), 0.0, 2.5)
        outs.append(np.array([np.r_[s.T_world_body.t, s.v_world_m_s, s.bias.accel_m_s2] for s in log.states]))
    np.testing.assert_array_equal(outs[0], outs[1])


def test_bad_input_is_refused() -> None:
    sc = _scenario("handheld", 2.0)
    with pytest.raises(ShapeError, match="K must be"):
        VioBackend(VioConfig(), np.eye(2), sc.T_body_cam)
    with pytest.raises(ShapeError, match="twice"):
        VisualObservations(np.array([1, 2, 1]), np.zeros((3, 2)))
    with pytest.raises(ShapeError, match="finite"):
        VisualObservations(np.array([1]), np.array([[np.nan, 1.0]]))
    with pytest.raises(ShapeError):
        VisualObservations(np.array([1, 2]), np.zeros((3, 2)))
    with pytest.raises(ConfigError, match="window_keyframes"):
        VioConfig(window_keyframes=1)
    with pytest.raises(ConfigError, match="max_depth_m"):
        VisualConfig(min_depth_m=5.0, max_depth_m=1.0)
    with pytest.raises(ConfigError, match="imu_noise_scale"):
        VioConfig(imu_noise_scale=0.0)
    be = VioBackend(VioConfig(), K_EUROC, sc.T_body_cam)
    assert be.add_frame(START_NS, sc.imu_between(0, 0.1), sc.observe(0.1)).estimate.status \
        is VioStatus.NOT_INITIALISED
    be = start(sc)
    with pytest.raises(ShapeError, match="increase"):
        be.add_frame(sc.t_ns(0.0), sc.imu_between(0, 0.1), sc.observe(0.0))


def test_imu_noise_scale_multiplies_the_model() -> None:
    cfg = VioConfig(imu_noise_scale=5.0)
    m = cfg.imu_model()
    assert m.gyro_noise_density == pytest.approx(5 * NOISE.gyro_noise_density)
    assert m.accel_random_walk == pytest.approx(5 * NOISE.accel_random_walk)
    assert m.rate_hz == NOISE.rate_hz


def _sliding_tracks(sc: Scenario, px_per_log_scale: float) -> Callable[[float], VisualObservations]:
    """Observations whose track slides over the surface as the patch grows or shrinks, the way
    a translation-only KLT does: ``px_per_log_scale`` pixels per unit of |ln(distance at the
    first observation / distance now)|, each track in its own random direction."""
    rng = np.random.default_rng(3)
    first_range: dict[int, float] = {}
    direction: dict[int, F64] = {}

    def observe(t: float) -> VisualObservations:
        obs = sc.observe(t)
        T_wc = sc.true_state(t).T_world_body @ sc.T_body_cam
        r = np.linalg.norm(sc.points[obs.ids] - T_wc.t, axis=1)
        uv = obs.uv_px.copy()
        for j, i in enumerate(obs.ids.tolist()):
            r0 = first_range.setdefault(i, float(r[j]))
            if i not in direction:
                a = rng.uniform(0.0, 2.0 * np.pi)
                direction[i] = np.array([np.cos(a), np.sin(a)])
            uv[j] += px_per_log_scale * abs(np.log(r0 / r[j])) * direction[i]
        return VisualObservations(obs.ids, uv)

    return observe


def test_a_track_beyond_the_range_ratio_limit_starts_a_new_landmark() -> None:
    """Forward-stop-turn with tracks that slide 10 px per unit of log scale change. Measured
    (RMS position error over 8 s): 1.94 cm on clean tracks without the limit, 2.05 cm with it;
    with sliding tracks 3.27 cm without the limit (``max_log_scale`` 0) and 2.10 cm with it (0.2,
    the default), which ends 180 landmarks and triangulates 416 against 317."""

    def run(limit: float, px_per_log_scale: float) -> tuple[float, int]:
        sc = _scenario("forward-stop-turn", 8.0)
        cfg = VioConfig(visual=VisualConfig(max_log_scale=limit))
        log = run_frames(sc, start(sc, seed_sigma_m=None, config=cfg), 0.0, 8.0,
                         observe=_sliding_tracks(sc, px_per_log_scale))
        errors = log.position_errors_m()
        return float(np.sqrt(np.mean(errors ** 2))), sum(r.visual.n_new_landmarks for r in log.results)

    assert VisualConfig().max_log_scale == 0.2
    clean, _ = run(0.0, 0.0)
    without, new_without = run(0.0, 10.0)
    with_limit, new_with = run(0.2, 10.0)
    assert new_with > new_without + 50
    assert without > 1.4 * clean
    assert with_limit < 1.25 * clean
    with pytest.raises(ConfigError, match="max_log_scale"):
        VisualConfig(max_log_scale=-0.1)


def test_the_smoother_reuses_the_slots_of_removed_factors() -> None:
    """Each frame adds factors and removes about as many (its projection factors at the next
    frame, the marginalised ones); iSAM2 keeps a slot for every factor ever added unless it
    reuses them. Measured: 2317 slots for 1713 factors after 60 frames; 6519 slots for the same
    1713 factors without reuse."""
    sc = _scenario("handheld", 6.0, seed=3)
    be = start(sc)
    log = run_frames(sc, be, 0.0, 6.0)
    assert all(r.estimate.status is VioStatus.OK for r in log.results)
    slots, factors = be.factor_slots
    assert factors > 50
    assert slots <= 2 * factors
