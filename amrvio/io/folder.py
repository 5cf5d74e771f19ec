"""A plain image folder with a timestamps CSV.

``PATH/timestamps.csv`` (or ``times.csv``, ``frames.csv``, ``data.csv``, or any ``*.csv`` whose
header names a file column) with a header naming the time column (``timestamp [ns]``, ``t_ns`` ->
integer nanoseconds; ``t_s``, ``time [s]`` -> seconds) and the ``filename`` column. Without a
header the file must have two columns ``time, filename`` (a time with ``.`` or ``e`` is in
seconds, else nanoseconds). Image names are relative to the CSV folder (or its ``images/`` /
``data/``). Optional beside it: ``imu.csv`` (EuRoC imu0 columns), a calibration (``camchain.yaml``,
``sensor.yaml``, ``camera.txt`` or ``calib.txt``), ``imu.yaml`` (Kalibr noise), ``pcalib.txt``,
``vignette.png``. A row whose image is missing is skipped (one warning that counts them).
"""

from __future__ import annotations

from pathlib import Path

from amrvio.errors import DatasetFormatError
from amrvio.io.base import Dataset, first_image_shape, read_imu_csv, warn_missing_images
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
    int_column,
    read_table,
    seconds_column_ns,
)
from amrvio.types.sensors import Frame

TIMESTAMP_FILES = ("timestamps.csv", "times.csv", "frames.csv", "data.csv")
IMU_FILES = ("imu.csv", "imu0.csv", "imu_data.csv", "imu0/data.csv")
CALIB_FILES = (
    "camchain.yaml",
    "camchain-imucam.yaml",
    "sensor.yaml",
    "calib.yaml",
    "camera.txt",
    "calib.txt",
)
_FILE_COLUMNS = ("filename", "file", "file_name", "image", "image_path", "path")
_NS_COLUMNS = ("timestamp [ns]", "timestamp", "t_ns", "timestamp_ns", "time [ns]", "stamp_ns")
_S_COLUMNS = ("t_s", "t [s]", "time [s]", "timestamp [s]", "timestamp_s", "time_s", "time", "t")


def _norm(name: str) -> str:
    return " ".join(name.strip().lower().split())


def find_timestamps_csv(path: Path) -> Path:
    """The timestamps CSV of a plain folder."""
    for name in TIMESTAMP_FILES:
        if (path / name).is_file():
            return path / name
    for candidate in sorted(path.glob("*.csv")):
        first = _first_line(candidate)
        if any(col in _norm(first).replace("#", " ") for col in _FILE_COLUMNS):
            return candidate
    raise DatasetFormatError(
        path,
        "not a recognised dataset: no timestamps CSV (timestamps.csv with columns "
        "'timestamp [ns]' or 't_s', and 'filename'), and not an EuRoC/TUM-VI/KITTI/TUM-mono/bag layout",
    )


def _first_line(path: Path) -> str:
    try:
        with path.open(encoding="utf-8", errors="replace") as fh:
            return fh.readline()
    except OSError:
        return ""


def _columns(table: TextTable) -> tuple[int, str, int]:
    """(time column, "ns" | "s", filename column) from the header or the first row."""
    if table.header is not None:
        names = [_norm(h) for h in table.header]
        t_col = next((i for i, n in enumerate(names) if n in _NS_COLUMNS + _S_COLUMNS), None)
        f_col = next((i for i, n in enumerate(names) if n in _FILE_COLUMNS), None)
        if t_col is None or f_col is None:
            missing = "a time column (timestamp [ns] or t_s)" if t_col is None else "filename"
            raise DatasetFormatError(
                table.path, f"header {list(table.header)} lacks {missing}", _header_line(table)
            )
        return t_col, ("ns" if names[t_col] in _NS_COLUMNS else "s"), f_col
    if not table.rows:
        raise DatasetFormatError(table.path, "timestamps file has no rows")
    first = table.rows[0][0]
    unit = "s" if any(c in first.lower() for c in ".e") else "ns"
    return 0, unit, 1


def _header_line(table: TextTable) -> int:
    return max(1, table.lines[0] - 1) if table.lines else 1


def _resolve_image(csv_dir: Path, name: str) -> Path | None:
    for base in (csv_dir, csv_dir / "images", csv_dir / "data"):
        candidate = base / name
        try:
            if candidate.is_file():
                return candidate
        except OSError:  # a name too long for the file system
            return None
    return None


def read_folder(path: Path, calib: Path | None = None) -> Dataset:
    """Open a plain image folder (see the module docstring); ``calib`` overrides its calibration."""
    if not path.is_dir():
        raise DatasetFormatError(path, "folder dataset: not a folder")
    csv_path = find_timestamps_csv(path)
    table = read_table(csv_path, ",", "timestamps CSV")
    t_col, unit, f_col = _columns(table)
    check_columns(table, max(t_col, f_col) + 1, "timestamps row")
    if unit == "ns":
        stamps = int_column(table, t_col, "timestamp [ns]")
    else:
        stamps = seconds_column_ns(table, t_col, "time [s]")
    check_increasing(table, stamps, "timestamps")
    frames: list[Frame] = []
    missing = 0
    for t_ns, row in zip(stamps.tolist(), table.rows, strict=True):
        image = _resolve_image(csv_path.parent, row[f_col])
        if image is None:
            missing += 1
            continue
        frames.append(Frame(int(t_ns), len(frames), image, loader=ImageFile(image)))
    warn_missing_images(csv_path, missing, len(table))
    if not frames:
        raise DatasetFormatError(csv_path, "no row names an existing image file")
    image_hw, image_name = first_image_shape(frames)

    calib_path = calib
    if calib_path is None:
        calib_path = next((path / n for n in CALIB_FILES if (path / n).is_file()), None)
    camera, T_body_cam = load_checked_calibration(calib_path, image_hw, image_name)

    imu_path = next((path / n for n in IMU_FILES if (path / n).is_file()), None)
    imu = None if imu_path is None else read_imu_csv(imu_path)
    imu_noise = None
    if imu is not None and (path / "imu.yaml").is_file():
        imu_noise = read_imu_noise_file(path / "imu.yaml")
    pcalib_path, vignette_path = find_photometric([path])
    response, vignette = read_photometric(pcalib_path, vignette_path, image_hw)
    return Dataset(
        kind="folder",
        root=path,
        frames=tuple(frames),
        camera=camera,
        T_body_cam=T_body_cam,
        imu=imu,
        imu_noise=imu_noise,
        inverse_response=response,
        vignette=vignette,
    )
