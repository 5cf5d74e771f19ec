"""Run the pipeline over a dataset, and write its outputs from the frame records."""

from __future__ import annotations

import csv
import dataclasses
import json
import sys
from collections.abc import Iterable, Sequence
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from amrvio.config import PipelineConfig, config_to_dict
from amrvio.diagnostics.health import health_rows
from amrvio.errors import DatasetFormatError
from amrvio.imu.window import frame_imu_window
from amrvio.io.base import Dataset
from amrvio.pipeline.diagnose import DiagnosticsSetup, setup_diagnostics
from amrvio.pipeline.pipeline import Pipeline, PipelineOutput
from amrvio.pipeline.records import FrameRecord, PoseStatus
from amrvio.types.sensors import Frame
from amrvio.types.trajectory import Trajectory


def run_pipeline(
    dataset: Dataset,
    config: PipelineConfig | None = None,
    *,
    max_frames: int | None = None,
    progress: bool = False,
    diagnostics: DiagnosticsSetup | None = None,
) -> PipelineOutput:
    """Feed every frame of ``dataset`` and its IMU samples through the pipeline. With
    ``config.diagnose`` and no ``diagnostics`` given, the diagnostics stage is set up with its
    defaults for this dataset (gyro bias from a still start)."""
    cfg = config or PipelineConfig()
    cam = dataset.camera
    if cam is None:
        raise DatasetFormatError(dataset.root, "the dataset has no camera calibration; pass one")
    if diagnostics is None and cfg.diagnose:
        diagnostics = setup_diagnostics(dataset, cfg.diagnostics)
    pipe = Pipeline(cam, cfg, diagnostics.stage if diagnostics is not None else None)
    expo_default = diagnostics.config.assumed_exposure_s if diagnostics is not None else None
    frames = dataset.frames[:max_frames] if max_frames else dataset.frames
    it: Iterable[Frame] = frames
    if progress:
        from tqdm import tqdm

        it = tqdm(frames, desc="amrvio", unit="frame", file=sys.stderr,
                  disable=not sys.stderr.isatty())
    prev_t: int | None = None
    for fr in it:
        imu = None
        if dataset.imu is not None and diagnostics is not None:
            imu = frame_imu_window(dataset.imu, fr.t_ns, prev_t,
                                   fr.exposure_s or expo_default or 0.0)
        pipe.process(fr.load(), fr.t_ns, imu, fr.exposure_s)
        prev_t = fr.t_ns
    return pipe.finish()


def diagnose(dataset: Dataset, config: PipelineConfig | None = None, *,
             gyro_bias: str | NDArray[np.float64] = "auto", assumed_ms: float | None = None,
             max_frames: int | None = None, progress: bool = False
             ) -> tuple[tuple[FrameRecord, ...], DiagnosticsSetup]:
    """The per-frame health of ``dataset``: the pipeline with tracking off."""
    cfg = dataclasses.replace(config or PipelineConfig(), track=False, diagnose=True)
    setup = setup_diagnostics(dataset, cfg.diagnostics, gyro_bias, assumed_ms)
    out = run_pipeline(dataset, cfg, max_frames=max_frames, progress=progress,
                       diagnostics=setup)
    return out.records, setup


def write_health(path: Path, records: Sequence[FrameRecord]) -> None:
    """health.csv: one row per frame, the diagnostics columns (when computed) then the tracking
    columns (when tracked)."""
    healths = [r.diagnostics for r in records if r.diagnostics is not None]
    tracked = any(r.tracking is not None for r in records)
    cols: list[str] = []
    rows: list[dict[str, str]] = [{} for _ in records]
    if len(healths) == len(records) and healths:
        hcols, hrows = health_rows(healths)
        cols += hcols
        for row, h in zip(rows, hrows, strict=True):
            row.update(h)
    if tracked:
        extra = FRAME_COLUMNS if not cols else FRAME_COLUMNS[2:]
        cols += extra
        for row, r in zip(rows, records, strict=True):
            row.update(zip(FRAME_COLUMNS, frame_row(r), strict=True))
    with path.open("w", newline="", encoding="utf-8") as fh:
        w = csv.DictWriter(fh, fieldnames=cols, extrasaction="ignore")
        w.writeheader()
        w.writerows(rows)


FRAME_COLUMNS = ["index", "t_s", "status", "segment", "is_keyframe", "n_tracks", "n_inliers",
                 "tracking", "blur_score", "brightness_a", "brightness_b", "init_status", "scale",
                 "online_x", "online_y", "online_z", "events"]


