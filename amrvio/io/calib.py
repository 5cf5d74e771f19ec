"""Calibration readers (and some writers) for the formats the field uses.

Formats
-------
- Kalibr ``camchain.yaml`` (``cam0: {camera_model, distortion_model, intrinsics, distortion_coeffs,
  resolution, T_cam_imu}``) -> :class:`CameraCalib`; Kalibr ``imu.yaml`` -> :class:`ImuNoise`.
- EuRoC/ASL ``sensor.yaml`` of a camera (``T_BS``, intrinsics, distortion, ``rate_hz``) ->
  :class:`EurocCameraCalib` and of an IMU (noise densities) -> :class:`ImuNoise`; both writable.
  ``T_BS`` is the sensor pose in the body frame, i.e. ``T_body_sensor``.
- KITTI odometry ``calib.txt`` (``P0: 12 values``, row-major 3x4) -> :class:`PinholeCamera`.
- DSO / TUM-monoVO ``camera.txt`` -> :class:`DsoCameraCalib`.
- DSO ``pcalib.txt`` (256 inverse-response values G^-1) and ``vignette.png``; both writable.

Every problem with a file raises :class:`CalibrationError` whose message is one line
``path[:line]: problem``.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from amrvio.errors import CalibrationError, ShapeError
from amrvio.types.camera import (
    DISTORTION_COUNTS,
    CameraModel,
    EquidistantCamera,
    FovCamera,
    PinholeCamera,
    RadTanCamera,
    camera_from_params,
    canonical_distortion_model,
)
from amrvio.types.lie import SE3
from amrvio.types.sensors import ImuNoise

FloatArray = NDArray[np.float64]

# Largest |R R^T - I| accepted for a rotation read from a file: Kalibr and EuRoC print ~1e-12;
# hand-copied matrices with 5 decimals stay below 1e-4. The accepted matrix is re-orthonormalised.
_ORTHONORMAL_TOL = 1e-4
PCALIB_SIZE = 256


@dataclass(frozen=True, slots=True, eq=False)
class CameraCalib:
    """A camera and, when calibrated against an IMU, its extrinsics ``T_cam_imu`` (Kalibr).

    ``timeshift_cam_imu_s``: Kalibr's ``t_imu = t_cam + timeshift_cam_imu``.
    """

    camera: CameraModel
    T_cam_imu: SE3 | None = None
    timeshift_cam_imu_s: float = 0.0


@dataclass(frozen=True, slots=True, eq=False)
class EurocCameraCalib:
    """A camera from an EuRoC/ASL ``sensor.yaml``: ``T_body_cam`` is ``T_BS``; ``rate_hz`` its rate."""

    camera: CameraModel
    T_body_cam: SE3
    rate_hz: float

    def to_camera_calib(self, T_body_imu: SE3 | None = None) -> CameraCalib:
        """As a :class:`CameraCalib`. ``T_body_imu`` is the IMU's ``T_BS`` (identity in EuRoC)."""
        T_b_i = SE3.identity() if T_body_imu is None else T_body_imu
        return CameraCalib(self.camera, self.T_body_cam.inverse() @ T_b_i)


@dataclass(frozen=True, slots=True, eq=False)
class DsoCameraCalib:
    """A DSO ``camera.txt``: the input camera and the requested rectified output.

    ``output_mode`` is ``crop``, ``full``, ``none`` or ``manual`` (explicit output intrinsics in
    ``output_camera``); ``None`` when lines 3-4 are absent. ``output_size`` is ``(width, height)``.
    """

    camera: CameraModel
    output_mode: str | None = None
    output_size: tuple[int, int] | None = None
    output_camera: PinholeCamera | None = None


# ----------------------------------------------------------------------------------------------
# helpers


def _read_text(path: Path) -> str:
    try:
        return path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise CalibrationError(path, "file not found") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise CalibrationError(path, f"cannot be read: {exc}") from None


def _number(path: Path, value: Any, what: str, line: int | None) -> float:
    """One finite number from a YAML scalar or a text token."""
    if isinstance(value, bool) or value is None or isinstance(value, list | dict):
        raise CalibrationError(path, f"{what}: expected a number, got {value!r}", line)
    try:
        out = float(value)
    except (TypeError, ValueError):
        raise CalibrationError(path, f"{what}: {value!r} is not a number", line) from None
    if not math.isfinite(out):
        raise CalibrationError(path, f"{what}: value {value!r} is not finite", line)
    return out


