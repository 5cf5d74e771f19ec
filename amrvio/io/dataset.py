"""Which reader opens a recording: the dataset spec, format detection and :func:`open_dataset`.

``open_dataset("euroc:PATH")`` (or ``tumvi:``, ``tum-mono:``, ``kitti:``, ``bag:``, ``folder:``, or a
bare PATH whose format is detected) returns a :class:`~amrvio.io.base.Dataset` (re-exported here).
The readers live in ``amrvio/io/{asl,tum_mono,kitti,rosbag,folder}.py`` and never import this
module; the text tables they share are :mod:`amrvio.io.table`, the calibration they load is
:mod:`amrvio.io.calib_load`.
"""

from __future__ import annotations

import re
from pathlib import Path

from amrvio.errors import CalibrationError, DatasetFormatError
from amrvio.io.asl import read_asl
from amrvio.io.base import KINDS, Dataset
from amrvio.io.folder import read_folder
from amrvio.io.kitti import read_kitti_odometry
from amrvio.io.rosbag import read_bag
from amrvio.io.tum_mono import read_tum_mono

__all__ = ["KINDS", "Dataset", "detect_kind", "open_dataset", "parse_spec"]


def parse_spec(spec: str | Path) -> tuple[str | None, Path]:
    """Split ``"kind:PATH"`` into (kind, PATH); a bare PATH gives (None, PATH)."""
    text = str(spec)
    head, sep, rest = text.partition(":")
    if sep and head in KINDS:
        return head, Path(rest).expanduser()
    return None, Path(text).expanduser()


def detect_kind(path: Path) -> str:
    """The format of a bare PATH (see the module docstring of each reader)."""
    if not path.exists():
        raise DatasetFormatError(path, "dataset path does not exist")
    if path.is_file():
        if path.suffix in (".bag", ".db3", ".mcap"):
            return "bag"
        raise DatasetFormatError(
            path, "a dataset is a folder, a .bag file or a ROS2 bag folder; got a plain file"
        )
    if (path / "metadata.yaml").is_file():
        return "bag"
    if (path / "dso").is_dir() and (path / "mav0").is_dir():
        return "tumvi"
    if (path / "mav0").is_dir() or (path.name == "mav0" and (path / "cam0").is_dir()):
        return "euroc"
    if (path / "image_0").is_dir() and (path / "calib.txt").is_file():
        return "kitti"
    if (path / "times.txt").is_file() and (
        (path / "images").is_dir() or (path / "images.zip").is_file()
    ):
        return "tum-mono"
    return "folder"


def open_dataset(
    spec: str | Path,
    calib: str | Path | None = None,
    *,
    image_topic: str | None = None,
    imu_topic: str | None = None,
) -> Dataset:
    """Open a recording named ``"kind:PATH"`` or a bare PATH (format detected).

    ``calib`` overrides the calibration the dataset ships (Kalibr camchain.yaml, EuRoC
    sensor.yaml, ORB-SLAM3 settings yaml, DSO camera.txt or KITTI calib.txt). ``image_topic`` and
    ``imu_topic`` choose bag topics. Bad files raise ``DatasetFormatError``/``CalibrationError``.
    """
    kind, path = parse_spec(spec)
    if kind is None:
        head, sep, _ = str(spec).partition(":")
        if sep and not path.exists() and re.fullmatch(r"[a-z][a-z0-9_-]+", head):
            raise DatasetFormatError(
                spec, f"unknown dataset kind {head!r}; use one of {', '.join(KINDS)} or a bare PATH"
            )
        kind = detect_kind(path)
    elif not path.exists():
        raise DatasetFormatError(path, f"{kind} dataset path does not exist")
    calib_path = None if calib is None else Path(calib).expanduser()
    if calib_path is not None and not calib_path.is_file():
        raise CalibrationError(calib_path, "calibration file does not exist")
    if kind in ("euroc", "tumvi"):
        return read_asl(path, kind=kind, calib=calib_path)
    if kind == "tum-mono":
        return read_tum_mono(path, calib=calib_path)
    if kind == "kitti":
        return read_kitti_odometry(path, calib=calib_path)
    if kind == "bag":
        return read_bag(path, calib=calib_path, image_topic=image_topic, imu_topic=imu_topic)
    return read_folder(path, calib=calib_path)
