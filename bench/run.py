"""Benchmark runner: ``make bench`` -> bench/results/results.{json,md}; ``make bench-quick`` runs
the modules behind the headline figures only, with fewer repeats.

Each ``bench/bench_<topic>.py`` defines ``run(quick: bool) -> list[dict]`` whose rows are
``{"name", "value", "unit", "note"}``, and, for a figure with a goal, ``"target"`` (text) and
``"pass"`` (bool). Figures are medians over repeats (machines are shared and noisy), and accuracy
figures come from ground truth; none of them is asserted by the test suite.

The results accumulate: a run replaces the sections it ran and keeps the others, each section
with the machine, date and mode (quick or full) it was measured with. results.md opens with the
headline table (one line per figure with a goal: value, target, pass or fail, machine, date;
see bench/headlines.py), then the details of every section.
"""

from __future__ import annotations

import argparse
import datetime
import importlib
import json
import math
import os
import pkgutil
import platform
import sys
import time
from pathlib import Path
from typing import Any

import bench
from bench.headlines import HEADLINES

QUICK_MODULES = ("bench_diagnostics", "bench_diag_truth")  # under 5 minutes; bench_speed alone takes 6


def _modules(only: list[str] | None) -> list[str]:
    names = sorted(m.name for m in pkgutil.iter_modules(bench.__path__) if m.name.startswith("bench_"))
    if only:
        names = [n for n in names if any(o in n for o in only)]
    return names


def machine() -> str:
    """One line: CPU, cores, OS, Python (and the OpenBLAS kernels when they are pinned)."""
    cpu = platform.processor() or platform.machine()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    blas = os.environ.get("OPENBLAS_CORETYPE")
    return (f"{cpu}, {os.cpu_count()} cores, {platform.system()} {platform.release()}, "
            f"Python {sys.version.split()[0]}" + (f", OpenBLAS {blas} kernels" if blas else ""))


def _load(path: Path) -> dict[str, Any]:
    """Sections of an earlier results.json (sections of the old layout get its machine line)."""
    try:
        old = json.loads(path.read_text())
    except (OSError, ValueError):
        return {}
    sections = old.get("sections", {}) if isinstance(old, dict) else {}
    m = old.get("machine", {}) if isinstance(old, dict) else {}
    fallback = (f"{m.get('platform', '?')}, Python {m.get('python', '?')}" if isinstance(m, dict)
                else str(m))
    for sec in sections.values():
        sec.setdefault("machine", fallback)
        sec.setdefault("date", "before 2026-12 (date not recorded)")
        sec.setdefault("quick", bool(old.get("quick", False)))
    return dict(sections)


def _fmt(v: object) -> str:
    if isinstance(v, float):
        return "n/a" if math.isnan(v) else f"{v:.4g}"
    return str(v)


def _cell(text: object) -> str:
    return str(text).replace("|", "\\|").replace("\n", " ")


def headline_rows(sections: dict[str, Any]) -> list[list[str]]:
    """[figure, value, target, result, machine, date] for every figure with a goal."""
    out: list[list[str]] = []

    def add(sec: dict[str, Any], row: dict[str, Any], target: str, ok: bool | None) -> None:
        mode = " (quick)" if sec.get("quick") else ""
        out.append([_cell(row["name"]), f"{_fmt(row['value'])} {row.get('unit', '')}".strip(),
                    _cell(target), "n/a" if ok is None else ("pass" if ok else "**FAIL**"),
                    _cell(sec.get("machine", "")), f"{sec.get('date', '')}{mode}"])

    for name, sec in sections.items():
        for row in sec.get("rows", []):
            if "target" in row:
                add(sec, row, str(row["target"]), row.get("pass"))
        if sec.get("error"):
            out.append([f"{name} (section failed)", "", "", "**FAIL**", _cell(sec["error"]), ""])
    for h in HEADLINES:
        sec = sections.get(h.section)
        row = next((r for r in (sec or {}).get("rows", []) if r.get("name") == h.name), None)
        if sec is None or row is None:
            out.append([_cell(h.name), "missing", _cell(h.target), "n/a", "", ""])
            continue
        v = row.get("value")
        ok = h.passes(float(v)) if isinstance(v, (int, float)) and not math.isnan(float(v)) else None
        add(sec, row, h.target, ok)
    return out


def write_markdown(sections: dict[str, Any], path: Path) -> None:
    lines = ["# amrvio benchmark results", "",
             "Regenerate with `make bench` (everything) or `make bench-quick` (the modules behind "
             "the headline figures, fewer repeats; the other sections are kept from their last "
             "run). Each line says the machine and date it was measured on.", "",
             "## Headline", "",
             "| figure | value | target | result | machine | date |", "|---|---:|---|---|---|---|"]
    lines += ["| " + " | ".join(r) + " |" for r in headline_rows(sections)]
    lines += ["", "## Details", ""]
    for name, sec in sorted(sections.items()):
        mode = "quick" if sec.get("quick") else "full"
        lines += [f"### {name}", "",
                  f"{mode} run on {sec.get('date', '?')}, {sec.get('machine', '?')}; "
                  f"{sec.get('seconds', float('nan')):.0f} s.", ""]
        if sec.get("error"):
            lines += [f"**failed:** {sec['error']}", ""]
        lines += ["| figure | value | unit | note |", "|---|---:|---|---|"]
        for r in sec.get("rows", []):
            lines.append(f"| {_cell(r['name'])} | {_fmt(r['value'])} | {_cell(r.get('unit', ''))} "
                         f"| {_cell(r.get('note', ''))} |")
        lines.append("")
    path.write_text("\n".join(lines))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description="Run amrvio benchmarks and write a results table.")
    ap.add_argument("--out", type=Path, default=Path("bench/results"))
    ap.add_argument("--quick", action="store_true", help="fewer repeats and shorter sequences")
    ap.add_argument("--only", nargs="*", help="run only modules whose name contains one of these")
    ap.add_argument("--headline", action="store_true",
                    help=f"run only the modules behind the headline figures: {', '.join(QUICK_MODULES)}")
    args = ap.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    sections = _load(args.out / "results.json")
    where = machine()
    only = list(QUICK_MODULES) if args.headline else args.only
    failed = False
    for name in _modules(only):
        mod = importlib.import_module(f"bench.{name}")
        t0 = time.perf_counter()
        try:
            rows = mod.run(args.quick)
            error = None
        except Exception as exc:  # a failing benchmark is reported, not hidden
            rows, error = [], f"{type(exc).__name__}: {exc}"
            failed = True
        seconds = time.perf_counter() - t0
        sections[name] = {"rows": rows, "error": error, "seconds": seconds, "quick": args.quick,
                          "machine": where,
                          "date": datetime.datetime.now(datetime.UTC).strftime("%Y-%m-%d %H:%M UTC")}
        print(f"{name}: {len(rows)} figures in {seconds:.1f} s" + (f" ERROR {error}" if error else ""),
              file=sys.stderr)
    results = {"layout": 2, "sections": sections}
    (args.out / "results.json").write_text(json.dumps(results, indent=2, default=float) + "\n")
    write_markdown(sections, args.out / "results.md")
    print(f"wrote {args.out / 'results.json'} and {args.out / 'results.md'}", file=sys.stderr)
    return 1 if failed else 0


if __name__ == "__main__":
    from amrvio.cli.reproducible import make_reproducible

    make_reproducible("run")  # the figures `amrvio run` gives, whatever the x86-64 processor
    sys.exit(main())