def _numbers(
    path: Path, values: Any, what: str, line: int | None, counts: Sequence[int] | None = None
) -> list[float]:
    if not isinstance(values, list | tuple):
        raise CalibrationError(path, f"{what}: expected a list of numbers, got {values!r}", line)
    if counts is not None and len(values) not in counts:
        want = " or ".join(str(c) for c in counts)
        raise CalibrationError(path, f"{what}: expected {want} values, got {len(values)}", line)
    return [_number(path, v, what, line) for v in values]


def _integer(path: Path, value: float, what: str, line: int | None) -> int:
    if not float(value).is_integer() or value <= 0:
        raise CalibrationError(path, f"{what}: expected a positive integer, got {value}", line)
    return int(value)


def _se3_from_matrix(path: Path, values: Sequence[float], what: str, line: int | None) -> SE3:
    """SE3 from 16 (row-major 4x4) or 12 (3x4) numbers; checks the last row and orthonormality."""
    m = np.asarray(values, dtype=np.float64)
    if m.size == 16:
        m = m.reshape(4, 4)
        if np.abs(m[3] - np.array([0.0, 0.0, 0.0, 1.0])).max() > 1e-9:
            raise CalibrationError(path, f"{what}: last row must be [0, 0, 0, 1], got {m[3]}", line)
    elif m.size == 12:
        m = m.reshape(3, 4)
    else:
        raise CalibrationError(path, f"{what}: expected a 4x4 matrix (16 values), got {m.size}", line)
    rot = m[:3, :3]
    err = float(np.abs(rot @ rot.T - np.eye(3)).max())
    if err > _ORTHONORMAL_TOL or np.linalg.det(rot) <= 0.0:
        raise CalibrationError(
            path,
            f"{what}: rotation is not orthonormal (max |R R^T - I| = {err:.3g}, "
            f"det = {np.linalg.det(rot):.6g})",
            line,
        )
    return SE3.from_matrix(m[:3, :4])


def _camera(
    path: Path,
    model: Any,
    distortion_model: Any,
    intrinsics: list[float],
    distortion: list[float],
    resolution: list[float],
    lines: Mapping[str, int | None],
) -> CameraModel:
    """Build a camera; ``lines`` gives the line of each item (keys: model, distortion_model,
    intrinsics, distortion, resolution) for the error message."""
    if str(model).strip().lower() != "pinhole":
        raise CalibrationError(
            path, f"camera model {model!r} is not supported (only 'pinhole')", lines.get("model")
        )
    try:
        dist_name = canonical_distortion_model(str(distortion_model))
    except ValueError as exc:
        raise CalibrationError(path, str(exc), lines.get("distortion_model")) from None
    counts = DISTORTION_COUNTS[dist_name]
    if counts is not None and len(distortion) not in counts:
        want = " or ".join(str(c) for c in counts)
        raise CalibrationError(
            path,
            f"{dist_name} distortion takes {want} coefficients, got {len(distortion)}",
            lines.get("distortion"),
        )
    if counts is None and any(v != 0.0 for v in distortion):
        raise CalibrationError(
            path, "distortion model 'none' takes no non-zero coefficients", lines.get("distortion")
        )
    if len(intrinsics) != 4:
        raise CalibrationError(
            path, f"intrinsics must be [fx, fy, cx, cy], got {len(intrinsics)} values",
            lines.get("intrinsics"),
        )
    if len(resolution) != 2:
        raise CalibrationError(
            path, f"resolution must be [width, height], got {len(resolution)} values",
            lines.get("resolution"),
        )
    for value in resolution:
        _integer(path, value, "resolution", lines.get("resolution"))
    try:
        return camera_from_params("pinhole", dist_name, intrinsics, distortion, resolution)
    except ValueError as exc:  # ShapeError is a ValueError: focal length <= 0
        raise CalibrationError(path, str(exc), lines.get("intrinsics")) from None


# ----- YAML with line numbers ----------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class _YamlDoc:
    """A parsed YAML mapping plus the 1-based line of every key (dotted path: ``cam0.intrinsics``)."""

    path: Path
    data: dict[str, Any]
    lines: dict[str, int]

    def section(self, key: str) -> _YamlDoc:
        value = self.get(key)
        if not isinstance(value, dict):
            raise CalibrationError(self.path, f"'{key}' must be a mapping", self.line(key))
        prefix = key + "."
        lines = {k[len(prefix) :]: v for k, v in self.lines.items() if k.startswith(prefix)}
        return _YamlDoc(self.path, value, lines)

    def line(self, key: str) -> int | None:
        return self.lines.get(key)

    def has(self, key: str) -> bool:
        return key in self.data

    def get(self, key: str) -> Any:
        if key not in self.data:
            raise CalibrationError(self.path, f"missing key '{key}'")
        return self.data[key]

    def number(self, key: str) -> float:
        return _number(self.path, self.get(key), key, self.line(key))

    def numbers(self, key: str, counts: Sequence[int] | None = None) -> list[float]:
        return _numbers(self.path, self.get(key), key, self.line(key), counts)


