"""The :class:`Dataset` value every reader returns, and the helpers the readers share.

A :class:`Dataset` holds time-ordered :class:`~amrvio.types.sensors.Frame` objects (images are read
only by ``Frame.load()``), the IMU stream, the calibration and the ground truth when the recording
has them. :meth:`Dataset.stream` merges frames and IMU samples by time. The readers live in
``amrvio/io/{asl,tum_mono,kitti,rosbag,folder}.py``; ``amrvio.io.dataset.open_dataset`` picks one.
"""

from __future__ import annotations

import logging
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from amrvio.errors import DatasetFormatError, InputFileError
from amrvio.io.image import to_grey
from amrvio.io.table import (
    check_columns,
    check_increasing,
    check_magnitude,
    float_columns,
    int_column,
    read_table,
)
from amrvio.types.camera import CameraModel
from amrvio.types.lie import SE3
from amrvio.types.sensors import Frame, ImuData, ImuNoise, ImuSample, WheelData
from amrvio.types.trajectory import Trajectory

log = logging.getLogger(__name__)

KINDS: tuple[str, ...] = ("euroc", "tumvi", "tum-mono", "kitti", "bag", "folder")

F64 = NDArray[np.float64]
I64 = NDArray[np.int64]
U8 = NDArray[np.uint8]


@dataclass(frozen=True, slots=True, eq=False)
class Dataset:
    """A recording: frames (lazy), IMU, calibration and ground truth.

    kind: one of :data:`KINDS`. frames: time-ordered, images not loaded. camera: intrinsics or None.
    T_body_cam: camera pose in the body (IMU) frame, or None when unknown. groundtruth: poses as
    stored by the dataset (EuRoC/TUM-VI: ``T_world_body``, ``groundtruth_frame == "body"``; KITTI:
    ``T_cam0_camk``, ``"cam"``; ``""`` when there is none). inverse_response: (256,) G^-1 from
    pcalib.txt; vignette: (H, W) in [0, 1] from vignette.png. wheel: wheel odometry (forward
    speed and yaw rate) of a ground robot, or None.
    """

    kind: str
    root: Path
    frames: tuple[Frame, ...]
    camera: CameraModel | None = None
    T_body_cam: SE3 | None = None
    imu: ImuData | None = None
    imu_noise: ImuNoise | None = None
    groundtruth: Trajectory | None = None
    groundtruth_frame: str = ""
    inverse_response: F64 | None = None
    vignette: F64 | None = None
    wheel: WheelData | None = None

    def __post_init__(self) -> None:
        if self.kind not in KINDS:
            raise DatasetFormatError(self.root, f"unknown dataset kind {self.kind!r}")
        if self.groundtruth_frame not in ("body", "cam", ""):
            raise DatasetFormatError(
                self.root, f"groundtruth_frame must be body, cam or '', got {self.groundtruth_frame!r}"
            )
        stamps = [f.t_ns for f in self.frames]
        if any(b <= a for a, b in zip(stamps, stamps[1:], strict=False)):
            raise DatasetFormatError(self.root, "frame timestamps are not strictly increasing")

    @property
    def frame_stamps_ns(self) -> I64:
        """(N,) int64 frame timestamps."""
        return np.array([f.t_ns for f in self.frames], dtype=np.int64)

    def stream(self) -> Iterator[Frame | ImuSample]:
        """Frames and IMU samples merged by time; an IMU sample comes before a frame at equal time."""
        imu = self.imu
        n_imu = 0 if imu is None else len(imu)
        i = 0
        for frame in self.frames:
            while imu is not None and i < n_imu and int(imu.stamps_ns[i]) <= frame.t_ns:
                yield imu.sample(i)
                i += 1
            yield frame
        while imu is not None and i < n_imu:
            yield imu.sample(i)
            i += 1


MAX_GYRO_RAD_S = 100.0
"""Largest |angular rate| an IMU file may hold (rad/s; MEMS gyros saturate near 35)."""
MAX_ACCEL_M_S2 = 2000.0
"""Largest |acceleration| an IMU file may hold (m/s^2, about 200 g)."""


def read_imu_csv(path: Path) -> ImuData:
    """EuRoC imu0 layout: ``t_ns, w_x, w_y, w_z [rad/s], a_x, a_y, a_z [m/s^2]``."""
    table = read_table(path, ",", "IMU file")
    check_columns(table, 7, "IMU row")
    stamps = int_column(table, 0, "IMU timestamp [ns]")
    values = float_columns(table, range(1, 7), "IMU value")
    check_magnitude(table, values[:, 0:3], MAX_GYRO_RAD_S, "IMU angular rate [rad/s]")
    check_magnitude(table, values[:, 3:6], MAX_ACCEL_M_S2, "IMU acceleration [m/s^2]")
    check_increasing(table, stamps, "IMU")
    if not len(table):
        raise DatasetFormatError(path, "IMU file has no data rows")
    return ImuData(stamps, values[:, 0:3], values[:, 3:6])


