"""``amrvio batch INPUTS... --out DIR``: many recordings, one ``amrvio run`` each, one table."""

from __future__ import annotations

import argparse
from pathlib import Path

from amrvio.cli.args import bounded, interval
from amrvio.cli.cmd_run import add_config_arguments

NAME = "batch"
HELP = ("run many recordings (folders, globs or a text list) on a local process pool or Ray; "
        "one output folder each and a table (batch.csv, batch.html); exit status 2 when some "
        "recordings failed")

MAX_JOBS = 1024
"""Largest --jobs."""
EXIT_SOME_FAILED = 2
"""Exit status when the batch ran to its end but some recordings failed (their rows say why)."""


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("inputs", nargs="+", metavar="INPUT",
                        help="a dataset folder or KIND:PATH, a glob pattern (quoted), or a text "
                             "file (.txt/.list) listing such inputs one a line")
    parser.add_argument("--out", type=Path, required=True,
                        help="output folder: one sub-folder per recording plus batch.csv and "
                             "batch.html; a re-run into it skips the recordings that finished "
                             "with the same configuration and options")
    add_config_arguments(parser)
    parser.add_argument("--jobs", type=bounded(1, MAX_JOBS, integer=True), default=None,
                        metavar="N",
                        help=f"worker processes of the local pool, in {interval(1, MAX_JOBS)} "
                             "(default: the CPU count, at most the number of recordings)")
    parser.add_argument("--ray", nargs="?", const="local", default=None, metavar="ADDRESS",
                        help="run the recordings as Ray tasks: on a new local Ray instance, or "
                             "on the cluster at ADDRESS ('auto', 'ray://HOST:10001'); --out "
                             "must then be on a file system every node shares. Needs "
                             "pip install 'amrvio[cluster]'")
    parser.add_argument("--no-report", action="store_true",
                        help="do not write each recording's report.html")


def run(args: argparse.Namespace) -> int:
    import os
    import sys

    from amrvio.app.batch import (
        BatchOptions,
        Row,
        expand_inputs,
        finished_here,
        recordings,
        run_local,
        run_ray,
        table_row,
        write_table,
    )
    from amrvio.cli.cmd_run import build_config
    from amrvio.config import PipelineConfig, config_to_dict
    from amrvio.io.outdir import prepare_output_dir

    cfg = build_config(args)
    if not isinstance(cfg, PipelineConfig):
        raise TypeError("build_config returned no PipelineConfig")
    specs = expand_inputs(args.inputs)
    recs = recordings(specs)
    out: Path = args.out
    prepare_output_dir(out, force=True)  # a batch folder is re-used on purpose: nothing removed
    options = BatchOptions(config_to_dict(cfg), args.max_frames, not args.no_report)

    def told(done: int, total: int, row: Row) -> None:
        what = row["status"]
        if row["status"] == "failed":
            what += f": {row['error']}"
        elif row["with_pose_pct"]:
            what += f", {row['with_pose_pct']} % of {row['frames']} frames with a pose"
            if row["ate_sim3_pct"]:
                what += f", ATE {row['ate_sim3_pct']} % of the path (Sim3)"
        print(f"[{done}/{total}] {row['recording']}: {what}", flush=True)

    done = {r.name: table_row(r, out / r.name) for r in recs
            if finished_here(out / r.name, r, options)}
    todo = [r for r in recs if r.name not in done]
    print(f"amrvio batch: {len(recs)} recordings -> {out}"
          + (f" ({len(done)} finished earlier with the same configuration: skipped)"
             if done else ""), flush=True)
    try:
        if not todo:
            ran: list[Row] = []
        elif args.ray is not None:
            ran = run_ray(todo, out, options, None if args.ray == "local" else args.ray, told)
        else:
            jobs = args.jobs or min(len(todo), os.cpu_count() or 1)
            ran = run_local(todo, out, options, jobs, told)
    except KeyboardInterrupt:
        print("amrvio batch: interrupted; the recordings that finished keep their folders, a "
              "re-run skips them", file=sys.stderr)
        return 130
    by_name = {**done, **{r["recording"]: r for r in ran}}
    rows = [by_name[r.name] for r in recs]
    csv_path, html_path = write_table(rows, out)
    n_failed = sum(r["status"] == "failed" for r in rows)
    print(f"{len(rows) - n_failed} of {len(rows)} recordings finished, {n_failed} failed; table: "
          f"{csv_path}, {html_path}")
    return EXIT_SOME_FAILED if n_failed else 0
