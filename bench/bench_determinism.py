"""Same command, same output: `amrvio run` repeated on one recording, each run its own process.

A simulated 320x240 corridor at 5 frames/s (140 s, 700 frames, with its IMU: the VIO runs) is run
``REPEATS`` times as `amrvio run` does it by default, which restarts itself with a fixed memory
layout (``amrvio.cli.reproducible``: Python's hash seed 0 and address-space randomisation off),
and as many times with ``AMRVIO_REPRODUCIBLE=0`` (the layout the kernel and Python choose). The
figure is the number of distinct ``trajectory.tum`` files (by content): 1 means every run wrote the
same trajectory. Before the restart was added, the 20 min drive of bench_speed's memory rows made
1657, 1639 and 1654 keyframes in three runs of the same input.

Run alone: ``.venv/bin/python -m bench.bench_determinism [--quick]``.
"""

from __future__ import annotations

import hashlib
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

from bench.bench_speed import sim_corridor

ROOT = Path(__file__).resolve().parents[1]
AMRVIO = Path(sys.executable).with_name("amrvio")
REPEATS = 4
Row = dict[str, object]


def _distinct(seq: Path, work: Path, tag: str, repeats: int, env: dict[str, str]) -> tuple[int, list[str]]:
    """(distinct trajectory.tum contents, each run's keyframes and digest) over ``repeats`` runs."""
    digests: list[str] = []
    keyframes: list[str] = []
    for k in range(repeats):
        out = work / f"{tag}{k}"
        subprocess.run([str(AMRVIO), "run", str(seq), "--out", str(out), "--no-report"], env=env, check=True,
                       capture_output=True, text=True, cwd=ROOT)
        digests.append(hashlib.sha256((out / "trajectory.tum").read_bytes()).hexdigest())
        summary = json.loads((out / "summary.json").read_text(encoding="utf-8"))
        keyframes.append(f"{summary['n_keyframes']} ({digests[-1][:8]})")
    return len(set(digests)), keyframes


def run(quick: bool) -> list[Row]:
    repeats = 2 if quick else REPEATS
    seconds = 60.0 if quick else 140.0
    base = {k: v for k, v in os.environ.items() if k not in ("PYTHONHASHSEED", "AMRVIO_REPRODUCIBLE")}
    rows: list[Row] = []
    with tempfile.TemporaryDirectory() as td:
        work = Path(td)
        seq = sim_corridor(work / "seq", seconds, 320, 240, 5.0, bursts=False)
        n_on, kf_on = _distinct(seq, work, "on", repeats, base)
        n_off, kf_off = _distinct(seq, work, "off", repeats, {**base, "AMRVIO_REPRODUCIBLE": "0"})
    what = f"corridor 320x240, 5 frames/s, {seconds:g} s ({int(seconds * 5)} frames), VIO"
    rows.append({"name": "same command, same output: distinct trajectories over repeated runs",
                 "value": n_on, "unit": "trajectories", "target": "1", "pass": n_on == 1,
                 "note": f"{repeats} runs of `amrvio run` (default: fixed memory layout); {what}; "
                         f"keyframes (trajectory digest) {kf_on}"})
    rows.append({"name": "same, with AMRVIO_REPRODUCIBLE=0 (layout chosen by the kernel and Python)",
                 "value": n_off, "unit": "trajectories",
                 "note": f"{repeats} runs; {what}; keyframes (trajectory digest) {kf_off}"})
    return rows


if __name__ == "__main__":
    for r in run("--quick" in sys.argv):
        print(r)
