"""Trajectory and sensor value types."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest

from amrvio.errors import DatasetFormatError, ShapeError
from amrvio.types.lie import SE3, SO3, Sim3
from amrvio.types.sensors import Frame, ImuData, ImuNoise
from amrvio.types.trajectory import Trajectory


def _traj(n: int = 20, seed: int = 0) -> Trajectory:
    rng = np.random.default_rng(seed)
    poses = [SE3.exp(rng.normal(size=6)) for _ in range(n)]
    return Trajectory.from_poses(np.arange(n) * 0.1, poses)


def test_round_trip_poses_and_matrices() -> None:
    tr = _traj()
    again = Trajectory.from_matrices(tr.stamps_s, tr.matrices())
    np.testing.assert_allclose(again.matrices(), tr.matrices(), atol=1e-12)
    for i, T in enumerate(tr.poses()):
        np.testing.assert_allclose(T.matrix(), tr.pose(i).matrix(), atol=1e-12)


def test_transformed_is_left_multiplication() -> None:
    tr = _traj()
    S = Sim3(SO3.exp(np.array([0.1, -0.2, 0.3])), np.array([1.0, 2.0, 3.0]), 1.7)
    out = tr.transformed(S)
    for i in range(len(tr)):
        expected = S.matrix() @ tr.pose(i).matrix()
        np.testing.assert_allclose(out.positions_m[i], expected[:3, 3], atol=1e-12)
        np.testing.assert_allclose(out.rotations()[i], expected[:3, :3] / S.s, atol=1e-12)


def test_right_multiplied_changes_body_frame() -> None:
    tr = _traj()
    T_x_y = SE3.exp(np.array([0.1, 0.2, 0.3, 0.4, -0.1, 0.2]))
    out = tr.right_multiplied(T_x_y)
    for i in range(len(tr)):
        np.testing.assert_allclose(out.pose(i).matrix(), (tr.pose(i) @ T_x_y).matrix(), atol=1e-12)


def test_path_length_closed_form() -> None:
    t = np.arange(5.0)
    p = np.array([[0, 0, 0], [3, 4, 0], [3, 4, 0.5], [3, 4, 1.5], [0, 0, 1.5]], dtype=float)
    q = np.tile([1.0, 0, 0, 0], (5, 1))
    assert Trajectory(t, p, q).path_length_m() == pytest.approx(5 + 0.5 + 1 + 5)


@pytest.mark.parametrize(
    "stamps, pos, quat, msg",
    [
        ([0.0, 1.0, 1.0], np.zeros((3, 3)), np.tile([1.0, 0, 0, 0], (3, 1)), "strictly increasing at index 2"),
        ([0.0, 2.0, 1.0], np.zeros((3, 3)), np.tile([1.0, 0, 0, 0], (3, 1)), "strictly increasing"),
        ([0.0, 1.0], [[0, 0, 0], [np.nan, 0, 0]], np.tile([1.0, 0, 0, 0], (2, 1)), "non-finite value at index 1"),
        ([0.0, 1.0], np.zeros((2, 2)), np.tile([1.0, 0, 0, 0], (2, 1)), "must be"),
        ([0.0], np.zeros((1, 3)), np.zeros((1, 4)), "zero"),
    ],
)
def test_trajectory_rejects_bad_input(stamps, pos, quat, msg) -> None:
    with pytest.raises(ShapeError, match=msg):
        Trajectory(np.asarray(stamps, dtype=float), np.asarray(pos, dtype=float), np.asarray(quat, dtype=float))


def test_quaternions_are_normalised_with_positive_w() -> None:
    tr = Trajectory(np.array([0.0]), np.zeros((1, 3)), np.array([[-2.0, 0, 0, 0]]))
    np.testing.assert_allclose(tr.quats_wxyz, [[1.0, 0, 0, 0]])


def test_imu_window_and_noise() -> None:
    t = np.arange(10, dtype=np.int64) * 5_000_000
    imu = ImuData(t, np.zeros((10, 3)), np.ones((10, 3)))
    w = imu.window(10_000_000, 20_000_000)
    np.testing.assert_array_equal(w.stamps_ns, [10_000_000, 15_000_000, 20_000_000])
    g, a = ImuNoise.euroc_adis16448().discrete_sigmas()
    assert g == pytest.approx(1.6968e-04 * np.sqrt(200.0))
    assert a == pytest.approx(2.0e-3 * np.sqrt(200.0))
    with pytest.raises(ShapeError):
        ImuData(t[::-1].copy(), np.zeros((10, 3)), np.zeros((10, 3)))
    with pytest.raises(ShapeError):
        ImuNoise(-1.0, 0.0, 0.0, 0.0)


def test_frame_loads_lazily_and_reports_bad_images(tmp_path: Path) -> None:
    img = (np.arange(24 * 32) % 256).astype(np.uint8).reshape(24, 32)
    good = tmp_path / "a.png"
    cv2.imwrite(str(good), cv2.cvtColor(img, cv2.COLOR_GRAY2BGR))
    np.testing.assert_array_equal(Frame(0, 0, good).load(), img)
    bad = tmp_path / "b.png"
    bad.write_bytes(b"not a png")
    with pytest.raises(DatasetFormatError, match="b.png: image cannot be decoded"):
        Frame(1, 1, bad).load()
    with pytest.raises(DatasetFormatError, match="missing"):
        Frame(2, 2, tmp_path / "c.png").load()


def test_interpolated_at_matches_se3_interpolation() -> None:
    tr = _traj(6, seed=4)
    stamps = np.array([0.0, 0.05, 0.13, 0.3, 0.5])
    out = tr.interpolated_at(stamps)
    for k, t in enumerate(stamps):
        i = min(int(t // 0.1), len(tr) - 2)
        alpha = (t - tr.stamps_s[i]) / 0.1
        expected = tr.pose(i).interpolate(tr.pose(i + 1), alpha)
        np.testing.assert_allclose(out.pose(k).matrix(), expected.matrix(), atol=1e-9)
    with pytest.raises(ShapeError, match="leave the trajectory"):
        tr.interpolated_at(np.array([0.6]))
