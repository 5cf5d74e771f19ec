"""``amrvio config --dump``: the pipeline configuration with a comment per field."""

from __future__ import annotations

import argparse
from pathlib import Path

NAME = "config"
HELP = "print the pipeline configuration (defaults, or a file checked and completed)"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--dump", action="store_true",
                        help="print the configuration as YAML with a comment per field")
    parser.add_argument("--check", type=Path, default=None, metavar="FILE.yaml",
                        help="validate FILE.yaml (unknown keys and wrong types are errors) and "
                             "print the complete configuration it gives")


def run(args: argparse.Namespace) -> int:
    from amrvio.config import PipelineConfig, dump_config, load_config
    from amrvio.errors import ConfigError

    if not args.dump and args.check is None:
        raise ConfigError("amrvio config: give --dump or --check FILE.yaml")
    cfg = load_config(args.check) if args.check is not None else PipelineConfig()
    print(dump_config(cfg), end="")
    return 0
