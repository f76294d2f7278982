"""Safe file access for the command lines and readers: inputs that cannot hang, outputs that
cannot clobber.

Inputs (``check_input_file``, ``open_input_file``, ``read_input_bytes``, ``read_toml``):
regular files only (a FIFO, device, socket or folder is refused: a FIFO would block the reader,
``/dev/zero`` would be read until memory runs out), opened without blocking, read up to a stated
size limit. Libraries that open a file by name (h5py, soundfile, scipy.io) get the path after
``check_input_file``.

Outputs (``check_output_file``, ``check_output_folder``, ``atomic_output``,
``write_bytes_atomic``): the destination is checked before the work starts (a regular file or
nothing; never a symbolic link, device or other special file, which would be replaced by a
regular file; its folder must exist and be writable), the data go to a hidden temporary file
in the same folder, created with mode 0666 filtered by the process umask (what ``open`` gives any
new file), and renamed onto the destination only once complete. Errors name the user's path,
never the temporary file. A missing folder of an output file is refused. Output folders
(``--out DIR``, ``check_output_folder``) may be missing: the writer creates them with their
parents, and the command says so on stderr once it has succeeded (``note_created_folder``).

Every refusal is an :class:`binsonar.errors.InputError` (one line, exit 2 from the command
lines); a path of the wrong type is an :class:`binsonar.errors.InputTypeError`.
"""

from __future__ import annotations

import errno
import os
import secrets
import stat
import sys
from contextlib import contextmanager
from pathlib import Path
from typing import IO, Any, Iterator

from binsonar.errors import InputError, InputTypeError, short_repr

TOML_MAX_BYTES = 16 * 2**20
"""Largest TOML file read (bytes): far above any scene or array description (a beam table of
100 frequencies x 180 angles is about 200 kB)."""

TEMPORARY_ATTEMPTS = 16
"""Names tried for a temporary output file before giving up (each a fresh random token)."""


def as_path(path: Any, argument: str) -> Path:
    """``path`` as a ``Path``, refusing other types and the empty path.

    Parameters
    ----------
    path : str or os.PathLike
    argument : str
        Names the argument or option in the message ("path", "-o", ...).

    Raises
    ------
    InputTypeError
        Not a str or os.PathLike (bytes included: paths are text here).
    InputError
        The empty path, or one with a NUL character.
    """
    if not isinstance(path, (str, os.PathLike)):
        raise InputTypeError(f"{argument} must be a file path (str or os.PathLike), got {type(path).__name__} "
                             f"{short_repr(path, 80)}")
    text = os.fspath(path)
    if not isinstance(text, str):
        raise InputTypeError(f"{argument} must be a text path, got {type(text).__name__} {short_repr(text, 80)}")
    if text == "":
        raise InputError(f"{argument}: the path is empty")
    if "\0" in text:
        raise InputError(f"{argument}: the path contains a NUL character: {short_repr(text, 80)}")
    return Path(text)


def _label(option: str, path: Path) -> str:
    """How messages name an output: the option and the user's path ("-o ping.h5"), or the path
    alone when no option gave it (the Python API)."""
    return f"{option} {path}" if option else str(path)


def _os_reason(exc: OSError) -> str:
    """The system's reason for an OSError, without the file name it may carry."""
    return exc.strerror or type(exc).__name__


def _kind(mode: int) -> str:
    """What a non-regular file is, for messages."""
    if stat.S_ISDIR(mode):
        return "a folder"
    if stat.S_ISFIFO(mode):
        return "a FIFO (named pipe)"
    if stat.S_ISCHR(mode) or stat.S_ISBLK(mode):
        return "a device"
    if stat.S_ISSOCK(mode):
        return "a socket"
    if stat.S_ISLNK(mode):
        return "a symbolic link"
    return "not a regular file"


