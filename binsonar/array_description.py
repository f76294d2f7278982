"""The sonar array's description: what each recorded channel is, where it points and how it hears.

A recording's waveforms are only half the story: localisation needs where each transducer is,
which one transmits, and (to undo the beam's filtering of off-axis echoes) its directivity;
converting codes to volts needs the electrical chain. :class:`ArrayDescription` holds all of it,
frozen, for the three channels (left, centre, right) of one head:

- each channel's ``name``, ``role`` ("transmit", "receive" or "both"), ``position_m`` and
  ``axis`` (unit acoustic axis) in the head frame (``conventions.md``: origin at the
  transmitter's face, y forward, x toward the right receiver, z up);
- its directivity: a baffled circular piston of given diameter (:class:`PistonDirectivity`,
  2 J1(x)/x with x = k a sin(theta), ``physics.md`` section 2), a measured beam table
  (:class:`BeamTable`: one-way pressure gain over frequency and off-axis angle, interpolated
  bilinearly), or None (not described);
- its electrical chain (:class:`ElectricalChain`): receiver gain, receive sensitivity, volts per
  ADC code and ADC bits, each optional;
- the sample rate of the digitiser.

The same description is a TOML file (``ArrayDescription.from_toml`` / ``to_toml``, documented
in the README's file-format section) for importing recordings from other formats, and the
``/array`` group of every recording (``binsonar.recording``). Recordings written before the
group existed get ``ArrayDescription.default(...)`` from their own fields (positions, names,
sample rate, ADC scale; no directivity).

For the localisers: ``geometry()`` is the :class:`binsonar.localization.array_geometry.ArrayGeometry`
(transmitter and receivers), ``transducers()`` the beams as
:class:`binsonar.localization.beam_model.PistonTransducers` when every channel is a piston, or a
:class:`BeamTableTransducers` (the same attributes, plus ``directivity``) when one has a measured
table; ``directivity(channel, angle, frequency, c)`` evaluates any channel's beam.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType
from typing import TYPE_CHECKING, Any, Mapping, Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from binsonar.errors import InputError, InputTypeError, checked_number, short_repr

if TYPE_CHECKING:
    from binsonar.localization.array_geometry import ArrayGeometry
    from binsonar.localization.beam_model import PistonTransducers

DESCRIPTION_VERSION = "1.0"
"""Version of the array description's layout (TOML file and ``/array`` group)."""
CHANNEL_NAMES: tuple[str, str, str] = ("left", "centre", "right")
ROLES: tuple[str, str, str] = ("transmit", "receive", "both")
BORESIGHT: tuple[float, float, float] = (0.0, 1.0, 0.0)
SAMPLE_RATE_RANGE_HZ: tuple[float, float] = (1e3, 1e10)
"""Sample rates accepted (Hz): any sonar digitiser, from a kHz to 10 GHz. Outside it the
numbers are a damaged file, not a recording (1 Hz or 1e300 Hz break every time axis)."""
POSITION_LIMIT_M = 100.0
"""Largest |coordinate| of a transducer in the head frame (m): a head, not a towed array."""
DIAMETER_RANGE_M: tuple[float, float] = (1e-5, 10.0)
"""Piston diameters accepted (m)."""
VOLTS_PER_CODE_RANGE: tuple[float, float] = (1e-15, 1e3)
"""ADC steps accepted (V per code): a 32-bit femtovolt ADC to a 2-bit kilovolt one."""
ADC_BITS_RANGE: tuple[int, int] = (2, 32)
GAIN_DB_LIMIT = 400.0
"""Largest |gain| or |sensitivity| in dB (a factor of 1e20)."""
BEAM_TABLE_MAX_VALUES = 2_000_000
"""Largest beam table (frequencies x angles)."""
TOML_KEYS: Mapping[str, tuple[str, ...]] = MappingProxyType({
    "top": ("version", "sample_rate_hz", "channels", "import"),
    "channel": ("name", "role", "position_m", "axis", "directivity", "electrical"),
    "piston": ("kind", "diameter_m"),
    "table": ("kind", "frequencies_hz", "angles_deg", "gain_db", "gain"),
    "electrical": ("gain_db", "receive_sensitivity_db", "volts_per_code", "adc_bits"),
})


