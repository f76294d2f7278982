"""The receiver chain: sensitivity, gains, band-pass, main bang, time-varying gain, noise, ADC.

Modelled on the seed's hardware (thesis section 3): a Panametrics 5052PR pulser-receiver on
the centre (transmit/receive) channel and 5662 preamplifiers on the side channels, 40 dB gain,
0-68 dB attenuation, a broadband receiver with switchable filters, and a 12-bit, 20 MS/s
CompuScope 1012 digitiser. Values that the seed does not give are chosen and documented here,
in one visible place.

Signal flow per channel (all linear until the ADC)::

    pressure p(t) at the face (Pa) --x sensitivity--> volts at the receiver input
        + thermal noise (Mellen, received through the transducer's directivity)
        + electrical noise (coloured, interference lines, level varying per ping)
    --x 10^((gain - attenuation)/20)--> + main bang / cross-talk (at t = 0)
    --band-pass H(f)--> x TVG g(t) --> ADC (rounding, clipping)
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from acoustisim.errors import InputError

ATTENUATION_RANGE_DB: tuple[float, float] = (0.0, 68.0)
"""The 5052PR's receiver attenuation range (dB)."""


def _finite(owner: str, name: str, value: float, *, positive: bool = False, nonneg: bool = False) -> None:
    ok = isinstance(value, (int, float, np.floating, np.integer)) and math.isfinite(float(value))
    if ok and positive:
        ok = value > 0
    if ok and nonneg:
        ok = value >= 0
    if not ok:
        need = " and > 0" if positive else (" and >= 0" if nonneg else "")
        raise InputError(f"{owner}.{name} must be a finite number{need}, got {value!r}")


@dataclass(frozen=True)
class InterferenceLine:
    """A narrow-band electrical interference line (e.g. a switching supply of the motion system).

    Attributes
    ----------
    frequency_hz : float
        Line frequency (Hz).
    amplitude_v : float
        Peak amplitude at the receiver input (V), before the ping-to-ping level variation.
    """

    frequency_hz: float
    amplitude_v: float

    def __post_init__(self) -> None:
        _finite("interference_line", "frequency_hz", self.frequency_hz, positive=True)
        _finite("interference_line", "amplitude_v", self.amplitude_v, nonneg=True)


@dataclass(frozen=True)
class TimeVaryingGain:
    """A time-varying gain g(t): 0 dB until ``start_s``, then ``slope_db_per_decade`` per decade
    of time, capped at ``max_gain_db`` (20 dB/decade compensates one-way spherical spreading).

    Attributes
    ----------
    start_s : float
        Time after the trigger where the ramp starts (s).
    slope_db_per_decade : float
        Gain slope (dB per decade of time).
    max_gain_db : float
        Cap (dB).
    """

    start_s: float = 2.0e-4
    slope_db_per_decade: float = 20.0
    max_gain_db: float = 30.0

    def __post_init__(self) -> None:
        _finite("tvg", "start_s", self.start_s, positive=True)
        _finite("tvg", "slope_db_per_decade", self.slope_db_per_decade)
        _finite("tvg", "max_gain_db", self.max_gain_db, nonneg=True)

    def gain(self, t_s: ArrayLike) -> NDArray[np.float64]:
        """Linear gain at the times ``t_s`` (s), any shape."""
        t = np.maximum(np.asarray(t_s, dtype=float), self.start_s)
        gain_db = np.minimum(self.slope_db_per_decade * np.log10(t / self.start_s), self.max_gain_db)
        return 10.0 ** (gain_db / 20.0)


DEFAULT_INTERFERENCE_LINES: tuple[InterferenceLine, ...] = (
    InterferenceLine(153.6e3, 4.0e-4),
    InterferenceLine(460.8e3, 2.0e-4),
    InterferenceLine(1.25e6, 1.5e-4),
)
"""Representative lines (a switching supply's harmonics, a clock): the seed blames the motion
control system, the PC and the building's equipment but gives no spectrum, so these are
illustrative, of the order of the broadband noise in the signal band."""