# ------------------------------------------------------------------------------------------ inputs
def check_input_file(path: Any, what: str = "file", *, max_bytes: int | None = None) -> Path:
    """The path of an existing, readable regular file (symbolic links to one are followed).

    Parameters
    ----------
    path : str or os.PathLike
    what : str
        Names the input in messages ("recording", "array description", ...).
    max_bytes : int, optional
        Refuse larger files.

    Returns
    -------
    Path

    Raises
    ------
    InputError
        Missing, not a regular file, unreadable, empty or too large.
    """
    p = as_path(path, what)
    try:
        info = os.stat(p)
    except FileNotFoundError:
        raise InputError(f"{p}: no such file") from None
    except OSError as exc:
        raise InputError(f"{p}: cannot read the {what}: {_os_reason(exc)}") from None
    if not stat.S_ISREG(info.st_mode):
        raise InputError(f"{p}: the {what} must be a regular file, this is {_kind(info.st_mode)}")
    if info.st_size == 0:
        raise InputError(f"{p}: the {what} is empty")
    if max_bytes is not None and info.st_size > max_bytes:
        raise InputError(f"{p}: the {what} is {info.st_size} bytes, more than the {max_bytes} allowed")
    if not os.access(p, os.R_OK):
        raise InputError(f"{p}: cannot read the {what}: permission denied")
    return p


@contextmanager
def open_input_file(path: Any, what: str = "file", *, max_bytes: int | None = None) -> Iterator[IO[bytes]]:
    """Open a regular file for reading without ever blocking (a FIFO swapped in after
    ``check_input_file`` is refused too: the descriptor itself is checked).

    Yields
    ------
    binary file object, positioned at the start

    Raises
    ------
    InputError
        As ``check_input_file``.
    """
    p = check_input_file(path, what, max_bytes=max_bytes)
    flags = os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_NOCTTY", 0) | getattr(os, "O_CLOEXEC", 0)
    try:
        fd = os.open(p, flags)
    except OSError as exc:
        raise InputError(f"{p}: cannot open the {what}: {_os_reason(exc)}") from None
    try:
        info = os.fstat(fd)
        if not stat.S_ISREG(info.st_mode):
            raise InputError(f"{p}: the {what} must be a regular file, this is {_kind(info.st_mode)}")
        if max_bytes is not None and info.st_size > max_bytes:
            raise InputError(f"{p}: the {what} is {info.st_size} bytes, more than the {max_bytes} allowed")
        if hasattr(os, "set_blocking"):
            os.set_blocking(fd, True)
        handle = os.fdopen(fd, "rb")
    except BaseException:
        os.close(fd)
        raise
    with handle:
        yield handle


def read_input_bytes(path: Any, what: str = "file", *, max_bytes: int) -> bytes:
    """The whole content of a regular file of at most ``max_bytes`` bytes (checked while
    reading too: a file that grows is cut off and refused)."""
    with open_input_file(path, what, max_bytes=max_bytes) as handle:
        data = handle.read(max_bytes + 1)
    if len(data) > max_bytes:
        raise InputError(f"{path}: the {what} is more than the {max_bytes} bytes allowed")
    return data


def read_toml(path: Any, what: str = "TOML file", *, max_bytes: int = TOML_MAX_BYTES) -> dict[str, Any]:
    """Parse a TOML file safely: a regular file, at most ``max_bytes``, UTF-8, nesting the parser
    can handle (a document nested thousands deep is refused, not a RecursionError).

    Raises
    ------
    InputError
        Unreadable, too large, not UTF-8 or not valid TOML (with the parser's line and column).
    """
    import tomllib

    p = as_path(path, what)
    raw = read_input_bytes(p, what, max_bytes=max_bytes)
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise InputError(f"{p}: the {what} is not UTF-8 text (byte {exc.start})") from None
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise InputError(f"{p}: invalid TOML: {str(exc).splitlines()[0]}") from None
    except RecursionError:
        raise InputError(f"{p}: the {what} nests tables or arrays too deeply") from None


