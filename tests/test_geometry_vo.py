"""Two-view, PnP, triangulation and ground plane on synthetic data with closed-form answers."""

from __future__ import annotations

import numpy as np
import pytest

from amrvio.errors import ShapeError
from amrvio.geometry.ground_plane import PlaneStatus, fit_ground_plane
from amrvio.geometry.pnp import PnPStatus, refine_pose_huber, solve_pnp
from amrvio.geometry.projection import pixels_to_normalized, project
from amrvio.geometry.triangulation import triangulate
from amrvio.geometry.two_view import TwoViewStatus, two_view_init
from amrvio.types.lie import se3_matrix, se3_matrix_inverse, so3_exp

K = np.array([[500.0, 0, 320.0], [0, 500.0, 240.0], [0, 0, 1]])


def _scene(n: int = 300, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return rng.uniform([-4, -3, 6], [4, 3, 14], (n, 3))


def _views(T21: np.ndarray, X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    u1, _ = project(K, np.eye(4), X)
    u2, _ = project(K, T21, X)
    return u1, u2


def test_two_view_recovers_rotation_and_translation_direction() -> None:
    X = _scene()
    R = so3_exp(np.array([0.02, -0.05, 0.01]))
    t = np.array([0.3, -0.05, -1.0])
    T21 = se3_matrix(R, t)
    u1, u2 = _views(T21, X)
    res = two_view_init(u1, u2, K)
    assert res.status is TwoViewStatus.OK
    assert np.abs(res.T_c2_c1[:3, :3] - R).max() < 1e-4
    assert np.abs(res.T_c2_c1[:3, 3] - t / np.linalg.norm(t)).max() < 1e-4
    # structure equals the truth up to the baseline scale
    s = np.linalg.norm(t)
    v = res.point_valid
    assert v.sum() > 250
    assert np.abs(res.points_c1[v] * s - X[v]).max() < 1e-3


def test_two_view_zero_parallax_is_typed_failure() -> None:
    X = _scene()
    u1, _ = _views(np.eye(4), X)
    res = two_view_init(u1, u1.copy(), K)
    assert res.status is TwoViewStatus.LOW_PARALLAX
    assert not res.ok


def test_two_view_pure_rotation_is_typed_failure() -> None:
    X = _scene()
    T21 = se3_matrix(so3_exp(np.array([0.0, 0.08, 0.02])), np.zeros(3))
    u1, u2 = _views(T21, X)
    res = two_view_init(u1, u2, K)
    assert res.status is TwoViewStatus.PURE_ROTATION


def test_two_view_too_few_points_and_bad_shapes() -> None:
    u = np.zeros((10, 2))
    assert two_view_init(u, u, K).status is TwoViewStatus.TOO_FEW_POINTS
    with pytest.raises(ShapeError):
        two_view_init(np.zeros((60, 3)), np.zeros((60, 3)), K)
    with pytest.raises(ShapeError):
        two_view_init(np.full((60, 2), np.nan), np.zeros((60, 2)), K)


def test_triangulation_is_exact_and_flags_points_behind() -> None:
    X = _scene(100)
    T1 = np.eye(4)
    T2 = se3_matrix(so3_exp(np.array([0.01, 0.03, 0.0])), np.array([-0.5, 0.0, 0.1]))
    x1 = pixels_to_normalized(project(K, T1, X)[0], K)
    x2 = pixels_to_normalized(project(K, T2, X)[0], K)
    tri = triangulate(T1, T2, x1, x2, min_parallax_deg=0.1, max_reproj_px=0.01, focal_px=500)
    assert tri.valid.all()
    assert np.abs(tri.points_world - X).max() < 1e-8
    # a point behind both cameras is not valid
    Xb = np.array([[0.0, 0.0, -5.0]])
    pc1 = Xb[:, :2] / Xb[:, 2:]
    pc2h = (Xb @ T2[:3, :3].T + T2[:3, 3])
    pc2 = pc2h[:, :2] / pc2h[:, 2:]
    tb = triangulate(T1, T2, pc1, pc2)
    assert not tb.in_front[0]


def test_pnp_exact_and_huber_refinement() -> None:
    X = _scene(200, seed=3)
    T = se3_matrix(so3_exp(np.array([0.1, -0.2, 0.05])), np.array([0.4, 0.2, -0.3]))
    u, _ = project(K, T, X)
    rng = np.random.default_rng(1)
    u_bad = u.copy()
    out = rng.choice(len(u), 30, replace=False)
    u_bad[out] += rng.uniform(20, 60, (30, 2))
    res = solve_pnp(X, u_bad, K, seed=0)
    assert res.status is PnPStatus.OK
    assert np.abs(res.T_cam_world - T).max() < 1e-6
    assert not res.inliers[out].any()
    T0 = se3_matrix(so3_exp(np.array([0.02, 0.0, -0.01])), np.array([0.05, 0.0, 0.02])) @ T
    Tr = refine_pose_huber(T0, X, u, K)
    assert np.abs(Tr - T).max() < 1e-8
    assert solve_pnp(X[:4], u[:4], K).status is PnPStatus.TOO_FEW_POINTS


@pytest.mark.parametrize("height", [1.65, 0.3])
def test_ground_plane_recovers_known_plane_and_height(height: float) -> None:
    rng = np.random.default_rng(5)
    # camera frame: y down; a plane tilted by -3 deg about x, 'height' below the camera
    R = so3_exp(np.array([np.radians(-3.0), 0.0, 0.0]))  # ground falls away
    n_down = R @ np.array([0.0, 1.0, 0.0])
    ground_xz = rng.uniform([-5, 2], [5, 30], (300, 2))
    e1 = R @ np.array([1.0, 0, 0])
    e2 = R @ np.array([0, 0, 1.0])
    G = height * n_down + ground_xz[:, :1] * e1 + ground_xz[:, 1:] * e2
    G += rng.normal(0, 0.002 * height, G.shape)
    clutter = rng.uniform([-5, -3, 2], [5, 0.5 * height, 30], (200, 3))
    res = fit_ground_plane(np.vstack([G, clutter]), seed=0)
    assert res.status is PlaneStatus.OK
    assert abs(res.height - height) < 0.01 * height
    assert np.degrees(np.arccos(abs(res.normal @ n_down))) < 0.5
    assert res.inliers[:300].mean() > 0.9


def test_ground_plane_typed_failure_without_points_below() -> None:
    pts = np.random.default_rng(0).uniform([-5, -3, 2], [5, -0.1, 30], (100, 3))
    assert fit_ground_plane(pts).status is PlaneStatus.TOO_FEW_POINTS


def test_invert_T_roundtrip() -> None:
    T = se3_matrix(so3_exp(np.array([0.3, -0.2, 0.1])), np.array([1.0, 2.0, 3.0]))
    assert np.allclose(se3_matrix_inverse(T) @ T, np.eye(4))


def _plane(n: int = 300, seed: int = 1) -> np.ndarray:
    """Points on the tilted plane z = 5 + 0.3 x (a wall seen at an angle)."""
    rng = np.random.default_rng(seed)
    xy = rng.uniform([-3, -2], [3, 2], (n, 2))
    return np.c_[xy, 5.0 + 0.3 * xy[:, 0]]


def test_two_view_planar_scene_uses_the_homography_and_recovers_the_motion() -> None:
    """A desk-like scene: 90 % of the points on one plane, 10 % on objects above it. The
    homography wins the model selection; the off-plane points pick the true one of its two
    decompositions; an exactly planar scene is reported AMBIGUOUS rather than guessed."""
    from amrvio.geometry.two_view import TwoViewModel

    X = _plane()
    X[::10, 2] -= np.random.default_rng(5).uniform(0.3, 1.0, len(X[::10]))
    R = so3_exp(np.array([0.01, -0.04, 0.02]))
    t = np.array([0.4, 0.1, -0.2])
    T21 = se3_matrix(R, t)
    rng = np.random.default_rng(3)
    u1, u2 = _views(T21, X)
    u2 = u2 + rng.normal(0, 0.3, u2.shape)
    res = two_view_init(u1, u2, K)
    assert res.status is TwoViewStatus.OK
    assert res.model is TwoViewModel.HOMOGRAPHY
    assert res.homography_ratio > 0.45
    ang = np.degrees(np.arccos(np.clip((np.trace(res.T_c2_c1[:3, :3].T @ R) - 1) / 2, -1, 1)))
    assert ang < 0.2
    assert res.T_c2_c1[:3, 3] @ (t / np.linalg.norm(t)) > 0.995
    v = res.point_valid
    assert v.sum() > 250
    # depths up to the baseline scale
    assert np.median(np.abs(res.points_c1[v, 2] * np.linalg.norm(t) / X[v, 2] - 1)) < 0.02
    u1p, u2p = _views(T21, _plane())
    flat = two_view_init(u1p, u2p + rng.normal(0, 0.3, u2p.shape), K)
    assert flat.status is TwoViewStatus.AMBIGUOUS


def test_two_view_general_scene_uses_the_essential_matrix() -> None:
    from amrvio.geometry.two_view import TwoViewModel

    X = _scene()
    T21 = se3_matrix(so3_exp(np.array([0.0, 0.03, 0.0])), np.array([0.5, 0.0, -0.3]))
    u1, u2 = _views(T21, X)
    res = two_view_init(u1, u2, K)
    assert res.ok and res.model is TwoViewModel.ESSENTIAL
    assert res.homography_ratio < 0.45


def test_two_view_parallax_gate_is_the_kth_largest_point_parallax() -> None:
    """A 1 deg gate: a short baseline fails with LOW_PARALLAX, a longer one passes, and the
    reported order statistic matches the true ray angles of the points."""
    X = _scene()
    for base, ok in ((0.05, False), (0.4, True)):
        t = np.array([base, 0.0, 0.0])
        u1, u2 = _views(se3_matrix(np.eye(3), t), X)
        res = two_view_init(u1, u2, K)
        c2 = -t
        r1, r2 = X, X - c2
        ang = np.degrees(np.arccos(np.sum(r1 * r2, 1) / np.linalg.norm(r1, axis=1)
                                   / np.linalg.norm(r2, axis=1)))
        kth = np.sort(ang)[::-1][49]
        assert res.ok is ok, (base, res.status)
        if ok:
            assert abs(res.parallax_deg - kth) < 0.02
        else:
            assert res.status is TwoViewStatus.LOW_PARALLAX


def test_two_view_pure_rotation_returns_the_rotation() -> None:
    X = _scene()
    R = so3_exp(np.array([0.0, 0.08, 0.02]))
    u1, u2 = _views(se3_matrix(R, np.zeros(3)), X)
    res = two_view_init(u1, u2, K)
    assert res.status is TwoViewStatus.PURE_ROTATION
    assert np.abs(res.T_c2_c1[:3, :3] - R).max() < 1e-9
    assert np.allclose(res.T_c2_c1[:3, 3], 0.0)


def test_two_view_tiny_forward_motion_over_a_floor_is_not_mistaken() -> None:
    """A ground robot 2.5 cm into its drive: floor points below and far points ahead. Every
    model fits at this baseline; the homography's other decomposition (moving along the floor
    normal) is as consistent as the truth, so the answer is AMBIGUOUS or the true motion, never
    the mirror one (seen on the simulator's turn-in-place: a wrong map from frame 1)."""
    rng = np.random.default_rng(7)
    floor = np.c_[rng.uniform(-2, 2, 900), np.full(900, 0.3), rng.uniform(1.0, 5.0, 900)]
    far = np.c_[rng.uniform(-8, 8, 100), rng.uniform(-3, 0.2, 100), rng.uniform(20, 40, 100)]
    X = np.vstack([floor, far])
    t = np.array([0.0, 0.0, -0.025])
    u1, u2 = _views(se3_matrix(np.eye(3), t), X)
    ok_in = (u1[:, 0] > 0) & (u1[:, 0] < 640) & (u1[:, 1] > 0) & (u1[:, 1] < 480)
    u2 = u2 + rng.normal(0, 0.3, u2.shape)
    res = two_view_init(u1[ok_in], u2[ok_in], K)
    if res.ok:
        assert res.T_c2_c1[:3, 3] @ np.array([0.0, 0.0, -1.0]) > 0.98
    else:
        assert res.status in (TwoViewStatus.AMBIGUOUS, TwoViewStatus.LOW_PARALLAX)