@dataclass(frozen=True)
class ReceiverChain:
    """Settings of the receiving electronics (one frozen description, no state).

    Attributes
    ----------
    receive_sensitivity_db : float
        Open-circuit receive sensitivity (dB re 1 V/uPa), flat over the band. -190 dB re
        1 V/uPa (3.16e-4 V/Pa) is a typical broadband piezo-composite NDT transducer such as
        the V318; the seed gives no value.
    gain_db : tuple of 3 float
        Receiver gain per channel (left, centre, right) (dB); the 5052PR's 40 dB.
    attenuation_db : tuple of 3 float
        Receiver attenuation per channel (dB), within the 5052PR's 0-68 dB. The default 40 dB
        puts the thesis tank's target echoes at 10-100 mV at the ADC (the seed's plots use a
        0.04 V detection threshold) with the pulse's 220 dB re 1 uPa source level, and its
        strongest wall echoes well inside the +/-1 V range.
    bandpass_low_hz, bandpass_high_hz : float or None
        Corners of the receive band-pass (Hz), an analog Butterworth (causal): the 5052PR's
        selectable high-pass and the digitiser's anti-alias low-pass. None disables that side.
    bandpass_order : int
        Butterworth order of each side (1-8).
    main_bang_peak_v : float
        Peak of the transmit "main bang" on the centre channel at the ADC input (V): the pulser's
        excitation leaking into the receiver (behind its limiter) at t = 0, a damped oscillation
        at the transducer's frequency.
    main_bang_decay_s : float
        Its exponential decay time (s) (the transducer's and the receiver's ring-down).
    crosstalk_db : float
        Electrical cross-talk of the main bang onto the side channels (dB re the centre's).
    tvg : TimeVaryingGain or None
        Optional time-varying gain after the band-pass.
    thermal_noise : bool
        Add the acoustic thermal noise (Mellen, physics.md section 6).
    electrical_noise_v_per_rthz : float
        Electrical noise density at the receiver input at ``electrical_noise_ref_hz``
        (V/sqrt(Hz)). The seed finds electrical noise "many orders of magnitude larger" than the
        acoustic one: 2 uV/sqrt(Hz) against about 1.4 nV/sqrt(Hz) of thermal noise at 500 kHz.
    electrical_noise_ref_hz : float
        Reference frequency of that density (Hz).
    electrical_noise_slope_db_per_octave : float
        Spectral slope of the electrical noise's PSD (dB/octave; -3 is pink). The PSD is held
        constant below 20 kHz.
    electrical_noise_level_sigma_db : float
        Standard deviation (dB) of the electrical noise level from ping to ping (log-normal);
        the seed: it "varies with location in the tank, with time of day".
    interference_lines : tuple of InterferenceLine
        Narrow-band lines added to the electrical noise, random phase per ping and channel.
    adc_full_scale_v : float
        ADC input range +/- this (V); step = 2 full scale / 2^bits.
    """

    receive_sensitivity_db: float = -190.0
    gain_db: tuple[float, float, float] = (40.0, 40.0, 40.0)
    attenuation_db: tuple[float, float, float] = (40.0, 40.0, 40.0)
    bandpass_low_hz: float | None = 100e3
    bandpass_high_hz: float | None = 2.0e6
    bandpass_order: int = 2
    main_bang_peak_v: float = 0.8
    main_bang_decay_s: float = 2.0e-6
    crosstalk_db: float = -30.0
    tvg: TimeVaryingGain | None = None
    thermal_noise: bool = True
    electrical_noise_v_per_rthz: float = 2.0e-6
    electrical_noise_ref_hz: float = 500e3
    electrical_noise_slope_db_per_octave: float = -3.0
    electrical_noise_level_sigma_db: float = 3.0
    interference_lines: tuple[InterferenceLine, ...] = field(default=DEFAULT_INTERFERENCE_LINES)
    adc_full_scale_v: float = 1.0

    def __post_init__(self) -> None:
        owner = "chain"
        for name in ("gain_db", "attenuation_db"):
            value = getattr(self, name)
            if isinstance(value, (int, float)):
                value = (float(value),) * 3
            values = tuple(float(v) for v in np.asarray(value, dtype=float).ravel()) if np.size(value) else ()
            if len(values) != 3 or not all(math.isfinite(v) for v in values):
                raise InputError(f"{owner}.{name} must be 3 finite numbers (left, centre, right), got {value!r}")
            object.__setattr__(self, name, values)
        lo, hi = ATTENUATION_RANGE_DB
        if not all(lo <= v <= hi for v in self.attenuation_db):
            raise InputError(f"{owner}.attenuation_db must lie in [{lo:g}, {hi:g}] dB, got {self.attenuation_db!r}")
        _finite(owner, "receive_sensitivity_db", self.receive_sensitivity_db)
        for name in ("bandpass_low_hz", "bandpass_high_hz"):
            if getattr(self, name) is not None:
                _finite(owner, name, getattr(self, name), positive=True)
        if (
            self.bandpass_low_hz is not None
            and self.bandpass_high_hz is not None
            and not self.bandpass_low_hz < self.bandpass_high_hz
        ):
            raise InputError(
                f"{owner}.bandpass_low_hz ({self.bandpass_low_hz!r}) must be below bandpass_high_hz "
                f"({self.bandpass_high_hz!r})"
            )
        if not (isinstance(self.bandpass_order, int) and 1 <= self.bandpass_order <= 8):
            raise InputError(f"{owner}.bandpass_order must be an integer in [1, 8], got {self.bandpass_order!r}")
        _finite(owner, "main_bang_peak_v", self.main_bang_peak_v, nonneg=True)
        _finite(owner, "main_bang_decay_s", self.main_bang_decay_s, positive=True)
        _finite(owner, "crosstalk_db", self.crosstalk_db)
        _finite(owner, "electrical_noise_v_per_rthz", self.electrical_noise_v_per_rthz, nonneg=True)
        _finite(owner, "electrical_noise_ref_hz", self.electrical_noise_ref_hz, positive=True)
        _finite(owner, "electrical_noise_slope_db_per_octave", self.electrical_noise_slope_db_per_octave)
        _finite(owner, "electrical_noise_level_sigma_db", self.electrical_noise_level_sigma_db, nonneg=True)
        _finite(owner, "adc_full_scale_v", self.adc_full_scale_v, positive=True)
        object.__setattr__(self, "interference_lines", tuple(self.interference_lines))

    # ------------------------------------------------------------------ gains
    @property
    def sensitivity_v_per_pa(self) -> float:
        """Receive sensitivity (V/Pa): 1 Pa = 10^6 uPa, hence +120 dB."""
        return 10.0 ** ((self.receive_sensitivity_db + 120.0) / 20.0)

    @property
    def net_gain(self) -> NDArray[np.float64]:
        """Linear voltage gain per channel (3,), gain minus attenuation."""
        return 10.0 ** ((np.asarray(self.gain_db) - np.asarray(self.attenuation_db)) / 20.0)

    @property
    def main_bang_amplitudes_v(self) -> NDArray[np.float64]:
        """Main-bang peak per channel (3,) (V): centre, and cross-talk on the sides."""
        side = self.main_bang_peak_v * 10.0 ** (self.crosstalk_db / 20.0)
        return np.array([side, self.main_bang_peak_v, side])

    @property
    def band_top_hz(self) -> float | None:
        """Upper corner of the receive band (Hz), None when the band-pass has no low-pass side."""
        return self.bandpass_high_hz

    # ------------------------------------------------------------- responses
    def bandpass_response(self, frequency_hz: ArrayLike) -> NDArray[np.complex128]:
        """Complex response H(f) of the analog Butterworth band-pass (causal), any shape."""
        from scipy import signal

        f = np.asarray(frequency_hz, dtype=float)
        response = np.ones(f.shape, dtype=complex)
        w = 2.0 * np.pi * f.ravel()
        if self.bandpass_low_hz is not None:
            b, a = signal.butter(self.bandpass_order, 2.0 * np.pi * self.bandpass_low_hz, "highpass", analog=True)
            response *= signal.freqs(b, a, w)[1].reshape(f.shape)
        if self.bandpass_high_hz is not None:
            b, a = signal.butter(self.bandpass_order, 2.0 * np.pi * self.bandpass_high_hz, "lowpass", analog=True)
            response *= signal.freqs(b, a, w)[1].reshape(f.shape)
        return response

    def bandpass_settle_s(self) -> float:
        """Time (s) after which the band-pass's impulse response is negligible (< -120 dB).

        The slowest poles are the high-pass corner's: decay rate about 2 pi f_low sin(pi/(2N)).
        """
        if self.bandpass_low_hz is None:
            f = self.bandpass_high_hz or 1e6
        else:
            f = self.bandpass_low_hz
        rate = 2.0 * np.pi * f * math.sin(math.pi / (2.0 * self.bandpass_order))
        return 14.0 / rate + 2.0e-6

    def main_bang_spectrum(self, frequency_hz: ArrayLike, centre_frequency_hz: float) -> NDArray[np.complex128]:
        """Fourier transform (V s) of the centre channel's main bang m(t) = A exp(-t/tau) sin(w0 t), t >= 0.

        M(f) = A w0 / ((1/tau + j w)^2 + w0^2), w = 2 pi f; any shape. A is set so that the peak
        of m(t) (at t* = atan(w0 tau) / w0) is ``main_bang_peak_v``.
        """
        w = 2.0 * np.pi * np.asarray(frequency_hz, dtype=float)
        w0 = 2.0 * np.pi * centre_frequency_hz
        tau = self.main_bang_decay_s
        t_peak = math.atan(w0 * tau) / w0
        amplitude = self.main_bang_peak_v / (math.exp(-t_peak / tau) * math.sin(w0 * t_peak))
        return amplitude * w0 / ((1.0 / tau + 1j * w) ** 2 + w0**2)
