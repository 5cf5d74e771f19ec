"""The VO's camera motion for the translational smear (amrvio.diagnostics.vo_motion), against
closed forms: a camera moving at a known velocity past known points."""

from __future__ import annotations

import numpy as np
import pytest

from amrvio.diagnostics.vo_motion import HISTORY, MAX_POINTS, MotionHistory, motion_at_pose
from amrvio.types.camera import PinholeCamera

CAM = PinholeCamera(640, 480, 500.0, 500.0, 319.5, 239.5)
DT_NS = 100_000_000
V_WORLD = np.array([0.3, 0.0, 1.2])  # camera axes = world axes: the camera looks along +z


def _T_cam_world(t_s: float, jump: float = 0.0) -> np.ndarray:
    T = np.eye(4)
    T[:3, 3] = -(V_WORLD * t_s + [0.0, 0.0, jump])
    return T


def _points() -> np.ndarray:
    g = np.linspace(-2.0, 2.0, 7)
    x, y = np.meshgrid(g, g)
    return np.stack([x.ravel(), y.ravel(), np.full(x.size, 8.0)], axis=1)


def _history(n: int, poses: dict[int, np.ndarray]) -> MotionHistory:
    h = MotionHistory()
    for k in range(n):
        h.observe(k * DT_NS, k, segment=0)
        poses.setdefault(k, _T_cam_world(k * 0.1))
    return h


def test_constant_velocity_and_depths_are_recovered() -> None:
    poses: dict[int, np.ndarray] = {}
    h = _history(HISTORY, poses)
    t = (HISTORY - 1) * DT_NS
    m = h.camera_motion(t, poses.get, _points(), CAM)
    assert m is not None
    assert m.velocity_cam_m_s == pytest.approx(V_WORLD, abs=1e-9)
    z_now = 8.0 - V_WORLD[2] * (HISTORY - 1) * 0.1
    assert m.points_px is not None and len(m.depths_m) == len(m.points_px) > 8
    assert m.depths_m == pytest.approx(np.full(len(m.depths_m), z_now))


def test_poses_are_read_when_asked_not_when_observed() -> None:
    """Bundle adjustment moves frames after they were tracked: the motion uses the poses as
    ``pose_of`` gives them at the query, so a pose that was wrong when observed and has been
    corrected since does not enter."""
    poses: dict[int, np.ndarray] = {}
    h = _history(HISTORY, poses)
    wrong = dict(poses)
    wrong[HISTORY - 3] = _T_cam_world((HISTORY - 3) * 0.1, jump=0.2)
    t = (HISTORY - 1) * DT_NS
    ok = h.camera_motion(t, poses.get, _points(), CAM)
    assert ok is not None and ok.velocity_cam_m_s == pytest.approx(V_WORLD, abs=1e-9)
    # one interval jumps forward and the next back: both lie far off the line and are left out
    bad = h.camera_motion(t, wrong.get, _points(), CAM)
    assert bad is not None and bad.velocity_cam_m_s == pytest.approx(V_WORLD, abs=1e-9)
    # a plain least-squares line through them, evaluated at the frame, would not be
    vz = [(wrong[k][2, 3] - wrong[k + 1][2, 3]) / 0.1 for k in range(HISTORY - 1)]
    mids = np.arange(HISTORY - 1) + 0.5
    line = np.polyval(np.polyfit(mids, vz, 1), HISTORY - 1)
    assert abs(line - V_WORLD[2]) > 0.2


def test_a_gap_or_a_new_segment_restarts_the_history() -> None:
    """After a gap the history keeps only its last pose before it: the first frame after the
    gap gets the velocity across the gap, the next ones the new velocity."""
    poses: dict[int, np.ndarray] = {}
    h = _history(4, poses)  # frames 0..3 at V_WORLD
    # nothing tracked for 6 frame intervals (the camera covers 0.7 s x V_WORLD meanwhile), then
    # frames moving at twice the velocity
    for k in (10, 11):
        poses[k] = np.eye(4)
        poses[k][:3, 3] = -(V_WORLD * 0.3 + 0.7 * V_WORLD + 2.0 * V_WORLD * (k - 10) * 0.1)
        h.observe(k * DT_NS, k, segment=0)
        m = h.camera_motion(k * DT_NS, poses.get, _points(), CAM)
        across, new = V_WORLD, 2.0 * V_WORLD
        assert m is not None and m.velocity_cam_m_s == pytest.approx(across if k == 10 else new, abs=1e-9)
    # a frame of another map segment: no history to difference
    h.observe(12 * DT_NS, 12, segment=1)
    poses[12] = _T_cam_world(1.2)
    assert h.camera_motion(12 * DT_NS, poses.get, _points(), CAM) is None
    # too old: the last pose is more than two intervals back
    h2 = _history(HISTORY, {})
    assert h2.camera_motion((HISTORY + 2) * DT_NS, {k: _T_cam_world(k * 0.1) for k in range(HISTORY)}.get,
                            _points(), CAM) is None


def test_motion_at_pose_needs_points_in_view() -> None:
    T = _T_cam_world(0.0)
    v = np.array([0.0, 0.0, 1.0])
    assert motion_at_pose(T, _points(), CAM, v, None) is not None
    behind = _points() * [1.0, 1.0, -1.0]
    assert motion_at_pose(T, behind, CAM, v, None) is None
    assert motion_at_pose(T, _points()[:5], CAM, v, None) is None
    assert motion_at_pose(T, _points(), CAM, np.array([np.nan, 0.0, 0.0]), None) is None


def test_motion_at_pose_thins_the_points_in_view_not_all_points() -> None:
    # a window's landmarks after a turn: most are behind the camera, a few hundred in view; the
    # depths come from every point in view up to MAX_POINTS (thinning all points first kept
    # about a third of those in view)
    rng = np.random.default_rng(3)
    n_view = MAX_POINTS - 20
    seen = np.c_[rng.uniform(-2, 2, (n_view, 2)), rng.uniform(4, 12, n_view)]
    behind = np.c_[rng.uniform(-2, 2, (2 * MAX_POINTS, 2)), -rng.uniform(1, 10, 2 * MAX_POINTS)]
    pts = np.r_[behind[:MAX_POINTS], seen, behind[MAX_POINTS:]]
    motion = motion_at_pose(np.eye(4), pts, CAM, np.array([0.0, 0.0, 1.0]), None)
    assert motion is not None and motion.points_px is not None
    assert len(motion.depths_m) == n_view
    np.testing.assert_allclose(np.sort(motion.depths_m), np.sort(seen[:, 2]))
    many = np.r_[behind, np.c_[rng.uniform(-2, 2, (3 * MAX_POINTS, 2)), rng.uniform(4, 12, 3 * MAX_POINTS)]]
    thinned = motion_at_pose(np.eye(4), many, CAM, np.array([0.0, 0.0, 1.0]), None)
    assert thinned is not None and len(thinned.depths_m) == MAX_POINTS
