"""ROS1 (``.bag``) and ROS2 (folder with ``metadata.yaml``) bags through ``rosbags``.

Reads ``sensor_msgs/Image`` (mono8, mono16, bgr8, rgb8, bgra8, rgba8, 8UC1, 16UC1 -> grey uint8),
``sensor_msgs/CompressedImage`` (decoded with ``cv2.imdecode``) and ``sensor_msgs/Imu``. The
frame and IMU times are the message header stamps (the bag receive time when a stamp is zero).

Images are read lazily: opening the bag reads every message once to collect stamps, then keeps
only (topic, bag time); ``Frame.load()`` reads that one message again. Topic choice: the
``image_topic`` / ``imu_topic`` options, else the only image / IMU topic of the bag (an error
lists the candidates when there are several).
"""

from __future__ import annotations

import threading
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from amrvio.errors import DatasetFormatError
from amrvio.io.base import MAX_ACCEL_M_S2, MAX_GYRO_RAD_S, Dataset, first_image_shape
from amrvio.io.calib_load import load_checked_calibration
from amrvio.io.image import check_decoded, decode_image
from amrvio.types.sensors import Frame, ImuData

IMAGE_TYPES = ("sensor_msgs/msg/Image", "sensor_msgs/msg/CompressedImage")
IMU_TYPE = "sensor_msgs/msg/Imu"

U8 = NDArray[np.uint8]


def bag_paths(path: Path) -> list[Path]:
    """What AnyReader opens: a ``.bag`` file, or the folder of a ROS2 bag."""
    if path.is_file() and path.suffix == ".bag":
        return [path]
    if path.is_file() and path.suffix in (".db3", ".mcap"):
        return [path.parent]
    if path.is_dir() and (path / "metadata.yaml").is_file():
        return [path]
    raise DatasetFormatError(path, "not a bag: expected a .bag file or a ROS2 bag folder")


def _open_reader(paths: list[Path]) -> Any:
    from rosbags.highlevel import AnyReader
    from rosbags.typesys import Stores, get_typestore

    reader = AnyReader(paths, default_typestore=get_typestore(Stores.ROS2_HUMBLE))
    try:
        reader.open()
    except Exception as err:  # rosbags raises several unrelated types for a bad file
        raise DatasetFormatError(paths[0], f"cannot open bag ({err})") from None
    return reader


def _stamp_ns(msg: Any, bag_ns: int) -> int:
    stamp = msg.header.stamp
    ns = int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)
    return ns if ns > 0 else int(bag_ns)


def _choose(topics: dict[str, str], wanted: str | None, types: tuple[str, ...], what: str,
            path: Path, required: bool) -> str | None:
    candidates = sorted(t for t, ty in topics.items() if ty in types)
    if wanted is not None:
        if wanted not in topics:
            raise DatasetFormatError(
                path, f"{what} topic {wanted!r} is not in the bag; topics: {_listing(topics)}"
            )
        if topics[wanted] not in types:
            raise DatasetFormatError(
                path, f"topic {wanted!r} has type {topics[wanted]}, not {' or '.join(types)}"
            )
        return wanted
    if len(candidates) == 1:
        return candidates[0]
    if not candidates:
        if required:
            raise DatasetFormatError(path, f"no {what} topic in the bag; topics: {_listing(topics)}")
        return None
    option = "image_topic" if what == "image" else "imu_topic"
    raise DatasetFormatError(
        path, f"several {what} topics {candidates}; choose one with the {option} option"
    )


def _listing(topics: dict[str, str]) -> str:
    return ", ".join(f"{t} ({ty})" for t, ty in sorted(topics.items())) or "none"


def image_from_msg(msg: Any, msgtype: str, where: str) -> U8:
    """A sensor_msgs Image or CompressedImage as (H, W) uint8 grey, checked like an image file
    (:mod:`amrvio.io.image`)."""
    if msgtype.endswith("CompressedImage"):
        data = np.asarray(msg.data, dtype=np.uint8).tobytes()
        return decode_image(data, where)
    img = _raw_image(msg, where)
    check_decoded(img, where)
    return img


