"""EuRoC / ASL and TUM-VI recordings.

Layout (EuRoC): ``[PATH/]mav0/cam0/{data.csv, data/*.png, sensor.yaml}``, ``mav0/imu0/{data.csv,
sensor.yaml}``, and ground truth in ``mav0/state_groundtruth_estimate0/data.csv`` (or
``mav0/mocap0/data.csv``) when present. TUM-VI ships the same ``mav0/`` tree (ground truth in
``mocap0``, no cam0 sensor.yaml) plus ``dso/`` with ``camchain.yaml`` (Kalibr), ``imu_config.yaml``
and ``cam0/{times.txt (id t_s exposure_ms), pcalib.txt, vignette.png}``; its 16-bit PNGs are read
as 8-bit by ``Frame.load``. Exposure times come from a DSO-style ``times.txt`` (``id t_s
exposure_ms``) in ``dso/cam0/``, beside ``mav0/`` (amrvio's simulator) or in ``cam0/``.

A ``data.csv`` row whose image file is missing is skipped, with one warning that counts them.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from amrvio.errors import DatasetFormatError, TrajectoryFormatError
from amrvio.io.base import (
    WHEEL_FILE,
    Dataset,
    first_image_shape,
    read_imu_csv,
    read_wheel_csv,
    rethrow_as_dataset_error,
    warn_missing_images,
)
from amrvio.io.calib_load import (
    find_photometric,
    load_checked_calibration,
    read_imu_noise_file,
    read_photometric,
)
from amrvio.io.image import ImageFile
from amrvio.io.table import (
    TextTable,
    check_columns,
    check_increasing,
    float_columns,
    int_column,
    read_table,
    seconds_column_ns,
)
from amrvio.io.trajectory import read_euroc_csv
from amrvio.types.sensors import Frame
from amrvio.types.trajectory import Trajectory


def find_mav0(path: Path) -> Path:
    """The ``mav0`` folder: PATH/mav0, or PATH itself when it is mav0 (or holds cam0/)."""
    if (path / "mav0").is_dir():
        return path / "mav0"
    if (path / "cam0").is_dir():
        return path
    raise DatasetFormatError(path, "not an ASL/EuRoC folder: neither mav0/ nor cam0/ found in it")


MAX_NAME_CHARS = 4096
"""Longest image name (a relative path) a data.csv row may give."""


def _is_file(path: Path) -> bool:
    try:
        return path.is_file()
    except OSError:  # a name too long for the file system, a loop of links
        return False


def read_asl_frames(cam_dir: Path) -> tuple[Frame, ...]:
    """Frames of ``cam_dir/data.csv`` (``t_ns, filename``); rows with a missing image are skipped."""
    csv_path = cam_dir / "data.csv"
    table = read_table(csv_path, ",", "camera data.csv")
    check_columns(table, 2, "camera row")
    stamps = int_column(table, 0, "timestamp [ns]")
    check_increasing(table, stamps, "camera")
    image_dir = cam_dir / "data"
    try:
        present = set(os.listdir(image_dir))
    except FileNotFoundError:
        raise DatasetFormatError(image_dir, "image folder is missing") from None
    except OSError as err:
        raise DatasetFormatError(image_dir, f"cannot list the image folder: {err.strerror}") from None
    frames: list[Frame] = []
    missing = 0
    for t_ns, row, line in zip(stamps.tolist(), table.rows, table.lines, strict=True):
        name = row[1]
        if len(name) > MAX_NAME_CHARS:
            raise DatasetFormatError(csv_path, f"image name of {len(name)} characters (at most "
                                               f"{MAX_NAME_CHARS})", line)
        if name not in present and not _is_file(image_dir / name):
            missing += 1
            continue
        image = image_dir / name
        frames.append(Frame(t_ns=int(t_ns), index=len(frames), path=image, loader=ImageFile(image)))
    warn_missing_images(csv_path, missing, len(table))
    if not frames:
        raise DatasetFormatError(csv_path, "no camera rows with an existing image file")
    return tuple(frames)


def attach_exposures(times_path: Path, frames: tuple[Frame, ...]) -> tuple[Frame, ...]:
    """Exposure times from a DSO-style ``times.txt`` (``id t_s exposure_ms``), matched by time.

    TUM-VI keeps it in ``dso/cam0/``; amrvio's simulator writes it beside ``mav0/``. A frame is
    matched by its exact nanosecond time (from ``t_s``, or from an ``id`` that is the time in ns);
    frames without a row keep ``exposure_s = None``.
    """
    table: TextTable = read_table(times_path, None, "times.txt", allow_header=False)
    check_columns(table, 3, "times.txt row", n_max=3)
    stamps = seconds_column_ns(table, 1, "time [s]")
    exposure_ms = float_columns(table, [2], "exposure [ms]")[:, 0]
    if np.any(exposure_ms < 0):
        bad = int(np.flatnonzero(exposure_ms < 0)[0])
        raise DatasetFormatError(times_path, "negative exposure time", table.lines[bad])
    by_ns = dict(zip(stamps.tolist(), exposure_ms.tolist(), strict=True))
    for row, e in zip(table.rows, exposure_ms.tolist(), strict=True):
        if row[0].isdigit() and len(row[0]) >= 16:  # TUM-VI: the id is the time in ns
            by_ns.setdefault(int(row[0]), e)
    return tuple(
        Frame(f.t_ns, f.index, f.path, by_ns[f.t_ns] / 1000.0 if f.t_ns in by_ns else None, f.loader)
        for f in frames
    )


def _groundtruth(mav: Path) -> Trajectory | None:
    for sub in ("state_groundtruth_estimate0", "mocap0"):
        gt_path = mav / sub / "data.csv"
        if gt_path.is_file():
            try:
                return read_euroc_csv(gt_path).trajectory
            except TrajectoryFormatError as err:
                raise rethrow_as_dataset_error(err) from None
    return None


def read_asl(path: Path, kind: str = "euroc", calib: Path | None = None) -> Dataset:
    """Open an EuRoC (``kind="euroc"``) or TUM-VI (``kind="tumvi"``) recording.

    ``calib`` overrides the camera calibration of the recording.
    """
    mav = find_mav0(path)
    cam_dir = mav / "cam0"
    if not cam_dir.is_dir():
        raise DatasetFormatError(mav, "cam0/ folder is missing")
    frames = read_asl_frames(cam_dir)
    base = mav.parent if mav.name == "mav0" else mav  # the folder that holds mav0/ and dso/
    dso = base / "dso"
    for times_path in (dso / "cam0" / "times.txt", base / "times.txt", cam_dir / "times.txt"):
        if times_path.is_file():
            frames = attach_exposures(times_path, frames)
            break
    image_hw, image_name = first_image_shape(frames)

    # Calibration: override, else TUM-VI camchain, else cam0/sensor.yaml.
    calib_path = calib
    if calib_path is None:
        for candidate in (dso / "camchain.yaml", cam_dir / "sensor.yaml"):
            if candidate.is_file():
                calib_path = candidate
                break
    camera, T_body_cam = load_checked_calibration(calib_path, image_hw, image_name)

    imu_path = mav / "imu0" / "data.csv"
    imu = read_imu_csv(imu_path) if imu_path.is_file() else None
    imu_noise = None
    for noise_path in (mav / "imu0" / "sensor.yaml", dso / "imu_config.yaml"):
        if imu is not None and noise_path.is_file():
            imu_noise = read_imu_noise_file(noise_path)
            break

    wheel_path = base / WHEEL_FILE
    wheel = read_wheel_csv(wheel_path) if wheel_path.is_file() else None
    groundtruth = _groundtruth(mav)
    pcalib_path, vignette_path = find_photometric(
        [cam_dir, dso / "cam0", mav, base, *sorted(base.glob("photometric*"))]
    )
    inverse_response, vignette = read_photometric(pcalib_path, vignette_path, image_hw)
    return Dataset(
        kind=kind,
        root=path,
        frames=frames,
        camera=camera,
        T_body_cam=T_body_cam,
        imu=imu,
        imu_noise=imu_noise,
        groundtruth=groundtruth,
        groundtruth_frame="body" if groundtruth is not None else "",
        inverse_response=None if inverse_response is None else np.asarray(inverse_response),
        vignette=vignette,
        wheel=wheel,
    )
