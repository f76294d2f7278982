"""Local matched processing (seed section 4.2.4, method 9).

The seed: "First, the peak point of the echo signal is detected. Then, a local matching
process is executed between a known template signal and the partial echo signal which is
around the detected peak point. The time duration of the partial echo signal is about twice
of that of the template signal. By finding the peak of the output of the local matched
filter and carefully calibrating the offset caused by defining the partial echo signal, an
accurate time-of-flight estimate can be determined." Here:

1. Coarse peaks (one pass over the record). The record is cut into blocks of B samples and
   each block is correlated with a tone at the template's centre frequency f0,
   ``z_b = sum_k x[b B + k] exp(-2 pi i f0 k / fs)`` (a batched matrix product with a
   (B, 2) cos/sin table: one multiply-add per sample and column). The statistic of a window
   of ``span`` consecutive blocks is ``sum |z_b|^2``: the energy in a band about fs / B wide
   around f0 (B ~ fs / (4 beta), beta the template's RMS bandwidth, so that the band holds the
   template's spectrum to ~1 dB at one RMS bandwidth from f0), not the energy of the whole
   10 MHz of white noise a sum of x^2 collects. A window of noise alone then rarely looks like
   an echo: at 2E/N0 = 20 dB an echo window exceeds the largest of the ~6,000 noise windows
   of a 12.5 ms channel by ~3 standard deviations of its own statistic, against ~2.3 for the
   broadband energy (notes in ``plan_local``). The candidates are the ``candidates`` strongest
   windows, each at least a template length from the others; the lag of a window is its centre
   minus the template's envelope peak. This is the seed's "peak point of the echo signal":
   the strongest echo, as the full matched filter (``detect_matched``, the seed's
   global-maximum detection) reports, so that the two can be compared echo for echo.
2. Local matched filter. Around each candidate, the stretch of record twice the template's
   length plus one template (``2 half + m`` samples) is correlated with the template by a
   short FFT (one real FFT of the stretch, the template's analytic spectrum 2 conj(S) on the
   band's bins, an inverse FFT at full rate): z at every lag within ``half = m // 2`` of the
   coarse lag, exactly the full matched filter's band-limited z for those lags except for the
   Hilbert tails of samples outside the stretch (~1e-5 of the peak). The candidate and lag
   with the largest |z| win: the full filter's global maximum whenever its echo is among the
   candidates.
3. Offset calibrated out and sub-sample peak. Lags are counted from sample 0 of the record
   (each stretch's start index is added back), and the template's own ``t0_s`` is subtracted
   as for the full matched filter. The peak is refined as the full filter refines its own
   (``matched.refine_peaks``: z at the 2 R + 1 integer lags around it by direct dot products
   with the analytic template, then ``matched.refine``'s log-parabolic vertex; here compiled,
   ``local_kernels.local_peaks``, checked against those functions), so the two give the same
   TOF, to rounding, whenever they find the same echo.

Cost per channel: one pass over the samples (the block correlations, ~2 flops per sample),
then work on a few candidates only: a dot product of the analytic template's length at every
``decimation``-th lag of each stretch (41 for the 5 us pulse), and (2 R + 1) more around the peak.

How it runs (``detect_local_matched``): everything is one compiled call for all rows of a
record (``local_kernels.local_echoes``, numba, imported on first use): the coarse pass of step
1 (each searched sample read once), then each pick's stretch searched at every
``LocalPlan.decimation``-th lag by direct dot products with the analytic template (step 2
sampled on the lattice the decimated FFT route samples: |z| there is the refinement's own z),
the refinement of step 3 and ``matched.echo_values``. The FFT route of step 2
(``candidate_correlations``: one batched single-precision real FFT of the stretches, the
band's inverse FFT decimated, then ``local_kernels.local_peaks``) gives the same echoes bit for
bit on the tests' records and is the reference the direct search is checked against, with the
numpy definitions below (``block_tone_power``, ``coarse_lags``, ``segment_correlation``,
``numpy_peaks``: the same steps written with numpy; ``tests/parity/test_detection_local_kernels.py``).

Records of int16 ADC codes (``volts_per_code``: ``DetectionMethod.reads_codes``) are read as
they are, 2 bytes a sample instead of 8: the block correlations of the codes are scaled to
volts once per block, the searched stretches are converted once each (float32), the direct
correlations are made of code * volts_per_code, and the robust DC and noise come from a
histogram of the codes (``code_kernels``). The clipping test of the codes (the ADC's rails, a
``full_scale_v``) is read with the coarse pass (``extremes_out``: each chunk of blocks scanned
again while in cache, then the samples outside the searched blocks), not by a pass of its own
(``DetectionMethod.measures_extremes``).

A row's DC offset (``dc_v``, still in the samples) is folded in rather than removed from a
copy of the record: the block correlations of x - dc are those of x minus dc times the sum of
the tone table (exact, one constant per row); the stretches are copies anyway, from which dc
is subtracted; and each directly computed z(lag) has dc times the sum of the analytic taps
that overlap the record at that lag subtracted, which is exactly the correlation of the
constant dc (the direct correlations treat samples outside the record as 0).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from binsonar.detection.kernel_types import ECHO, ECHO_CONSTANTS, LOCAL_SEARCH, read_only, record
from binsonar.detection.matched import (
    MatchedPlan,
    check_pfa,
    dc_correlation,
    lag_range,
    lags_time_domain,
    plan_matched,
    refine,
    white_noise_power,
)
from binsonar.detection.noise import noise_sigma
from binsonar.recording import RecordingError, Template

SCORE = ECHO.names.index("score")
"""Position of the score in an ``ECHO`` record's tuple (``tolist``)."""
# Block length of the coarse stage: B = BLOCK_BANDWIDTH_FRACTION * fs / beta (beta the template's
# RMS bandwidth about its centre frequency). A block's tone correlation has the response
# sinc(B (f - f0) / fs) in amplitude: at one RMS bandwidth from f0 it is sinc(0.25), a power
# loss of 0.9 dB, at two 3.9 dB, so a block keeps most of the template's energy while it
# collects the noise of a band ~fs / B = 4 beta wide instead of all fs / 2.
BLOCK_BANDWIDTH_FRACTION = 0.25
# Integer lags each side of the local peak at which z is recomputed directly for the
# sub-sample refinement (the same evaluation as the full matched filter's refinement).
REFINE_HALF_WIDTH = 3
# Band of the stretch's FFT: rfft bins below which all but this fraction of the template's
# energy lies (as ``matched.BAND_ENERGY_TAIL``: z exact to ~1e-6 of its peak).
_BAND_TAIL = 1e-12


