"""Reading HDF5 files that may be hostile: only what is stored in the file, only what was declared,
never more than the limits.

HDF5 can make a dataset read bytes from elsewhere: external storage (raw data in another file,
e.g. ``/etc/passwd``), external links (an object in another HDF5 file) and virtual datasets
(a mapping onto other files). It can also declare far more data than it stores: a compressed
dataset of 60 GB in a 10 MB file, or chunks never written (read back as the fill value). The
functions here open a file (``open_hdf5``: a regular file, read-only), reach objects through
hard links only (``hard_object``), accept a dataset only when its data are stored in the file,
its declared size and chunk size are within ``ReadLimits`` and its declared bytes are at most
``max_expansion`` times the bytes it stores (``checked_dataset``), and read attributes only
after checking their size (``attribute``). Every refusal is a one-line ``RecordingError``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from binsonar.errors import short_repr
from binsonar.files import check_input_file
from binsonar.recording.model import RecordingError

if TYPE_CHECKING:
    import h5py


@dataclass(frozen=True)
class ReadLimits:
    """What a recording file may declare before it is read (raise a limit for a legitimate
    larger file).

    Attributes
    ----------
    max_samples_per_channel : int
        Samples per channel of one ping: one ping must fit in memory (2^26 samples is 3.4 s at
        20 MS/s; 1.6 GB as float64 volts for three channels).
    max_expansion : float
        Largest ratio of a dataset's declared bytes to the bytes it stores. Real ADC data
        compress 2-4 times; a dataset declaring hundreds of times what it stores is a
        decompression bomb or mostly never-written chunks.
    max_chunk_bytes : int
        Largest HDF5 chunk (decompressed) of a dataset: a chunk is decompressed whole to read
        any part of it.
    max_small_dataset_values : int
        Largest template, beam table, pose or flags dataset (values).
    max_attribute_bytes : int
        Largest attribute read.
    """

    max_samples_per_channel: int = 2**26
    max_expansion: float = 256.0
    max_chunk_bytes: int = 256 * 2**20
    max_small_dataset_values: int = 2**24
    max_attribute_bytes: int = 2**20


EXPANSION_FREE_BYTES = 2**16
"""Datasets declaring at most this many bytes are exempt from the expansion test (a few
bytes stored compactly, or a tiny dataset with a large fill)."""


def open_hdf5(path: Any, what: str = "recording") -> "h5py.File":
    """Open a regular file read-only with h5py.

    Raises
    ------
    RecordingError
        Missing, not a regular file, empty, or not HDF5.
    """
    import h5py

    from binsonar.errors import InputError

    try:
        p = check_input_file(path, what)
    except InputError as exc:
        raise RecordingError(str(exc)) from None
    try:
        return h5py.File(p, "r")
    except (OSError, ValueError) as exc:
        raise RecordingError(f"{p}: not a readable HDF5 {what} (truncated or corrupt?): "
                             f"{str(exc).splitlines()[0] if str(exc) else type(exc).__name__}") from None


def hard_object(parent: "h5py.Group", name: str, where: str) -> Any:
    """The object ``name`` of ``parent`` when it is stored in this file (a hard link), else None
    when absent.

    Raises
    ------
    RecordingError
        A soft or external link, or a link h5py cannot classify.
    """
    import h5py

    try:
        link = parent.get(name, getlink=True)
    except (KeyError, OSError, ValueError, TypeError) as exc:
        raise RecordingError(f"{where}: cannot read /{name}: {exc}") from None
    if link is None:
        return None
    if isinstance(link, h5py.ExternalLink):
        raise RecordingError(f"{where}: /{name} is an external link to {short_repr(link.filename)}; only data stored "
                             "in the file are read")
    if not isinstance(link, h5py.HardLink):
        raise RecordingError(f"{where}: /{name} is a {type(link).__name__}; only objects stored in the file are read")
    try:
        return parent[name]
    except (KeyError, OSError, ValueError, TypeError) as exc:
        raise RecordingError(f"{where}: cannot read /{name}: {exc}") from None


def checked_dataset(parent: "h5py.Group", name: str, where: str, limits: ReadLimits, *,
                    kinds: str = "biuf", required: bool = False) -> "h5py.Dataset | None":
    """The dataset ``name`` once its storage is safe to read (see the module notes).

    Parameters
    ----------
    parent : h5py.Group
    name : str
    where : str
        The file, for messages.
    limits : ReadLimits
    kinds : str
        Accepted numpy dtype kinds ("biuf": booleans, integers, floats).
    required : bool
        Raise when absent (else return None).

    Raises
    ------
    RecordingError
        Absent (when required), not a dataset, stored outside the file, of another dtype, or
        declaring more than the limits allow.
    """
    import h5py

    obj = hard_object(parent, name, where)
    label = f"{where}: /{name}" if parent.name == "/" else f"{where}: {parent.name}/{name}"
    if obj is None:
        if required:
            raise RecordingError(f"{where}: missing dataset {name!r}")
        return None
    if not isinstance(obj, h5py.Dataset):
        raise RecordingError(f"{label} must be a dataset, got a {type(obj).__name__}")
    try:
        plist = obj.id.get_create_plist()
        layout = plist.get_layout()
        external = plist.get_external_count()
        stored = int(obj.id.get_storage_size())
        dtype = obj.dtype
        shape = obj.shape
        chunks = obj.chunks
    except (OSError, ValueError, TypeError, RuntimeError) as exc:
        raise RecordingError(f"{label}: cannot read its layout: {exc}") from None
    if layout == h5py.h5d.VIRTUAL:
        raise RecordingError(f"{label} is a virtual dataset (data mapped from other files); not read")
    if external:
        raise RecordingError(f"{label} keeps its data in external file(s); only data stored in the file are read")
    if dtype.kind not in kinds or dtype.fields is not None or dtype.subdtype is not None:
        raise RecordingError(f"{label} has dtype {dtype}, expected {_kinds_text(kinds)}")
    if shape is None:
        raise RecordingError(f"{label} has no data (a null dataspace)")
    declared = int(np.prod(shape, dtype=np.float64)) * dtype.itemsize
    if chunks is not None:
        chunk_bytes = int(np.prod(chunks, dtype=np.float64)) * dtype.itemsize
        if chunk_bytes > limits.max_chunk_bytes:
            raise RecordingError(f"{label}: HDF5 chunks of {chunk_bytes} bytes exceed the {limits.max_chunk_bytes} "
                                 "allowed")
    if declared > EXPANSION_FREE_BYTES and declared > limits.max_expansion * stored:
        raise RecordingError(f"{label} declares {declared} bytes but stores {stored}: more than "
                             f"{limits.max_expansion:g} times (a decompression bomb or unwritten data); not read")
    return obj


def _kinds_text(kinds: str) -> str:
    names = {"b": "booleans", "i": "integers", "u": "unsigned integers", "f": "floats", "S": "strings",
             "O": "strings", "U": "strings"}
    return " or ".join(dict.fromkeys(names[k] for k in kinds if k in names))


def small_array(parent: "h5py.Group", name: str, where: str, limits: ReadLimits, *, kinds: str = "biuf",
                required: bool = False) -> np.ndarray | None:
    """A small dataset (at most ``limits.max_small_dataset_values`` values) read whole."""
    dataset = checked_dataset(parent, name, where, limits, kinds=kinds, required=required)
    if dataset is None:
        return None
    if dataset.size > limits.max_small_dataset_values:
        raise RecordingError(f"{where}: /{name} holds {dataset.size} values, more than the "
                             f"{limits.max_small_dataset_values} allowed")
    try:
        return np.asarray(dataset[()])
    except (OSError, ValueError, TypeError, RuntimeError) as exc:
        raise RecordingError(f"{where}: cannot read /{name}: {exc}") from None


def attribute(obj: "h5py.HLObject", key: str, where: str, limits: ReadLimits, *, required: bool = True,
              default: Any = None) -> Any:
    """An attribute's value as a Python scalar, string or small array, its size checked first.

    Bytes become text; numpy scalars become Python numbers.

    Raises
    ------
    RecordingError
        Missing (when required), too large or unreadable.
    """
    import h5py

    try:
        present = key in obj.attrs
    except (OSError, ValueError, TypeError, RuntimeError) as exc:
        raise RecordingError(f"{where}: cannot read attribute {key!r}: {exc}") from None
    if not present:
        if required:
            raise RecordingError(f"{where}: missing attribute {key!r}")
        return default
    try:
        attr_id = h5py.h5a.open(obj.id, key.encode())
        size = int(attr_id.get_storage_size())
        kind = attr_id.dtype.kind
        value = obj.attrs[key] if size <= limits.max_attribute_bytes else None
    except (OSError, ValueError, TypeError, RuntimeError, KeyError) as exc:
        raise RecordingError(f"{where}: cannot read attribute {key!r}: {exc}") from None
    if value is None:
        raise RecordingError(f"{where}: attribute {key!r} is {size} bytes, more than the "
                             f"{limits.max_attribute_bytes} allowed")
    if kind == "V":
        raise RecordingError(f"{where}: attribute {key!r} has an unsupported type")
    if isinstance(value, bytes):
        try:
            return value.decode("utf-8")
        except UnicodeDecodeError:
            raise RecordingError(f"{where}: attribute {key!r} is not UTF-8 text") from None
    if isinstance(value, np.generic):
        return value.item()
    return value


def text_attribute(obj: "h5py.HLObject", key: str, where: str, limits: ReadLimits, *, required: bool = True,
                   default: str | None = None, max_length: int = 4096) -> str | None:
    """A string attribute (at most ``max_length`` characters)."""
    value = attribute(obj, key, where, limits, required=required, default=default)
    if value is None:
        return None
    if not isinstance(value, str):
        raise RecordingError(f"{where}: attribute {key!r} must be text, got {short_repr(value)}")
    if len(value) > max_length:
        raise RecordingError(f"{where}: attribute {key!r} is longer than {max_length} characters")
    return value


def number_attribute(obj: "h5py.HLObject", key: str, where: str, limits: ReadLimits, *,
                     required: bool = True) -> float | None:
    """A real-number attribute (a 1-element array is taken as its element); None when absent and
    not required. Range checks are the caller's."""
    value = attribute(obj, key, where, limits, required=required)
    if value is None:
        return None
    if isinstance(value, np.ndarray) and value.size == 1 and value.dtype.kind in "biuf":
        value = value.reshape(()).item()
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise RecordingError(f"{where}: attribute {key!r} must be a number, got {short_repr(value)}")
    return value
