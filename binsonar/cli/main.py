"""Entry point of the ``binsonar`` command; its verbs are the modules ``binsonar/cli/cmd_*.py``
(see :mod:`binsonar.cli.verbs` for the contract and the exit codes)."""

from __future__ import annotations

import argparse
import sys
from typing import Sequence

import binsonar.cli as cli_package
from binsonar.cli.verbs import build_parser as _build_parser
from binsonar.cli.verbs import run_command

DESCRIPTION = "Detection and localisation for the binaural sonar, on real-format recordings."


def build_parser() -> argparse.ArgumentParser:
    """The full argument parser with every discovered verb."""
    return _build_parser(cli_package, "binsonar", DESCRIPTION)


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command line; returns the exit code (0 success, 2 bad input)."""
    return run_command(build_parser(), argv, "binsonar")


if __name__ == "__main__":
    sys.exit(main())