class ArrayDescriptionError(InputError):
    """An array description that cannot be used; the message names the source, field and value."""


def _vector(value: Any, where: str, limit: float) -> tuple[float, float, float]:
    """Three finite numbers, each |v| <= limit."""
    try:
        array = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise ArrayDescriptionError(f"{where} must be 3 numbers, got {short_repr(value)}") from None
    if array.shape != (3,) or not np.all(np.isfinite(array)):
        raise ArrayDescriptionError(f"{where} must be 3 finite numbers, got {short_repr(value)}")
    if np.any(np.abs(array) > limit):
        raise ArrayDescriptionError(f"{where} must be within +/-{limit:g}, got {short_repr(value)}")
    return float(array[0]), float(array[1]), float(array[2])


def _numeric_array(value: Any, where: str, ndim: int) -> NDArray[np.float64]:
    try:
        array = np.array(value, dtype=float)
    except (TypeError, ValueError):
        raise ArrayDescriptionError(f"{where} must be a {ndim}-D array of numbers") from None
    if array.ndim != ndim:
        raise ArrayDescriptionError(f"{where} must be a {ndim}-D array of numbers, got shape {array.shape}")
    if not np.all(np.isfinite(array)):
        raise ArrayDescriptionError(f"{where} must hold finite numbers")
    return array


# --------------------------------------------------------------------------------- directivities
@dataclass(frozen=True)
class PistonDirectivity:
    """A baffled circular piston: one-way pressure directivity 2 J1(x) / x, x = (2 pi f / c) a sin(theta).

    Attributes
    ----------
    diameter_m : float
        Active diameter 2a (m); the Panametrics V318's 19 mm.
    """

    diameter_m: float

    def __post_init__(self) -> None:
        object.__setattr__(self, "diameter_m", checked_number(
            self.diameter_m, "directivity.diameter_m", error=ArrayDescriptionError, low=DIAMETER_RANGE_M[0],
            high=DIAMETER_RANGE_M[1]))

    kind = "piston"

    @property
    def radius_m(self) -> float:
        """Piston radius a (m)."""
        return 0.5 * self.diameter_m

    def response(self, angle_rad: ArrayLike, frequency_hz: ArrayLike, sound_speed_m_s: float) -> NDArray[np.float64]:
        """Signed one-way directivity at off-axis angles (rad) and frequencies (Hz), broadcast;
        0 behind the baffle (``beam_model.piston_directivity``, the one implementation)."""
        from binsonar.localization.beam_model import piston_directivity

        return piston_directivity(angle_rad, frequency_hz, self.radius_m, sound_speed_m_s)


