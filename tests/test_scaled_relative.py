"""scaled_relative_pose against a synthetic two-view scene with known motion: rotation and the
direction of travel from the tracks, the step's length from a few map points; outliers among
both; the failures (rotation only, too few points or tracks) as statuses."""

from __future__ import annotations

import numpy as np
import pytest

from amrvio.errors import ShapeError
from amrvio.geometry.scaled_relative import ScaledRelativeConfig, ScaledRelativeStatus, scaled_relative_pose
from amrvio.types.lie import so3_exp

F = 500.0


def _scene(seed: int, t_cur_prev: np.ndarray, rotvec: np.ndarray, n: int = 300, n_pts: int = 20,
           noise_px: float = 0.3) -> tuple[np.ndarray, ...]:
    """n points 3-20 m ahead of the previous camera, seen in both cameras (normalised, with
    pixel noise); the first ``n_pts`` of them are map points."""
    rng = np.random.default_rng(seed)
    z = rng.uniform(3.0, 20.0, n)
    P = np.column_stack([rng.uniform(-0.6, 0.6, n) * z, rng.uniform(-0.4, 0.4, n) * z, z])
    R = so3_exp(rotvec)
    Q = P @ R.T + t_cur_prev
    x1 = P[:, :2] / P[:, 2:3] + rng.normal(0.0, noise_px / F, (n, 2))
    x2 = Q[:, :2] / Q[:, 2:3] + rng.normal(0.0, noise_px / F, (n, 2))
    has = np.zeros(n, dtype=bool)
    has[:n_pts] = True
    return x1, x2, has, P, R


def _rot_err_deg(Ra: np.ndarray, Rb: np.ndarray) -> float:
    c = (np.trace(Ra.T @ Rb) - 1.0) / 2.0
    return float(np.degrees(np.arccos(np.clip(c, -1.0, 1.0))))


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_recovers_rotation_direction_and_length(seed: int) -> None:
    t = np.array([0.15, -0.02, 1.3])  # a car's 3-frame step at 10 Hz, turning
    x1, x2, has, P, R = _scene(seed, t, np.array([0.0, 0.06, 0.0]))
    res = scaled_relative_pose(x1, x2, has, P, F)
    assert res.status is ScaledRelativeStatus.OK
    assert _rot_err_deg(res.T_cur_prev[:3, :3], R) < 0.05
    assert np.linalg.norm(res.T_cur_prev[:3, 3] - t) < 0.02 * np.linalg.norm(t)
    assert res.scale == pytest.approx(np.linalg.norm(res.T_cur_prev[:3, 3]))
    assert res.point_inliers.sum() >= 18 and not res.point_inliers[~has].any()
    assert res.track_inliers.sum() >= 280


def test_outlier_tracks_and_wrong_map_points_are_left_out() -> None:
    t = np.array([0.05, 0.0, 1.0])
    x1, x2, has, P, R = _scene(3, t, np.array([0.01, -0.04, 0.02]), n_pts=24)
    rng = np.random.default_rng(9)
    bad_tracks = np.arange(100, 190)  # 30 % of the tracks jump anywhere
    x2[bad_tracks] += rng.uniform(-0.1, 0.1, (len(bad_tracks), 2))
    P = P.copy()
    P[:5] *= 1.6  # five map points with a depth 60 % too far: they vote for a longer step
    res = scaled_relative_pose(x1, x2, has, P, F)
    assert res.ok
    assert not res.track_inliers[bad_tracks].any() or res.track_inliers[bad_tracks].sum() < 5
    assert not res.point_inliers[:5].any()
    assert res.point_inliers[5:24].sum() >= 17
    assert np.linalg.norm(res.T_cur_prev[:3, 3] - t) < 0.02


def test_pure_rotation_is_low_parallax() -> None:
    x1, x2, has, P, _ = _scene(4, np.zeros(3), np.array([0.0, 0.08, 0.01]))
    res = scaled_relative_pose(x1, x2, has, P, F)
    assert res.status is ScaledRelativeStatus.LOW_PARALLAX
    assert res.flow_px < 2.0
    assert np.array_equal(res.T_cur_prev, np.eye(4))


def test_too_few_map_points_or_tracks() -> None:
    t = np.array([0.0, 0.0, 1.0])
    x1, x2, has, P, _ = _scene(5, t, np.zeros(3), n_pts=7)
    assert scaled_relative_pose(x1, x2, has, P, F).status is \
        ScaledRelativeStatus.TOO_FEW_SCALE_POINTS
    x1, x2, has, P, _ = _scene(5, t, np.zeros(3), n=40)
    assert scaled_relative_pose(x1, x2, has, P, F).status is ScaledRelativeStatus.TOO_FEW_TRACKS
    # the same 40 tracks pass with a lower gate
    cfg = ScaledRelativeConfig(min_tracks=30)
    assert scaled_relative_pose(x1, x2, has, P, F, cfg).ok


def test_same_seed_same_result_and_shapes_checked() -> None:
    x1, x2, has, P, _ = _scene(6, np.array([0.3, 0.0, 0.8]), np.array([0.0, 0.03, 0.0]))
    a = scaled_relative_pose(x1, x2, has, P, F)
    b = scaled_relative_pose(x1, x2, has, P, F)
    assert np.array_equal(a.T_cur_prev, b.T_cur_prev)
    assert np.array_equal(a.track_inliers, b.track_inliers)
    with pytest.raises(ShapeError):
        scaled_relative_pose(x1, x2[:-1], has, P, F)
