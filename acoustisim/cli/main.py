"""Entry point of the ``acoustisim`` command.

Verbs are discovered from the modules ``acoustisim/cli/cmd_*.py``; each defines
``register(subparsers) -> None``, adding its parser with ``set_defaults(run=callable)``, where
``run(args) -> int`` returns the exit code. Bad input raises an exception listed in
``USER_ERRORS``: it is printed on one line (no traceback) and the exit code is 2.
"""

from __future__ import annotations

import argparse
import importlib
import pkgutil
import sys
from typing import Sequence

import acoustisim.cli as cli_package

USER_ERROR_NAMES: tuple[str, ...] = ("InputError", "RecordingError", "SceneFileError", "SpecError")


def build_parser() -> argparse.ArgumentParser:
    """The full argument parser with every discovered verb."""
    parser = argparse.ArgumentParser(
        prog="acoustisim",
        description="Physics-based ray-tracing simulator for the biomimetic binaural sonar.",
    )
    subparsers = parser.add_subparsers(dest="verb", metavar="VERB")
    subparsers.required = True
    for info in sorted(pkgutil.iter_modules(cli_package.__path__), key=lambda m: m.name):
        if info.name.startswith("cmd_"):
            module = importlib.import_module(f"acoustisim.cli.{info.name}")
            module.register(subparsers)
    return parser


def _is_user_error(exc: BaseException) -> bool:
    return any(cls.__name__ in USER_ERROR_NAMES for cls in type(exc).__mro__) or isinstance(
        exc, (FileNotFoundError, IsADirectoryError, PermissionError)
    )


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command line; returns the exit code (0 success, 2 bad input)."""
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return int(args.run(args) or 0)
    except BrokenPipeError:
        # The reader of stdout went away (e.g. `| head`): stop quietly, as Unix tools do.
        import os

        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0
    except KeyboardInterrupt:
        print("acoustisim: interrupted", file=sys.stderr)
        return 130
    except Exception as exc:  # noqa: BLE001 - user errors become one line and exit 2
        if _is_user_error(exc):
            message = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
            print(f"acoustisim: error: {message}", file=sys.stderr)
            return 2
        raise


if __name__ == "__main__":
    sys.exit(main())
