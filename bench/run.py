"""Benchmark runner: ``make bench`` -> bench/results/results.{json,md}.

Each ``bench/bench_<topic>.py`` defines ``run(quick: bool) -> list[dict]`` whose rows are
``{"name", "value", "unit", "note"}``. Figures are medians over repeats (machines are shared and
noisy), and accuracy figures come from ground truth; none of them is asserted by the test suite.
"""

from __future__ import annotations

import argparse
import importlib
import json
import pkgutil
import platform
import sys
import time
from pathlib import Path
from typing import Any

import bench


def _modules(only: list[str] | None) -> list[str]:
    names = sorted(m.name for m in pkgutil.iter_modules(bench.__path__) if m.name.startswith("bench_"))
    if only:
        names = [n for n in names if any(o in n for o in only)]
    return names


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description="Run amrvio benchmarks and write a results table.")
    ap.add_argument("--out", type=Path, default=Path("bench/results"))
    ap.add_argument("--quick", action="store_true", help="fewer repeats and shorter sequences")
    ap.add_argument("--only", nargs="*", help="run only modules whose name contains one of these")
    args = ap.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    results: dict[str, Any] = {
        "machine": {"python": sys.version.split()[0], "platform": platform.platform(),
                    "processor": platform.processor()},
        "quick": args.quick,
        "sections": {},
    }
    for name in _modules(args.only):
        mod = importlib.import_module(f"bench.{name}")
        t0 = time.perf_counter()
        try:
            rows = mod.run(args.quick)
            error = None
        except Exception as exc:  # a failing benchmark is reported, not hidden
            rows, error = [], f"{type(exc).__name__}: {exc}"
        results["sections"][name] = {"rows": rows, "error": error, "seconds": time.perf_counter() - t0}
        print(f"{name}: {len(rows)} figures in {time.perf_counter() - t0:.1f} s" + (f" ERROR {error}" if error else ""),
              file=sys.stderr)
    (args.out / "results.json").write_text(json.dumps(results, indent=2, default=float) + "\n")
    lines = ["# amrvio benchmark results", "", f"Python {results['machine']['python']} on "
             f"{results['machine']['platform']}; quick={args.quick}.", ""]
    for name, sec in results["sections"].items():
        lines += [f"## {name}", ""]
        if sec["error"]:
            lines += [f"**failed:** {sec['error']}", ""]
        lines += ["| figure | value | unit | note |", "|---|---:|---|---|"]
        for r in sec["rows"]:
            v = r["value"]
            vs = f"{v:.4g}" if isinstance(v, float) else str(v)
            lines.append(f"| {r['name']} | {vs} | {r.get('unit', '')} | {r.get('note', '')} |")
        lines.append("")
    (args.out / "results.md").write_text("\n".join(lines))
    print(f"wrote {args.out / 'results.json'} and {args.out / 'results.md'}", file=sys.stderr)
    return 1 if any(s["error"] for s in results["sections"].values()) else 0


if __name__ == "__main__":
    sys.exit(main())
