"""MATLAB files: v5 (scipy.io; the variable loaded whole after its declared size is checked) and
v7.3 (HDF5, through h5py with the recording reader's safety checks: no external storage, links
or virtual datasets, declared sizes within the limits; read ping range by ping range).

The variable read is ``[import] variable``, else ``waveforms``, else the only numeric one. Its
shape is taken in MATLAB's order: (3, n), (n, 3) (one column per channel) or (n_pings, 3, n).
"""

from __future__ import annotations

from types import MappingProxyType
from typing import Any, Mapping

import numpy as np

from binsonar.errors import InputError
from binsonar.files import check_input_file, open_input_file
from binsonar.importers.array_source import ArraySource
from binsonar.importers.numpy_files import MAX_LOADED_BYTES, choose_variable
from binsonar.importers.settings import ImportDescription
from binsonar.recording.hdf5_safety import ReadLimits, checked_dataset, open_hdf5

NUMERIC_CLASSES = ("double", "single", "int8", "int16", "int32", "int64", "uint8", "uint16", "uint32", "uint64")
ITEM_BYTES: Mapping[str, int] = MappingProxyType({
    "double": 8, "single": 4, "int8": 1, "int16": 2, "int32": 4, "int64": 8, "uint8": 1, "uint16": 2, "uint32": 4,
    "uint64": 8})


def mat_version(path: Any) -> int:
    """The MAT-file's major version: 1 for v5 (and v6, v7), 2 for v7.3 (HDF5); 0 for v4.

    Raises
    ------
    InputError
        Not a MAT-file.
    """
    from scipy.io.matlab import MatReadError, matfile_version

    with open_input_file(path, "MATLAB file") as handle:
        try:
            major, _ = matfile_version(handle)
        except (MatReadError, ValueError, OSError, EOFError, TypeError, IndexError) as exc:  # IndexError: a
            # file shorter than the 128-byte header whose first bytes are not a v4 header
            raise InputError(f"{path}: not a MATLAB file: {str(exc).splitlines()[0] if str(exc) else exc!r}"
                             ) from None
    return int(major)


def open_mat(path: Any, description: ImportDescription) -> ArraySource:
    """A MATLAB file (v5 or v7.3) as a ``PingSource`` (see the module notes).

    Raises
    ------
    InputError
        Not a readable MAT-file, no such variable, a variable too large or of another shape or class.
    """
    p = check_input_file(path, "MATLAB file")
    version = mat_version(p)
    if version == 2:
        return _open_v73(p, description)
    if version != 1:
        raise InputError(f"{p}: MATLAB v4 files are not supported (save with -v7 or -v7.3)")
    return _open_v5(p, description)


def _open_v5(path: Any, description: ImportDescription) -> ArraySource:
    import scipy.io
    from scipy.io.matlab import MatReadError

    where = str(path)
    try:
        variables = scipy.io.whosmat(str(path))
    except (MatReadError, ValueError, OSError, EOFError, TypeError, NotImplementedError, MemoryError) as exc:
        raise InputError(f"{where}: not a readable MATLAB file: {str(exc).splitlines()[0] if str(exc) else exc!r}"
                         ) from None
    numeric = {name: (tuple(shape), kind) for name, shape, kind in variables if kind in NUMERIC_CLASSES}
    name = choose_variable(sorted(numeric), description.settings.variable, where, "MATLAB")
    shape, kind = numeric[name]
    declared = int(np.prod(shape, dtype=np.float64)) * ITEM_BYTES[kind]
    if declared > MAX_LOADED_BYTES:
        raise InputError(f"{where}: variable {name!r} is {declared} bytes, more than the {MAX_LOADED_BYTES} loaded at "
                         "once; save with -v7.3 (read ping by ping)")
    try:
        loaded = scipy.io.loadmat(str(path), variable_names=[name], squeeze_me=False, mat_dtype=False)
    except (MatReadError, ValueError, OSError, EOFError, TypeError, NotImplementedError, MemoryError) as exc:
        raise InputError(f"{where}: cannot read variable {name!r}: {str(exc).splitlines()[0] if str(exc) else exc!r}"
                         ) from None
    data = np.asarray(loaded.get(name))
    if data.dtype.kind not in "iuf":
        raise InputError(f"{where}: variable {name!r} is not a numeric array")
    _signed_dtype(data.dtype, where, name)

    def read(key: tuple[slice, ...]) -> np.ndarray:
        return data[key]

    return ArraySource(read, data.shape, data.dtype, description.array, description.settings, f"{where}:{name}",
                       "binsonar import (MATLAB v5)")


def _open_v73(path: Any, description: ImportDescription) -> ArraySource:
    import h5py

    where = str(path)
    h5 = open_hdf5(path, "MATLAB v7.3 file")
    try:
        try:  # a damaged link table fails in HDF5's iteration (RuntimeError, KeyError, OSError)
            names = [key for key in h5.keys() if not key.startswith("#")]
            candidates = []
            for key in names:
                link = h5.get(key, getlink=True)
                if isinstance(link, h5py.HardLink) and isinstance(h5.get(key), h5py.Dataset):
                    candidates.append(key)
        except (RuntimeError, KeyError, OSError, ValueError) as exc:
            raise InputError(f"{where}: cannot list the variables of this MATLAB v7.3 file (damaged?): "
                             f"{str(exc).splitlines()[0] if str(exc) else type(exc).__name__}") from None
        name = choose_variable(candidates if description.settings.variable is None else names,
                               description.settings.variable, where, "MATLAB")
        dset = checked_dataset(h5, name, where, ReadLimits(), kinds="iuf", required=True)
        matlab_shape = tuple(reversed(dset.shape))  # MATLAB is column-major: h5py sees the axes reversed
        dtype = _signed_dtype(dset.dtype, where, name)

        def read(key: tuple[slice, ...]) -> np.ndarray:
            return np.transpose(dset[tuple(reversed(key))])

        return ArraySource(read, matlab_shape, dtype, description.array, description.settings, f"{where}:{name}",
                           "binsonar import (MATLAB v7.3)", close=h5.close)
    except BaseException:
        h5.close()
        raise


def _signed_dtype(dtype: np.dtype, where: str, name: str) -> np.dtype:
    if dtype.kind == "u":
        raise InputError(f"{where}: variable {name!r} holds unsigned integers; ADC codes must be signed (int8/16/32)")
    if dtype.kind not in "if":
        raise InputError(f"{where}: variable {name!r} is not a numeric array")
    return np.dtype(dtype)
