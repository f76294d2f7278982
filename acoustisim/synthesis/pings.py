"""From path rows to digitised three-channel pings: receiver chain, noise, ADC, template.

The deterministic part of a ping (echoes and main bang, through sensitivity, gains and the
band-pass) is computed once as a full-rate spectrum; each ping then adds its own noise
spectrum and takes one inverse FFT (realistic noise), or adds white noise in time (``snr_db``),
before the time-varying gain and the ADC.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from functools import cached_property
from typing import Any

import numpy as np
from numpy.typing import NDArray

from acoustisim.errors import InputError
from acoustisim.medium import Medium
from acoustisim.sonar import SonarHead
from acoustisim.synthesis.adc import adc_code_range, adc_step_v
from acoustisim.synthesis.chain import ReceiverChain
from acoustisim.synthesis.noise import NoiseModel, thermal_noise_psd_v2_per_hz
from acoustisim.propagation.responses import EchoResponse
from acoustisim.synthesis.synthesiser import PathSynthesiser
from acoustisim.synthesis.transducer import pulse_spectrum, pulse_support_s

TEMPLATE_FLOOR = 1e-4
"""The template is trimmed where it stays below this fraction of its peak (-80 dB)."""


@dataclass(frozen=True, eq=False)
class Pings:
    """Digitised pings and what made them.

    Attributes
    ----------
    codes : int16 ndarray, shape (n_pings, 3, n_samples)
    volts : ndarray, shape (n_pings, 3, n_samples)
        ``codes * volts_per_code``.
    clipped : bool ndarray, shape (n_pings, 3)
    volts_per_code : float
    clean : ndarray, shape (3, n_samples)
        The noise-free ADC input (V): echoes and main bang, after the chain and TVG (computed
        on first access: one inverse FFT).
    noise_sigma_v : ndarray, shape (3,) or None
        Per-channel white-noise standard deviation (V) when ``snr_db`` set it.
    """

    codes: NDArray[np.int16] = field(repr=False)
    volts: NDArray[np.float64] = field(repr=False)
    clipped: NDArray[np.bool_] = field(repr=False)
    volts_per_code: float
    noise_sigma_v: NDArray[np.float64] | None = None
    deterministic_spectrum: NDArray[np.complex128] | None = field(default=None, repr=False)
    synthesiser: "PingSynthesiser | None" = field(default=None, repr=False)

    @cached_property
    def clean(self) -> NDArray[np.float64]:
        """Noise-free ADC input (3, n_samples) (V)."""
        if self.synthesiser is None or self.deterministic_spectrum is None:
            raise ValueError("these pings carry no deterministic spectrum")
        return self.synthesiser.to_volts(self.deterministic_spectrum)


@dataclass(frozen=True, eq=False)
class PingSynthesiser:
    """Sonar + medium + receiver chain, planned once; renders pings for any path rows.

    Build with :meth:`create`.
    """

    sonar: SonarHead
    medium: Medium
    chain: ReceiverChain
    paths: PathSynthesiser
    _transfer: NDArray[np.complex128] = field(repr=False)  # (3, bins): V per Pa, gain x H(f)
    _noise: NoiseModel = field(repr=False)
    _tvg: NDArray[np.float64] | None = field(repr=False)
    _bang: NDArray[np.complex128] | None = field(repr=False)  # (3, bins) main bang at the ADC, or None

    @classmethod
    def create(cls, sonar: SonarHead, medium: Medium, chain: ReceiverChain | None = None) -> "PingSynthesiser":
        """Plan synthesis for this sonar, medium and chain.

        Raises
        ------
        InputError
            Sample rate below twice the pulse's band top or the band-pass's upper corner above
            the Nyquist frequency.
        """
        chain = ReceiverChain() if chain is None else chain
        fs = float(sonar.sample_rate_hz)
        if chain.bandpass_high_hz is not None and chain.bandpass_high_hz >= 0.5 * fs:
            raise InputError(
                f"chain.bandpass_high_hz = {chain.bandpass_high_hz:g} Hz is not below the Nyquist frequency "
                f"{0.5 * fs:g} Hz of sonar.sample_rate_hz"
            )
        padding = chain.bandpass_settle_s() + 8.0 * chain.main_bang_decay_s
        paths = PathSynthesiser.create(sonar, medium, padding_s=padding)
        f = paths.grid.frequencies_hz
        response = chain.bandpass_response(f)
        transfer = (chain.sensitivity_v_per_pa * chain.net_gain)[:, None] * response[None, :]
        thermal = (
            thermal_noise_psd_v2_per_hz(f, chain, sonar.piston_radius_m, medium.sound_speed)
            if chain.thermal_noise
            else None
        )
        tvg = None if chain.tvg is None else chain.tvg.gain(paths.grid.times_s)
        bang = None
        if chain.main_bang_peak_v > 0:
            spectrum = chain.main_bang_spectrum(f, sonar.centre_frequency_hz) * fs * response
            bang = (chain.main_bang_amplitudes_v / chain.main_bang_peak_v)[:, None] * spectrum[None, :]
        noise = NoiseModel.create(
            chain, f, paths.grid.n_fft, fs, transfer / chain.sensitivity_v_per_pa, thermal
        )
        return cls(sonar, medium, chain, paths, transfer, noise, tvg, bang)

    @property
    def n_samples(self) -> int:
        """Samples per channel."""
        return self.paths.grid.n_samples

    @property
    def sample_rate_hz(self) -> float:
        """fs (Hz)."""
        return self.paths.grid.sample_rate_hz

    # ---------------------------------------------------------------- spectra
    def echo_spectrum(self, rows: NDArray[Any], *, warn: bool = True,
                      responses: Sequence[EchoResponse] = ()) -> NDArray[np.complex128]:
        """rfft (3, M//2+1) of the echoes at the ADC input before TVG (V per sample); rows with a
        ``response_id`` name an entry of ``responses`` (``Paths.responses``)."""
        return self.paths.spectrum(rows, warn=warn, responses=responses) * self._transfer

    def main_bang_spectrum(self) -> NDArray[np.complex128]:
        """rfft (3, M//2+1) of the main bang and cross-talk at the ADC input before TVG."""
        if self._bang is None:
            return np.zeros((3, self.paths.grid.n_fft // 2 + 1), dtype=complex)
        return self._bang

    def to_volts(self, spectrum: NDArray[np.complex128]) -> NDArray[np.float64]:
        """Inverse FFT, cut to the record, time-varying gain: (3, n_samples) volts at the ADC."""
        grid = self.paths.grid
        volts = np.fft.irfft(spectrum, n=grid.n_fft, axis=-1)[..., : grid.n_samples]
        if self._tvg is not None:
            volts *= self._tvg
        return volts

    def echo_volts(self, rows: NDArray[Any], *, warn: bool = True,
                   responses: Sequence[EchoResponse] = ()) -> NDArray[np.float64]:
        """Noise-free echoes (3, n_samples) at the ADC input (V), without the main bang."""
        return self.to_volts(self.echo_spectrum(rows, warn=warn, responses=responses))

    # --------------------------------------------------------------- template
    def template(self) -> tuple[NDArray[np.float64], float]:
        """The transmitted pulse through the centre channel's chain, on axis (V), and its t0_s.

        Returns
        -------
        samples : ndarray, shape (n,)
            The pulse at 1 m on axis x sensitivity x gain x band-pass, sampled at fs.
        t0_s : float
            Time of ``samples[0]`` relative to the pulse's reference instant (s): an echo of
            delay tau is this template shifted by tau, so a matched filter peaks at tau.
        """
        fs = self.sample_rate_hz
        start, stop = pulse_support_s(self.sonar.pulse)
        lead = int(math.ceil(-start * fs)) + 8
        span = (stop - start) + self.chain.bandpass_settle_s()
        length = 1 << int(math.ceil(math.log2(span * fs + 2 * lead)))
        f = np.arange(length // 2 + 1) * (fs / length)
        gain = self.chain.sensitivity_v_per_pa * self.chain.net_gain[1]
        spectrum = fs * pulse_spectrum(self.sonar.pulse, f) * self.chain.bandpass_response(f) * gain
        spectrum *= np.exp(-2j * np.pi * np.arange(f.size) * lead / length)
        samples = np.fft.irfft(spectrum, n=length)
        above = np.flatnonzero(np.abs(samples) >= TEMPLATE_FLOOR * np.abs(samples).max())
        first, last = int(above[0]), int(above[-1]) + 1
        return samples[first:last], (first - lead) / fs

    # ------------------------------------------------------------------ pings
    def render(
        self,
        rows: NDArray[Any],
        *,
        seed: int | np.random.SeedSequence = 0,
        n_pings: int = 1,
        snr_db: float | None = None,
        snr_rows: tuple[NDArray[Any], NDArray[Any], NDArray[Any]] | None = None,
        responses: Sequence[EchoResponse] = (),
    ) -> Pings:
        """Render ``n_pings`` pings of the same paths with independent noise.

        Parameters
        ----------
        rows : structured ndarray of PATH_DTYPE
        seed : int or SeedSequence
            Each ping gets a Generator from ``SeedSequence(seed).spawn(n_pings)``.
        n_pings : int
        snr_db : float, optional
            Sets 2E/N0 = sum(s[n]^2) / sigma^2 of the echo made by ``snr_rows[c]`` on each channel
            c (physics.md section 6) with white Gaussian noise of variance sigma^2 at the ADC
            input, replacing the chain's noise models.
        snr_rows : 3 structured arrays, required with ``snr_db``
            The rows of the named echo on each channel.
        responses : sequence of EchoResponse
            The transfer functions the rows' ``response_id`` name (``Paths.responses``).
        """
        if not (isinstance(n_pings, (int, np.integer)) and n_pings >= 1):
            raise InputError(f"n_pings must be an integer >= 1, got {n_pings!r}")
        sequence = seed if isinstance(seed, np.random.SeedSequence) else np.random.SeedSequence(_check_seed(seed))
        generators = [np.random.Generator(np.random.PCG64(child)) for child in sequence.spawn(int(n_pings))]
        deterministic = self.echo_spectrum(rows, responses=responses)
        if self._bang is not None:
            deterministic = deterministic + self._bang
        sigma = None
        if snr_db is not None:
            if not math.isfinite(snr_db):
                raise InputError(f"snr_db must be a finite number, got {snr_db!r}")
            if snr_rows is None or len(snr_rows) != 3:
                raise InputError("snr_db needs the named echo's rows on each of the 3 channels")
            energy = np.array(
                [np.sum(self.echo_volts(snr_rows[c], warn=False, responses=responses)[c] ** 2) for c in range(3)]
            )
            if np.any(energy <= 0):
                channel = int(np.flatnonzero(energy <= 0)[0])
                raise InputError(f"snr_db: the named echo has no energy inside the record on channel {channel}")
            sigma = np.sqrt(energy / 10.0 ** (snr_db / 10.0))
        from scipy.fft import irfft

        from acoustisim.synthesis.ping_loops import digitise

        lowest, highest = adc_code_range(int(self.sonar.adc_bits))
        step = adc_step_v(self.chain.adc_full_scale_v, int(self.sonar.adc_bits))
        shape = (int(n_pings), 3, self.n_samples)
        codes = np.empty(shape, dtype=np.int16)
        volts = np.empty(shape)
        clipped = np.empty(shape[:2], dtype=bool)
        if sigma is not None:
            clean = self.to_volts(deterministic)
            for ping, rng in enumerate(generators):
                noisy = clean + sigma[:, None] * rng.standard_normal((3, self.n_samples))
                digitise(noisy, np.empty(0), step, lowest, highest, codes[ping], volts[ping], clipped[ping])
        else:
            # Per ping: noise bins (+ the deterministic part) in single precision, one inverse
            # FFT, then TVG and the ADC in one compiled pass.
            single = deterministic.astype(np.complex64)
            gain = np.empty(0) if self._tvg is None else self._tvg
            for ping, rng in enumerate(generators):
                signal = irfft(self._noise.draw(rng, single), n=self.paths.grid.n_fft, axis=-1, overwrite_x=True)
                digitise(signal, gain, step, lowest, highest, codes[ping], volts[ping], clipped[ping])
        return Pings(codes, volts, clipped, step, sigma, deterministic, self)


def _check_seed(seed: Any) -> int:
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise InputError(f"seed must be an integer >= 0, got {seed!r}")
    return int(seed)
