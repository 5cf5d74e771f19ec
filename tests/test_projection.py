"""The one pinhole projection: against OpenCV, its Jacobian against finite differences, the
near-zero-depth rule and bad input."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from amrvio.errors import ShapeError
from amrvio.geometry.projection import (
    MIN_DEPTH,
    normalized_to_bearings,
    normalized_to_pixels,
    pixels_to_normalized,
    project,
    project_jacobian,
)
from amrvio.types.lie import SE3

K = np.array([[718.856, 0.0, 607.19], [0.0, 712.3, 185.2], [0.0, 0.0, 1.0]])


def _scene(seed: int, n: int = 40) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    T = SE3.exp(np.r_[rng.normal(0, 0.5, 3), rng.normal(0, 0.3, 3)]).matrix()
    p_cam = rng.uniform([-4, -3, 2], [4, 3, 30], (n, 3))
    return T, SE3.from_matrix(T).inverse().act(p_cam)


@pytest.mark.parametrize("seed", range(5))
def test_project_matches_cv2_project_points(seed: int) -> None:
    T, P = _scene(seed)
    uv, z = project(K, T, P)
    rvec, _ = cv2.Rodrigues(T[:3, :3])
    ref, _ = cv2.projectPoints(P, rvec, T[:3, 3], K, None)
    np.testing.assert_allclose(uv, ref.reshape(-1, 2), atol=1e-8)
    np.testing.assert_allclose(z, (P @ T[:3, :3].T + T[:3, 3])[:, 2], atol=1e-12)


def test_project_with_one_pose_per_point_equals_shared_pose() -> None:
    T, P = _scene(7)
    T2 = SE3.exp([0.3, -0.1, 0.2, 0.05, 0.02, -0.04]).matrix() @ T
    Ts = np.stack([T if i % 2 else T2 for i in range(len(P))])
    uv, z = project(K, Ts, P)
    uv1, z1 = project(K, T, P)
    uv2, z2 = project(K, T2, P)
    np.testing.assert_allclose(uv[1::2], uv1[1::2], atol=1e-9)
    np.testing.assert_allclose(uv[0::2], uv2[0::2], atol=1e-9)
    np.testing.assert_allclose(z[0::2], z2[0::2], atol=1e-12)


@pytest.mark.parametrize("batched", [False, True])
def test_project_jacobian_matches_central_differences(batched: bool) -> None:
    T, P = _scene(3, n=12)
    Tb = np.repeat(T[None], len(P), axis=0) if batched else T
    J_pose, J_point = project_jacobian(K, Tb, P)
    assert J_pose.shape == (12, 2, 6) and J_point.shape == (12, 2, 3)
    h = 1e-6
    for k in range(6):
        e = np.zeros(6)
        e[k] = h
        # left perturbation in the SE3 tangent of types/lie: [rho, phi]
        up = project(K, SE3.exp(e).matrix() @ T, P)[0]
        dn = project(K, SE3.exp(-e).matrix() @ T, P)[0]
        np.testing.assert_allclose(J_pose[:, :, k], (up - dn) / (2 * h), rtol=1e-5, atol=1e-4)
    for k in range(3):
        e = np.zeros(3)
        e[k] = h
        num = (project(K, T, P + e)[0] - project(K, T, P - e)[0]) / (2 * h)
        np.testing.assert_allclose(J_point[:, :, k], num, rtol=1e-5, atol=1e-4)


def test_near_zero_and_negative_depth_rule() -> None:
    T = np.eye(4)
    P = np.array([[1.0, 0.5, -2.0], [1.0, 0.5, 0.0], [1.0, 0.5, 0.5 * MIN_DEPTH], [1.0, 0.5, 2.0]])
    uv, z = project(K, T, P)
    np.testing.assert_array_equal(z, P[:, 2])  # the true depth comes back for the caller
    assert np.all(np.isfinite(uv))
    # at or behind the camera: divided by MIN_DEPTH, far outside any image, never mirrored
    expected_u = K[0, 0] * 1.0 / MIN_DEPTH + K[0, 2]
    np.testing.assert_allclose(uv[:3, 0], expected_u, rtol=1e-12)
    assert uv[3, 0] == pytest.approx(K[0, 0] * 0.5 + K[0, 2])
    J_pose, J_point = project_jacobian(K, T, P)
    assert np.all(np.isfinite(J_pose)) and np.all(np.isfinite(J_point))


def test_pixel_normalized_round_trip_and_bearings() -> None:
    rng = np.random.default_rng(1)
    px = rng.uniform([0, 0], [1241, 376], (50, 2))
    xn = pixels_to_normalized(px, K)
    ref = cv2.undistortPoints(px.reshape(-1, 1, 2), K, None).reshape(-1, 2)
    np.testing.assert_allclose(xn, ref, atol=1e-9)
    np.testing.assert_allclose(normalized_to_pixels(xn, K), px, atol=1e-9)
    b = normalized_to_bearings(xn)
    np.testing.assert_allclose(np.linalg.norm(b, axis=1), 1.0, atol=1e-12)
    np.testing.assert_allclose(b[:, :2] / b[:, 2:], xn, atol=1e-12)


@pytest.mark.parametrize(
    "T,P",
    [(np.eye(3), np.zeros((4, 3))), (np.eye(4), np.zeros((4, 2))), (np.zeros((3, 4, 4)), np.zeros((4, 3)))],
)
def test_bad_shapes_raise(T: np.ndarray, P: np.ndarray) -> None:
    with pytest.raises(ShapeError):
        project(K, T, P)
    with pytest.raises(ShapeError):
        project_jacobian(K, T, P)
