"""Paths -> band-limited pressure signals at the receivers, each path at its exact delay.

Every path row is the impulse ``geometric_gain * delta(t - delay_s)`` with the constant phase
``phase_rad`` (``acoustisim.propagation.paths``). Its echo at a receiver face is, per frequency,

    P(f) = g Q(f) D(theta_tx, f) D(theta_rx, f) 10^(-alpha(f) L / 20) exp(j phi) exp(-j 2 pi f tau),

Q the pulse's spectrum, D the piston directivity 2 J1(x)/x (``propagation/directivity.py``; 0
beyond 90 deg: nothing radiates behind the baffle), alpha the medium's
absorption (dB/m) over the path length L. Edge elements sharing a ``path_id`` are summed like
any row, so the band-limited Biot-Tolstoy-Medwin response (the half-integrated pulse) comes
out of the sum by itself.

Method (fast for 10^4 and more rows, no loop per row or sample): the signals are band-limited
well below the digitiser's Nyquist frequency, so they are built on a grid decimated by ``q``.
For a chunk of rows, a (rows, bins) matrix of short-kernel spectra on an ``Lk``-point grid
(only the bins inside the pulse's band) is assembled from per-bin lookup tables planned once
(directivity against sin(theta), absorption against path length, pulse spectrum times the
fractional-delay phase ramp against the fraction of a sample), inverse FFT'd to (rows, Lk)
kernels holding each echo sampled at its fractional delay, and scatter-added (``np.bincount``
on flat indices) into the decimated record. One FFT of that record, zero-padded in frequency
by ``q``, gives the full-rate spectrum that the receiver chain then shapes. Rows on one
channel that start on the same sample with nearly the same shape (the close-spaced elements
of a diffracting edge) share one kernel, each keeping its exact weight and delay (see
``decimated_record``). Memory: O(chunk x Lk) plus O(record) plus the tables (a few MB).

Table resolutions (nearest entry): sin(theta) in steps of 1/8192 (directivity error below
7e-4 absolute at the centre frequency, 0.02 dB where D = 0.3), path length in 1 cm steps
(absorption error below 3e-5 relative at 500 kHz), delay in steps of at most 0.05 ns (a
power-of-two fraction of a decimated sample: the echo's error is below 1e-4 of its peak at
500 kHz and its delay is exact to 0.025 ns).
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from acoustisim.errors import InputError
from acoustisim.medium import Medium
from acoustisim.sonar import SonarHead
from acoustisim.propagation.directivity import piston_directivity
from acoustisim.synthesis.transducer import Pulse, pulse_band_top_hz, pulse_spectrum, pulse_support_s

SYNTHESIS_BAND_DB = -100.0
"""Pulse spectrum level (dB re its peak) above which bins are synthesised; the rest (< 1e-5
relative) is dropped."""

NYQUIST_BAND_DB = -40.0
"""The pulse's band top is where its spectrum falls 40 dB below the peak: the sample rate must
be at least twice that frequency."""

CHUNK_ROWS = 8192
"""Rows per vectorised block (bounds the (rows, Lk) working arrays to a few MB)."""

SINE_STEPS = 8192
"""Directivity table: entries per unit of sin(theta)."""

DELAY_RESOLUTION_S = 5e-11
"""Phase-ramp table: fractional-delay step at most this (s); 8192 steps per sample at 20 MS/s / 7."""

LENGTH_STEP_M = 0.01
"""Absorption table: path-length step (m)."""

MERGE_SINE_STEPS = 8
"""Rows on one sample share a kernel when their sin(theta) agree within 8 / SINE_STEPS (1e-3):
the group's mean is then within 5e-4 of each row's, a directivity error below 6e-3 at 500 kHz."""

MERGE_LENGTH_STEPS = 16
"""... and their path lengths within 16 LENGTH_STEP_M (0.16 m: absorption error < 1e-3 at 500 kHz)."""


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
    phase_table : ndarray (delay_steps + 1, n_bins) complex64
        fs_dec Q(f_k) exp(-j 2 pi k (centre + u / delay_steps) / Lk): the sampled pulse with its
        reference instant at centre + u / delay_steps samples.
    directivity_table : ndarray (SINE_STEPS + 1, n_bins) float32
        2 J1(x)/x at x = k a s, s = i / SINE_STEPS.
    absorption_table : ndarray (n_lengths, n_bins) float32
        10^(-alpha(f_k) L / 20) at L = i LENGTH_STEP_M (held beyond the last entry).
    """

    length: int
    centre: int
    max_spread: float
    phase_table: NDArray[np.complex64] = field(repr=False)
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
        # exp(-j 2 pi k shift / Lk) as running powers over k (one multiply per entry).
        shift = centre + np.arange(delay_steps + 1) / delay_steps
        phase = np.empty((delay_steps + 1, bins_hz.size), dtype=complex)
        phase[:, :1] = 1.0
        phase[:, 1:] = np.exp(-2j * np.pi * shift / length)[:, None]
        np.cumprod(phase, axis=1, out=phase)
        phase *= fs_dec * pulse_spectrum(pulse, bins_hz)
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
            length, centre, max_spread, phase.astype(np.complex64), delay_steps, directivity.astype(np.float32),
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
    """

    pulse: Pulse
    medium: Medium
    piston_radius_m: float
    sound_speed_m_s: float
    grid: RecordGrid
    plans: tuple[KernelPlan, ...]

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
        return cls(pulse, medium, radius, c, grid, tuple(plans))

    @staticmethod
    def _kernels(
        plan: KernelPlan,
        i_tx: NDArray[np.intp],
        i_rx: NDArray[np.intp],
        i_len: NDArray[np.intp],
        ramps: NDArray[np.complex64],
    ) -> NDArray[np.float32]:
        """(groups, Lk) kernels at fs / q from each group's table indices and summed ramps."""
        from scipy.fft import irfft

        n_groups, n_bins = ramps.shape
        # Real factors in float32, applied to the complex ramps in place (numpy's complex64 x
        # float32 loop: twice as fast as a broadcast over the float32 view's pairs).
        real = np.take(plan.directivity_table, i_tx, axis=0)
        real *= np.take(plan.directivity_table, i_rx, axis=0)
        real *= np.take(plan.absorption_table, np.minimum(i_len, plan.absorption_table.shape[0] - 1), axis=0)
        ramps *= real
        full = np.zeros((n_groups, plan.length // 2 + 1), dtype=np.complex64)
        full[:, :n_bins] = ramps
        return irfft(full, n=plan.length, axis=1)

    def decimated_record(self, rows: NDArray[Any], *, warn: bool = True) -> NDArray[np.float64]:
        """The pressure at the three receivers (Pa), (3, M / q), sampled at fs / q.

        Rows on the same channel whose echoes start on the same sample and whose directivity
        and absorption indices agree within ``MERGE_SINE_STEPS`` / ``MERGE_LENGTH_STEPS`` (the
        close-spaced elements of a diffracting edge, mostly) share one kernel: each keeps its
        exact weight and fractional delay, the shared factors take the group's |weight|-mean
        indices. A row alone in its group is synthesised exactly as it is.

        Kernel samples before t = 0 or past the record's end are dropped; when whole arrivals
        fall past the end a warning says how many (the rest is kept).
        """
        from scipy import sparse

        m_dec = self.grid.n_fft_decimated
        keep = int(math.ceil(self.grid.n_samples / self.grid.decimation)) + 1
        fs_dec = self.grid.sample_rate_hz / self.grid.decimation
        out = np.zeros(3 * m_dec)
        # Contiguous copies of the columns used, read in one pass over the (wide) structured
        # rows: the float columns as one (rows, 6) strided view, transposed into a copy.
        from numpy.lib.recfunctions import structured_to_unstructured

        floats = np.ascontiguousarray(
            structured_to_unstructured(rows[list(ROW_COLUMNS[:-1])], dtype=np.float64, copy=False).T
        )
        columns = dict(zip(ROW_COLUMNS[:-1], floats))
        columns["channel"] = np.ascontiguousarray(rows["channel"])
        check_columns(columns)
        if rows.size == 0:
            return out.reshape(3, m_dec)
        position = columns["delay_s"] * fs_dec
        whole = np.floor(position)
        late = whole - self.plans[-1].centre >= keep
        if warn and np.any(late):
            lost = np.unique(rows["path_id"][late]).size
            warnings.warn(
                f"record_length_s = {self.grid.n_samples / self.grid.sample_rate_hz:g} s is too short for "
                f"{lost} arrival(s) (latest delay {columns['delay_s'].max():.6g} s): they are left out",
                UserWarning,
                stacklevel=3,
            )
        angle_tx, angle_rx = columns["angle_tx_rad"], columns["angle_rx_rad"]
        sin_tx, sin_rx = np.abs(np.sin(angle_tx)), np.abs(np.sin(angle_rx))
        # A baffled piston radiates (and receives) only in front of its face: D = 0 beyond
        # 90 deg off axis (the housing), as in propagation.directivity (cos(angle) >= 0, i.e.
        # |angle| <= pi/2 in doubles, is the front).
        front = (np.abs(angle_tx) <= 0.5 * np.pi) & (np.abs(angle_rx) <= 0.5 * np.pi)
        phase = columns["phase_rad"]
        gain = columns["geometric_gain"] * front
        weight = np.empty(rows.size, dtype=np.complex64)
        if np.any(phase != 0.0):
            weight.real = gain * np.cos(phase)
            weight.imag = gain * np.sin(phase)
        else:
            weight.real = gain
            weight.imag = 0.0
        i_tx = np.rint(sin_tx * SINE_STEPS).astype(np.int64)
        i_rx = np.rint(sin_rx * SINE_STEPS).astype(np.int64)
        i_len = np.rint(columns["path_length_m"] * (1.0 / LENGTH_STEP_M)).astype(np.int64)
        frac = position - whole
        sample = columns["channel"].astype(np.int64) * m_dec + whole.astype(np.int64)
        limits = np.array([plan.max_spread for plan in self.plans])
        which = np.minimum(np.searchsorted(limits, sin_tx + sin_rx, side="left"), len(self.plans) - 1)
        for plan_number, plan in enumerate(self.plans):
            selected = np.flatnonzero((which == plan_number) & ~late & (whole - plan.centre + plan.length > 0))
            if selected.size == 0:
                continue
            # Group rows by (channel and start sample, coarse sin_tx, sin_rx, path length).
            key = (
                (sample[selected] * (SINE_STEPS // MERGE_SINE_STEPS + 1) + i_tx[selected] // MERGE_SINE_STEPS)
                * (SINE_STEPS // MERGE_SINE_STEPS + 1)
                + i_rx[selected] // MERGE_SINE_STEPS
            ) * (int(i_len.max()) // MERGE_LENGTH_STEPS + 1) + i_len[selected] // MERGE_LENGTH_STEPS
            order, key = _stable_order(key, selected)
            starts = np.flatnonzero(np.r_[True, key[1:] != key[:-1]])
            bounds = np.r_[starts, order.size]
            offsets = np.arange(plan.length)
            group_chunk = max(1, CHUNK_ROWS)
            for g0 in range(0, starts.size, group_chunk):
                g1 = min(g0 + group_chunk, starts.size)
                members = order[bounds[g0] : bounds[g1]]
                local = bounds[g0:g1] - bounds[g0]
                w = weight[members]
                ramps = np.take(plan.phase_table, np.rint(frac[members] * plan.delay_steps).astype(np.intp), axis=0)
                ramps *= w[:, None]
                if members.size > g1 - g0:  # some groups hold several rows: sum them
                    # Segmented sums as a sparse (groups x rows) product (one pass, in C).
                    summing = sparse.csr_matrix(
                        (np.ones(members.size, dtype=np.float32), np.arange(members.size), np.r_[local, members.size]),
                        shape=(g1 - g0, members.size),
                    )
                    ramps = np.asarray(summing @ ramps, dtype=np.complex64)
                    magnitude = np.abs(w).astype(np.float64) + 1e-300
                    shares = np.column_stack([magnitude * v[members] for v in (i_tx, i_rx, i_len)] + [magnitude])
                    sums = summing.astype(np.float64) @ shares
                    g_tx, g_rx, g_len = (np.rint(sums[:, j] / sums[:, 3]).astype(np.intp) for j in range(3))
                else:
                    g_tx, g_rx, g_len = i_tx[members], i_rx[members], i_len[members]
                kernels = self._kernels(plan, g_tx, g_rx, g_len, ramps)
                first = members[local]
                start = whole[first].astype(np.int64) - plan.centre
                flat = (sample[first] - plan.centre)[:, None] + offsets
                if np.all((start >= 0) & (start + plan.length <= keep)):
                    out += np.bincount(flat.ravel(), weights=kernels.ravel(), minlength=3 * m_dec)
                else:
                    index = start[:, None] + offsets
                    valid = (index >= 0) & (index < keep)
                    out += np.bincount(flat[valid], weights=kernels[valid], minlength=3 * m_dec)
        return out.reshape(3, m_dec)

    def spectrum(self, rows: NDArray[Any], *, warn: bool = True) -> NDArray[np.complex128]:
        """Full-rate rfft (3, M//2 + 1) of the pressure at the receivers (Pa per sample).

        X[k] = q X_dec[k] below the decimated Nyquist frequency, 0 above (the signal has no
        energy there: the pulse is below -100 dB).
        """
        q = self.grid.decimation
        m_dec = self.grid.n_fft_decimated
        spectrum_dec = np.fft.rfft(self.decimated_record(rows, warn=warn), axis=1)
        full = np.zeros((3, self.grid.n_fft // 2 + 1), dtype=complex)
        top = m_dec // 2 if q > 1 else m_dec // 2 + 1
        full[:, :top] = q * spectrum_dec[:, :top]
        return full


def _stable_order(key: NDArray[np.int64], items: NDArray[np.intp]) -> tuple[NDArray[np.intp], NDArray[np.int64]]:
    """``items`` and ``key`` (both (n,), key >= 0) sorted by key, ties in their given order.

    When key x n fits in int64, the position is appended to the key: the keys are then
    distinct, and the (4x faster, SIMD) unstable sort gives exactly the stable order.
    """
    n = key.size
    if n and (int(key.max()) + 1) * n < 2**63:
        by_key = np.argsort(key * n + np.arange(n))
    else:
        by_key = np.argsort(key, kind="stable")
    return items[by_key], key[by_key]


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

