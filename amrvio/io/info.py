"""What a recording holds, as plain data: the library side of ``amrvio info``.

:func:`dataset_summary` describes an opened :class:`~amrvio.io.base.Dataset` (frames, time span,
frame rate, image size, camera, IMU, noise, ``T_body_cam``, ground truth, exposure and photometric
files) as a JSON-ready dict. :func:`check_images` decodes every frame and lists those that ``amrvio run``
would skip (unreadable, truncated, or of another size; the readers decode only the first image).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from amrvio.io.base import Dataset, SkippedFrame, first_image_shape, load_checked
from amrvio.types.camera import CameraModel
from amrvio.types.lie import SE3


def _median_rate_hz(stamps_ns: NDArray[np.int64]) -> float | None:
    """1 / median interval (Hz), robust to a few dropped frames; None with fewer than 2 stamps."""
    if stamps_ns.shape[0] < 2:
        return None
    return float(1e9 / np.median(np.diff(stamps_ns).astype(np.float64)))


def _span(stamps_ns: NDArray[np.int64]) -> dict[str, Any]:
    first, last = int(stamps_ns[0]), int(stamps_ns[-1])
    return {"first_t_ns": first, "last_t_ns": last, "duration_s": (last - first) * 1e-9}


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
        (height, width), _ = first_image_shape(ds.frames)
        frames["width"], frames["height"] = width, height
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


@dataclass(frozen=True, slots=True)
class ImageCheck:
    """What :func:`check_images` found: frames decoded and the frames that cannot be used."""

    n_checked: int
    skipped: tuple[SkippedFrame, ...]

    @property
    def n_usable(self) -> int:
        return self.n_checked - len(self.skipped)


def check_images(ds: Dataset, progress: Callable[[int], None] | None = None) -> ImageCheck:
    """Decode every frame as ``amrvio run`` would, and list those it would skip: images that
    cannot be read or decoded, truncated ones, and any whose size differs from the recording's
    (the first usable image's, which the calibration was checked against).

    ``progress(k)`` is called after frame k.
    """
    size: tuple[int, int] | None = None
    if ds.frames:
        size = first_image_shape(ds.frames)[0]
    skipped: list[SkippedFrame] = []
    for k, frame in enumerate(ds.frames):
        got = load_checked(frame, size)
        if isinstance(got, SkippedFrame):
            skipped.append(got)
        if progress is not None:
            progress(k)
    return ImageCheck(len(ds.frames), tuple(skipped))
