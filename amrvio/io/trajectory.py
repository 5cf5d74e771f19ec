"""Trajectory files: TUM, KITTI (with an optional times file) and EuRoC CSV.

Formats (poses are ``T_world_x``):

- TUM: ``t x y z qx qy qz qw`` per line, seconds and metres, ``#`` starts a comment.
- KITTI: 12 numbers per line, the row-major 3x4 matrix ``[R | t]``; stamps come from a separate
  times file (one number of seconds per line) or, without one, are the pose index 0, 1, 2, ...
  Rotation blocks are stored rounded, so they are projected to the nearest rotation on reading.
- EuRoC CSV (``state_groundtruth_estimate0/data.csv``): ``t_ns, p xyz, q wxyz`` optionally followed
  by ``v xyz``, ``b_w xyz``, ``b_a xyz``; integer nanoseconds, ``#`` header line.

Writers use the shortest representation that reads back to the same float (``repr``), so a
written file reads back to the same numbers. Every problem in a file raises
``TrajectoryFormatError`` naming the file and the line.
"""

from __future__ import annotations

import re
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from amrvio.errors import ShapeError, TrajectoryFormatError
from amrvio.types.trajectory import Trajectory

F64 = NDArray[np.float64]
I64 = NDArray[np.int64]

TrajectoryFormat = Literal["tum", "kitti", "euroc"]
FORMATS: tuple[str, ...] = ("tum", "kitti", "euroc")

# A quaternion whose norm is off by more than this is an error; closer ones are normalised.
QUAT_NORM_TOL = 1e-3
# A KITTI rotation block further than this from orthonormal (max |R R^T - I|) is an error.
ROT_ORTHO_TOL = 1e-3

_TUM_HEADER = "# timestamp_s tx ty tz qx qy qz qw"
_EUROC_HEADER_8 = "#timestamp [ns],p_x [m],p_y [m],p_z [m],q_w [],q_x [],q_y [],q_z []"
_EUROC_HEADER_EXTRA = (
    ",v_x [m s^-1],v_y [m s^-1],v_z [m s^-1],b_w_x [rad s^-1],b_w_y [rad s^-1],"
    "b_w_z [rad s^-1],b_a_x [m s^-2],b_a_y [m s^-2],b_a_z [m s^-2]"
)
_SPLIT_WS = re.compile(r"\s+")


@dataclass(frozen=True, slots=True)
class EurocGroundTruth:
    """Contents of an EuRoC ground-truth CSV (world = Vicon frame, body = IMU frame).

    trajectory: poses T_world_body at stamps_ns / 1e9 seconds.
    stamps_ns: (N,) int64, the exact file stamps.
    velocities_m_s, gyro_bias, accel_bias: (N, 3) arrays, or None when the file lacks them
    (gyro_bias in rad/s, accel_bias in m/s^2).
    """

    trajectory: Trajectory
    stamps_ns: I64
    velocities_m_s: F64 | None = None
    gyro_bias: F64 | None = None
    accel_bias: F64 | None = None


@dataclass(frozen=True, slots=True)
class _Rows:
    """Numeric rows of a text file and the 1-based line number of each row."""

    values: F64
    lines: I64
    tokens: list[list[str]]


def _read_text(path: Path) -> str:
    try:
        return path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise TrajectoryFormatError(path, "file not found") from None
    except IsADirectoryError:
        raise TrajectoryFormatError(path, "is a directory, expected a trajectory file") from None
    except UnicodeDecodeError:
        raise TrajectoryFormatError(path, "is not a text file (cannot decode as UTF-8)") from None
    except OSError as err:
        raise TrajectoryFormatError(path, f"cannot read: {err.strerror}") from None


