"""Run the VO over a dataset and write its outputs (trajectory, keyframes, map, status, scale)."""

from __future__ import annotations

import csv
import json
import logging
import sys
from pathlib import Path

import numpy as np

from amrvio.errors import DatasetFormatError
from amrvio.io.dataset import Dataset
from amrvio.pipeline.vo import PoseStatus, VoConfig, VoOutput, VoPipeline
from amrvio.types.trajectory import Trajectory

log = logging.getLogger(__name__)


def run_vo(
    dataset: Dataset,
    config: VoConfig | None = None,
    *,
    max_frames: int | None = None,
    progress: bool = False,
) -> VoOutput:
    """Feed every frame of ``dataset`` (undistorted to its pinhole K) through the VO."""
    cam = dataset.camera
    if cam is None:
        raise DatasetFormatError(dataset.root, "the dataset has no camera calibration; pass one")
    pin = cam.pinhole()
    undistort = any(abs(c) > 0 for c in cam.distortion)
    vo = VoPipeline(np.asarray(pin.K, dtype=np.float64), config)
    frames = dataset.frames[:max_frames] if max_frames else dataset.frames
    it = frames
    if progress:
        from tqdm import tqdm

        it = tqdm(frames, desc="vo", unit="frame", file=sys.stderr,
                  disable=not sys.stderr.isatty())
    for fr in it:
        img = fr.load()
        if undistort:
            img = np.asarray(cam.undistort_image(img), dtype=np.uint8)
        vo.process(img, fr.t_ns)
    return vo.finish()


def write_outputs(out: VoOutput, out_dir: Path) -> dict[str, object]:
    """Write DIR/trajectory.tum, keyframes.tum, map.ply, frames.csv, scale_drift.csv and
    summary.json. Returns the summary."""
    from amrvio.io.trajectory import write_tum

    out_dir.mkdir(parents=True, exist_ok=True)
    stamps_s = out.stamps_ns.astype(np.float64) * 1e-9
    traj = Trajectory.from_matrices(stamps_s, out.T_world_cam)
    write_tum(out_dir / "trajectory.tum", traj)
    write_tum(out_dir / "keyframes.tum", traj.select(out.keyframe_indices))
    _write_ply(out_dir / "map.ply", out.map_points)
    with (out_dir / "frames.csv").open("w", newline="", encoding="utf-8") as fh:
        w = csv.writer(fh)
        w.writerow(["index", "t_s", "status", "segment", "keyframe", "n_tracks", "n_inliers",
                    "blurred", "blur_score", "brightness_a", "brightness_b", "scale", "event"])
        for i, f in enumerate(out.frames):
            w.writerow([f.index, f"{stamps_s[i]:.9f}", f.status.value, f.segment,
                        int(f.is_keyframe), f.n_tracks, f.n_inliers, int(f.blurred),
                        f"{f.blur_score:.2f}", f"{f.brightness_a:.4f}", f"{f.brightness_b:.2f}",
                        f"{out.frame_scale[i]:.5f}", f.event])
    with (out_dir / "scale_drift.csv").open("w", newline="", encoding="utf-8") as fh:
        w = csv.writer(fh)
        w.writerow(["frame_index", "t_s", "status", "height_map_units", "scale", "n_inliers",
                    "smoothed_scale"])
        for h in out.height_record:
            w.writerow([h.frame_index, f"{stamps_s[h.frame_index]:.9f}", h.status.value,
                        f"{h.height_map:.6f}", f"{h.scale:.6f}", h.n_inliers,
                        f"{out.frame_scale[h.frame_index]:.6f}"])
    counts = {s.value: sum(f.status is s for f in out.frames) for s in PoseStatus}
    summary: dict[str, object] = {
        "n_frames": len(out.frames),
        "status_counts": counts,
        "n_keyframes": len(out.keyframe_indices),
        "n_map_points": len(out.map_points),
        "events": [[i, e] for i, e in out.events],
        "timings_s": {k: round(v, 4) for k, v in out.timings_s.items()},
    }
    (out_dir / "summary.json").write_text(json.dumps(summary, indent=1) + "\n", encoding="utf-8")
    return summary


def _write_ply(path: Path, pts: np.ndarray) -> None:
    head = ("ply\nformat ascii 1.0\n"
            f"element vertex {len(pts)}\nproperty float x\nproperty float y\nproperty float z\n"
            "end_header\n")
    body = "".join(f"{x:.4f} {y:.4f} {z:.4f}\n" for x, y, z in pts)
    path.write_text(head + body, encoding="ascii")


__all__ = ["run_vo", "write_outputs"]
