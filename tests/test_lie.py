"""Group rules for SO3, SE3 and Sim3, checked against scipy's matrix exponential and Rotation."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays
from scipy.linalg import expm
from scipy.spatial.transform import Rotation

from amrvio.errors import ShapeError
from amrvio.types.lie import (
    SE3,
    SO3,
    Sim3,
    hat,
    interpolate_se3,
    matrix_to_quat_wxyz,
    quat_wxyz_to_matrix,
    so3_exp,
    so3_log,
    transform_points,
)

finite = st.floats(-3.0, 3.0, allow_nan=False, allow_infinity=False)
vec3 = arrays(np.float64, 3, elements=finite)
rotvec = arrays(np.float64, 3, elements=st.floats(-1.7, 1.7))  # |phi| < pi
vec6 = st.tuples(vec3, rotvec).map(lambda a: np.concatenate(a))
vec7 = st.tuples(vec3, rotvec, st.floats(-1.5, 1.5)).map(lambda a: np.concatenate([a[0], a[1], [a[2]]]))


def _se3_generator(xi: np.ndarray) -> np.ndarray:
    G = np.zeros((4, 4))
    G[:3, :3] = hat(xi[3:6])
    G[:3, 3] = xi[:3]
    return G


def _sim3_generator(xi: np.ndarray) -> np.ndarray:
    G = _se3_generator(xi[:6])
    G[:3, :3] += xi[6] * np.eye(3)
    return G


ELEMENTS: dict[str, tuple[Any, Any, Any]] = {
    "SO3": (rotvec, SO3.exp, lambda x: SO3.exp(x).matrix()),
    "SE3": (vec6, SE3.exp, lambda x: SE3.exp(x).matrix()),
    "Sim3": (vec7, Sim3.exp, lambda x: Sim3.exp(x).matrix()),
}


@pytest.mark.parametrize("name", list(ELEMENTS))
def test_group_rules(name: str) -> None:
    strategy, exp, _ = ELEMENTS[name]

    @settings(max_examples=60, deadline=None)
    @given(strategy, strategy, strategy)
    def check(x: np.ndarray, y: np.ndarray, z: np.ndarray) -> None:
        a, b, c = exp(x), exp(y), exp(z)
        # exp/log round trip
        np.testing.assert_allclose(a.log(), x, atol=1e-9)
        # associativity
        np.testing.assert_allclose(((a @ b) @ c).matrix(), (a @ (b @ c)).matrix(), atol=1e-9)
        # inverse
        np.testing.assert_allclose((a @ a.inverse()).matrix(), np.eye(a.matrix().shape[0]), atol=1e-9)
        np.testing.assert_allclose((a.inverse() @ a).matrix(), np.eye(a.matrix().shape[0]), atol=1e-9)
        # identity
        ident = type(a).identity()
        np.testing.assert_allclose((a @ ident).matrix(), a.matrix(), atol=1e-12)
        # composition matches matrices, action matches matrices
        np.testing.assert_allclose((a @ b).matrix(), a.matrix() @ b.matrix(), atol=1e-9)
        p = np.array([0.3, -1.2, 2.5])
        M = a.matrix()
        expected = M[:3, :3] @ p + (M[:3, 3] if M.shape[0] == 4 else 0.0)
        np.testing.assert_allclose(a.act(p), expected, atol=1e-9)
        np.testing.assert_allclose(a.act(np.stack([p, 2 * p])), np.stack([expected, a.act(2 * p)]), atol=1e-9)
        # interpolation end points and midpoint geodesic property
        np.testing.assert_allclose(a.interpolate(b, 0.0).matrix(), a.matrix(), atol=1e-9)
        np.testing.assert_allclose(a.interpolate(b, 1.0).matrix(), b.matrix(), atol=1e-8)

    check()


@settings(max_examples=60, deadline=None)
@given(vec6)
def test_se3_exp_matches_matrix_exponential(xi: np.ndarray) -> None:
    np.testing.assert_allclose(SE3.exp(xi).matrix(), expm(_se3_generator(xi)), atol=1e-9)


@settings(max_examples=60, deadline=None)
@given(vec7)
def test_sim3_exp_matches_matrix_exponential(xi: np.ndarray) -> None:
    np.testing.assert_allclose(Sim3.exp(xi).matrix(), expm(_sim3_generator(xi)), atol=1e-9)


def test_sim3_round_trip_near_the_small_scale_switch() -> None:
    """Hypothesis found [0, 1, 1, 1, 1, 1, 1e-8]: exp took sigma = 1e-8 through the closed
    forms, log got 9.99999994e-09 and took the zero-scale ones, 2e-8 apart. Scales and rotations
    around every switch, against the matrix exponential too."""
    rng = np.random.default_rng(3)
    for theta in (0.0, 1e-10, 1e-6, 5e-5, 1e-4, 2e-4, 1e-2, 1.0):
        for sigma in (0.0, 1e-13, 1e-10, 9.99e-9, 1e-8, 1.001e-8, 2e-8, 1e-6, 1e-4, 2e-4, -1e-8, 0.5):
            axis = rng.normal(size=3)
            xi = np.concatenate([rng.uniform(-3, 3, 3), theta * axis / np.linalg.norm(axis), [sigma]])
            np.testing.assert_allclose(Sim3.exp(xi).log(), xi, atol=1e-11)
            np.testing.assert_allclose(Sim3.exp(xi).matrix(), expm(_sim3_generator(xi)), atol=1e-11)


@settings(max_examples=60, deadline=None)
@given(rotvec)
def test_so3_matches_scipy_rotation(w: np.ndarray) -> None:
    R = SO3.exp(w)
    ref = Rotation.from_rotvec(w)
    np.testing.assert_allclose(R.matrix(), ref.as_matrix(), atol=1e-12)
    x, y, z, qw = ref.as_quat()
    q = np.array([qw, x, y, z])
    q = q if q[0] >= 0 else -q
    np.testing.assert_allclose(R.quat_wxyz(), q, atol=1e-12)
    np.testing.assert_allclose(SO3.from_quat_wxyz(q).matrix(), R.matrix(), atol=1e-12)


def test_tiny_rotations_are_not_rounded_to_identity() -> None:
    # cv2.Rodrigues returns exactly zero below ~1e-5 rad; IMU integration needs these increments.
    for angle in (1e-6, 1e-9, 1e-12):
        w = np.array([angle, -2 * angle, 0.5 * angle])
        R = so3_exp(w)
        np.testing.assert_allclose(vee_of(R), w, rtol=1e-9)
        np.testing.assert_allclose(so3_log(R), w, rtol=1e-6)


def vee_of(R: np.ndarray) -> np.ndarray:
    return np.array([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]]) / 2.0


def test_log_near_pi() -> None:
    for axis in (np.array([1.0, 0, 0]), np.array([0.3, -0.5, 0.8]) / np.linalg.norm([0.3, -0.5, 0.8])):
        for theta in (np.pi - 1e-3, np.pi - 1e-9, np.pi):
            w = axis * theta
            got = so3_log(so3_exp(w))
            # at exactly pi, +axis and -axis are the same rotation
            ok = np.allclose(got, w, atol=1e-6) or (theta == np.pi and np.allclose(got, -w, atol=1e-6))
            assert ok, (got, w)
            np.testing.assert_allclose(so3_exp(got), so3_exp(w), atol=1e-9)


def test_batch_quaternion_round_trip() -> None:
    rng = np.random.default_rng(3)
    q = rng.normal(size=(200, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    q[q[:, 0] < 0] *= -1
    np.testing.assert_allclose(matrix_to_quat_wxyz(quat_wxyz_to_matrix(q)), q, atol=1e-12)
    ws = rng.normal(size=(50, 3))
    np.testing.assert_allclose(so3_log(so3_exp(ws * 0.5)), ws * 0.5, atol=1e-9)


def test_frame_convention() -> None:
    T_a_b = SE3.exp(np.array([1.0, 2.0, 3.0, 0.1, 0.2, -0.3]))
    T_b_c = SE3.exp(np.array([-0.5, 0.0, 1.0, -0.2, 0.4, 0.1]))
    p_c = np.array([0.1, 0.2, 0.3])
    np.testing.assert_allclose((T_a_b @ T_b_c).act(p_c), T_a_b.act(T_b_c.act(p_c)), atol=1e-12)
    np.testing.assert_allclose(T_a_b.inverse().act(T_a_b.act(p_c)), p_c, atol=1e-12)


def test_sim3_scale_and_se3_interop() -> None:
    S = Sim3(SO3.exp(np.array([0, 0, 0.5])), np.array([1.0, 0, 0]), 2.0)
    np.testing.assert_allclose(S.act(np.array([1.0, 0, 0])), 2 * SO3.exp(np.array([0, 0, 0.5])).act(np.array([1.0, 0, 0])) + [1, 0, 0])
    np.testing.assert_allclose(Sim3.from_matrix(S.matrix()).matrix(), S.matrix(), atol=1e-12)
    assert S.inverse().s == pytest.approx(0.5)


@pytest.mark.parametrize(
    "bad",
    [
        lambda: SO3.exp(np.array([np.nan, 0, 0])),
        lambda: SO3.exp(np.zeros(4)),
        lambda: SO3(np.diag([1.0, 1.0, -1.0])),
        lambda: SO3(np.ones((3, 3))),
        lambda: SE3.from_matrix(np.eye(3)),
        lambda: Sim3(SO3.identity(), np.zeros(3), 0.0),
        lambda: Sim3(SO3.identity(), np.zeros(3), -1.0),
        lambda: SE3(SO3.identity(), np.zeros(2)),
        lambda: quat_wxyz_to_matrix(np.zeros(4)),
    ],
)
def test_bad_input_raises_shape_error(bad) -> None:
    with pytest.raises(ShapeError):
        bad()


def test_values_are_immutable() -> None:
    T: Any = SE3.identity()
    with pytest.raises(ValueError):
        T.t[0] = 1.0
    with pytest.raises(AttributeError):
        T.t = np.zeros(3)


def _random_se3(rng: np.random.Generator) -> SE3:
    return SE3.exp(np.r_[rng.normal(0, 2.0, 3), rng.normal(0, 0.8, 3)])


def test_interpolate_se3_matches_scipy_slerp_and_linear_translation() -> None:
    from scipy.spatial.transform import Slerp

    rng = np.random.default_rng(4)
    A = np.stack([_random_se3(rng).matrix() for _ in range(20)])
    B = np.stack([_random_se3(rng).matrix() for _ in range(20)])
    alpha = rng.uniform(0, 1, 20)
    out = interpolate_se3(A, B, alpha)
    for i in range(20):
        slerp = Slerp([0.0, 1.0], Rotation.from_matrix(np.stack([A[i, :3, :3], B[i, :3, :3]])))
        np.testing.assert_allclose(out[i, :3, :3], slerp([alpha[i]]).as_matrix()[0], atol=1e-10)
        t = (1 - alpha[i]) * A[i, :3, 3] + alpha[i] * B[i, :3, 3]
        np.testing.assert_allclose(out[i, :3, 3], t, atol=1e-12)
        np.testing.assert_array_equal(out[i, 3], [0, 0, 0, 1])
    np.testing.assert_allclose(interpolate_se3(A, B, np.zeros(20)), A, atol=1e-12)
    np.testing.assert_allclose(interpolate_se3(A, B, np.ones(20)), B, atol=1e-9)
    # one pair: rotation about z by 2 theta, halfway is theta (closed form)
    R2 = SE3(SO3.exp([0, 0, 1.2]), np.array([2.0, 0, 0])).matrix()
    mid = interpolate_se3(np.eye(4), R2, 0.5)
    np.testing.assert_allclose(mid, SE3(SO3.exp([0, 0, 0.6]), np.array([1.0, 0, 0])).matrix(),
                               atol=1e-12)
    with pytest.raises(ShapeError):
        interpolate_se3(A, B[:3], alpha)


def test_transform_points_single_and_per_point() -> None:
    rng = np.random.default_rng(5)
    T = _random_se3(rng)
    P = rng.normal(0, 3, (7, 3))
    np.testing.assert_allclose(transform_points(T.matrix(), P), T.act(P), atol=1e-12)
    Ts = np.stack([_random_se3(rng).matrix() for _ in range(7)])
    ref = np.stack([Ts[i, :3, :3] @ P[i] + Ts[i, :3, 3] for i in range(7)])
    np.testing.assert_allclose(transform_points(Ts, P), ref, atol=1e-12)


def test_sim3_acts_on_poses_and_round_trips_its_parts() -> None:
    rng = np.random.default_rng(6)
    for _ in range(10):
        S = Sim3.exp(np.r_[rng.normal(0, 1, 6), rng.normal(0, 0.7)])
        S2 = Sim3.exp(np.r_[rng.normal(0, 1, 6), rng.normal(0, 0.7)])
        T = _random_se3(rng)
        # closed form: the 4x4 product S T has rotation block s R_S R_T
        M = S.matrix() @ T.matrix()
        got = S.transform_pose(T)
        np.testing.assert_allclose(got.R, M[:3, :3] / S.s, atol=1e-12)
        np.testing.assert_allclose(got.t, M[:3, 3], atol=1e-12)
        np.testing.assert_allclose(S.transform_pose_matrix(T.matrix()), got.matrix(), atol=0)
        # the camera centre moves as a point
        np.testing.assert_allclose(got.t, S.act(T.t), atol=1e-12)
        # composition and inverse agree with acting twice / undoing
        np.testing.assert_allclose((S @ S2).transform_pose(T).matrix(),
                                   S.transform_pose(S2.transform_pose(T)).matrix(), atol=1e-10)
        np.testing.assert_allclose(S.inverse().transform_pose(got).matrix(), T.matrix(), atol=1e-10)
        s, R, t = S.srt()
        back = Sim3.from_srt(s, R, t)
        np.testing.assert_array_equal(back.matrix(), S.matrix())
        np.testing.assert_allclose(back.act(T.t), s * (R @ T.t) + t, atol=1e-12)
    with pytest.raises(ShapeError):
        Sim3.from_srt(0.0, np.eye(3), np.zeros(3))
    with pytest.raises(ShapeError):
        Sim3.from_srt(1.0, 2.0 * np.eye(3), np.zeros(3))
