"""The ``amrvio run`` output folder, written as the run goes.

:class:`RunWriter` is the :class:`~amrvio.pipeline.run.FrameSink` of a command-line run. While the
frames go by it appends to ``health.csv`` (each frame's row as processed) and to
``trajectory_online.tum`` (the causal pose of each frame not LOST when processed) and to
``events.jsonl`` (each frame's events, see :mod:`amrvio.pipeline.events`), and keeps
``summary.json`` saying ``"state": "running"`` with the frame count. At the end
:meth:`RunWriter.finish` writes every output from the final records (refined poses, final
statuses), each file moved into place whole. A run stopped by Ctrl-C ends between two frames and
is finished the same way, with ``"interrupted": true``; a run killed harder still leaves
valid partial files and a summary that says it did not finish.
"""

from __future__ import annotations

import csv
from collections.abc import Sequence
from pathlib import Path
from typing import IO, Any

from amrvio.config import PipelineConfig, config_to_dict
from amrvio.io.base import SkippedFrame
from amrvio.pipeline.events import event_line, frame_events, run_events, skipped_event
from amrvio.pipeline.pipeline import PipelineOutput
from amrvio.pipeline.records import FrameRecord, PoseStatus
from amrvio.pipeline.run import (
    FRAME_COLUMNS,
    TRAJECTORY_COMMENT,
    frame_row,
    health_csv_columns,
    replacing,
    write_json,
    write_outputs,
)

RUN_OUTPUTS: tuple[str, ...] = (
    "trajectory.tum", "trajectory_online.tum", "keyframes.tum", "map.ply", "health.csv",
    "events.jsonl", "advice.txt", "scale_drift.csv", "summary.json", "timings.json", "eval.json",
    "report.html")
"""The files ``amrvio run`` writes (``--force`` removes these from an earlier run; eval.json and
report.html are written by the caller, see :mod:`amrvio.app.run`)."""

SUMMARY_EVERY = 20
"""The running summary.json is rewritten every this many frames."""


class RunWriter:
    """Writes ``out_dir`` for one run (the folder was checked and emptied before, see
    :func:`amrvio.io.outdir.prepare_output_dir`). ``n_planned``: frames the run will read."""

    def __init__(self, out_dir: Path, config: PipelineConfig, notes: Sequence[str] = (),
                 n_planned: int | None = None) -> None:
        self.out_dir = out_dir
        self.config = config
        self.notes = tuple(notes)
        self.n_planned = n_planned
        self.online_status: list[PoseStatus] = []
        self.skipped: list[SkippedFrame] = []
        self._health: IO[str] | None = None
        self._health_csv: csv.DictWriter[str] | None = None
        self._online: IO[str] | None = None
        self._events: IO[str] | None = None

    # ----------------------------------------------------------------- as the run goes
    def begin(self) -> None:
        """Open the growing files and write the first running summary."""
        self._online = (self.out_dir / "trajectory_online.tum").open("w", encoding="utf-8")
        self._online.write(TRAJECTORY_COMMENT.format(name="trajectory_online.tum").replace(
            "LOST frames", "frames LOST when processed") + "\n# timestamp_s tx ty tz qx qy qz qw\n")
        self._online.flush()
        self._events = (self.out_dir / "events.jsonl").open("w", encoding="utf-8")
        self._write_running()

    def record(self, rec: FrameRecord) -> None:
        self.online_status.append(rec.status)
        self._health_row(rec)
        if self._online is not None and rec.pose_online is not None \
                and rec.status is not PoseStatus.LOST:
            from amrvio.io.trajectory import tum_line

            line = tum_line(rec.t_ns * 1e-9, rec.pose_online.t, rec.pose_online.rot.quat_wxyz())
            if line is not None:
                self._online.write(line + "\n")
                self._online.flush()
        if self._events is not None:
            lines = frame_events(rec)
            if lines:
                self._events.write("".join(event_line(e) + "\n" for e in lines))
                self._events.flush()
        if len(self.online_status) % SUMMARY_EVERY == 0:
            self._write_running()

    def skip(self, skipped: SkippedFrame) -> None:
        self.skipped.append(skipped)
        if self._events is not None:
            self._events.write(event_line(skipped_event(skipped)) + "\n")
            self._events.flush()

    def _health_row(self, rec: FrameRecord) -> None:
        row = dict(zip(FRAME_COLUMNS, frame_row(rec), strict=True))
        if self._health_csv is None:
            d = rec.diagnostics
            cols = health_csv_columns(d is not None, d is not None and d.excitation is not None, True,
                                      rec.estimator.vio is not None)
            self._health = (self.out_dir / "health.csv").open("w", newline="", encoding="utf-8")
            self._health_csv = csv.DictWriter(self._health, fieldnames=cols, extrasaction="ignore")
            self._health_csv.writeheader()
        if rec.diagnostics is not None:
            row.update(rec.diagnostics.as_row())
        if rec.estimator.vio is not None:
            row.update(rec.estimator.vio.health_fields())
        self._health_csv.writerow(row)
        if self._health is not None:
            self._health.flush()

    def _write_running(self, state: str = "running") -> None:
        counts = {s.value: sum(x is s for x in self.online_status) for s in PoseStatus}
        write_json(self.out_dir / "summary.json", {
            "state": state,
            "interrupted": state == "interrupted",
            "n_frames": len(self.online_status),
            "n_planned": self.n_planned,
            "n_skipped": len(self.skipped),
            "status_counts_online": counts,
            "note": "partial: health.csv and trajectory_online.tum hold the frames done; the "
                    "refined trajectory.tum is written when the run ends",
            "config": config_to_dict(self.config),
        })

    def _close(self) -> None:
        for fh in (self._health, self._online, self._events):
            if fh is not None:
                fh.close()
        self._health = self._online = self._events = None

    # ----------------------------------------------------------------- the end
    def finish(self, out: PipelineOutput, interrupted: bool) -> dict[str, Any]:
        """Every output from the final records; returns the summary."""
        self._close()
        summary = write_outputs(out, self.out_dir, self.config, self.notes, skipped=self.skipped,
                                interrupted=interrupted, online_status=self.online_status)
        with replacing(self.out_dir / "events.jsonl") as tmp:
            tmp.write_text("".join(event_line(e) + "\n" for e in run_events(out.records,
                                                                            self.skipped)),
                           encoding="utf-8")
        return summary

    def abandon(self) -> None:
        """The run stopped before it could be finished (a second Ctrl-C): the growing files
        stay as they are, and summary.json says the run was interrupted."""
        self._close()
        self._write_running("interrupted")


__all__ = ["RUN_OUTPUTS", "SUMMARY_EVERY", "RunWriter"]