def _load_yaml(path: Path) -> _YamlDoc:
    import yaml

    text = _read_text(path)
    # OpenCV FileStorage writes "%YAML:1.0" (EuRoC); PyYAML only knows "%YAML 1.1". Blank the
    # directive and the document marker that follows it, keeping line numbers.
    lines = text.splitlines()
    if lines and lines[0].startswith("%YAML"):
        lines[0] = ""
        if len(lines) > 1 and lines[1].strip() == "---":
            lines[1] = ""
    clean = "\n".join(lines)

    class _Loader(yaml.SafeLoader):
        pass

    def _opencv_matrix(loader: yaml.SafeLoader, node: yaml.Node) -> Any:
        if not isinstance(node, yaml.MappingNode):
            return loader.construct_object(node)
        return loader.construct_mapping(node, deep=True)

    _Loader.add_constructor("tag:yaml.org,2002:opencv-matrix", _opencv_matrix)
    try:
        root = yaml.compose(clean, Loader=_Loader)
        data = yaml.load(clean, Loader=_Loader)  # a SafeLoader subclass
    except yaml.MarkedYAMLError as exc:
        mark = exc.problem_mark or exc.context_mark
        line = mark.line + 1 if mark is not None else None
        raise CalibrationError(path, f"invalid YAML: {exc.problem or exc}", line) from None
    except yaml.YAMLError as exc:
        raise CalibrationError(path, f"invalid YAML: {exc}") from None
    if not isinstance(data, dict):
        raise CalibrationError(path, "expected a YAML mapping of keys to values")
    key_lines: dict[str, int] = {}

    def walk(node: Any, prefix: str) -> None:
        if isinstance(node, yaml.MappingNode):
            for key_node, value_node in node.value:
                key = f"{prefix}{key_node.value}"
                key_lines[key] = key_node.start_mark.line + 1
                walk(value_node, key + ".")

    walk(root, "")
    return _YamlDoc(path, {str(k): v for k, v in data.items()}, key_lines)


def _fmt(value: float) -> str:
    """Shortest text that reads back as the same float."""
    return repr(float(value))


def _fmt_list(values: Sequence[float]) -> str:
    return "[" + ", ".join(_fmt(v) for v in values) + "]"


# ----------------------------------------------------------------------------------------------
# Kalibr


def read_kalibr_camchain(path: str | Path, cam: str = "cam0") -> CameraCalib:
    """Camera ``cam`` of a Kalibr ``camchain.yaml`` (or ``camchain-imucam.yaml``).

    ``T_cam_imu`` (4x4, maps IMU-frame points into the camera frame) is ``None`` when absent.
    """
    p = Path(path)
    doc = _load_yaml(p)
    sec = doc.section(cam)
    model = sec.get("camera_model")
    dist_model = sec.get("distortion_model")
    intr = sec.numbers("intrinsics")
    dist = sec.numbers("distortion_coeffs")
    res = sec.numbers("resolution", (2,))
    keys = {"model": "camera_model", "distortion_model": "distortion_model",
            "intrinsics": "intrinsics", "distortion": "distortion_coeffs", "resolution": "resolution"}
    camera = _camera(p, model, dist_model, intr, dist, res, {k: sec.line(v) for k, v in keys.items()})
    T_cam_imu: SE3 | None = None
    if sec.has("T_cam_imu"):
        rows = sec.get("T_cam_imu")
        line = sec.line("T_cam_imu")
        if not isinstance(rows, list) or len(rows) != 4:
            raise CalibrationError(p, "T_cam_imu: expected 4 rows of 4 numbers", line)
        flat: list[float] = []
        for row in rows:
            flat.extend(_numbers(p, row, "T_cam_imu", line, (4,)))
        T_cam_imu = _se3_from_matrix(p, flat, "T_cam_imu", line)
    shift = sec.number("timeshift_cam_imu") if sec.has("timeshift_cam_imu") else 0.0
    return CameraCalib(camera, T_cam_imu, shift)