@dataclass(frozen=True, eq=False)
class BeamTable:
    """A measured beam: one-way pressure gain over frequency and off-axis angle.

    The beam is taken axially symmetric about the channel's axis. Values between the grid
    points are interpolated bilinearly (in frequency and angle, on the linear gain); outside the
    grid the edge values hold (below the lowest frequency the lowest row, past the last angle
    the last column). Each frequency's row is normalised to its on-axis value (the frequency
    response belongs to the electrical chain and the template, not the beam).

    Attributes
    ----------
    frequencies_hz : ndarray, shape (k,)
        Strictly increasing frequencies (Hz, >= 0).
    angles_deg : ndarray, shape (m,)
        Strictly increasing off-axis angles (deg), from 0 to at most 180.
    gain : ndarray, shape (k, m)
        Linear pressure gain (signed: a measured phase flip past a null may be kept), 1 at 0 deg.
    """

    frequencies_hz: NDArray[np.float64] = field(repr=False)
    angles_deg: NDArray[np.float64] = field(repr=False)
    gain: NDArray[np.float64] = field(repr=False)

    kind = "table"

    def __post_init__(self) -> None:
        where = "directivity"
        f = _numeric_array(self.frequencies_hz, f"{where}.frequencies_hz", 1)
        a = _numeric_array(self.angles_deg, f"{where}.angles_deg", 1)
        g = _numeric_array(self.gain, f"{where}.gain", 2)
        if f.size < 1 or a.size < 2:
            raise ArrayDescriptionError(f"{where}: a beam table needs >= 1 frequency and >= 2 angles, got "
                                        f"{f.size} and {a.size}")
        if f.size * a.size > BEAM_TABLE_MAX_VALUES:
            raise ArrayDescriptionError(f"{where}: a beam table of {f.size} x {a.size} values is larger than the "
                                        f"{BEAM_TABLE_MAX_VALUES} allowed")
        if np.any(np.diff(f) <= 0) or f[0] < 0:
            raise ArrayDescriptionError(f"{where}.frequencies_hz must be >= 0 and strictly increasing")
        if np.any(np.diff(a) <= 0) or a[0] != 0.0 or a[-1] > 180.0:
            raise ArrayDescriptionError(f"{where}.angles_deg must start at 0, increase strictly and end at or "
                                        f"before 180, got [{a[0]:g} .. {a[-1]:g}]")
        if g.shape != (f.size, a.size):
            raise ArrayDescriptionError(f"{where}: gain must have one row per frequency and one column per angle, "
                                        f"({f.size}, {a.size}), got {g.shape}")
        on_axis = g[:, 0]
        if np.any(on_axis <= 0.0):
            raise ArrayDescriptionError(f"{where}: the on-axis gain (angle 0) must be > 0 at every frequency")
        g = g / on_axis[:, np.newaxis]
        if np.any(np.abs(g) > 1e3):
            raise ArrayDescriptionError(f"{where}: an off-axis gain is more than 60 dB above the on-axis one")
        for array in (f, a, g):
            array.setflags(write=False)
        object.__setattr__(self, "frequencies_hz", f)
        object.__setattr__(self, "angles_deg", a)
        object.__setattr__(self, "gain", g)

    @classmethod
    def from_db(cls, frequencies_hz: ArrayLike, angles_deg: ArrayLike, gain_db: ArrayLike) -> "BeamTable":
        """A table from magnitudes in dB (``20 log10 |gain|``), shape (k, m)."""
        db = _numeric_array(gain_db, "directivity.gain_db", 2)
        if np.any(np.abs(db) > GAIN_DB_LIMIT):
            raise ArrayDescriptionError(f"directivity.gain_db values must be within +/-{GAIN_DB_LIMIT:g} dB")
        return cls(frequencies_hz, angles_deg, 10.0 ** (db / 20.0))

    def response(self, angle_rad: ArrayLike, frequency_hz: ArrayLike,
                 sound_speed_m_s: float | None = None) -> NDArray[np.float64]:
        """The interpolated gain at off-axis angles (rad; the sign is ignored: axial symmetry)
        and frequencies (Hz), broadcast together (``sound_speed_m_s`` is not needed: a measured
        table is already in angle and frequency; it is accepted for the piston's signature)."""
        angle = np.abs(np.degrees(np.asarray(angle_rad, dtype=float)))
        frequency = np.asarray(frequency_hz, dtype=float)
        angle, frequency = np.broadcast_arrays(angle, frequency)
        fi, fw = _bracket(self.frequencies_hz, frequency)
        ai, aw = _bracket(self.angles_deg, angle)
        g = self.gain
        low = g[fi, ai] * (1.0 - aw) + g[fi, ai + 1] * aw if g.shape[1] > 1 else g[fi, ai]
        if g.shape[0] == 1:
            return low
        high = g[fi + 1, ai] * (1.0 - aw) + g[fi + 1, ai + 1] * aw
        return low * (1.0 - fw) + high * fw


