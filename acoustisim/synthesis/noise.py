"""Noise of the pings, drawn directly on the record's rfft grid.

A real stationary noise of one-sided power spectral density S(f) (V^2/Hz), sampled at fs over
M samples (circularly), has independent rfft bins with E|N_k|^2 = M fs S(f_k) / 2, real and
imaginary parts each of variance M fs S / 4 (DC and Nyquist bins are left at 0: the receiver is
AC-coupled). Drawing the bins directly costs the same M normal draws as white noise in time.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

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


@dataclass(frozen=True, eq=False)
class NoiseModel:
    """One receiver chain's noise at the ADC input, planned on a record grid; draws pings.

    Noise enters at the receiver input and goes through gain x H(f). Its bins have random
    phases, so only |gain H(f)| matters: the per-bin variances are precomputed and a ping costs
    one complex normal draw per bin plus one compiled pass (square root, multiply, add).

    Attributes
    ----------
    electrical_var : ndarray (3, M//2+1) float32
        Variance of the real (and of the imaginary) part of each bin of the broadband electrical
        noise at the ADC input, before the ping's level factor.
    thermal_var : ndarray (3, M//2+1) float32 or None
        The same for the thermal noise.
    line_bins : ndarray (n_lines,) int
        rfft bins of the interference lines (inside the band).
    line_amplitudes : ndarray (3, n_lines)
        |bin value| of each line at the ADC input: A M / 2 |gain H(f_line)|.
    level_sigma_db : float
        Ping-to-ping level standard deviation (dB) of the electrical noise.
    """

    electrical_var: NDArray[np.float64] = field(repr=False)
    thermal_var: NDArray[np.float64] | None = field(repr=False)
    line_bins: NDArray[np.int64] = field(repr=False)
    line_amplitudes: NDArray[np.float64] = field(repr=False)
    level_sigma_db: float = 0.0

    @classmethod
    def create(
        cls,
        chain: ReceiverChain,
        frequency_hz: NDArray[np.float64],
        n_fft: int,
        sample_rate_hz: float,
        gain_response: NDArray[np.complex128],
        thermal_psd_v2_per_hz: NDArray[np.float64] | None,
    ) -> "NoiseModel":
        """Plan the noise of ``chain`` on the rfft grid ``frequency_hz`` of an ``n_fft`` record.

        Parameters
        ----------
        gain_response : ndarray (3, M//2+1)
            gain x H(f) per channel (V/V).
        thermal_psd_v2_per_hz : ndarray (M//2+1,) or None
            Thermal noise at the receiver input (one-sided, V^2/Hz), None for none.
        """
        power = np.abs(gain_response) ** 2 * (n_fft * sample_rate_hz / 4.0)
        edges = np.ones(frequency_hz.size)
        edges[0] = 0.0  # AC-coupled: no DC
        if n_fft % 2 == 0:
            edges[-1] = 0.0
        electrical = power * (electrical_noise_psd_v2_per_hz(frequency_hz, chain) * edges)
        thermal = None if thermal_psd_v2_per_hz is None else power * (thermal_psd_v2_per_hz * edges)
        freqs = np.array([line.frequency_hz for line in chain.interference_lines], dtype=float)
        amps = np.array([line.amplitude_v for line in chain.interference_lines], dtype=float)
        index = np.rint(freqs * n_fft / sample_rate_hz).astype(np.int64)
        inside = (index > 0) & (index < (n_fft + 1) // 2)
        index, amps = index[inside], amps[inside]
        # A cos(2 pi k n / M + psi) has rfft bin k equal to A M / 2 exp(j psi).
        line_amplitudes = np.abs(gain_response[:, index]) * (amps * n_fft / 2.0)
        return cls(
            electrical.astype(np.float32),
            None if thermal is None else thermal.astype(np.float32),
            index,
            line_amplitudes,
            chain.electrical_noise_level_sigma_db,
        )

    def draw(
        self, rng: np.random.Generator, deterministic: NDArray[np.complex64] | None = None
    ) -> NDArray[np.complex64]:
        """One ping's noise at the ADC input before TVG, as rfft bins (3, M//2+1), plus
        ``deterministic`` (the same shape) when given.

        The electrical part (broadband and lines) is scaled by one log-normal level factor per
        ping; line phases are uniform and independent per channel. The bins are single
        precision (relative rounding 6e-8, far below a 12-bit ADC's step).
        """
        from acoustisim.synthesis.ping_loops import scale_noise_bins

        level = 10.0 ** (self.level_sigma_db * rng.standard_normal() / 20.0)
        spectrum = rng.standard_normal(self.electrical_var.shape + (2,), dtype=np.float32).view(np.complex64)[..., 0]
        empty = np.empty((0, 0), dtype=np.float32)
        scale_noise_bins(
            spectrum,
            level * level,
            self.electrical_var,
            empty if self.thermal_var is None else self.thermal_var,
            empty.astype(np.complex64) if deterministic is None else deterministic,
        )
        if self.line_bins.size:
            phases = rng.uniform(0.0, 2.0 * np.pi, size=self.line_amplitudes.shape)
            spectrum[:, self.line_bins] += level * self.line_amplitudes * np.exp(1j * phases)
        return spectrum
