"""``amrvio batch``: one ``amrvio run`` per recording, then one table of per-recording figures.

Inputs are dataset folders (or ``KIND:PATH`` specs), glob patterns, and text files that list
such inputs one a line (``#`` starts a comment; relative paths are relative to the list file).
Each recording is run into ``OUT/<name>/`` (the folder's name, made unique), on a local process
pool or on Ray tasks. A recording that fails (bad files, a crash) gets a row with its error and
does not stop the others; a recording whose folder holds a finished run with the same
configuration is not run again. The table (``batch.csv`` and ``batch.html``) is made from the
output folders' ``summary.json`` and ``eval.json`` only, so it does not depend on where or in
which order the recordings ran.
"""

from __future__ import annotations

import csv
import glob
import html
import json
import math
import os
import traceback
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from amrvio.errors import AmrvioError, ConfigError
from amrvio.pipeline.events import CAUSES

LIST_SUFFIXES = (".txt", ".list", ".lst")
"""A file with one of these suffixes is a list of inputs (other files are datasets: bags)."""

COLUMNS: tuple[str, ...] = (
    "recording", "dataset", "status", "frames", "in_trajectory", "with_pose_pct", "lost_frames",
    "keyframes", "losses", "relocalisations", "reinits",
    *(f"ranges_{c}" for c in CAUSES),
    "ate_sim3_m", "ate_sim3_pct", "ate_metric_m", "scale_error_pct", "eval_note", "error",
)
"""The columns of batch.csv (``ranges_CAUSE``: flagged frame ranges by cause)."""

Row = dict[str, str]


@dataclass(frozen=True, slots=True)
class Recording:
    """One input: its ``name`` (the output sub-folder) and dataset ``spec``."""

    name: str
    spec: str


@dataclass(frozen=True, slots=True)
class BatchOptions:
    """What every recording's run gets: the configuration (as its mapping), ``max_frames``,
    and whether to write report.html."""

    config: dict[str, Any]
    max_frames: int | None = None
    report: bool = True


# ------------------------------------------------------------------------------------ inputs
def _has_glob(text: str) -> bool:
    return any(ch in text for ch in "*?[")


def _split_kind(spec: str) -> tuple[str, str]:
    from amrvio.io.base import KINDS

    kind, sep, path = spec.partition(":")
    if sep and kind in KINDS:
        return f"{kind}:", path
    return "", spec


def expand_inputs(inputs: Sequence[str], _depth: int = 0) -> list[str]:
    """Dataset specs from folders, ``KIND:PATH`` specs, glob patterns and list files, in the
    order given, without repeats. An input that matches nothing is a ConfigError naming it."""
    if _depth > 4:
        raise ConfigError(f"{inputs[0]}: list files nested too deep (more than 4 levels)")
    out: list[str] = []
    for raw in inputs:
        kind, path = _split_kind(raw.strip())
        if not path:
            continue
        if _has_glob(path):
            found = sorted(glob.glob(os.path.expanduser(path)))
            if not found:
                raise ConfigError(f"{raw}: no file or folder matches the pattern")
            out += [kind + f for f in found if not Path(f).name.startswith(".")]
            continue
        p = Path(os.path.expanduser(path))
        if not kind and p.is_file() and p.suffix.lower() in LIST_SUFFIXES:
            out += expand_inputs(_read_list(p), _depth + 1)
        elif p.exists():
            out.append(kind + str(p))
        else:
            raise ConfigError(f"{raw}: no such file or folder")
    return list(dict.fromkeys(out))


def _read_list(path: Path) -> list[str]:
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as err:
        raise ConfigError(f"{path}: cannot read the list of recordings ({err})") from None
    items = []
    for line in text.splitlines():
        line = line.split("#", 1)[0].strip()
        if not line:
            continue
        kind, p = _split_kind(line)
        if not _has_glob(p) and not os.path.isabs(os.path.expanduser(p)):
            p = str(path.parent / p)
        elif _has_glob(p) and not os.path.isabs(os.path.expanduser(p)):
            p = os.path.join(str(path.parent), p)
        items.append(kind + p)
    if not items:
        raise ConfigError(f"{path}: the list of recordings is empty")
    return items


