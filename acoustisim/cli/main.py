"""Entry point of the ``acoustisim`` command; its verbs are the modules ``acoustisim/cli/cmd_*.py``
(see :mod:`binsonar.cli.verbs` for the contract and the exit codes)."""

from __future__ import annotations

import argparse
import sys
from typing import Sequence

from binsonar.cli import verbs

DESCRIPTION = "Physics-based ray-tracing simulator for the biomimetic binaural sonar."


def build_parser() -> argparse.ArgumentParser:
    """The full argument parser with every discovered verb."""
    return verbs.build_parser(__package__, "acoustisim", DESCRIPTION)


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command line; returns the exit code (0 success, 2 bad input)."""
    return verbs.run_command(build_parser(), argv, "acoustisim")


if __name__ == "__main__":
    sys.exit(main())
