"""One run of the whole product on a recording: diagnostics, tracking, evaluation and report.

:func:`run` is ``amrvio run`` as a function. Without ``out`` it keeps everything in memory and
returns it; with ``out`` it writes the output folder as the run goes (see
:mod:`amrvio.pipeline.run_output`) and then ``eval.json`` (when the dataset has ground truth),
``report.html`` and, with ``bag_out``, a ROS 2 bag of the trajectory.

    import amrvio
    res = amrvio.run("euroc:/data/MH_01_easy")            # or a Dataset, with config=...
    print(res.summary["status_counts"], res.eval_summary)
    res.trajectory                                         # amrvio.types.Trajectory, T_world_cam

For images of your own, feed :class:`amrvio.pipeline.pipeline.Pipeline` frame by frame.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from amrvio.config import PipelineConfig, config_from_dict, dump_config, load_config
from amrvio.errors import ConfigError, DatasetFormatError
from amrvio.io.base import Dataset, SkippedFrame
from amrvio.pipeline.events import run_events
from amrvio.pipeline.pipeline import PipelineOutput
from amrvio.pipeline.records import FrameRecord
from amrvio.pipeline.run import FrameSink, replacing, run_pipeline, summarise, write_json
from amrvio.pipeline.run_eval import (
    RunEvaluation,
    estimate_trajectory,
    evaluate_run,
    posed_indices,
)
from amrvio.types.trajectory import Trajectory

ConfigLike = PipelineConfig | str | Path | Mapping[str, Any] | None
"""A configuration, a YAML file of one, or its mapping (keys = field names); None: defaults."""


@dataclass(frozen=True, slots=True, eq=False)
class RunResult:
    """A finished (or interrupted) run: the pipeline output (one record per frame, refined
    poses, map), the summary (as summary.json), the events (as events.jsonl), the advice lines,
    the evaluation against ground truth (None without one), the configuration used and the
    output folder (None for a run in memory)."""

    output: PipelineOutput
    summary: dict[str, Any]
    events: tuple[dict[str, Any], ...]
    advice: tuple[str, ...]
    evaluation: RunEvaluation | None
    config: PipelineConfig
    out_dir: Path | None

    @property
    def records(self) -> Sequence[FrameRecord]:
        return self.output.records

    @property
    def trajectory(self) -> Trajectory:
        """``T_world_cam`` of every frame with a pose (trajectory.tum)."""
        return estimate_trajectory(self.output)

    @property
    def interrupted(self) -> bool:
        return bool(self.summary.get("interrupted"))

    @property
    def eval_summary(self) -> dict[str, Any] | None:
        """The figures of eval.json, or None without ground truth."""
        return self.evaluation.summary if self.evaluation is not None else None


def as_config(config: ConfigLike) -> PipelineConfig:
    """A PipelineConfig from any :data:`ConfigLike`."""
    if config is None:
        return PipelineConfig()
    if isinstance(config, PipelineConfig):
        return config
    if isinstance(config, str | Path):
        return load_config(Path(config))
    if isinstance(config, Mapping):
        return config_from_dict(dict(config), "config")
    raise ConfigError(f"config must be a PipelineConfig, a YAML file or a mapping, got "
                      f"{type(config).__name__}")


class _Skips:
    """Collects the skipped images and passes everything on."""

    def __init__(self, inner: FrameSink | None) -> None:
        self.inner = inner
        self.skipped: list[SkippedFrame] = []

    def record(self, rec: FrameRecord) -> None:
        if self.inner is not None:
            self.inner.record(rec)

    def skip(self, skipped: SkippedFrame) -> None:
        self.skipped.append(skipped)
        if self.inner is not None:
            self.inner.skip(skipped)


def run(dataset: str | Path | Dataset, config: ConfigLike = None, *, out: str | Path | None = None,
        calib: str | Path | None = None, max_frames: int | None = None, force: bool = False,
        progress: bool = False, report: bool = True, bag_out: str | Path | None = None,
        gt: str | Path | None = None, gt_frame: str = "cam",
        stop: Callable[[], bool] | None = None) -> RunResult:
    """Run the pipeline on ``dataset`` (a Dataset, or a spec such as ``euroc:PATH`` or a bare
    folder) and evaluate it against its ground truth.

    ``out``: write the output folder there (checked before any work; a non-empty one needs
    ``force``). ``progress``: a progress bar with a live health line on stderr. ``report``:
    write report.html (with ``out``). ``bag_out``: a ROS 2 bag folder (must not exist) with the
    trajectory as nav_msgs/Odometry. ``gt``: a ground-truth file (TUM, EuRoC CSV or KITTI
    poses) that replaces the dataset's own, of the camera (``gt_frame="cam"``) or of the body
    (``"body"``: times the dataset's T_body_cam). ``stop()`` is asked before each frame; True ends
    the run there (the outputs cover the frames done and say the run was interrupted).
    Bad input is an :class:`~amrvio.errors.AmrvioError` naming the file and the problem.
    """
    from amrvio.diagnostics.advice import make_advice
    from amrvio.io.dataset import open_dataset
    from amrvio.io.outdir import prepare_output_dir
    from amrvio.pipeline.diagnose import setup_diagnostics
    from amrvio.pipeline.run_output import RUN_OUTPUTS, RunWriter

    cfg = as_config(config)
    out_dir = Path(out) if out is not None else None
    if out_dir is not None:
        prepare_output_dir(out_dir, force, RUN_OUTPUTS)
    bag_path = Path(bag_out) if bag_out is not None else None
    if bag_path is not None:
        from amrvio.io.bag_out import check_bag_path

        check_bag_path(bag_path)
    if gt_frame not in ("cam", "body"):
        raise ConfigError(f"gt_frame must be cam or body, got {gt_frame!r}")
    gt_traj = None
    if gt is not None:
        from amrvio.io.trajectory import read_trajectory

        gt_traj = read_trajectory(gt)
    ds = dataset if isinstance(dataset, Dataset) else open_dataset(
        str(dataset), Path(calib) if calib is not None else None)
    if gt_traj is not None:
        ds = dataclasses.replace(ds, groundtruth=gt_traj, groundtruth_frame=gt_frame)
    if ds.camera is None:
        raise DatasetFormatError(ds.root, "the dataset has no camera calibration; pass one "
                                          "with --calib FILE (Kalibr, EuRoC sensor.yaml, "
                                          "ORB-SLAM3, KITTI calib.txt or DSO camera.txt)")
    setup = setup_diagnostics(ds, cfg.diagnostics) if cfg.diagnose else None
    notes = setup.notes if setup is not None else ()
    n_planned = min(len(ds.frames), max_frames or len(ds.frames))
    writer = RunWriter(out_dir, cfg, notes, n_planned) if out_dir is not None else None
    inner: FrameSink | None = writer
    bar = None
    if progress:
        from amrvio.app.progress import ProgressSink

        bar = ProgressSink(n_planned, writer)
        inner = bar
    sink = _Skips(inner)
    if writer is not None:
        writer.begin()
    stopped = False

    def ask() -> bool:
        nonlocal stopped
        stopped = stopped or (stop is not None and stop())
        return stopped

    try:
        output = run_pipeline(ds, cfg, max_frames=max_frames, diagnostics=setup, sink=sink,
                              stop=ask)
        ask()  # a Ctrl-C during the last frame counts too
        if writer is not None:
            summary = writer.finish(output, interrupted=stopped)
        else:
            summary = summarise(output, cfg, skipped=sink.skipped, interrupted=stopped)
    except KeyboardInterrupt:  # a second Ctrl-C: keep the partial files as they are
        if writer is not None:
            writer.abandon()
        raise
    finally:
        if bar is not None:
            bar.close()
    healths = [r.diagnostics for r in output.records if r.diagnostics is not None]
    advice = tuple(make_advice(healths, cfg.diagnostics.smear_bound_px) + list(notes))
    events = tuple(run_events(output.records, sink.skipped))
    evaluation = evaluate_run(ds, output, cfg)
    result = RunResult(output, summary, events, advice, evaluation, cfg, out_dir)
    if out_dir is not None:
        if evaluation is not None:
            write_json(out_dir / "eval.json", evaluation.summary)
        if report:
            write_report(result, out_dir / "report.html", f"{ds.kind}:{ds.root.name}", notes)
    if bag_path is not None:
        from amrvio.io.bag_out import write_odometry_bag

        idx = posed_indices(output)
        write_odometry_bag(bag_path, output.stamps_ns[idx], output.T_world_cam[idx])
    return result


def write_report(result: RunResult, path: Path, title: str,
                 notes: tuple[str, ...] = ()) -> Path:
    """report.html of a run (see :mod:`amrvio.report.run_report`)."""
    from amrvio.report.run_report import ReportInput, render_html

    ev = result.evaluation
    data = ReportInput(title=title, output=result.output, summary=result.summary,
                       advice=result.advice, events=result.events,
                       config_yaml=dump_config(result.config),
                       eval_summary=ev.summary if ev is not None else None,
                       sim3=ev.sim3 if ev is not None else None, notes=notes)
    with replacing(path) as tmp:
        tmp.write_text(render_html(data), encoding="utf-8")
    return path


__all__ = ["ConfigLike", "RunResult", "as_config", "run", "write_report"]
