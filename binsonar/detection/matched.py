"""The matched filter: FFT correlation with the template, analytic envelope, sub-sample peak.

How it is computed (one real FFT of the record per channel, nothing else at full size):

1. ``X = rfft(x, n_fft)`` with ``n_fft = next_fast_len(n + m - 1)`` (linear, not circular,
   correlation for every lag of a template of m samples).
2. The analytic correlation z(l) = sum_n x[n + l] s_a*[n] (s_a the template's analytic signal;
   Re z is the ordinary correlation, |z| its envelope) has the spectrum ``2 X conj(S)`` on
   f > 0 and nothing below. The template's energy lies below ``f_hi`` (bin ``k_hi``), so an
   inverse FFT of only those bins, of length ``n_env >= k_hi``, samples z exactly (it is band
   limited) every ``n_fft / n_env`` samples. This decimated envelope is what detection, the
   noise floor and CFAR use. ``detect`` ("matched", "seed-3/4") gets the same decimated
   envelope by overlap-save instead (``plan_matched(..., overlap_save=True)``,
   ``overlap_save.block_envelope``): ~35 real FFTs of 8,192 samples per channel rather than one
   of ~256,000 (short transforms stay in the cache), equal to it to the Hilbert tails'
   truncation (~1e-2 of the noise, 1e-4 of an echo's peak, tested), on a grid of ~14.6 samples
   instead of ~14.9.
3. The peak is refined at full rate: z at the integer lags around the coarse peak is computed
   directly in the time domain (a few dot products with the analytic template), and the
   parabola through log|z|^2 at the three samples around the maximum gives the sub-sample lag.
   For a Gaussian pulse log|z|^2 is exactly a parabola, so the interpolation adds no bias; for
   other smooth pulses the 50 ns spacing is much finer than the envelope width and the vertex
   converges to the continuous maximum, the maximum-likelihood TOF for an unknown carrier
   phase (its error reaches the envelope Cramer-Rao bound above threshold SNR).

A TOF is ``t0_s + lag / fs - template.t0_s``: sample 0 of the template is ``template.t0_s``
after its reference instant.

Noise floor: for Gaussian noise z is complex Gaussian, |z|^2 exponential with mean
``2 sigma^2 E_s``; its median over the record (robust to the few samples echoes occupy) divided
by ln 2 gives that mean, hence 2E/N0 = 2 |z_peak|^2 / mean - 2 (the -2 removes the noise's own
contribution to the peak) and a detection threshold for a design false-alarm probability.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Callable

import numpy as np
from numpy.typing import NDArray

from binsonar.bounds import rms_bandwidth_hz, tof_crlb_s
from binsonar.detection.noise import row_median
from binsonar.detection.overlap_save import BlockEnvelopePlan, block_envelope, plan_blocks
from binsonar.detection.peaks import SidelobeModel, log_parabolic_offset
from binsonar.recording import RecordingError, Template

# Fraction of the template's energy allowed above the band edge f_hi: the decimated envelope
# is then exact to about sqrt(1e-12) = 1e-6 of its peak.
BAND_ENERGY_TAIL = 1e-12
# Fraction of the analytic template's peak below which its (Hilbert) tails are truncated for
# the time-domain refinement. The tails decay like 1/t from the template's truncation; cutting
# them at 1e-5 of the peak changes z near its peak by ~1e-5 relative, smoothly in lag, which
# moves the vertex by ~1e-5 of the envelope width (~10 ps here), far below any TOF effect.
ANALYTIC_TAIL = 1e-5
LN2 = math.log(2.0)


@dataclass(frozen=True, eq=False)
class MatchedPlan:
    """Everything the matched filter precomputes for one template and record length.

    Attributes
    ----------
    n_samples : int
        Record length the plan is for.
    n_fft : int
        Real FFT size (>= n_samples + template length - 1).
    k_hi : int
        Number of rfft bins [0, k_hi) kept (the template's band).
    n_env : int
        Length of the decimated analytic envelope; its sample j is lag j * n_fft / n_env.
    weights : ndarray, shape (k_hi,), complex
        Frequency response applied to X: 2 conj(S) / P (P = 1 for white noise, the noise PSD for
        the whitened filter; DC weighted once).
    sample_rate_hz : float
    template : Template
    template_length : int
    peak_response : float
        |z| at zero lag when the input is the template itself (sum s^2 for white noise).
    analytic_template_conj : ndarray, shape (m_a,), complex
        conj of the template's analytic signal (plain matched filter only, else empty).
    analytic_offset : int
        Index in ``analytic_template_conj`` of template sample 0.
    rms_bandwidth_hz : float
        Envelope RMS bandwidth of the (weighted) template spectrum (Hz).
    response_power : ndarray, shape (n,)
        |response to one echo|^2, normalised, at delays 0, 1, 2, ... times
        ``response_spacing_s``; also the squared correlation coefficient of |z|^2 for white
        input noise.
    response_spacing_s : float
    correlation_time_s : float
        Integral of response_power: time over which |z|^2 of noise stays correlated (s).
    mainlobe_fwhm_s : float
        Full width at half maximum of the response's envelope |z| (s).
    """

    n_samples: int
    n_fft: int
    k_hi: int
    n_env: int
    weights: NDArray[np.complex128] = field(repr=False)
    sample_rate_hz: float
    template: Template = field(repr=False)
    template_length: int
    peak_response: float
    analytic_template_conj: NDArray[np.complex128] = field(repr=False)
    analytic_offset: int
    rms_bandwidth_hz: float
    response_power: NDArray[np.float64] = field(repr=False)
    response_spacing_s: float
    correlation_time_s: float
    mainlobe_fwhm_s: float
    analytic_parts: NDArray[np.float64] | None = field(default=None, repr=False)
    """Real and imaginary parts of ``analytic_template_conj`` as columns, shape (m_a, 2)
    (the matrix the direct correlations multiply by; None: made on use)."""
    blocks: "BlockEnvelopePlan | None" = field(default=None, repr=False)
    """Overlap-save plan of the decimated envelope (``overlap_save``; ``plan_matched(...,
    overlap_save=True)``): ``detect_matched`` then computes the envelope block by block, and
    ``decimation`` / ``n_valid`` refer to its grid. None: from the record-size spectrum."""

    @property
    def decimation(self) -> float:
        """Full-rate samples per decimated envelope sample (of the blocks' envelope when the
        plan has one)."""
        return self.blocks.decimation if self.blocks is not None else self.n_fft / self.n_env

    @property
    def n_valid(self) -> int:
        """Decimated samples whose lag lies in [0, n_samples - template_length] (full overlap)."""
        return int(math.floor((self.n_samples - self.template_length) / self.decimation)) + 1

    def lag_to_tof(self, lag: NDArray[np.float64], t0_s: float) -> NDArray[np.float64]:
        """TOF (s) of a (fractional) lag in full-rate samples."""
        return t0_s + np.asarray(lag) / self.sample_rate_hz - self.template.t0_s

    def sidelobes(self) -> SidelobeModel:
        """Relative power of the response versus distance in seconds."""
        return SidelobeModel(self.response_power, self.response_spacing_s)

    def threshold_factor(self, pfa: float, searched_lags: int | None = None) -> float:
        """|z|^2 / mean noise |z|^2 at which the searched maximum exceeds it with probability pfa.

        The envelope of complex Gaussian noise crosses r upward at the mean rate (Rice)
        2 sqrt(pi T) beta e^-T per second, with T = r^2 / mean |z|^2 and beta the RMS bandwidth
        of the output spectrum; over a searched duration L, adding the chance e^-T of starting
        above, pfa = e^-T (1 + 2 sqrt(pi T) beta L), solved for T by fixed-point iteration.

        Parameters
        ----------
        pfa : float
            False-alarm probability over the searched lags.
        searched_lags : int, optional
            Span of the searched lags (full-rate samples), e.g. of a search window; default:
            every full-overlap lag of the record, ``n_samples - template_length``.
        """
        span = self.n_samples - self.template_length if searched_lags is None else int(searched_lags)
        return envelope_threshold_factor(pfa, self.rms_bandwidth_hz, max(span, 1) / self.sample_rate_hz)


def envelope_threshold_factor(pfa: float, rms_bandwidth_hz: float, duration_s: float) -> float:
    """T = r^2 / mean |z|^2 that the envelope of complex Gaussian noise exceeds over ``duration_s`` with probability pfa.

    Rice's mean upcrossing rate of r is 2 sqrt(pi T) beta e^-T per second (beta the RMS bandwidth
    of the output spectrum, Hz); adding the chance e^-T of starting above,
    pfa = e^-T (1 + 2 sqrt(pi T) beta L), solved for T by fixed-point iteration (a contraction).
    """
    c = 2.0 * math.sqrt(math.pi) * rms_bandwidth_hz * duration_s
    factor = -math.log(pfa)
    for _ in range(50):  # contraction: converges to 1e-12 in a few tens of steps
        updated = math.log((1.0 + c * math.sqrt(factor)) / pfa)
        if abs(updated - factor) < 1e-12:
            break
        factor = updated
    return factor


def band_edge_cycles(samples: NDArray[np.float64]) -> float:
    """f_hi / fs: the frequency (cycles per sample) below which all but BAND_ENERGY_TAIL of the
    template's energy lies (on an rfft grid of at least 8 template lengths)."""
    import scipy.fft as sfft

    n_small = sfft.next_fast_len(max(8 * samples.size, 4096), real=True)
    power = np.abs(sfft.rfft(samples, n_small)) ** 2
    tail = np.cumsum(power[::-1])[::-1] / power.sum()  # tail[k]: energy fraction at bins >= k
    k_small = int(np.argmax(tail < BAND_ENERGY_TAIL)) if np.any(tail < BAND_ENERGY_TAIL) else power.size
    return k_small / n_small