def frame_row(r: FrameRecord) -> list[str]:
    """The tracking columns (``FRAME_COLUMNS``) of a final record."""
    tr = r.tracking
    on = r.pose_online.t if r.pose_online is not None else np.full(3, np.nan)
    return [str(r.index), f"{r.t_ns * 1e-9:.9f}", r.status.value,
            "" if r.segment is None else str(r.segment), str(int(r.is_keyframe)),
            str(tr.n_tracks if tr else 0), str(tr.n_inliers if tr else 0),
            tr.outcome.value if tr else "", f"{r.blur.score:.2f}",
            f"{tr.brightness_a:.4f}" if tr else "", f"{tr.brightness_b:.2f}" if tr else "",
            r.estimator.init.status.value if r.estimator.init is not None else "", f"{r.scale_factor:.5f}",
            *(f"{v:.6f}" for v in on), ";".join(r.events)]


def write_outputs(out: PipelineOutput, out_dir: Path, config: PipelineConfig | None = None,
                  notes: Sequence[str] = ()) -> dict[str, object]:
    """Write DIR/trajectory.tum (refined poses), trajectory_online.tum (the pose each frame had
    when it was processed), keyframes.tum, map.ply, health.csv, advice.txt,
    scale_drift.csv and summary.json (with the configuration used). Returns the summary."""
    from amrvio.io.trajectory import write_tum

    out_dir.mkdir(parents=True, exist_ok=True)
    stamps_s = out.stamps_ns.astype(np.float64) * 1e-9
    traj = Trajectory.from_matrices(stamps_s, out.T_world_cam)
    write_tum(out_dir / "trajectory.tum", traj)
    write_tum(out_dir / "keyframes.tum", traj.select(out.keyframe_indices))
    online = [(i, r.pose_online) for i, r in enumerate(out.records) if r.pose_online is not None]
    if online:
        idx = np.array([i for i, _ in online], dtype=np.int64)
        write_tum(out_dir / "trajectory_online.tum", Trajectory.from_matrices(
            stamps_s[idx], np.stack([p.matrix() for _, p in online])))
    _write_ply(out_dir / "map.ply", out.map_points)
    write_health(out_dir / "health.csv", out.records)
    write_advice(out_dir / "advice.txt", out.records, config or PipelineConfig(), notes)
    with (out_dir / "scale_drift.csv").open("w", newline="", encoding="utf-8") as fh:
        w = csv.writer(fh)
        w.writerow(["frame_index", "t_s", "status", "height_map_units", "scale", "n_inliers",
                    "smoothed_scale"])
        for h in out.height_readings:
            w.writerow([h.frame_index, f"{stamps_s[h.frame_index]:.9f}", h.status.value,
                        f"{h.height_map:.6f}", f"{h.scale:.6f}", h.n_inliers,
                        f"{out.frame_scale[h.frame_index]:.6f}"])
    summary = summarise(out, config)
    (out_dir / "summary.json").write_text(json.dumps(summary, indent=1) + "\n", encoding="utf-8")
    return summary


def write_advice(path: Path, records: Sequence[FrameRecord], config: PipelineConfig,
                 notes: Sequence[str] = ()) -> list[str]:
    """advice.txt: the problem ranges of the health record with remedies, then the notes."""
    from amrvio.diagnostics.advice import make_advice

    healths = [r.diagnostics for r in records if r.diagnostics is not None]
    lines = make_advice(healths, config.diagnostics.smear_bound_px) + list(notes)
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return lines


def summarise(out: PipelineOutput, config: PipelineConfig | None) -> dict[str, object]:
    """The run summary from the records (status counts, keyframes, events, timings)."""
    counts = {s.value: sum(r.status is s for r in out.records) for s in PoseStatus}
    return {
        "n_frames": len(out.records),
        "status_counts": counts,
        "n_keyframes": len(out.keyframe_indices),
        "n_map_points": len(out.map_points),
        "events": [[r.index, e] for r in out.records for e in r.events],
        "config": config_to_dict(config or PipelineConfig()),
        "timings_s": {k: round(v, 4) for k, v in out.timings_s.items()},
    }


def _write_ply(path: Path, pts: np.ndarray) -> None:
    head = ("ply\nformat ascii 1.0\n"
            f"element vertex {len(pts)}\nproperty float x\nproperty float y\nproperty float z\n"
            "end_header\n")
    body = "".join(f"{x:.4f} {y:.4f} {z:.4f}\n" for x, y, z in pts)
    path.write_text(head + body, encoding="ascii")


__all__ = ["FRAME_COLUMNS", "diagnose", "frame_row", "run_pipeline", "summarise", "write_advice",
           "write_health", "write_outputs"]
