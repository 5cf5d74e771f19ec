"""Motions: analytic derivatives against finite differences, scene bounds, camera mount."""

from __future__ import annotations

import math

import numpy as np
import pytest

from amrvio.errors import ConfigError, ShapeError
from amrvio.sim.motion import (
    MOTION_KINDS,
    BlurBurst,
    MotionLayout,
    default_T_body_cam,
    make_motion,
    parse_blur_bursts,
)
from amrvio.types.lie import so3_log

CORRIDOR = MotionLayout(start_xy=(1.0, 0.0), heading_rad=0.0, free_length_m=35.0)
ROOM = MotionLayout(start_xy=(-2.0, -2.0), heading_rad=0.0, free_length_m=4.0, loop_side_m=4.0)


def _fd_check(motion, t: np.ndarray) -> None:
    h = 1e-5
    s0, sp, sm = motion.states(t), motion.states(t + h), motion.states(t - h)
    v_fd = (sp.p_world - sm.p_world) / (2 * h)
    a_fd = (sp.v_world - sm.v_world) / (2 * h)
    np.testing.assert_allclose(s0.v_world, v_fd, atol=1e-6)
    np.testing.assert_allclose(s0.a_world, a_fd, atol=1e-5)
    # omega_body = log(R(t-h)^T R(t+h)) / 2h (body-frame increment)
    dR = np.einsum("nji,njk->nik", sm.R_world_body, sp.R_world_body)
    w_fd = so3_log(dR) / (2 * h)
    np.testing.assert_allclose(s0.omega_body, w_fd, atol=1e-6)
    Rt_R = np.einsum("nji,njk->nik", s0.R_world_body, s0.R_world_body)
    np.testing.assert_allclose(Rt_R, np.broadcast_to(np.eye(3), Rt_R.shape), atol=1e-12)


@pytest.mark.parametrize("kind", MOTION_KINDS)
@pytest.mark.parametrize("layout", [CORRIDOR, ROOM], ids=["corridor", "room"])
def test_derivatives_match_finite_differences(kind: str, layout: MotionLayout) -> None:
    bursts = (BlurBurst(2.0, 0.6, 2.5),)
    m = make_motion(kind, 12.0, layout, seed=3, blur_bursts=bursts)
    t = np.random.default_rng(0).uniform(0.01, 11.99, size=300)
    _fd_check(m, t)


@pytest.mark.parametrize("kind", MOTION_KINDS)
def test_corridor_motion_stays_in_corridor(kind: str) -> None:
    m = make_motion(kind, 40.0, CORRIDOR, seed=1)
    s = m.states(np.linspace(0, 40.0, 4001))
    x, y, z = s.p_world.T
    assert x.min() >= CORRIDOR.start_xy[0] - 0.3
    assert x.max() <= CORRIDOR.start_xy[0] + CORRIDOR.free_length_m
    assert np.abs(y).max() < 0.8  # corridor is ~2.4 m wide
    assert z.min() > 0.2 and z.max() < 2.0
    travelled = np.linalg.norm(np.diff(s.p_world, axis=0), axis=1).sum()
    assert travelled > 3.0


def test_room_loop_is_a_square_inside_the_room() -> None:
    m = make_motion("forward-stop-turn", 40.0, ROOM, seed=0)
    s = m.states(np.linspace(0, 40.0, 4001))
    assert s.p_world[:, 0].min() >= -2.0 - 1e-9 and s.p_world[:, 0].max() <= 2.0 + 1e-9
    assert s.p_world[:, 1].min() >= -2.0 - 1e-9 and s.p_world[:, 1].max() <= 2.0 + 1e-9
    # one full loop (4 x 8 s cycles + 0.5 s dwell) returns to the start heading and position
    end = m.states(np.array([32.5]))
    np.testing.assert_allclose(end.p_world[0, :2], ROOM.start_xy, atol=1e-9)


def test_forward_stop_turn_has_rest_stops_and_turns_in_place() -> None:
    m = make_motion("forward-stop-turn", 16.0, CORRIDOR)
    s = m.states(np.linspace(0, 16.0, 1601))
    speed = np.linalg.norm(s.v_world, axis=1)
    yaw_rate = s.omega_body[:, 2]
    assert speed[:50].max() == 0.0  # rest at the start
    turning = np.abs(yaw_rate) > 0.05
    assert turning.any()
    assert speed[turning].max() < 1e-9  # turns happen in place
    assert np.abs(s.a_world[:, 0]).max() > 0.3  # real acceleration: scale excitation


def test_constant_velocity_is_constant() -> None:
    m = make_motion("constant-velocity", 10.0, CORRIDOR)
    s = m.states(np.linspace(0, 10.0, 101))
    np.testing.assert_allclose(s.v_world, np.broadcast_to(s.v_world[0], s.v_world.shape))
    assert np.abs(s.a_world).max() == 0.0 and np.abs(s.omega_body).max() == 0.0


def test_rough_floor_vibrates_in_pitch_and_roll() -> None:
    m = make_motion("rough-floor", 4.0, CORRIDOR, seed=2)
    t = np.arange(0, 4.0, 1e-3)
    s = m.states(t)
    pitch = -np.arcsin(s.R_world_body[:, 2, 0])
    assert 0.8 < np.degrees(np.abs(pitch).max()) < 2.5
    spec = np.abs(np.fft.rfft(s.omega_body[:, 1]))
    f = np.fft.rfftfreq(t.size, 1e-3)
    assert 8.0 <= f[np.argmax(spec)] <= 15.0


