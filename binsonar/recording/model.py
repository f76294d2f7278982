"""A recording in memory: ``Recording`` (pings and what they need), ``Template`` and their checks.

A ``Recording`` holds the waveforms of one or many pings as volts, or as the int16 ADC codes
they were made from (``codes``, with ``volts_per_code``): then its volts are made only when
someone reads ``waveforms`` (once, then kept), so that detectors that work on codes never pay
for a float64 copy of the record. Everything a user or a file can get wrong is checked on
construction and reported as a one-line ``RecordingError`` naming the source, the field and the
value, with limits that say what a sonar recording can be (``RecordingLimits``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from binsonar.array_description import (
    ADC_BITS_RANGE,
    POSITION_LIMIT_M,
    SAMPLE_RATE_RANGE_HZ,
    VOLTS_PER_CODE_RANGE,
    ArrayDescription,
    ArrayDescriptionError,
)
from binsonar.errors import InputError, InputTypeError, checked_number, short_repr

FORMAT_VERSION = "1.1"
"""Version of the recording file's layout: 1.1 added the optional ``/array`` group (1.0 files
are read, their array described by ``ArrayDescription.default``)."""
CHANNEL_NAMES: tuple[str, str, str] = ("left", "centre", "right")
POSE_COLUMNS: tuple[str, ...] = ("x_m", "y_m", "z_m", "yaw_deg", "pitch_deg", "roll_deg")
SEED_SEPARATION_M = 0.065
"""Centre-to-side separation of the default head (``conventions.md``: d = 65 mm)."""
T0_LIMIT_S = 3600.0
"""Largest |t0_s| (s): the first sample is within an hour of the trigger."""
VOLTS_LIMIT = 1e6
"""Largest |sample| in volts: no digitiser reads a megavolt; larger values are damage that would
overflow the detectors' energy sums."""
POSE_POSITION_LIMIT_M = 1e7
POSE_ANGLE_LIMIT_DEG = 1e5
HEADER_FIELDS: tuple[str, ...] = ("sample_rate_hz", "t0_s", "channel_positions_m", "channel_names", "template",
                                  "sound_speed_m_s", "temperature_c", "volts_per_code", "adc_bits", "created_by",
                                  "source", "array")
"""``Recording``'s fields that describe the recording rather than its pings (``RecordingHeader``)."""
TEMPLATE_RESAMPLED_LIMIT = 2**22
"""Largest template, in samples at the recording's rate after resampling (a template longer
than the record is useless; this bound keeps a template at 1e3 Hz for a 1e10 Hz record from
being interpolated to billions of samples)."""


class RecordingError(InputError):
    """A recording file or array that cannot be used; the message names file, field and value."""


def finite_number(value: Any, where: str, name: str, *, low: float | None = None, high: float | None = None,
                  low_open: bool = False) -> float:
    """``value`` as a finite float within [low, high] (``low_open``: > low).

    Raises
    ------
    RecordingError
        Not a real number, not finite, or out of the range (naming ``where``, ``name``, value).
    """
    return checked_number(value, f"{where}: {name}", error=RecordingError, low=low, high=high, low_open=low_open)


def sample_rate(value: Any, where: str, name: str = "sample_rate_hz") -> float:
    """A sample rate within ``SAMPLE_RATE_RANGE_HZ`` (Hz)."""
    low, high = SAMPLE_RATE_RANGE_HZ
    return finite_number(value, where, name, low=low, high=high)


def adc_bits_value(value: Any, where: str, high: int = ADC_BITS_RANGE[1]) -> int:
    """An ADC resolution: an integer in [2, high]."""
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or not ADC_BITS_RANGE[0] <= value <= high:
        raise RecordingError(f"{where}: adc_bits must be an integer in [{ADC_BITS_RANGE[0]}, {high}], got "
                             f"{short_repr(value)}")
    return int(value)


def volts_per_code_value(value: Any, where: str) -> float:
    """An ADC step within ``VOLTS_PER_CODE_RANGE`` (V per code)."""
    return finite_number(value, where, "volts_per_code", low=VOLTS_PER_CODE_RANGE[0], high=VOLTS_PER_CODE_RANGE[1])


