"""The ``amrvio`` command: a thin dispatcher.

Every sub-command is a module ``amrvio/cli/cmd_<name>.py`` that defines ``NAME``, ``HELP``,
``add_arguments(parser)`` and ``run(args) -> int``. Those modules import heavy libraries only
inside ``run``, so ``amrvio --help`` stays fast. Known errors become one line on stderr and exit
code 1; the library itself never calls ``sys.exit``.
"""

from __future__ import annotations

import argparse
import contextlib
import importlib
import os
import pkgutil
import sys
from collections.abc import Iterator, Sequence
from types import ModuleType
from typing import NoReturn

from amrvio.errors import AmrvioError


def _command_modules() -> list[ModuleType]:
    import amrvio.cli as cli_pkg

    names = sorted(
        m.name for m in pkgutil.iter_modules(cli_pkg.__path__) if m.name.startswith("cmd_")
    )
    return [importlib.import_module(f"amrvio.cli.{n}") for n in names]


class UsageError(Exception):
    """A command line argparse refuses: ``prog`` (``amrvio run``) and argparse's message."""

    def __init__(self, prog: str, message: str) -> None:
        super().__init__(message)
        self.prog = prog
        self.message = message


class OneLineParser(argparse.ArgumentParser):
    """An ArgumentParser whose errors are one line (no usage block) and exit code 1, like every
    other amrvio error; ``--help`` shows the usage and the ranges."""

    def error(self, message: str) -> NoReturn:
        raise UsageError(self.prog, message)


def build_parser() -> argparse.ArgumentParser:
    parser = OneLineParser(
        prog="amrvio",
        description="Robust monocular VO/VIO for mobile robots, with per-frame health records.",
    )
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for mod in _command_modules():
        p = sub.add_parser(mod.NAME, help=mod.HELP, description=mod.HELP)
        mod.add_arguments(p)
        p.set_defaults(_run=mod.run)
    return parser


@contextlib.contextmanager
def native_stderr_silenced() -> Iterator[None]:
    """Send what C libraries write on file descriptor 2 to /dev/null; ``sys.stderr`` keeps the
    terminal.

    libpng, libjpeg and OpenCV print their own notes when an image is broken; amrvio's error line
    already names the file, and a user must see exactly one line. Python output (errors, logging
    warnings, tqdm) still goes to the real stderr. ``AMRVIO_NATIVE_STDERR=1`` keeps the notes.
    """
    try:
        fd = sys.stderr.fileno()
    except (AttributeError, OSError, ValueError):  # a stream without a descriptor (pytest capsys)
        fd = -1
    if fd < 0 or os.environ.get("AMRVIO_NATIVE_STDERR") == "1":
        yield
        return
    python_stderr = sys.stderr
    python_stderr.flush()
    saved = os.dup(fd)
    devnull = os.open(os.devnull, os.O_WRONLY)
    os.dup2(devnull, fd)
    os.close(devnull)
    sys.stderr = os.fdopen(saved, "w", buffering=1, encoding=python_stderr.encoding,
                           errors="backslashreplace")
    try:
        yield
    finally:
        sys.stderr.flush()
        os.dup2(saved, fd)
        sys.stderr.close()
        sys.stderr = python_stderr


def one_line(text: str) -> str:
    """``text`` with its line breaks (a YAML parser's context, say) folded into spaces."""
    return " ".join(text.split())


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except UsageError as err:
        print(f"{err.prog}: error: {one_line(err.message)} (see {err.prog} --help)",
              file=sys.stderr)
        return 1
    try:
        with native_stderr_silenced():
            rc: int = args._run(args)
    except AmrvioError as err:
        print(f"amrvio {args.command}: error: {one_line(str(err))}", file=sys.stderr)
        return 1
    except BrokenPipeError:  # output piped into `head` and closed early: not an error
        sys.stderr.close()
        return 0
    except KeyboardInterrupt:
        print(f"amrvio {args.command}: interrupted", file=sys.stderr)
        return 130
    return rc


def entry() -> NoReturn:
    """The ``amrvio`` console script: ``run`` and ``batch`` first make the process reproducible
    (:mod:`amrvio.cli.reproducible`: it may start the command again), then :func:`main`."""
    from amrvio.cli.reproducible import make_reproducible

    if len(sys.argv) > 1:
        make_reproducible(sys.argv[1])
    sys.exit(main())


if __name__ == "__main__":
    entry()