# ----------------------------------------------------------------------------------------- outputs
def _refuse_special(p: Path, option: str) -> bool:
    """Raise for an existing destination that is not a regular file; True when one exists."""
    try:
        info = os.lstat(p)
    except FileNotFoundError:
        return False
    except OSError as exc:
        raise InputError(f"{_label(option, p)}: cannot use this path: {_os_reason(exc)}") from None
    if stat.S_ISLNK(info.st_mode):
        raise InputError(f"{_label(option, p)}: is a symbolic link; refusing to replace it (give the file it points to, "
                         "or another name)")
    if not stat.S_ISREG(info.st_mode):
        raise InputError(f"{_label(option, p)}: exists and is {_kind(info.st_mode)}, not a regular file; refusing to "
                         "replace it")
    return True


def _probe_folder(folder: Path, option: str, shown: Path) -> None:
    """Create and remove a temporary file in ``folder``: the one sure test that it takes new
    files (permissions, ACLs, read-only mounts, a full inode table)."""
    try:
        probe = _create_temporary(folder, ".binsonar-probe", "")
    except InputError:
        raise
    except OSError as exc:
        raise InputError(f"{_label(option, shown)}: cannot write in folder {folder}: {_os_reason(exc)}") from None
    os.unlink(probe)


def check_output_file(path: Any, option: str = "-o") -> Path:
    """Check, before any work, that a file can be written at ``path``.

    The destination must be absent or a regular file (not a symbolic link, folder, device,
    FIFO or socket), its folder must exist and take new files (tested by creating and removing
    a temporary file there), and its name must be valid on this file system.

    Parameters
    ----------
    path : str or os.PathLike
    option : str
        The option that gave the path ("-o", "--png", ...), named in messages.

    Returns
    -------
    Path

    Raises
    ------
    InputError
        Any of the above, naming the option and the user's path.
    """
    p = as_path(path, option)
    if p.name in ("", ".", ".."):
        raise InputError(f"{_label(option, p)}: names a folder, not a file")
    existing = _refuse_special(p, option)
    folder = p.parent
    try:
        folder_info = os.stat(folder)
    except FileNotFoundError:
        raise InputError(f"{_label(option, p)}: folder {folder} does not exist (create it first)") from None
    except OSError as exc:
        raise InputError(f"{_label(option, p)}: cannot use folder {folder}: {_os_reason(exc)}") from None
    if not stat.S_ISDIR(folder_info.st_mode):
        raise InputError(f"{_label(option, p)}: {folder} is not a folder")
    name_max = _name_max(folder)
    if len(os.fsencode(p.name)) > name_max:
        raise InputError(f"{_label(option, p)}: the file name is longer than the {name_max} bytes this file system allows")
    if existing and not os.access(p, os.W_OK):
        raise InputError(f"{_label(option, p)}: exists and is read-only")
    _probe_folder(folder, option, p)
    return p


def _name_max(folder: Path) -> int:
    """Longest file name (bytes) the folder's file system takes (255 when unknown)."""
    try:
        return int(os.pathconf(folder, "PC_NAME_MAX"))
    except (OSError, ValueError, AttributeError):
        return 255


def check_output_folder(path: Any, option: str = "--out") -> Path:
    """Check, before any work, that an output folder can be used or made at ``path``.

    An existing path must be a folder (a symbolic link to one is followed) that takes new
    files; for a missing one, its nearest existing ancestor must be a folder that takes new
    files (the writer creates the missing folders; ``note_created_folder`` then says so).
    Nothing is created here.

    Returns
    -------
    Path

    Raises
    ------
    InputError
        Not a folder, or no writable ancestor (naming the option and path).
    """
    p = as_path(path, option)
    try:
        info = os.stat(p)
    except (FileNotFoundError, NotADirectoryError):
        info = None
    except OSError as exc:
        raise InputError(f"{_label(option, p)}: cannot use this path: {_os_reason(exc)}") from None
    if info is not None:
        if not stat.S_ISDIR(info.st_mode):
            raise InputError(f"{_label(option, p)}: exists and is {_kind(info.st_mode)}, not a folder")
        _probe_folder(p, option, p)
        return p
    ancestor = p.absolute().parent
    while not os.path.lexists(ancestor) and ancestor != ancestor.parent:
        ancestor = ancestor.parent
    if not ancestor.is_dir():
        raise InputError(f"{_label(option, p)}: {ancestor} is not a folder")
    _probe_folder(ancestor, option, p)
    return p