@dataclass(frozen=True, eq=False)
class Template:
    """A matched-filter template.

    Attributes
    ----------
    samples : ndarray, shape (n,)
        The template (any unit; only its shape matters).
    sample_rate_hz : float
    t0_s : float
        Time of ``samples[0]`` relative to the reference instant a TOF refers to (s).
    kind : str
        "transmitted-pulse", "calibration-echo" or "user".
    """

    samples: NDArray[np.float64] = field(repr=False)
    sample_rate_hz: float
    t0_s: float = 0.0
    kind: str = "transmitted-pulse"

    def __post_init__(self) -> None:
        try:
            samples = np.array(self.samples, dtype=float, copy=True)
        except (TypeError, ValueError):
            raise RecordingError(f"template: samples must be numbers, got {short_repr(self.samples)}") from None
        if samples.ndim != 1 or samples.size < 2:
            raise RecordingError(f"template: samples must be 1-D with >= 2 values, got shape {samples.shape}")
        if not np.all(np.isfinite(samples)):
            raise RecordingError("template: samples contain NaN or infinite values")
        if np.max(np.abs(samples)) > VOLTS_LIMIT:
            raise RecordingError(f"template: samples must be within +/-{VOLTS_LIMIT:g}")
        object.__setattr__(self, "sample_rate_hz", sample_rate(self.sample_rate_hz, "template"))
        object.__setattr__(self, "t0_s", finite_number(self.t0_s, "template", "t0_s", low=-T0_LIMIT_S,
                                                       high=T0_LIMIT_S))
        if not isinstance(self.kind, str) or len(self.kind) > 64:
            raise RecordingError(f"template: kind must be a short string, got {short_repr(self.kind)}")
        samples.setflags(write=False)
        object.__setattr__(self, "samples", samples)


