"""``make demo``: the main job on an embedded default.

Evaluates the built-in example trajectory pair (``amrvio/data/example_{est,gt}.tum``) with
``amrvio eval`` and writes the metrics and plot under ``--out``.
"""

from __future__ import annotations

import argparse
import sys
from importlib import resources
from pathlib import Path

from amrvio.cli.main import main as amrvio_main


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description="Run amrvio on its embedded example.")
    ap.add_argument("--out", type=Path, default=Path("demo_out"))
    args = ap.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    data = resources.files("amrvio") / "data"
    with resources.as_file(data / "example_est.tum") as est, resources.as_file(data / "example_gt.tum") as gt:
        print(f"amrvio demo: evaluating {est.name} against {gt.name}", file=sys.stderr)
        rc = amrvio_main(["eval", str(est), str(gt), "--align", "sim3",
                          "--json", str(args.out / "eval.json"), "--plot", str(args.out / "eval.png")])
    if rc == 0:
        print(f"amrvio demo: wrote {args.out / 'eval.json'} and {args.out / 'eval.png'}", file=sys.stderr)
    return rc


if __name__ == "__main__":
    sys.exit(main())
