"""Run the pipeline over a dataset, and write its outputs from the frame records.

:func:`run_pipeline` feeds the frames one by one; an image that cannot be used (unreadable,
truncated, another size than the recording's) is skipped, logged with its file name and counted,
never tracked. A :class:`FrameSink` sees every record and every skip as the run goes (the
``amrvio run`` output folder is written that way, see :mod:`amrvio.pipeline.run_output`), and a
``stop`` callable ends the run between two frames (Ctrl-C) so that the records stay consistent.
"""

from __future__ import annotations

import csv
import dataclasses
import json
import logging
import math
import sys
from collections.abc import Callable, Iterable, Sequence
from pathlib import Path
from typing import Any, Protocol

import numpy as np
from numpy.typing import NDArray

from amrvio.config import PipelineConfig, config_to_dict
from amrvio.diagnostics.health import health_columns
from amrvio.errors import DatasetFormatError
from amrvio.estimator.wheel_calibration import calibrate_wheel
from amrvio.imu.window import frame_imu_window
from amrvio.io.base import Dataset, SkippedFrame, load_checked
from amrvio.pipeline.diagnose import DiagnosticsSetup, setup_diagnostics
from amrvio.pipeline.events import flagged_ranges
from amrvio.pipeline.pipeline import Pipeline, PipelineOutput
from amrvio.pipeline.records import FrameRecord, PoseStatus
from amrvio.pipeline.vio_report import VIO_COLUMNS, ImuSetup
from amrvio.types.sensors import Frame, ImuNoise, WheelData
from amrvio.types.trajectory import Trajectory

log = logging.getLogger(__name__)


class FrameSink(Protocol):
    """What :func:`run_pipeline` tells as it goes: each frame's record (online pose and status)
    and each skipped frame."""

    def record(self, rec: FrameRecord) -> None: ...

    def skip(self, skipped: SkippedFrame) -> None: ...


def run_pipeline(
    dataset: Dataset,
    config: PipelineConfig | None = None,
    *,
    max_frames: int | None = None,
    progress: bool = False,
    diagnostics: DiagnosticsSetup | None = None,
    sink: FrameSink | None = None,
    stop: Callable[[], bool] | None = None,
) -> PipelineOutput:
    """Feed every frame of ``dataset`` and its IMU samples through the pipeline. With
    ``config.diagnose`` and no ``diagnostics`` given, the diagnostics stage is set up with its
    defaults for this dataset (gyro bias from a still start).

    A frame whose image cannot be used is skipped (one warning naming the file; ``sink.skip``);
    when no frame is usable that is a DatasetFormatError naming the first bad file. ``stop()`` is
    asked before each frame; True ends the run there, and the output covers the frames done.
    """
    cfg = config or PipelineConfig()
    cam = dataset.camera
    if cam is None:
        raise DatasetFormatError(dataset.root, "the dataset has no camera calibration; pass one")
    if diagnostics is None and cfg.diagnose:
        diagnostics = setup_diagnostics(dataset, cfg.diagnostics)
    wheel = wheel_readings(dataset, cfg)
    inertial = imu_setup(dataset, cfg)
    pipe = Pipeline(cam, cfg, diagnostics.stage if diagnostics is not None else None, inertial, wheel=wheel)
    expo_default = diagnostics.config.assumed_exposure_s if diagnostics is not None else None
    frames = dataset.frames[:max_frames] if max_frames else dataset.frames
    it: Iterable[Frame] = frames
    if progress:
        from tqdm import tqdm

        it = tqdm(frames, desc="amrvio", unit="frame", file=sys.stderr,
                  disable=not sys.stderr.isatty())
    size_hw = (cam.height, cam.width)
    prev_t: int | None = None
    first_skip: SkippedFrame | None = None
    n_skipped = 0
    stopped = False
    for fr in it:
        if stop is not None and stop():
            stopped = True
            break
        image = load_checked(fr, size_hw)
        if isinstance(image, SkippedFrame):
            log.warning("skipped frame %d: %s", fr.index, image.line())
            first_skip = first_skip or image
            n_skipped += 1
            if sink is not None:
                sink.skip(image)
            continue
        imu = None
        if dataset.imu is not None and (diagnostics is not None or inertial is not None):
            imu = frame_imu_window(dataset.imu, fr.t_ns, prev_t,
                                   fr.exposure_s or expo_default or 0.0)
        rec = pipe.process(image, fr.t_ns, imu, fr.exposure_s)
        if sink is not None:
            sink.record(rec)
        prev_t = fr.t_ns
    if first_skip is not None and not pipe.records and not stopped:
        raise DatasetFormatError(first_skip.file, f"{first_skip.problem}; no usable image: all "
                                                  f"{n_skipped} frames are unusable")
    out = pipe.finish()
    if wheel is not None and out.body is not None:
        out = dataclasses.replace(out, wheel_calibration=calibrate_wheel(
            out.stamps_ns, out.body.T_world_body, out.body.init_frame, wheel, applied=cfg.scale.wheel.factor,
            wheels_used=cfg.vio.wheel_sigma_m_s > 0))
    return out