def _parse_rows(
    path: Path,
    sep: Literal["ws", "comma"],
    allowed_cols: Sequence[int],
    what: str,
) -> _Rows:
    """Split non-comment lines into floats; every row must have one of ``allowed_cols`` columns,
    and all rows the same number."""
    rows: list[list[float]] = []
    toks_all: list[list[str]] = []
    lines: list[int] = []
    ncols: int | None = None
    for lineno, raw in enumerate(_read_text(path).splitlines(), start=1):
        text = raw.strip()
        if not text or text.startswith("#"):
            continue
        if sep == "ws":
            toks = _SPLIT_WS.split(text)
        else:
            toks = [t.strip() for t in text.split(",")]
            if toks and toks[-1] == "":
                toks = toks[:-1]  # tolerate one trailing comma
        if len(toks) not in allowed_cols:
            expected = " or ".join(str(c) for c in allowed_cols)
            raise TrajectoryFormatError(
                path, f"expected {expected} columns ({what}), found {len(toks)}", lineno
            )
        if ncols is not None and len(toks) != ncols:
            raise TrajectoryFormatError(
                path, f"found {len(toks)} columns where earlier lines have {ncols}", lineno
            )
        ncols = len(toks)
        vals: list[float] = []
        for col, tok in enumerate(toks, start=1):
            try:
                if "_" in tok:  # Python reads 4_0 as 40; a file means no such number
                    raise ValueError(tok)
                vals.append(float(tok))
            except ValueError:
                raise TrajectoryFormatError(
                    path, f"column {col}: cannot read {tok[:40]!r} as a number", lineno
                ) from None
        rows.append(vals)
        toks_all.append(toks)
        lines.append(lineno)
    if not rows:
        raise TrajectoryFormatError(path, f"contains no poses (expected lines of {what})")
    values = np.asarray(rows, dtype=np.float64)
    line_arr = np.asarray(lines, dtype=np.int64)
    bad = ~np.all(np.isfinite(values), axis=1)
    if np.any(bad):
        i = int(np.flatnonzero(bad)[0])
        col = int(np.flatnonzero(~np.isfinite(values[i]))[0]) + 1
        raise TrajectoryFormatError(
            path, f"column {col}: value {toks_all[i][col - 1]!r} is not finite", int(line_arr[i])
        )
    return _Rows(values, line_arr, toks_all)


MAX_ABS_POSITION_M = 1e9
"""Largest |coordinate| of a position (m): beyond any Earth-fixed frame; a larger value is a
broken file (and its squares would overflow the alignment)."""
MAX_ABS_STAMP_S = 9e9
"""Largest |stamp| (s): int64 nanoseconds end at 9.2e9 s."""


def _check_range(path: Path, values: F64, lines: I64, first_col: int, limit: float,
                 what: str) -> None:
    """|values| <= limit; the error names the line and the 1-based column
    (``first_col`` + offset)."""
    over = np.abs(values) > limit
    if np.any(over):
        i = int(np.flatnonzero(np.any(over, axis=1))[0])
        j = int(np.flatnonzero(over[i])[0])
        raise TrajectoryFormatError(
            path, f"column {first_col + j}: {what} {values[i, j]:.6g} is beyond +-{limit:g}",
            int(lines[i]))


def _check_stamps(path: Path, stamps: ArrayLike, lines: I64) -> None:
    t = np.asarray(stamps)
    back = np.flatnonzero(np.diff(t) <= 0)
    if back.size:
        i = int(back[0]) + 1
        kind = "repeats" if t[i] == t[i - 1] else "goes backwards from"
        now, before = t[i].item(), t[i - 1].item()
        raise TrajectoryFormatError(
            path,
            f"timestamp {now!r} {kind} the previous one {before!r} (line {int(lines[i - 1])}); "
            "stamps must be strictly increasing",
            int(lines[i]),
        )


def _checked_quats(path: Path, quats_wxyz: F64, lines: I64) -> F64:
    norms = np.linalg.norm(quats_wxyz, axis=1)
    bad = np.flatnonzero(np.abs(norms - 1.0) > QUAT_NORM_TOL)
    if bad.size:
        i = int(bad[0])
        raise TrajectoryFormatError(
            path,
            f"quaternion norm {norms[i]:.6g} is not 1 (tolerance {QUAT_NORM_TOL:g})",
            int(lines[i]),
        )
    return np.asarray(quats_wxyz / norms[:, None], dtype=np.float64)