def _bracket(grid: NDArray[np.float64], values: NDArray[np.float64]) -> tuple[NDArray[np.intp], NDArray[np.float64]]:
    """Index of the grid cell holding each value and the fractional position in it; values
    outside the grid are held at its edges. A one-point grid gives index 0 and weight 0."""
    if grid.size == 1:
        return np.zeros(values.shape, dtype=np.intp), np.zeros(values.shape)
    clipped = np.clip(values, grid[0], grid[-1])
    index = np.clip(np.searchsorted(grid, clipped, side="right") - 1, 0, grid.size - 2)
    weight = (clipped - grid[index]) / (grid[index + 1] - grid[index])
    return index, weight


Directivity = PistonDirectivity | BeamTable


def directivity_gain(directivity: Directivity, angle_rad: ArrayLike, frequency_hz: ArrayLike,
                     sound_speed_m_s: float) -> NDArray[np.float64]:
    """One-way pressure directivity of a piston or a beam table (the sound speed matters for the piston)."""
    return directivity.response(angle_rad, frequency_hz, sound_speed_m_s)


# ----------------------------------------------------------------------------------- channels
@dataclass(frozen=True)
class ElectricalChain:
    """A channel's receive electronics; every field optional (None: not known).

    Attributes
    ----------
    gain_db : float or None
        Net receiver gain from the transducer's terminals to the ADC input (dB).
    receive_sensitivity_db : float or None
        Open-circuit receive sensitivity (dB re 1 V/uPa).
    volts_per_code : float or None
        ADC step (V per code): volts = code x volts_per_code.
    adc_bits : int or None
        ADC resolution; codes reach +/-(2^(bits - 1) - 1) when the input clips.
    """

    gain_db: float | None = None
    receive_sensitivity_db: float | None = None
    volts_per_code: float | None = None
    adc_bits: int | None = None

    def __post_init__(self) -> None:
        for name in ("gain_db", "receive_sensitivity_db"):
            value = getattr(self, name)
            if value is not None:
                object.__setattr__(self, name, checked_number(
                    value, f"electrical.{name}", error=ArrayDescriptionError, low=-GAIN_DB_LIMIT, high=GAIN_DB_LIMIT))
        if self.volts_per_code is not None:
            object.__setattr__(self, "volts_per_code", checked_number(
                self.volts_per_code, "electrical.volts_per_code", error=ArrayDescriptionError,
                low=VOLTS_PER_CODE_RANGE[0], high=VOLTS_PER_CODE_RANGE[1]))
        if self.adc_bits is not None:
            bits = self.adc_bits
            if isinstance(bits, bool) or not isinstance(bits, (int, np.integer)) or not (
                    ADC_BITS_RANGE[0] <= bits <= ADC_BITS_RANGE[1]):
                raise ArrayDescriptionError(f"electrical.adc_bits must be an integer in [{ADC_BITS_RANGE[0]}, "
                                            f"{ADC_BITS_RANGE[1]}], got {short_repr(bits)}")
            object.__setattr__(self, "adc_bits", int(bits))


@dataclass(frozen=True)
class ChannelDescription:
    """One recorded channel of the head.

    Attributes
    ----------
    name : str
        "left", "centre" or "right" (the channel order of every recording).
    role : {"transmit", "receive", "both"}
    position_m : tuple of 3 float
        Centre of the transducer's face in the head frame (m).
    axis : tuple of 3 float
        Unit acoustic axis in the head frame (normalised on construction); default the boresight.
    directivity : PistonDirectivity, BeamTable or None
        None: not described (the localisers then ignore the beam).
    electrical : ElectricalChain
    """

    name: str
    role: str
    position_m: tuple[float, float, float]
    axis: tuple[float, float, float] = BORESIGHT
    directivity: Directivity | None = None
    electrical: ElectricalChain = field(default_factory=ElectricalChain)

    def __post_init__(self) -> None:
        if not isinstance(self.name, str) or not self.name or len(self.name) > 64:
            raise ArrayDescriptionError(f"channel name must be a non-empty string of <= 64 characters, got "
                                        f"{short_repr(self.name)}")
        where = f"channel {self.name!r}"
        if self.role not in ROLES:
            raise ArrayDescriptionError(f"{where}: role must be one of {', '.join(ROLES)}, got {short_repr(self.role)}")
        object.__setattr__(self, "position_m", _vector(self.position_m, f"{where}: position_m", POSITION_LIMIT_M))
        axis = np.array(_vector(self.axis, f"{where}: axis", 1e6))
        norm = float(np.linalg.norm(axis))
        if not norm > 1e-9:
            raise ArrayDescriptionError(f"{where}: axis must be a non-zero vector, got {short_repr(self.axis)}")
        object.__setattr__(self, "axis", tuple(float(v) for v in axis / norm))
        if self.directivity is not None and not isinstance(self.directivity, (PistonDirectivity, BeamTable)):
            raise InputTypeError(f"{where}: directivity must be a PistonDirectivity, a BeamTable or None, got "
                                 f"{type(self.directivity).__name__}")
        if not isinstance(self.electrical, ElectricalChain):
            raise InputTypeError(f"{where}: electrical must be an ElectricalChain, got "
                                 f"{type(self.electrical).__name__}")

    @property
    def transmits(self) -> bool:
        """The channel's transducer transmits."""
        return self.role in ("transmit", "both")

    @property
    def receives(self) -> bool:
        """The channel records echoes."""
        return self.role in ("receive", "both")