def wheel_readings(dataset: Dataset, config: PipelineConfig) -> WheelData | None:
    """The recording's wheel odometry divided by its calibration ``scale.wheel.factor``."""
    factor = config.scale.wheel.factor
    return dataset.wheel if dataset.wheel is None or factor == 1.0 else dataset.wheel.divided(factor)


def imu_setup(dataset: Dataset, config: PipelineConfig) -> ImuSetup | None:
    """The VIO stage's inputs when the recording has an IMU and its camera-IMU transform and
    ``config.vio.enabled`` (None: the VO alone). Without a noise file, the ADIS16448's."""
    if dataset.imu is None or len(dataset.imu) < 2 or dataset.T_body_cam is None or not config.vio.enabled:
        return None
    return ImuSetup(dataset.imu_noise or ImuNoise.euroc_adis16448(), dataset.T_body_cam,
                    wheel_readings(dataset, config))


def diagnose(dataset: Dataset, config: PipelineConfig | None = None, *,
             gyro_bias: str | NDArray[np.float64] = "auto", assumed_ms: float | None = None,
             max_frames: int | None = None, progress: bool = False,
             stop: Callable[[], bool] | None = None,
             ) -> tuple[Sequence[FrameRecord], DiagnosticsSetup]:
    """The per-frame health of ``dataset``: the pipeline with tracking off (unusable images
    skipped, ``stop`` as in :func:`run_pipeline`)."""
    cfg = dataclasses.replace(config or PipelineConfig(), track=False, diagnose=True)
    setup = setup_diagnostics(dataset, cfg.diagnostics, gyro_bias, assumed_ms)
    out = run_pipeline(dataset, cfg, max_frames=max_frames, progress=progress,
                       diagnostics=setup, stop=stop)
    return out.records, setup


def write_health(path: Path, records: Sequence[FrameRecord],
                 online_status: Sequence[PoseStatus] | None = None) -> None:
    """health.csv: one row per frame, the diagnostics columns (when computed) then the tracking
    columns (when tracked). ``online_status``: each frame's status when it was processed (the
    online position is left empty for a frame LOST then; default: the final status). The rows
    are written as the records are read (one pass decides the columns, one writes), so the
    memory does not grow with the recording."""
    n = n_health = 0
    tracked = excitation = vio = False
    for r in records:
        n += 1
        n_health += r.diagnostics is not None
        excitation = excitation or (r.diagnostics is not None and r.diagnostics.excitation is not None)
        tracked = tracked or r.tracking is not None
        vio = vio or r.estimator.vio is not None
    with_health = n_health == n > 0
    cols = health_csv_columns(with_health, excitation, tracked, vio)
    with path.open("w", newline="", encoding="utf-8") as fh:
        w = csv.DictWriter(fh, fieldnames=cols, extrasaction="ignore")
        w.writeheader()
        for i, r in enumerate(records):
            row: dict[str, str] = {}
            if with_health and r.diagnostics is not None:
                row.update(r.diagnostics.as_row())
            if tracked:
                on = online_status[i] if online_status is not None else None
                row.update(zip(FRAME_COLUMNS, frame_row(r, on), strict=True))
                if r.estimator.vio is not None:
                    row.update(r.estimator.vio.health_fields())
            w.writerow(row)


