"""Output folders and files, checked before any work: a command that would fail to write its
results after an hour of computing must fail at once instead.

:func:`prepare_output_dir` refuses a path that is a file, lies under a file, has a name too long
for the file system, cannot be created or written, or is a non-empty folder (unless ``force``:
then the command's own earlier outputs are removed, so that no stale file looks current).
:func:`check_output_file` does the same for a single output file (``--json``, ``--plot``).
Every refusal is one :class:`~amrvio.errors.ConfigError` line naming the path.
"""

from __future__ import annotations

import os
import shutil
import tempfile
from collections.abc import Sequence
from pathlib import Path

from amrvio.errors import ConfigError

MAX_PATH_CHARS = 4000
"""Longest output path accepted (characters); Linux allows 4096 bytes."""


def _name_max(folder: Path) -> int:
    try:
        return int(os.pathconf(folder, "PC_NAME_MAX"))
    except (OSError, ValueError):
        return 255


def _existing_ancestor(path: Path) -> Path:
    for parent in [path, *path.parents]:
        if os.path.lexists(parent):
            return parent
    return Path(".")


def _check_names(path: Path, option: str) -> None:
    if len(str(path)) > MAX_PATH_CHARS:
        raise ConfigError(f"{option} {str(path)[:60]}...: path of {len(str(path))} characters "
                          f"(at most {MAX_PATH_CHARS})")
    limit = _name_max(_existing_ancestor(path.absolute()))
    for part in path.parts:
        if len(os.fsencode(part)) > limit:
            raise ConfigError(f"{option} {str(path)[:60]}...: a folder or file name of "
                              f"{len(os.fsencode(part))} bytes (the file system allows {limit})")


def _check_parent_chain(path: Path, option: str) -> None:
    anc = _existing_ancestor(path.absolute())
    if anc != path.absolute() and not anc.is_dir():
        raise ConfigError(f"{option} {path}: {anc} is a file, not a folder")


def _probe_writable(folder: Path, option: str) -> None:
    try:
        fd, name = tempfile.mkstemp(prefix=".amrvio-write-test-", dir=folder)
        os.close(fd)
        os.unlink(name)
    except OSError as err:
        raise ConfigError(f"{option} {folder}: cannot write in the folder: "
                          f"{err.strerror or err}") from None


def prepare_output_dir(path: Path, force: bool, ours: Sequence[str] = (),
                       option: str = "--out") -> None:
    """Make ``path`` a writable, empty (or ``force``d) output folder, before any work.

    ``ours``: the names of the files and folders the command writes there; with ``force`` those
    are removed from a non-empty folder (other files are left alone).
    """
    _check_names(path, option)
    if path.exists() and not path.is_dir():
        raise ConfigError(f"{option} {path}: output path exists and is not a folder")
    _check_parent_chain(path, option)
    try:
        non_empty = path.is_dir() and any(path.iterdir())
    except OSError as err:
        raise ConfigError(f"{option} {path}: cannot list the folder: {err.strerror}") from None
    if non_empty:
        if not force:
            raise ConfigError(f"{path}: output folder is not empty; use --force to overwrite")
        for name in ours:
            p = path / name
            try:
                if p.is_dir() and not p.is_symlink():
                    shutil.rmtree(p)
                elif os.path.lexists(p):
                    p.unlink()
            except OSError as err:
                raise ConfigError(f"{option} {p}: cannot remove the earlier output: "
                                  f"{err.strerror}") from None
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        raise ConfigError(f"{option} {path}: cannot create the folder: "
                          f"{err.strerror or err}") from None
    _probe_writable(path, option)


def check_output_file(path: Path, option: str) -> None:
    """``path`` can be written as a file: not a folder, its folder exists and is writable, its
    name fits the file system. Nothing is left behind."""
    _check_names(path, option)
    if path.is_dir():
        raise ConfigError(f"{option} {path}: cannot write: is a folder, expected a file name")
    _check_parent_chain(path, option)
    folder = path.parent if str(path.parent) else Path(".")
    if not folder.is_dir():
        raise ConfigError(f"{option} {path}: cannot write: its folder {folder} does not exist")
    _probe_writable(folder, option)


__all__ = ["MAX_PATH_CHARS", "check_output_file", "prepare_output_dir"]