def _raw_image(msg: Any, where: str) -> U8:
    import cv2

    enc = str(msg.encoding).lower()
    h, w, step = int(msg.height), int(msg.width), int(msg.step)
    raw = np.asarray(msg.data, dtype=np.uint8)
    channels = {"mono8": 1, "8uc1": 1, "mono16": 2, "16uc1": 2, "bgr8": 3, "rgb8": 3,
                "bgra8": 4, "rgba8": 4}
    if enc not in channels:
        raise DatasetFormatError(where, f"image encoding {msg.encoding!r} is not supported")
    bpp = channels[enc]
    if h <= 0 or w <= 0 or step < w * bpp or raw.size < h * step:
        raise DatasetFormatError(
            where, f"image data ({raw.size} bytes) does not match {w}x{h}, step {step}, {enc}"
        )
    rows = raw[: h * step].reshape(h, step)[:, : w * bpp]
    if bpp == 1:
        return np.ascontiguousarray(rows)
    if bpp == 2:
        dtype = ">u2" if int(msg.is_bigendian) else "<u2"
        wide = np.ascontiguousarray(rows).view(dtype).reshape(h, w)
        return (wide.astype(np.uint16) >> 8).astype(np.uint8)
    colour = np.ascontiguousarray(rows).reshape(h, w, bpp)
    code = {
        "bgr8": cv2.COLOR_BGR2GRAY,
        "rgb8": cv2.COLOR_RGB2GRAY,
        "bgra8": cv2.COLOR_BGRA2GRAY,
        "rgba8": cv2.COLOR_RGBA2GRAY,
    }[enc]
    return np.asarray(cv2.cvtColor(colour, code), dtype=np.uint8)


@dataclass(eq=False)
class BagImageSource:
    """Re-reads image messages of one topic on demand; keeps one reader open while in use."""

    paths: list[Path]
    topic: str
    _reader: Any = field(default=None, repr=False)
    _lock: threading.Lock = field(default_factory=threading.Lock, repr=False)

    def read(self, bag_ns: int, ordinal: int) -> U8:
        where = f"{self.paths[0]}:{self.topic}@{bag_ns}"
        with self._lock:
            if self._reader is None:
                self._reader = _open_reader(self.paths)
            reader = self._reader
            conns = [c for c in reader.connections if c.topic == self.topic]
            found = None
            for k, (conn, _, raw) in enumerate(
                reader.messages(connections=conns, start=bag_ns, stop=bag_ns + 1)
            ):
                if k == ordinal:
                    found = (conn, raw)
                    break
            if found is None:
                raise DatasetFormatError(where, "image message is no longer in the bag")
            conn, raw = found
            try:
                msg = reader.deserialize(raw, conn.msgtype)
            except Exception as err:  # rosbags' serde errors
                raise DatasetFormatError(where, f"cannot deserialise message ({err})") from None
        return image_from_msg(msg, conn.msgtype, where)

    def close(self) -> None:
        with self._lock:
            if self._reader is not None:
                self._reader.close()
                self._reader = None


@dataclass(frozen=True, slots=True)
class BagImage:
    """Loader of one bag image (``Frame.loader``)."""

    source: BagImageSource
    bag_ns: int
    ordinal: int

    def __call__(self) -> U8:
        return self.source.read(self.bag_ns, self.ordinal)