def health_csv_columns(health: bool, excitation: bool, tracked: bool, vio: bool) -> list[str]:
    """health.csv's columns: the diagnostics' (``health``; with ``excitation``), then the
    tracking columns (``tracked``; the frame index and time once), then the VIO's (``vio``)."""
    cols = health_columns(excitation) if health else []
    if tracked:
        cols += FRAME_COLUMNS if not cols else FRAME_COLUMNS[2:]
        cols += VIO_COLUMNS if vio else []
    return cols


FRAME_COLUMNS = ["index", "t_s", "status", "segment", "is_keyframe", "vo_tracks", "n_inliers",
                 "tracking", "blur_score", "brightness_a", "brightness_b", "init_status", "scale",
                 "online_x", "online_y", "online_z", "events"]
"""The tracking columns of health.csv; ``vo_tracks``: the tracker's live tracks (the
diagnostics' own ``n_tracks`` counts the tracks since the parallax reference)."""


def _num(v: float, fmt: str) -> str:
    """``v`` formatted, or empty when it is not finite (no NaN or inf in an output)."""
    return format(v, fmt) if math.isfinite(v) else ""


def frame_row(r: FrameRecord, online_status: PoseStatus | None = None) -> list[str]:
    """The tracking columns (``FRAME_COLUMNS``) of a record; the online position is empty for a
    frame without an online pose, and for one LOST when processed (``online_status``, default
    the record's status): its pose then is a placeholder."""
    tr = r.tracking
    status_then = online_status if online_status is not None else r.status
    has_pose = r.pose_online is not None and status_then is not PoseStatus.LOST
    on = r.pose_online.t if r.pose_online is not None and has_pose else np.full(3, np.nan)
    return [str(r.index), f"{r.t_ns * 1e-9:.9f}", r.status.value,
            "" if r.segment is None else str(r.segment), str(int(r.is_keyframe)),
            str(tr.n_tracks if tr else 0), str(tr.n_inliers if tr else 0),
            tr.outcome.value if tr else "", _num(r.blur.score, ".2f"),
            _num(tr.brightness_a, ".4f") if tr else "", _num(tr.brightness_b, ".2f") if tr else "",
            r.estimator.init.status.value if r.estimator.init is not None else "",
            _num(r.scale_factor, ".5f"), *(_num(float(v), ".6f") for v in on), ";".join(r.events)]


TRAJECTORY_COMMENT = ("# amrvio {name}: T_world_cam, the camera pose in the world frame (the first "
                      "map's first keyframe), per frame at its image time; LOST frames are left "
                      "out (their status is in health.csv)")


BODY_TRAJECTORY_COMMENT = (
    "# amrvio {name}: T_world_body, the pose of the IMU body frame (EuRoC's ground-truth frame) "
    "in the gravity-aligned metric world (z up, yaw and origin of the visual-inertial "
    "initialisation), per frame at its image time; LOST frames are left out (their status is in "
    "health.csv)")


def pose_rows(stamps_s: NDArray[np.float64], T_world_cam: NDArray[np.float64],
              keep: Sequence[bool]) -> tuple[NDArray[np.int64], Trajectory]:
    """The frames to write (``keep`` and a finite pose) and their trajectory."""
    finite = np.all(np.isfinite(T_world_cam.reshape(-1, 16)), axis=1)
    idx = np.flatnonzero(np.asarray(keep, dtype=bool) & finite).astype(np.int64)
    return idx, Trajectory.from_matrices(stamps_s[idx], T_world_cam[idx])