@dataclass(frozen=True, eq=False, repr=False)
class RecordingHeader:
    """Everything about a recording but its pings: what ``Recording`` checks once per source, and
    what a file reader (``RecordingFile``) knows before it reads a ping.

    Attributes
    ----------
    sample_rate_hz : float
    n_samples : int
        Samples per channel of each ping.
    t0_s : float
    channel_positions_m : ndarray, shape (3, 3), or None
        None: those of ``array``, else the seed's head (d = 65 mm).
    channel_names : tuple of str
    template : Template or None
    sound_speed_m_s, temperature_c : float or None
    volts_per_code : float or None
    adc_bits : int or None
    created_by : str
    source : str
    array : ArrayDescription or None
        None: ``ArrayDescription.default`` of the other fields.
    stores_codes : bool
        The pings are int16 ADC codes (``adc_bits`` then at most 16).

    See ``Recording`` for the meaning and limits of each field.
    """

    sample_rate_hz: float
    n_samples: int
    t0_s: float = 0.0
    channel_positions_m: NDArray[np.float64] | None = None
    channel_names: tuple[str, ...] = CHANNEL_NAMES
    template: Template | None = None
    sound_speed_m_s: float | None = None
    temperature_c: float | None = None
    volts_per_code: float | None = None
    adc_bits: int | None = None
    created_by: str = ""
    source: str = ""
    array: ArrayDescription | None = None
    stores_codes: bool = False

    def __post_init__(self) -> None:
        if not isinstance(self.source, str):
            raise InputTypeError(f"recording: source must be a string, got {type(self.source).__name__}")
        where = self.where
        if self.sample_rate_hz is None:
            raise RecordingError(f"{where}: sample_rate_hz is required")
        object.__setattr__(self, "sample_rate_hz", sample_rate(self.sample_rate_hz, where))
        object.__setattr__(self, "t0_s", finite_number(self.t0_s, where, "t0_s", low=-T0_LIMIT_S, high=T0_LIMIT_S))
        if self.volts_per_code is not None:
            object.__setattr__(self, "volts_per_code", volts_per_code_value(self.volts_per_code, where))
        elif self.stores_codes:
            raise RecordingError(f"{where}: codes need volts_per_code > 0, got None")
        if self.adc_bits is not None:
            object.__setattr__(self, "adc_bits", adc_bits_value(self.adc_bits, where,
                                                                16 if self.stores_codes else ADC_BITS_RANGE[1]))
        self._check_names(where)
        self._set_positions(where)
        if self.sound_speed_m_s is not None:
            object.__setattr__(self, "sound_speed_m_s", finite_number(self.sound_speed_m_s, where, "sound_speed_m_s",
                                                                      low=1000.0, high=2000.0, low_open=True))
        if self.temperature_c is not None:
            object.__setattr__(self, "temperature_c", finite_number(self.temperature_c, where, "temperature_c",
                                                                    low=-5.0, high=100.0, low_open=True))
        if not isinstance(self.created_by, str):
            raise RecordingError(f"{where}: created_by must be a string, got {short_repr(self.created_by)}")
        if self.template is not None:
            self._check_template(where)
        self._set_array(where)

    @property
    def where(self) -> str:
        """The source, as messages name it."""
        return self.source or "recording"

    def _check_names(self, where: str) -> None:
        names = self.channel_names
        if isinstance(names, str) or not isinstance(names, (tuple, list)) or len(names) != 3 or not all(
                isinstance(n, str) and 0 < len(n) <= 64 for n in names):
            raise RecordingError(f"{where}: channel_names must name 3 channels (strings of 1-64 characters), got "
                                 f"{short_repr(names)}")
        object.__setattr__(self, "channel_names", tuple(names))

    def _set_positions(self, where: str) -> None:
        if self.channel_positions_m is None:
            if isinstance(self.array, ArrayDescription):
                positions = self.array.positions_m
            else:
                d = SEED_SEPARATION_M
                positions = np.array([[-d, 0.0, 0.0], [0.0, 0.0, 0.0], [d, 0.0, 0.0]])
        else:
            try:
                with np.errstate(invalid="ignore", over="ignore"):  # what does not convert is refused below
                    positions = np.array(self.channel_positions_m, dtype=float)
            except (TypeError, ValueError):
                raise RecordingError(f"{where}: channel_positions_m must be (3, 3) numbers, got "
                                     f"{short_repr(self.channel_positions_m)}") from None
        if positions.shape != (3, 3) or not np.all(np.isfinite(positions)):
            raise RecordingError(f"{where}: channel_positions_m must be (3, 3) finite, got shape {positions.shape}")
        if np.any(np.abs(positions) > POSITION_LIMIT_M):
            raise RecordingError(f"{where}: channel_positions_m must be within +/-{POSITION_LIMIT_M:g} m of the head")
        positions.setflags(write=False)
        object.__setattr__(self, "channel_positions_m", positions)

    def _check_template(self, where: str) -> None:
        template = self.template
        if not isinstance(template, Template):
            raise InputTypeError(f"{where}: template must be a Template or None, got {type(template).__name__}")
        resampled = template.samples.size * self.sample_rate_hz / template.sample_rate_hz
        if resampled > max(TEMPLATE_RESAMPLED_LIMIT, 2 * self.n_samples):
            raise RecordingError(
                f"{where}: template of {template.samples.size} samples at {template.sample_rate_hz:g} Hz would be "
                f"{resampled:.3g} samples at the recording's {self.sample_rate_hz:g} Hz (record: {self.n_samples})")

    def _set_array(self, where: str) -> None:
        array = self.array
        if array is None:
            try:
                array = ArrayDescription.default(self.channel_positions_m, self.sample_rate_hz,  # type: ignore[arg-type]
                                                 self.channel_names, self.volts_per_code, self.adc_bits)
            except ArrayDescriptionError as exc:
                raise RecordingError(f"{where}: {exc}") from None
            object.__setattr__(self, "array", array)
            return
        if not isinstance(array, ArrayDescription):
            raise InputTypeError(f"{where}: array must be an ArrayDescription or None, got {type(array).__name__}")
        if not math.isclose(array.sample_rate_hz, self.sample_rate_hz, rel_tol=1e-9):
            raise RecordingError(f"{where}: the array description's sample_rate_hz {array.sample_rate_hz!r} differs "
                                 f"from the recording's {self.sample_rate_hz!r}")
        if not np.allclose(array.positions_m, self.channel_positions_m, rtol=0.0, atol=1e-9):
            raise RecordingError(f"{where}: the array description's channel positions differ from "
                                 "channel_positions_m")
        if array.names != self.channel_names:
            raise RecordingError(f"{where}: the array description's channel names {list(array.names)} differ from "
                                 f"channel_names {list(self.channel_names)}")
        step = array.volts_per_code
        if self.stores_codes and step is not None and not math.isclose(step, self.volts_per_code, rel_tol=1e-9):
            raise RecordingError(f"{where}: the array description's volts_per_code {step!r} differs from the "
                                 f"codes' {self.volts_per_code!r}")

    def recording_fields(self) -> dict[str, Any]:
        """The ``Recording`` constructor's arguments this header supplies."""
        return {name: getattr(self, name) for name in HEADER_FIELDS}


