"""Text tables shared by the dataset readers: CSV or whitespace rows, typed columns, times.

Bad input is a ``DatasetFormatError(path, problem, line)`` naming the 1-based file line.
"""

from __future__ import annotations

import itertools
import re
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from amrvio.errors import DatasetFormatError

F64 = NDArray[np.float64]
I64 = NDArray[np.int64]


@dataclass(frozen=True, slots=True)
class TextTable:
    """Rows of a CSV or whitespace table. lines[i] is the 1-based file line of rows[i]."""

    path: Path
    header: tuple[str, ...] | None
    rows: tuple[tuple[str, ...], ...]
    lines: tuple[int, ...]

    def __len__(self) -> int:
        return len(self.rows)


def _looks_numeric(field: str) -> bool:
    try:
        float(field)
    except ValueError:
        return False
    return True


def _looks_like_names(fields: Sequence[str]) -> bool:
    first = fields[0].lstrip()
    return not any(map(_looks_numeric, fields)) and not first[:1].isdigit()


def read_table(
    path: Path, delimiter: str | None = ",", what: str = "file", allow_header: bool = True
) -> TextTable:
    """Read a text table: blank lines skipped, ``#`` lines are comments.

    With ``allow_header``, the first ``#`` line before any data, or a first line that looks like
    column names (no field is a number, the first does not start with a digit), is the header.
    ``delimiter=None`` splits on whitespace. Fields are stripped.
    """
    try:
        text = path.read_text(encoding="utf-8", errors="strict")
    except FileNotFoundError:
        raise DatasetFormatError(path, f"{what} is missing") from None
    except UnicodeDecodeError:
        raise DatasetFormatError(path, f"{what} is not a UTF-8 text file") from None
    except OSError as err:
        raise DatasetFormatError(path, f"cannot read {what}: {err.strerror}") from None
    header: tuple[str, ...] | None = None
    rows: list[tuple[str, ...]] = []
    lines: list[int] = []
    for number, raw in enumerate(text.splitlines(), start=1):
        line = raw.strip()
        if not line:
            continue
        if line.startswith("#") or line.startswith("%"):
            if allow_header and header is None and not rows and line.startswith("#"):
                header = _split(line.lstrip("#"), delimiter)
            continue
        fields = _split(line, delimiter)
        if allow_header and not rows and header is None and _looks_like_names(fields):
            header = fields
            continue
        rows.append(fields)
        lines.append(number)
    return TextTable(path, header, tuple(rows), tuple(lines))


def _split(line: str, delimiter: str | None) -> tuple[str, ...]:
    if delimiter is None:
        return tuple(line.split())
    parts = line.split(delimiter)
    if " " in line or "\t" in line:
        return tuple(f.strip() for f in parts)
    return tuple(parts)


def check_columns(table: TextTable, n_min: int, what: str, n_max: int | None = None) -> None:
    """Every row has between n_min and n_max fields (n_max None: no upper limit)."""
    lengths = set(map(len, table.rows))
    fits = all(n >= n_min and (n_max is None or n <= n_max) for n in lengths)
    if fits and not any("" in row[:n_min] for row in table.rows):
        return
    for row, line in zip(table.rows, table.lines, strict=True):
        if len(row) < n_min or (n_max is not None and len(row) > n_max):
            expect = f"{n_min}" if n_max == n_min else f"at least {n_min}"
            if n_max is not None and n_max != n_min:
                expect = f"{n_min} to {n_max}"
            raise DatasetFormatError(
                table.path, f"{what}: expected {expect} columns, found {len(row)}", line
            )
        if any(f == "" for f in row[:n_min]):
            raise DatasetFormatError(table.path, f"{what}: an empty column", line)


def _plain(text: str) -> str:
    """``text`` unless it has a ``_``: Python reads ``4_0.0`` as 40, a file means no such thing."""
    if "_" in text:
        raise ValueError(f"{text!r} has an underscore")
    return text


def _parsed_column(
    table: TextTable, col: int, what: str, parse: Callable[[str], int], expected: str
) -> I64:
    out = np.empty(len(table), dtype=np.int64)
    for i, (row, line) in enumerate(zip(table.rows, table.lines, strict=True)):
        try:
            out[i] = parse(_plain(row[col]))
        except (ValueError, OverflowError):
            raise DatasetFormatError(
                table.path, f"{what}: {row[col]!r} is not {expected}", line
            ) from None
    return out


