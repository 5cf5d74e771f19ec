"""Run the pipeline over a dataset, and write its outputs from the frame records."""

from __future__ import annotations

import csv
import json
import sys
from collections.abc import Iterable
from pathlib import Path

import numpy as np

from amrvio.config import PipelineConfig, config_to_dict
from amrvio.errors import DatasetFormatError
from amrvio.io.dataset import Dataset
from amrvio.pipeline.pipeline import Pipeline, PipelineOutput
from amrvio.pipeline.records import FrameRecord, PoseStatus
from amrvio.types.trajectory import Trajectory


def run_pipeline(
    dataset: Dataset,
    config: PipelineConfig | None = None,
    *,
    max_frames: int | None = None,
    progress: bool = False,
) -> PipelineOutput:
    """Feed every frame of ``dataset`` (undistorted to its pinhole K) through the pipeline."""
    cam = dataset.camera
    if cam is None:
        raise DatasetFormatError(dataset.root, "the dataset has no camera calibration; pass one")
    pin = cam.pinhole()
    undistort = any(abs(c) > 0 for c in cam.distortion)
    pipe = Pipeline(np.asarray(pin.K, dtype=np.float64), config)
    frames = dataset.frames[:max_frames] if max_frames else dataset.frames
    it: Iterable = frames
    if progress:
        from tqdm import tqdm

        it = tqdm(frames, desc="vo", unit="frame", file=sys.stderr,
                  disable=not sys.stderr.isatty())
    for fr in it:
        img = fr.load()
        if undistort:
            img = np.asarray(cam.undistort_image(img), dtype=np.uint8)
        pipe.process(img, fr.t_ns)
    return pipe.finish()


FRAME_COLUMNS = ["index", "t_s", "status", "segment", "keyframe", "n_tracks", "n_inliers",
                 "tracking", "blur_score", "brightness_a", "brightness_b", "init_status", "scale",
                 "online_x", "online_y", "online_z", "events"]


def frame_row(r: FrameRecord) -> list[str]:
    """One row of frames.csv (``FRAME_COLUMNS``) from a final record."""
    tr = r.tracking
    on = r.pose_online.t if r.pose_online is not None else np.full(3, np.nan)
    return [str(r.index), f"{r.t_ns * 1e-9:.9f}", r.status.value,
            "" if r.segment is None else str(r.segment), str(int(r.is_keyframe)),
            str(tr.n_tracks if tr else 0), str(tr.n_inliers if tr else 0),
            tr.outcome.value if tr else "", f"{r.blur.score:.2f}",
            f"{tr.brightness_a:.4f}" if tr else "", f"{tr.brightness_b:.2f}" if tr else "",
            r.estimator.init.status.value if r.estimator.init is not None else "", f"{r.scale_factor:.5f}",
            *(f"{v:.6f}" for v in on), ";".join(r.events)]


def write_outputs(out: PipelineOutput, out_dir: Path,
                  config: PipelineConfig | None = None) -> dict[str, object]:
    """Write DIR/trajectory.tum, keyframes.tum, map.ply, frames.csv, scale_drift.csv and
    summary.json (with the configuration used). Returns the summary."""
    from amrvio.io.trajectory import write_tum

    out_dir.mkdir(parents=True, exist_ok=True)
    stamps_s = out.stamps_ns.astype(np.float64) * 1e-9
    traj = Trajectory.from_matrices(stamps_s, out.T_world_cam)
    write_tum(out_dir / "trajectory.tum", traj)
    write_tum(out_dir / "keyframes.tum", traj.select(out.keyframe_indices))
    _write_ply(out_dir / "map.ply", out.map_points)
    with (out_dir / "frames.csv").open("w", newline="", encoding="utf-8") as fh:
        w = csv.writer(fh)
        w.writerow(FRAME_COLUMNS)
        for r in out.records:
            w.writerow(frame_row(r))
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


__all__ = ["FRAME_COLUMNS", "frame_row", "run_pipeline", "summarise", "write_outputs"]