@dataclass(frozen=True, eq=False)
class LocalPlan:
    """Everything the local matched filter precomputes for one template and record length.

    Attributes
    ----------
    matched : MatchedPlan
        The matched filter's plan without its record-size spectrum (``plan_matched(...,
        full=False)``): analytic template for the refinement, constants for TOF and SNR.
    block : int
        Coarse-stage block length B (samples).
    span : int
        Blocks per coarse window.
    tone : ndarray, shape (block, 2)
        cos and -sin of 2 pi f0 k / fs, k = 0 .. B - 1 (z_b = x_block @ tone, real and
        imaginary parts).
    tone_sum : ndarray, shape (2,)
        Column sums of ``tone``: the block correlation of a constant 1 V row.
    centre_hz : float
        Tone frequency f0: the centroid of the template's power spectrum (Hz).
    reference : int
        Index (template samples) of the template's envelope maximum: a window centred on sample
        c has coarse lag c - reference.
    half : int
        Lags searched each side of a coarse lag (``template_length // 2``): a stretch of
        2 half + m samples, about twice the template, as the seed describes.
    segment_fft : int
        FFT size of a stretch (>= 2 half + 2 m - 1: linear correlation at every searched lag).
    segment_weights : ndarray, shape (k,), complex
        2 conj(S) on the stretch FFT's first k bins (the template's band; DC weighted once).
    tap_partial : ndarray, shape (m_a + 1,), complex
        Running sums of the analytic taps, 0 first (``dc_correlation``).
    """

    matched: MatchedPlan = field(repr=False)
    block: int
    span: int
    tone: NDArray[np.float64] = field(repr=False)
    tone_sum: NDArray[np.float64] = field(repr=False)
    centre_hz: float
    reference: int
    half: int
    segment_fft: int
    segment_weights: NDArray[np.complex128] = field(repr=False)
    tap_partial: NDArray[np.complex128] = field(repr=False)
    tap_parts: NDArray[np.float64] = field(repr=False)
    """Real and imaginary parts of the analytic taps and of ``tap_partial``, shape (4, m_a + 1)
    (taps in the first m_a columns of rows 0-1, running sums in rows 2-3)."""
    exclusion: int
    """Coarse windows blanked each side of a pick: ceil(m / block), at least 1 (a template length)."""
    tone_lanes: NDArray[np.float64] = field(repr=False)
    """``tone`` transposed, shape (2, L), zero padded to L = the next multiple of 8 >= block
    (``local_kernels.block_powers``: whole vectors per block)."""
    segment_weights32: NDArray[np.complex64] = field(repr=False)
    """``segment_weights`` in single precision (the candidates' short FFTs, ``candidate_correlations``)."""
    noise_gain: float
    """``matched.white_noise_power`` of 1 V: the mean |z|^2 of white noise of unit variance."""
    tone_lanes32: NDArray[np.float32] = field(repr=False)
    """``tone_lanes`` in single precision: the coarse pass of int16 codes sums in float32
    (``local_kernels.block_powers``)."""
    tap_parts32: NDArray[np.float32] = field(repr=False)
    """The first two rows of ``tap_parts`` in single precision, shape (2, m_a + 1): the taps of
    the stretches' search (``local_kernels.local_echoes``)."""
    decimation: int = 1
    """D: the candidates' z is computed at every D-th lag only, by an inverse FFT of
    ``segment_fft // D`` points of the band (exact: z is band-limited to the band's bins, all
    below ``segment_fft // D``, so the short inverse FFT gives D z at lags start + D j);
    the largest of those picks the neighbourhood that the direct correlations then search at
    every lag (``REFINE_HALF_WIDTH + D - 1`` each side). D is the largest divisor of
    ``segment_fft`` that leaves at least two samples per cycle of the band's highest
    frequency (``segment_fft // D >= 2 k_hi``): 5 for the 5 us pulse (625 -> 125 points, the
    band 45 bins), where |z| (an envelope ~30 samples wide at half height) is sampled every 5
    lags, so the largest sample is within D - 1 lags of the largest |z|."""
    _factors: dict = field(default_factory=dict, init=False, repr=False)
    """Memo of ``matched.threshold_factor`` by (pfa, searched lags): a pure function of the plan
    (a fixed-point iteration of tens of Python steps)."""
    _records: dict = field(default_factory=dict, init=False, repr=False)
    """Memo of the kernels' read-only records (``search``, ``echo_constants``) by their arguments:
    a live loop builds each once."""

    def _forget_records(self) -> None:
        """Keep the records' memo small (records for other time origins or windows come and go)."""
        if len(self._records) >= 32:
            self._records.clear()

    def search(self, lag_bounds: tuple[int, int], candidates: int, scale: float = 1.0,
               stride: int | None = None) -> NDArray[np.void]:
        """The kernels' ``kernel_types.LOCAL_SEARCH`` record: samples of ``scale`` V per unit,
        this plan's layout, the searched lags (inclusive ``lag_bounds``, ``candidates`` picks per
        row), every ``stride``-th lag searched (default ``decimation``) and ``REFINE_HALF_WIDTH +
        stride - 1`` refined each side."""
        key = ("search", lag_bounds[0], lag_bounds[1], candidates, scale, stride)
        found = self._records.get(key)
        if found is None:
            stride = self.decimation if stride is None else int(stride)
            self._forget_records()
            found = self._records[key] = read_only(record(
                LOCAL_SEARCH, scale=scale, block=self.block, span=self.span, reference=self.reference, exclusion=self.exclusion,
                half=self.half, segment_length=self.segment_length, lag_lo=lag_bounds[0], lag_hi=lag_bounds[1],
                candidates=candidates, analytic_offset=self.matched.analytic_offset, stride=stride,
                reach=REFINE_HALF_WIDTH + stride - 1))
        return found

    def echo_constants(self, t0_s: float, threshold_factor: float) -> NDArray[np.void]:
        """The kernels' ``kernel_types.ECHO_CONSTANTS`` record (``matched.echo_values``' constants)."""
        key = ("constants", t0_s, threshold_factor)
        found = self._records.get(key)
        if found is None:
            matched = self.matched
            self._forget_records()
            found = self._records[key] = read_only(record(
                ECHO_CONSTANTS, t0_s=t0_s, sample_rate_hz=matched.sample_rate_hz, template_t0_s=matched.template.t0_s,
                noise_gain=self.noise_gain, peak_response=matched.peak_response,
                peak_abs=float(np.max(np.abs(matched.template.samples))), rms_bandwidth_hz=matched.rms_bandwidth_hz,
                threshold_factor=threshold_factor))
        return found

    def threshold_factor(self, pfa: float, searched_lags: int) -> float:
        """``self.matched.threshold_factor(pfa, searched_lags)``, computed once per pair."""
        key = (pfa, searched_lags)
        factor = self._factors.get(key)
        if factor is None:
            factor = self._factors[key] = self.matched.threshold_factor(pfa, searched_lags)
        return factor

    @property
    def template_length(self) -> int:
        """Template length m (samples)."""
        return self.matched.template_length

    @property
    def segment_length(self) -> int:
        """Samples in a stretch: 2 half + m (lags -half .. +half around the coarse lag)."""
        return 2 * self.half + self.matched.template_length


