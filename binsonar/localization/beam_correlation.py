"""The correlation of a record with an expected echo spectrum, and its continuous maximum.

Shared by the beam-aware refinement (``beam_refine``) and the cued search of a missing echo
(``beam_cue``). For a record segment with spectrum X (absolute-time phases) and an expected echo
A referred to its reference instant,

    z(tau) = sum_{f > 0} X(f) conj(A(f)) exp(j 2 pi f tau),

the analytic correlation at delay tau: for a noise-free echo x = a(t - tau_0), |z| is largest
at tau_0 exactly (triangle inequality), so the reference delay needs no calibration.

Method: the segment (``segment_spectra``) is long enough to hold the whole expected echo for
every searched delay (``CorrelationGrid``), so the circular correlation equals the linear one;
the maximum is found on a half-sample grid (one inverse FFT when the frequencies lie on an rfft
grid, ``correlation_maximum``) and polished by Newton's method on |z|^2, whose derivatives are
exact sums over the band.

Accuracy: bins below ``TEMPLATE_BAND_FLOOR`` of the template's peak are left out (~1e-10 of its
energy: far below a picosecond of TOF); Newton's steps reach 1e-15 s from within a quarter
sample of the peak.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np
from numpy.typing import NDArray

from binsonar.localization.beam_model import BeamModelConfig, PistonTransducers
from binsonar.recording import RecordingError, Template

TEMPLATE_BAND_FLOOR = 1e-5
"""Bins where the template's spectrum is below this fraction of its peak are left out of the
correlation (they carry ~1e-10 of its energy: the TOF changes by far below a picosecond)."""
STEP_BAND_DB = -30.0
"""The line integral's grid is fine enough at the template's highest frequency this far below its
peak (``BeamModelConfig.step_frequency_hz``)."""
NEWTON_STEPS = 6
"""Newton steps on |z|^2 from the best half-sample grid point: quadratic convergence from within a
quarter sample of the peak reaches 1e-15 s in 3-4 steps."""


def template_spectrum(template: Template, n_fft: int, bins: NDArray[np.intp]) -> NDArray[np.complex128]:
    """T(f_k) = sum_n s[n] exp(-j 2 pi f_k (t0 + n / fs)) at f_k = k fs / n_fft: the template's DTFT
    referred to its reference instant, on the rfft bins ``bins`` (shape (k,)) of an n_fft grid
    (n_fft >= the template's length)."""
    import scipy.fft as sfft

    s = np.asarray(template.samples, dtype=float)
    if n_fft < s.size:
        raise RecordingError(f"beam refinement: FFT length {n_fft} is shorter than the template ({s.size} samples)")
    f = np.asarray(bins) * (float(template.sample_rate_hz) / n_fft)
    return sfft.rfft(s, n_fft)[bins] * np.exp(-2j * np.pi * f * template.t0_s)


def _band(template: Template, n_fft: int) -> tuple[NDArray[np.float64], float]:
    """The rfft frequencies (Hz) of an n_fft grid where the template has energy (>= TEMPLATE_BAND_FLOOR of
    its peak), and the highest frequency where it is within ``STEP_BAND_DB`` of its peak (Hz)."""
    import scipy.fft as sfft

    fs = float(template.sample_rate_hz)
    magnitude = np.abs(sfft.rfft(np.asarray(template.samples, dtype=float), n_fft))
    keep = np.flatnonzero(magnitude >= TEMPLATE_BAND_FLOOR * magnitude.max())
    k_lo, k_hi = max(int(keep[0]), 1), int(keep[-1]) + 1  # DC never (the record's offset sits there)
    top = int(np.flatnonzero(magnitude >= 10.0 ** (STEP_BAND_DB / 20.0) * magnitude.max())[-1])
    return np.arange(k_lo, k_hi) * fs / n_fft, top * fs / n_fft


def segment_spectra(rows: NDArray[np.float64], t0_s: float, fs: float, starts_s: NDArray[np.float64], n_fft: int,
              bins: NDArray[np.intp]) -> tuple[NDArray[np.complex128], NDArray[np.float64]]:
    """Spectra (c, k) on ``bins`` of n_fft-sample record segments starting at ``starts_s`` (zeros outside the record).

    Returns the spectra with absolute-time phases, X(f) = sum_n x[n] exp(-j 2 pi f t_n), and the
    segments' start times (s, on the sample grid).
    """
    import scipy.fft as sfft

    n = rows.shape[1]
    first = np.floor((starts_s - t0_s) * fs).astype(np.intp)  # (c,)
    index = first[:, np.newaxis] + np.arange(n_fft)
    inside = (index >= 0) & (index < n)
    segment = np.where(inside, rows[np.arange(rows.shape[0])[:, np.newaxis], np.clip(index, 0, n - 1)], 0.0)
    start = t0_s + first / fs
    spectrum = sfft.rfft(segment, axis=-1)[:, bins]
    return spectrum * np.exp(-2j * np.pi * np.outer(start, bins * fs / n_fft)), start


def correlation_maximum(spectrum: NDArray[np.complex128], expected: NDArray[np.complex128],
                        frequency_hz: NDArray[np.float64], centre_s: NDArray[np.float64],
                        half_width_s: float, fs: float) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Lag of the largest |z(tau)|, z(tau) = sum_k X_k conj(A_k) exp(j 2 pi f_k tau), within a window.

    Parameters
    ----------
    spectrum : ndarray, shape (c, k)
        X with absolute-time phases.
    expected : ndarray, shape (c, k)
        A, the expected echo's spectrum referred to its reference instant.
    frequency_hz : ndarray, shape (k,)
    centre_s : ndarray, shape (c,)
        Centre of each row's search window (s).
    half_width_s : float
        Half-width of the window (s).
    fs : float
        Sample rate (Hz): the search grid's spacing is 1 / (2 fs).

    Returns
    -------
    tau_s : ndarray, shape (c,)
        The continuous maximum (s).
    peak : ndarray, shape (c,)
        |z| there.
    """
    coeff = spectrum * np.conj(expected)  # (c, k)
    omega = 2.0 * np.pi * frequency_hz
    n_half = int(math.ceil(half_width_s * 2.0 * fs))
    offsets = np.arange(-n_half, n_half + 1) / (2.0 * fs)  # half-sample grid covering the window
    half_width_s = float(offsets[-1])
    # Phases relative to each window's centre keep the exponents small (no loss of precision).
    base = coeff * np.exp(1j * np.outer(centre_s, omega))  # (c, k)
    z = _grid_values(base, frequency_hz, offsets)  # (c, g)
    best = np.argmax(np.abs(z), axis=1)
    x = offsets[best]
    for _ in range(NEWTON_STEPS):
        rot = base * np.exp(1j * np.outer(x, omega))
        z0 = rot.sum(axis=1)
        z1 = (rot * (1j * omega)).sum(axis=1)
        z2 = (rot * (-(omega ** 2))).sum(axis=1)
        d1 = 2.0 * np.real(np.conj(z0) * z1)
        d2 = 2.0 * (np.abs(z1) ** 2 + np.real(np.conj(z0) * z2))
        ok = d2 < 0.0
        step = np.where(ok, -d1 / np.where(ok, d2, -1.0), 0.0)
        step = np.clip(step, -0.5 / fs, 0.5 / fs)  # never more than a grid cell at a time
        x = np.clip(x + step, -half_width_s, half_width_s)
    peak = np.abs((base * np.exp(1j * np.outer(x, omega))).sum(axis=1))
    return centre_s + x, peak


def _grid_values(base: NDArray[np.complex128], frequency_hz: NDArray[np.float64],
                 offsets: NDArray[np.float64]) -> NDArray[np.complex128]:
    """z(x_j) = sum_k base_k exp(j 2 pi f_k x_j) at equally spaced offsets x_j, shape (c, g).

    On an rfft grid (f_k = n_k df, integers n_k) one inverse FFT of length M >= 1 / (df dx) with
    M dx df an integer, i.e. exactly the sum, evaluated at x_0 + j dx (O(M log M) instead of
    g k complex exponentials); otherwise the direct sum.
    """
    f = np.asarray(frequency_hz, dtype=float)
    dx = float(offsets[1] - offsets[0]) if offsets.size > 1 else 0.0
    if f.size > 1 and dx > 0.0:
        df = float(f[1] - f[0])
        index = f / df
        cycles = 1.0 / (df * dx)  # M: grid points per period of the lowest frequency step
        if (np.allclose(index, np.rint(index), rtol=0, atol=1e-6) and abs(cycles - round(cycles)) < 1e-6
                and round(cycles) >= offsets.size):
            m = int(round(cycles))
            bins = np.rint(index).astype(np.intp)
            if bins.max() < m:
                spectrum = np.zeros((base.shape[0], m), dtype=complex)
                spectrum[:, bins] = base * np.exp(2j * np.pi * f * offsets[0])
                return np.fft.ifft(spectrum, axis=1)[:, : offsets.size] * m
    return base @ np.exp(1j * np.outer(offsets, 2.0 * np.pi * f)).T


@dataclass(frozen=True, eq=False)
class CorrelationGrid:
    """The frequency grid of a beam-aware correlation over a search window (``create``).

    Attributes
    ----------
    model : BeamModelConfig
        The model with its line-integral step set from the template's band.
    n_fft : int
        Segment length (samples): the widest search window plus the expected echo's span
        (template, beam spread, edge tail), so a segment holds a(t - tau) for every searched tau
        and the circular correlation equals the linear one.
    frequency_hz : ndarray, shape (k,)
        The band's rfft frequencies (Hz).
    bins : ndarray, shape (k,)
        Their rfft bin indices.
    template_spectrum : ndarray, shape (k,)
        ``template_spectrum`` on those bins.
    lead_s : float
        How far the expected echo starts before its reference delay (s).
    """

    model: BeamModelConfig
    n_fft: int
    frequency_hz: NDArray[np.float64] = field(repr=False)
    bins: NDArray[np.intp] = field(repr=False)
    template_spectrum: NDArray[np.complex128] = field(repr=False)
    lead_s: float

    @classmethod
    def create(cls, template: Template, transducers: PistonTransducers, model: BeamModelConfig,
               sound_speed_m_s: float, half_width_s: float) -> "CorrelationGrid":
        """The grid for searches within ``half_width_s`` (s) of a centre."""
        fs = float(template.sample_rate_hz)
        m = template.samples.size
        spread_s = 2.0 * float(transducers.radii_m.max()) / sound_speed_m_s  # a sin(theta) / c per piston, both ways
        tail_s = model.edge_tail_s if model.target == "vertical-edge" else 0.0
        lead_s = -template.t0_s + spread_s
        span_s = 2.0 * half_width_s + m / fs + 2.0 * spread_s + tail_s
        n_fft = 1 << int(math.ceil(math.log2(span_s * fs + 16)))
        frequency, step_top_hz = _band(template, n_fft)
        if model.step_frequency_hz is None:
            model = replace(model, step_frequency_hz=step_top_hz)
        bins = np.rint(frequency * n_fft / fs).astype(np.intp)
        return cls(model, n_fft, frequency, bins, template_spectrum(template, n_fft, bins), lead_s)


__all__ = ("CorrelationGrid", "correlation_maximum", "segment_spectra", "template_spectrum")