# --------------------------------------------------------------------------------- transducers
@dataclass(frozen=True, eq=False)
class BeamTableTransducers:
    """The head's three beams when one is a measured table: the attributes of
    ``beam_model.PistonTransducers`` that do not assume a piston, and ``directivity``.

    Attributes
    ----------
    directivities : tuple of 3 (PistonDirectivity or BeamTable)
        Left, centre, right.
    axes_head : tuple of three 3-tuples
        Unit acoustic axes in the head frame.
    transmitter_channel : int
    """

    directivities: tuple[Directivity, Directivity, Directivity]
    axes_head: tuple[tuple[float, float, float], ...]
    transmitter_channel: int = 1

    @property
    def axes(self) -> NDArray[np.float64]:
        """Unit axes (3, 3), rows left, centre, right (head frame)."""
        return np.asarray(self.axes_head, dtype=float)

    def directivity(self, channel: int, angle_rad: ArrayLike, frequency_hz: ArrayLike,
                    sound_speed_m_s: float) -> NDArray[np.float64]:
        """One-way pressure directivity of ``channel``'s beam, broadcast over angles (rad) and
        frequencies (Hz)."""
        return directivity_gain(self.directivities[channel], angle_rad, frequency_hz, sound_speed_m_s)


# ----------------------------------------------------------------------------------- the array
@dataclass(frozen=True)
class ArrayDescription:
    """The head's three channels and its digitiser (see the module notes).

    Attributes
    ----------
    channels : tuple of 3 ChannelDescription
        Left, centre, right (in that order: the recording's channel order).
    sample_rate_hz : float
        The digitiser's sample rate (Hz).
    """

    channels: tuple[ChannelDescription, ...]
    sample_rate_hz: float

    def __post_init__(self) -> None:
        channels = tuple(self.channels) if isinstance(self.channels, (tuple, list)) else self.channels
        if not isinstance(channels, tuple) or len(channels) != 3 or not all(
                isinstance(c, ChannelDescription) for c in channels):
            raise ArrayDescriptionError(f"array: channels must be 3 ChannelDescription (left, centre, right), got "
                                        f"{short_repr(self.channels)}")
        object.__setattr__(self, "channels", channels)
        names = [c.name for c in channels]
        if len(set(names)) != 3:
            raise ArrayDescriptionError(f"array: channel names must differ, got {names}")
        transmitters = [i for i, c in enumerate(channels) if c.transmits]
        if len(transmitters) != 1:
            raise ArrayDescriptionError(f"array: exactly one channel must transmit (role 'transmit' or 'both'), got "
                                        f"{len(transmitters)}")
        low, high = SAMPLE_RATE_RANGE_HZ
        object.__setattr__(self, "sample_rate_hz", checked_number(
            self.sample_rate_hz, "array: sample_rate_hz", error=ArrayDescriptionError, low=low, high=high))
        positions = np.array([c.position_m for c in channels])
        for i in range(3):
            for j in range(i + 1, 3):
                if np.linalg.norm(positions[i] - positions[j]) <= 1e-9:
                    raise ArrayDescriptionError(f"array: channels {names[i]!r} and {names[j]!r} are at the same "
                                                f"position {list(positions[i])}")

    # ---------------------------------------------------------------- views
    @property
    def names(self) -> tuple[str, ...]:
        """Channel names, left, centre, right."""
        return tuple(c.name for c in self.channels)

    @property
    def positions_m(self) -> NDArray[np.float64]:
        """Face centres (3, 3) in the head frame (m), rows left, centre, right."""
        return np.array([c.position_m for c in self.channels], dtype=float)

    @property
    def axes(self) -> NDArray[np.float64]:
        """Unit acoustic axes (3, 3) in the head frame."""
        return np.array([c.axis for c in self.channels], dtype=float)

    @property
    def transmitter_channel(self) -> int:
        """Index of the transmitting channel."""
        return next(i for i, c in enumerate(self.channels) if c.transmits)

    @property
    def describes_beams(self) -> bool:
        """Every channel's directivity is described (a piston or a table)."""
        return all(c.directivity is not None for c in self.channels)

    @property
    def volts_per_code(self) -> float | None:
        """The ADC step shared by every channel (V per code); None when unknown or when the
        channels differ."""
        steps = {c.electrical.volts_per_code for c in self.channels}
        return steps.pop() if len(steps) == 1 else None

    @property
    def adc_bits(self) -> int | None:
        """The ADC resolution shared by every channel; None when unknown or when they differ."""
        bits = {c.electrical.adc_bits for c in self.channels}
        return bits.pop() if len(bits) == 1 else None

    # ---------------------------------------------------------- for localisers
    def geometry(self) -> "ArrayGeometry":
        """Transmitter and receivers for the localisers.

        Raises
        ------
        ArrayDescriptionError
            A channel that does not receive (the localisers need three receivers).
        """
        from binsonar.localization.array_geometry import ArrayGeometry

        deaf = [c.name for c in self.channels if not c.receives]
        if deaf:
            raise ArrayDescriptionError(f"array: localisation needs three receiving channels; {deaf} only transmit")
        try:
            return ArrayGeometry.from_channel_positions(self.positions_m, self.transmitter_channel)
        except ValueError as exc:
            raise ArrayDescriptionError(f"array: {exc}") from None

    def transducers(self) -> "PistonTransducers | BeamTableTransducers | None":
        """The beams: ``PistonTransducers`` when every channel is a piston, ``BeamTableTransducers``
        when one has a measured table, None when a directivity is not described."""
        if not self.describes_beams:
            return None
        axes = tuple(c.axis for c in self.channels)
        if all(isinstance(c.directivity, PistonDirectivity) for c in self.channels):
            from binsonar.localization.beam_model import PistonTransducers

            diameters = tuple(c.directivity.diameter_m for c in self.channels)  # type: ignore[union-attr]
            return PistonTransducers(diameters, axes, self.transmitter_channel)  # type: ignore[arg-type]
        return BeamTableTransducers(tuple(c.directivity for c in self.channels), axes,  # type: ignore[arg-type]
                                    self.transmitter_channel)

    def directivity(self, channel: int, angle_rad: ArrayLike, frequency_hz: ArrayLike,
                    sound_speed_m_s: float) -> NDArray[np.float64]:
        """One-way pressure directivity of ``channel``'s beam at off-axis angles (rad) and
        frequencies (Hz), broadcast.

        Raises
        ------
        ArrayDescriptionError
            The channel's directivity is not described.
        """
        described = self.channels[channel].directivity
        if described is None:
            raise ArrayDescriptionError(f"array: channel {self.channels[channel].name!r} has no directivity")
        return directivity_gain(described, angle_rad, frequency_hz, sound_speed_m_s)

    # ------------------------------------------------------------ constructors
    @classmethod
    def default(cls, channel_positions_m: ArrayLike, sample_rate_hz: float,
                channel_names: Sequence[str] = CHANNEL_NAMES, volts_per_code: float | None = None,
                adc_bits: int | None = None) -> "ArrayDescription":
        """What a recording without an ``/array`` group says about its array: the positions and
        names it stores, the centre channel transmitting and receiving, the sides receiving, every
        axis on the boresight, the ADC scale it stores; no directivity, no gains."""
        positions = np.asarray(channel_positions_m, dtype=float)
        if positions.shape != (3, 3):
            raise ArrayDescriptionError(f"array: channel positions must be (3, 3), got shape {positions.shape}")
        chain = ElectricalChain(volts_per_code=volts_per_code, adc_bits=adc_bits)
        roles = ("receive", "both", "receive")
        return cls(tuple(ChannelDescription(str(name), role, tuple(row), BORESIGHT, None, chain)  # type: ignore[arg-type]
                         for name, role, row in zip(channel_names, roles, positions)), float(sample_rate_hz))

    @classmethod
    def from_mapping(cls, data: Mapping[str, Any], where: str = "array description") -> "ArrayDescription":
        """From the TOML structure (the README's file-format section); unknown keys are refused.

        Raises
        ------
        ArrayDescriptionError
            A missing, unknown or invalid key, named with ``where``.
        """
        try:
            return _from_mapping(data, where)
        except ArrayDescriptionError as exc:
            message = str(exc)
            raise ArrayDescriptionError(message if message.startswith(where) else f"{where}: {message}") from None

    @classmethod
    def from_toml(cls, path: str | Path) -> "ArrayDescription":
        """Read a TOML array description (``binsonar.files.read_toml``: size and nesting limits).

        Raises
        ------
        InputError
            Unreadable or invalid file, naming it, the key and the value.
        """
        from binsonar.files import read_toml

        return cls.from_mapping(read_toml(path, "array description"), str(path))

    def to_mapping(self) -> dict[str, Any]:
        """The TOML structure (``from_mapping`` reads it back to an equal description)."""
        channels = []
        for c in self.channels:
            entry: dict[str, Any] = {"name": c.name, "role": c.role, "position_m": list(c.position_m),
                                     "axis": list(c.axis)}
            if isinstance(c.directivity, PistonDirectivity):
                entry["directivity"] = {"kind": "piston", "diameter_m": c.directivity.diameter_m}
            elif isinstance(c.directivity, BeamTable):
                entry["directivity"] = {"kind": "table", "frequencies_hz": c.directivity.frequencies_hz.tolist(),
                                        "angles_deg": c.directivity.angles_deg.tolist(),
                                        "gain": c.directivity.gain.tolist()}
            electrical = {k: getattr(c.electrical, k) for k in TOML_KEYS["electrical"]
                          if getattr(c.electrical, k) is not None}
            if electrical:
                entry["electrical"] = electrical
            channels.append(entry)
        return {"version": DESCRIPTION_VERSION, "sample_rate_hz": self.sample_rate_hz, "channels": channels}

    def to_toml(self) -> str:
        """The description as TOML text."""
        import tomli_w

        return tomli_w.dumps(self.to_mapping())

    def matches(self, other: "ArrayDescription") -> bool:
        """Same channels, roles, positions, axes, directivities, chains and sample rate (to 1e-12)."""
        if self.names != other.names or [c.role for c in self.channels] != [c.role for c in other.channels]:
            return False
        if not (np.allclose(self.positions_m, other.positions_m, rtol=0, atol=1e-12)
                and np.allclose(self.axes, other.axes, rtol=0, atol=1e-12)
                and math.isclose(self.sample_rate_hz, other.sample_rate_hz, rel_tol=1e-12)):
            return False
        for a, b in zip(self.channels, other.channels):
            if a.electrical != b.electrical or type(a.directivity) is not type(b.directivity):
                return False
            if isinstance(a.directivity, PistonDirectivity) and a.directivity != b.directivity:
                return False
            if isinstance(a.directivity, BeamTable) and not all(
                    np.array_equal(getattr(a.directivity, k), getattr(b.directivity, k))
                    for k in ("frequencies_hz", "angles_deg", "gain")):
                return False
        return True