def plan_local(template: Template, n_samples: int, sample_rate_hz: float) -> LocalPlan:
    """Precompute the local matched filter for a template and record length.

    Why a tone-correlation coarse stage (numbers for the 5 us Gaussian pulse at 20 MS/s,
    2E/N0 = 20 dB, i.e. sum s^2 = 100 sigma^2, B = 42, windows of 2 blocks): the window
    statistic of noise alone is sigma^2 B times a Gamma(2) variable (mean 2, and
    P(> x) = e^-x (1 + x)): among ~6,000 windows per 12.5 ms channel the largest is ~11.8
    sigma^2 B. An echo window adds ~ (B / 2) sum s^2 ~ 36 sigma^2 B (one block's coherent gain
    on ~90 % of the pulse's energy) with a signal-times-noise scatter of ~8.5 sigma^2 B: ~3
    scatters above the largest noise window. The broadband energy sum x^2 over the same span
    (chi-square with ~50 degrees of freedom, largest noise window ~95 sigma^2 against an echo
    window of ~140 +/- 19 sigma^2) leaves ~2.3 scatters. Either way a few candidates
    (default 3) make the chance that the echo is not among them negligible. Measured on 120
    channels of 12.5 ms with one echo each, against the full matched filter's TOF (within
    1 ns): 120/120 agree at 20 dB with 1, 2, 3 or 5 candidates; at 15 dB (where the full filter
    itself finds only 66) 62 with 1 candidate, 65 with 2, 3 or 5.

    Parameters
    ----------
    template : Template
        At ``sample_rate_hz``.
    n_samples : int
        Record length (samples).
    sample_rate_hz : float

    Raises
    ------
    RecordingError
        A template longer than the record.
    """
    import scipy.fft as sfft

    matched = plan_matched(template, n_samples, sample_rate_hz, full=False)
    s = np.asarray(template.samples, dtype=float)
    m = s.size
    fs = float(sample_rate_hz)
    half = m // 2
    segment_fft = sfft.next_fast_len(2 * half + 2 * m - 1, real=True)
    spectrum = sfft.rfft(s, segment_fft)
    spectrum_power = np.abs(spectrum) ** 2
    # Centre frequency and RMS bandwidth about it, from the template's power spectrum on the
    # stretch's FFT grid (spacing fs / (3 m), ~30 kHz here): B is rounded to whole samples and
    # the tone's frequency need only be close to the band's centre, so this grid is fine enough.
    freqs = np.arange(spectrum_power.size) * fs / segment_fft
    total = float(spectrum_power.sum())
    centre = float((freqs * spectrum_power).sum() / total)
    beta = float(np.sqrt(((freqs - centre) ** 2 * spectrum_power).sum() / total))
    block = int(np.clip(round(BLOCK_BANDWIDTH_FRACTION * fs / max(beta, 1e-12 * fs)), 1, max(1, m // 4)))
    # Windows of at least 2 blocks (an echo centred anywhere has a window whose middle is
    # within B / 2 of its centre) and covering 4 RMS durations of the template's energy.
    weight = s * s / float(np.sum(s * s))
    index = np.arange(m)
    mean_index = float((index * weight).sum())
    duration = 4.0 * math.sqrt(float(((index - mean_index) ** 2 * weight).sum()))
    span = int(max(2, math.ceil(duration / block)))
    span = min(span, max(1, n_samples // block))
    k = np.arange(block)
    phase = 2.0 * np.pi * centre / fs * k
    tone = np.stack([np.cos(phase), -np.sin(phase)], axis=1)
    lanes = np.zeros((2, block + (-block % 8)))  # the tone, zero padded (``LocalPlan.tone_lanes``)
    lanes[:, :block] = tone.T
    taps = matched.analytic_template_conj
    reference = int(np.argmax(np.abs(taps))) - matched.analytic_offset
    tail = np.cumsum(spectrum_power[::-1])[::-1] / total  # energy fraction at bins >= k
    k_hi = int(np.argmax(tail < _BAND_TAIL)) if np.any(tail < _BAND_TAIL) else spectrum.size
    k_hi = min(spectrum.size, k_hi + 2)
    weights = 2.0 * np.conj(spectrum[:k_hi])
    weights[0] *= 0.5
    # A band reaching the Nyquist frequency leaves no decimation: full rate (1).
    decimation = max(
        (d for d in range(1, segment_fft + 1) if segment_fft % d == 0 and segment_fft // d >= 2 * k_hi), default=1
    )
    partial = np.concatenate([[0.0], np.cumsum(taps)])
    return LocalPlan(
        matched=matched,
        block=block,
        span=span,
        tone=np.ascontiguousarray(tone),
        tone_sum=tone.sum(axis=0),
        centre_hz=centre,
        reference=reference,
        half=half,
        segment_fft=int(segment_fft),
        segment_weights=weights,
        tap_partial=partial,
        tap_parts=np.stack([np.append(taps.real, 0.0), np.append(taps.imag, 0.0), partial.real, partial.imag]),
        exclusion=max(1, -(-m // block)),
        tone_lanes=lanes,
        segment_weights32=weights.astype(np.complex64),
        noise_gain=float(white_noise_power(matched, 1.0)),
        tone_lanes32=lanes.astype(np.float32),
        tap_parts32=np.stack([np.append(taps.real, 0.0), np.append(taps.imag, 0.0)]).astype(np.float32),
        decimation=int(decimation),
    )


def block_tone_power(
    plan: LocalPlan, rows: NDArray[np.float64], dc: NDArray[np.float64] | None = None
) -> NDArray[np.float64]:
    """|z_b|^2 of every whole block of each row (tone correlation at f0, module notes).

    Parameters
    ----------
    rows : ndarray, shape (n_rows, n_samples)
    dc : ndarray, shape (n_rows,), optional
        Offset still in each row: the result is that of ``rows - dc``.

    Returns
    -------
    ndarray, shape (n_rows, n_samples // block), V^2
    """
    n_rows, n = rows.shape
    b = plan.block
    n_blocks = n // b
    parts = rows[:, : n_blocks * b].reshape(n_rows, n_blocks, b) @ plan.tone  # (n_rows, n_blocks, 2)
    if dc is not None:
        parts -= dc[:, np.newaxis, np.newaxis] * plan.tone_sum
    np.square(parts, out=parts)
    return parts[..., 0] + parts[..., 1]


def coarse_lags(
    plan: LocalPlan,
    rows: NDArray[np.float64],
    candidates: int,
    lag_bounds: tuple[int, int],
    dc: NDArray[np.float64] | None = None,
) -> NDArray[np.intp]:
    """Lags of the ``candidates`` strongest coarse windows of each row, a template length apart.

    Only windows whose lag lies in ``lag_bounds`` (inclusive) are considered; when a row has
    fewer such windows, the remaining picks repeat its strongest.

    Returns
    -------
    ndarray of int, shape (n_rows, candidates)
    """
    n_rows = rows.shape[0]
    energy = block_tone_power(plan, rows, dc)
    span = min(plan.span, energy.shape[1])
    n_windows = energy.shape[1] - span + 1
    # Moving sum of ``span`` blocks as shifted slices (a few adds over the block powers).
    b = plan.block
    centre = (span * b) // 2 - plan.reference  # lag of window w: w * b + centre
    lo, hi = lag_bounds
    first = min(max(-(-(lo - centre) // b), 0), n_windows - 1)  # windows [first, last) have lags in bounds
    last = max(min((hi - centre) // b + 1, n_windows), first + 1)
    window = energy[:, first:last] + energy[:, first + 1:last + 1] if span == 2 else energy[:, first:last].copy()
    if span != 2:
        for k in range(1, span):  # a few slices, not samples
            window += energy[:, first + k:last + k]
    exclusion = max(1, -(-plan.template_length // b))  # windows within a template length
    rows_index = np.arange(n_rows)[:, np.newaxis]
    offsets = np.arange(-exclusion, exclusion + 1)
    picks = np.empty((n_rows, int(candidates)), dtype=np.intp)
    for k in range(int(candidates)):  # a few candidates per row, not samples
        best = np.argmax(window, axis=1)
        picks[:, k] = best
        if k + 1 < candidates:  # blank each pick's neighbourhood (one fancy assignment)
            window[rows_index, np.minimum(np.maximum(best[:, np.newaxis] + offsets, 0), window.shape[1] - 1)] = -np.inf
    return np.minimum(np.maximum((first + picks) * b + centre, lo), hi)


def segment_spectra(
    plan: LocalPlan,
    rows: NDArray[np.float64],
    row_index: NDArray[np.intp],
    start_lag: NDArray[np.intp],
    dc: NDArray[np.float64] | None = None,
) -> NDArray[np.complex128]:
    """Band spectra of the local filter's output for stretches starting at ``start_lag``.

    The inverse FFT of length ``plan.segment_fft`` of a row of the result is z at lags
    ``start_lag + 0, 1, ...`` (exact for the first 2 half + 1).

    Parameters
    ----------
    row_index, start_lag : ndarray of int, shape (k,)
    dc : ndarray, shape (n_rows,), optional
        Offsets still in the rows (subtracted from the stretches).

    Returns
    -------
    ndarray, shape (k, n_bins), complex
        Samples beyond the record count as 0.
    """
    import scipy.fft as sfft

    n = rows.shape[1]
    index = start_lag[:, np.newaxis] + np.arange(plan.segment_length)
    if index.size and (index.min() < 0 or index.max() >= n):
        inside = (index >= 0) & (index < n)
        segment = np.where(inside, rows[row_index[:, np.newaxis], np.minimum(np.maximum(index, 0), n - 1)], 0.0)
        if dc is not None:
            segment -= np.where(inside, dc[row_index][:, np.newaxis], 0.0)
    else:
        segment = rows[row_index[:, np.newaxis], index]
        if dc is not None:
            segment -= dc[row_index][:, np.newaxis]
    spectrum = sfft.rfft(segment, plan.segment_fft, axis=-1)[:, : plan.segment_weights.size]
    spectrum *= plan.segment_weights
    return spectrum


def segment_correlation(
    plan: LocalPlan,
    rows: NDArray[np.float64],
    row_index: NDArray[np.intp],
    start_lag: NDArray[np.intp],
    dc: NDArray[np.float64] | None = None,
) -> NDArray[np.complex128]:
    """Analytic correlation z at lags ``start_lag + 0 .. 2 half`` from short FFTs of stretches.

    Returns
    -------
    ndarray, shape (k, 2 half + 1), complex
    """
    import scipy.fft as sfft

    spectrum = segment_spectra(plan, rows, row_index, start_lag, dc)
    return sfft.ifft(spectrum, plan.segment_fft, axis=-1)[:, : 2 * plan.half + 1]


def candidate_correlations(
    plan: LocalPlan,
    rows: NDArray[np.float64],
    candidates: int,
    lag_bounds: tuple[int, int],
    dc: NDArray[np.float64] | None = None,
    scale: float = 1.0,
    stride: int = 1,
) -> tuple[NDArray[np.complex64], NDArray[np.int64]]:
    """z around each row's ``candidates`` coarse picks: what ``coarse_lags`` then
    ``segment_correlation`` give, from one compiled pass (``local_kernels.coarse_stretches``)
    and one batched short FFT pair over all rows' stretches.

    The short FFTs run in single precision (the stretches rounded to float32): z then carries
    relative errors of ~1e-6 of its largest value, which only choose the integer lag of the
    largest |z|; the TOF and amplitude come from the direct float64 correlations around that lag
    (``local_kernels.local_peaks``, which takes the largest of the 2 R + 1 direct values, the
    outer two excepted), so the result is the same unless two lags more than R - 1 apart have |z|
    within ~1e-6 of each other (two echoes of equal strength to a part in a million). Half the
    bytes of the float64 FFTs. The detection path (``local_kernels.local_echoes``) searches the
    stretches by direct correlations instead; this FFT route is its reference.

    Parameters
    ----------
    scale : float
        Volts per unit of ``rows`` (1.0 for volts, the code step for int16 codes).
    stride : int
        1: z at every lag; ``plan.decimation``: at every stride-th lag (times stride: the
        inverse FFT normalises by its length).

    Returns
    -------
    z : ndarray, shape (n_rows * candidates, segment_fft // stride), complex64
        Row r's pick k at r * candidates + k; its entries j with stride j <= 2 half are z at
        lags ``start + stride j`` (times stride).
    start : ndarray of int, shape (n_rows * candidates,)
    """
    import scipy.fft as sfft

    from binsonar.detection import local_kernels

    n_rows = rows.shape[0]
    count = n_rows * candidates
    segments = np.empty((count, plan.segment_fft), dtype=np.float32)
    start = np.empty(count, dtype=np.int64)
    samples = np.ascontiguousarray(rows, dtype=np.int16 if np.issubdtype(rows.dtype, np.integer) else float)
    offsets = np.zeros(n_rows) if dc is None else np.ascontiguousarray(dc, dtype=float).reshape(n_rows)
    local_kernels.coarse_stretches(samples, offsets, plan.tone_lanes, plan.search(lag_bounds, candidates, float(scale)),
                                   segments, start)
    spectrum = sfft.rfft(segments, axis=-1, overwrite_x=True)
    band = plan.segment_weights32.size
    # The band, zero above it, inverse transformed on segment_fft // stride points: z at every
    # ``stride``-th lag, over ``stride`` (``LocalPlan.decimation``).
    weighted = np.zeros((count, plan.segment_fft // stride), dtype=np.complex64)
    np.multiply(spectrum[:, :band], plan.segment_weights32, out=weighted[:, :band])
    return sfft.ifft(weighted, axis=-1, overwrite_x=True), start


def numpy_peaks(
    plan: LocalPlan,
    rows: NDArray[np.float64],
    candidates: int,
    lag_bounds: tuple[int, int],
    dc: NDArray[np.float64] | None = None,
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Each row's refined peak, all in numpy: the definition the compiled detection path
    (``local_kernels.local_echoes``) is checked against.

    ``coarse_lags``, then z at every lag of each pick's stretch (``segment_correlation``), the
    largest |z| over the searched lags, then the full matched filter's refinement around it
    (``matched.lags_time_domain`` minus ``matched.dc_correlation`` at the 2 R + 1 lags around,
    0 outside ``lag_bounds``, and ``matched.refine``'s vertex).

    Returns
    -------
    lag : ndarray, shape (n_rows,)
        Fractional lag of each row's vertex (samples).
    power : ndarray, shape (n_rows,)
        |z|^2 there.
    """
    lo, hi = lag_bounds
    n_rows = rows.shape[0]
    coarse = coarse_lags(plan, rows, candidates, lag_bounds, dc)
    width = 2 * plan.half + 1
    start = np.maximum(np.minimum(coarse - plan.half, hi - (width - 1)), lo).reshape(-1)
    z = segment_correlation(plan, rows, np.repeat(np.arange(n_rows), candidates), start, dc)
    power = np.abs(z) ** 2
    lags = start[:, np.newaxis] + np.arange(width)
    power[(lags < lo) | (lags > hi)] = -1.0
    best = np.argmax(power.reshape(n_rows, -1), axis=1)
    peak_lag = lags.reshape(n_rows, -1)[np.arange(n_rows), best]
    refine_lags = peak_lag[:, np.newaxis] + np.arange(-REFINE_HALF_WIDTH, REFINE_HALF_WIDTH + 1)
    direct = lags_time_domain(plan.matched, rows, np.arange(n_rows), refine_lags)
    if dc is not None:
        direct -= dc_correlation(plan.matched, rows.shape[1], dc, refine_lags, plan.tap_partial)
    direct[(refine_lags < lo) | (refine_lags > hi)] = 0.0
    return refine(direct, refine_lags)


def detect_local_matched(
    rows: NDArray[np.float64],
    plan: LocalPlan,
    *,
    t0_s: float,
    pfa: float = 1e-3,
    search_window_s: tuple[float, float] | None = None,
    noise_window_s: tuple[float, float] | None = None,
    candidates: int = 3,
    where: str = "record",
    noise_floor_v: float = 0.0,
    dc_v: NDArray[np.float64] | None = None,
    robust_sigma_v: NDArray[np.float64] | None = None,
    volts_per_code: float | None = None,
    extremes_out: NDArray[np.float64] | None = None,
) -> list[list[tuple[float, float, float, float, float]]]:
    """Local matched filter around the strongest coarse windows of each row (module notes).

    Parameters
    ----------
    rows : ndarray, shape (n_rows, n_samples)
        Volts, or int16 ADC codes with ``volts_per_code``.
    plan : LocalPlan
        From ``plan_local`` for this template and record length.
    t0_s : float
    pfa : float
        Design false-alarm probability per record (same threshold as ``detect_matched``).
    search_window_s : (start_s, stop_s), optional
        Only TOFs in this window (s after the trigger); as for ``detect_matched``, lags where
        the template would stick out of the record are never searched.
    noise_window_s : (start_s, stop_s), optional
        Noise-only window for the noise floor (default: robust estimate over the record).
    candidates : int
        Number of coarse windows (the strongest, a template length apart) around which the
        local matched filter is run; the largest |z| among them wins.
    noise_floor_v : float
        Least noise standard deviation (V), the ADC's quantisation noise: the noise estimate
        is never below it.
    dc_v : ndarray, shape (n_rows,), optional
        DC offset of each row still in ``rows`` (``Signals.dc_v``), folded in (module notes):
        the result is that of ``rows - dc_v`` to rounding, without a copy of the record.
    robust_sigma_v : ndarray, shape (n_rows,), optional
        The rows' robust noise estimate, already measured (``inputs.Signals.noise_sigma_v``):
        used instead of measuring it again when there is no ``noise_window_s``.
    volts_per_code : float, optional
        ``rows`` are ADC codes of this step (V), read as they are (2 bytes a sample): the
        block correlations are scaled to volts, the stretches and the direct correlations
        made of volts code * volts_per_code, so the result is that of the volts to rounding.
    extremes_out : ndarray, shape (n_rows, 2), optional
        Written with each row's largest and smallest value (units of ``rows``), read with the
        coarse pass (no pass of its own): the clipping test ``api`` defers to here for records
        of ADC codes (``inputs.Signals.pending_full_scales_v``).

    Returns
    -------
    list (n_rows) of list of (tof_s, amplitude, snr_db, score, tof_std_s)
    """
    pfa = check_pfa(pfa)
    if not isinstance(plan, LocalPlan):
        raise TypeError("detect_local_matched needs a LocalPlan (plan_local)")
    matched = plan.matched
    fs = matched.sample_rate_hz
    n_rows = rows.shape[0]
    if not (isinstance(candidates, (int, np.integer)) and 1 <= candidates <= 16):
        raise RecordingError(f"{where}: candidates must be an integer in [1, 16], got {candidates!r}")
    lag_lo, lag_hi = lag_range(matched, t0_s, search_window_s, where)
    dc = None if dc_v is None else np.ascontiguousarray(dc_v, dtype=float).reshape(n_rows)
    sigma = noise_sigma(rows, sample_rate_hz=fs, t0_s=t0_s, noise_window_s=noise_window_s, where=where,
                        floor_v=noise_floor_v, offset_v=dc, robust_v=robust_sigma_v, volts_per_code=volts_per_code)
    samples = np.ascontiguousarray(rows, dtype=np.int16 if volts_per_code is not None else float)  # contiguous blocks
    scale = 1.0 if volts_per_code is None else float(volts_per_code)
    # ``matched.echo_values`` of the vertex, the noise as ``white_noise_power`` (2 sigma^2 sum s^2:
    # white noise through the filter); pfa over the searched lags, as detect_matched.
    constants = plan.echo_constants(t0_s, plan.threshold_factor(pfa, lag_hi - lag_lo))
    echoes = np.empty(n_rows, dtype=ECHO)
    from binsonar.detection import local_kernels

    # Steps 1-3 and the echo values in one compiled call (``local_kernels.local_echoes``: the
    # coarse pass, each stretch searched every ``stride`` lags by direct correlations, the
    # refinement as the full matched filter's, ``matched.echo_values``; checked against
    # ``numpy_peaks`` and the FFT route in tests/parity/test_detection_local_kernels.py).
    lanes = plan.tone_lanes if volts_per_code is None else plan.tone_lanes32  # codes: float32 block sums
    local_kernels.local_echoes(samples, np.zeros(n_rows) if dc is None else dc, sigma, lanes, plan.tap_parts,
                               plan.tap_parts32, plan.search((lag_lo, lag_hi), candidates, scale), constants, echoes,
                               np.empty((0, 2)) if extremes_out is None else extremes_out)
    # One conversion to Python floats for all rows (``tolist``: the same values as float(v[row])).
    return [[echo] if echo[SCORE] >= 1.0 else [] for echo in echoes.tolist()]
