"""Transmitted pulses.

A pulse is a real waveform q(t) in pascals at 1 m on the transmitter's axis (the source's
free-field pressure p(t) = q(t - r/c) / r). Its time reference t = 0 is the instant a path's
delay refers to: an echo of delay tau is q(t - tau). For the Gaussian pulse t = 0 is the
envelope peak, so the matched-filter peak of an echo sits exactly at the path delay.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from acoustisim import checks, ranges
from acoustisim.errors import InputError


@dataclass(frozen=True)
class GaussianPulse:
    """The seed's pulse, q(t) = A exp(-13.8 t^2 / T^2) cos(2 pi f0 t).

    Attributes
    ----------
    centre_frequency_hz : float
        Carrier f0 (Hz).
    duration_s : float
        T (s); the envelope falls to exp(-13.8) (-60 dB) at t = +/- T.
    amplitude_pa : float
        A, the peak pressure at 1 m on axis (Pa). The default, 1e5 Pa, is a source level of
        about 220 dB re 1 uPa at 1 m, the seed's figure (its eq. 3.6).
    """

    centre_frequency_hz: float = 500e3
    duration_s: float = 5e-6
    amplitude_pa: float = 1.0e5

    def __post_init__(self) -> None:
        for name, allowed in (("centre_frequency_hz", ranges.CENTRE_FREQUENCY_HZ),
                              ("duration_s", ranges.PULSE_DURATION_S), ("amplitude_pa", ranges.SOURCE_LEVEL_PA)):
            object.__setattr__(self, name, checks.real("pulse", name, getattr(self, name), allowed))

    @property
    def support_s(self) -> tuple[float, float]:
        """Interval (s) outside which the pulse is below -120 dB of its peak."""
        half = self.duration_s * math.sqrt(120.0 * math.log(10.0) / 20.0 / 13.8)
        return (-half, half)

    def waveform(self, t_s: ArrayLike) -> NDArray[np.float64]:
        """q(t) in Pa at the times ``t_s`` (s), any shape."""
        t = np.asarray(t_s, dtype=float)
        envelope = np.exp(-13.8 * t * t / self.duration_s**2)
        return self.amplitude_pa * envelope * np.cos(2.0 * np.pi * self.centre_frequency_hz * t)

    def spectrum(self, frequency_hz: ArrayLike) -> NDArray[np.complex128]:
        """Fourier transform Q(f) = int q(t) exp(-2 pi j f t) dt (Pa s), analytic."""
        f = np.asarray(frequency_hz, dtype=float)
        a = 13.8 / self.duration_s**2
        g = lambda nu: math.sqrt(math.pi / a) * np.exp(-(np.pi * nu) ** 2 / a)  # noqa: E731
        f0 = self.centre_frequency_hz
        return (0.5 * self.amplitude_pa * (g(f - f0) + g(f + f0))).astype(complex)

    def sampled(self, sample_rate_hz: float) -> "SampledPulse":
        """The pulse sampled over its support at ``sample_rate_hz``."""
        start, stop = self.support_s
        n0 = math.floor(start * sample_rate_hz)
        n1 = math.ceil(stop * sample_rate_hz)
        t = np.arange(n0, n1 + 1) / sample_rate_hz
        return SampledPulse(self.waveform(t), sample_rate_hz, t0_s=n0 / sample_rate_hz)


@dataclass(frozen=True, eq=False)
class SampledPulse:
    """A user-supplied pulse (measured pulse, chirp, ...), sampled.

    Attributes
    ----------
    samples : ndarray, shape (n,)
        q(t0 + i / fs) in Pa at 1 m on axis.
    sample_rate_hz : float
        fs (Hz).
    t0_s : float
        Time of ``samples[0]`` relative to the pulse's reference instant (s); negative when
        the reference lies inside the pulse.
    """

    samples: NDArray[np.float64] = field(repr=False)
    sample_rate_hz: float = 20e6
    t0_s: float = 0.0

    def __post_init__(self) -> None:
        raw = self.samples
        if isinstance(raw, (str, bytes)) or not isinstance(raw, (np.ndarray, list, tuple)):
            raise checks.type_error("pulse", "samples", raw, "a 1-D array of numbers")
        try:
            samples = np.array(raw, dtype=float, copy=True)
        except (TypeError, ValueError):
            raise checks.type_error("pulse", "samples", raw, "a 1-D array of numbers") from None
        if samples.ndim != 1 or samples.size < 2:
            raise InputError(f"pulse.samples: expected a 1-D array of >= 2 values, got shape {samples.shape}")
        if not np.all(np.isfinite(samples)):
            raise InputError("pulse.samples: contain NaN or infinite values")
        object.__setattr__(self, "sample_rate_hz",
                           checks.real("pulse", "sample_rate_hz", self.sample_rate_hz, ranges.SAMPLE_RATE_HZ))
        object.__setattr__(self, "t0_s", checks.real("pulse", "t0_s", self.t0_s, ranges.PULSE_OFFSET_S))
        samples.setflags(write=False)
        object.__setattr__(self, "samples", samples)

    @property
    def support_s(self) -> tuple[float, float]:
        """Interval (s) covered by the samples."""
        return (self.t0_s, self.t0_s + (self.samples.size - 1) / self.sample_rate_hz)

    def spectrum(self, frequency_hz: ArrayLike) -> NDArray[np.complex128]:
        """Fourier transform (Pa s) of the band-limited interpolant, by a direct DTFT."""
        f = np.asarray(frequency_hz, dtype=float)
        n = np.arange(self.samples.size)
        t = self.t0_s + n / self.sample_rate_hz
        phase = np.exp(-2j * np.pi * np.multiply.outer(f, t))
        return phase @ self.samples / self.sample_rate_hz

    def waveform(self, t_s: ArrayLike) -> NDArray[np.float64]:
        """Linear interpolation of the samples at ``t_s`` (zero outside)."""
        t = np.asarray(t_s, dtype=float)
        x = self.t0_s + np.arange(self.samples.size) / self.sample_rate_hz
        return np.interp(t, x, self.samples, left=0.0, right=0.0)


Pulse = GaussianPulse | SampledPulse