def write_kalibr_camchain(path: str | Path, calib: CameraCalib, cam: str = "cam0") -> None:
    """Write ``calib`` as a one-camera Kalibr camchain (radtan k3 must be 0: Kalibr has 4 terms)."""
    cam_model = calib.camera
    dist = list(cam_model.distortion)
    if isinstance(cam_model, RadTanCamera):
        if cam_model.k3 != 0.0:
            raise ShapeError("Kalibr radtan has no k3 term; cannot write k3 != 0")
        dist = dist[:4]
    lines = [f"{cam}:"]
    if calib.T_cam_imu is not None:
        lines.append("  T_cam_imu:")
        for row in calib.T_cam_imu.matrix():
            lines.append(f"  - {_fmt_list(row)}")
    lines += [
        "  cam_overlaps: []",
        "  camera_model: pinhole",
        f"  distortion_coeffs: {_fmt_list(dist)}",
        f"  distortion_model: {cam_model.distortion_model}",
        f"  intrinsics: {_fmt_list([cam_model.fx, cam_model.fy, cam_model.cx, cam_model.cy])}",
        f"  resolution: [{cam_model.width}, {cam_model.height}]",
        f"  timeshift_cam_imu: {_fmt(calib.timeshift_cam_imu_s)}",
    ]
    Path(path).write_text("\n".join(lines) + "\n", encoding="utf-8")


def _imu_noise(doc: _YamlDoc, rate_key: str) -> ImuNoise:
    values = {
        "gyroscope_noise_density": doc.number("gyroscope_noise_density"),
        "gyroscope_random_walk": doc.number("gyroscope_random_walk"),
        "accelerometer_noise_density": doc.number("accelerometer_noise_density"),
        "accelerometer_random_walk": doc.number("accelerometer_random_walk"),
        rate_key: doc.number(rate_key),
    }
    for key, value in values.items():
        if value < 0.0 or (key == rate_key and value <= 0.0):
            raise CalibrationError(doc.path, f"{key} must be positive, got {value}", doc.line(key))
    return ImuNoise(
        gyro_noise_density=values["gyroscope_noise_density"],
        gyro_random_walk=values["gyroscope_random_walk"],
        accel_noise_density=values["accelerometer_noise_density"],
        accel_random_walk=values["accelerometer_random_walk"],
        rate_hz=values[rate_key],
    )


def read_kalibr_imu(path: str | Path, imu: str = "imu0") -> ImuNoise:
    """Noise densities of a Kalibr ``imu.yaml`` (flat keys, or nested under ``imu``)."""
    p = Path(path)
    doc = _load_yaml(p)
    if doc.has(imu) and isinstance(doc.data[imu], dict):
        doc = doc.section(imu)
    return _imu_noise(doc, "update_rate")


def write_kalibr_imu(path: str | Path, noise: ImuNoise, rostopic: str = "/imu0") -> None:
    """Write a Kalibr ``imu.yaml`` (the flat input format of kalibr_calibrate_imu_camera)."""
    text = (
        f"rostopic: {rostopic}\n"
        f"update_rate: {_fmt(noise.rate_hz)}\n"
        f"accelerometer_noise_density: {_fmt(noise.accel_noise_density)}\n"
        f"accelerometer_random_walk: {_fmt(noise.accel_random_walk)}\n"
        f"gyroscope_noise_density: {_fmt(noise.gyro_noise_density)}\n"
        f"gyroscope_random_walk: {_fmt(noise.gyro_random_walk)}\n"
    )
    Path(path).write_text(text, encoding="utf-8")


# ----------------------------------------------------------------------------------------------
# EuRoC / ASL sensor.yaml


def _euroc_T_BS(doc: _YamlDoc) -> SE3:
    tbs = doc.section("T_BS")
    rows = _integer(doc.path, tbs.number("rows"), "T_BS.rows", tbs.line("rows"))
    cols = _integer(doc.path, tbs.number("cols"), "T_BS.cols", tbs.line("cols"))
    if (rows, cols) != (4, 4):
        where = tbs.line("rows") if rows != 4 else tbs.line("cols")
        raise CalibrationError(doc.path, f"T_BS must be 4x4, got {rows}x{cols}", where)
    data = tbs.numbers("data", (16,))
    return _se3_from_matrix(doc.path, data, "T_BS", tbs.line("data"))


def read_euroc_sensor_T_BS(path: str | Path) -> SE3:
    """``T_BS`` of any EuRoC/ASL ``sensor.yaml``: the sensor pose in the body frame."""
    return _euroc_T_BS(_load_yaml(Path(path)))