class _Volts:
    """``Recording.waveforms``: the volts, made from the codes on first reading when the
    recording was built from codes alone (then kept). A data descriptor, so that the frozen
    dataclass's constructor and ``dataclasses.replace`` use it like a plain field
    (Python's "descriptor-typed fields"); it has no default (``__get__`` on the class raises)."""

    slot = "_waveforms"

    def __get__(self, instance: Any, owner: Any = None) -> Any:
        if instance is None:
            raise AttributeError("waveforms")  # no default value for the dataclass field
        stored = instance.__dict__.get(self.slot)
        if stored is None and instance.__dict__.get("codes") is not None:
            stored = instance.__dict__["codes"] * float(instance.volts_per_code)
            stored.setflags(write=False)
            instance.__dict__[self.slot] = stored
        return stored

    def __set__(self, instance: Any, value: Any) -> None:
        instance.__dict__[self.slot] = value


@dataclass(frozen=True, eq=False, repr=False)
class Recording:
    """One recording of one or many pings.

    Attributes
    ----------
    waveforms : ndarray, shape (n_pings, 3, n_samples), float64
        Volts, channels left, centre, right, finite and within +/-1e6 V. For a recording built
        from ``codes`` alone they are made (``codes * volts_per_code``) when first read, then
        kept. A read-only C-ordered float64 array is taken as it is (no copy).
    sample_rate_hz : float
        Within 1 kHz - 10 GHz.
    t0_s : float
        Time of the first sample after the transmit trigger (s), within an hour.
    channel_positions_m : ndarray, shape (3, 3)
        Channel positions in the head frame (m); default those of ``array``, else the seed's head
        (d = 65 mm).
    channel_names : tuple of str
    clipped : ndarray of bool, shape (n_pings, 3)
        Where the ADC clipped (all False when unknown).
    template : Template or None
    sound_speed_m_s, temperature_c : float or None
    pose : ndarray, shape (n_pings, 6), or None
        x_m, y_m, z_m, yaw_deg, pitch_deg, roll_deg per ping.
    volts_per_code : float or None
        Set when stored as int16 ADC codes.
    adc_bits : int or None
        2-32 (2-16 with codes).
    created_by : str
    source : str
        Path the recording was read from ("" for arrays).
    codes : ndarray of int16, shape (n_pings, 3, n_samples), or None
        The ADC codes the volts were made from (``waveforms`` = ``codes * volts_per_code``),
        kept when asked for (``read_recording(..., keep_codes=True)``): detectors that work on
        codes read them instead of the volts (a quarter of the bytes). Needs
        ``volts_per_code``; with codes, ``waveforms`` may be None (made from the codes when read).
    array : ArrayDescription or None
        The array's description (``binsonar.array_description``); None on construction gives
        ``ArrayDescription.default`` of the other fields, so it is never None afterwards. Its
        positions, names, sample rate and ADC step must agree with the recording's.
    """

    waveforms: NDArray[np.float64] | None = _Volts()  # type: ignore[assignment]
    sample_rate_hz: float
    t0_s: float = 0.0
    channel_positions_m: NDArray[np.float64] | None = field(default=None)
    channel_names: tuple[str, ...] = CHANNEL_NAMES
    clipped: NDArray[np.bool_] | None = field(default=None)
    template: Template | None = None
    sound_speed_m_s: float | None = None
    temperature_c: float | None = None
    pose: NDArray[np.float64] | None = field(default=None)
    volts_per_code: float | None = None
    adc_bits: int | None = None
    created_by: str = ""
    source: str = ""
    codes: NDArray[np.int16] | None = field(default=None)
    array: ArrayDescription | None = None

    def __post_init__(self) -> None:
        where = self.source if isinstance(self.source, str) and self.source else "recording"
        given = self.__dict__.get(_Volts.slot)
        if self.codes is not None:
            codes = as_codes(self.codes, self.volts_per_code, where)
            object.__setattr__(self, "codes", codes)
            shape = codes.shape
            if given is not None:
                volts = as_volts(given, where)
                if volts.shape != shape:
                    raise RecordingError(f"{where}: codes shape {shape} != waveforms shape {volts.shape}")
                if not np.array_equal(volts, codes * float(self.volts_per_code)):  # type: ignore[arg-type]
                    raise RecordingError(f"{where}: waveforms are not codes * volts_per_code "
                                         f"({self.volts_per_code!r})")
                object.__setattr__(self, "waveforms", volts)
        else:
            if given is None:
                raise RecordingError(f"{where}: waveforms (or codes with volts_per_code) are required")
            volts = as_volts(given, where)
            object.__setattr__(self, "waveforms", volts)
            shape = volts.shape
        header = RecordingHeader(
            sample_rate_hz=self.sample_rate_hz, n_samples=shape[2], t0_s=self.t0_s,
            channel_positions_m=self.channel_positions_m, channel_names=self.channel_names, template=self.template,
            sound_speed_m_s=self.sound_speed_m_s, temperature_c=self.temperature_c,
            volts_per_code=self.volts_per_code, adc_bits=self.adc_bits, created_by=self.created_by,
            source=self.source, array=self.array, stores_codes=self.codes is not None)
        for name, value in header.recording_fields().items():
            object.__setattr__(self, name, value)
        clipped = np.zeros(shape[:2], dtype=bool) if self.clipped is None else _as_flags(self.clipped, where)
        if clipped.shape != shape[:2]:
            raise RecordingError(f"{where}: clipped must have shape {shape[:2]}, got {clipped.shape}")
        clipped.setflags(write=False)
        object.__setattr__(self, "clipped", clipped)
        if self.pose is not None:
            pose = as_poses(self.pose, shape[0], where)
            pose.setflags(write=False)
            object.__setattr__(self, "pose", pose)

    @property
    def header(self) -> RecordingHeader:
        """Everything but the pings (validated already)."""
        return RecordingHeader(n_samples=self.n_samples, stores_codes=self.codes is not None, **self.header_fields())

    def header_fields(self) -> dict[str, Any]:
        """The constructor's arguments other than the pings' (``waveforms``, ``codes``,
        ``clipped``, ``pose``): for a new recording of other pings with the same header."""
        return {name: getattr(self, name) for name in HEADER_FIELDS}

    # ------------------------------------------------------------------ views
    def __repr__(self) -> str:
        stored = "codes" if self.codes is not None else "volts"
        return (f"Recording(source={self.source!r}, n_pings={self.n_pings}, n_samples={self.n_samples}, "
                f"sample_rate_hz={self.sample_rate_hz!r}, t0_s={self.t0_s!r}, stored as {stored})")

    @property
    def _shape(self) -> tuple[int, ...]:
        data = self.codes if self.codes is not None else self.__dict__[_Volts.slot]
        return tuple(data.shape)

    @property
    def n_pings(self) -> int:
        """Number of pings."""
        return int(self._shape[0])

    @property
    def n_samples(self) -> int:
        """Samples per channel."""
        return int(self._shape[2])

    @property
    def times_s(self) -> NDArray[np.float64]:
        """Time (s) of each sample after the trigger, shape (n_samples,)."""
        return self.t0_s + np.arange(self.n_samples) / self.sample_rate_hz


