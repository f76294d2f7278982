"""Transducer side of synthesis: the pulse's spectrum and band, the piston's directivity factor.

The transmitted pulse q(t) (Pa at 1 m on axis) comes from ``acoustisim.pulse``: the seed's
Gaussian pulse (analytic spectrum) or any user ``SampledPulse`` (measured pulse, chirp), whose
spectrum is its band-limited interpolant's (zero above the pulse's own Nyquist frequency).
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

from acoustisim.pulse import Pulse, SampledPulse


def pulse_spectrum(pulse: Pulse, frequency_hz: ArrayLike) -> NDArray[np.complex128]:
    """Q(f) (Pa s) of the pulse at the frequencies ``frequency_hz`` (Hz), any shape.

    For a sampled pulse, frequencies at or above its Nyquist frequency get 0 (its band-limited
    interpolant has no energy there).
    """
    f = np.asarray(frequency_hz, dtype=float)
    spectrum = np.asarray(pulse.spectrum(f), dtype=complex)
    if isinstance(pulse, SampledPulse):
        spectrum = np.where(np.abs(f) < 0.5 * pulse.sample_rate_hz, spectrum, 0.0)
    return spectrum


def pulse_band_top_hz(pulse: Pulse, level_db: float = -40.0) -> float:
    """Highest frequency (Hz) where |Q(f)| is within ``level_db`` of its peak.

    Parameters
    ----------
    pulse : GaussianPulse or SampledPulse
    level_db : float
        Level below the spectrum's peak (dB, negative).
    """
    if isinstance(pulse, SampledPulse):
        # |DTFT| on a fine grid up to the pulse's Nyquist frequency: a zero-padded FFT (the
        # reference-instant phase does not change the magnitude).
        n = max(16384, 1 << int(math.ceil(math.log2(4 * pulse.samples.size))))
        magnitude = np.abs(np.fft.rfft(pulse.samples, n))
        f = np.fft.rfftfreq(n, 1.0 / pulse.sample_rate_hz)
    else:
        f = np.linspace(0.0, pulse.centre_frequency_hz + 12.0 / pulse.duration_s, 8192)
        magnitude = np.abs(pulse_spectrum(pulse, f))
    above = np.flatnonzero(magnitude >= magnitude.max() * 10.0 ** (level_db / 20.0))
    return float(f[min(int(above[-1]) + 1, f.size - 1)])


def pulse_support_s(pulse: Pulse) -> tuple[float, float]:
    """Interval (s), relative to the pulse's reference instant, that holds the pulse."""
    start, stop = pulse.support_s
    return float(start), float(stop)


def piston_directivity_factor(frequency_hz: ArrayLike, radius_m: float, sound_speed_m_s: float) -> NDArray[np.float64]:
    """Directivity factor (linear, intensity) of a baffled piston: (ka)^2 / (1 - J1(2ka)/(ka)).

    It tends to (ka)^2 (DI = 20 log10 ka, 26 dB at 500 kHz for a = 9.5 mm) for ka >> 1 and to
    2 (the baffle's half-space) for ka -> 0. Scales isotropic (thermal) noise received by a
    directional transducer.

    Parameters
    ----------
    frequency_hz : array_like
        Frequency (Hz), any shape.
    radius_m, sound_speed_m_s : float
        Piston radius (m) and sound speed (m/s).
    """
    from scipy.special import j1

    ka = 2.0 * np.pi * np.asarray(frequency_hz, dtype=float) * float(radius_m) / float(sound_speed_m_s)
    safe = np.where(ka < 1e-4, 1e-4, ka)
    # Below ka = 1e-4 the series gives 2 (1 + ka^2/2 ...): the half-space limit.
    return np.where(ka < 1e-4, 2.0, safe * safe / (1.0 - j1(2.0 * safe) / safe))
