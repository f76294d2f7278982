"""NumPy files: ``.npy`` (memory-mapped: read ping range by ping range) and ``.npz`` (the member
named by ``[import] variable``, else ``waveforms``, else the only one; loaded whole after its
declared size is checked). No pickled objects are ever loaded.
"""

from __future__ import annotations

import zipfile
from typing import Any

import numpy as np

from binsonar.errors import InputError
from binsonar.files import check_input_file, open_input_file
from binsonar.importers.array_source import ArraySource
from binsonar.importers.settings import ImportDescription

MAX_LOADED_BYTES = 2**30
"""Largest array loaded whole (bytes), from formats that cannot be read in parts (.npz members,
MATLAB v5, CSV): for longer recordings use .npy, WAV or MATLAB v7.3, read ping by ping."""


def _header(handle: Any, where: str) -> tuple[tuple[int, ...], np.dtype, bool, int]:
    """Shape, dtype, Fortran order and data offset of a .npy stream, from its header only."""
    from numpy.lib import format as npy_format

    try:
        version = npy_format.read_magic(handle)
        if version == (1, 0):
            shape, fortran, dtype = npy_format.read_array_header_1_0(handle)
        elif version in ((2, 0), (3, 0)):
            shape, fortran, dtype = npy_format.read_array_header_2_0(handle)
        else:
            raise ValueError(f"unknown .npy version {version}")
    except (ValueError, OSError, EOFError, SyntaxError) as exc:
        raise InputError(f"{where}: not a readable .npy array: {str(exc).splitlines()[0] if str(exc) else exc!r}"
                         ) from None
    if dtype.hasobject or dtype.fields is not None or dtype.subdtype is not None:
        raise InputError(f"{where}: the array holds {dtype} values; expected numbers")
    return tuple(int(v) for v in shape), dtype, bool(fortran), int(handle.tell())


def open_npy(path: Any, description: ImportDescription) -> ArraySource:
    """A .npy file as a ``PingSource``, memory-mapped (see the module notes).

    Raises
    ------
    InputError
        Not a readable .npy array, truncated, or of another shape or dtype.
    """
    p = check_input_file(path, ".npy file")
    where = str(p)
    with open_input_file(p, ".npy file") as handle:
        shape, dtype, fortran, offset = _header(handle, where)
        size = handle.seek(0, 2)
    declared = int(np.prod(shape, dtype=np.float64)) * dtype.itemsize
    if offset + declared > size:
        raise InputError(f"{where}: truncated: the header declares {declared} bytes of data, the file holds "
                         f"{size - offset}")
    if declared == 0:
        raise InputError(f"{where}: the array is empty (shape {shape})")
    try:
        data = np.memmap(p, dtype=dtype, mode="r", offset=offset, shape=shape, order="F" if fortran else "C")
    except (OSError, ValueError) as exc:
        raise InputError(f"{where}: cannot map the array: {exc}") from None

    def read(key: tuple[slice, ...]) -> np.ndarray:
        return np.array(data[key])

    # The map is released with the last reference to ``data`` (numpy offers no public close).
    return ArraySource(read, shape, dtype, description.array, description.settings, where, "binsonar import (.npy)")


def open_npz(path: Any, description: ImportDescription) -> ArraySource:
    """One array of a .npz file as a ``PingSource`` (see the module notes).

    Raises
    ------
    InputError
        Not a readable .npz archive, no such member, a member too large, or of another shape or dtype.
    """
    p = check_input_file(path, ".npz file")
    where = str(p)
    try:
        archive = zipfile.ZipFile(p)
    except (zipfile.BadZipFile, OSError, ValueError, EOFError) as exc:
        raise InputError(f"{where}: not a readable .npz archive: {exc}") from None
    with archive:
        members = [name[:-4] for name in archive.namelist() if name.endswith(".npy")]
        name = choose_variable(members, description.settings.variable, where, ".npz")
        info = archive.getinfo(name + ".npy")
        if info.file_size > MAX_LOADED_BYTES:
            raise InputError(f"{where}: member {name!r} is {info.file_size} bytes, more than the {MAX_LOADED_BYTES} "
                             "loaded at once; store a .npy (read ping by ping) instead")
        try:
            with archive.open(info) as handle:
                shape, dtype, fortran, _ = _header(handle, f"{where}: member {name!r}")
                declared = int(np.prod(shape, dtype=np.float64)) * dtype.itemsize
                if declared > info.file_size:
                    raise InputError(f"{where}: member {name!r} declares {declared} bytes but holds {info.file_size}")
                raw = handle.read(declared + 1)
        except (zipfile.BadZipFile, OSError, ValueError, EOFError, RuntimeError) as exc:
            raise InputError(f"{where}: cannot read member {name!r}: {exc}") from None
    if len(raw) != declared or declared == 0:
        raise InputError(f"{where}: member {name!r} holds {len(raw)} bytes of data, its header declares {declared}")
    data = np.frombuffer(raw, dtype=dtype).reshape(shape, order="F" if fortran else "C")

    def read(key: tuple[slice, ...]) -> np.ndarray:
        return data[key]

    return ArraySource(read, shape, dtype, description.array, description.settings, f"{where}:{name}",
                       "binsonar import (.npz)")


def choose_variable(members: list[str], wanted: str | None, where: str, kind: str) -> str:
    """The member or variable to read: ``wanted``, else "waveforms", else the only one."""
    if wanted is not None:
        if wanted not in members:
            raise InputError(f"{where}: no {kind} variable {wanted!r} ([import] variable); it holds: "
                             f"{', '.join(members) or 'nothing'}")
        return wanted
    if "waveforms" in members:
        return "waveforms"
    if len(members) == 1:
        return members[0]
    raise InputError(f"{where}: holds {len(members)} arrays ({', '.join(members[:10]) or 'none'}); name the one to read "
                     "with [import] variable (or call it 'waveforms')")
