"""The machinery shared by the ``binsonar`` and ``acoustisim`` commands.

Verbs are discovered from a package's ``cmd_*.py`` modules; each defines
``register(subparsers) -> None``, adding its parser with ``set_defaults(run=callable)``, where
``run(args) -> int`` returns the exit code.

The contract for every input: exit 0, or exit 2 with exactly one line on stderr.

- Bad options (argparse's errors) print one line, ``PROG VERB: error: MESSAGE (see PROG VERB
  --help)``; the usage stays in ``--help`` (:class:`OneLineArgumentParser`).
- Bad input raises an exception whose class (or a base) is named in ``USER_ERROR_NAMES``, or a
  file-system error (``OSError``: the message names the path, shortened in the middle when
  long): it is printed on one line, no traceback, exit code 2.
- Running out of memory is one line and exit 2 as well (the pre-flight's limits exist to
  prevent it; the line says which way out there is).
"""

from __future__ import annotations

import argparse
import importlib
import os
import pkgutil
import sys
from typing import NoReturn, Sequence

USER_ERROR_NAMES: tuple[str, ...] = ("InputError", "RecordingError", "SceneFileError", "SpecError")

MAX_SHOWN_CHARS = 160
"""Paths and messages longer than this are shown with their middle elided."""


def one_line(text: str, limit: int = 2000) -> str:
    """``text`` on one line (runs of whitespace, newlines included, become one space), elided
    in the middle beyond ``limit`` characters."""
    flat = " ".join(str(text).split())
    if len(flat) <= limit:
        return flat
    half = limit // 2 - 2
    return f"{flat[:half]} ... {flat[-half:]}"


class OneLineArgumentParser(argparse.ArgumentParser):
    """An ``ArgumentParser`` whose errors are one line on stderr (exit 2), without the usage block.

    Sub-command parsers made by ``add_subparsers`` are of the same class, so every verb's
    errors follow the rule; ``--help`` still prints the usage and the options.
    """

    def error(self, message: str) -> NoReturn:  # type: ignore[override]
        self.exit(2, f"{self.prog}: error: {one_line(message)} (see {self.prog} --help)\n")


def build_parser(package: str, prog: str, description: str) -> argparse.ArgumentParser:
    """An argument parser with every verb of the package named ``package`` (its ``cmd_*``
    modules; a command's ``main`` module passes its own ``__package__``, so that the package
    and its entry point do not import each other)."""
    parser = OneLineArgumentParser(prog=prog, description=description)
    subparsers = parser.add_subparsers(dest="verb", metavar="VERB")
    subparsers.required = True
    for info in sorted(pkgutil.iter_modules(importlib.import_module(package).__path__), key=lambda m: m.name):
        if info.name.startswith("cmd_"):
            importlib.import_module(f"{package}.{info.name}").register(subparsers)
    return parser


def is_user_error(exc: BaseException) -> bool:
    """Whether ``exc`` is bad input (exit 2, one line) rather than a bug (traceback)."""
    return any(cls.__name__ in USER_ERROR_NAMES for cls in type(exc).__mro__) or isinstance(exc, OSError)


def _shown_path(path: object) -> str:
    text = path if isinstance(path, str) else repr(path)
    if len(text) <= MAX_SHOWN_CHARS:
        return text
    half = MAX_SHOWN_CHARS // 2 - 2
    return f"{text[:half]}...{text[-half:]} ({len(text)} characters)"


def user_message(exc: BaseException) -> str:
    """The one line printed for a user error: the message's first line; for a file-system error
    its reason and the path(s) it names."""
    if isinstance(exc, OSError) and not any(cls.__name__ in USER_ERROR_NAMES for cls in type(exc).__mro__):
        reason = exc.strerror or type(exc).__name__
        names = [_shown_path(name) for name in (exc.filename, exc.filename2) if name is not None]
        return one_line(f"{' -> '.join(names)}: {reason}" if names else reason)
    text = str(exc).strip()
    return one_line(text.splitlines()[0]) if text else type(exc).__name__


def run_command(parser: argparse.ArgumentParser, argv: Sequence[str] | None, prog: str) -> int:
    """Parse ``argv`` and run the chosen verb; returns the exit code (0 success, 2 bad input).

    argparse's own exits (``--help``: 0; a bad option: 2, after its one line) are returned as
    codes too, so that in-process callers get a code, never ``SystemExit``.
    """
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:
        return exc.code if isinstance(exc.code, int) else (0 if exc.code is None else 2)
    try:
        return int(args.run(args) or 0)
    except BrokenPipeError:
        # The reader of stdout went away (e.g. `| head`): stop quietly, as Unix tools do.
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0
    except KeyboardInterrupt:
        print(f"{prog}: interrupted", file=sys.stderr)
        return 130
    except MemoryError:
        print(f"{prog}: error: out of memory: this input needs more memory than the machine has"
              " (lower the record length, the pings or the objects)", file=sys.stderr)
        return 2
    except UnicodeEncodeError as exc:
        print(f"{prog}: error: cannot print a result: it holds characters the output's encoding"
              f" ({exc.encoding}) cannot show (set PYTHONIOENCODING=utf-8:backslashreplace)", file=sys.stderr)
        return 2
    except Exception as exc:  # noqa: BLE001 - user errors become one line and exit 2
        if is_user_error(exc):
            print(f"{prog}: error: {user_message(exc)}", file=sys.stderr)
            return 2
        raise
