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
from amrvio.io.table import (
    check_columns,
    check_increasing,
    float_columns,
    int_column,
    read_table,
)
from amrvio.types.camera import CameraModel
from amrvio.types.lie import SE3
from amrvio.types.sensors import Frame, ImuData, ImuNoise, ImuSample
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
    pcalib.txt; vignette: (H, W) in [0, 1] from vignette.png.
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


def read_imu_csv(path: Path) -> ImuData:
    """EuRoC imu0 layout: ``t_ns, w_x, w_y, w_z [rad/s], a_x, a_y, a_z [m/s^2]``."""
    table = read_table(path, ",", "IMU file")
    check_columns(table, 7, "IMU row")
    stamps = int_column(table, 0, "IMU timestamp [ns]")
    values = float_columns(table, range(1, 7), "IMU value")
    check_increasing(table, stamps, "IMU")
    if not len(table):
        raise DatasetFormatError(path, "IMU file has no data rows")
    return ImuData(stamps, values[:, 0:3], values[:, 3:6])


def warn_missing_images(path: Path, n_missing: int, n_rows: int) -> None:
    """One warning that counts the rows skipped because their image file is missing."""
    if n_missing:
        log.warning(
            "%s: skipped %d of %d rows whose image file is missing", path, n_missing, n_rows
        )


def first_image_shape(frames: Sequence[Frame]) -> tuple[tuple[int, int], str]:
    """(height, width) of the first frame and a name for it (reads that one image only)."""
    if not frames:
        raise DatasetFormatError("<dataset>", "the dataset has no frames")
    first = frames[0]
    img = first.load()
    name = str(first.path) if first.path is not None else f"frame 0 (t={first.t_ns} ns)"
    return (int(img.shape[0]), int(img.shape[1])), name


def rethrow_as_dataset_error(err: InputFileError) -> DatasetFormatError:
    """A DatasetFormatError with the same path, line and problem (for errors from other readers)."""
    return DatasetFormatError(err.path, err.problem, err.line)


def to_grey_u8(img: NDArray[np.generic], where: str) -> U8:
    """A decoded image (grey, BGR or BGRA; 8 or 16 bit) as (H, W) uint8 grey."""
    import cv2

    if img.ndim == 3:
        code = cv2.COLOR_BGRA2GRAY if img.shape[2] == 4 else cv2.COLOR_BGR2GRAY
        img = cv2.cvtColor(img, code)
    if img.dtype == np.uint16:
        img = (img.astype(np.uint16) >> 8).astype(np.uint8)
    if img.dtype != np.uint8 or img.ndim != 2:
        raise DatasetFormatError(where, f"unsupported image format {img.dtype} {img.shape}")
    return np.asarray(img, dtype=np.uint8)
