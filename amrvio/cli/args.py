"""Small pieces the ``cmd_*`` modules share: argument types and the ``--json OUT`` writer."""

from __future__ import annotations

import argparse
import json
import math
from collections.abc import Callable
from pathlib import Path
from typing import Any


def _number(text: str, kind: type[float] | type[int], rng: str = "") -> float:
    try:
        return kind(text.strip())
    except ValueError:
        what = "an integer" if kind is int else "a number"
        where = f" in {rng}" if rng else ""
        raise argparse.ArgumentTypeError(f"expected {what}{where}, got {text[:40]!r}") from None


def _fmt_bound(v: float) -> str:
    text = f"{v:g}" if isinstance(v, float) else str(v)
    return text.replace("e+0", "e").replace("e+", "e")


def interval(lo: float, hi: float, lo_open: bool = False) -> str:
    """``[lo, hi]`` or ``(lo, hi]``: the range as --help and the errors state it."""
    return f"{'(' if lo_open else '['}{_fmt_bound(lo)}, {_fmt_bound(hi)}]"


def bounded(lo: float, hi: float, *, integer: bool = False,
            lo_open: bool = False) -> Callable[[str], Any]:
    """argparse type: a finite number (an integer with ``integer``) in [lo, hi] (or (lo, hi]
    with ``lo_open``); the error states the range. ``NaN``, ``inf`` and values whose size no
    computation needs are refused here rather than deep inside a run."""
    rng = interval(lo, hi, lo_open)

    def parse(text: str) -> float:
        v = _number(text, int if integer else float, rng)
        if not math.isfinite(v):
            raise argparse.ArgumentTypeError(f"must be a finite number in {rng}, got {text}")
        if v < lo or v > hi or (lo_open and v == lo):
            raise argparse.ArgumentTypeError(f"must be in {rng}, got {text}")
        return v

    parse.__name__ = "integer" if integer else "number"
    return parse


MAX_FRAMES = 10_000_000
"""Largest --max-frames."""
SEED_RANGE = (0, 2**32 - 1)
"""--seed: what numpy's generators and OpenCV's RNG take."""

positive_float = bounded(0.0, 1e9, lo_open=True)
"""argparse type: a finite number in (0, 1e9]."""
non_negative_float = bounded(0.0, 1e9)
"""argparse type: a finite number in [0, 1e9]."""
positive_int = bounded(1, MAX_FRAMES, integer=True)
"""argparse type: an integer in [1, 1e7]."""
seed_int = bounded(*SEED_RANGE, integer=True)
"""argparse type: a seed in [0, 2^32 - 1]."""
max_frames_int = bounded(1, MAX_FRAMES, integer=True)
"""argparse type: --max-frames in [1, 1e7]."""


def write_json(path: Path, data: dict[str, Any], option: str = "--json") -> None:
    """Write ``data`` as indented strict JSON (non-finite floats become null); a ConfigError
    naming ``option`` when it cannot be written."""
    from amrvio.errors import ConfigError
    from amrvio.pipeline.run import finite_json

    try:
        path.write_text(json.dumps(finite_json(data), indent=2, allow_nan=False) + "\n",
                        encoding="utf-8")
    except OSError as err:
        raise ConfigError(f"{option} {path}: cannot write: {err.strerror}") from None


def check_output_file(path: Path | None, option: str) -> None:
    """Refuse an output file that cannot be written (before any work); None: not asked for."""
    if path is not None:
        from amrvio.io.outdir import check_output_file as check

        check(path, option)
