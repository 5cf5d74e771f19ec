"""Exceptions for bad files, bad configuration and bugs.

Expected estimation failures (low parallax, lost tracking, unobservable scale) are *data*:
they are returned as typed results, never raised. Exceptions are for input the user must fix,
and every message says which file (and line, when known) and what is wrong with it.
"""

from __future__ import annotations

from pathlib import Path


class AmrvioError(Exception):
    """Base class of every error amrvio raises on purpose."""


class InputFileError(AmrvioError):
    """A file the user gave us cannot be used. The message names the file and, if known, the line.

    ``str(err)`` is one line: ``PATH:LINE: problem`` or ``PATH: problem``.
    """

    def __init__(self, path: str | Path, problem: str, line: int | None = None) -> None:
        self.path = str(path)
        self.problem = " ".join(problem.split())  # one line, whatever a parser put in it
        self.line = line
        where = f"{self.path}:{line}" if line is not None else self.path
        super().__init__(f"{where}: {self.problem}")


class DatasetFormatError(InputFileError):
    """A dataset folder, image, IMU or ground-truth file is malformed."""


class CalibrationError(InputFileError):
    """A calibration file is malformed or does not match its images."""


class TrajectoryFormatError(InputFileError):
    """A trajectory file (TUM, KITTI, EuRoC CSV) is malformed."""


class ConfigError(AmrvioError):
    """A configuration value or command-line option is invalid. The message says how to fix it."""


class ShapeError(AmrvioError, ValueError):
    """An array argument has the wrong shape or contains non-finite values."""


class EvaluationError(AmrvioError):
    """Two trajectories cannot be compared (no common stamps, too few poses to align).

    The message says what to change (time offset, ``--max-diff``, ``--align``, ``--n-align``).
    """