def write_outputs(out: PipelineOutput, out_dir: Path, config: PipelineConfig | None = None,
                  notes: Sequence[str] = (), *, skipped: Sequence[SkippedFrame] = (),
                  interrupted: bool = False,
                  online_status: Sequence[PoseStatus] | None = None) -> dict[str, Any]:
    """Write DIR/trajectory.tum (refined poses), trajectory_online.tum (the pose each frame had
    when it was processed), keyframes.tum, map.ply, health.csv, advice.txt, scale_drift.csv,
    summary.json (with the configuration used; the same for the same input) and timings.json
    (seconds per stage; differs from run to run). Returns the summary.

    A frame LOST in the end is not in trajectory.tum; one LOST when it was processed
    (``online_status``, else its final status) is not in trajectory_online.tum. Each file is
    written beside and then moved into place, so a file present is complete.
    """
    from amrvio.io.trajectory import write_tum

    out_dir.mkdir(parents=True, exist_ok=True)
    records = out.records
    stamps_s = out.stamps_ns.astype(np.float64) * 1e-9
    final_ok = [r.status is not PoseStatus.LOST for r in records]
    comment = TRAJECTORY_COMMENT if out.body is None else BODY_TRAJECTORY_COMMENT
    idx, traj = pose_rows(stamps_s, out.T_world_cam if out.body is None else out.body.T_world_body,
                          final_ok)
    with replacing(out_dir / "trajectory.tum") as tmp:
        write_tum(tmp, traj, comment.format(name="trajectory.tum"))
    kf = np.isin(idx, out.keyframe_indices)
    with replacing(out_dir / "keyframes.tum") as tmp:
        write_tum(tmp, traj.select(np.flatnonzero(kf)),
                  comment.format(name="keyframes.tum") + "; VO keyframes only")
    statuses = online_status if online_status is not None else [r.status for r in records]
    online = [(i, r.pose_online) for i, r in enumerate(records)
              if r.pose_online is not None and statuses[i] is not PoseStatus.LOST]
    on_T = (np.stack([p.matrix() for _, p in online]) if online else np.zeros((0, 4, 4)))
    on_idx = np.array([i for i, _ in online], dtype=np.int64)
    _, on_traj = pose_rows(stamps_s[on_idx], on_T, [True] * len(online))
    with replacing(out_dir / "trajectory_online.tum") as tmp:
        write_tum(tmp, on_traj, TRAJECTORY_COMMENT.format(name="trajectory_online.tum").replace(
            "LOST frames", "frames LOST when processed"))
    with replacing(out_dir / "map.ply") as tmp:
        _write_ply(tmp, out.map_points)
    with replacing(out_dir / "health.csv") as tmp:
        write_health(tmp, records, online_status)
    with replacing(out_dir / "advice.txt") as tmp:
        write_advice(tmp, records, config or PipelineConfig(),
                     [*notes, *([] if out.wheel_calibration is None else [out.wheel_calibration.advice()])])
    with replacing(out_dir / "scale_drift.csv") as tmp:
        _write_scale_drift(tmp, out, stamps_s)
    write_json(out_dir / "timings.json", {"timings_s": {
        k: round(v, 4) for k, v in sorted(out.timings_s.items()) if math.isfinite(v)}})
    summary = summarise(out, config, skipped=skipped, interrupted=interrupted,
                        n_in_trajectory=len(idx))
    write_json(out_dir / "summary.json", summary)
    return summary


def _write_scale_drift(path: Path, out: PipelineOutput, stamps_s: NDArray[np.float64]) -> None:
    with path.open("w", newline="", encoding="utf-8") as fh:
        w = csv.writer(fh)
        w.writerow(["frame_index", "t_s", "status", "height_map_units", "scale", "n_inliers",
                    "smoothed_scale"])
        for h in out.height_readings:
            w.writerow([h.frame_index, f"{stamps_s[h.frame_index]:.9f}", h.status.value,
                        _num(h.height_map, ".6f"), _num(h.scale, ".6f"), h.n_inliers,
                        _num(float(out.frame_scale[h.frame_index]), ".6f")])


