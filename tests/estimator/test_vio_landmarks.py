"""Landmark bookkeeping and multi-view triangulation of the VIO back-end against exact geometry."""

from __future__ import annotations

import numpy as np
import pytest

from amrvio.estimator.vio_landmarks import LandmarkTracks, project_px, triangulate_tracks
from amrvio.estimator.vio_triangulate import keyframe_parallax_deg
from amrvio.types.lie import SE3, SO3

K = np.array([[450.0, 0.0, 320.0], [0.0, 450.0, 240.0], [0.0, 0.0, 1.0]])


def _rays(X: np.ndarray, centers: np.ndarray) -> np.ndarray:
    d = X[None] - centers
    return d / np.linalg.norm(d, axis=1, keepdims=True)


def test_noise_free_rays_meet_at_the_point_and_give_the_parallax() -> None:
    rng = np.random.default_rng(0)
    pts = rng.uniform([-2, -2, 3], [2, 2, 8], size=(20, 3))
    centers, rays, track = [], [], []
    for t, X in enumerate(pts):
        c = rng.uniform(-0.3, 0.3, size=(2 + t % 4, 3))  # 2 to 5 views per track
        centers.append(c)
        rays.append(_rays(X, c))
        track += [t] * len(c)
    tri = triangulate_tracks(np.array(track), np.concatenate(centers), np.concatenate(rays), len(pts))
    assert tri.ok.all()
    np.testing.assert_allclose(tri.points_world, pts, atol=1e-9)
    for t, (X, c) in enumerate(zip(pts, centers, strict=True)):
        d = _rays(X, c)
        expect = np.degrees(np.arccos(np.clip(d @ d[-1], -1, 1)).max())
        assert tri.parallax_deg[t] == pytest.approx(expect, abs=1e-6)


def test_parallel_rays_are_not_triangulated() -> None:
    c = np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 0.0, 0.0]])
    d = np.array([[0.0, 0.0, 1.0], [0.0, 0.0, 1.0], [0.0, 0.0, 1.0], [0.0, 0.0, 1.0]])
    tri = triangulate_tracks(np.array([0, 0, 1, 1]), c, d, 2)
    assert not tri.ok.any() and np.isnan(tri.points_world).all()
    assert tri.parallax_deg == pytest.approx([0.0, 0.0])


def test_projection_is_the_pinhole_model() -> None:
    T_wc = SE3(SO3.exp([0.1, -0.2, 0.3]), np.array([0.5, -0.2, 0.1]))
    p_cam = np.array([[0.2, -0.1, 2.0], [-1.0, 0.5, 4.0]])
    uv, z = project_px(K, T_wc, T_wc.act(p_cam))
    np.testing.assert_allclose(z, p_cam[:, 2])
    np.testing.assert_allclose(uv, (p_cam[:, :2] / p_cam[:, 2:]) * 450.0 + [320.0, 240.0])


def test_keyframe_parallax_is_the_angle_the_baseline_makes_at_the_points() -> None:
    pts = np.array([[0.0, 0.0, 5.0], [0.0, 0.0, 10.0], [0.0, 0.0, 20.0]])
    b = 0.1
    # the median point is at 10 m: 2 atan(0.05 / 10) for a baseline centred under it
    ang = keyframe_parallax_deg(pts, np.array([-b / 2, 0, 0]), np.array([b / 2, 0, 0]))
    assert ang == pytest.approx(np.degrees(2 * np.arctan(0.05 / 10.0)))
    assert keyframe_parallax_deg(pts, np.zeros(3), np.zeros(3)) == 0.0
    assert keyframe_parallax_deg(np.zeros((0, 3)), np.zeros(3), np.ones(3)) == 0.0


def test_tracks_forget_what_left_the_window() -> None:
    tr = LandmarkTracks(seeds={7: np.ones(3)})
    tr.observe_pending(1, 3, np.array([1.0, 2.0]))
    tr.observe_pending(1, 5, np.array([1.5, 2.0]))
    tr.observe_pending(2, 4, np.array([3.0, 2.0]))
    tr.observe_pending(7, 5, np.array([3.0, 3.0]))
    key = tr.activate(7, 5)
    assert key == 0 and 7 not in tr.seeds and 7 not in tr.pending and tr.active[7].first_keyframe == 5
    assert tr.activate(1, 3) == 1
    tr.forget_before(5)
    assert 2 not in tr.pending  # only seen by keyframe 4
    assert 1 not in tr.active and 7 in tr.active  # landmark 1 left with its first keyframe (3)