def read_bag(
    path: Path,
    calib: Path | None = None,
    image_topic: str | None = None,
    imu_topic: str | None = None,
) -> Dataset:
    """Open a ROS1 or ROS2 bag (see the module docstring); ``calib`` gives the camera."""
    paths = bag_paths(path)
    reader = _open_reader(paths)
    try:
        topics = {c.topic: c.msgtype for c in reader.connections}
        img_topic = _choose(topics, image_topic, IMAGE_TYPES, "image", path, required=True)
        if img_topic is None:  # _choose raises instead; keeps the type narrow
            raise DatasetFormatError(path, "no image topic in the bag")
        imu_topic_ = _choose(topics, imu_topic, (IMU_TYPE,), "IMU", path, required=False)
        img_conns = [c for c in reader.connections if c.topic == img_topic]
        records: list[tuple[int, int, int]] = []  # (stamp, bag time, ordinal at that bag time)
        last_bag, ordinal = -1, 0
        for conn, bag_ns, raw in reader.messages(connections=img_conns):
            ordinal = ordinal + 1 if bag_ns == last_bag else 0
            last_bag = bag_ns
            msg = reader.deserialize(raw, conn.msgtype)
            records.append((_stamp_ns(msg, bag_ns), int(bag_ns), ordinal))
        imu = None
        if imu_topic_ is not None:
            imu_conns = [c for c in reader.connections if c.topic == imu_topic_]
            stamps: list[int] = []
            values: list[tuple[float, ...]] = []
            for conn, bag_ns, raw in reader.messages(connections=imu_conns):
                msg = reader.deserialize(raw, conn.msgtype)
                w, a = msg.angular_velocity, msg.linear_acceleration
                stamps.append(_stamp_ns(msg, bag_ns))
                values.append((w.x, w.y, w.z, a.x, a.y, a.z))
            imu = _imu_data(path, imu_topic_, stamps, values)
    except DatasetFormatError:
        raise
    except Exception as err:  # rosbags' reader and serde errors
        raise DatasetFormatError(path, f"cannot read bag ({err})") from None
    finally:
        reader.close()

    records.sort()
    for (t0, _, _), (t1, b1, _) in zip(records, records[1:], strict=False):
        if t1 == t0:
            raise DatasetFormatError(
                path, f"two {img_topic} messages have the header stamp {t1} ns (bag time {b1})"
            )
    if not records:
        raise DatasetFormatError(path, f"topic {img_topic} has no messages")
    source = BagImageSource(paths, img_topic)
    frames = tuple(
        Frame(t_ns=t, index=i, path=None, loader=BagImage(source, b, k))
        for i, (t, b, k) in enumerate(records)
    )
    camera, T_body_cam = (None, None) if calib is None else load_checked_calibration(
        calib, *first_image_shape(frames)
    )
    return Dataset(
        kind="bag", root=path, frames=frames, camera=camera, T_body_cam=T_body_cam, imu=imu
    )


def _imu_data(
    path: Path, topic: str, stamps: Sequence[int], values: Sequence[Sequence[float]]
) -> ImuData | None:
    if not stamps:
        return None
    t = np.array(stamps, dtype=np.int64)
    v = np.array(values, dtype=np.float64).reshape(-1, 6)
    order = np.argsort(t, kind="stable")
    t, v = t[order], v[order]
    if np.any(np.diff(t) <= 0):
        i = int(np.flatnonzero(np.diff(t) <= 0)[0]) + 1
        raise DatasetFormatError(path, f"{topic}: two IMU messages have the header stamp {t[i]} ns")
    if not np.all(np.isfinite(v)):
        i = int(np.flatnonzero(~np.all(np.isfinite(v), axis=1))[0])
        raise DatasetFormatError(path, f"{topic}: IMU message at {t[i]} ns has a NaN value")
    over = (np.abs(v[:, :3]) > MAX_GYRO_RAD_S).any(axis=1) | (
        np.abs(v[:, 3:]) > MAX_ACCEL_M_S2).any(axis=1)
    if np.any(over):
        i = int(np.flatnonzero(over)[0])
        raise DatasetFormatError(path, f"{topic}: IMU message at {t[i]} ns is beyond "
                                       f"+-{MAX_GYRO_RAD_S:g} rad/s or +-{MAX_ACCEL_M_S2:g} m/s^2")
    return ImuData(t, v[:, :3], v[:, 3:])
