"""What a recording holds, as plain data: the library side of ``amrvio info``.

:func:`dataset_summary` describes an opened :class:`~amrvio.io.base.Dataset` (frames, time span,
frame rate, image size, camera, IMU, noise, ``T_body_cam``, ground truth, exposure and photometric
files) as a JSON-ready dict. :func:`check_images` decodes every frame and checks that all have the
size of the first one (the readers only decode the first image when opening).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
from numpy.typing import NDArray

from amrvio.errors import DatasetFormatError
from amrvio.io.base import Dataset
from amrvio.types.camera import CameraModel
from amrvio.types.lie import SE3
from amrvio.types.sensors import Frame


def _median_rate_hz(stamps_ns: NDArray[np.int64]) -> float | None:
    """1 / median interval (Hz), robust to a few dropped frames; None with fewer than 2 stamps."""
    if stamps_ns.shape[0] < 2:
        return None
    return float(1e9 / np.median(np.diff(stamps_ns).astype(np.float64)))


def _span(stamps_ns: NDArray[np.int64]) -> dict[str, Any]:
    first, last = int(stamps_ns[0]), int(stamps_ns[-1])
    return {"first_t_ns": first, "last_t_ns": last, "duration_s": (last - first) * 1e-9}


def _frame_name(frame: Frame) -> str:
    if frame.path is not None:
        return str(frame.path)
    return f"frame {frame.index} (t={frame.t_ns} ns)"


def camera_summary(camera: CameraModel) -> dict[str, Any]:
    """Model, (width, height), intrinsics and distortion coefficients of ``camera``."""
    return {
        "class": type(camera).__name__,
        "distortion_model": camera.distortion_model,
        "width": camera.width,
        "height": camera.height,
        "fx": camera.fx,
        "fy": camera.fy,
        "cx": camera.cx,
        "cy": camera.cy,
        "distortion": list(camera.distortion),
    }


def pose_summary(T_a_b: SE3) -> dict[str, Any]:
    """Translation (m), quaternion wxyz, rotation angle (deg) and the 4x4 matrix of a pose."""
    return {
        "t_m": T_a_b.t.tolist(),
        "quat_wxyz": T_a_b.rot.quat_wxyz().tolist(),
        "angle_deg": float(np.degrees(np.linalg.norm(T_a_b.rot.log()))),
        "matrix": T_a_b.matrix().tolist(),
    }


def dataset_summary(ds: Dataset) -> dict[str, Any]:
    """Everything ``amrvio info`` reports about ``ds``; reads the first image (for its size) only.

    Keys: kind, root, frames {count, first_t_ns, last_t_ns, duration_s, rate_hz, width, height},
    camera (or None), T_body_cam (or None), imu {samples, span, rate_hz} (or None), imu_noise (or
    None), groundtruth {poses, frame, span, path_length_m} (or None), exposure {frames_with,
    min_s, max_s}, photometric {inverse_response, vignette}.
    """
    stamps = ds.frame_stamps_ns
    frames: dict[str, Any] = {"count": len(ds.frames), "rate_hz": _median_rate_hz(stamps)}
    if ds.frames:
        frames.update(_span(stamps))
        first = ds.frames[0].load()
        frames["width"], frames["height"] = int(first.shape[1]), int(first.shape[0])
    imu: dict[str, Any] | None = None
    if ds.imu is not None and len(ds.imu):
        imu = {"samples": len(ds.imu), "rate_hz": _median_rate_hz(ds.imu.stamps_ns)}
        imu.update(_span(ds.imu.stamps_ns))
    noise = ds.imu_noise
    gt: dict[str, Any] | None = None
    if ds.groundtruth is not None:
        g = ds.groundtruth
        gt = {
            "poses": len(g),
            "frame": ds.groundtruth_frame,
            "first_t_s": float(g.stamps_s[0]) if len(g) else None,
            "last_t_s": float(g.stamps_s[-1]) if len(g) else None,
            "path_length_m": g.path_length_m(),
        }
    exposures = [f.exposure_s for f in ds.frames if f.exposure_s is not None]
    return {
        "kind": ds.kind,
        "root": str(ds.root),
        "frames": frames,
        "camera": None if ds.camera is None else camera_summary(ds.camera),
        "T_body_cam": None if ds.T_body_cam is None else pose_summary(ds.T_body_cam),
        "imu": imu,
        "imu_noise": None if noise is None else {
            "gyro_noise_density": noise.gyro_noise_density,
            "gyro_random_walk": noise.gyro_random_walk,
            "accel_noise_density": noise.accel_noise_density,
            "accel_random_walk": noise.accel_random_walk,
            "rate_hz": noise.rate_hz,
        },
        "groundtruth": gt,
        "exposure": {
            "frames_with": len(exposures),
            "min_s": min(exposures) if exposures else None,
            "max_s": max(exposures) if exposures else None,
        },
        "photometric": {
            "inverse_response": ds.inverse_response is not None,
            "vignette": ds.vignette is not None,
        },
    }


def check_images(ds: Dataset, progress: Callable[[int], None] | None = None) -> int:
    """Decode every frame; all must have the size of the first. Returns the number checked.

    Raises DatasetFormatError naming the first image that cannot be decoded or has another size.
    ``progress(k)`` is called after frame k.
    """
    size: tuple[int, ...] | None = None
    for k, frame in enumerate(ds.frames):
        shape = frame.load().shape
        if size is None:
            size = shape
        elif shape != size:
            raise DatasetFormatError(
                _frame_name(frame),
                f"image is {shape[1]}x{shape[0]} but {_frame_name(ds.frames[0])} is "
                f"{size[1]}x{size[0]}; every frame of a recording must have the same size",
            )
        if progress is not None:
            progress(k)
    return len(ds.frames)
