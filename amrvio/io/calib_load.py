"""The calibration a reader loads: the file format detected by content, checked against the images.

The file formats themselves are parsed by :mod:`amrvio.io.calib` and :mod:`amrvio.io.orbslam`;
this module picks the parser, and reports a size mismatch as a ``CalibrationError`` that names
the calibration file and its size line.
"""

from __future__ import annotations

import re
from collections.abc import Sequence
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from amrvio.errors import CalibrationError
from amrvio.io import calib as cal
from amrvio.io.orbslam import line_of_key, read_orbslam_settings
from amrvio.types.camera import CameraModel
from amrvio.types.lie import SE3
from amrvio.types.sensors import ImuNoise

F64 = NDArray[np.float64]


def _size_mismatch(
    calib_path: Path, calib_wh: tuple[int, int], image_hw: tuple[int, int], image_name: str,
    line: int | None,
) -> CalibrationError:
    return CalibrationError(
        calib_path,
        f"calibration is for {calib_wh[0]}x{calib_wh[1]} images but {image_name} is "
        f"{image_hw[1]}x{image_hw[0]}; give the calibration of this camera (--calib FILE, or "
        "open_dataset(..., calib=PATH))",
        line,
    )


def check_camera_size(
    camera: CameraModel, image_hw: tuple[int, int], calib_path: Path, image_name: str
) -> None:
    """CalibrationError naming ``calib_path`` and its size line when the camera size differs."""
    h, w = image_hw
    if (camera.width, camera.height) != (w, h):
        raise _size_mismatch(
            calib_path, (camera.width, camera.height), image_hw, image_name, _size_line(calib_path)
        )


def check_vignette_size(vignette: F64, image_hw: tuple[int, int], path: Path) -> None:
    if tuple(vignette.shape) != tuple(image_hw):
        raise CalibrationError(
            path,
            f"vignette is {vignette.shape[1]}x{vignette.shape[0]} but the images are "
            f"{image_hw[1]}x{image_hw[0]}",
        )


def _size_line(path: Path) -> int | None:
    """The line that holds the image size: a yaml size key, else line 2 of a DSO camera.txt."""
    line = line_of_key(path, ("resolution", "Camera.width", "image_width", "width"))
    if line is not None or path.suffix.lower() in (".yaml", ".yml"):
        return line
    try:
        lines = path.read_text(encoding="utf-8", errors="replace").splitlines()
    except OSError:
        return None
    if any(ln.strip().startswith("P0:") for ln in lines):
        return None  # KITTI calib.txt: no size in the file
    filled = [n for n, ln in enumerate(lines, start=1) if ln.strip()]
    return filled[1] if len(filled) > 1 else None


_RESOLUTION = re.compile(r"^\s*resolution\s*:\s*\[\s*(\d+)\s*,\s*(\d+)\s*\]")


def declared_resolution(path: Path) -> tuple[int, int, int] | None:
    """``(width, height, line)`` from a ``resolution: [w, h]`` line, read without a YAML parser.

    Lets a reader report a size mismatch even when the rest of a sensor.yaml does not parse.
    """
    try:
        lines = path.read_text(encoding="utf-8", errors="replace").splitlines()
    except OSError:
        return None
    for number, line in enumerate(lines, start=1):
        m = _RESOLUTION.match(line)
        if m is not None:
            return int(m.group(1)), int(m.group(2)), number
    return None


def check_declared_resolution(path: Path, image_hw: tuple[int, int], image_name: str) -> None:
    """Size check on the ``resolution:`` line of a calibration file before parsing it fully."""
    found = declared_resolution(path)
    if found is None:
        return
    w, h, line = found
    if (w, h) != (image_hw[1], image_hw[0]):
        raise _size_mismatch(path, (w, h), image_hw, image_name, line)


def load_calibration(path: Path, image_hw: tuple[int, int]) -> tuple[CameraModel, SE3 | None]:
    """Camera and ``T_body_cam`` (None when the file has no extrinsics) from a calibration file.

    Detected by content: ORB-SLAM3 settings yaml (``Camera1.fx``), Kalibr camchain (``cam0:``),
    EuRoC sensor.yaml (``T_BS``), KITTI calib.txt (``P0:``; size from ``image_hw``), else a DSO
    camera.txt.
    """
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as err:
        raise CalibrationError(path, f"cannot read calibration file ({err})") from None
    if path.suffix.lower() in (".yaml", ".yml"):
        if re.search(r"^\s*Camera1?\.fx\s*:", text, re.MULTILINE):
            return read_orbslam_settings(path)
        if re.search(r"^cam0\s*:", text, re.MULTILINE):
            chain = cal.read_kalibr_camchain(path)
            T_cam_imu = chain.T_cam_imu
            return chain.camera, None if T_cam_imu is None else T_cam_imu.inverse()
        euroc = cal.read_euroc_camera(path)
        return euroc.camera, euroc.T_body_cam
    if re.search(r"^\s*P0\s*:", text, re.MULTILINE):
        return cal.read_kitti_calib(path, image_hw[1], image_hw[0]), None
    return cal.read_dso_camera(path).camera, None


def load_checked_calibration(
    calib_path: Path | None, image_hw: tuple[int, int], image_name: str
) -> tuple[CameraModel | None, SE3 | None]:
    """:func:`load_calibration` of ``calib_path`` checked against the (height, width) of the
    images (``image_name`` names one in the error); (None, None) when ``calib_path`` is None."""
    if calib_path is None:
        return None, None
    check_declared_resolution(calib_path, image_hw, image_name)
    camera, T_body_cam = load_calibration(calib_path, image_hw)
    check_camera_size(camera, image_hw, calib_path, image_name)
    return camera, T_body_cam


def read_imu_noise_file(path: Path) -> ImuNoise:
    """IMU noise from an EuRoC imu0 sensor.yaml or a Kalibr imu.yaml / TUM-VI imu_config.yaml."""
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as err:
        raise CalibrationError(path, f"cannot read IMU noise file ({err})") from None
    if re.search(r"^sensor_type\s*:", text, re.MULTILINE):
        return cal.read_euroc_imu(path)
    return cal.read_kalibr_imu(path)


def find_photometric(dirs: Sequence[Path]) -> tuple[Path | None, Path | None]:
    """The first ``pcalib.txt`` and the first ``vignette.png`` found in ``dirs`` (in order)."""
    pcalib = next((d / "pcalib.txt" for d in dirs if (d / "pcalib.txt").is_file()), None)
    vignette = next((d / "vignette.png" for d in dirs if (d / "vignette.png").is_file()), None)
    return pcalib, vignette


def read_photometric(
    pcalib_path: Path | None, vignette_path: Path | None, image_hw: tuple[int, int]
) -> tuple[F64 | None, F64 | None]:
    """(inverse response (256,), vignette (H, W)) read by amrvio.io.calib; None where absent.

    A vignette whose size differs from ``image_hw`` (height, width) is a CalibrationError.
    """
    response = None if pcalib_path is None else cal.read_pcalib(pcalib_path)
    vignette = None if vignette_path is None else cal.read_vignette(vignette_path)
    if vignette is not None and vignette_path is not None:
        check_vignette_size(vignette, image_hw, vignette_path)
    return response, vignette
