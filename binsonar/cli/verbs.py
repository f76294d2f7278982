"""The machinery shared by the ``binsonar`` and ``acoustisim`` commands.

Verbs are discovered from a package's ``cmd_*.py`` modules; each defines
``register(subparsers) -> None``, adding its parser with ``set_defaults(run=callable)``, where
``run(args) -> int`` returns the exit code. Bad input raises an exception whose class (or a base)
is named in ``USER_ERROR_NAMES``, or a file-system error: it is printed on one line (no
traceback) and the exit code is 2.
"""

from __future__ import annotations

import argparse
import importlib
import os
import pkgutil
import sys
from types import ModuleType
from typing import Sequence

USER_ERROR_NAMES: tuple[str, ...] = ("InputError", "RecordingError", "SceneFileError", "SpecError")


def build_parser(package: ModuleType, prog: str, description: str) -> argparse.ArgumentParser:
    """An argument parser with every verb of ``package`` (its ``cmd_*`` modules)."""
    parser = argparse.ArgumentParser(prog=prog, description=description)
    subparsers = parser.add_subparsers(dest="verb", metavar="VERB")
    subparsers.required = True
    for info in sorted(pkgutil.iter_modules(package.__path__), key=lambda m: m.name):
        if info.name.startswith("cmd_"):
            importlib.import_module(f"{package.__name__}.{info.name}").register(subparsers)
    return parser


def is_user_error(exc: BaseException) -> bool:
    """Whether ``exc`` is bad input (exit 2, one line) rather than a bug (traceback)."""
    return any(cls.__name__ in USER_ERROR_NAMES for cls in type(exc).__mro__) or isinstance(
        exc, (FileNotFoundError, IsADirectoryError, PermissionError)
    )


def run_command(parser: argparse.ArgumentParser, argv: Sequence[str] | None, prog: str) -> int:
    """Parse ``argv`` and run the chosen verb; returns the exit code (0 success, 2 bad input)."""
    args = parser.parse_args(argv)
    try:
        return int(args.run(args) or 0)
    except BrokenPipeError:
        # The reader of stdout went away (e.g. `| head`): stop quietly, as Unix tools do.
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0
    except KeyboardInterrupt:
        print(f"{prog}: interrupted", file=sys.stderr)
        return 130
    except Exception as exc:  # noqa: BLE001 - user errors become one line and exit 2
        if is_user_error(exc):
            message = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
            print(f"{prog}: error: {message}", file=sys.stderr)
            return 2
        raise