def test_blur_burst_reaches_its_peak_rate_only_inside_its_interval() -> None:
    base = make_motion("constant-velocity", 6.0, CORRIDOR)
    m = make_motion("constant-velocity", 6.0, CORRIDOR, blur_bursts=parse_blur_bursts("2:1:3.0"))
    t = np.linspace(0, 6.0, 60001)
    w = m.states(t).omega_body[:, 2] - base.states(t).omega_body[:, 2]
    assert np.abs(w[(t < 2.0) | (t > 3.0)]).max() == 0.0
    assert 0.85 * 3.0 < np.abs(w).max() <= 3.0 + 1e-9
    np.testing.assert_allclose(m.states(t).p_world, base.states(t).p_world)


def test_parse_blur_bursts_errors() -> None:
    assert parse_blur_bursts("") == ()
    assert parse_blur_bursts("1:0.5:2, 4:1:1") == (BlurBurst(1, 0.5, 2), BlurBurst(4, 1, 1))
    for bad in ("1:2", "a:b:c", "1:0:2", "1:nan:2"):
        with pytest.raises(ConfigError):
            parse_blur_bursts(bad)


def test_default_camera_looks_forward_and_down() -> None:
    T = default_T_body_cam(pitch_down_deg=10.0)
    z_cam_in_body = T.R[:, 2]
    np.testing.assert_allclose(
        z_cam_in_body, [math.cos(math.radians(10)), 0.0, -math.sin(math.radians(10))], atol=1e-12
    )
    np.testing.assert_allclose(T.R[:, 0], [0.0, -1.0, 0.0], atol=1e-12)  # image x = body right


def test_bad_inputs() -> None:
    with pytest.raises(ConfigError):
        make_motion("teleport", 5.0)
    with pytest.raises(ConfigError):
        make_motion("handheld", 0.0)
    m = make_motion("handheld", 5.0)
    with pytest.raises(ShapeError):
        m.states(np.array([[0.0, 1.0]]))
    with pytest.raises(ShapeError):
        m.states(np.array([np.nan]))


def test_scalar_accessors_agree_with_states() -> None:
    m = make_motion("handheld", 5.0, seed=4)
    s = m.states(np.array([1.7]))
    T = m.T_world_body(1.7)
    np.testing.assert_allclose(T.R, s.R_world_body[0], atol=1e-12)
    np.testing.assert_allclose(T.t, s.p_world[0])
    np.testing.assert_allclose(m.velocity_world(1.7), s.v_world[0])
    np.testing.assert_allclose(m.accel_world(1.7), s.a_world[0])
    np.testing.assert_allclose(m.omega_body(1.7), s.omega_body[0])


def test_replay_of_a_tum_file_follows_the_source_motion(tmp_path) -> None:
    from amrvio.io.trajectory import write_tum
    from amrvio.sim.replay import load_groundtruth, make_replay_motion
    from amrvio.types.lie import matrix_to_quat_wxyz
    from amrvio.types.trajectory import Trajectory

    src = make_motion("handheld", 8.0, CORRIDOR, seed=2)
    t = np.arange(0.0, 8.0 + 1e-9, 0.01)  # 100 Hz ground truth
    s = src.states(t)
    path = tmp_path / "gt.tum"
    write_tum(path, Trajectory(100.0 + t, s.p_world, matrix_to_quat_wxyz(s.R_world_body)))
    ns, p, q, bg, ba = load_groundtruth(path)
    assert bg is None and ba is None
    m = make_replay_motion(ns, p, q, start_s=2.0, duration_s=4.0)
    assert m.t0_ns == 102_000_000_000 and m.duration_s == 4.0
    tt = np.random.default_rng(1).uniform(0.0, 4.0, 400)
    r, ref = m.states(tt), src.states(tt + 2.0)
    assert np.abs(r.p_world - ref.p_world).max() < 1e-5
    assert np.abs(r.v_world - ref.v_world).max() < 2e-3
    assert np.abs(r.a_world - ref.a_world).max() < 0.05
    assert np.abs(r.omega_body - ref.omega_body).max() < 5e-3
    dR = np.einsum("nji,njk->nik", r.R_world_body, ref.R_world_body)
    assert np.linalg.norm(so3_log(dR), axis=1).max() < 1e-5
    _fd_check(m, tt[(tt > 0.01) & (tt < 3.99)])
    with pytest.raises(ConfigError):
        make_replay_motion(ns, p, q, start_s=2.0, duration_s=10.0)


def test_replay_smoothing_spline_reduces_position_noise() -> None:
    from amrvio.sim.replay import make_replay_motion
    from amrvio.types.lie import matrix_to_quat_wxyz

    src = make_motion("forward-stop-turn", 20.0, CORRIDOR)
    t = np.arange(0.0, 20.0 + 1e-9, 0.05)
    s = src.states(t)
    noisy = s.p_world + np.random.default_rng(0).normal(0.0, 0.003, s.p_world.shape)
    ns = np.round(t * 1e9).astype(np.int64)
    q = matrix_to_quat_wxyz(s.R_world_body)
    tt = np.linspace(2.0, 16.0, 500) + 0.0123  # off the 20 Hz knots (jerk jumps there)
    ref = src.states(tt + 1.0)
    raw = make_replay_motion(ns, noisy, q, 1.0, 17.0)
    smooth = make_replay_motion(ns, noisy, q, 1.0, 17.0, smoothing=1e-3)
    e_raw = np.abs(raw.states(tt).v_world - ref.v_world).max()
    e_smooth = np.abs(smooth.states(tt).v_world - ref.v_world).max()
    assert e_smooth < 0.5 * e_raw
    assert np.abs(smooth.states(tt).p_world - ref.p_world).max() < 0.01
    _fd_check(smooth, tt)
