"""One streaming interface over every recording format amrvio reads.

A :class:`Dataset` holds time-ordered :class:`~amrvio.types.sensors.Frame` objects (images are read
only by ``Frame.load()``), the IMU stream, the calibration and the ground truth when the recording
has them. :meth:`Dataset.stream` merges frames and IMU samples by time.

``open_dataset("euroc:PATH")`` (or ``tumvi:``, ``tum-mono:``, ``kitti:``, ``bag:``, ``folder:``, or a
bare PATH whose format is detected) returns one. The readers live in ``amrvio/io/{asl,tum_mono,kitti,
rosbag,folder}.py``; this module also holds the small text-table parser they share, which reports bad
input as ``DatasetFormatError(path, problem, line)``.
"""

from __future__ import annotations

import itertools
import logging
import re
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from amrvio.errors import CalibrationError, DatasetFormatError, InputFileError
from amrvio.types.camera import CameraModel
from amrvio.types.lie import SE3
from amrvio.types.sensors import Frame, ImuData, ImuNoise, ImuSample
from amrvio.types.trajectory import Trajectory

log = logging.getLogger(__name__)

KINDS: tuple[str, ...] = ("euroc", "tumvi", "tum-mono", "kitti", "bag", "folder")

F64 = NDArray[np.float64]
I64 = NDArray[np.int64]


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


# ------------------------------------------------------------------------------------------------
# Opening a dataset
# ------------------------------------------------------------------------------------------------


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
        from amrvio.io.asl import read_asl

        return read_asl(path, kind=kind, calib=calib_path)
    if kind == "tum-mono":
        from amrvio.io.tum_mono import read_tum_mono

        return read_tum_mono(path, calib=calib_path)
    if kind == "kitti":
        from amrvio.io.kitti import read_kitti_odometry

        return read_kitti_odometry(path, calib=calib_path)
    if kind == "bag":
        from amrvio.io.rosbag import read_bag

        return read_bag(path, calib=calib_path, image_topic=image_topic, imu_topic=imu_topic)
    from amrvio.io.folder import read_folder

    return read_folder(path, calib=calib_path)


# ------------------------------------------------------------------------------------------------
# Text tables shared by the readers
# ------------------------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class TextTable:
    """Rows of a CSV or whitespace table. lines[i] is the 1-based file line of rows[i]."""

    path: Path
    header: tuple[str, ...] | None
    rows: tuple[tuple[str, ...], ...]
    lines: tuple[int, ...]

    def __len__(self) -> int:
        return len(self.rows)


def _looks_numeric(field: str) -> bool:
    try:
        float(field)
    except ValueError:
        return False
    return True


def _looks_like_names(fields: Sequence[str]) -> bool:
    first = fields[0].lstrip()
    return not any(map(_looks_numeric, fields)) and not first[:1].isdigit()


def read_table(
    path: Path, delimiter: str | None = ",", what: str = "file", allow_header: bool = True
) -> TextTable:
    """Read a text table: blank lines skipped, ``#`` lines are comments.

    With ``allow_header``, the first ``#`` line before any data, or a first line that looks like
    column names (no field is a number, the first does not start with a digit), is the header.
    ``delimiter=None`` splits on whitespace. Fields are stripped.
    """
    try:
        text = path.read_text(encoding="utf-8", errors="strict")
    except FileNotFoundError:
        raise DatasetFormatError(path, f"{what} is missing") from None
    except UnicodeDecodeError:
        raise DatasetFormatError(path, f"{what} is not a UTF-8 text file") from None
    except OSError as err:
        raise DatasetFormatError(path, f"cannot read {what}: {err.strerror}") from None
    header: tuple[str, ...] | None = None
    rows: list[tuple[str, ...]] = []
    lines: list[int] = []
    for number, raw in enumerate(text.splitlines(), start=1):
        line = raw.strip()
        if not line:
            continue
        if line.startswith("#") or line.startswith("%"):
            if allow_header and header is None and not rows and line.startswith("#"):
                header = _split(line.lstrip("#"), delimiter)
            continue
        fields = _split(line, delimiter)
        if allow_header and not rows and header is None and _looks_like_names(fields):
            header = fields
            continue
        rows.append(fields)
        lines.append(number)
    return TextTable(path, header, tuple(rows), tuple(lines))


