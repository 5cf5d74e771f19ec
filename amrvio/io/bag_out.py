"""A trajectory as a ROS 2 bag of ``nav_msgs/msg/Odometry``, through ``rosbags`` (no ROS needed).

The bag is a new folder (rosbag2 format version 8, SQLite3 storage) with one topic,
:data:`TOPIC`. Each message carries one pose ``T_world_cam`` at its image time: the header's
``frame_id`` is the world (:data:`WORLD_FRAME`), ``child_frame_id`` the camera
(:data:`CAMERA_FRAME`). The twist, in the child frame as ROS specifies, is the finite difference
of the neighbouring poses (central where both exist). Covariances are zero: not estimated.
The bag's receive time of each message is its header stamp, so that it replays in step with the
robot's own topics.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from amrvio.errors import ConfigError, ShapeError
from amrvio.types.lie import matrix_to_quat_wxyz, so3_log

TOPIC = "/amrvio/odometry"
WORLD_FRAME = "world"
CAMERA_FRAME = "camera"
MSGTYPE = "nav_msgs/msg/Odometry"
BAG_VERSION = 8

F64 = NDArray[np.float64]
I64 = NDArray[np.int64]


def check_bag_path(path: Path, option: str = "--bag-out") -> None:
    """``path`` can become a new bag folder: it does not exist, and its parent folder exists and
    is writable. Checked before any work."""
    if os.path.lexists(path):
        raise ConfigError(f"{option} {path}: exists already; a bag is written as a new folder "
                          "(remove it or choose another name)")
    parent = path.parent if str(path.parent) else Path(".")
    if not parent.is_dir():
        raise ConfigError(f"{option} {path}: its folder {parent} does not exist")
    if not os.access(parent, os.W_OK | os.X_OK):
        raise ConfigError(f"{option} {path}: cannot write in {parent}")


def body_twist(stamps_ns: ArrayLike, T_world_cam: ArrayLike) -> tuple[F64, F64]:
    """(N, 3) linear and (N, 3) angular velocity of each pose, in its own (child) frame, from
    the neighbouring poses: v = R_i^T (p_b - p_a) / (t_b - t_a), w = log(R_a^T R_b) / (t_b - t_a)
    with a, b = i-1, i+1 (i, i+1 at the start, i-1, i at the end). Zero for a single pose."""
    t_ns = np.asarray(stamps_ns, dtype=np.int64)
    T = np.asarray(T_world_cam, dtype=np.float64)
    n = len(t_ns)
    if T.shape != (n, 4, 4):
        raise ShapeError(f"T_world_cam must be ({n}, 4, 4), got {T.shape}")
    v = np.zeros((n, 3))
    w = np.zeros((n, 3))
    if n < 2:
        return v, w
    a = np.clip(np.arange(n) - 1, 0, n - 1)
    b = np.clip(np.arange(n) + 1, 0, n - 1)
    dt = (t_ns[b] - t_ns[a]) * 1e-9  # differences of integers: seconds since 1970 in a
    # float64 keep only ~0.2 us
    R, p = T[:, :3, :3], T[:, :3, 3]
    v_world = (p[b] - p[a]) / dt[:, None]
    v = np.einsum("nji,nj->ni", R, v_world)
    w = so3_log(np.einsum("nji,njk->nik", R[a], R[b])) / dt[:, None]
    return v, w


def write_odometry_bag(path: Path, stamps_ns: ArrayLike, T_world_cam: ArrayLike,
                       topic: str = TOPIC, frame_id: str = WORLD_FRAME,
                       child_frame_id: str = CAMERA_FRAME) -> int:
    """Write the poses (``stamps_ns`` (N,), ``T_world_cam`` (N, 4, 4)) as a new ROS 2 bag at
    ``path``; returns the number of messages."""
    from rosbags.rosbag2 import Writer
    from rosbags.typesys import Stores, get_typestore

    stamps = np.asarray(stamps_ns, dtype=np.int64)
    T = np.asarray(T_world_cam, dtype=np.float64)
    v, w = body_twist(stamps, T)
    q = matrix_to_quat_wxyz(T[:, :3, :3]).reshape(-1, 4) if len(T) else np.zeros((0, 4))
    ts = get_typestore(Stores.ROS2_HUMBLE)
    try:
        _write(_writer(Writer, path), ts, stamps, T, q, v, w, topic, frame_id, child_frame_id)
    except BaseException:  # a bag half written is no bag: remove it (Ctrl-C included)
        import shutil

        shutil.rmtree(path, ignore_errors=True)
        raise
    return len(stamps)


def _writer(cls: Any, path: Path) -> Any:
    """rosbags' Writer at format :data:`BAG_VERSION` (rosbags >= 0.11 asks for it; earlier
    versions write their own latest format)."""
    import inspect

    if "version" in inspect.signature(cls.__init__).parameters:
        return cls(path, version=BAG_VERSION)
    return cls(path)


def _write(writer: Any, ts: Any, stamps: I64, T: F64, q: F64, v: F64, w: F64, topic: str,
           frame_id: str, child_frame_id: str) -> None:
    m = ts.types
    zeros = np.zeros(36, dtype=np.float64)
    with writer:
        conn = writer.add_connection(topic, MSGTYPE, typestore=ts)
        for i in range(len(stamps)):
            t_ns = int(stamps[i])
            msg = m[MSGTYPE](
                header=m["std_msgs/msg/Header"](
                    stamp=m["builtin_interfaces/msg/Time"](sec=t_ns // 1_000_000_000,
                                                           nanosec=t_ns % 1_000_000_000),
                    frame_id=frame_id),
                child_frame_id=child_frame_id,
                pose=m["geometry_msgs/msg/PoseWithCovariance"](
                    pose=m["geometry_msgs/msg/Pose"](
                        position=m["geometry_msgs/msg/Point"](*(float(x) for x in T[i, :3, 3])),
                        orientation=m["geometry_msgs/msg/Quaternion"](
                            x=float(q[i, 1]), y=float(q[i, 2]), z=float(q[i, 3]), w=float(q[i, 0]))),
                    covariance=zeros),
                twist=m["geometry_msgs/msg/TwistWithCovariance"](
                    twist=m["geometry_msgs/msg/Twist"](
                        linear=m["geometry_msgs/msg/Vector3"](*(float(x) for x in v[i])),
                        angular=m["geometry_msgs/msg/Vector3"](*(float(x) for x in w[i]))),
                    covariance=zeros))
            writer.write(conn, t_ns, ts.serialize_cdr(msg, MSGTYPE))


def read_odometry_bag(path: Path, topic: str = TOPIC) -> tuple[I64, F64, F64, F64]:
    """The messages of :func:`write_odometry_bag` read back: stamps (N,) ns, positions (N, 3),
    quaternions (N, 4) wxyz, and (N, 6) twists [v, w]."""
    from rosbags.highlevel import AnyReader
    from rosbags.typesys import Stores, get_typestore

    stamps: list[int] = []
    pos: list[list[float]] = []
    quat: list[list[float]] = []
    tw: list[list[float]] = []
    with AnyReader([path], default_typestore=get_typestore(Stores.ROS2_HUMBLE)) as reader:
        conns = [c for c in reader.connections if c.topic == topic]
        for conn, _, raw in reader.messages(connections=conns):
            msg = reader.deserialize(raw, conn.msgtype)
            st = msg.header.stamp
            stamps.append(int(st.sec) * 1_000_000_000 + int(st.nanosec))
            p, o = msg.pose.pose.position, msg.pose.pose.orientation
            pos.append([p.x, p.y, p.z])
            quat.append([o.w, o.x, o.y, o.z])
            lin, ang = msg.twist.twist.linear, msg.twist.twist.angular
            tw.append([lin.x, lin.y, lin.z, ang.x, ang.y, ang.z])
    return (np.array(stamps, dtype=np.int64), np.array(pos).reshape(-1, 3),
            np.array(quat).reshape(-1, 4), np.array(tw).reshape(-1, 6))


__all__ = ["BAG_VERSION", "CAMERA_FRAME", "MSGTYPE", "TOPIC", "WORLD_FRAME", "body_twist",
           "check_bag_path", "read_odometry_bag", "write_odometry_bag"]
