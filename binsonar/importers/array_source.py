"""Pings from an array of samples in any of the usual layouts, converted to codes or volts.

The importers (WAV, NumPy, MATLAB, CSV) all end in an array-like of samples (a memory map, an
HDF5 dataset, a loaded array, a sound file's frames) whose layout is one of

- (n_pings, 3, n_samples): pings, channels, samples (``conventions.md``'s order);
- (3, N): channels, samples;
- (N, 3), N != 3: samples, channels (a WAV file's frames, a CSV file's rows, MATLAB's columns);

where the N samples of a 2-D layout are one ping, or ``samples_per_ping`` each. ``PingLayout``
finds the layout of a shape and reads any range of pings as (k, 3, n); ``ArraySource`` turns
that into a ``PingSource``: integer samples are ADC codes (int16 codes kept as they are when every
channel shares one ``volts_per_code`` and they fit int16; otherwise volts = code x the channel's
step), float samples are volts (times ``volts_per_unit``).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable

import numpy as np
from numpy.typing import NDArray

from binsonar.array_description import ArrayDescription
from binsonar.errors import InputError
from binsonar.importers.settings import ImportSettings
from binsonar.recording.model import RecordingError, RecordingHeader
from binsonar.recording.source import PingSource

MAX_SAMPLES_PER_CHANNEL = 2**26
"""Samples per channel of one ping (as ``ReadLimits.max_samples_per_channel``)."""

Reader = Callable[[tuple[slice, ...]], NDArray[Any]]
"""Reads a block of the array given one slice per axis (in the layout's axis order)."""


@dataclass(frozen=True)
class PingLayout:
    """How an array's axes map to pings, channels and samples.

    Attributes
    ----------
    kind : {"pings-channels-samples", "channels-samples", "samples-channels"}
    n_pings : int
    samples_per_ping : int
    """

    kind: str
    n_pings: int
    samples_per_ping: int

    @classmethod
    def of(cls, shape: tuple[int, ...], samples_per_ping: int | None, where: str) -> "PingLayout":
        """The layout of an array of this shape (see the module notes).

        Raises
        ------
        InputError
            Another shape, or a sample count that ``samples_per_ping`` does not divide.
        """
        if len(shape) == 3 and shape[1] == 3 and shape[0] >= 1 and shape[2] >= 2:
            if samples_per_ping is not None and samples_per_ping != shape[2]:
                raise InputError(f"{where}: the array holds pings of {shape[2]} samples; [import] samples_per_ping = "
                                 f"{samples_per_ping} disagrees")
            return cls("pings-channels-samples", int(shape[0]), int(shape[2]))
        if len(shape) == 2 and shape[0] == 3:
            kind, total = "channels-samples", int(shape[1])
        elif len(shape) == 2 and shape[1] == 3:
            kind, total = "samples-channels", int(shape[0])
        else:
            raise InputError(f"{where}: samples must have shape (n_pings, 3, n), (3, n) or (n, 3) (three channels: "
                             f"left, centre, right), got {tuple(shape)}")
        per_ping = total if samples_per_ping is None else samples_per_ping
        if total < 2 or total % per_ping:
            raise InputError(f"{where}: {total} samples per channel cannot be split into pings of {per_ping} "
                             "([import] samples_per_ping)")
        return cls(kind, total // per_ping, per_ping)

    def read(self, reader: Reader, start: int, stop: int) -> NDArray[Any]:
        """Pings ``start`` to ``stop`` as (k, 3, samples_per_ping), in the array's dtype."""
        k, n = stop - start, self.samples_per_ping
        everything = slice(None)
        if self.kind == "pings-channels-samples":
            return np.asarray(reader((slice(start, stop), everything, everything)))
        span = slice(start * n, stop * n)
        if self.kind == "channels-samples":
            block = np.asarray(reader((everything, span)))  # (3, k n)
            return block.reshape(3, k, n).transpose(1, 0, 2)
        block = np.asarray(reader((span, everything)))  # (k n, 3)
        return block.reshape(k, n, 3).transpose(0, 2, 1)


class ArraySource(PingSource):
    """A ``PingSource`` over an array of samples (see the module notes).

    Parameters
    ----------
    reader : callable
        Reads a block given one slice per axis.
    shape : tuple of int
        The array's shape (in the reader's axis order).
    dtype : numpy dtype
        The samples' dtype: signed integers (codes) or floats (volts).
    array : ArrayDescription
    settings : ImportSettings
    where : str
        The file, for messages (and ``Recording.source``).
    created_by : str
    code_bits : int, optional
        For integer samples held in a wider type (a 24-bit WAV read as int32): the width of the
        codes; samples are then shifted right by (bits of the type - code_bits) first.
    close : callable, optional
        Releases the file.

    Raises
    ------
    InputError
        A shape, dtype or description that does not fit (one line).
    """

    def __init__(self, reader: Reader, shape: tuple[int, ...], dtype: np.dtype, array: ArrayDescription,
                 settings: ImportSettings, where: str, created_by: str, *, code_bits: int | None = None,
                 close: Callable[[], None] | None = None) -> None:
        self._reader = reader
        self._close = close
        self.layout = PingLayout.of(tuple(int(v) for v in shape), settings.samples_per_ping, where)
        if self.layout.samples_per_ping > MAX_SAMPLES_PER_CHANNEL:
            raise InputError(f"{where}: pings of {self.layout.samples_per_ping} samples per channel are more than the "
                             f"{MAX_SAMPLES_PER_CHANNEL} allowed; set [import] samples_per_ping")
        self.n_pings = self.layout.n_pings
        dtype = np.dtype(dtype)
        self._shift = 0
        self._scale: NDArray[np.float64] | None = None
        if dtype.kind == "i":
            steps = [c.electrical.volts_per_code for c in array.channels]
            if any(step is None for step in steps):
                raise InputError(f"{where}: integer samples are ADC codes: every channel of the array description needs "
                                 "electrical.volts_per_code")
            if code_bits is not None:
                self._shift = dtype.itemsize * 8 - code_bits
            width = code_bits if code_bits is not None else dtype.itemsize * 8
            bits = array.adc_bits
            stores_codes = width <= 16 and array.volts_per_code is not None and (bits is None or bits <= 16)
            self._scale = None if stores_codes else np.array(steps, dtype=float)[np.newaxis, :, np.newaxis]
            volts_per_code = array.volts_per_code if stores_codes else None
            adc_bits = bits if stores_codes else None
        elif dtype.kind == "f":
            stores_codes = False
            volts_per_code = adc_bits = None
            self._scale = np.full((1, 3, 1), settings.volts_per_unit)
        else:
            raise InputError(f"{where}: samples of dtype {dtype} are not supported (signed integer ADC codes or float "
                             "volts)")
        self.header = RecordingHeader(
            sample_rate_hz=array.sample_rate_hz, n_samples=self.layout.samples_per_ping, t0_s=settings.t0_s,
            channel_positions_m=array.positions_m, channel_names=array.names, template=settings.template,
            sound_speed_m_s=settings.sound_speed_m_s, temperature_c=settings.temperature_c,
            volts_per_code=volts_per_code, adc_bits=adc_bits, created_by=created_by, source=where, array=array,
            stores_codes=stores_codes)

    def close(self) -> None:
        """Release the file."""
        if self._close is not None:
            self._close()
            self._close = None

    def read_stored(self, start: int, stop: int) -> tuple[NDArray[Any], None, None]:
        """Pings ``start`` to ``stop`` as int16 codes or float64 volts (no flags, no poses)."""
        try:
            block = self.layout.read(self._reader, start, stop)
        except InputError:
            raise
        except (OSError, ValueError, TypeError, RuntimeError, EOFError) as exc:
            raise RecordingError(f"{self.source}: cannot read pings {start}-{stop - 1}: "
                                 f"{str(exc).splitlines()[0] if str(exc) else type(exc).__name__}") from None
        if self._shift:
            block = block >> self._shift
        if self.header.stores_codes:
            return block.astype(np.int16), None, None
        return block * self._scale, None, None  # float64 volts