def _split(line: str, delimiter: str | None) -> tuple[str, ...]:
    if delimiter is None:
        return tuple(line.split())
    parts = line.split(delimiter)
    if " " in line or "\t" in line:
        return tuple(f.strip() for f in parts)
    return tuple(parts)


def check_columns(table: TextTable, n_min: int, what: str, n_max: int | None = None) -> None:
    """Every row has between n_min and n_max fields (n_max None: no upper limit)."""
    lengths = set(map(len, table.rows))
    fits = all(n >= n_min and (n_max is None or n <= n_max) for n in lengths)
    if fits and not any("" in row[:n_min] for row in table.rows):
        return
    for row, line in zip(table.rows, table.lines, strict=True):
        if len(row) < n_min or (n_max is not None and len(row) > n_max):
            expect = f"{n_min}" if n_max == n_min else f"at least {n_min}"
            if n_max is not None and n_max != n_min:
                expect = f"{n_min} to {n_max}"
            raise DatasetFormatError(
                table.path, f"{what}: expected {expect} columns, found {len(row)}", line
            )
        if any(f == "" for f in row[:n_min]):
            raise DatasetFormatError(table.path, f"{what}: an empty column", line)


def _parsed_column(
    table: TextTable, col: int, what: str, parse: Callable[[str], int], expected: str
) -> I64:
    out = np.empty(len(table), dtype=np.int64)
    for i, (row, line) in enumerate(zip(table.rows, table.lines, strict=True)):
        try:
            out[i] = parse(row[col])
        except (ValueError, OverflowError):
            raise DatasetFormatError(
                table.path, f"{what}: {row[col]!r} is not {expected}", line
            ) from None
    return out


def int_column(table: TextTable, col: int, what: str) -> I64:
    """Column ``col`` as int64 (for example nanosecond timestamps)."""
    return _parsed_column(table, col, what, int, "an integer")


def float_columns(table: TextTable, cols: Sequence[int], what: str) -> F64:
    """Columns ``cols`` as an (N, len(cols)) float64 array; non-numbers and NaN/inf are errors."""
    cols = list(cols)
    block = [[row[c] for c in cols] for row in table.rows]
    try:
        flat = map(float, itertools.chain.from_iterable(block))
        out = np.fromiter(flat, dtype=np.float64, count=len(block) * len(cols))
        out = out.reshape(len(block), len(cols))
    except ValueError:
        for vals, line in zip(block, table.lines, strict=True):
            for v in vals:
                try:
                    float(v)
                except ValueError:
                    raise DatasetFormatError(
                        table.path, f"{what}: {v!r} is not a number", line
                    ) from None
        raise
    finite = np.isfinite(out)
    if not np.all(finite):
        bad = int(np.flatnonzero(~np.all(finite, axis=1))[0])
        raise DatasetFormatError(table.path, f"{what}: non-finite value (NaN or inf)", table.lines[bad])
    return out


_DECIMAL = re.compile(r"^([+-]?)(\d*)(?:\.(\d*))?$")


def seconds_to_ns(text: str) -> int:
    """A decimal seconds string to integer nanoseconds, exact for plain decimals (no float rounding)."""
    m = _DECIMAL.match(text)
    if m is not None and (m.group(2) or m.group(3)):
        sign = -1 if m.group(1) == "-" else 1
        whole = int(m.group(2) or "0")
        frac = (m.group(3) or "")[:9].ljust(9, "0")
        # Round half up on the tenth fractional digit.
        extra = (m.group(3) or "")[9:10]
        ns = whole * 1_000_000_000 + int(frac) + (1 if extra and int(extra) >= 5 else 0)
        return sign * ns
    value = float(text)  # exponent notation, e.g. KITTI's "1.037359e-01"
    if not np.isfinite(value):
        raise ValueError(f"non-finite time {text!r}")
    return int(round(value * 1e9))


