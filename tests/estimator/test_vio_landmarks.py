"""Landmark bookkeeping and multi-view triangulation of the VIO back-end against exact geometry."""

from __future__ import annotations

import numpy as np
import pytest

from amrvio.errors import ConfigError
from amrvio.estimator.vio_landmarks import LandmarkTracks, project_px, triangulate_tracks
from amrvio.estimator.vio_triangulate import (
    keyframe_due,
    keyframe_parallax_deg,
    landmark_prior_share,
    triangulate_pending,
)
from amrvio.estimator.vio_types import VisualConfig
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


def test_a_frame_that_sees_few_landmarks_is_a_keyframe_only_once_it_has_moved() -> None:
    """With fewer than ``min_tracked_landmarks`` in view, a keyframe needs the baseline that makes
    ``keyframe_parallax_deg`` (1 deg) at the typical depth (4 m: tan 1 deg * 4 m = 6.98 cm); an
    unknown depth takes any frame. With enough landmarks the parallax rule decides."""
    vis = VisualConfig()
    few = np.array([[0.0, 0.0, 4.0]] * (vis.min_tracked_landmarks - 1))
    c0 = np.zeros(3)
    assert not keyframe_due(few, c0, np.array([0.0698, 0.0, 0.0]), 4.0, vis)
    assert keyframe_due(few, c0, np.array([0.0699, 0.0, 0.0]), 4.0, vis)
    assert keyframe_due(few, c0, c0, None, vis)
    assert keyframe_due(np.zeros((0, 3)), c0, c0, None, vis)
    many = np.tile([[0.0, 0.0, 4.0]], (vis.min_tracked_landmarks, 1))
    b = 4.0 * np.tan(np.radians(1.0))  # the parallax at a point straight ahead: atan(b / 4) for a sideways b
    assert not keyframe_due(many, c0, np.array([0.99 * b, 0.0, 0.0]), None, vis)
    assert keyframe_due(many, c0, np.array([1.01 * b, 0.0, 0.0]), None, vis)


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


def test_weak_prior_share_is_the_depth_information_of_two_views() -> None:
    """The closed form of landmark_prior_share against the marginal depth variance of the
    3-D point computed from the numeric Jacobians of two pinhole projections."""
    f, sigma_px, parallax = 450.0, 1.0, 1.0
    z = 5.0
    b = 2 * z * np.tan(np.radians(parallax) / 2)  # two cameras whose rays meet at `parallax`
    X = np.array([0.0, 0.0, z])
    info = np.zeros((3, 3))
    for cx in (-b / 2, b / 2):
        T_wc = SE3(SO3.exp([0.0, 0.0, 0.0]), np.array([cx, 0.0, 0.0]))
        Kf = np.array([[f, 0.0, 320.0], [0.0, f, 240.0], [0.0, 0.0, 1.0]])
        J = np.zeros((2, 3))
        for i in range(3):
            d = np.zeros(3)
            d[i] = 1e-6
            J[:, i] = (project_px(Kf, T_wc, (X + d)[None])[0][0] - project_px(Kf, T_wc, (X - d)[None])[0][0]) / 2e-6
        info += J.T @ J / sigma_px**2
    u = (X - np.array([-b / 2, 0.0, 0.0])) / np.linalg.norm(X - np.array([-b / 2, 0.0, 0.0]))
    var_depth = u @ np.linalg.inv(info) @ u  # marginal, along the first camera's ray
    rng = float(np.linalg.norm(X - np.array([-b / 2, 0.0, 0.0])))
    for factor in (1.0, 3.0, 10.0):
        info_prior = 1.0 / (factor * rng) ** 2
        share = info_prior / (info_prior + 1.0 / var_depth)
        assert landmark_prior_share(factor, parallax, sigma_px, f) == pytest.approx(share, rel=0.02)
    assert landmark_prior_share(0.0, parallax, sigma_px, f) == 0.0
    # the default holds under 1 % of the depth information at the smallest parallax for a 376 px
    # wide image (f 229 px) and less for larger images
    assert landmark_prior_share(VisualConfig().landmark_prior_range, VisualConfig().min_parallax_deg, 1.0,
                                229.36) < 0.01


