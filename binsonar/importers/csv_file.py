"""CSV files: one row per sample, one column per channel (left, centre, right), comma-separated,
an optional header row naming the columns (``left``, ``centre``, ``right`` in any order; other
names are refused). Values are volts (times ``volts_per_unit``), or ADC codes with
``[import] samples = "codes"``. The file is parsed whole (at most ``MAX_CSV_BYTES``); pings of
``samples_per_ping`` rows follow one another.
"""

from __future__ import annotations

import io
from typing import Any

import numpy as np

from binsonar.errors import InputError
from binsonar.files import read_input_bytes
from binsonar.importers.array_source import ArraySource
from binsonar.importers.settings import ImportDescription

MAX_CSV_BYTES = 2**28
"""Largest CSV file parsed (bytes; about 10 million samples per channel): longer recordings
belong in a binary format (WAV, .npy, MATLAB v7.3)."""
CHANNEL_COLUMNS = ("left", "centre", "right")


def open_csv(path: Any, description: ImportDescription) -> ArraySource:
    """A CSV file as a ``PingSource`` (see the module notes).

    Raises
    ------
    InputError
        Unreadable, not UTF-8, a malformed row (its line named), or not three columns.
    """
    raw = read_input_bytes(path, "CSV file", max_bytes=MAX_CSV_BYTES)
    where = str(path)
    try:
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        raise InputError(f"{where}: not UTF-8 text (byte {exc.start})") from None
    first_line = text.split("\n", 1)[0].strip()
    order = (0, 1, 2)
    skip = 0
    if first_line and not _numeric_row(first_line):
        names = tuple(cell.strip().strip('"').lower() for cell in first_line.split(","))
        if sorted(names) != sorted(CHANNEL_COLUMNS):
            raise InputError(f"{where}: the header row must name the columns left, centre, right, got {first_line[:80]!r}")
        order = tuple(names.index(name) for name in CHANNEL_COLUMNS)
        skip = 1
    codes = description.settings.samples == "codes"
    try:
        data = np.loadtxt(io.StringIO(text), delimiter=",", skiprows=skip, ndmin=2,
                          dtype=np.int64 if codes else np.float64)
    except (ValueError, OverflowError) as exc:
        raise InputError(f"{where}: {str(exc).splitlines()[0] if str(exc) else 'malformed CSV'}") from None
    if data.shape[1] != 3:
        raise InputError(f"{where}: {data.shape[1]} column(s); a recording has 3 (left, centre, right)")
    data = data[:, order]
    if codes:
        if data.size and (data.min() < -(2**31) or data.max() >= 2**31):
            raise InputError(f"{where}: ADC codes beyond 32 bits")
        data = data.astype(np.int32 if (data.size and (data.min() < -32768 or data.max() > 32767)) else np.int16)

    def read(key: tuple[slice, ...]) -> np.ndarray:
        return data[key]

    return ArraySource(read, data.shape, data.dtype, description.array, description.settings, where,
                       "binsonar import (CSV)")


def _numeric_row(line: str) -> bool:
    try:
        [float(cell) for cell in line.split(",")]
    except ValueError:
        return False
    return True
