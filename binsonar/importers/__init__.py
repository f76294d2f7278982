"""Recordings from other formats: multi-channel WAV, NumPy ``.npy``/``.npz``, MATLAB ``.mat``
(v5 and v7.3) and CSV, described by an array description file (TOML, with an ``[import]`` table).

``open_source(path, array_toml)`` opens any supported file as a ``PingSource`` (a recording file
without an array description, a foreign file with one), so that ``binsonar detect``,
``localize`` and ``import`` treat them alike; ``import_recording`` writes one as a recording file.
The format is chosen by the file's suffix: ``.h5``/``.hdf5`` recordings, ``.wav``, ``.npy``,
``.npz``, ``.mat``, ``.csv``.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any, Callable, Mapping

from binsonar.errors import InputError
from binsonar.files import as_path
from binsonar.importers.settings import ImportDescription, read_import_description
from binsonar.recording.source import PingSource

RECORDING_SUFFIXES = (".h5", ".hdf5", ".hdf")
IMPORT_SUFFIXES = (".wav", ".wave", ".npy", ".npz", ".mat", ".csv")


def _openers() -> Mapping[str, Callable[[Any, ImportDescription], PingSource]]:
    from binsonar.importers.csv_file import open_csv
    from binsonar.importers.matlab import open_mat
    from binsonar.importers.numpy_files import open_npy, open_npz
    from binsonar.importers.wav import open_wav

    return {".wav": open_wav, ".wave": open_wav, ".npy": open_npy, ".npz": open_npz, ".mat": open_mat,
            ".csv": open_csv}


def open_foreign(path: str | os.PathLike[str], array_toml: str | os.PathLike[str]) -> PingSource:
    """A WAV, NumPy, MATLAB or CSV file as a ``PingSource``, described by ``array_toml``.

    Raises
    ------
    InputError
        An unknown suffix, an unreadable file or description, or samples that do not fit it.
    """
    p = as_path(path, "input")
    suffix = p.suffix.lower()
    openers = _openers()
    if suffix not in openers:
        raise InputError(f"{p}: unknown format {suffix or '(no suffix)'!r}; binsonar reads recordings "
                         f"({', '.join(RECORDING_SUFFIXES)}) and imports {', '.join(IMPORT_SUFFIXES)}")
    description = read_import_description(array_toml)
    return openers[suffix](p, description)


def open_source(path: str | os.PathLike[str], array_toml: str | os.PathLike[str] | None = None) -> PingSource:
    """Any file binsonar reads, as a ``PingSource``: a recording (HDF5; no ``array_toml``), or a
    foreign file described by ``array_toml``.

    Raises
    ------
    InputError
        A foreign file without ``array_toml``, a recording with one, or any reading error.
    """
    from binsonar.recording import open_recording

    p = as_path(path, "input")
    suffix = p.suffix.lower()
    if suffix in IMPORT_SUFFIXES:
        if array_toml is None:
            raise InputError(f"{p}: a {suffix} file needs its array description: --array ARRAY.toml")
        return open_foreign(p, array_toml)
    if array_toml is not None:
        raise InputError(f"{p}: --array describes files of other formats ({', '.join(IMPORT_SUFFIXES)}); a "
                         "recording carries its own description")
    return open_recording(p)


def import_recording(path: str | os.PathLike[str], array_toml: str | os.PathLike[str],
                     output: str | os.PathLike[str], *, option: str = "-o") -> tuple[Path, PingSource]:
    """Convert a foreign file to a recording file (written ping range by ping range, atomically).

    Returns
    -------
    (Path, PingSource)
        The written file, and the (closed) source it was made from (its header and ``n_pings``).

    Raises
    ------
    InputError
        As ``open_foreign``, the output path refused, or the output is the input.
    """
    from binsonar.files import check_output_file
    from binsonar.recording import write_recording_chunks

    destination = check_output_file(output, option)
    source_path = as_path(path, "input")
    if destination.exists() and source_path.exists() and os.path.samefile(destination, source_path):
        raise InputError(f"{option} {destination}: is the input file; write the recording elsewhere")
    with open_foreign(source_path, array_toml) as source:
        write_recording_chunks(destination, (chunk for _, chunk in source.chunks(keep_codes=True)), source.n_pings,
                               store_codes=source.header.stores_codes, option=option)
    return destination, source


__all__ = ("IMPORT_SUFFIXES", "RECORDING_SUFFIXES", "import_recording", "open_foreign", "open_source")
