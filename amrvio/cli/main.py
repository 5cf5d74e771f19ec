"""The ``amrvio`` command: a thin dispatcher.

Every sub-command is a module ``amrvio/cli/cmd_<name>.py`` that defines ``NAME``, ``HELP``,
``add_arguments(parser)`` and ``run(args) -> int``. Those modules import heavy libraries only
inside ``run``, so ``amrvio --help`` stays fast. Known errors become one line on stderr and exit
code 1; the library itself never calls ``sys.exit``.
"""

from __future__ import annotations

import argparse
import importlib
import pkgutil
import sys
from collections.abc import Sequence
from types import ModuleType

from amrvio.errors import AmrvioError


def _command_modules() -> list[ModuleType]:
    import amrvio.cli as cli_pkg

    names = sorted(
        m.name for m in pkgutil.iter_modules(cli_pkg.__path__) if m.name.startswith("cmd_")
    )
    return [importlib.import_module(f"amrvio.cli.{n}") for n in names]


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="amrvio",
        description="Robust monocular VO/VIO for mobile robots, with per-frame health records.",
    )
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for mod in _command_modules():
        p = sub.add_parser(mod.NAME, help=mod.HELP, description=mod.HELP)
        mod.add_arguments(p)
        p.set_defaults(_run=mod.run)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        rc: int = args._run(args)
    except AmrvioError as err:
        print(f"amrvio {args.command}: error: {err}", file=sys.stderr)
        return 1
    except BrokenPipeError:  # output piped into `head` and closed early: not an error
        sys.stderr.close()
        return 0
    except KeyboardInterrupt:
        print(f"amrvio {args.command}: interrupted", file=sys.stderr)
        return 130
    return rc


if __name__ == "__main__":
    sys.exit(main())