def _check_keys(data: Any, allowed: tuple[str, ...], where: str) -> Mapping[str, Any]:
    if not isinstance(data, Mapping):
        raise ArrayDescriptionError(f"{where} must be a table, got {short_repr(data)}")
    unknown = sorted(set(data) - set(allowed))
    if unknown:
        raise ArrayDescriptionError(f"{where}: unknown key(s) {', '.join(map(repr, unknown))} (known: "
                                    f"{', '.join(allowed)})")
    return data


def _directivity_from(data: Any, where: str) -> Directivity | None:
    if data is None:
        return None
    if not isinstance(data, Mapping):
        raise ArrayDescriptionError(f"{where} must be a table, got {short_repr(data)}")
    kind = data.get("kind")
    if kind == "piston":
        _check_keys(data, TOML_KEYS["piston"], where)
        if "diameter_m" not in data:
            raise ArrayDescriptionError(f"{where}: a piston needs diameter_m")
        return PistonDirectivity(data["diameter_m"])
    if kind == "table":
        _check_keys(data, TOML_KEYS["table"], where)
        missing = [k for k in ("frequencies_hz", "angles_deg") if k not in data]
        if missing:
            raise ArrayDescriptionError(f"{where}: a beam table needs {', '.join(missing)}")
        if ("gain_db" in data) == ("gain" in data):
            raise ArrayDescriptionError(f"{where}: a beam table needs exactly one of gain_db and gain")
        if "gain_db" in data:
            return BeamTable.from_db(data["frequencies_hz"], data["angles_deg"], data["gain_db"])
        return BeamTable(data["frequencies_hz"], data["angles_deg"], data["gain"])
    raise ArrayDescriptionError(f"{where}.kind must be 'piston' or 'table', got {short_repr(kind)}")