def _two_view_graph(prior_range: float, shift: np.ndarray) -> float:
    """The error of the graph triangulate_pending builds for one track seen by two keyframes,
    at values where the new landmark is moved by ``shift`` from its triangulation."""
    import gtsam

    from amrvio.estimator.vio_graph import make_camera, state_keys, sym
    from amrvio.estimator.vio_types import VisualObservations
    from amrvio.imu.propagation import to_gtsam_pose

    vis = VisualConfig(landmark_prior_range=prior_range)
    cam = make_camera(K, SE3.identity(), vis)
    X = np.array([0.3, -0.2, 4.0])
    cams = {0: SE3.identity(), 1: SE3(SO3.exp([0.0, 0.02, 0.0]), np.array([0.2, 0.0, 0.0]))}
    tracks = LandmarkTracks()
    uv = {k: project_px(K, T, X[None])[0][0] for k, T in cams.items()}
    tracks.observe_pending(5, 0, uv[0])
    tracks.observe_pending(5, 1, uv[1])
    graph, values = gtsam.NonlinearFactorGraph(), gtsam.Values()
    stamps: dict[int, float] = {}
    used: list[tuple[int, np.ndarray]] = []
    obs = VisualObservations(np.array([5]), uv[1][None])
    n = triangulate_pending(tracks, obs, 1, cams, {0: 0, 1: 1}, cam, vis, graph, values, stamps, used, 0.05)
    assert n == 1 and 5 in tracks.active
    np.testing.assert_allclose(values.atPoint3(sym("l", 0)), X, atol=1e-6)
    for k, T in cams.items():
        values.insert(state_keys(k)[0], to_gtsam_pose(T))
    moved = gtsam.Values(values)
    moved.update(sym("l", 0), X + shift)
    return float(graph.error(moved))


def test_a_triangulated_landmark_gets_the_weak_prior_of_its_range() -> None:
    shift = np.array([0.0, 0.0, 0.5])
    with_prior, without = _two_view_graph(3.0, shift), _two_view_graph(0.0, shift)
    sigma = 3.0 * np.linalg.norm([0.3, -0.2, 4.0])  # 3 ranges from the first camera (at the origin)
    assert with_prior - without == pytest.approx(0.5 * 0.25 / sigma**2, rel=1e-6)
    assert _two_view_graph(3.0, np.zeros(3)) == pytest.approx(0.0, abs=1e-9)  # it sits at the triangulation


def test_landmark_prior_range_must_be_a_non_negative_number() -> None:
    with pytest.raises(ConfigError, match="landmark_prior_range"):
        VisualConfig(landmark_prior_range=-1.0)
    with pytest.raises(ConfigError, match="landmark_prior_range"):
        VisualConfig(landmark_prior_range=float("nan"))


def test_observation_sigma_grows_with_the_age_of_its_landmark() -> None:
    """sigma(age) = pixel_sigma * sqrt(1 + age / track_age_sigma_frames): whitening a residual of
    that many pixels gives one standard deviation; age 0 and a factor of 0 keep the camera's own."""
    from amrvio.estimator.vio_graph import age_noise

    vis = VisualConfig(pixel_sigma_px=1.0, track_age_sigma_frames=10.0)
    for age in (5, 10, 30):
        sigma = float(np.sqrt(1.0 + age / 10.0))
        noise = age_noise(vis, age)
        assert noise is not None
        np.testing.assert_allclose(noise.whiten(np.array([sigma, 0.0])), [1.0, 0.0], rtol=1e-12)
    assert age_noise(vis, 0) is None
    assert age_noise(VisualConfig(track_age_sigma_frames=0.0), 30) is None


def test_track_age_sigma_frames_must_be_a_non_negative_number() -> None:
    with pytest.raises(ConfigError, match="track_age_sigma_frames"):
        VisualConfig(track_age_sigma_frames=-1.0)
    with pytest.raises(ConfigError, match="track_age_sigma_frames"):
        VisualConfig(track_age_sigma_frames=float("inf"))
