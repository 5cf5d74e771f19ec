"""The ORB-SLAM3 settings yaml (an OpenCV FileStorage file): camera and ``T_body_cam``."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from amrvio.errors import CalibrationError
from amrvio.io.image import MAX_SIDE_PX, MIN_SIDE_PX
from amrvio.types.camera import CameraModel, camera_from_params
from amrvio.types.lie import SE3

MAX_FOCAL_PX = 1e6
"""Largest focal length or principal point coordinate (px) a settings file may give."""


def line_of_key(path: Path, keys: Sequence[str]) -> int | None:
    """The 1-based line of the first ``key:`` (any of ``keys``) in a yaml file, read as text."""
    try:
        lines = path.read_text(encoding="utf-8", errors="replace").splitlines()
    except OSError:
        return None
    for number, line in enumerate(lines, start=1):
        stripped = line.strip()
        if any(stripped.startswith(k + ":") for k in keys):
            return number
    return None


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
                path, f"{key} must be a number, got {value!r}", line_of_key(path, [key])
            ) from None
        if not np.isfinite(out):
            raise CalibrationError(path, f"{key} is not finite", line_of_key(path, [key]))
        return out

    def check(key: str, value: float, ok: bool, need: str) -> None:
        if not ok:
            raise CalibrationError(path, f"{key} must be {need}, got {value:g}",
                                   line_of_key(path, [key]))

    cam_type = str(data.get("Camera.type", "PinHole")).strip().lower()
    intr = [num(prefix + k) for k in ("fx", "fy", "cx", "cy")]
    for k, v in zip(("fx", "fy"), intr[:2], strict=True):
        check(prefix + k, v, 0 < v <= MAX_FOCAL_PX, f"in (0, {MAX_FOCAL_PX:g}] px")
    for k, v in zip(("cx", "cy"), intr[2:], strict=True):
        check(prefix + k, v, abs(v) <= MAX_FOCAL_PX, f"in [-{MAX_FOCAL_PX:g}, {MAX_FOCAL_PX:g}] px")
    size = [num("Camera.width"), num("Camera.height")]
    for k, v in zip(("Camera.width", "Camera.height"), size, strict=True):
        check(k, v, v == int(v) and MIN_SIDE_PX <= v <= MAX_SIDE_PX,
              f"an integer in [{MIN_SIDE_PX}, {MAX_SIDE_PX}] px")
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
            line_of_key(path, ["Camera.type"]),
        )
    try:
        camera = camera_from_params("pinhole", dist_model, intr, coeffs, size)
    except ValueError as err:  # the coefficients (the intrinsics and size are checked above)
        key = prefix + ("k1" if dist_model != "none" else "fx")
        raise CalibrationError(path, str(err), line_of_key(path, [key])) from None
    T_body_cam = None
    for key in ("IMU.T_b_c1", "Tbc"):
        if key in data:
            T_body_cam = _se3_from(data[key], path, key)
            break
    return camera, T_body_cam


def _se3_from(value: object, path: Path, key: str) -> SE3:
    m = np.asarray(value, dtype=np.float64)
    line = line_of_key(path, [key])
    if m.shape == (16,):
        m = m.reshape(4, 4)
    if m.shape != (4, 4) or not np.all(np.isfinite(m)):
        raise CalibrationError(path, f"{key} must be a finite 4x4 matrix", line)
    R = m[:3, :3]
    if np.abs(R @ R.T - np.eye(3)).max() > 1e-3:
        raise CalibrationError(path, f"{key} rotation is not orthonormal", line)
    return SE3.from_matrix(m)