def _load_sensor_yaml(path: Path, sensor_type: str) -> _YamlDoc:
    """An EuRoC/ASL ``sensor.yaml`` whose ``sensor_type`` (when present) is ``sensor_type``."""
    doc = _load_yaml(path)
    found = doc.data.get("sensor_type", sensor_type)
    if found != sensor_type:
        raise CalibrationError(
            path, f"sensor_type is {found!r}, expected {sensor_type!r}", doc.line("sensor_type")
        )
    return doc


def read_euroc_camera(path: str | Path) -> EurocCameraCalib:
    """An EuRoC/ASL camera ``sensor.yaml`` (``cam0/sensor.yaml``)."""
    p = Path(path)
    doc = _load_sensor_yaml(p, "camera")
    keys = {"model": "camera_model", "distortion_model": "distortion_model",
            "intrinsics": "intrinsics", "distortion": "distortion_coefficients",
            "resolution": "resolution"}
    T_body_cam = _euroc_T_BS(doc)
    rate = doc.number("rate_hz")
    if rate <= 0.0:
        raise CalibrationError(p, f"rate_hz must be positive, got {rate}", doc.line("rate_hz"))
    camera = _camera(
        p,
        doc.get("camera_model"),
        doc.get("distortion_model"),
        doc.numbers("intrinsics"),
        doc.numbers("distortion_coefficients"),
        doc.numbers("resolution", (2,)),
        {k: doc.line(v) for k, v in keys.items()},
    )
    return EurocCameraCalib(camera, T_body_cam, rate)


_EUROC_DIST_NAMES = {
    "radtan": "radial-tangential",
    "equidistant": "equidistant",
    "fov": "fov",
    "none": "none",
}


def _euroc_T_BS_text(T: SE3) -> list[str]:
    m = T.matrix()
    rows = [", ".join(_fmt(v) for v in row) for row in m]
    return [
        "T_BS:",
        "  cols: 4",
        "  rows: 4",
        "  data: [" + rows[0] + ",",
        "         " + rows[1] + ",",
        "         " + rows[2] + ",",
        "         " + rows[3] + "]",
    ]


def write_euroc_camera(
    path: str | Path, camera: CameraModel, T_body_cam: SE3, rate_hz: float, comment: str = ""
) -> None:
    """Write an EuRoC/ASL camera ``sensor.yaml`` (OpenCV ``%YAML:1.0`` header, like the dataset)."""
    lines = ["%YAML:1.0", "sensor_type: camera", f"comment: {comment!r}", ""]
    lines += _euroc_T_BS_text(T_body_cam)
    lines += [
        "",
        f"rate_hz: {_fmt(rate_hz)}",
        f"resolution: [{camera.width}, {camera.height}]",
        "camera_model: pinhole",
        f"intrinsics: {_fmt_list([camera.fx, camera.fy, camera.cx, camera.cy])}",
        f"distortion_model: {_EUROC_DIST_NAMES[camera.distortion_model]}",
        f"distortion_coefficients: {_fmt_list(camera.distortion)}",
    ]
    Path(path).write_text("\n".join(lines) + "\n", encoding="utf-8")


def read_euroc_imu(path: str | Path) -> ImuNoise:
    """Noise densities and rate of an EuRoC/ASL IMU ``sensor.yaml`` (``imu0/sensor.yaml``)."""
    doc = _load_sensor_yaml(Path(path), "imu")
    return _imu_noise(doc, "rate_hz")


def write_euroc_imu(
    path: str | Path, noise: ImuNoise, T_body_imu: SE3 | None = None, comment: str = ""
) -> None:
    """Write an EuRoC/ASL IMU ``sensor.yaml``."""
    lines = ["%YAML:1.0", "sensor_type: imu", f"comment: {comment!r}", ""]
    lines += _euroc_T_BS_text(SE3.identity() if T_body_imu is None else T_body_imu)
    lines += [
        f"rate_hz: {_fmt(noise.rate_hz)}",
        "",
        f"gyroscope_noise_density: {_fmt(noise.gyro_noise_density)}",
        f"gyroscope_random_walk: {_fmt(noise.gyro_random_walk)}",
        f"accelerometer_noise_density: {_fmt(noise.accel_noise_density)}",
        f"accelerometer_random_walk: {_fmt(noise.accel_random_walk)}",
    ]
    Path(path).write_text("\n".join(lines) + "\n", encoding="utf-8")


# ----------------------------------------------------------------------------------------------
# KITTI