def _make(path: Path, stamps_s: F64, positions: F64, quats_wxyz: F64) -> Trajectory:
    try:
        return Trajectory(stamps_s, positions, quats_wxyz)
    except ShapeError as err:
        raise TrajectoryFormatError(path, str(err)) from None


# ----------------------------------------------------------------------------------------- TUM


def read_tum(path: str | Path) -> Trajectory:
    """Read a TUM trajectory file (``t x y z qx qy qz qw``)."""
    p = Path(path)
    rows = _parse_rows(p, "ws", (8,), "t x y z qx qy qz qw")
    v = rows.values
    _check_range(p, v[:, :1], rows.lines, 1, MAX_ABS_STAMP_S, "timestamp [s]")
    _check_range(p, v[:, 1:4], rows.lines, 2, MAX_ABS_POSITION_M, "position [m]")
    _check_stamps(p, v[:, 0], rows.lines)
    quats = _checked_quats(p, v[:, [7, 4, 5, 6]], rows.lines)
    return _make(p, v[:, 0], v[:, 1:4], quats)


def _fmt(x: float) -> str:
    return repr(float(x))


def _fmt_stamp_s(t: float) -> str:
    # At least nanosecond decimals, and never fewer digits than the float holds.
    fixed = f"{t:.9f}"
    return fixed if float(fixed) == t else repr(float(t))


def write_tum(path: str | Path, traj: Trajectory, comment: str | None = None) -> None:
    """Write ``traj`` as a TUM file (stamps with at least 9 decimals, values repr-precise);
    ``comment`` (one line, ``#`` added when missing) goes before the column header."""
    out = [_TUM_HEADER]
    if comment is not None:
        text = " ".join(comment.split())
        out.insert(0, text if text.startswith("#") else f"# {text}")
    q = traj.quats_wxyz
    for t, pos, qq in zip(traj.stamps_s, traj.positions_m, q, strict=True):
        line = tum_line(float(t), pos, qq)
        if line is None:
            raise ShapeError(f"{path}: a pose at t={float(t)!r} s is not finite")
        out.append(line)
    Path(path).write_text("\n".join(out) + "\n", encoding="utf-8")


def tum_line(t_s: float, position_m: ArrayLike, quat_wxyz: ArrayLike) -> str | None:
    """One TUM line ``t x y z qx qy qz qw``; None when a value is not finite."""
    pos = np.asarray(position_m, dtype=np.float64).reshape(3)
    q = np.asarray(quat_wxyz, dtype=np.float64).reshape(4)
    if not (np.isfinite(t_s) and np.all(np.isfinite(pos)) and np.all(np.isfinite(q))):
        return None
    vals = [*pos, q[1], q[2], q[3], q[0]]
    return " ".join([_fmt_stamp_s(float(t_s))] + [_fmt(float(v)) for v in vals])


# --------------------------------------------------------------------------------------- KITTI


def read_kitti_times(path: str | Path) -> F64:
    """Read a KITTI times file: one stamp in seconds per line, strictly increasing."""
    p = Path(path)
    rows = _parse_rows(p, "ws", (1,), "t_s")
    _check_range(p, rows.values, rows.lines, 1, MAX_ABS_STAMP_S, "timestamp [s]")
    _check_stamps(p, rows.values[:, 0], rows.lines)
    return np.asarray(rows.values[:, 0], dtype=np.float64)


