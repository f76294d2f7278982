"""Synthetic echoes for the detection tests (made here: binsonar's tests need no simulator).

The pulse is the thesis's: exp(-13.8 t^2 / T^2) cos(2 pi f0 t), T = 5 us, f0 = 500 kHz,
sampled at 20 MHz, with t = 0 its envelope peak (the reference instant a TOF refers to).
Echoes are evaluated analytically at arbitrary (fractional) delays, so no interpolation error
enters the truth. The SNR is 2E/N0 = sum(s[n]^2) / sigma^2 (physics.md section 6).
"""

from __future__ import annotations

import numpy as np

from binsonar.recording import Template

FS = 20e6
T_PULSE = 5e-6
F0 = 500e3
HALF = 100  # template half-length (samples): +/- 5 us, where the envelope is exp(-13.8) = 1e-6


def gaussian_pulse(t: np.ndarray) -> np.ndarray:
    """The thesis pulse at times t (s), unit peak envelope."""
    return np.exp(-13.8 * t ** 2 / T_PULSE ** 2) * np.cos(2 * np.pi * F0 * t)


def pulse_template() -> Template:
    """The pulse sampled over +/- HALF samples; t0_s = -HALF / FS (sample 0 before the peak)."""
    t = (np.arange(2 * HALF + 1) - HALF) / FS
    return Template(gaussian_pulse(t), FS, -HALF / FS, "transmitted-pulse")


def pulse_energy() -> float:
    """sum(s[n]^2) of a unit-amplitude echo (independent of the fractional delay to 1e-12)."""
    return float(np.sum(pulse_template().samples ** 2))


def echo_rows(
    delays_s: np.ndarray,
    n_samples: int,
    amplitudes: np.ndarray | float = 1.0,
) -> np.ndarray:
    """Noise-free records, one row per delay: amplitude * pulse(t - delay), shape (k, n)."""
    t = np.arange(n_samples) / FS
    delays = np.asarray(delays_s, dtype=float)
    amps = np.broadcast_to(np.asarray(amplitudes, dtype=float), delays.shape)
    return amps[:, np.newaxis] * gaussian_pulse(t[np.newaxis, :] - delays[:, np.newaxis])


def noise_sigma_for(snr_db: float, amplitude: float = 1.0) -> float:
    """White-noise standard deviation giving 2E/N0 = snr_db for an echo of this amplitude."""
    return float(np.sqrt(amplitude ** 2 * pulse_energy() / 10 ** (snr_db / 10)))