def _band_edge_bin(samples: NDArray[np.float64], n_fft: int) -> int:
    """Number of rfft bins (of size n_fft) below which all but BAND_ENERGY_TAIL of the energy lies."""
    return int(min(n_fft // 2 + 1, math.ceil(band_edge_cycles(samples) * n_fft) + 2))


def _analytic_template(samples: NDArray[np.float64]) -> tuple[NDArray[np.complex128], int]:
    """conj of the analytic signal of the template, its Hilbert tails truncated; and the offset."""
    import scipy.fft as sfft

    m = samples.size
    n = sfft.next_fast_len(5 * m)
    padded = np.zeros(n)
    padded[2 * m: 3 * m] = samples
    spectrum = sfft.fft(padded)
    gain = np.zeros(n)
    gain[0] = 1.0
    gain[1:(n + 1) // 2] = 2.0
    if n % 2 == 0:
        gain[n // 2] = 1.0
    analytic = sfft.ifft(spectrum * gain)
    magnitude = np.abs(analytic)
    keep = np.flatnonzero(magnitude > ANALYTIC_TAIL * magnitude.max())
    start, stop = int(keep[0]), int(keep[-1]) + 1
    start = min(start, 2 * m)
    stop = max(stop, 3 * m)
    return np.conj(analytic[start:stop]), 2 * m - start


def _response(
    spectrum_power: NDArray[np.float64], n_fft: int, n_env: int, sample_rate_hz: float
) -> tuple[NDArray[np.float64], float, float, float]:
    """Normalised |response|^2 on a grid, its spacing (s), correlation time (s) and FWHM (s).

    ``spectrum_power`` is |S|^2 / P on rfft bins [0, k) of an FFT of size n_fft (DC halved).
    """
    import scipy.fft as sfft

    response = sfft.ifft(spectrum_power, n_env)
    power = np.abs(response[: n_env // 2]) ** 2
    power /= power[0]
    spacing_s = n_fft / n_env / sample_rate_hz
    correlation_time_s = float((2.0 * power.sum() - 1.0) * spacing_s)
    below = np.flatnonzero(power < 0.25)  # |response| = 1/2
    if below.size:
        i = int(below[0])
        p0, p1 = power[i - 1], power[i]
        fwhm_s = 2.0 * (i - 1 + (p0 - 0.25) / (p0 - p1)) * spacing_s
    else:
        fwhm_s = float(n_env * spacing_s)
    return power, spacing_s, correlation_time_s, fwhm_s


def plan_matched(
    template: Template,
    n_samples: int,
    sample_rate_hz: float,
    noise_psd: "Callable[[NDArray[np.float64]], NDArray[np.float64]] | None" = None,
    *,
    full: bool = True,
    overlap_save: bool = False,
) -> MatchedPlan:
    """Precompute the matched filter for a template and record length.

    Parameters
    ----------
    template : Template
        At ``sample_rate_hz`` (see ``inputs.resolve_template``).
    n_samples : int
        Record length (samples).
    sample_rate_hz : float
    noise_psd : callable or None
        For the extended (whitened) matched filter: ``noise_psd(f_hz) -> PSD`` (any unit,
        > 0); None for white noise.
    full : bool
        False skips the record-size spectrum and the response's properties (correlation time,
        FWHM, side lobes: NaN): enough for the local matched filter.
    overlap_save : bool
        Plan the decimated envelope block by block (``overlap_save.plan_blocks``, plain filter
        only) instead of from the record-size spectrum, which is then not computed (``k_hi``
        0, ``weights`` empty, whatever ``full`` says): what ``detect_matched`` needs, at a
        fraction of the cost. ``full`` still sets whether the response's properties are made.
    """
    import scipy.fft as sfft

    s = np.asarray(template.samples, dtype=float)
    m = s.size
    if m > n_samples:
        raise RecordingError(f"template ({m} samples) is longer than the record ({n_samples} samples)")
    fs = sample_rate_hz
    if full:
        # Template properties on a small grid (the response lasts < 2 m samples; 8 m avoids wrap).
        n_small = sfft.next_fast_len(max(8 * m, 4096), real=True)
        k_small = _band_edge_bin(s, n_small)
        spectrum_small = sfft.rfft(s, n_small)[:k_small]
        freqs_small = np.arange(k_small) * fs / n_small
        psd_small = np.ones(k_small) if noise_psd is None else np.asarray(noise_psd(freqs_small), dtype=float)
        filtered_small = np.abs(spectrum_small) ** 2 / psd_small
        filtered_small[0] *= 0.5
        response_power, spacing_s, correlation_time_s, fwhm_s = _response(
            filtered_small, n_small, sfft.next_fast_len(4 * k_small), fs
        )
    else:  # the local matched filter needs none of these
        response_power, spacing_s, correlation_time_s, fwhm_s = np.ones(1), float("nan"), float("nan"), float("nan")
    if noise_psd is None:
        analytic_conj, offset = _analytic_template(s)
        beta = rms_bandwidth_hz(s, fs)
    else:
        analytic_conj, offset = np.zeros(0, dtype=complex), 0
        centroid = (freqs_small * filtered_small).sum() / filtered_small.sum()
        beta = float(np.sqrt(((freqs_small - centroid) ** 2 * filtered_small).sum() / filtered_small.sum()))
    n_fft = fast_fft_size(n_samples + m - 1)
    blocks = None
    if overlap_save:
        if noise_psd is not None:
            raise ValueError("plan_matched: overlap_save is for the plain (white-noise) matched filter only")
        blocks = plan_blocks(s, n_samples, band_edge_cycles(s), offset, analytic_conj.size)
    if full and not overlap_save:
        k_hi = _band_edge_bin(s, n_fft)
        n_env = sfft.next_fast_len(k_hi)
        if noise_psd is None:
            # The template's spectrum on the record's grid from a float32 FFT (half the work of a
            # float64 one, paid whenever ``detect`` plans per call): relative errors ~1e-7 of its
            # peak, as those of the float32 record FFT the
            # plain filter's envelope comes from anyway (``filtered_spectrum``); the TOF is
            # refined with the float64 analytic template. Not for a whitened plan, whose 1 / PSD
            # weights could amplify the rounding in the spectrum's weak tails.
            padded = np.zeros(n_fft, dtype=np.float32)
            padded[:m] = s
            spectrum = sfft.rfft(padded)[:k_hi].astype(np.complex128)
        else:
            spectrum = sfft.rfft(s, n_fft)[:k_hi]
        psd = np.ones(k_hi) if noise_psd is None else np.asarray(noise_psd(np.arange(k_hi) * fs / n_fft), dtype=float)
        weights = 2.0 * np.conj(spectrum) / psd
        weights[0] *= 0.5
        peak_response = float((np.abs(spectrum) ** 2 / psd * np.where(np.arange(k_hi) == 0, 1.0, 2.0)).sum() / n_fft)
    else:
        k_hi, n_env = 0, 1
        weights = np.zeros(0, dtype=complex)
        peak_response = float(np.sum(s * s)) if noise_psd is None else float("nan")
    return MatchedPlan(
        n_samples=int(n_samples),
        n_fft=int(n_fft),
        k_hi=int(k_hi),
        n_env=int(n_env),
        weights=weights,
        sample_rate_hz=float(fs),
        template=template,
        template_length=int(m),
        peak_response=peak_response,
        analytic_template_conj=analytic_conj,
        analytic_offset=int(offset),
        rms_bandwidth_hz=float(beta),
        response_power=response_power,
        response_spacing_s=float(spacing_s),
        correlation_time_s=correlation_time_s,
        mainlobe_fwhm_s=float(fwhm_s),
        analytic_parts=np.ascontiguousarray(np.stack([analytic_conj.real, analytic_conj.imag], axis=1)),
        blocks=blocks,
    )


def fast_fft_size(target: int) -> int:
    """Smallest FFT length >= ``target`` of the form 2^a * c, c an odd 5-smooth number <= 625.

    A large power-of-two factor suits pocketfft's single-precision kernels: for the thesis's
    records (250,200 samples) 256,000 = 2^11 * 125 rather than ``next_fast_len``'s 253,125 =
    3^4 * 5^5 (``benchmarks/bench_detection.py`` times the filter against an FFT of the record).
    """
    target = max(int(target), 1)
    best = None
    for c in (1, 3, 5, 9, 15, 25, 27, 45, 75, 81, 125, 135, 225, 243, 375, 405, 625):
        size = c << max(0, (target - 1) // c).bit_length()  # c * smallest power of 2 with c * 2^a >= target
        while size // 2 >= target and size % 2 == 0:
            size //= 2
        if best is None or size < best:
            best = size
    return int(best)


def filtered_spectrum(
    plan: MatchedPlan, rows: NDArray[np.float64], single: bool = False, dc: NDArray[np.float64] | None = None
) -> NDArray[np.complex128]:
    """The filter output's analytic spectrum on the kept bins: X * weights, shape (n_rows, k_hi).

    ``dc`` (shape (n_rows,)): offsets still in ``rows``, subtracted first (in the cast copy when
    ``single``). With ``single`` the result is complex64 (and so is ``envelope`` of it).

    ``single``: the record's FFT in float32 (copied with its zero padding into one float32
    buffer, then one real FFT without further padding), half the bytes of float64. The
    data are ADC codes of 12-16 bits, far inside float32's 24-bit mantissa; the FFT's relative
    rounding (~1e-7 of the record's RMS spectrum) is ~100 dB below the white noise of any real
    record, and only the decimated envelope (peak cell, noise median) comes from it: the TOF
    refinement is recomputed from the float64 samples (``refine_peaks``), so TOFs agree with
    the float64 path to far below 0.1 ns (``tests/unit/test_detection_matched.py``). Not for the
    whitened filter, whose weights can amplify the rounding in bins where the noise is low.
    """
    import scipy.fft as sfft

    if plan.k_hi == 0:
        raise ValueError("filtered_spectrum: the plan has no record-size spectrum (plan_matched with full=True and "
                         "overlap_save=False)")
    if single:
        n_rows, n = rows.shape
        buffer = np.empty((n_rows, plan.n_fft), dtype=np.float32)
        if dc is None:
            buffer[:, :n] = rows
        else:  # the offset removed in the same pass as the cast (no float64 copy of the record)
            np.subtract(rows, np.asarray(dc, dtype=float).reshape(n_rows, 1), out=buffer[:, :n], casting="same_kind")
        buffer[:, n:] = 0.0
        spectrum = sfft.rfft(buffer, axis=-1)[:, : plan.k_hi]  # complex64
        spectrum *= plan.weights.astype(np.complex64)
        return spectrum
    if dc is not None:
        rows = rows - np.asarray(dc, dtype=float).reshape(-1, 1)
    spectrum = sfft.rfft(rows, plan.n_fft, axis=-1)[:, : plan.k_hi]
    spectrum *= plan.weights
    return spectrum


def envelope(plan: MatchedPlan, spectrum: NDArray[np.complex128]) -> NDArray[np.complex128]:
    """Decimated analytic filter output over the full-overlap lags, shape (n_rows, n_valid).

    Sample j is z at lag j * plan.decimation (full-rate samples).
    """
    import scipy.fft as sfft

    z = sfft.ifft(spectrum, plan.n_env, axis=-1)[:, : plan.n_valid]
    z *= plan.n_env / plan.n_fft
    return z


def white_noise_power(plan: MatchedPlan, sigma_v: float | NDArray[np.float64]) -> NDArray[np.float64]:
    """Mean |z|^2 of the filter output for white input noise of standard deviation ``sigma_v``.

    z is the input filtered by the impulse response whose (one-sided, analytic) spectrum is
    ``plan.weights``, so E|z|^2 = sigma^2 sum_l |h_l|^2 = sigma^2 sum_k |w_k|^2 / n_fft
    (Parseval). For the plain filter (w = 2 conj(S)) this is 2 sigma^2 sum s^2 = 2 sigma^2
    ``peak_response``, the value used when the plan holds no weights (local matched filter).
    """
    sigma2 = np.square(np.asarray(sigma_v, dtype=float))
    if plan.blocks is not None:
        gain = plan.blocks.noise_gain
    elif plan.weights.size:
        gain = float(np.sum(np.abs(plan.weights) ** 2)) / plan.n_fft
    else:
        gain = 2.0 * plan.peak_response
    return sigma2 * gain


def noise_mean_power(power: NDArray[np.float64], floor_power: float = 0.0) -> NDArray[np.float64]:
    """Mean |z|^2 of the noise per row, from the median (exponential law), shape (n_rows,).

    ``floor_power``: the least it can be (``white_noise_power`` of the ADC's quantisation
    noise): a quantised record whose noise is below one code step has stretches of exactly
    constant samples, where the median would otherwise report (almost) no noise.
    """
    return np.maximum(row_median(power) / LN2, max(float(floor_power), np.finfo(float).tiny))


def lags_time_domain(
    plan: MatchedPlan,
    rows: NDArray[np.float64],
    row_index: NDArray[np.intp],
    lags: NDArray[np.intp],
    stride: int = 1,
    scale: float = 1.0,
) -> NDArray[np.complex128]:
    """Analytic correlation z at equally spaced integer lags, computed directly (plain filter).

    ``rows`` may be int16 ADC codes with ``scale`` their volts per code: the gathered samples
    are converted (code * scale, the volts numpy makes of the whole record).

    Parameters
    ----------
    rows : ndarray, shape (n_rows, n_samples)
    row_index : ndarray of int, shape (k,)
        Row of each peak.
    lags : ndarray of int, shape (k, w)
        Lags (full-rate samples) to evaluate for each peak: lags[:, 0] + stride * arange(w).
    stride : int
        Spacing of the lags.

    Returns
    -------
    ndarray, shape (k, w), complex
    """
    from numpy.lib.stride_tricks import as_strided

    taps = plan.analytic_template_conj
    n = rows.shape[1]
    w = lags.shape[1]
    start = lags[:, 0] - plan.analytic_offset  # first record sample under the template at the first lag
    index = start[:, np.newaxis] + np.arange((w - 1) * stride + taps.size)
    if index.size and index.min() >= 0 and index.max() < n:  # all inside the record (the usual case)
        segment = rows[row_index[:, np.newaxis], index]
    else:
        inside = (index >= 0) & (index < n)
        segment = np.where(inside, rows[row_index[:, np.newaxis], np.minimum(np.maximum(index, 0), n - 1)], 0.0)
    if scale != 1.0 or segment.dtype != np.float64:
        segment = segment * float(scale)
    # (k, w, m_a) overlapping windows as a strided view of the segment (read only, no copy).
    s0, s1 = segment.strides
    windows = as_strided(segment, shape=(segment.shape[0], w, taps.size), strides=(s0, stride * s1, s1), writeable=False)
    columns = plan.analytic_parts if plan.analytic_parts is not None else np.stack([taps.real, taps.imag], axis=1)
    parts = np.matmul(windows, columns)  # (k, w, 2)
    return parts[..., 0] + 1j * parts[..., 1]


def dc_correlation(
    plan: MatchedPlan,
    n_samples: int,
    dc: NDArray[np.float64],
    lags: NDArray[np.intp],
    partial: NDArray[np.complex128] | None = None,
) -> NDArray[np.complex128]:
    """Analytic correlation of constant rows (value ``dc``) with the template, at ``lags``,
    samples outside the record counting as 0 (as in ``lags_time_domain``).

    Parameters
    ----------
    dc : ndarray, shape (k,)
    lags : ndarray of int, shape (k, w)
    partial : ndarray, shape (m_a + 1,), complex, optional
        Running sums of the analytic taps, 0 first (``LocalPlan.tap_partial``); made if absent.

    Returns
    -------
    ndarray, shape (k, w), complex
    """
    taps = plan.analytic_template_conj
    if partial is None:
        partial = np.concatenate([[0.0], np.cumsum(taps)])
    first = lags - plan.analytic_offset  # record sample under tap 0
    lo = np.minimum(np.maximum(-first, 0), taps.size)
    hi = np.minimum(np.maximum(n_samples - first, 0), taps.size)
    return dc[:, np.newaxis] * np.where(hi > lo, partial[hi] - partial[lo], 0.0)


def lags_from_spectrum(plan: MatchedPlan, spectrum: NDArray[np.complex128], lags: NDArray[np.intp]) -> NDArray[np.complex128]:
    """Analytic filter output at integer lags from its band spectrum (any weights).

    Parameters
    ----------
    spectrum : ndarray, shape (k, k_hi)
        ``filtered_spectrum`` rows of the peaks.
    lags : ndarray of int, shape (k, w)
        Equally spaced lags for each peak (the same spacing for all).

    Returns
    -------
    ndarray, shape (k, w), complex
    """
    bins = np.arange(plan.k_hi)
    stride = int(lags[0, 1] - lags[0, 0]) if lags.shape[1] > 1 else 1
    phasor = np.exp(2j * np.pi * np.outer(lags[:, 0], bins) / plan.n_fft)  # (k, k_hi)
    step = np.exp(2j * np.pi * stride * bins / plan.n_fft)
    out = np.empty(lags.shape, dtype=complex)
    for j in range(lags.shape[1]):  # a few lags around each peak, not samples of the record
        out[:, j] = (spectrum * phasor).sum(axis=-1) / plan.n_fft
        phasor *= step
    return out


def refine(values: NDArray[np.complex128], lags: NDArray[np.intp]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Sub-sample peak of |z| from z at consecutive integer lags (log-parabolic vertex).

    Parameters
    ----------
    values : ndarray, shape (k, w), complex
    lags : ndarray of int, shape (k, w)

    Returns
    -------
    lag : ndarray, shape (k,)
        Fractional lag of the envelope peak (full-rate samples).
    power : ndarray, shape (k,)
        |z|^2 at the vertex.
    """
    power = np.abs(values) ** 2
    w = power.shape[1]
    i = np.clip(np.argmax(power, axis=1), 1, w - 2)
    k = np.arange(power.shape[0])
    offset, peak = log_parabolic_offset(power[k, i - 1], power[k, i], power[k, i + 1])
    return lags[k, i] + offset, peak


def refine_window(plan: MatchedPlan) -> int:
    """Half-width (full-rate samples) of the refinement window around a coarse decimated peak."""
    return int(math.ceil(plan.decimation)) + 2


def refine_peaks(
    plan: MatchedPlan,
    rows: NDArray[np.float64],
    spectrum: NDArray[np.complex128] | None,
    peak_rows: NDArray[np.intp],
    coarse_lags: NDArray[np.float64],
    half_width: int | None = None,
    dc: NDArray[np.float64] | None = None,
    scale: float = 1.0,
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Refine coarse peaks (full-rate lags) to sub-sample lags and peak powers.

    Uses the time-domain analytic template for the plain matched filter and the band spectrum
    for a weighted (whitened) one. ``dc`` (shape (n_rows,), plain filter only): offsets still
    in ``rows``, whose correlation (``dc_correlation``) is subtracted. ``scale``: volts per unit
    of ``rows`` (int16 ADC codes; plain filter only).
    """
    if peak_rows.size == 0:
        return np.zeros(0), np.zeros(0)
    w = refine_window(plan) if half_width is None else int(half_width)
    lags = np.rint(coarse_lags).astype(np.intp)[:, np.newaxis] + np.arange(-w, w + 1)
    if plan.analytic_template_conj.size:
        values = lags_time_domain(plan, rows, peak_rows, lags, scale=scale)
        if dc is not None:
            values -= dc_correlation(plan, rows.shape[1], dc[peak_rows], lags)
    else:
        if spectrum is None:
            raise ValueError("refine_peaks: a weighted (whitened) plan needs its filtered spectrum")
        values = lags_from_spectrum(plan, spectrum[peak_rows], lags)
    return refine(values, lags)


def echo_values(
    plan: MatchedPlan,
    lag: NDArray[np.float64],
    power: NDArray[np.float64],
    noise_mean: NDArray[np.float64],
    threshold_factor: float,
    t0_s: float,
) -> tuple[NDArray[np.float64], ...]:
    """TOF (s), amplitude (V), SNR (dB, 2E/N0), score and TOF std (s) of refined peaks.

    Amplitude is the echo's peak in volts, taking the template's sample peak as its unit.
    """
    tof = plan.lag_to_tof(lag, t0_s)
    # A noise-free record has (almost) no noise floor: cap the SNR at 200 dB.
    noise_mean = np.maximum(noise_mean, 1e-20 * power)
    amplitude = np.sqrt(power) / plan.peak_response * float(np.max(np.abs(plan.template.samples)))
    snr = np.maximum(2.0 * power / noise_mean - 2.0, 1e-3)
    score = power / (threshold_factor * noise_mean)
    tof_std = tof_crlb_s(snr, plan.rms_bandwidth_hz)
    return tof, amplitude, 10.0 * np.log10(snr), score, tof_std


def check_pfa(pfa: float) -> float:
    """Validate a false-alarm probability in (0, 1)."""
    if not (isinstance(pfa, (int, float)) and 0.0 < pfa < 1.0):
        raise RecordingError(f"pfa must be in (0, 1), got {pfa!r}")
    return float(pfa)


def lag_range(
    plan: MatchedPlan, t0_s: float, search_window_s: tuple[float, float] | None = None, where: str = "record"
) -> tuple[int, int]:
    """Inclusive range [lo, hi] of full-overlap lags (full-rate samples) whose TOF lies in the
    search window (s after the trigger; None: every full-overlap lag, [0, n - m]).

    Raises
    ------
    RecordingError
        A malformed window or one that holds no lag.
    """
    lo, hi = 0, plan.n_samples - plan.template_length
    if search_window_s is not None:
        try:
            start_s, stop_s = (float(v) for v in search_window_s)
        except (TypeError, ValueError):
            raise RecordingError(f"{where}: search_window_s must be (start_s, stop_s), got {search_window_s!r}") from None
        shift = plan.template.t0_s - t0_s
        if math.isfinite(start_s):
            lo = max(lo, int(math.ceil((start_s + shift) * plan.sample_rate_hz)))
        if math.isfinite(stop_s):
            hi = min(hi, int(math.floor((stop_s + shift) * plan.sample_rate_hz)))
        if hi < lo:
            raise RecordingError(f"{where}: search_window_s={search_window_s!r} holds no time of flight of the record")
    return lo, hi


def cell_mask(plan: MatchedPlan, n_cells: int, lags: tuple[int, int]) -> NDArray[np.bool_]:
    """True for the decimated envelope cells whose lag lies in the inclusive range ``lags``."""
    lag = np.arange(n_cells) * plan.decimation
    return (lag >= lags[0] - 0.5 * plan.decimation) & (lag <= lags[1] + 0.5 * plan.decimation)


def cell_bounds(plan: MatchedPlan, n_cells: int, lags: tuple[int, int]) -> tuple[int, int]:
    """``cell_mask``'s True cells as a range [first, stop) (they are contiguous), without the
    mask: the same floating-point tests on the few cells at its ends only."""
    d = plan.decimation
    low, high = lags[0] - 0.5 * d, lags[1] + 0.5 * d
    first = min(max(0, int(math.ceil(low / d)) - 2), n_cells)
    while first < n_cells and not float(first) * d >= low:
        first += 1
    stop = min(max(first, int(math.floor(high / d)) + 3), n_cells)
    while stop > first and not float(stop - 1) * d <= high:
        stop -= 1
    return first, stop


def detect_matched(
    rows: NDArray[np.float64],
    plan: MatchedPlan,
    *,
    t0_s: float,
    pfa: float = 1e-3,
    search_window_s: tuple[float, float] | None = None,
    noise_floor_v: float = 0.0,
    single: bool = True,
    dc_v: NDArray[np.float64] | None = None,
    volts_per_code: float | None = None,
) -> list[list[tuple[float, float, float, float, float]]]:
    """Strongest matched-filter echo of each row (the seed's global-maximum peak detection).

    Parameters
    ----------
    rows : ndarray, shape (n_rows, n_samples)
    plan : MatchedPlan
    t0_s : float
        Time of sample 0 (s).
    pfa : float
        Design false-alarm probability over the searched lags (the search window, or the whole
        record): a row whose peak is below the threshold for it reports no echo.
    search_window_s : (start_s, stop_s), optional
        Only TOFs in this window (s after the trigger), e.g. to skip the transmitter's direct
        cross-talk; default: every lag where the template lies inside the record.
    noise_floor_v : float
        Least input noise standard deviation (V), the ADC's quantisation noise: the noise
        floor of |z|^2 is never below its ``white_noise_power``.
    single : bool
        The record's FFT in float32 (``filtered_spectrum``, or the blocks' FFTs of
        ``overlap_save.block_envelope`` when the plan has ``blocks``); the TOF refinement stays
        float64.
    dc_v : ndarray, shape (n_rows,), optional
        DC offset of each row still in ``rows`` (``Signals.dc_v``): removed in the FFT's input
        copy and subtracted from the direct correlations (``dc_correlation``), so the result is
        that of ``rows - dc_v`` without a copy of the record.
    volts_per_code : float, optional
        ``rows`` are int16 ADC codes of this step (V). With the overlap-save plan they are read
        as they are (the blocks' gather and the refinement convert the samples they use, to
        the same volts); with a record-size spectrum they are converted first.

    Returns
    -------
    list (n_rows) of list of (tof_s, amplitude, snr_db, score, tof_std_s)
    """
    pfa = check_pfa(pfa)
    dc = None if dc_v is None else np.asarray(dc_v, dtype=float).reshape(rows.shape[0])
    scale = 1.0
    if volts_per_code is not None:
        if plan.blocks is None:
            rows = rows * float(volts_per_code)
        else:
            scale = float(volts_per_code)
    if plan.blocks is not None:  # overlap-save: no record-size spectrum (refinement in the time domain)
        spectrum = None
        z = block_envelope(plan.blocks, rows, dc, single, scale)
    else:
        spectrum = filtered_spectrum(plan, rows, single=single, dc=dc)
        z = envelope(plan, spectrum)
    power = np.square(z.real, dtype=float) + np.square(z.imag, dtype=float)  # float64 even from float32 z
    noise = noise_mean_power(power, float(white_noise_power(plan, noise_floor_v)))
    lags = lag_range(plan, t0_s, search_window_s)
    first, stop = cell_bounds(plan, power.shape[1], lags)
    if stop > first:  # the searched cells' maximum (the first on ties)
        coarse = first + np.argmax(power[:, first:stop], axis=1)
    else:  # no cell inside the searched lags (as the mask's argmax: cell 0)
        coarse = np.zeros(rows.shape[0], dtype=np.intp)
    row_index = np.arange(rows.shape[0])
    lag, peak = refine_peaks(plan, rows, spectrum, row_index, coarse * plan.decimation, dc=dc, scale=scale)
    factor = plan.threshold_factor(pfa, lags[1] - lags[0])  # pfa over the searched lags only
    values = echo_values(plan, lag, peak, noise, factor, t0_s)
    out: list[list[tuple[float, float, float, float, float]]] = []
    for r in range(rows.shape[0]):
        echo = tuple(float(v[r]) for v in values)
        out.append([echo] if echo[3] >= 1.0 else [])  # type: ignore[list-item]
    return out