def _from_mapping(data: Mapping[str, Any], where: str) -> ArrayDescription:
    top = _check_keys(data, TOML_KEYS["top"], where)
    version = top.get("version", DESCRIPTION_VERSION)
    if not isinstance(version, str) or version.split(".")[0] != DESCRIPTION_VERSION.split(".")[0]:
        raise ArrayDescriptionError(f"{where}: version {short_repr(version)} is not supported (expected 1.x)")
    if "sample_rate_hz" not in top:
        raise ArrayDescriptionError(f"{where}: missing sample_rate_hz")
    entries = top.get("channels")
    if not isinstance(entries, list) or len(entries) != 3:
        raise ArrayDescriptionError(f"{where}: needs exactly 3 [[channels]] (left, centre, right), got "
                                    f"{len(entries) if isinstance(entries, list) else short_repr(entries)}")
    channels = []
    for index, entry in enumerate(entries):
        label = f"channels[{index}]"
        entry = _check_keys(entry, TOML_KEYS["channel"], label)
        for key in ("name", "role", "position_m"):
            if key not in entry:
                raise ArrayDescriptionError(f"{label}: missing {key}")
        electrical = _check_keys(entry.get("electrical", {}), TOML_KEYS["electrical"], f"{label}.electrical")
        try:
            channels.append(ChannelDescription(
                name=entry["name"], role=entry["role"], position_m=entry["position_m"],
                axis=entry.get("axis", BORESIGHT),
                directivity=_directivity_from(entry.get("directivity"), f"{label}.directivity"),
                electrical=ElectricalChain(**electrical)))
        except ArrayDescriptionError as exc:
            raise ArrayDescriptionError(f"{label}: {exc}") from None
    return ArrayDescription(tuple(channels), top["sample_rate_hz"])


__all__ = (
    "ArrayDescription",
    "ArrayDescriptionError",
    "BeamTable",
    "BeamTableTransducers",
    "ChannelDescription",
    "DESCRIPTION_VERSION",
    "ElectricalChain",
    "PistonDirectivity",
    "directivity_gain",
)