def recordings(specs: Sequence[str]) -> list[Recording]:
    """A unique output name for each spec: the folder's name, then its parent's, then a
    number."""
    names: list[str] = []
    for spec in specs:
        p = Path(_split_kind(spec)[1].rstrip("/"))
        base = (p.stem if p.is_file() else p.name) or "recording"
        name = base
        if name in names:
            name = f"{p.parent.name}_{base}" if p.parent.name else base
        k = 2
        while name in names:
            name = f"{base}_{k}"
            k += 1
        names.append(name)
    return [Recording(n, s) for n, s in zip(names, specs, strict=True)]


# ------------------------------------------------------------------------------------ one run
RUN_MARK = "batch_run.json"
"""Written in a recording's folder after its run finished: the dataset spec and the options it
ran with (a re-run skips the recording when they are the same)."""


def _mark(rec: Recording, options: BatchOptions) -> dict[str, Any]:
    # as read back from JSON (tuples become lists)
    return json.loads(json.dumps({"dataset": rec.spec, "config": options.config,
                                  "max_frames": options.max_frames, "report": options.report}))


def finished_here(folder: Path, rec: Recording, options: BatchOptions) -> bool:
    """``folder`` holds a finished run of ``rec`` with ``options`` (a re-run skips it)."""
    try:
        summary = json.loads((folder / "summary.json").read_text(encoding="utf-8"))
        mark = json.loads((folder / RUN_MARK).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return False
    return (isinstance(summary, dict) and summary.get("state") == "finished"
            and mark == _mark(rec, options))


def run_recording(rec: Recording, out_root: str, options: BatchOptions) -> Row:
    """Run one recording into ``out_root/<name>`` (unless it finished there before) and return
    its table row. Never raises for a bad recording: its row says ``failed`` and why, and
    ``error.txt`` in its folder holds the details. Runs in a worker process or a Ray task."""
    from amrvio.app.run import run
    from amrvio.config import config_from_dict
    from amrvio.pipeline.threads import run_settings

    folder = Path(out_root) / rec.name
    if finished_here(folder, rec, options):
        return table_row(rec, folder)
    run_settings()
    try:
        folder.mkdir(parents=True, exist_ok=True)
        for name in ("error.txt", RUN_MARK):
            (folder / name).unlink(missing_ok=True)
        res = run(rec.spec, config_from_dict(options.config), out=folder, force=True,
                  max_frames=options.max_frames, report=options.report)
        if not res.interrupted:
            (folder / RUN_MARK).write_text(json.dumps(_mark(rec, options), indent=1) + "\n",
                                           encoding="utf-8")
    except AmrvioError as err:
        return failed_row(rec, folder, " ".join(str(err).split()))
    except Exception as err:  # a bug must not stop the other recordings
        return failed_row(rec, folder, f"internal error: {type(err).__name__}: {err}",
                          traceback.format_exc())
    return table_row(rec, folder)


def failed_row(rec: Recording, folder: Path, message: str, details: str = "") -> Row:
    try:
        folder.mkdir(parents=True, exist_ok=True)
        (folder / "error.txt").write_text(message + "\n" + details, encoding="utf-8")
    except OSError:
        pass
    row = {c: "" for c in COLUMNS}
    row.update(recording=rec.name, dataset=rec.spec, status="failed",
               error=" ".join(message.split()))
    return row


def _f(v: Any, nd: int) -> str:
    return f"{v:.{nd}f}" if isinstance(v, int | float) and math.isfinite(v) else ""


def table_row(rec: Recording, folder: Path) -> Row:
    """The row of a recording from its summary.json and eval.json."""
    row = {c: "" for c in COLUMNS}
    row.update(recording=rec.name, dataset=rec.spec)
    try:
        s = json.loads((folder / "summary.json").read_text(encoding="utf-8"))
    except (OSError, ValueError) as err:
        row.update(status="failed", error=f"no readable summary.json ({err})")
        return row
    n = int(s.get("n_frames", 0))
    kinds = [e[1].partition(":")[0] for e in s.get("events", [])]
    ranges = s.get("flagged_ranges", {})
    lost = sum(b - a + 1 for a, b in ranges.get("lost", []))
    row.update(status=str(s.get("state", "")), frames=str(n),
               in_trajectory=str(s.get("n_in_trajectory", "")),
               with_pose_pct=_f(100.0 * s.get("n_in_trajectory", 0) / n, 1) if n else "",
               lost_frames=str(lost), keyframes=str(s.get("n_keyframes", "")),
               losses=str(kinds.count("lost")), relocalisations=str(kinds.count("relocalised")),
               reinits=str(max(0, kinds.count("init_ok") - 1)))
    for c in CAUSES:
        row[f"ranges_{c}"] = str(len(ranges.get(c, [])))
    ev_path = folder / "eval.json"
    if ev_path.is_file():
        try:
            ev = json.loads(ev_path.read_text(encoding="utf-8"))
        except ValueError:
            ev = {"error": "eval.json is not valid JSON"}
        if ev.get("error"):
            row["eval_note"] = " ".join(str(ev["error"]).split())
        row.update(ate_sim3_m=_f(ev.get("ate_sim3_m"), 4),
                   ate_sim3_pct=_f(ev.get("ate_sim3_pct_of_path"), 3),
                   ate_metric_m=_f(ev.get("ate_metric_m"), 4),
                   scale_error_pct=_f(ev.get("scale_error_pct"), 3))
    else:
        row["eval_note"] = "no ground truth"
    return row


# ------------------------------------------------------------------------------------ executors
Progress = Callable[[int, int, Row], None]
"""Told after each recording: (done, total, its row)."""


def run_local(recs: Sequence[Recording], out_root: Path, options: BatchOptions, jobs: int,
              progress: Progress | None = None) -> list[Row]:
    """The recordings on a pool of ``jobs`` worker processes (spawned: no state shared with
    this process), each recording in a fresh worker: a worker's memory layout then does not
    depend on which recordings it ran before, so a recording's outputs do not depend on the
    scheduling (amrvio.cli.reproducible); rows in the order of ``recs``."""
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor, as_completed

    rows: dict[int, Row] = {}
    ctx = multiprocessing.get_context("spawn")
    with ProcessPoolExecutor(max_workers=max(1, jobs), mp_context=ctx, max_tasks_per_child=1) as pool:
        futures = {pool.submit(run_recording, r, str(out_root), options): i
                   for i, r in enumerate(recs)}
        try:
            for fut in as_completed(futures):
                i = futures[fut]
                try:
                    rows[i] = fut.result()
                except Exception as err:  # the worker process died (killed, out of memory)
                    rows[i] = failed_row(recs[i], out_root / recs[i].name,
                                         f"worker process failed: {type(err).__name__}: {err}")
                if progress is not None:
                    progress(len(rows), len(recs), rows[i])
        except KeyboardInterrupt:
            pool.shutdown(wait=False, cancel_futures=True)
            raise
    return [rows[i] for i in range(len(recs))]


def run_ray(recs: Sequence[Recording], out_root: Path, options: BatchOptions,
            address: str | None, progress: Progress | None = None) -> list[Row]:
    """The recordings as Ray tasks (one CPU each) on the cluster at ``address`` ("auto": the
    running one; None: a local Ray instance started for this batch). ``out_root`` must be a
    folder every node can write (a shared file system)."""
    try:
        import ray
    except ImportError:
        raise ConfigError("--ray needs Ray: pip install 'amrvio[cluster]'") from None
    started = not ray.is_initialized()
    if started:
        try:
            ray.init(address=address, include_dashboard=False, log_to_driver=False,
                     configure_logging=False)
        except (ConnectionError, RuntimeError, ValueError) as err:
            raise ConfigError(f"--ray {address or ''}: cannot start or reach Ray: "
                              f"{' '.join(str(err).split())}") from None
    try:
        task = ray.remote(num_cpus=1, max_retries=0)(run_recording)
        refs = {task.remote(r, str(out_root), options): i for i, r in enumerate(recs)}
        rows: dict[int, Row] = {}
        pending = list(refs)
        while pending:
            done, pending = ray.wait(pending, num_returns=1)
            for ref in done:
                i = refs[ref]
                try:
                    rows[i] = ray.get(ref)
                except Exception as err:  # the task's worker died
                    rows[i] = failed_row(recs[i], out_root / recs[i].name,
                                         f"Ray task failed: {type(err).__name__}: "
                                         f"{str(err).splitlines()[0] if str(err) else ''}")
                if progress is not None:
                    progress(len(rows), len(recs), rows[i])
        return [rows[i] for i in range(len(recs))]
    finally:
        if started:
            ray.shutdown()


# ------------------------------------------------------------------------------------ the table
def write_table(rows: Iterable[Row], out_root: Path) -> tuple[Path, Path]:
    """batch.csv and batch.html in ``out_root``."""
    from amrvio.pipeline.run import replacing

    rows = list(rows)
    csv_path, html_path = out_root / "batch.csv", out_root / "batch.html"
    with replacing(csv_path) as tmp, tmp.open("w", newline="", encoding="utf-8") as fh:
        w = csv.DictWriter(fh, fieldnames=list(COLUMNS))
        w.writeheader()
        w.writerows(rows)
    with replacing(html_path) as tmp:
        tmp.write_text(table_html(rows), encoding="utf-8")
    return csv_path, html_path


def table_html(rows: Sequence[Row]) -> str:
    """The table as one self-contained page; each recording links to its report.html."""
    e = html.escape
    n_ok = sum(r["status"] == "finished" for r in rows)
    head = "".join(f"<th>{e(c.replace('_', ' '))}</th>" for c in COLUMNS)
    body = []
    for r in rows:
        cells = []
        for c in COLUMNS:
            v = r.get(c, "")
            if c == "recording" and r["status"] != "failed":
                cells.append(f"<td><a href='{e(r['recording'])}/report.html'>{e(v)}</a></td>")
            elif c == "status":
                cls = "ok" if v == "finished" else "bad"
                cells.append(f"<td class='{cls}'>{e(v)}</td>")
            else:
                cells.append(f"<td>{e(v)}</td>")
        body.append("<tr>" + "".join(cells) + "</tr>")
    return f"""<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8"><title>amrvio batch</title>
<style>body{{font-family:system-ui,sans-serif;margin:1.5em}}table{{border-collapse:collapse;font-size:.85em}}
td,th{{border:1px solid #ccc;padding:3px 6px}}th{{background:#f3f3f3}}.ok{{color:#070}}
.bad{{color:#b00;font-weight:bold}}</style>
</head><body><h1>amrvio batch: {len(rows)} recordings, {n_ok} finished</h1>
<p>ranges: flagged frame ranges by cause; ATE: Sim3-aligned against the camera ground truth
(metric ATE and scale error with a metric scale source).</p>
<table><tr>{head}</tr>
{chr(10).join(body)}
</table></body></html>
"""


__all__ = ["COLUMNS", "LIST_SUFFIXES", "RUN_MARK", "BatchOptions", "Recording", "expand_inputs", "failed_row",
           "finished_here", "recordings", "run_local", "run_ray", "run_recording", "table_html",
           "table_row", "write_table"]
