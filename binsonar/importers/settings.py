"""The ``[import]`` table of an array description file: how to read a foreign file's samples.

An array description (``binsonar.array_description``) says what the channels are; a file from
a DAQ or a lab script also needs what the array cannot say: when its first sample was taken,
how its samples map to pings and volts, and the matched filter's template. Keys (all optional)::

    [import]
    t0_s = 0.0                 # time of each ping's first sample after the transmit trigger (s)
    samples_per_ping = 250000  # split a continuous stream (WAV, CSV, 2-D arrays) into pings
    volts_per_unit = 1.0       # float samples are multiplied by this to give volts
    samples = "volts"          # CSV only: "volts" (floats) or "codes" (integers x volts_per_code)
    variable = "waveforms"     # the array to read in a .npz or .mat holding several
    template = "pulse.npy"     # 1-D template (.npy), relative to the description file
    template_sample_rate_hz = 20e6   # default: the array's sample rate
    template_t0_s = -1.0e-5    # time of the template's first sample relative to its reference instant
    template_kind = "transmitted-pulse"
    sound_speed_m_s = 1482.4
    temperature_c = 20.0

Integer samples (WAV PCM, integer arrays) are ADC codes: volts = code x the channel's
``electrical.volts_per_code``, which every channel then needs.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Mapping

import numpy as np

from binsonar.array_description import ArrayDescription
from binsonar.errors import InputError, short_repr
from binsonar.recording.model import Template

IMPORT_KEYS: tuple[str, ...] = (
    "t0_s", "samples_per_ping", "volts_per_unit", "samples", "variable", "template", "template_sample_rate_hz",
    "template_t0_s", "template_kind", "sound_speed_m_s", "temperature_c",
)
TEMPLATE_MAX_BYTES = 2**26
"""Largest template file (.npy) read (bytes)."""


@dataclass(frozen=True)
class ImportSettings:
    """The ``[import]`` table, checked (see the module notes for each key)."""

    t0_s: float = 0.0
    samples_per_ping: int | None = None
    volts_per_unit: float = 1.0
    samples: str = "volts"
    variable: str | None = None
    template: Template | None = None
    sound_speed_m_s: float | None = None
    temperature_c: float | None = None


@dataclass(frozen=True)
class ImportDescription:
    """An array description file read for an import: the array and the ``[import]`` settings.

    Attributes
    ----------
    array : ArrayDescription
    settings : ImportSettings
    path : str
        The description file.
    """

    array: ArrayDescription
    settings: ImportSettings
    path: str


def _number(table: Mapping[str, Any], key: str, where: str, default: Any) -> Any:
    if key not in table:
        return default
    value = table[key]
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise InputError(f"{where}: [import] {key} must be a finite number, got {short_repr(value)}")
    return value


def read_import_description(path: Any) -> ImportDescription:
    """Read an array description file and its ``[import]`` table.

    Raises
    ------
    InputError
        Unreadable file, invalid array description or import key (naming the file, key, value).
    """
    from binsonar.files import as_path, read_toml

    p = as_path(path, "--array")
    data = read_toml(p, "array description")
    where = str(p)
    array = ArrayDescription.from_mapping(data, where)
    table = data.get("import", {})
    if not isinstance(table, Mapping):
        raise InputError(f"{where}: [import] must be a table")
    unknown = sorted(set(table) - set(IMPORT_KEYS))
    if unknown:
        raise InputError(f"{where}: [import] unknown key(s) {', '.join(map(repr, unknown))} (known: "
                         f"{', '.join(IMPORT_KEYS)})")
    per_ping = table.get("samples_per_ping")
    if per_ping is not None and (isinstance(per_ping, bool) or not isinstance(per_ping, int) or per_ping < 2):
        raise InputError(f"{where}: [import] samples_per_ping must be an integer >= 2, got {short_repr(per_ping)}")
    scale = _number(table, "volts_per_unit", where, 1.0)
    if not 0.0 < scale <= 1e6:
        raise InputError(f"{where}: [import] volts_per_unit must be in (0, 1e6], got {short_repr(scale)}")
    samples = table.get("samples", "volts")
    if samples not in ("volts", "codes"):
        raise InputError(f"{where}: [import] samples must be 'volts' or 'codes', got {short_repr(samples)}")
    variable = table.get("variable")
    if variable is not None and (not isinstance(variable, str) or not 0 < len(variable) <= 256):
        raise InputError(f"{where}: [import] variable must be a name, got {short_repr(variable)}")
    try:
        settings = ImportSettings(
            t0_s=float(_number(table, "t0_s", where, 0.0)),
            samples_per_ping=per_ping,
            volts_per_unit=float(scale),
            samples=samples,
            variable=variable,
            template=_template(table, p, array, where),
            sound_speed_m_s=_number(table, "sound_speed_m_s", where, None),
            temperature_c=_number(table, "temperature_c", where, None),
        )
    except InputError as exc:
        message = str(exc)
        raise InputError(message if message.startswith(where) else f"{where}: [import] {message}") from None
    return ImportDescription(array, settings, where)


def _template(table: Mapping[str, Any], description: Path, array: ArrayDescription, where: str) -> Template | None:
    name = table.get("template")
    if name is None:
        for key in ("template_sample_rate_hz", "template_t0_s", "template_kind"):
            if key in table:
                raise InputError(f"{where}: [import] {key} is given without a template")
        return None
    if not isinstance(name, str) or not name:
        raise InputError(f"{where}: [import] template must be a file name (.npy), got {short_repr(name)}")
    path = Path(name) if Path(name).is_absolute() else description.parent / name
    samples = load_npy_vector(path, "template")
    kind = table.get("template_kind", "transmitted-pulse")
    if not isinstance(kind, str):
        raise InputError(f"{where}: [import] template_kind must be text, got {short_repr(kind)}")
    return Template(samples, _number(table, "template_sample_rate_hz", where, array.sample_rate_hz),
                    _number(table, "template_t0_s", where, 0.0), kind)


def load_npy_vector(path: Any, what: str) -> np.ndarray:
    """A 1-D numeric array from a .npy file (no pickles; at most ``TEMPLATE_MAX_BYTES``)."""
    import io

    from binsonar.files import read_input_bytes

    raw = read_input_bytes(path, what, max_bytes=TEMPLATE_MAX_BYTES)
    try:
        array = np.load(io.BytesIO(raw), allow_pickle=False)
    except (OSError, ValueError, EOFError) as exc:
        raise InputError(f"{path}: cannot read the {what} (.npy): {str(exc).splitlines()[0] if str(exc) else exc!r}"
                         ) from None
    if not isinstance(array, np.ndarray) or array.ndim != 1 or array.dtype.kind not in "iuf":
        raise InputError(f"{path}: the {what} must be a 1-D array of numbers, got "
                         f"{getattr(array, 'shape', '?')} {getattr(array, 'dtype', type(array).__name__)}")
    return array