def seconds_column_ns(table: TextTable, col: int, what: str) -> I64:
    """Column ``col`` of decimal seconds as int64 nanoseconds."""
    return _parsed_column(table, col, what, seconds_to_ns, "a finite time in seconds")


def check_increasing(table: TextTable, stamps_ns: I64, what: str) -> None:
    """Timestamps strictly increase; the error names the first line that goes backwards."""
    if stamps_ns.shape[0] < 2:
        return
    bad = np.flatnonzero(np.diff(stamps_ns) <= 0)
    if bad.size:
        i = int(bad[0]) + 1
        kind = "repeats" if stamps_ns[i] == stamps_ns[i - 1] else "goes backwards"
        raise DatasetFormatError(
            table.path, f"{what}: timestamp {int(stamps_ns[i])} {kind}", table.lines[i]
        )


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


# ------------------------------------------------------------------------------------------------
# Frames, images and calibration helpers shared by the readers
# ------------------------------------------------------------------------------------------------


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
    line = _line_of_key(path, ("resolution", "Camera.width", "image_width", "width"))
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


def _line_of_key(path: Path, keys: Sequence[str]) -> int | None:
    try:
        lines = path.read_text(encoding="utf-8", errors="replace").splitlines()
    except OSError:
        return None
    for number, line in enumerate(lines, start=1):
        stripped = line.strip()
        if any(stripped.startswith(k + ":") for k in keys):
            return number
    return None


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


def rethrow_as_dataset_error(err: InputFileError) -> DatasetFormatError:
    """A DatasetFormatError with the same path, line and problem (for errors from other readers)."""
    return DatasetFormatError(err.path, err.problem, err.line)


# ------------------------------------------------------------------------------------------------
# Calibration files (parsed by amrvio.io.calib, except the ORB-SLAM3 settings yaml read here)
# ------------------------------------------------------------------------------------------------


def _opencv_yaml(path: Path) -> dict[str, object]:
    """An OpenCV FileStorage yaml (``%YAML:1.0`` header, ``!!opencv-matrix``) as a dict."""
    import yaml

    class _Loader(yaml.SafeLoader):
        pass

    def _matrix(loader: yaml.SafeLoader, node: yaml.MappingNode) -> NDArray[np.float64]:
        m = loader.construct_mapping(node, deep=True)
        try:
            return np.array(m["data"], dtype=np.float64).reshape(int(m["rows"]), int(m["cols"]))
        except (KeyError, ValueError, TypeError) as err:
            raise CalibrationError(
                path, f"bad opencv-matrix ({err})", node.start_mark.line + 1
            ) from None

    _Loader.add_constructor("tag:yaml.org,2002:opencv-matrix", _matrix)
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as err:
        raise CalibrationError(path, f"cannot read calibration file ({err})") from None
    text = "\n".join("" if ln.startswith("%YAML") else ln for ln in text.splitlines())
    try:
        data = yaml.load(text, Loader=_Loader)  # noqa: S506 - SafeLoader subclass
    except yaml.YAMLError as err:
        mark = getattr(err, "problem_mark", None)
        line = None if mark is None else int(mark.line) + 1
        problem = getattr(err, "problem", None) or "invalid YAML"
        raise CalibrationError(path, f"invalid YAML: {problem}", line) from None
    if not isinstance(data, dict):
        raise CalibrationError(path, "calibration yaml is not a mapping of keys to values")
    return data


