"""The motions of issue 9: start-in-turn, turn-in-place (wheeled robots that follow their heading)
and wall-scan (hand-held in front of a wall). Checked against finite differences of the poses and
against the geometry each one promises."""

from __future__ import annotations

import math

import numpy as np
import pytest

from amrvio.sim.imu_synth import GRAVITY_WORLD, synthesize_imu
from amrvio.sim.kinematics import MotionLayout, RateProfile
from amrvio.sim.motion import default_T_body_cam, make_motion
from amrvio.sim.scene import WALL_X_M, make_scene
from amrvio.sim.simulate import layout_for_scene
from amrvio.types.lie import so3_log

NEW_MOTIONS = [("room", "start-in-turn"), ("corridor", "start-in-turn"), ("room", "turn-in-place"),
               ("warehouse", "turn-in-place"), ("wall", "wall-scan")]


def _layout(scene: str) -> MotionLayout:
    return layout_for_scene(make_scene(scene, 0))


def _yaw(R: np.ndarray) -> np.ndarray:
    return np.unwrap(np.arctan2(R[:, 1, 0], R[:, 0, 0]))


@pytest.mark.parametrize(("scene", "kind"), NEW_MOTIONS)
def test_synthetic_imu_matches_finite_differences_of_the_poses(scene: str, kind: str) -> None:
    """Exact 200 Hz IMU vs central differences (step 1 ms) of the ground-truth poses around each
    sample: gyro from log(R(t-h)^T R(t+h)) / 2h, accelerometer from
    R(t)^T ((p(t+h) - 2 p(t) + p(t-h)) / h^2 - g)."""
    m = make_motion(kind, 10.0, _layout(scene), seed=2)
    syn = synthesize_imu(m, 200.0, None, None)
    t = syn.t_s[(syn.t_s > 0.01) & (syn.t_s < 9.99)]
    gyro = syn.imu.gyro_rad_s[(syn.t_s > 0.01) & (syn.t_s < 9.99)]
    accel = syn.imu.accel_m_s2[(syn.t_s > 0.01) & (syn.t_s < 9.99)]
    h = 1e-3
    s0, sp, sm = m.states(t), m.states(t + h), m.states(t - h)
    w_fd = so3_log(np.einsum("nji,njk->nik", sm.R_world_body, sp.R_world_body)) / (2 * h)
    acc_world = (sp.p_world - 2 * s0.p_world + sm.p_world) / h**2 - GRAVITY_WORLD
    f_fd = np.einsum("nji,nj->ni", s0.R_world_body, acc_world)
    # central differences are second order: errors ~ h^2 / 6 x the third derivative (< 1e-5 here)
    np.testing.assert_allclose(gyro, w_fd, atol=2e-5)
    np.testing.assert_allclose(accel, f_fd, atol=1e-4)
    assert np.abs(syn.imu.gyro_rad_s[:, 2]).max() > 0.3  # the motion does turn


@pytest.mark.parametrize(("scene", "kind"), NEW_MOTIONS)
def test_the_path_stays_in_the_free_floor_area(scene: str, kind: str) -> None:
    sc = make_scene(scene, 0)
    for seconds in (8.0, 30.0):
        p = make_motion(kind, seconds, layout_for_scene(sc), seed=1).states(
            np.linspace(0.0, seconds, 3001)).p_world
        assert np.all(p[:, :2] >= sc.free_xy_min) and np.all(p[:, :2] <= sc.free_xy_max), seconds


def test_robots_drive_along_their_heading() -> None:
    """No side slip: the body-frame velocity has no lateral or vertical part."""
    for kind in ("start-in-turn", "turn-in-place"):
        s = make_motion(kind, 20.0, _layout("room")).states(np.linspace(0.0, 20.0, 2001))
        v_body = np.einsum("nji,nj->ni", s.R_world_body, s.v_world)
        assert np.abs(v_body[:, 1:]).max() < 1e-12
        assert v_body[:, 0].min() >= -1e-12  # forwards only