def read_kitti_calib(
    path: str | Path, width: int, height: int, projection: str = "P0"
) -> PinholeCamera:
    """The rectified camera of a KITTI odometry ``calib.txt`` (``P0: 12 values``, 3x4 row-major).

    KITTI images are rectified, so the camera is a pinhole; the size is not in the file and is
    passed in (normally from the first image).
    """
    p = Path(path)
    text = _read_text(p)
    found: tuple[int, list[str]] | None = None
    for number, raw in enumerate(text.splitlines(), start=1):
        line = raw.strip()
        if not line:
            continue
        key, sep, rest = line.partition(":")
        if not sep:
            raise CalibrationError(p, f"expected 'NAME: values', got {line[:40]!r}", number)
        if key.strip() == projection:
            found = (number, rest.split())
    if found is None:
        raise CalibrationError(p, f"missing projection matrix '{projection}'")
    number, tokens = found
    if len(tokens) != 12:
        raise CalibrationError(
            p, f"{projection}: expected 12 values (3x4 row-major), got {len(tokens)}", number
        )
    P = np.array([_number(p, t, projection, number) for t in tokens]).reshape(3, 4)
    if P[0, 1] != 0.0 or P[1, 0] != 0.0 or np.any(P[2, :3] != np.array([0.0, 0.0, 1.0])):
        raise CalibrationError(
            p, f"{projection}: not a rectified projection [[fx 0 cx tx] [0 fy cy ty] [0 0 1 tz]]",
            number,
        )
    try:
        return PinholeCamera(int(width), int(height), P[0, 0], P[1, 1], P[0, 2], P[1, 2])
    except ShapeError as exc:
        raise CalibrationError(p, f"{projection}: {exc}", number) from None


# ----------------------------------------------------------------------------------------------
# DSO / TUM monoVO camera.txt

_DSO_MODELS = {
    "pinhole": ("none", 4),
    "fov": ("fov", 5),
    "radtan": ("radtan", 8),
    "equidistant": ("equidistant", 8),
    "kannalabrandt": ("equidistant", 8),
}


def _dso_intrinsics(
    intr: list[float], width: int, height: int
) -> tuple[float, float, float, float]:
    fx, fy, cx, cy = intr
    if cx < 1.0 and cy < 1.0:
        # DSO "relative" format: fractions of the image size, pixel (0,0) covering [0,1]^2;
        # DSO shifts by -0.5 to the pixel-centre convention (Undistort.cpp, readFromFile).
        return fx * width, fy * height, cx * width - 0.5, cy * height - 0.5
    return fx, fy, cx, cy


