"""ROS1 and ROS2 bags written here with rosbags' writers, read back through open_dataset."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pytest
from rosbags.rosbag1 import Writer as Writer1
from rosbags.rosbag2 import Writer as Writer2
from rosbags.typesys import Stores, get_typestore

from amrvio.errors import CalibrationError, DatasetFormatError
from amrvio.io.dataset import detect_kind, open_dataset
from amrvio.io.rosbag import image_from_msg
from amrvio.types.sensors import Frame, ImuSample

W, H = 40, 30
SEC0 = 1_700_000_000


def _grey(k: int) -> np.ndarray:
    return np.random.default_rng(100 + k).integers(0, 256, size=(H, W), dtype=np.uint8)


def _colour(k: int) -> np.ndarray:
    return np.random.default_rng(200 + k).integers(0, 256, size=(H, W, 3), dtype=np.uint8)


class _Msgs:
    """Message builders for one typestore (ROS1 headers carry ``seq``)."""

    def __init__(self, store: Any, ros1: bool) -> None:
        self.store = store
        self.ros1 = ros1
        self.T = store.types

    def header(self, t_ns: int) -> Any:
        stamp = self.T["builtin_interfaces/msg/Time"](sec=t_ns // 10**9, nanosec=t_ns % 10**9)
        if self.ros1:
            return self.T["std_msgs/msg/Header"](seq=0, stamp=stamp, frame_id="cam")
        return self.T["std_msgs/msg/Header"](stamp=stamp, frame_id="cam")

    def image(self, t_ns: int, img: np.ndarray, encoding: str, pad: int = 0) -> Any:
        h, w = img.shape[:2]
        row_bytes = img.reshape(h, -1).view(np.uint8)
        step = row_bytes.shape[1] + pad
        data = np.zeros((h, step), dtype=np.uint8)
        data[:, : row_bytes.shape[1]] = row_bytes
        return self.T["sensor_msgs/msg/Image"](
            header=self.header(t_ns), height=h, width=w, encoding=encoding,
            is_bigendian=0, step=step, data=data.reshape(-1),
        )

    def compressed(self, t_ns: int, img: np.ndarray) -> Any:
        ok, buf = cv2.imencode(".png", img)
        assert ok
        return self.T["sensor_msgs/msg/CompressedImage"](
            header=self.header(t_ns), format="png", data=buf.reshape(-1).astype(np.uint8)
        )

    def imu(self, t_ns: int, gyro: np.ndarray, accel: np.ndarray) -> Any:
        V = self.T["geometry_msgs/msg/Vector3"]
        Q = self.T["geometry_msgs/msg/Quaternion"]
        return self.T["sensor_msgs/msg/Imu"](
            header=self.header(t_ns), orientation=Q(x=0.0, y=0.0, z=0.0, w=1.0),
            orientation_covariance=np.zeros(9), angular_velocity=V(x=gyro[0], y=gyro[1], z=gyro[2]),
            angular_velocity_covariance=np.zeros(9),
            linear_acceleration=V(x=accel[0], y=accel[1], z=accel[2]),
            linear_acceleration_covariance=np.zeros(9),
        )


FRAME_NS = [SEC0 * 10**9 + k * 50_000_000 + 123 for k in range(3)]
IMU_NS = [SEC0 * 10**9 + i * 5_000_000 for i in range(25)]


def _imu_vals(i: int) -> tuple[np.ndarray, np.ndarray]:
    return np.array([0.01 * i, -0.02, 0.3]), np.array([9.81, 0.1 * i, -0.5])


def write_bag(path: Path, version: int, extra_image_topic: bool = True) -> Path:
    """A bag with /cam/image_raw (mono8 x3), /cam/compressed (png x3) and /imu (x25)."""
    ros1 = version == 1
    store = get_typestore(Stores.ROS1_NOETIC if ros1 else Stores.ROS2_HUMBLE)
    m = _Msgs(store, ros1)
    ser = store.serialize_ros1 if ros1 else store.serialize_cdr
    writer: Any = Writer1(path) if ros1 else Writer2(path, version=9)
    with writer:
        c_img = writer.add_connection("/cam/image_raw", "sensor_msgs/msg/Image", typestore=store)
        c_cmp = None
        if extra_image_topic:
            c_cmp = writer.add_connection(
                "/cam/compressed", "sensor_msgs/msg/CompressedImage", typestore=store
            )
        c_imu = writer.add_connection("/imu", "sensor_msgs/msg/Imu", typestore=store)
        events: list[tuple[int, Any, Any, str]] = []
        for i, t in enumerate(IMU_NS):
            events.append((t + 1000, c_imu, m.imu(t, *_imu_vals(i)), "sensor_msgs/msg/Imu"))
        for k, t in enumerate(FRAME_NS):
            # Receive time later than the header stamp: the reader must use the header.
            events.append((t + 2_000_000, c_img, m.image(t, _grey(k), "mono8", pad=3),
                           "sensor_msgs/msg/Image"))
            if c_cmp is not None:
                events.append((t + 2_000_000, c_cmp, m.compressed(t, _colour(k)),
                               "sensor_msgs/msg/CompressedImage"))
        for bag_t, conn, msg, typ in sorted(events, key=lambda e: e[0]):
            writer.write(conn, bag_t, ser(msg, typ))
    return path


@pytest.mark.parametrize("version", [1, 2])
def test_bag_images_and_imu_read_back_exactly(tmp_path: Path, version: int) -> None:
    bag = write_bag(tmp_path / ("rec.bag" if version == 1 else "rec_ros2"), version)
    assert detect_kind(bag) == "bag"
    # Two image topics: no silent choice.
    with pytest.raises(DatasetFormatError, match="several image topics") as info:
        open_dataset(bag)
    assert "/cam/compressed" in str(info.value) and "\n" not in str(info.value)

    raw = open_dataset(f"bag:{bag}", image_topic="/cam/image_raw")
    assert raw.kind == "bag"
    assert [f.t_ns for f in raw.frames] == FRAME_NS
    assert all(f.path is None for f in raw.frames)
    for k in (2, 0, 1):  # lazy, any order
        np.testing.assert_array_equal(raw.frames[k].load(), _grey(k))

    cmp_ds = open_dataset(f"bag:{bag}", image_topic="/cam/compressed")
    for k in range(3):
        expected = cv2.cvtColor(_colour(k), cv2.COLOR_BGR2GRAY)
        np.testing.assert_array_equal(cmp_ds.frames[k].load(), expected)

    imu = raw.imu
    assert imu is not None and len(imu) == len(IMU_NS)
    np.testing.assert_array_equal(imu.stamps_ns, IMU_NS)
    for i in (0, 7, 24):
        gyro, accel = _imu_vals(i)
        np.testing.assert_array_equal(imu.gyro_rad_s[i], gyro)
        np.testing.assert_array_equal(imu.accel_m_s2[i], accel)

    items = list(raw.stream())
    assert [it.t_ns for it in items] == sorted(it.t_ns for it in items)
    assert sum(isinstance(it, Frame) for it in items) == 3
    assert sum(isinstance(it, ImuSample) for it in items) == 25


def test_bag_single_image_topic_default_and_bad_topic(tmp_path: Path) -> None:
    bag = write_bag(tmp_path / "one.bag", 1, extra_image_topic=False)
    ds = open_dataset(bag)
    assert len(ds.frames) == 3 and ds.imu is not None
    with pytest.raises(DatasetFormatError, match="'/nope' is not in the bag"):
        open_dataset(bag, image_topic="/nope")
    with pytest.raises(DatasetFormatError, match="has type sensor_msgs/msg/Imu"):
        open_dataset(bag, image_topic="/imu")


def test_bag_calibration_size_checked(tmp_path: Path) -> None:
    bag = write_bag(tmp_path / "one.bag", 1, extra_image_topic=False)
    chain = tmp_path / "camchain.yaml"
    body = ("cam0:\n  camera_model: pinhole\n  distortion_coeffs: [0.0, 0.0, 0.0, 0.0]\n"
            "  distortion_model: radtan\n  intrinsics: [30.0, 30.0, 20.0, 15.0]\n")
    chain.write_text(body + f"  resolution: [{W}, {H}]\n")
    ds = open_dataset(bag, calib=chain)
    assert ds.camera is not None and ds.camera.fx == 30.0
    chain.write_text(body + "  resolution: [640, 480]\n")
    with pytest.raises(CalibrationError, match="camchain.yaml"):
        open_dataset(bag, calib=chain)


def test_image_encodings() -> None:
    store = get_typestore(Stores.ROS2_HUMBLE)
    m = _Msgs(store, ros1=False)
    colour = _colour(0)
    typ = "sensor_msgs/msg/Image"
    bgr = image_from_msg(m.image(1, colour, "bgr8", pad=2), typ, "x")
    np.testing.assert_array_equal(bgr, cv2.cvtColor(colour, cv2.COLOR_BGR2GRAY))
    rgb = image_from_msg(m.image(1, colour, "rgb8"), typ, "x")
    np.testing.assert_array_equal(rgb, cv2.cvtColor(colour, cv2.COLOR_RGB2GRAY))
    wide = (_grey(1).astype(np.uint16) << 8) | 0x7F
    mono16 = image_from_msg(m.image(1, wide.astype("<u2"), "mono16"), typ, "x")
    np.testing.assert_array_equal(mono16, _grey(1))
    with pytest.raises(DatasetFormatError, match="not supported"):
        image_from_msg(m.image(1, _grey(0), "bayer_rggb8"), typ, "x")
    short = m.image(1, _grey(0), "mono8")
    short.height = H + 5
    with pytest.raises(DatasetFormatError, match="does not match"):
        image_from_msg(short, typ, "x")
    bad = m.compressed(1, _grey(0))
    bad.data = np.frombuffer(b"not an image", dtype=np.uint8)
    with pytest.raises(DatasetFormatError, match="cannot be decoded"):
        image_from_msg(bad, "sensor_msgs/msg/CompressedImage", "x")


def test_not_a_bag(tmp_path: Path) -> None:
    junk = tmp_path / "junk.bag"
    junk.write_bytes(b"#ROSBAG V2.0\nnonsense")
    with pytest.raises(DatasetFormatError, match="junk.bag"):
        open_dataset(junk)


def test_ros2_db3_file_path_and_bad_imu_stamps(tmp_path: Path) -> None:
    from amrvio.io.rosbag import _imu_data

    bag = write_bag(tmp_path / "r2", 2, extra_image_topic=False)
    db3 = next(bag.glob("*.db3"))
    assert detect_kind(db3) == "bag"
    assert len(open_dataset(db3).frames) == 3
    vals = [(0.0,) * 6] * 3
    with pytest.raises(DatasetFormatError, match="two IMU messages have the header stamp 5"):
        _imu_data(bag, "/imu", [1, 5, 5], vals)
    with pytest.raises(DatasetFormatError, match="NaN"):
        _imu_data(bag, "/imu", [1, 2, 3], [(0.0,) * 6, (float("nan"),) + (0.0,) * 5, (0.0,) * 6])
    imu = _imu_data(bag, "/imu", [3, 1, 2], [(3.0,) * 6, (1.0,) * 6, (2.0,) * 6])
    assert imu is not None
    np.testing.assert_array_equal(imu.stamps_ns, [1, 2, 3])
    np.testing.assert_array_equal(imu.gyro_rad_s[:, 0], [1.0, 2.0, 3.0])