def as_volts(waveforms: Any, where: str, first_ping: int = 0) -> NDArray[np.float64]:
    """Waveforms as a read-only float64 (n_pings, 3, n) array ((3, n) gets a ping axis), finite
    and within +/-``VOLTS_LIMIT``. A read-only C-ordered float64 array is taken as it is (no
    copy). ``first_ping`` is the index of the first ping in messages (a chunk of a file).

    Raises
    ------
    RecordingError
        Not real numbers, another shape, NaN/infinite samples or samples beyond the limit (the
        first one's ping, channel and sample named).
    """
    if isinstance(waveforms, np.ndarray) and waveforms.dtype == np.float64 and not waveforms.flags.writeable \
            and waveforms.flags.c_contiguous:
        w = waveforms
    else:
        try:
            array = np.asarray(waveforms)
        except (TypeError, ValueError):
            raise RecordingError(f"{where}: waveforms must be an array of numbers") from None
        if array.dtype.kind not in "biuf":
            raise RecordingError(f"{where}: waveforms must be real numbers, got dtype {array.dtype}")
        w = np.array(array, dtype=float, copy=True, order="C")
    if w.ndim == 2:
        w = w[np.newaxis]
    if w.ndim != 3 or w.shape[1] != 3 or w.shape[2] < 1 or w.shape[0] < 1:
        raise RecordingError(f"{where}: waveforms must have shape (n_pings, 3, n_samples), got {w.shape}")
    high, low = float(w.max()), float(w.min())  # NaN propagates; no temporary arrays
    if not (math.isfinite(high) and math.isfinite(low)):
        bad = np.argwhere(~np.isfinite(w))[0]
        raise RecordingError(f"{where}: waveforms contain NaN or infinite samples (first at ping "
                             f"{bad[0] + first_ping}, channel {bad[1]}, sample {bad[2]})")
    if max(high, -low) > VOLTS_LIMIT:
        bad = np.argwhere(np.abs(w) > VOLTS_LIMIT)[0]
        raise RecordingError(f"{where}: a sample exceeds +/-{VOLTS_LIMIT:g} V (first at ping {bad[0] + first_ping}, "
                             f"channel {bad[1]}, sample {bad[2]}): not a recording in volts")
    if w.flags.writeable:
        w.setflags(write=False)
    return w