MAX_WHEEL_SPEED_M_S = 100.0
"""Largest |forward speed| a wheel odometry file may hold (m/s)."""
MAX_WHEEL_YAW_RATE_RAD_S = 100.0
"""Largest |yaw rate| a wheel odometry file may hold (rad/s)."""
WHEEL_FILE = "wheel_odometry.csv"
"""Wheel odometry beside ``mav0/`` (amrvio's simulator writes it there)."""


def read_wheel_csv(path: Path) -> WheelData:
    """Wheel odometry: ``timestamp_ns, v_forward_m_s, yaw_rate_rad_s[, ...]`` (further columns,
    such as the simulator's ground truth, are ignored)."""
    table = read_table(path, ",", "wheel odometry file")
    check_columns(table, 3, "wheel odometry row")
    stamps = int_column(table, 0, "wheel odometry timestamp [ns]")
    values = float_columns(table, range(1, 3), "wheel odometry value")
    check_magnitude(table, values[:, 0:1], MAX_WHEEL_SPEED_M_S, "wheel forward speed [m/s]")
    check_magnitude(table, values[:, 1:2], MAX_WHEEL_YAW_RATE_RAD_S, "wheel yaw rate [rad/s]")
    check_increasing(table, stamps, "wheel odometry")
    if len(table) < 2:
        raise DatasetFormatError(path, "wheel odometry file needs at least 2 data rows")
    return WheelData(stamps, values[:, 0], values[:, 1])


def warn_missing_images(path: Path, n_missing: int, n_rows: int) -> None:
    """One warning that counts the rows skipped because their image file is missing (none when
    every row misses its image: the reader's error then says so, in one line)."""
    if n_missing and n_missing < n_rows:
        log.warning(
            "%s: skipped %d of %d rows whose image file is missing", path, n_missing, n_rows
        )


def frame_name(frame: Frame) -> str:
    """The image file of ``frame``, or ``frame K (t=... ns)`` when it has none (bag, zip)."""
    loader = frame.loader
    if frame.path is not None:
        return str(frame.path)
    described = getattr(loader, "where", None)
    if isinstance(described, str):
        return described
    return f"frame {frame.index} (t={frame.t_ns} ns)"


MAX_LEADING_BAD_IMAGES = 10
"""How many unusable images at the start of a recording the readers pass over to find its size."""


def first_image_shape(frames: Sequence[Frame]) -> tuple[tuple[int, int], str]:
    """(height, width) of the first usable frame and a name for it.

    An unusable first image (truncated, undecodable) is passed over as the pipeline passes over
    it, up to :data:`MAX_LEADING_BAD_IMAGES`; after that, or when no image is usable, the first
    one's error is raised.
    """
    if not frames:
        raise DatasetFormatError("<dataset>", "the dataset has no frames")
    first_err: DatasetFormatError | None = None
    for frame in frames[:MAX_LEADING_BAD_IMAGES + 1]:
        try:
            img = frame.load()
        except DatasetFormatError as err:
            first_err = first_err or err
            continue
        return (int(img.shape[0]), int(img.shape[1])), frame_name(frame)
    if first_err is None:  # unreachable: the loop ran at least once
        raise DatasetFormatError("<dataset>", "the dataset has no frames")
    raise first_err


@dataclass(frozen=True, slots=True)
class SkippedFrame:
    """A frame whose image cannot be used: ``index`` and ``t_ns`` in the dataset, ``file`` (the
    image, or a description for a bag or zip member) and the ``problem``."""

    index: int
    t_ns: int
    file: str
    problem: str

    def line(self) -> str:
        """``FILE: problem`` (one line)."""
        return f"{self.file}: {self.problem}"


def load_checked(frame: Frame, size_hw: tuple[int, int] | None) -> U8 | SkippedFrame:
    """The frame's (H, W) uint8 image, or why it cannot be used: it cannot be read or decoded
    (see :mod:`amrvio.io.image`), or its (height, width) differs from ``size_hw`` (the size of
    the recording's other images, which the calibration is for).

    A differing size is a skip, not an error: one odd file in a recording (a frame written by
    another tool, a thumbnail) must not cost the whole run, and the calibration cannot be used
    on it, so the frame cannot be tracked. The skip is counted and names the file.
    """
    try:
        img = frame.load()
    except DatasetFormatError as err:
        return SkippedFrame(frame.index, frame.t_ns, err.path, err.problem)
    if size_hw is not None and (img.shape[0], img.shape[1]) != size_hw:
        return SkippedFrame(
            frame.index, frame.t_ns, frame_name(frame),
            f"image is {img.shape[1]}x{img.shape[0]} but the recording's images are "
            f"{size_hw[1]}x{size_hw[0]}",
        )
    return img


def rethrow_as_dataset_error(err: InputFileError) -> DatasetFormatError:
    """A DatasetFormatError with the same path, line and problem (for errors from other readers)."""
    return DatasetFormatError(err.path, err.problem, err.line)


def to_grey_u8(img: NDArray[np.generic], where: str) -> U8:
    """A decoded image (grey, BGR or BGRA; 8 or 16 bit) as (H, W) uint8 grey, checked
    (:func:`amrvio.io.image.to_grey`)."""
    return to_grey(img, where)