def note_created_folder(path: Path, existed: bool, prog: str) -> None:
    """Say on stderr that an output folder was created ("PROG: note: created folder DIR") when it
    did not exist before the work and does now."""
    if not existed and os.path.isdir(path):
        print(f"{prog}: note: created folder {path}", file=sys.stderr)


def _create_temporary(folder: Path, stem: str, suffix: str) -> Path:
    """A new empty file ``folder/.stem.TOKEN.tmp<suffix>`` created with mode 0666 & ~umask.

    ``O_EXCL | O_NOFOLLOW``: never an existing file or a link planted under the name.
    """
    flags = os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_NOFOLLOW", 0) | getattr(os, "O_CLOEXEC", 0)
    for _ in range(TEMPORARY_ATTEMPTS):
        candidate = folder / f".{stem}.{secrets.token_hex(6)}.tmp{suffix}"
        try:
            fd = os.open(candidate, flags, 0o666)
        except FileExistsError:
            continue
        os.close(fd)
        return candidate
    raise OSError(errno.EEXIST, "could not find a free temporary file name")


@contextmanager
def atomic_output(path: Any, option: str = "-o") -> Iterator[Path]:
    """Write a file atomically: yield a temporary path in the destination's folder, then rename
    it onto ``path`` once the ``with`` block has finished without error.

    The temporary file exists (empty) when yielded, with mode 0666 & ~umask: writers that
    truncate and rewrite it (h5py, matplotlib, VTK) keep that mode. Its name keeps the
    destination's suffix (``.png``, ``.html``) for writers that choose the format by it. The
    destination is checked before (``check_output_file``) and again just before the rename.
    On an error the temporary file is removed; an OSError from the writer becomes an
    InputError naming the user's path.

    Raises
    ------
    InputError
        As ``check_output_file``, or the write failed (disk full, ...).
    """
    p = check_output_file(path, option)
    # A very long name leaves no room for the temporary's token: shorten its stem.
    stem = p.name[: max(1, _name_max(p.parent) - 40 - len(p.suffix))]
    try:
        temporary = _create_temporary(p.parent, stem, p.suffix if len(p.suffix) <= 16 else "")
    except OSError as exc:
        raise InputError(f"{_label(option, p)}: cannot write in folder {p.parent}: {_os_reason(exc)}") from None
    try:
        try:
            yield temporary
        except OSError as exc:
            raise InputError(f"{_label(option, p)}: cannot write the file: {_os_reason(exc)}") from None
        _refuse_special(p, option)
        try:
            os.replace(temporary, p)
        except OSError as exc:
            raise InputError(f"{_label(option, p)}: cannot write the file: {_os_reason(exc)}") from None
    except BaseException:
        try:
            os.unlink(temporary)
        except FileNotFoundError:
            pass
        raise


def write_bytes_atomic(path: Any, data: bytes, option: str = "-o") -> Path:
    """Write ``data`` to ``path`` atomically (``atomic_output``); returns the path."""
    with atomic_output(path, option) as temporary:
        with open(temporary, "wb") as handle:
            handle.write(data)
    return Path(path)


def write_text_atomic(path: Any, text: str, option: str = "-o") -> Path:
    """Write UTF-8 ``text`` to ``path`` atomically (``atomic_output``); returns the path."""
    return write_bytes_atomic(path, text.encode("utf-8"), option)


__all__ = (
    "TOML_MAX_BYTES",
    "as_path",
    "atomic_output",
    "check_input_file",
    "check_output_file",
    "check_output_folder",
    "note_created_folder",
    "open_input_file",
    "read_input_bytes",
    "read_toml",
    "write_bytes_atomic",
    "write_text_atomic",
)