def int_column(table: TextTable, col: int, what: str) -> I64:
    """Column ``col`` as int64 (for example nanosecond timestamps)."""
    return _parsed_column(table, col, what, int, "an integer")


def float_columns(table: TextTable, cols: Sequence[int], what: str) -> F64:
    """Columns ``cols`` as an (N, len(cols)) float64 array; non-numbers and NaN/inf are errors."""
    cols = list(cols)
    block = [[row[c] for c in cols] for row in table.rows]
    try:
        flat = map(float, map(_plain, itertools.chain.from_iterable(block)))
        out = np.fromiter(flat, dtype=np.float64, count=len(block) * len(cols))
        out = out.reshape(len(block), len(cols))
    except ValueError:
        for vals, line in zip(block, table.lines, strict=True):
            for v in vals:
                try:
                    float(_plain(v))
                except ValueError:
                    raise DatasetFormatError(
                        table.path, f"{what}: {v!r} is not a number", line
                    ) from None
        raise
    finite = np.isfinite(out)
    if not np.all(finite):
        bad = int(np.flatnonzero(~np.all(finite, axis=1))[0])
        raise DatasetFormatError(table.path, f"{what}: non-finite value (NaN or inf)", table.lines[bad])
    return out


def check_magnitude(table: TextTable, values: F64, limit: float, what: str) -> None:
    """Every |value| of the (N, k) ``values`` (rows of ``table``) is at most ``limit``; the error
    names the first line beyond it (an absurd finite number is a broken file, and it would
    overflow the computations downstream)."""
    over = np.abs(values) > limit
    if np.any(over):
        i = int(np.flatnonzero(np.any(over, axis=1))[0])
        v = float(values[i][over[i]][0])
        raise DatasetFormatError(table.path, f"{what}: {v:.6g} is beyond +-{limit:g}",
                                 table.lines[i])


MAX_ABS_TIME_S = 9e9
"""Largest |time| in seconds: int64 nanoseconds end at 9.2e9 s (the year 2262)."""

_DECIMAL = re.compile(r"^([+-]?)(\d*)(?:\.(\d*))?$")


def seconds_to_ns(text: str) -> int:
    """A decimal seconds string to integer nanoseconds, exact for plain decimals (no float rounding)."""
    m = _DECIMAL.match(text)
    if m is not None and (m.group(2) or m.group(3)):
        sign = -1 if m.group(1) == "-" else 1
        whole = int(m.group(2) or "0")
        if whole > MAX_ABS_TIME_S:
            raise ValueError(f"time {text[:40]!r} is beyond +-{MAX_ABS_TIME_S:g} s")
        frac = (m.group(3) or "")[:9].ljust(9, "0")
        # Round half up on the tenth fractional digit.
        extra = (m.group(3) or "")[9:10]
        ns = whole * 1_000_000_000 + int(frac) + (1 if extra and int(extra) >= 5 else 0)
        return sign * ns
    value = float(_plain(text))  # exponent notation, e.g. KITTI's "1.037359e-01"
    if not np.isfinite(value) or abs(value) > MAX_ABS_TIME_S:
        raise ValueError(f"time {text!r} is not finite or beyond +-{MAX_ABS_TIME_S:g} s")
    return int(round(value * 1e9))


def seconds_column_ns(table: TextTable, col: int, what: str) -> I64:
    """Column ``col`` of decimal seconds as int64 nanoseconds."""
    return _parsed_column(table, col, what, seconds_to_ns, "a finite time in seconds")


def check_increasing(table: TextTable, stamps_ns: I64, what: str) -> None:
    """Timestamps strictly increase; the error names the first line that goes backwards."""
    if stamps_ns.shape[0] < 2:
        return
    bad = np.flatnonzero(np.diff(stamps_ns) <= 0)
    if bad.size:
        i = int(bad[0]) + 1
        kind = "repeats" if stamps_ns[i] == stamps_ns[i - 1] else "goes backwards"
        raise DatasetFormatError(
            table.path, f"{what}: timestamp {int(stamps_ns[i])} {kind}", table.lines[i]
        )