def read_dso_camera(path: str | Path) -> DsoCameraCalib:
    """A DSO / TUM-monoVO ``camera.txt``.

    Line 1: ``Pinhole fx fy cx cy 0`` | ``RadTan fx fy cx cy k1 k2 p1 p2`` | ``EquiDistant``/
    ``KannalaBrandt fx fy cx cy k1 k2 k3 k4`` | eight bare numbers (RadTan) | ``FOV fx fy cx cy
    omega`` or five bare numbers (FOV). Intrinsics with ``cx, cy < 1`` are relative to the size.
    Line 2: ``width height``. Line 3 (optional): ``crop`` | ``full`` | ``none`` | ``fx fy cx cy 0``
    (relative). Line 4: output ``width height``.
    """
    p = Path(path)
    lines = _read_text(p).splitlines()
    while lines and not lines[-1].strip():
        lines.pop()
    if len(lines) < 2:
        raise CalibrationError(p, "expected at least 2 lines (model line, 'width height')")
    tokens = lines[0].split()
    if not tokens:
        raise CalibrationError(p, "line 1 is empty", 1)
    name = tokens[0]
    try:
        float(name)
        is_bare = True
    except ValueError:
        is_bare = False
    if is_bare:
        values = [_number(p, t, "camera parameters", 1) for t in tokens]
        if len(values) == 5:
            model = "fov"
        elif len(values) == 8:
            model = "radtan"
        else:
            raise CalibrationError(
                p, f"expected 5 (FOV) or 8 (RadTan) numbers on line 1, got {len(values)}", 1
            )
    else:
        model = name.lower()
        values = [_number(p, t, f"{name} parameters", 1) for t in tokens[1:]]
    if model not in _DSO_MODELS:
        raise CalibrationError(
            p,
            f"unknown camera model {name!r} (use Pinhole, FOV, RadTan, EquiDistant, KannalaBrandt)",
            1,
        )
    dist_model, count = _DSO_MODELS[model]
    if model == "pinhole":
        if len(values) not in (4, 5):
            raise CalibrationError(p, f"Pinhole takes 'fx fy cx cy 0', got {len(values)} values", 1)
        if len(values) == 5 and values[4] != 0.0:
            raise CalibrationError(p, "Pinhole: the fifth value must be 0", 1)
        values = values[:4]
    elif len(values) != count:
        raise CalibrationError(p, f"{name} takes {count} values, got {len(values)}", 1)

    size = lines[1].split()
    if len(size) != 2:
        raise CalibrationError(p, f"expected 'width height', got {lines[1].strip()!r}", 2)
    width = _integer(p, _number(p, size[0], "width", 2), "width", 2)
    height = _integer(p, _number(p, size[1], "height", 2), "height", 2)
    intr = list(_dso_intrinsics(values[:4], width, height))
    camera = _camera(
        p, "pinhole", dist_model, intr, values[4:], [width, height],
        {"intrinsics": 1, "distortion": 1, "resolution": 2},
    )

    if len(lines) < 3:
        return DsoCameraCalib(camera)
    out_tokens = lines[2].split()
    if len(lines) < 4:
        raise CalibrationError(p, "line 3 (output mode) needs line 4 'width height'", 3)
    out_size = lines[3].split()
    if len(out_size) != 2:
        raise CalibrationError(p, f"expected 'width height', got {lines[3].strip()!r}", 4)
    out_w = _integer(p, _number(p, out_size[0], "output width", 4), "output width", 4)
    out_h = _integer(p, _number(p, out_size[1], "output height", 4), "output height", 4)
    if len(out_tokens) == 1 and out_tokens[0].lower() in ("crop", "full", "none"):
        return DsoCameraCalib(camera, out_tokens[0].lower(), (out_w, out_h))
    if len(out_tokens) != 5:
        raise CalibrationError(
            p, f"line 3 must be crop, full, none or 'fx fy cx cy 0', got {lines[2].strip()!r}", 3
        )
    out_vals = [_number(p, t, "output intrinsics", 3) for t in out_tokens]
    ofx, ofy, ocx, ocy = out_vals[:4]
    # manual output calibration is relative (DSO Undistort.cpp): K = [fx w, fy h, cx w - .5, cy h - .5]
    try:
        out_cam = PinholeCamera(out_w, out_h, ofx * out_w, ofy * out_h, ocx * out_w - 0.5,
                                ocy * out_h - 0.5)
    except ShapeError as exc:
        raise CalibrationError(p, f"output intrinsics: {exc}", 3) from None
    return DsoCameraCalib(camera, "manual", (out_w, out_h), out_cam)


def write_dso_camera(path: str | Path, calib: DsoCameraCalib) -> None:
    """Write a DSO ``camera.txt`` with absolute intrinsics (output lines when present)."""
    cam = calib.camera
    intr = [cam.fx, cam.fy, cam.cx, cam.cy]
    if isinstance(cam, PinholeCamera):
        first = "Pinhole " + " ".join(_fmt(v) for v in intr) + " 0"
    elif isinstance(cam, RadTanCamera):
        if cam.k3 != 0.0:
            raise ShapeError("DSO RadTan has no k3 term; cannot write k3 != 0")
        first = "RadTan " + " ".join(_fmt(v) for v in [*intr, *cam.distortion[:4]])
    elif isinstance(cam, EquidistantCamera):
        first = "EquiDistant " + " ".join(_fmt(v) for v in [*intr, *cam.distortion])
    elif isinstance(cam, FovCamera):
        first = "FOV " + " ".join(_fmt(v) for v in [*intr, cam.omega])
    else:
        raise ShapeError(f"cannot write a {type(cam).__name__} as a DSO camera.txt")
    lines = [first, f"{cam.width} {cam.height}"]
    if calib.output_mode is not None and calib.output_size is not None:
        w, h = calib.output_size
        if calib.output_mode == "manual":
            oc = calib.output_camera
            if oc is None:
                raise ShapeError("output_mode 'manual' needs output_camera")
            rel = [oc.fx / w, oc.fy / h, (oc.cx + 0.5) / w, (oc.cy + 0.5) / h]
            lines.append(" ".join(_fmt(v) for v in rel) + " 0")
        else:
            lines.append(calib.output_mode)
        lines.append(f"{w} {h}")
    Path(path).write_text("\n".join(lines) + "\n", encoding="utf-8")


# ----------------------------------------------------------------------------------------------
# photometric calibration: pcalib.txt and vignette.png