def test_turn_in_place_turns_30_deg_about_the_axle_in_2_s() -> None:
    m = make_motion("turn-in-place", 8.0, _layout("room"))
    t = np.linspace(0.0, 8.0, 8001)
    s = m.states(t)
    speed = np.linalg.norm(s.v_world, axis=1)
    turning = np.abs(s.omega_body[:, 2]) > 1e-9
    t_turn = t[turning]
    assert t_turn[-1] - t_turn[0] == pytest.approx(2.0, abs=1e-2)  # the rate starts as 30 tau^2
    assert 2.0 <= t_turn[0] <= 3.0 and t_turn[-1] <= 8.0 - 2.0  # drives 2-3 s before, >= 2 s after
    assert speed[turning].max() < 1e-12  # the axle centre (body origin) does not move
    p_turn = s.p_world[turning]
    assert np.ptp(p_turn, axis=0).max() < 1e-12
    yaw = _yaw(s.R_world_body)
    assert yaw[turning][-1] - yaw[turning][0] == pytest.approx(math.radians(30.0), abs=1e-4)
    assert np.abs(s.omega_body[:, 2]).max() == pytest.approx(1.875 * math.radians(30.0) / 2.0, rel=1e-3)
    assert speed[t < t_turn[0] - 1.5].min() > 0.45 and speed[t > t_turn[-1] + 1.5].min() > 0.45
    # the camera, 0.1 m ahead of the axle, moves on a chord of 2 r sin(15 deg)
    T_bc = default_T_body_cam()
    i0, i1 = np.flatnonzero(turning)[[0, -1]]
    c0 = s.R_world_body[i0] @ T_bc.t + s.p_world[i0]
    c1 = s.R_world_body[i1] @ T_bc.t + s.p_world[i1]
    assert np.linalg.norm(c1 - c0) == pytest.approx(2 * 0.1 * math.sin(math.radians(15.0)), rel=1e-3)


@pytest.mark.parametrize("scene", ["room", "corridor"])
def test_start_in_turn_is_moving_and_turning_at_the_first_frame(scene: str) -> None:
    m = make_motion("start-in-turn", 12.0, _layout(scene))
    t = np.linspace(0.0, 12.0, 12001)
    s = m.states(t)
    speed = np.linalg.norm(s.v_world, axis=1)
    assert s.omega_body[0, 2] == pytest.approx(0.4)
    assert np.abs(s.omega_body[t <= 2.0, 2] - 0.4).max() < 1e-12  # held for 2 s
    assert 0.25 < speed[0] <= 0.3 + 1e-12 and speed.max() <= 0.5 + 1e-12
    yaw = _yaw(s.R_world_body)
    # the first turn (2 s at 0.4 rad/s, faded over 2 s) ends on the layout heading
    assert yaw[t == 4.0][0] - yaw[0] == pytest.approx(0.4 * 2.0 + 0.4 * 1.0, abs=1e-9)
    assert yaw[t == 4.0][0] == pytest.approx(_layout(scene).heading_rad, abs=1e-9)
    if scene == "corridor":  # then straight along the corridor
        assert np.abs(s.omega_body[t >= 4.0, 2]).max() < 1e-12
        assert np.abs(s.v_world[t >= 4.0, 1]).max() < 1e-12
    else:  # the room: a loop, the next corner turns by exactly 90 deg
        corner = (t >= 5.0) & (t <= 5.0 + 0.5 * math.pi / 0.4 + 2.0)
        assert yaw[corner][-1] - yaw[corner][0] == pytest.approx(math.pi / 2, abs=1e-9)


def test_rate_profile_value_is_the_integral_of_its_rate() -> None:
    sig = RateProfile((0.0, 1.0, 2.5, 3.0), (0.4, 0.4, -0.2, 0.0), value0=-1.0)
    t = np.linspace(-1.0, 4.0, 50001)
    v, r, dr = sig.eval(t)
    integ = v[0] + np.concatenate([[0.0], np.cumsum(0.5 * (r[1:] + r[:-1]) * np.diff(t))])
    np.testing.assert_allclose(v, integ, atol=1e-8)
    np.testing.assert_allclose(np.gradient(r, t)[1:-1], dr[1:-1], atol=1e-3)
    assert sig.eval(np.array([0.0]))[0][0] == -1.0


def test_wall_scan_keeps_the_wall_1_to_3_m_ahead_and_sweeps_along_it() -> None:
    m = make_motion("wall-scan", 30.0, _layout("wall"), seed=0)
    s = m.states(np.linspace(0.0, 30.0, 3001))
    T_bc = default_T_body_cam()
    cam = np.einsum("nij,j->ni", s.R_world_body, T_bc.t) + s.p_world
    axis = np.einsum("nij,j->ni", s.R_world_body, T_bc.R[:, 2])  # optical axis in the world
    dist = WALL_X_M - cam[:, 0]
    assert 1.0 < dist.min() and dist.max() < 3.0
    along_axis = dist / axis[:, 0]  # range to the wall along the optical axis
    assert np.all(axis[:, 0] > math.cos(math.radians(30.0))) and along_axis.max() < 3.3
    assert np.ptp(cam[:, 1]) > 2.0  # sideways sweep of +-1.2 m
    assert np.ptp(dist) > 1.2  # towards and away from the wall
