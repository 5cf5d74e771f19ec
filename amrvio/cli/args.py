"""Small pieces the ``cmd_*`` modules share: argument types and the ``--json OUT`` writer."""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any


def _number(text: str, kind: type[float] | type[int]) -> float:
    try:
        return kind(text)
    except ValueError:
        what = "an integer" if kind is int else "a number"
        raise argparse.ArgumentTypeError(f"expected {what}, got {text!r}") from None


def positive_float(text: str) -> float:
    """argparse type: a number > 0."""
    v = _number(text, float)
    if not v > 0:
        raise argparse.ArgumentTypeError(f"must be > 0, got {text}")
    return v


def non_negative_float(text: str) -> float:
    """argparse type: a number >= 0."""
    v = _number(text, float)
    if not v >= 0:
        raise argparse.ArgumentTypeError(f"must be >= 0, got {text}")
    return v


def positive_int(text: str) -> int:
    """argparse type: an integer >= 1."""
    v = int(_number(text, int))
    if v < 1:
        raise argparse.ArgumentTypeError(f"must be >= 1, got {text}")
    return v


def write_json(path: Path, data: dict[str, Any], option: str = "--json") -> None:
    """Write ``data`` as indented JSON; a ConfigError naming ``option`` when it cannot be written."""
    from amrvio.errors import ConfigError

    try:
        path.write_text(json.dumps(data, indent=2) + "\n", encoding="utf-8")
    except OSError as err:
        raise ConfigError(f"{option} {path}: cannot write: {err.strerror}") from None