def read_kitti(path: str | Path, times: str | Path | ArrayLike | None = None) -> Trajectory:
    """Read a KITTI pose file (row-major 3x4 ``[R | t]`` per line).

    times: a times file path, an array of stamps in seconds, or None for stamps = pose index.
    """
    p = Path(path)
    rows = _parse_rows(p, "ws", (12,), "row-major 3x4 matrix [R|t]")
    m = rows.values.reshape(-1, 3, 4)
    for c in (3, 7, 11):
        _check_range(p, rows.values[:, c:c + 1], rows.lines, c + 1, MAX_ABS_POSITION_M,
                     "translation [m]")
    Rs = m[:, :, :3]
    ortho = np.abs(Rs @ np.transpose(Rs, (0, 2, 1)) - np.eye(3)).max(axis=(1, 2))
    dets = np.linalg.det(Rs)
    bad = np.flatnonzero((ortho > ROT_ORTHO_TOL) | (dets < 0.0))
    if bad.size:
        i = int(bad[0])
        raise TrajectoryFormatError(
            p,
            f"the 3x3 block is not a rotation (max |R R^T - I| = {ortho[i]:.3g}, "
            f"det = {dets[i]:.6g})",
            int(rows.lines[i]),
        )
    n = m.shape[0]
    if times is None:
        stamps = np.arange(n, dtype=np.float64)
    elif isinstance(times, str | Path):
        tp = Path(times)
        stamps = read_kitti_times(tp)
        if stamps.shape[0] != n:
            raise TrajectoryFormatError(
                tp, f"has {stamps.shape[0]} stamps but the pose file {p} has {n} poses"
            )
    else:
        stamps = np.asarray(times, dtype=np.float64)
        if stamps.shape != (n,):
            raise TrajectoryFormatError(
                p, f"{n} poses but {stamps.reshape(-1).shape[0]} stamps were given"
            )
    try:
        return Trajectory.from_matrices(stamps, m)
    except ShapeError as err:
        raise TrajectoryFormatError(p, str(err)) from None


def write_kitti(path: str | Path, traj: Trajectory, times_path: str | Path | None = None) -> None:
    """Write ``traj`` as KITTI poses; with ``times_path`` also the stamps, one per line."""
    T = traj.matrices()
    lines = [" ".join(_fmt(v) for v in M[:3, :4].reshape(-1)) for M in T]
    Path(path).write_text("\n".join(lines) + ("\n" if lines else ""), encoding="utf-8")
    if times_path is not None:
        tl = [_fmt_stamp_s(float(t)) for t in traj.stamps_s]
        Path(times_path).write_text("\n".join(tl) + ("\n" if tl else ""), encoding="utf-8")


# --------------------------------------------------------------------------------------- EuRoC


def read_euroc_csv(path: str | Path) -> EurocGroundTruth:
    """Read an EuRoC ground-truth CSV (8 columns ``t_ns,p,q_wxyz``; or 11/14/17 with v, b_w, b_a)."""
    p = Path(path)
    rows = _parse_rows(p, "comma", (8, 11, 14, 17), "t_ns,px,py,pz,qw,qx,qy,qz[,v,b_w,b_a]")
    stamps_ns = np.empty(len(rows.tokens), dtype=np.int64)
    for i, toks in enumerate(rows.tokens):
        tok = toks[0]
        try:
            if "_" in tok:
                raise ValueError(tok)
            stamps_ns[i] = int(tok)
        except (ValueError, OverflowError):
            raise TrajectoryFormatError(
                p,
                f"column 1: timestamp {tok[:40]!r} is not an integer number of nanoseconds",
                int(rows.lines[i]),
            ) from None
    _check_stamps(p, stamps_ns, rows.lines)
    v = rows.values
    _check_range(p, v[:, 1:4], rows.lines, 2, MAX_ABS_POSITION_M, "position [m]")
    if v.shape[1] > 8:
        _check_range(p, v[:, 8:], rows.lines, 9, 1e6, "velocity or bias")
    quats = _checked_quats(p, v[:, 4:8], rows.lines)
    # Seconds from integer ns without the rounding of a single float division of 1e18 values.
    stamps_s = (stamps_ns // 1_000_000_000).astype(np.float64) + (
        stamps_ns % 1_000_000_000
    ).astype(np.float64) * 1e-9
    traj = _make(p, stamps_s, v[:, 1:4], quats)
    ncol = v.shape[1]
    vel = v[:, 8:11].copy() if ncol >= 11 else None
    bw = v[:, 11:14].copy() if ncol >= 14 else None
    ba = v[:, 14:17].copy() if ncol >= 17 else None
    return EurocGroundTruth(traj, stamps_ns, vel, bw, ba)


