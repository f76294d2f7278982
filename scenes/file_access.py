"""Reading the files a scene names (the scene file, its meshes) without hanging or reading without bound.

Rules
-----
- Only regular files are read. A directory, a FIFO, a socket or a device (``/dev/zero``) is
  refused before it is opened; the file is then opened without blocking (``O_NONBLOCK``: a FIFO
  swapped in meanwhile cannot stall the open) and checked again on the open descriptor.
- At most ``max_bytes`` are read; a larger file is refused by its size before any byte is read,
  and a file that grows while it is read is refused when it passes the bound.
- Every failure is one :class:`~scenes.errors.SceneFileError` line naming the path (shortened
  in the middle beyond :data:`MAX_SHOWN_PATH` characters) and the reason (``File name too
  long``, ``Permission denied``, ...), never an ``OSError`` traceback.
"""

from __future__ import annotations

import errno
import os
import stat
from typing import Any

from acoustisim.checks import shown
from scenes.errors import SceneFileError

MAX_SHOWN_PATH = 160
"""Paths longer than this are shown with their middle elided."""

READ_CHUNK_BYTES = 1 << 20
"""Bytes read per system call."""


def shown_path(path: str) -> str:
    """The path for a message: whole when short, else its start and end around an ellipsis."""
    if len(path) <= MAX_SHOWN_PATH:
        return path
    half = MAX_SHOWN_PATH // 2 - 2
    return f"{path[:half]}...{path[-half:]} ({len(path)} characters)"


def path_text(value: Any, what: str) -> str:
    """``value`` as a path string (str or ``os.PathLike`` of str).

    Raises
    ------
    SceneFileError
        Anything else (bytes, numbers, None), or a path holding a NUL character.
    """
    try:
        text = os.fspath(value)
    except TypeError:
        raise SceneFileError(f"{what} = {shown(value)}: expected a path (str or os.PathLike),"
                             f" got {type(value).__name__}") from None
    if not isinstance(text, str):
        raise SceneFileError(f"{what} = {shown(value)}: expected a text path, got {type(text).__name__}")
    if "\0" in text:
        raise SceneFileError(f"{what} = {shown(text)}: a path cannot contain a NUL character")
    if not text:
        raise SceneFileError(f"{what} = '': empty path")
    return text


def _kind(mode: int) -> str:
    if stat.S_ISDIR(mode):
        return "a directory"
    if stat.S_ISFIFO(mode):
        return "a FIFO (named pipe)"
    if stat.S_ISCHR(mode):
        return "a character device"
    if stat.S_ISBLK(mode):
        return "a block device"
    if stat.S_ISSOCK(mode):
        return "a socket"
    return "not a regular file"


def _os_problem(exc: OSError) -> str:
    if exc.errno == errno.ENOENT:
        return "no such file"
    return exc.strerror or type(exc).__name__


def lookup(path: str) -> os.stat_result | OSError:
    """``os.stat(path)``, or the ``OSError`` it raised (a missing file, a name too long...)."""
    try:
        return os.stat(path)
    except OSError as exc:
        return exc


def read_regular_file(path: str, *, max_bytes: int, label: str) -> bytes:
    """The bytes of the regular file ``path``, at most ``max_bytes`` of them.

    Parameters
    ----------
    path : str
    max_bytes : int
        Largest accepted size (bytes).
    label : str
        How messages name the file: the path itself, or ``"objects[2].path = 'rock.stl'"``.

    Raises
    ------
    SceneFileError
        Missing, not a regular file, unreadable, or larger than ``max_bytes``.
    """
    status = lookup(path)
    if isinstance(status, OSError):
        raise SceneFileError(f"{label}: {_os_problem(status)}")
    if not stat.S_ISREG(status.st_mode):
        raise SceneFileError(f"{label}: is {_kind(status.st_mode)}, not a regular file")
    flags = os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_NOCTTY", 0) | getattr(os, "O_CLOEXEC", 0)
    try:
        descriptor = os.open(path, flags)
    except OSError as exc:
        raise SceneFileError(f"{label}: cannot open ({_os_problem(exc)})") from None
    try:
        opened = os.fstat(descriptor)
        if not stat.S_ISREG(opened.st_mode):
            raise SceneFileError(f"{label}: is {_kind(opened.st_mode)}, not a regular file")
        if opened.st_size > max_bytes:
            raise SceneFileError(f"{label}: {opened.st_size:,} bytes, more than the {max_bytes:,} accepted")
        chunks: list[bytes] = []
        total = 0
        while True:
            chunk = os.read(descriptor, min(READ_CHUNK_BYTES, max_bytes + 1 - total))
            if not chunk:
                break
            chunks.append(chunk)
            total += len(chunk)
            if total > max_bytes:
                raise SceneFileError(f"{label}: grew past the {max_bytes:,} bytes accepted while being read")
        return b"".join(chunks)
    except OSError as exc:
        raise SceneFileError(f"{label}: cannot read ({_os_problem(exc)})") from None
    finally:
        os.close(descriptor)


__all__ = ("MAX_SHOWN_PATH", "lookup", "path_text", "read_regular_file", "shown_path")