def read_pcalib(path: str | Path) -> FloatArray:
    """The ``(256,)`` inverse response G^-1 of a DSO ``pcalib.txt`` (one line of 256 values).

    G^-1 maps an 8-bit pixel value to irradiance (arbitrary units) and must be strictly increasing
    (as DSO requires). A trailing ``vis_exponent: x`` line (EuRoC's copy) is accepted and ignored.
    """
    p = Path(path)
    lines = _read_text(p).splitlines()
    values: FloatArray | None = None
    for number, raw in enumerate(lines, start=1):
        line = raw.strip()
        if not line or line.startswith("#"):
            continue
        if values is not None:
            if line.startswith("vis_exponent"):
                continue
            raise CalibrationError(p, f"unexpected content after the response: {line[:40]!r}", number)
        tokens = line.split()
        if len(tokens) != PCALIB_SIZE:
            raise CalibrationError(
                p, f"expected {PCALIB_SIZE} inverse-response values, got {len(tokens)}", number
            )
        values = np.array([_number(p, t, "inverse response", number) for t in tokens])
        if np.any(np.diff(values) <= 0.0):
            first = int(np.argmax(np.diff(values) <= 0.0))
            raise CalibrationError(
                p,
                f"inverse response must be strictly increasing (value {first + 1} >= value "
                f"{first + 2})",
                number,
            )
    if values is None:
        raise CalibrationError(p, "file is empty")
    return values


def write_pcalib(path: str | Path, inverse_response: ArrayLike) -> None:
    """Write a ``(256,)`` strictly increasing inverse response as a DSO ``pcalib.txt``."""
    g = np.asarray(inverse_response, dtype=np.float64)
    if g.shape != (PCALIB_SIZE,) or not np.all(np.isfinite(g)):
        raise ShapeError(f"inverse response must be a finite ({PCALIB_SIZE},) array, got {g.shape}")
    if np.any(np.diff(g) <= 0.0):
        raise ShapeError("inverse response must be strictly increasing")
    Path(path).write_text(" ".join(_fmt(v) for v in g) + "\n", encoding="utf-8")


def read_vignette(path: str | Path) -> FloatArray:
    """A DSO ``vignette.png`` (8- or 16-bit grey) as ``(H, W)`` float64 with max == 1."""
    import cv2

    p = Path(path)
    if not p.is_file():
        raise CalibrationError(p, "file not found")
    img = cv2.imread(str(p), cv2.IMREAD_UNCHANGED)
    if img is None:
        raise CalibrationError(p, "cannot be decoded as an image")
    if img.ndim != 2:
        raise CalibrationError(p, f"vignette must be a grey image, got shape {img.shape}")
    if img.dtype not in (np.uint8, np.uint16):
        raise CalibrationError(p, f"vignette must be 8- or 16-bit, got {img.dtype}")
    v = img.astype(np.float64)
    peak = float(v.max())
    if peak <= 0.0:
        raise CalibrationError(p, "vignette is all zero")
    out: FloatArray = v / peak
    return out


def write_vignette(path: str | Path, vignette: ArrayLike) -> None:
    """Write an ``(H, W)`` non-negative vignette as a 16-bit PNG scaled so that its max is 65535."""
    import cv2

    v = np.asarray(vignette, dtype=np.float64)
    if v.ndim != 2 or v.size == 0 or not np.all(np.isfinite(v)) or np.any(v < 0.0):
        raise ShapeError(f"vignette must be a finite non-negative (H, W) array, got {v.shape}")
    peak = float(v.max())
    if peak <= 0.0:
        raise ShapeError("vignette is all zero")
    img = np.round(v / peak * 65535.0).astype(np.uint16)
    p = Path(path)
    if p.suffix.lower() != ".png":
        raise ShapeError(f"vignette must be written as .png, got {p.name}")
    if not cv2.imwrite(str(p), img):
        raise CalibrationError(p, "cannot be written")


# ----------------------------------------------------------------------------------------------


def check_image_size(
    camera: CameraModel,
    image_shape: Sequence[int],
    calib_path: str | Path,
    image_path: str | Path,
) -> None:
    """Raise CalibrationError (naming ``calib_path``) when an image of ``image_shape`` ((H, W) or
    (H, W, C)) does not have the camera's size."""
    shape = tuple(int(s) for s in image_shape)
    if len(shape) not in (2, 3):
        raise ShapeError(f"image_shape must be (H, W) or (H, W, C), got {shape}")
    height, width = shape[0], shape[1]
    if (width, height) != (camera.width, camera.height):
        raise CalibrationError(
            calib_path,
            f"calibration is for {camera.width}x{camera.height} images but {image_path} is "
            f"{width}x{height}",
        )
