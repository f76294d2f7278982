"""WAV files from a DAQ: three channels (left, centre, right), 16/24/32-bit integer or float
samples, read frame range by frame range with soundfile (libsndfile).

Integer samples are ADC codes (16-bit ones kept as int16 codes, 24- and 32-bit ones converted to
volts with each channel's ``volts_per_code``); float samples are volts times ``volts_per_unit``
(a WAV's float full scale is 1.0). The file's sample rate must be the array's.
"""

from __future__ import annotations

from types import MappingProxyType
from typing import Any, Mapping

import numpy as np

from binsonar.errors import InputError
from binsonar.files import check_input_file, open_input_file
from binsonar.importers.array_source import ArraySource
from binsonar.importers.settings import ImportDescription

CODE_BITS: Mapping[str, int] = MappingProxyType({"PCM_S8": 8, "PCM_U8": 8, "PCM_16": 16, "PCM_24": 24, "PCM_32": 32})
"""Integer WAV subtypes and the width of their codes."""
FLOAT_SUBTYPES = ("FLOAT", "DOUBLE")
CONTAINERS = ("WAV", "WAVEX", "RF64", "W64")


def _check_riff_size(path: Any, where: str) -> None:
    """Refuse a RIFF file shorter than its header says (libsndfile reads what is there, silently)."""
    with open_input_file(path, "WAV file") as handle:
        head = handle.read(12)
        size = handle.seek(0, 2)
    if len(head) == 12 and head[:4] == b"RIFF" and head[8:12] in (b"WAVE",):
        declared = int.from_bytes(head[4:8], "little")
        if declared != 0xFFFFFFFF and declared + 8 > size:
            raise InputError(f"{where}: truncated: the RIFF header declares {declared + 8} bytes, the file holds {size}")


def open_wav(path: Any, description: ImportDescription) -> ArraySource:
    """A WAV file as a ``PingSource`` (see the module notes).

    Raises
    ------
    InputError
        Not a readable WAV file, not three channels, another sample rate or an unsupported
        sample format.
    """
    import soundfile

    p = check_input_file(path, "WAV file")
    where = str(p)
    _check_riff_size(p, where)
    try:
        handle = soundfile.SoundFile(str(p), "r")
    except (soundfile.LibsndfileError, RuntimeError, OSError, ValueError, TypeError) as exc:
        raise InputError(f"{where}: not a readable WAV file: {str(exc).splitlines()[0] if str(exc) else exc!r}"
                         ) from None
    try:
        if handle.format not in CONTAINERS:
            raise InputError(f"{where}: a {handle.format} sound file, not WAV")
        if handle.channels != 3:
            raise InputError(f"{where}: {handle.channels} channel(s); a recording has 3 (left, centre, right)")
        rate = float(handle.samplerate)
        if abs(rate - description.array.sample_rate_hz) > 1e-9 * rate:
            raise InputError(f"{where}: sampled at {rate:g} Hz, but the array description ({description.path}) says "
                             f"{description.array.sample_rate_hz:g} Hz")
        subtype = handle.subtype
        if subtype in CODE_BITS:
            dtype, bits = np.dtype(np.int32), CODE_BITS[subtype]
        elif subtype in FLOAT_SUBTYPES:
            dtype, bits = np.dtype(np.float64), None
        else:
            raise InputError(f"{where}: WAV sample format {subtype} is not supported (PCM 8/16/24/32-bit or float)")
        frames = int(handle.frames)

        def read(key: tuple[slice, ...]) -> np.ndarray:
            rows = key[0]
            handle.seek(rows.start or 0)
            count = (rows.stop if rows.stop is not None else frames) - (rows.start or 0)
            block = handle.read(count, dtype=dtype.name, always_2d=True)
            if block.shape[0] != count:
                raise InputError(f"{where}: the file ends early ({block.shape[0]} of {count} frames read)")
            return block

        return ArraySource(read, (frames, 3), dtype, description.array, description.settings, where,
                           f"binsonar import (WAV {subtype})", code_bits=bits, close=handle.close)
    except BaseException:
        handle.close()
        raise