class replacing:  # noqa: N801 (used as a context manager, like open)
    """``with replacing(path) as tmp:`` write ``tmp``; on success it replaces ``path`` at once,
    so a reader (or a run stopped half-way) never sees a half-written file."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self.tmp = path.with_name(f".{path.name}.partial")

    def __enter__(self) -> Path:
        return self.tmp

    def __exit__(self, exc_type: object, exc: object, tb: object) -> None:
        if exc_type is None:
            self.tmp.replace(self.path)
        else:
            self.tmp.unlink(missing_ok=True)


def finite_json(value: Any) -> Any:
    """``value`` with every non-finite float replaced by None (JSON has no NaN or inf)."""
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        return {k: finite_json(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [finite_json(v) for v in value]
    return value


def write_json(path: Path, data: dict[str, Any]) -> None:
    """Strict JSON (no NaN or inf: those become null), written beside and moved into place."""
    with replacing(path) as tmp:
        tmp.write_text(json.dumps(finite_json(data), indent=1, allow_nan=False) + "\n",
                       encoding="utf-8")


def write_advice(path: Path, records: Sequence[FrameRecord], config: PipelineConfig,
                 notes: Sequence[str] = ()) -> list[str]:
    """advice.txt: the problem ranges of the health record with remedies, then the notes."""
    from amrvio.diagnostics.advice import make_advice

    healths = [r.diagnostics for r in records if r.diagnostics is not None]
    lines = make_advice(healths, config.diagnostics.smear_bound_px) + list(notes)
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return lines


def summarise(out: PipelineOutput, config: PipelineConfig | None, *,
              skipped: Sequence[SkippedFrame] = (), interrupted: bool = False,
              n_in_trajectory: int | None = None) -> dict[str, Any]:
    """The run summary from the records: frames, status counts, keyframes, events, the flagged
    frame ranges by cause (:func:`amrvio.pipeline.events.flagged_ranges`, as frame indices),
    skipped frames, the configuration; whether the run was interrupted (Ctrl-C: the figures cover the
    frames done). No wall-clock figure: the same input gives the same summary (timings are in
    timings.json)."""
    counts = {s.value: sum(r.status is s for r in out.records) for s in PoseStatus}
    n_traj = n_in_trajectory if n_in_trajectory is not None else (
        len(out.records) - counts[PoseStatus.LOST.value])
    return {
        "state": "interrupted" if interrupted else "finished",
        "interrupted": interrupted,
        "n_frames": len(out.records),
        "n_skipped": len(skipped),
        "n_in_trajectory": n_traj,
        "status_counts": counts,
        "n_keyframes": len(out.keyframe_indices),
        "n_map_points": len(out.map_points),
        "events": [[r.index, e] for r in out.records for e in r.events],
        "flagged_ranges": {c: [[out.records[a].index, out.records[b].index] for a, b in rr]
                           for c, rr in flagged_ranges(out.records).items()},
        "skipped_frames": [{"index": s.index, "t_ns": s.t_ns, "file": s.file, "problem": s.problem}
                           for s in skipped],
        "wheel_calibration": None if out.wheel_calibration is None else out.wheel_calibration.as_dict(),
        "config": config_to_dict(config or PipelineConfig()),
    }


def _write_ply(path: Path, pts: np.ndarray) -> None:
    """map.ply: the finite points, ASCII."""
    pts = pts[np.all(np.isfinite(pts), axis=1)] if len(pts) else pts
    head = ("ply\nformat ascii 1.0\n"
            f"element vertex {len(pts)}\nproperty float x\nproperty float y\nproperty float z\n"
            "end_header\n")
    body = "".join(f"{x:.4f} {y:.4f} {z:.4f}\n" for x, y, z in pts)
    path.write_text(head + body, encoding="ascii")


__all__ = ["BODY_TRAJECTORY_COMMENT", "FRAME_COLUMNS", "TRAJECTORY_COMMENT", "FrameSink", "diagnose", "finite_json",
           "frame_row", "health_csv_columns", "imu_setup", "pose_rows", "replacing", "run_pipeline", "summarise",
           "wheel_readings", "write_advice", "write_health", "write_json", "write_outputs"]
