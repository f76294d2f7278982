"""Paths -> band-limited pressure signals at the receivers, each path at its exact delay.

Every path row is the impulse ``geometric_gain * delta(t - delay_s)`` with the constant phase
``phase_rad`` (``acoustisim.propagation.paths``). Its echo at a receiver face is, per frequency,

    P(f) = g Q(f) D(theta_tx, f) D(theta_rx, f) 10^(-alpha(f) L / 20) exp(j phi) exp(-j 2 pi f tau),

Q the pulse's spectrum, D the piston directivity 2 J1(x)/x (``propagation/directivity.py``; 0 at
and beyond 90 deg: nothing radiates behind the baffle), alpha the medium's
absorption (dB/m) over the path length L. Edge elements sharing a ``path_id`` are summed like
any row, so the band-limited Biot-Tolstoy-Medwin response (the half-integrated pulse) comes
out of the sum by itself.

Method (fast for 10^4 and more rows, no loop per row or sample): the signals are band-limited
well below the digitiser's Nyquist frequency, so they are built on a grid decimated by ``q``.
For a chunk of rows, a (rows, bins) matrix of short-kernel spectra on an ``Lk``-point grid
(only the bins inside the pulse's band) is evaluated in one vectorised expression, inverse
FFT'd to (rows, Lk) kernels holding each echo sampled at its fractional delay, and
scatter-added (``np.bincount`` on flat indices) into the decimated record. One FFT of that
record, zero-padded in frequency by ``q``, gives the full-rate spectrum that the receiver
chain then shapes. Memory: O(chunk x Lk) plus O(record).
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
from acoustisim.synthesis.transducer import JincTable, Pulse, pulse_band_top_hz, pulse_spectrum, pulse_support_s

SYNTHESIS_BAND_DB = -100.0
"""Pulse spectrum level (dB re its peak) above which bins are synthesised; the rest (< 1e-5
relative) is dropped."""

NYQUIST_BAND_DB = -40.0
"""The pulse's band top is where its spectrum falls 40 dB below the peak: the sample rate must
be at least twice that frequency."""

CHUNK_ROWS = 8192
"""Rows per vectorised block (bounds the (rows, Lk) working arrays to a few MB)."""


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
    """One kernel size: rows whose echo spans fewer than ``length`` samples at fs / q use it.

    Attributes
    ----------
    length : int
        Lk, kernel samples at fs / q (a power of two).
    centre : int
        Index of the pulse's reference instant in a kernel, before the fractional shift.
    max_spread : float
        Largest |sin theta_tx| + |sin theta_rx| the kernel holds without wrap-around.
    base : ndarray (n_bins,) complex64
        fs_dec Q(f_k) exp(-j 2 pi k centre / Lk) on the synthesised bins.
    alpha : ndarray (n_bins,) float32
        Absorption (Np/m) at the bins.
    kappa : ndarray (n_bins,) float32
        2 pi f a / c: the directivity's argument per unit sin(theta).
    """

    length: int
    centre: int
    max_spread: float
    base: NDArray[np.complex64] = field(repr=False)
    alpha: NDArray[np.float32] = field(repr=False)
    kappa: NDArray[np.float32] = field(repr=False)


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
    _jinc: JincTable = field(repr=False)

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
        plans = []
        for length in lengths:
            max_spread = min(2.0, (length - pulse_span) / (2.0 * per_spread * fs_dec))
            centre = int(math.ceil(-start * fs_dec + max_spread * per_spread * fs_dec)) + 3
            n_bins = min(int(math.floor(synth_top / (fs_dec / length))) + 1, length // 2)
            bins = np.arange(n_bins) * (fs_dec / length)
            # Sampled echo with its reference instant at `centre`: fs_dec Q(f) exp(-j 2 pi k centre / Lk).
            base = fs_dec * pulse_spectrum(pulse, bins) * np.exp(-2j * np.pi * np.arange(n_bins) * centre / length)
            alpha = medium.absorption_db_per_m(bins) * (math.log(10.0) / 20.0)
            kappa = 2.0 * np.pi * bins * radius / c
            plans.append(
                KernelPlan(length, centre, max_spread, base.astype(np.complex64), alpha.astype(np.float32),
                           kappa.astype(np.float32))
            )
        padding = padding_s + (longest + 2) / fs_dec
        grid = make_record_grid(fs, int(sonar.n_samples), decimation, padding)
        x_max = float(plans[-1].kappa[-1]) if plans[-1].kappa.size else 1.0
        return cls(pulse, medium, radius, c, grid, tuple(plans), JincTable(x_max + 1.0))

    def _kernels(self, rows: NDArray[Any], plan: KernelPlan, frac: NDArray[np.float64]) -> NDArray[np.float32]:
        """(rows, Lk) kernels at fs / q; row i's reference instant at plan.centre + frac_i."""
        n_bins = plan.base.size
        # A baffled piston radiates (and receives) only in front of its face: D = 0 at and
        # beyond 90 deg off axis (the housing), not the mirror of the front lobe.
        s_tx = np.where(np.abs(rows["angle_tx_rad"]) < 0.5 * np.pi, np.abs(np.sin(rows["angle_tx_rad"])), -1.0)
        s_rx = np.where(np.abs(rows["angle_rx_rad"]) < 0.5 * np.pi, np.abs(np.sin(rows["angle_rx_rad"])), -1.0)
        spectra = self._jinc(np.multiply.outer(np.abs(s_tx).astype(np.float32), plan.kappa))
        spectra *= self._jinc(np.multiply.outer(np.abs(s_rx).astype(np.float32), plan.kappa))
        spectra *= np.exp(np.multiply.outer(-rows["path_length_m"].astype(np.float32), plan.alpha))
        weight = rows["geometric_gain"] * np.exp(1j * rows["phase_rad"]) * ((s_tx >= 0) & (s_rx >= 0))
        # Fractional delay exp(-j 2 pi k frac / Lk) by a running product over the bins.
        step = np.exp(-2j * np.pi * frac / plan.length).astype(np.complex64)
        ramp = np.empty((rows.size, n_bins), dtype=np.complex64)
        ramp[:, 0] = weight
        ramp[:, 1:] = step[:, None]
        np.cumprod(ramp, axis=1, out=ramp)
        full = np.zeros((rows.size, plan.length // 2 + 1), dtype=np.complex64)
        np.multiply(ramp * plan.base, spectra, out=full[:, :n_bins])
        from scipy.fft import irfft

        return irfft(full, n=plan.length, axis=1)

    def _plan_index(self, rows: NDArray[Any]) -> NDArray[np.intp]:
        spread = np.abs(np.sin(rows["angle_tx_rad"])) + np.abs(np.sin(rows["angle_rx_rad"]))
        limits = np.array([plan.max_spread for plan in self.plans])
        return np.minimum(np.searchsorted(limits, spread, side="left"), len(self.plans) - 1)

    def decimated_record(self, rows: NDArray[Any], *, warn: bool = True) -> NDArray[np.float64]:
        """The pressure at the three receivers (Pa), (3, M / q), sampled at fs / q.

        Kernel samples before t = 0 or past the record's end are dropped; when whole arrivals
        fall past the end a warning says how many (the rest is kept).
        """
        check_rows(rows)
        m_dec = self.grid.n_fft_decimated
        keep = int(math.ceil(self.grid.n_samples / self.grid.decimation)) + 1
        fs_dec = self.grid.sample_rate_hz / self.grid.decimation
        out = np.zeros(3 * m_dec)
        if rows.size == 0:
            return out.reshape(3, m_dec)
        position = rows["delay_s"] * fs_dec
        whole = np.floor(position)
        late = whole - self.plans[-1].centre >= keep
        if warn and np.any(late):
            lost = np.unique(rows["path_id"][late]).size
            warnings.warn(
                f"record_length_s = {self.grid.n_samples / self.grid.sample_rate_hz:g} s is too short for "
                f"{lost} arrival(s) (latest delay {rows['delay_s'].max():.6g} s): they are left out",
                UserWarning,
                stacklevel=3,
            )
        which = self._plan_index(rows)
        for plan_number, plan in enumerate(self.plans):
            selected = np.flatnonzero((which == plan_number) & ~late & (whole - plan.centre + plan.length > 0))
            offsets = np.arange(plan.length)
            for lo in range(0, selected.size, CHUNK_ROWS):
                index_rows = selected[lo : lo + CHUNK_ROWS]
                chunk = rows[index_rows]
                kernels = self._kernels(chunk, plan, position[index_rows] - whole[index_rows])
                start = whole[index_rows].astype(np.int64) - plan.centre
                flat = (chunk["channel"].astype(np.int64) * m_dec + start)[:, None] + offsets
                inside = (start >= 0) & (start + plan.length <= keep)
                if np.all(inside):
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


def check_rows(rows: NDArray[Any]) -> None:
    """Raise InputError when path rows hold NaN/inf or impossible values."""
    for name in ("delay_s", "path_length_m", "geometric_gain", "phase_rad", "angle_tx_rad", "angle_rx_rad"):
        values = rows[name]
        if not np.all(np.isfinite(values)):
            bad = int(np.flatnonzero(~np.isfinite(values))[0])
            raise InputError(f"paths.{name} holds a non-finite value at row {bad}: {values[bad]!r}")
    if rows.size and (np.any(rows["channel"] < 0) or np.any(rows["channel"] > 2)):
        raise InputError(f"paths.channel must be 0, 1 or 2, got {sorted(set(rows['channel'].tolist()))}")
    if rows.size and np.any(rows["path_length_m"] < 0):
        raise InputError("paths.path_length_m holds negative values")