def write_euroc_csv(
    path: str | Path,
    data: Trajectory | EurocGroundTruth,
    stamps_ns: ArrayLike | None = None,
) -> None:
    """Write an EuRoC CSV. ``data`` may be a Trajectory (8 columns) or an EurocGroundTruth (8 to 17
    columns, as many as it holds). Stamps: ``stamps_ns`` if given, else the ground truth's, else
    ``round(stamps_s * 1e9)``."""
    if isinstance(data, EurocGroundTruth):
        traj = data.trajectory
        extras = [data.velocities_m_s, data.gyro_bias, data.accel_bias]
        ns_default: ArrayLike = data.stamps_ns
    else:
        traj = data
        extras = [None, None, None]
        ns_default = np.round(traj.stamps_s * 1e9)
    ns = np.asarray(stamps_ns if stamps_ns is not None else ns_default)
    if ns.shape != (len(traj),):
        raise ShapeError(f"stamps_ns must have shape ({len(traj)},), got {ns.shape}")
    cols = [traj.positions_m, traj.quats_wxyz]
    n_extra = 0
    for e in extras:
        if e is None:
            break
        cols.append(np.asarray(e, dtype=np.float64))
        n_extra += 1
    header = _EUROC_HEADER_8 + ",".join(_EUROC_HEADER_EXTRA.split(",")[: 3 * n_extra + 1])
    table = np.hstack(cols)
    lines = [header.rstrip(",")]
    for t, row in zip(ns, table, strict=True):
        lines.append(",".join([str(int(t))] + [_fmt(x) for x in row]))
    Path(path).write_text("\n".join(lines) + "\n", encoding="utf-8")


# ------------------------------------------------------------------------------ auto detection


def detect_format(path: str | Path) -> TrajectoryFormat:
    """Guess the format from the extension (.csv -> euroc, .tum, .kitti) or the first data line
    (commas -> euroc, 8 numbers -> tum, 12 numbers -> kitti)."""
    p = Path(path)
    ext = p.suffix.lower()
    if ext == ".csv":
        return "euroc"
    if ext == ".tum":
        return "tum"
    if ext == ".kitti":
        return "kitti"
    for lineno, raw in enumerate(_read_text(p).splitlines(), start=1):
        text = raw.strip()
        if not text or text.startswith("#"):
            continue
        if "," in text:
            return "euroc"
        n = len(_SPLIT_WS.split(text))
        if n == 8:
            return "tum"
        if n == 12:
            return "kitti"
        raise TrajectoryFormatError(
            p,
            f"cannot tell the trajectory format: {n} columns (TUM has 8, KITTI 12, "
            "EuRoC CSV is comma-separated)",
            lineno,
        )
    raise TrajectoryFormatError(p, "contains no poses")


def read_trajectory(
    path: str | Path,
    fmt: str = "auto",
    times: str | Path | ArrayLike | None = None,
) -> Trajectory:
    """Read a trajectory in ``fmt`` ("auto", "tum", "kitti", "euroc"); ``times`` is for KITTI."""
    p = Path(path)
    if fmt == "auto":
        fmt = detect_format(p)
    if fmt == "tum":
        traj = read_tum(p)
    elif fmt == "kitti":
        return read_kitti(p, times)
    elif fmt == "euroc":
        traj = read_euroc_csv(p).trajectory
    else:
        raise TrajectoryFormatError(p, f"unknown trajectory format {fmt!r}; use one of {FORMATS}")
    if times is not None:
        raise TrajectoryFormatError(p, f"a times file only applies to KITTI poses, not {fmt}")
    return traj


def write_trajectory(
    path: str | Path,
    traj: Trajectory,
    fmt: str = "auto",
    times_path: str | Path | None = None,
) -> None:
    """Write ``traj`` in ``fmt``; "auto" picks from the extension (.csv euroc, .kitti kitti,
    anything else TUM). ``times_path`` is for KITTI."""
    p = Path(path)
    if fmt == "auto":
        ext = p.suffix.lower()
        fmt = "euroc" if ext == ".csv" else "kitti" if ext == ".kitti" else "tum"
    if fmt == "tum":
        write_tum(p, traj)
    elif fmt == "kitti":
        write_kitti(p, traj, times_path)
    elif fmt == "euroc":
        write_euroc_csv(p, traj)
    else:
        raise ValueError(f"unknown trajectory format {fmt!r}; use one of {FORMATS}")