def _as_flags(clipped: Any, where: str) -> NDArray[np.bool_]:
    """Clipping flags as a new bool array: booleans or integers (non-zero: clipped), never text."""
    array = np.asarray(clipped)
    if array.dtype.kind not in "biu":
        raise RecordingError(f"{where}: clipped must be 0/1 flags (booleans or integers), got dtype {array.dtype}")
    return np.array(array != 0, dtype=bool)


def as_codes(codes: Any, volts_per_code: float | None, where: str) -> NDArray[np.int16]:
    """ADC codes as a read-only int16 array of shape (n_pings, 3, n) ((3, n) gets a ping axis).

    An int16 array is copied unless it is read-only already (then it is taken as it is).

    Raises
    ------
    RecordingError
        No valid ``volts_per_code``, a non-integer array, a wrong shape, or codes outside the
        int16 range.
    """
    if volts_per_code is None:
        raise RecordingError(f"{where}: codes need volts_per_code > 0, got None")
    volts_per_code_value(volts_per_code, where)
    array = np.asarray(codes)
    if array.dtype.kind not in "iu":
        raise RecordingError(f"{where}: codes must be integer ADC codes, got dtype {array.dtype}")
    if array.dtype != np.int16:
        if array.size and (int(array.min()) < -32768 or int(array.max()) > 32767):
            raise RecordingError(f"{where}: codes must fit int16, got values in [{array.min()}, {array.max()}]")
        out = array.astype(np.int16)
    elif array.flags.writeable or not array.flags.c_contiguous:
        out = np.array(array, dtype=np.int16, copy=True, order="C")
    else:
        out = array
    if out.ndim == 2:
        out = out[np.newaxis]
    if out.ndim != 3 or out.shape[1] != 3 or out.shape[2] < 1 or out.shape[0] < 1:
        raise RecordingError(f"{where}: codes must have shape (n_pings, 3, n_samples), got {array.shape}")
    if out.flags.writeable:
        out.setflags(write=False)
    return out


def as_poses(pose: Any, n_pings: int, where: str) -> NDArray[np.float64]:
    """Head poses as a new (n_pings, 6) float array: one pose (6,) is repeated for every ping.

    Parameters
    ----------
    pose : array_like, shape (6,) or (n_pings, 6)
        x_m, y_m, z_m, yaw_deg, pitch_deg, roll_deg (per ping).
    n_pings : int
    where : str
        Names the source in the error message.

    Raises
    ------
    RecordingError
        Another shape, a non-finite value, a position beyond 1e7 m or an angle beyond 1e5 deg.
    """
    try:
        poses = np.array(pose, dtype=float)
    except (TypeError, ValueError):
        raise RecordingError(f"{where}: pose must be ({n_pings}, 6) finite numbers, got {short_repr(pose)}") from None
    if poses.ndim == 1:
        poses = np.broadcast_to(poses, (n_pings, poses.size)).copy()
    if poses.shape != (n_pings, 6) or not np.all(np.isfinite(poses)):
        raise RecordingError(f"{where}: pose must be ({n_pings}, 6) finite, got shape {poses.shape}")
    if np.any(np.abs(poses[:, :3]) > POSE_POSITION_LIMIT_M) or np.any(np.abs(poses[:, 3:]) > POSE_ANGLE_LIMIT_DEG):
        raise RecordingError(f"{where}: pose positions must be within +/-{POSE_POSITION_LIMIT_M:g} m and angles "
                             f"within +/-{POSE_ANGLE_LIMIT_DEG:g} deg")
    return poses


__all__ = (
    "CHANNEL_NAMES",
    "FORMAT_VERSION",
    "POSE_COLUMNS",
    "Recording",
    "RecordingHeader",
    "RecordingError",
    "Template",
    "as_codes",
    "as_volts",
    "as_poses",
)
