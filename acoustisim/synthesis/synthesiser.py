"""Paths -> band-limited pressure signals at the receivers, each path at its exact delay.

Every path row is the impulse ``geometric_gain * delta(t - delay_s)`` with the constant phase
``phase_rad`` (``acoustisim.propagation.paths``). Its echo at a receiver face is, per frequency,

    P(f) = g Q(f) D(theta_tx, f) D(theta_rx, f) 10^(-alpha(f) L / 20) exp(j phi) exp(-j 2 pi f tau),

Q the pulse's spectrum, D the piston directivity 2 J1(x)/x (``propagation/directivity.py``; 0
beyond 90 deg: nothing radiates behind the baffle), alpha the medium's
absorption (dB/m) over the path length L. Edge elements sharing a ``path_id`` are summed like
any row, so the band-limited Biot-Tolstoy-Medwin response (the half-integrated pulse) comes
out of the sum by itself.

Method (fast for 10^4 and more rows, no Python loop per row or sample): the signals are
band-limited well below the digitiser's Nyquist frequency, so they are built on a grid
decimated by ``q``. Each row's short-kernel spectrum on an ``Lk``-point grid (only the bins
inside the pulse's band) is the product of per-bin lookup tables planned once (directivity
against sin(theta), absorption against path length, pulse spectrum times the fractional-delay
phase ramp against the fraction of a sample). Rows on one channel that start on the same
decimated sample form a group whose spectra are summed (exactly: each row keeps its own
weight, delay, directivities and absorption); one batched inverse FFT per block of groups
gives (groups, Lk) kernels holding the echoes sampled at their fractional delays, which are
overlap-added into the decimated record. The loops over rows are compiled
(:mod:`acoustisim.synthesis.row_kernels`, numba). One FFT of that record, zero-padded in
frequency by ``q``, gives the full-rate spectrum that the receiver chain then shapes.
Memory: O(CHUNK_ROWS x Lk) plus O(rows) plus O(record) plus the tables (a few MB).

Table resolutions (nearest entry): sin(theta) in steps of 1/8192 (directivity error below
7e-4 absolute at the centre frequency, 0.02 dB where D = 0.3), path length in 1 cm steps
(absorption error below 3e-5 relative at 500 kHz), delay in steps of at most 0.05 ns (a
power-of-two fraction of a decimated sample: the echo's error is below 1e-4 of its peak at
500 kHz and its delay is exact to 0.025 ns).
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from acoustisim.errors import InputError
from acoustisim.medium import Medium
from acoustisim.sonar import SonarHead
from acoustisim.propagation.directivity import piston_directivity
from acoustisim.propagation.responses import EchoResponse
from acoustisim.pulse import Pulse
from acoustisim.synthesis.spectral_rows import add_spectral_rows, needs_spectral_path
from acoustisim.synthesis.transducer import pulse_band_top_hz, pulse_spectrum, pulse_support_s

SYNTHESIS_BAND_DB = -100.0
"""Pulse spectrum level (dB re its peak) above which bins are synthesised; the rest (< 1e-5
relative) is dropped."""

NYQUIST_BAND_DB = -40.0
"""The pulse's band top is where its spectrum falls 40 dB below the peak: the sample rate must
be at least twice that frequency."""

CHUNK_ROWS = 8192
"""Groups per block (bounds the (groups, Lk) working arrays to a few MB)."""

SINE_STEPS = 8192
"""Directivity table: entries per unit of sin(theta)."""

DELAY_RESOLUTION_S = 5e-11
"""Phase-ramp table: fractional-delay step at most this (s); 8192 steps per sample at 20 MS/s / 7."""

FINE_DELAY_STEPS = 64
"""Phase-ramp tables: fine steps per coarse step (the fine table's rows)."""

LENGTH_STEP_M = 0.01
"""Absorption table: path-length step (m)."""

@dataclass(frozen=True, eq=False)
class RecordGrid:
    """Sampling grid of one record and of its FFT.

    Attributes
    ----------
    sample_rate_hz : float
        Digitiser rate fs (Hz).
    n_samples : int
        Samples kept per channel.
    n_fft : int
        FFT length M (record plus zero padding that absorbs the causal band-pass's tail and the
        kernels' spill-over); a multiple of ``decimation``.
    decimation : int
        q: the paths are synthesised at fs / q.
    """

    sample_rate_hz: float
    n_samples: int
    n_fft: int
    decimation: int

    @property
    def n_fft_decimated(self) -> int:
        """M / q."""
        return self.n_fft // self.decimation

    @property
    def frequencies_hz(self) -> NDArray[np.float64]:
        """The rfft bins (M//2 + 1,) (Hz)."""
        return np.arange(self.n_fft // 2 + 1) * (self.sample_rate_hz / self.n_fft)

    @property
    def times_s(self) -> NDArray[np.float64]:
        """Sample times (n_samples,) after the trigger (s)."""
        return np.arange(self.n_samples) / self.sample_rate_hz


def make_record_grid(sample_rate_hz: float, n_samples: int, decimation: int, padding_s: float) -> RecordGrid:
    """A grid whose FFT length is fast (5-smooth) and a multiple of ``decimation``."""
    from scipy.fft import next_fast_len

    pad = int(math.ceil(padding_s * sample_rate_hz))
    m_dec = next_fast_len(int(math.ceil((n_samples + pad) / decimation)), real=True)
    return RecordGrid(float(sample_rate_hz), int(n_samples), int(m_dec * decimation), int(decimation))


@dataclass(frozen=True, eq=False)
class KernelPlan:
    """One kernel size and its lookup tables: rows whose echo spans fewer than ``length``
    samples at fs / q use it.

    Attributes
    ----------
    length : int
        Lk, kernel samples at fs / q (a power of two).
    centre : int
        Index of the pulse's reference instant in a kernel, before the fractional shift.
    max_spread : float
        Largest |sin theta_tx| + |sin theta_rx| the kernel holds without wrap-around.
    phase_coarse : ndarray (2, delay_steps / FINE_DELAY_STEPS + 1, n_bins) float32
        Real and imaginary parts of fs_dec Q(f_k) exp(-j 2 pi k (centre + v FINE_DELAY_STEPS /
        delay_steps) / Lk): the sampled pulse with its reference instant at the coarse
        fractional delay v.
    phase_fine : ndarray (2, FINE_DELAY_STEPS, n_bins) float32
        Real and imaginary parts of exp(-j 2 pi k w / (delay_steps Lk)): the fine step w. A
        delay of u / delay_steps samples is coarse[u // FINE_DELAY_STEPS] x fine[u %
        FINE_DELAY_STEPS] (two small tables that stay in cache instead of one of 2 MB).
    directivity_table : ndarray (SINE_STEPS + 1, n_bins) float32
        2 J1(x)/x at x = k a s, s = i / SINE_STEPS.
    absorption_table : ndarray (n_lengths, n_bins) float32
        10^(-alpha(f_k) L / 20) at L = i LENGTH_STEP_M (held beyond the last entry).
    """

    length: int
    centre: int
    max_spread: float
    phase_coarse: NDArray[np.float32] = field(repr=False)
    phase_fine: NDArray[np.float32] = field(repr=False)
    delay_steps: int
    directivity_table: NDArray[np.float32] = field(repr=False)
    absorption_table: NDArray[np.float32] = field(repr=False)

    @classmethod
    def create(
        cls, length: int, centre: int, max_spread: float, bins_hz: NDArray[np.float64], pulse: Pulse,
        medium: Medium, radius_m: float, fs_dec: float, max_length_m: float,
    ) -> "KernelPlan":
        """Tabulate the factors of a kernel's spectrum on its bins ``bins_hz`` (Hz)."""
        delay_steps = 1 << int(math.ceil(math.log2(1.0 / (fs_dec * DELAY_RESOLUTION_S))))
        fine_steps = min(FINE_DELAY_STEPS, delay_steps)
        k = np.arange(bins_hz.size)
        coarse_shift = centre + np.arange(delay_steps // fine_steps + 1) * (fine_steps / delay_steps)
        coarse = np.exp(-2j * np.pi * np.multiply.outer(coarse_shift, k) / length)
        coarse *= fs_dec * pulse_spectrum(pulse, bins_hz)
        fine = np.exp(-2j * np.pi * np.multiply.outer(np.arange(fine_steps) / delay_steps, k) / length)
        # 2 J1(x)/x on a fine x grid (64 per unit: linear interpolation error h^2/32 < 1e-5),
        # through the shared piston model (x = k a sin(theta) with f = x / (2 pi), a = c = 1).
        kappa = 2.0 * np.pi * bins_hz * radius_m / medium.sound_speed
        x_grid = np.arange(int(math.ceil((kappa[-1] if kappa.size else 1.0) * 64)) + 2) / 64.0
        jinc = piston_directivity(0.5 * np.pi, x_grid / (2.0 * np.pi), 1.0, 1.0)
        sines = np.arange(SINE_STEPS + 1) / SINE_STEPS
        directivity = np.interp(np.multiply.outer(sines, kappa), x_grid, jinc)
        lengths = np.arange(int(math.ceil(max_length_m / LENGTH_STEP_M)) + 1) * LENGTH_STEP_M
        absorption = 10.0 ** (-np.multiply.outer(lengths, medium.absorption_db_per_m(bins_hz)) / 20.0)
        return cls(
            length, centre, max_spread, _split(coarse), _split(fine), delay_steps, directivity.astype(np.float32),
            absorption.astype(np.float32),
        )


@dataclass(frozen=True, eq=False)
class PathSynthesiser:
    """Turns path rows into the full-rate spectra of the pressure at the three receivers.

    Build it with :meth:`create`. Attributes are derived, read-only.

    Attributes
    ----------
    pulse : GaussianPulse or SampledPulse
    medium : Medium
    piston_radius_m : float
    sound_speed_m_s : float
        Used for the directivity's wavenumber.
    grid : RecordGrid
    plans : tuple of KernelPlan
        Kernel sizes, shortest first; each row takes the shortest that holds its echo (near-axis
        rows need about half the samples of rows at 90 deg).
    band_top_hz : float
        Highest synthesised frequency (Hz): where the pulse's spectrum falls
        :data:`SYNTHESIS_BAND_DB` below its peak, at most the decimated Nyquist frequency.
    """

    pulse: Pulse
    medium: Medium
    piston_radius_m: float
    sound_speed_m_s: float
    grid: RecordGrid
    plans: tuple[KernelPlan, ...]
    band_top_hz: float

    @classmethod
    def create(cls, sonar: SonarHead, medium: Medium, padding_s: float = 0.0) -> "PathSynthesiser":
        """Plan the synthesis for a sonar (pulse, pistons, digitiser) in a medium.

        Parameters
        ----------
        sonar : SonarHead
        medium : Medium
        padding_s : float
            Extra zero padding (s) after the record in the FFT (the band-pass's settling time).

        Raises
        ------
        InputError
            The sample rate is below twice the pulse's band top (its -40 dB frequency).
        """
        pulse = sonar.pulse
        fs = float(sonar.sample_rate_hz)
        band_top = pulse_band_top_hz(pulse, NYQUIST_BAND_DB)
        if fs < 2.0 * band_top:
            raise InputError(
                f"sonar.sample_rate_hz = {fs:g} Hz is below twice the pulse's band top ({band_top:g} Hz, "
                f"where its spectrum is {-NYQUIST_BAND_DB:g} dB down): raise the sample rate"
            )
        synth_top = pulse_band_top_hz(pulse, SYNTHESIS_BAND_DB)
        decimation = max(1, int(math.floor(fs / (2.0 * 1.05 * synth_top))))
        fs_dec = fs / decimation
        synth_top = min(synth_top, 0.5 * fs_dec)
        c = float(medium.sound_speed)
        radius = float(sonar.piston_radius_m)
        start, stop = pulse_support_s(pulse)
        per_spread = radius / c  # directivity kernel half-width per unit sin(theta), each side
        pulse_span = (stop - start) * fs_dec + 6.0
        longest = 1 << int(math.ceil(math.log2(pulse_span + 4.0 * per_spread * fs_dec)))
        lengths = [n for n in (longest // 2, longest) if n >= pulse_span + 2]
        # Longest path that can still reach the record (m), with a margin for hand-made rows.
        max_length = c * (float(sonar.record_length_s) + padding_s) + 10.0
        plans = []
        for length in lengths:
            max_spread = min(2.0, (length - pulse_span) / (2.0 * per_spread * fs_dec))
            centre = int(math.ceil(-start * fs_dec + max_spread * per_spread * fs_dec)) + 3
            n_bins = min(int(math.floor(synth_top / (fs_dec / length))) + 1, length // 2)
            bins = np.arange(n_bins) * (fs_dec / length)
            plans.append(KernelPlan.create(length, centre, max_spread, bins, pulse, medium, radius, fs_dec, max_length))
        padding = padding_s + (longest + 2) / fs_dec
        grid = make_record_grid(fs, int(sonar.n_samples), decimation, padding)
        return cls(pulse, medium, radius, c, grid, tuple(plans), float(synth_top))

    def decimated_record(self, rows: NDArray[Any], *, warn: bool = True,
                         responses: Sequence[EchoResponse] = ()) -> NDArray[np.float64]:
        """The pressure at the three receivers (Pa), (3, M / q), sampled at fs / q.

        Rows with a transfer function (``response_id`` >= 0, an entry of ``responses``) or a
        rough reflection (``roughness_m2`` > 0) are synthesised on kernels of their own
        (:mod:`acoustisim.synthesis.spectral_rows`); every other row as follows.

        Every row keeps its own spectrum (its exact weight, fractional delay, directivities and
        absorption, to the tables' resolution). Rows of one kernel size that start on the same
        sample of the same channel have their spectra summed before one inverse FFT (exact:
        the transform is linear), built in blocks of ``CHUNK_ROWS`` groups by the compiled
        loops of :mod:`acoustisim.synthesis.row_kernels` and one batched inverse FFT.
        Kernel samples before t = 0 or past the record's end are dropped; when whole arrivals
        fall past the end a warning says how many (the rest is kept).
        """
        from scipy.fft import irfft

        from acoustisim.synthesis.row_kernels import (
            ROWS_OK, fill_group_spectra, group_rows, overlap_add, row_parameters,
        )

        m_dec = self.grid.n_fft_decimated
        keep = int(math.ceil(self.grid.n_samples / self.grid.decimation)) + 1
        fs_dec = self.grid.sample_rate_hz / self.grid.decimation
        record = np.zeros((3, m_dec))
        # Strided views, no copies (a copy only for non-native byte order, which numba rejects).
        columns = {name: rows[name].astype(rows[name].dtype.newbyteorder("="), copy=False) for name in ROW_COLUMNS}
        if rows.size == 0:
            return record
        special = needs_spectral_path(rows)
        if special.any():
            add_spectral_rows(record, rows[special], responses, pulse=self.pulse, medium=self.medium,
                              radius_m=self.piston_radius_m, sound_speed_m_s=self.sound_speed_m_s, fs_dec=fs_dec,
                              band_top_hz=self.band_top_hz, keep=keep)
            rows = rows[~special]
            columns = {name: rows[name].astype(rows[name].dtype.newbyteorder("="), copy=False) for name in ROW_COLUMNS}
            if rows.size == 0:
                return record
        plans = self.plans
        status, plan, first, i_tx, i_rx, i_len, i_frac, weight = row_parameters(
            *(columns[name] for name in ROW_COLUMNS),
            fs_dec,
            SINE_STEPS,
            LENGTH_STEP_M,
            plans[0].delay_steps,
            np.array([p.max_spread for p in plans]),
            np.array([p.centre for p in plans], dtype=np.int64),
            np.array([p.length for p in plans], dtype=np.int64),
            keep,
        )
        if status != ROWS_OK:
            check_columns(columns)  # raises InputError naming the column, row and value
            raise InputError(f"paths: invalid row {status}")  # unreachable: check_columns names it
        late = plan == -2
        if warn and np.any(late):
            lost = np.unique(rows["path_id"][late]).size
            warnings.warn(
                f"record_length_s = {self.grid.n_samples / self.grid.sample_rate_hz:g} s is too short for "
                f"{lost} arrival(s) (latest delay {columns['delay_s'].max():.6g} s): they are left out",
                UserWarning,
                stacklevel=3,
            )
        longest = max(p.length for p in plans)
        span = keep + plans[-1].centre + 2 * longest
        for plan_number, kernel_plan in enumerate(plans):
            members, bounds, group_first, group_channel = group_rows(
                plan, first, columns["channel"], plan_number, -longest, span
            )
            for g0 in range(0, group_first.size, CHUNK_ROWS):
                g1 = min(g0 + CHUNK_ROWS, group_first.size)
                spectra = np.empty((g1 - g0, kernel_plan.length // 2 + 1), dtype=np.complex64)
                fill_group_spectra(
                    members, bounds, g0, i_tx, i_rx, i_len, i_frac, weight, kernel_plan.phase_coarse, kernel_plan.phase_fine,
                    kernel_plan.directivity_table, kernel_plan.absorption_table, spectra,
                )
                kernels = irfft(spectra, n=kernel_plan.length, axis=1, overwrite_x=True)
                overlap_add(kernels, group_first[g0:g1], group_channel[g0:g1], keep, record)
        return record

    def spectrum(self, rows: NDArray[Any], *, warn: bool = True,
                 responses: Sequence[EchoResponse] = ()) -> NDArray[np.complex128]:
        """Full-rate rfft (3, M//2 + 1) of the pressure at the receivers (Pa per sample).

        X[k] = q X_dec[k] below the decimated Nyquist frequency, 0 above (the signal has no
        energy there: the pulse is below -100 dB).
        """
        q = self.grid.decimation
        m_dec = self.grid.n_fft_decimated
        spectrum_dec = np.fft.rfft(self.decimated_record(rows, warn=warn, responses=responses), axis=1)
        full = np.zeros((3, self.grid.n_fft // 2 + 1), dtype=complex)
        top = m_dec // 2 if q > 1 else m_dec // 2 + 1
        full[:, :top] = q * spectrum_dec[:, :top]
        return full


def _split(table: NDArray[np.complex128]) -> NDArray[np.float32]:
    """(2, ...) float32 real and imaginary parts of a complex table, each contiguous."""
    return np.ascontiguousarray(np.stack([table.real, table.imag]), dtype=np.float32)


ROW_COLUMNS: tuple[str, ...] = (
    "delay_s", "path_length_m", "geometric_gain", "phase_rad", "angle_tx_rad", "angle_rx_rad", "channel",
)
"""The path-row columns synthesis reads."""


def check_columns(columns: dict[str, NDArray[Any]]) -> None:
    """Raise InputError when path columns hold NaN/inf or impossible values."""
    names = ROW_COLUMNS[:-1]
    total = np.zeros(columns["delay_s"].size)
    for name in names:
        total += columns[name]  # NaN or inf anywhere makes the sum non-finite (inf - inf is NaN)
    for name in names if not np.all(np.isfinite(total)) else ():
        values = columns[name]
        if not np.all(np.isfinite(values)):
            bad = int(np.flatnonzero(~np.isfinite(values))[0])
            raise InputError(f"paths.{name} holds a non-finite value at row {bad}: {values[bad]!r}")
    channel = columns["channel"]
    if channel.size and (channel.min() < 0 or channel.max() > 2):
        raise InputError(f"paths.channel must be 0, 1 or 2, got {sorted(set(channel.tolist()))}")
    if channel.size and columns["path_length_m"].min() < 0:
        raise InputError("paths.path_length_m holds negative values")

