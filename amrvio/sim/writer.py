"""Write a simulated sequence in the ASL/EuRoC layout plus TUM-monoVO photometric files.

OUT/
  mav0/cam0/{data.csv, data/<t_ns>.png, sensor.yaml}
  mav0/imu0/{data.csv, sensor.yaml}
  mav0/state_groundtruth_estimate0/data.csv   t_ns, p, q_wxyz, v, b_w, b_a (TRUE biases)
  times.txt         "<id> <t_s> <exposure_ms>" per frame (TUM monoVO)
  pcalib.txt        256 values of the inverse response G^-1 (DSO convention)
  vignette.png      16-bit vignette, max = 65535
  wheel_odometry.csv
  sim_frames.csv    per frame: t_ns, exposure_s, true smear (max over the image and at the
                    principal point, px), sub-frames averaged, mean intensity (DN), the share of
                    the exposure with the lens uncovered (0 in a --blackout)
  sim_config.yaml   every parameter and the seed; under derived.blackouts the frames each
                    black-out darkened

The yaml, pcalib and vignette writers are amrvio.io.calib's. Every float is written with a
fixed or shortest-round-trip format and nothing records the wall
clock, so the same inputs give byte-identical files.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from amrvio.errors import ShapeError
from amrvio.io.calib import write_euroc_camera, write_euroc_imu, write_pcalib, write_vignette
from amrvio.types.camera import CameraModel
from amrvio.types.lie import SE3
from amrvio.types.sensors import ImuData, ImuNoise

F64 = NDArray[np.float64]

EUROC_IMU_HEADER = (
    "#timestamp [ns],w_RS_S_x [rad s^-1],w_RS_S_y [rad s^-1],w_RS_S_z [rad s^-1],"
    "a_RS_S_x [m s^-2],a_RS_S_y [m s^-2],a_RS_S_z [m s^-2]"
)


def _f(x: float) -> str:
    """Shortest representation that reads back to the same float."""
    return repr(float(x))


def ns_to_s_text(t_ns: int) -> str:
    """Exact decimal seconds of an integer nanosecond stamp (no float rounding)."""
    sign = "-" if t_ns < 0 else ""
    a = abs(int(t_ns))
    return f"{sign}{a // 1_000_000_000}.{a % 1_000_000_000:09d}"


SIM_FRAMES_HEADER = ("t_ns,exposure_s,smear_px_max,smear_px_center,n_subframes,mean_intensity_dn,"
                     "lens_open_fraction")
# written before black-outs existed (no lens_open_fraction column: the lens was always open)
_SIM_FRAMES_HEADER_V1 = "t_ns,exposure_s,smear_px_max,smear_px_center,n_subframes,mean_intensity_dn"


@dataclass(frozen=True, slots=True)
class FrameRecord:
    """Simulator truth of one frame (a row of sim_frames.csv).

    ``smear_px_max`` / ``smear_px_center``: image-motion path length of the visible scene points
    over the exposure (rotation and translation, from the depth map), max over the image and at
    the principal point (amrvio.sim.image_formation.predict_smear). ``mean_intensity_dn``: mean of
    the written 8-bit image. ``lens_open_fraction``: share of the exposure during which the lens was
    not covered (amrvio.sim.blackout; 0: a dark frame).
    """

    t_ns: int
    exposure_s: float
    smear_px_max: float
    smear_px_center: float
    n_subframes: int
    mean_intensity_dn: float
    lens_open_fraction: float = 1.0


def write_frames_csv(path: Path, records: Sequence[FrameRecord]) -> None:
    """sim_frames.csv: one :class:`FrameRecord` per line (shortest round-trip floats)."""
    lines = [SIM_FRAMES_HEADER]
    for r in records:
        lines.append(f"{int(r.t_ns)},{_f(r.exposure_s)},{_f(r.smear_px_max)},"
                     f"{_f(r.smear_px_center)},{int(r.n_subframes)},{_f(r.mean_intensity_dn)},"
                     f"{_f(r.lens_open_fraction)}")
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")


def read_frames_csv(path: Path) -> list[FrameRecord]:
    """Read sim_frames.csv back (raises DatasetFormatError on a malformed line)."""
    from amrvio.errors import DatasetFormatError

    text = Path(path).read_text(encoding="utf-8").splitlines()
    header = text[0].strip() if text else ""
    if header not in (SIM_FRAMES_HEADER, _SIM_FRAMES_HEADER_V1):
        raise DatasetFormatError(path, f"expected the header {SIM_FRAMES_HEADER!r}", line=1)
    n_fields = header.count(",") + 1
    out: list[FrameRecord] = []
    for i, line in enumerate(text[1:], start=2):
        if not line.strip():
            continue
        v = line.split(",")
        try:
            if len(v) != n_fields:
                raise ValueError
            out.append(FrameRecord(int(v[0]), float(v[1]), float(v[2]), float(v[3]), int(v[4]),
                                   float(v[5]), float(v[6]) if n_fields == 7 else 1.0))
        except ValueError:
            raise DatasetFormatError(path, f"expected {n_fields} numeric fields", line=i) from None
    return out


def write_imu_csv(path: Path, imu: ImuData) -> None:
    lines = [EUROC_IMU_HEADER]
    g, a = imu.gyro_rad_s, imu.accel_m_s2
    for i in range(len(imu)):
        vals = (g[i, 0], g[i, 1], g[i, 2], a[i, 0], a[i, 1], a[i, 2])
        lines.append(",".join([str(int(imu.stamps_ns[i]))] + [_f(v) for v in vals]))
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")


def write_times_txt(path: Path, stamps_ns: Sequence[int], exposures_s: Sequence[float]) -> None:
    """TUM monoVO times.txt: ``<id> <t_s> <exposure_ms>``; exposures are whole microseconds."""
    if len(stamps_ns) != len(exposures_s):
        raise ShapeError("times.txt: one exposure per frame stamp")
    lines = []
    for i, (t, e) in enumerate(zip(stamps_ns, exposures_s, strict=True)):
        lines.append(f"{i:05d} {ns_to_s_text(int(t))} {e * 1e3:.3f}")
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")


class SequenceWriter:
    """Creates the folder tree in ``out_dir`` and writes frames as they are rendered."""

    def __init__(self, out_dir: Path) -> None:
        self.root = Path(out_dir)
        self.mav = self.root / "mav0"
        self.cam_dir = self.mav / "cam0"
        (self.cam_dir / "data").mkdir(parents=True, exist_ok=True)
        (self.mav / "imu0").mkdir(parents=True, exist_ok=True)
        (self.mav / "state_groundtruth_estimate0").mkdir(parents=True, exist_ok=True)
        self._frames: list[int] = []

    def write_frame(self, t_ns: int, image: NDArray[np.uint8]) -> None:
        import cv2

        if image.dtype != np.uint8 or image.ndim != 2:
            raise ShapeError(f"frame must be an (H,W) uint8 image, got {image.dtype} {image.shape}")
        path = self.cam_dir / "data" / f"{int(t_ns)}.png"
        if not cv2.imwrite(str(path), image):
            raise OSError(f"cannot write {path}")
        self._frames.append(int(t_ns))

    def finish_camera(self, camera: CameraModel, T_body_cam: SE3, rate_hz: float,
                      exposures_s: Sequence[float]) -> None:
        lines = ["#timestamp [ns],filename"] + [f"{t},{t}.png" for t in self._frames]
        (self.cam_dir / "data.csv").write_text("\n".join(lines) + "\n", encoding="utf-8")
        write_euroc_camera(self.cam_dir / "sensor.yaml", camera, T_body_cam, rate_hz,
                           comment="amrvio simulated camera")
        write_times_txt(self.root / "times.txt", self._frames, exposures_s)

    def write_imu(self, imu: ImuData, noise: ImuNoise, comment: str = "amrvio simulated IMU") -> None:
        write_imu_csv(self.mav / "imu0" / "data.csv", imu)
        write_euroc_imu(self.mav / "imu0" / "sensor.yaml", noise, comment=comment)

    def write_groundtruth(self, stamps_ns: NDArray[np.int64], R_world_body: F64, p_world: F64,
                          v_world: F64, gyro_bias: F64, accel_bias: F64) -> None:
        from amrvio.io.trajectory import EurocGroundTruth, write_euroc_csv
        from amrvio.types.lie import matrix_to_quat_wxyz
        from amrvio.types.trajectory import Trajectory

        stamps_s = (stamps_ns // 1_000_000_000).astype(np.float64) + (
            stamps_ns % 1_000_000_000
        ).astype(np.float64) * 1e-9
        traj = Trajectory(stamps_s, p_world, matrix_to_quat_wxyz(R_world_body).reshape(-1, 4))
        gt = EurocGroundTruth(traj, stamps_ns, v_world, gyro_bias, accel_bias)
        write_euroc_csv(self.mav / "state_groundtruth_estimate0" / "data.csv", gt)

    def write_photometric(self, inverse_response: ArrayLike, vignette: ArrayLike) -> None:
        write_pcalib(self.root / "pcalib.txt", inverse_response)
        write_vignette(self.root / "vignette.png", vignette)

    def write_frames(self, records: Sequence[FrameRecord]) -> None:
        write_frames_csv(self.root / "sim_frames.csv", records)

    def write_config(self, record: dict[str, Any]) -> None:
        import yaml

        text = yaml.safe_dump(record, sort_keys=True, default_flow_style=None, width=100)
        (self.root / "sim_config.yaml").write_text(text, encoding="utf-8")
