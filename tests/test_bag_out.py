"""The trajectory as a ROS 2 bag of nav_msgs/Odometry (amrvio.io.bag_out), read back with rosbags."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yaml

from amrvio.errors import ConfigError
from amrvio.io.bag_out import (
    CAMERA_FRAME,
    MSGTYPE,
    TOPIC,
    WORLD_FRAME,
    body_twist,
    check_bag_path,
    read_odometry_bag,
    write_odometry_bag,
)
from amrvio.types.lie import matrix_to_quat_wxyz, so3_exp


def _screw(n: int, v: float, w: float, t0_ns: int, dt_ns: int) -> tuple[np.ndarray, np.ndarray]:
    """Poses of a screw motion about the world z axis through (1, 2, 0): constant rotation rate w
    about z and speed v along z, seen from a camera whose axes are turned by a fixed rotation.
    In the camera's own frame the twist is constant: v R0^T e_z and w R0^T e_z, exactly."""
    R0 = so3_exp(np.array([0.3, -0.2, 0.5]))
    stamps = t0_ns + dt_ns * np.arange(n, dtype=np.int64)
    t = (stamps - t0_ns) * 1e-9
    T = np.tile(np.eye(4), (n, 1, 1))
    for i, ti in enumerate(t):
        Rz = so3_exp(np.array([0.0, 0.0, w * ti]))
        T[i, :3, :3] = Rz @ R0
        T[i, :3, 3] = np.array([1.0, 2.0, 0.0]) + np.array([0.0, 0.0, v * ti])
    return stamps, T


def test_twist_of_a_screw_motion_is_exact() -> None:
    stamps, T = _screw(12, v=0.7, w=0.4, t0_ns=1_403_636_579_763_555_584, dt_ns=50_000_000)
    v, w = body_twist(stamps, T)
    R0 = T[0, :3, :3]
    np.testing.assert_allclose(v, np.tile(0.7 * R0.T[:, 2], (12, 1)), atol=1e-9)
    np.testing.assert_allclose(w, np.tile(0.4 * R0.T[:, 2], (12, 1)), atol=1e-9)
    v1, w1 = body_twist(stamps[:1], T[:1])
    assert not v1.any() and not w1.any()


def test_bag_round_trip_to_the_nanosecond(tmp_path: Path) -> None:
    stamps, T = _screw(20, v=0.5, w=-0.3, t0_ns=1_403_636_579_763_555_584, dt_ns=49_999_999)
    bag = tmp_path / "odom"
    assert write_odometry_bag(bag, stamps, T) == 20
    meta = yaml.safe_load((bag / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    assert meta["message_count"] == 20
    topics = meta["topics_with_message_count"]
    assert [(t["topic_metadata"]["name"], t["topic_metadata"]["type"], t["message_count"])
            for t in topics] == [(TOPIC, MSGTYPE, 20)]
    got_t, pos, quat, twist = read_odometry_bag(bag)
    np.testing.assert_array_equal(got_t, stamps)  # header stamps, exact
    np.testing.assert_allclose(pos, T[:, :3, 3], atol=1e-12)
    q = matrix_to_quat_wxyz(T[:, :3, :3]).reshape(-1, 4)
    np.testing.assert_allclose(np.abs(np.sum(quat * q, axis=1)), 1.0, atol=1e-12)
    v, w = body_twist(stamps, T)
    np.testing.assert_allclose(twist, np.hstack([v, w]), atol=1e-12)
    # frames and bag times, read with rosbags' own reader
    from rosbags.highlevel import AnyReader
    from rosbags.typesys import Stores, get_typestore

    with AnyReader([bag], default_typestore=get_typestore(Stores.ROS2_HUMBLE)) as reader:
        msgs = list(reader.messages())
        assert [t for _, t, _ in msgs] == stamps.tolist()
        first = reader.deserialize(msgs[0][2], MSGTYPE)
        assert (first.header.frame_id, first.child_frame_id) == (WORLD_FRAME, CAMERA_FRAME)
        assert np.all(np.asarray(first.pose.covariance) == 0)


def test_an_empty_trajectory_is_an_empty_bag(tmp_path: Path) -> None:
    write_odometry_bag(tmp_path / "empty", np.zeros(0, np.int64), np.zeros((0, 4, 4)))
    t, pos, _, _ = read_odometry_bag(tmp_path / "empty")
    assert t.shape == (0,) and pos.shape == (0, 3)


def test_bag_path_checks(tmp_path: Path) -> None:
    check_bag_path(tmp_path / "new")
    (tmp_path / "taken").mkdir()
    with pytest.raises(ConfigError, match="exists already"):
        check_bag_path(tmp_path / "taken")
    with pytest.raises(ConfigError, match="does not exist"):
        check_bag_path(tmp_path / "no" / "bag")
