"""Pings read on demand: the interface every recording reader offers (HDF5 recordings, imported
WAV, NumPy, MATLAB and CSV files).

A ``PingSource`` knows its ``header`` (everything but the pings, checked when the file is
opened) and its ``n_pings``, and reads any range of pings as a ``Recording`` (``read``), or all
of them in chunks of bounded size (``chunks``): the command lines run ``detect`` and
``localize`` chunk by chunk, in memory that does not grow with the number of pings.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from typing import Any, Iterator

import numpy as np
from numpy.typing import NDArray

from binsonar.recording.model import Recording, RecordingError, RecordingHeader, as_volts

CHUNK_BYTES = 32 * 2**20
"""Bytes of stored samples read at once by ``chunks`` (at least one ping): 21 pings of the
thesis tank's 3 x 250,000 int16 codes, enough to batch the detectors' work per call."""


class PingSource(ABC):
    """A recording read ping range by ping range (see the module notes).

    Subclasses set ``header`` and ``n_pings`` and implement ``read_stored``; use them as context
    managers (``close`` releases the file).
    """

    header: RecordingHeader
    n_pings: int

    @property
    def n_samples(self) -> int:
        """Samples per channel of each ping."""
        return self.header.n_samples

    @property
    def source(self) -> str:
        """The file, as messages name it."""
        return self.header.where

    @property
    def stored_bytes_per_ping(self) -> int:
        """Bytes one ping occupies as read (int16 codes or float64 volts)."""
        itemsize = 2 if self.header.stores_codes else 8
        return 3 * self.n_samples * itemsize

    @abstractmethod
    def read_stored(self, start: int, stop: int) -> tuple[NDArray[Any], NDArray[np.bool_] | None,
                                                          NDArray[np.float64] | None]:
        """Pings ``start`` to ``stop`` as stored: the samples (k, 3, n) (int16 codes when
        ``header.stores_codes``, else float volts), the clipping flags (k, 3) or None, the poses
        (k, 6) or None.

        Raises
        ------
        RecordingError
            The file cannot be read there.
        """

    def close(self) -> None:
        """Release the file (nothing to release by default)."""

    def __enter__(self) -> "PingSource":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def read(self, start: int = 0, stop: int | None = None, *, keep_codes: bool = False) -> Recording:
        """Pings ``start`` to ``stop`` (default: to the last) as a ``Recording``.

        Parameters
        ----------
        start, stop : int
            Ping range, ``0 <= start < stop <= n_pings``.
        keep_codes : bool
            For ADC codes, keep them (``Recording.codes``; the volts are made only if read);
            otherwise the recording holds float64 volts.

        Raises
        ------
        RecordingError
            A bad range, or bad data in it (NaN, out-of-range values: the ping named).
        """
        stop = self.n_pings if stop is None else stop
        if not (isinstance(start, (int, np.integer)) and isinstance(stop, (int, np.integer))
                and 0 <= start < stop <= self.n_pings):
            raise RecordingError(f"{self.source}: ping range [{start!r}, {stop!r}) is outside [0, {self.n_pings})")
        data, clipped, pose = self.read_stored(int(start), int(stop))
        data.setflags(write=False)  # ours alone: the recording takes it without a copy
        fields = self.header.recording_fields()
        if self.header.stores_codes:
            if keep_codes:
                return Recording(None, codes=data, clipped=clipped, pose=pose, **fields)
            volts = data * float(self.header.volts_per_code)  # type: ignore[arg-type]
            volts.setflags(write=False)
            return Recording(volts, clipped=clipped, pose=pose, **fields)
        return Recording(as_volts(data, self.source, first_ping=int(start)), clipped=clipped, pose=pose, **fields)

    def chunks(self, max_bytes: int = CHUNK_BYTES, *, keep_codes: bool = True) -> Iterator[tuple[int, Recording]]:
        """Every ping, in consecutive ranges of at most ``max_bytes`` of stored samples (at least
        one ping each): yields (index of the range's first ping, its ``Recording``)."""
        step = max(1, int(max_bytes) // max(self.stored_bytes_per_ping, 1))
        for start in range(0, self.n_pings, step):
            yield start, self.read(start, min(self.n_pings, start + step), keep_codes=keep_codes)