def read_orbslam_settings(path: Path) -> tuple[CameraModel, SE3 | None]:
    """Camera and ``T_body_cam`` from an ORB-SLAM3 settings yaml (``Camera1.fx`` or ``Camera.fx``).

    ``Camera.type`` PinHole (radtan k1 k2 p1 p2 [k3]) or KannalaBrandt8 (k1..k4); the image size is
    ``Camera.width/height``; ``IMU.T_b_c1`` (or ``Tbc``) is the camera pose in the body frame.
    """
    from amrvio.types.camera import camera_from_params

    data = _opencv_yaml(path)
    prefix = "Camera1." if "Camera1.fx" in data else "Camera."

    def num(key: str, default: float | None = None) -> float:
        value = data.get(key, default)
        if value is None:
            raise CalibrationError(path, f"key {key} is missing")
        try:
            out = float(value)  # type: ignore[arg-type]
        except (TypeError, ValueError):
            raise CalibrationError(
                path, f"{key} must be a number, got {value!r}", _line_of_key(path, [key])
            ) from None
        if not np.isfinite(out):
            raise CalibrationError(path, f"{key} is not finite", _line_of_key(path, [key]))
        return out

    cam_type = str(data.get("Camera.type", "PinHole")).strip().lower()
    intr = [num(prefix + k) for k in ("fx", "fy", "cx", "cy")]
    size = [num("Camera.width"), num("Camera.height")]
    if cam_type == "pinhole":
        dist = [num(prefix + k, 0.0) for k in ("k1", "k2", "p1", "p2")]
        k3 = num(prefix + "k3", 0.0)
        dist_model = "radtan" if any(dist) or k3 else "none"
        coeffs = dist + ([k3] if k3 else []) if dist_model == "radtan" else []
    elif cam_type == "kannalabrandt8":
        dist_model, coeffs = "equidistant", [num(prefix + k, 0.0) for k in ("k1", "k2", "k3", "k4")]
    else:
        raise CalibrationError(
            path, f"Camera.type {cam_type!r} is not supported (PinHole or KannalaBrandt8)",
            _line_of_key(path, ["Camera.type"]),
        )
    try:
        camera = camera_from_params("pinhole", dist_model, intr, coeffs, size)
    except ValueError as err:
        raise CalibrationError(path, str(err)) from None
    T_body_cam = None
    for key in ("IMU.T_b_c1", "Tbc"):
        if key in data:
            T_body_cam = _se3_from(data[key], path, key)
            break
    return camera, T_body_cam


def _se3_from(value: object, path: Path, key: str) -> SE3:
    m = np.asarray(value, dtype=np.float64)
    line = _line_of_key(path, [key])
    if m.shape == (16,):
        m = m.reshape(4, 4)
    if m.shape != (4, 4) or not np.all(np.isfinite(m)):
        raise CalibrationError(path, f"{key} must be a finite 4x4 matrix", line)
    R = m[:3, :3]
    if np.abs(R @ R.T - np.eye(3)).max() > 1e-3:
        raise CalibrationError(path, f"{key} rotation is not orthonormal", line)
    return SE3.from_matrix(m)


def load_calibration(path: Path, image_hw: tuple[int, int]) -> tuple[CameraModel, SE3 | None]:
    """Camera and ``T_body_cam`` (None when the file has no extrinsics) from a calibration file.

    Detected by content: ORB-SLAM3 settings yaml (``Camera1.fx``), Kalibr camchain (``cam0:``),
    EuRoC sensor.yaml (``T_BS``), KITTI calib.txt (``P0:``; size from ``image_hw``), else a DSO
    camera.txt.
    """
    from amrvio.io import calib as cal

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
    from amrvio.io import calib as cal

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
    from amrvio.io import calib as cal

    response = None if pcalib_path is None else cal.read_pcalib(pcalib_path)
    vignette = None if vignette_path is None else cal.read_vignette(vignette_path)
    if vignette is not None and vignette_path is not None:
        check_vignette_size(vignette, image_hw, vignette_path)
    return response, vignette
