"""Noise spectra of one ping, drawn directly on the record's rfft grid.

A real stationary noise of one-sided power spectral density S(f) (V^2/Hz), sampled at fs over
M samples (circularly), has independent rfft bins with E|N_k|^2 = M fs S(f_k) / 2, real and
imaginary parts each of variance M fs S / 4 (DC and Nyquist bins are left at 0: the receiver is
AC-coupled). Drawing the bins directly costs the same M normal draws as white noise in time.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

from acoustisim.synthesis.chain import ReceiverChain
from acoustisim.synthesis.transducer import piston_directivity_factor

ELECTRICAL_NOISE_FLOOR_HZ = 20e3
"""Below this frequency the electrical noise PSD is held constant (no 1/f blow-up at DC)."""


def mellen_thermal_noise_psd_pa2_per_hz(frequency_hz: ArrayLike) -> NDArray[np.float64]:
    """Thermal noise spectrum level, one-sided (Pa^2/Hz), Mellen (1952):
    NL = -15 + 20 log10(f / 1 kHz) dB re 1 uPa^2/Hz (39 dB at 500 kHz); 0 at f = 0."""
    f = np.asarray(frequency_hz, dtype=float)
    f_khz = np.maximum(f, 1e-9) / 1e3
    level_db = -15.0 + 20.0 * np.log10(f_khz)
    return np.where(f > 0, 10.0 ** (level_db / 10.0) * 1e-12, 0.0)


def thermal_noise_psd_v2_per_hz(
    frequency_hz: ArrayLike, chain: ReceiverChain, radius_m: float, sound_speed_m_s: float
) -> NDArray[np.float64]:
    """Thermal noise at a receiver's input (V^2/Hz): the isotropic field received through the
    piston's directivity factor (noise intensity / DF) times the sensitivity squared."""
    f = np.asarray(frequency_hz, dtype=float)
    factor = piston_directivity_factor(f, radius_m, sound_speed_m_s)
    return mellen_thermal_noise_psd_pa2_per_hz(f) / factor * chain.sensitivity_v_per_pa**2


def electrical_noise_psd_v2_per_hz(frequency_hz: ArrayLike, chain: ReceiverChain) -> NDArray[np.float64]:
    """Broadband electrical noise at the receiver input (V^2/Hz), before the per-ping level."""
    f = np.maximum(np.asarray(frequency_hz, dtype=float), ELECTRICAL_NOISE_FLOOR_HZ)
    exponent = chain.electrical_noise_slope_db_per_octave / (10.0 * math.log10(2.0))
    return chain.electrical_noise_v_per_rthz**2 * (f / chain.electrical_noise_ref_hz) ** exponent


def gaussian_spectrum(
    rng: np.random.Generator, psd_v2_per_hz: NDArray[np.float64], n_fft: int, sample_rate_hz: float, n_channels: int = 3
) -> NDArray[np.complex128]:
    """Random rfft bins (n_channels, M//2 + 1) of stationary Gaussian noise with one-sided PSD
    ``psd_v2_per_hz`` given per bin (shape (M//2+1,) or (n_channels, M//2+1))."""
    n_bins = n_fft // 2 + 1
    scale = np.sqrt(np.broadcast_to(psd_v2_per_hz, (n_channels, n_bins)) * (n_fft * sample_rate_hz / 4.0))
    draws = rng.standard_normal((2, n_channels, n_bins))
    spectrum = scale * (draws[0] + 1j * draws[1])
    spectrum[:, 0] = 0.0
    if n_fft % 2 == 0:
        spectrum[:, -1] = 0.0
    return spectrum


def receiver_input_noise_spectrum(
    rng: np.random.Generator,
    chain: ReceiverChain,
    frequency_hz: NDArray[np.float64],
    n_fft: int,
    sample_rate_hz: float,
    thermal_psd_v2_per_hz: NDArray[np.float64] | None,
) -> NDArray[np.complex128]:
    """One ping's noise at the three receiver inputs, as rfft bins (3, M//2 + 1) (V per sample).

    Thermal noise (if ``thermal_psd_v2_per_hz`` is given) plus electrical noise: a coloured
    broadband part and interference lines (on their nearest bins, random phase per channel),
    both scaled by one log-normal level factor per ping (``electrical_noise_level_sigma_db``).
    """
    level = 10.0 ** (chain.electrical_noise_level_sigma_db * rng.standard_normal() / 20.0)
    psd = electrical_noise_psd_v2_per_hz(frequency_hz, chain) * level**2
    if thermal_psd_v2_per_hz is not None:
        psd = psd + thermal_psd_v2_per_hz
    spectrum = gaussian_spectrum(rng, psd, n_fft, sample_rate_hz)
    if chain.interference_lines:
        freqs = np.array([line.frequency_hz for line in chain.interference_lines])
        amps = np.array([line.amplitude_v for line in chain.interference_lines]) * level
        index = np.rint(freqs * n_fft / sample_rate_hz).astype(np.int64)
        inside = (index > 0) & (index < (n_fft + 1) // 2)
        phases = rng.uniform(0.0, 2.0 * np.pi, size=(3, freqs.size))
        # A cos(2 pi k n / M + psi) has rfft bin k equal to A M / 2 exp(j psi).
        lines = (amps * n_fft / 2.0)[None, :] * np.exp(1j * phases)
        np.add.at(spectrum, (slice(None), index[inside]), lines[:, inside])
    return spectrum
