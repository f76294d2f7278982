"""Compiled loops of the local matched filter (numba, cached on disk, GIL released).

Imported by :mod:`binsonar.detection.local` when a local matched filter runs (never by
``import binsonar``). The detection path is one call for all rows of a record,
:func:`local_echoes`: :func:`coarse_starts` (the coarse stage, each sample of the searched
blocks read once: the block correlations with the tone, the windows' moving sums, the
``candidates`` strongest windows a template length apart; optionally every sample's extremes,
the clipping test of records of codes), the search of each candidate's stretch every
``LocalPlan.decimation`` lags by direct dot products with the analytic template
(``_four_lags32``), z at the ``2 R + 1`` integer lags around the largest (``_refine_row``: the
same evaluation as ``matched.lags_time_domain`` minus ``matched.dc_correlation``) and the
log-parabolic vertex of ``matched.refine``, then :func:`echo_rows` (the TOF, amplitude, SNR,
score and TOF std of each row's vertex, ``matched.echo_values``' operations in its order).

The FFT route is the direct search's reference: :func:`coarse_stretches` (the coarse stage,
then each candidate's stretch, DC removed and zero padded, into the buffer of
``local.candidate_correlations``' batched short FFTs) and :func:`local_peaks` (the largest |z|
over all candidates' lags from those FFTs, then ``_refine_row``).

All follow :mod:`binsonar.detection.local`'s numpy definitions step for step (same ties:
first maximum; same bounds); only the order of the floating-point sums differs, i.e. results
agree to rounding (``tests/parity/test_detection_local_kernels.py``). The arguments are the
bundles of ``kernel_types``. ``cache=True`` stores the compiled code in ``__pycache__`` beside
this file (or numba's per-user cache directory): the first run in a fresh checkout compiles
them, later processes load them.
"""

from __future__ import annotations

import numpy as np
from numba import njit
from numpy.typing import NDArray


@njit(cache=True, nogil=True)
def tone_offsets(dc_v: NDArray[np.float64], lanes: NDArray, block: int) -> tuple:
    """The block correlation of each row's DC offset: dc times the tone's column sums over its
    ``block`` taps (real and imaginary parts, each shape (n_rows,))."""
    sum_cos = 0.0
    sum_sin = 0.0
    for q in range(block):
        sum_cos += lanes[0, q]
        sum_sin += lanes[1, q]
    return dc_v * sum_cos, dc_v * sum_sin


@njit(cache=True, nogil=True, fastmath=True)
def block_powers(samples: NDArray, lanes: NDArray, search: NDArray[np.void], first_block: int,
                 energy: NDArray[np.float64], offset_re: NDArray[np.float64], offset_im: NDArray[np.float64]) -> None:
    """|z_b|^2 of blocks first_block + 0 .. energy.shape[1] - 1 of every row (``local.block_tone_power``).

    Four blocks at a time: eight independent multiply-add chains over the tone table, with no
    reduction inside a block, so each sample is read once; the rows advance together, four
    blocks of each in turn (several memory streams keep more of a new record's cache misses in
    flight). The tone table is zero padded to a multiple of 8 taps (``lanes``): each block's sum
    then runs over whole vectors, with no scalar remainder loop; the padded taps read the next
    block's first samples and multiply them by exactly 0. Used wherever those extra samples
    exist in the row (all but the last few blocks of a row, which take their own taps only).
    fastmath is safe here: finite sums only.

    Parameters
    ----------
    samples : ndarray, shape (n_rows, n_samples), C-contiguous
        float64 volts or int16 ADC codes: each block's correlation of the raw values is scaled
        to volts once (``search``'s scale), before the offset is subtracted.
    lanes : ndarray, shape (2, L), L >= block a multiple of 8
        cos and -sin of 2 pi f0 k / fs for k < block, 0 beyond (``LocalPlan.tone_lanes``),
        float64; or float32 (``LocalPlan.tone_lanes32``) for int16 codes: the codes convert
        exactly to float32 and each group's sums run in float32, twice the lanes of a vector. A
        block's float32 sum of ~48 products is within ~48 x 6e-8 of the sum of their magnitudes
        (~1e-7 of a block's correlation): the coarse statistic only picks the candidates, which
        then are the float64 ones unless two windows' statistics agree to ~1e-6.
    search : ndarray of ``kernel_types.LOCAL_SEARCH``, shape (1,)
        Its scale and block (block length B, samples).
    first_block : int
    energy : ndarray, shape (n_rows, n_blocks), written
    offset_re, offset_im : ndarray, shape (n_rows,)
        ``tone_offsets(dc_v, lanes, block)``: subtracted from each block's correlation.
    """
    scale, block = search[0].scale, search[0].block
    n_rows, n = samples.shape
    n_blocks = energy.shape[1]
    padded = lanes.shape[1]
    c = lanes[0]
    s = lanes[1]
    zero = c[0] - c[0]  # the sums' type: the table's (float32 for int16 codes), or float64 rows'
    # Groups of four blocks whose padded reads stay inside the rows: blocks [0, fast), block j
    # reading up to sample (first_block + j) * block + padded - 1 < n.
    fast = max(0, min(n_blocks, (n - padded) // block - first_block + 1)) // 4 * 4
    for j in range(0, fast, 4):
        base = (first_block + j) * block
        for r in range(n_rows):
            row = samples[r]
            x0 = row[base: base + padded]
            x1 = row[base + block: base + block + padded]
            x2 = row[base + 2 * block: base + 2 * block + padded]
            x3 = row[base + 3 * block: base + 3 * block + padded]
            r0 = r1 = r2 = r3 = zero
            i0 = i1 = i2 = i3 = zero
            for q in range(padded):
                cq = c[q]
                sq = s[q]
                r0 += x0[q] * cq
                r1 += x1[q] * cq
                r2 += x2[q] * cq
                r3 += x3[q] * cq
                i0 += x0[q] * sq
                i1 += x1[q] * sq
                i2 += x2[q] * sq
                i3 += x3[q] * sq
            r0 = r0 * scale - offset_re[r]
            r1 = r1 * scale - offset_re[r]
            r2 = r2 * scale - offset_re[r]
            r3 = r3 * scale - offset_re[r]
            i0 = i0 * scale - offset_im[r]
            i1 = i1 * scale - offset_im[r]
            i2 = i2 * scale - offset_im[r]
            i3 = i3 * scale - offset_im[r]
            energy[r, j] = r0 * r0 + i0 * i0
            energy[r, j + 1] = r1 * r1 + i1 * i1
            energy[r, j + 2] = r2 * r2 + i2 * i2
            energy[r, j + 3] = r3 * r3 + i3 * i3
    for r in range(n_rows):  # the last few blocks: their own taps only
        row = samples[r]
        for j in range(fast, n_blocks):
            base = (first_block + j) * block
            x = row[base: base + block]
            re = 0.0
            im = 0.0
            for q in range(block):
                re += x[q] * c[q]
                im += x[q] * s[q]
            re = re * scale - offset_re[r]
            im = im * scale - offset_im[r]
            energy[r, j] = re * re + im * im


@njit(cache=True, nogil=True, fastmath=True)
def _span_extremes(row: NDArray, start: int, stop: int, extremes: NDArray[np.float64]) -> None:
    """Fold the largest and smallest of ``row[start:stop]`` (stop > start) into ``extremes``
    (largest, smallest), as ``code_kernels.row_extremes`` does for a whole row.

    Written as a loop over a slice with comparisons, which LLVM turns into vector max/min for
    int16 codes. Exact in any order. Float rows (finite: ``inputs`` refuses NaN/inf; fastmath
    assumes it) run scalar: only records of codes defer their clipping test to here
    (``DetectionMethod.measures_extremes``).
    """
    x = row[start:stop]
    high = x[0]
    low = x[0]
    for i in range(1, x.size):
        v = x[i]
        high = v if v > high else high
        low = v if v < low else low
    extremes[0] = max(extremes[0], float(high))
    extremes[1] = min(extremes[1], float(low))


# Blocks per chunk when ``coarse_starts`` also measures the rows' extremes: the block powers of
# a chunk (a multiple of four blocks: whole groups), then its extremes while the chunk is still
# in cache (64 blocks of 42 samples: 5 kB of codes or 21 kB of volts per row).
_EXTREMES_CHUNK = 64


# Windows per group of the candidate search: each pick scans the groups' maxima and one group,
# not every window.
_GROUP = 64


@njit(cache=True, nogil=True)
def _group_max(window: NDArray[np.float64], lo: int, hi: int) -> float:
    """max(window[lo:hi]) (hi > lo)."""
    value = window[lo]
    for w in range(lo + 1, hi):
        if window[w] > value:
            value = window[w]
    return value


@njit(cache=True, nogil=True)
def coarse_starts(
    samples: NDArray,
    dc_v: NDArray[np.float64],
    lanes: NDArray,
    search: NDArray[np.void],
    starts: NDArray[np.int64],
    extremes: NDArray[np.float64],
) -> None:
    """Coarse candidates of every row (``local.coarse_lags``, each searched sample read once):
    the first lag of the stretch searched around each.

    Parameters
    ----------
    samples : ndarray, shape (n_rows, n_samples), C-contiguous
        float64 volts or int16 ADC codes (``search``'s scale: volts per unit).
    dc_v : ndarray, shape (n_rows,)
        Each row's DC offset (V) still in the samples (zeros for none).
    lanes : ndarray, shape (2, L), C-contiguous
        cos and -sin of 2 pi f0 k / fs, k < block, zero padded (``LocalPlan.tone_lanes``, or
        ``LocalPlan.tone_lanes32`` for int16 codes: ``block_powers``).
    search : ndarray of ``kernel_types.LOCAL_SEARCH``, shape (1,)
        The scale, the layout (block, span, reference, exclusion, half) and the searched lags
        (lag_lo, lag_hi, candidates).
    starts : ndarray of int, shape (n_rows * candidates,), written
        Lag of each stretch's sample 0 (its first searched lag), row r's pick k at
        r * candidates + k.
    extremes : ndarray, shape (n_rows, 2) or (0, 2), written
        With n_rows rows: each row's largest and smallest value over all its samples, in the
        units of ``rows`` (the clipping test of ``inputs.Signals.with_extremes``), each chunk of
        blocks scanned while it is in cache after its block powers, then the samples outside
        the blocks read: no pass over the record of its own. With none: not computed.
    """
    p = search[0]
    span, reference, exclusion, half, block = p.span, p.reference, p.exclusion, p.half, p.block
    lag_lo, lag_hi, candidates = p.lag_lo, p.lag_hi, p.candidates
    n_rows, n = samples.shape
    n_blocks = n // block
    sp = min(span, n_blocks)
    n_windows = n_blocks - sp + 1
    centre = (sp * block) // 2 - reference  # lag of window w: w * block + centre
    first = min(max(-(-(lag_lo - centre) // block), 0), n_windows - 1)
    last = max(min((lag_hi - centre) // block + 1, n_windows), first + 1)
    n_searched = last - first
    energies = np.empty((n_rows, n_searched + sp - 1))
    window = np.empty(n_searched)
    n_groups = -(-n_searched // _GROUP)
    group_max = np.empty(n_groups)
    width = 2 * half + 1
    offset_re, offset_im = tone_offsets(dc_v, lanes, block)
    if extremes.shape[0] != n_rows:
        block_powers(samples, lanes, search, first, energies, offset_re, offset_im)
    else:
        # Chunk by chunk: the block powers (the same sums as in one call), then the chunk's
        # extremes, read again from the cache rather than from memory; then the samples outside
        # the blocks read.
        for r in range(n_rows):
            extremes[r, 0] = -np.inf
            extremes[r, 1] = np.inf
        n_read = energies.shape[1]
        for c0 in range(0, n_read, _EXTREMES_CHUNK):
            c1 = min(c0 + _EXTREMES_CHUNK, n_read)
            block_powers(samples, lanes, search, first + c0, energies[:, c0:c1], offset_re, offset_im)
            for r in range(n_rows):
                _span_extremes(samples[r], (first + c0) * block, (first + c1) * block, extremes[r])
        for r in range(n_rows):
            if first > 0:
                _span_extremes(samples[r], 0, first * block, extremes[r])
            if (first + n_read) * block < n:
                _span_extremes(samples[r], (first + n_read) * block, n, extremes[r])
    for r in range(n_rows):
        energy = energies[r]
        # The moving sums as ``sp`` passes over the windows (the same additions in the same
        # order as a sum per window, so the same values).
        for w in range(n_searched):
            window[w] = energy[w]
        for t in range(1, sp):
            for w in range(n_searched):
                window[w] += energy[w + t]
        for g in range(n_groups):
            group_max[g] = _group_max(window, g * _GROUP, min((g + 1) * _GROUP, n_searched))
        for k in range(candidates):
            # The first window holding the largest value (as one scan of all windows with a
            # strict >): the first group whose maximum is the largest, then its first window
            # reaching it. Exact, ties and all-blanked (-inf) rows included: window 0 then.
            top = 0
            value = group_max[0]
            for g in range(1, n_groups):
                if group_max[g] > value:
                    value = group_max[g]
                    top = g
            best = top * _GROUP
            value = window[best]
            for w in range(best + 1, min((top + 1) * _GROUP, n_searched)):
                if window[w] > value:
                    value = window[w]
                    best = w
            for o in range(-exclusion, exclusion + 1):
                window[min(max(best + o, 0), n_searched - 1)] = -np.inf
            for g in range(max(best - exclusion, 0) // _GROUP, min(best + exclusion, n_searched - 1) // _GROUP + 1):
                group_max[g] = _group_max(window, g * _GROUP, min((g + 1) * _GROUP, n_searched))
            lag = min(max((first + best) * block + centre, lag_lo), lag_hi)
            starts[r * candidates + k] = max(min(lag - half, lag_hi - (width - 1)), lag_lo)


@njit(cache=True, nogil=True)
def coarse_stretches(
    samples: NDArray,
    dc_v: NDArray[np.float64],
    lanes: NDArray,
    search: NDArray[np.void],
    segments: NDArray[np.float32],
    starts: NDArray[np.int64],
) -> None:
    """Coarse candidates of every row and their stretches (``local.coarse_lags`` and
    ``local.segment_spectra``'s input, in one pass): ``coarse_starts``, then each pick's
    stretch gathered for the short FFTs of ``local.candidate_correlations`` (the FFT route,
    the reference the direct search of ``local_echoes`` is tested against).

    Parameters
    ----------
    samples, dc_v, lanes, search, starts
        As for ``coarse_starts``.
    segments : ndarray, shape (n_rows * candidates, n_fft), float32, written
        Stretch of each pick (row r's pick k at r * candidates + k), ``rows - dc`` rounded to
        float32 (the short FFTs only pick the peak's integer lag), samples outside the record
        and beyond ``segment_length`` set to 0.
    """
    candidates, segment_length, scale = search[0].candidates, search[0].segment_length, search[0].scale
    n_rows, n = samples.shape
    n_fft = segments.shape[1]
    coarse_starts(samples, dc_v, lanes, search, starts, np.empty((0, 2)))
    for r in range(n_rows):
        d = dc_v[r]
        for k in range(candidates):
            i = r * candidates + k
            start = starts[i]
            for s in range(segment_length):
                index = start + s
                segments[i, s] = samples[r, index] * scale - d if 0 <= index < n else 0.0
            for s in range(segment_length, n_fft):
                segments[i, s] = 0.0


@njit(cache=True, nogil=True)
def _log_parabolic(left: float, centre: float, right: float) -> tuple:
    """``peaks.log_parabolic_offset`` for one peak: (offset, peak power)."""
    if not (left > 0.0 and right > 0.0 and centre >= left and centre >= right):
        return 0.0, centre
    y_l = np.log(left)
    y_c = np.log(centre)
    y_r = np.log(right)
    curvature = y_l - 2.0 * y_c + y_r
    if not curvature < 0.0:
        return 0.0, centre
    offset = min(max(0.5 * (y_l - y_r) / curvature, -0.5), 0.5)
    return offset, np.exp(y_c - 0.25 * (y_l - y_r) * offset)


@njit(cache=True, nogil=True)
def local_peaks(
    z: NDArray[np.complex128],
    starts: NDArray[np.int64],
    samples: NDArray,
    dc_v: NDArray[np.float64],
    taps: NDArray[np.float64],
    search: NDArray[np.void],
    values: NDArray[np.complex128],
    refined: NDArray[np.float64],
) -> None:
    """Each row's largest |z| over its candidates' lags, z at integer lags around it, its vertex.

    Parameters
    ----------
    z : ndarray, shape (n_rows * candidates, >= ceil(width / stride)), complex
        Local filter output of each stretch at lags ``starts + stride j`` (width = 2 half + 1
        lags).
    starts : ndarray of int, shape (n_rows * candidates,)
    samples, dc_v
        As for ``coarse_starts``.
    taps : ndarray, shape (4, m_a + 1)
        ``LocalPlan.tap_parts``: the conjugated analytic template (real, imaginary; first m_a
        columns) and its running sums, 0 first.
    search : ndarray of ``kernel_types.LOCAL_SEARCH``, shape (1,)
        Its scale, half, lag_lo, lag_hi, candidates, analytic_offset and stride (the reach is
        ``values``' half width).
    values : ndarray, shape (n_rows, 2 R + 1), complex, written
        Direct z (``rows - dc``; 0 at lags outside [lag_lo, lag_hi]) at the peak's lag + (-R .. R),
        as ``matched.lags_time_domain`` minus ``matched.dc_correlation`` (R >= stride keeps the
        largest |z| among them when z is sampled every stride lags: ``LocalPlan.decimation``).
    refined : ndarray, shape (n_rows, 2), written
        ``matched.refine`` of ``values``: fractional lag and |z|^2 at the vertex.
    """
    p = search[0]
    candidates, lag_lo, lag_hi = p.candidates, p.lag_lo, p.lag_hi
    width = 2 * p.half + 1
    stride = p.stride
    n_rows = samples.shape[0]
    power = np.empty(values.shape[1])
    for r in range(n_rows):
        best_lag = 0
        best = -2.0
        for k in range(candidates):
            i = r * candidates + k
            for j in range((width + stride - 1) // stride):
                lag = starts[i] + stride * j
                c = z[i, j]
                p = c.real * c.real + c.imag * c.imag if lag_lo <= lag <= lag_hi else -1.0
                if p > best:
                    best = p
                    best_lag = lag
        _refine_row(samples[r], dc_v[r], taps, search, best_lag, values[r], power, refined[r])


@njit(cache=True, nogil=True)
def _folded(re: float, im: float, first: int, n: int, scale: float, d: float, taps: NDArray[np.float64]) -> tuple:
    """z of ``row * scale - d`` at the lag whose tap 0 lies on sample ``first`` of a row of n
    samples, from the raw sums of row times the taps (samples outside the row counting 0): the
    sums scaled, then d times the sum of the taps that overlap the row subtracted
    (``matched.lags_time_domain`` minus ``matched.dc_correlation``). Real and imaginary parts."""
    m_a = taps.shape[1] - 1
    lo = min(max(-first, 0), m_a)
    hi = min(max(n - first, 0), m_a)
    re *= scale
    im *= scale
    if hi > lo:
        re -= d * (taps[2, hi] - taps[2, lo])
        im -= d * (taps[3, hi] - taps[3, lo])
    return re, im


@njit(cache=True, nogil=True)
def _refine_row(row: NDArray, d: float, taps: NDArray[np.float64], search: NDArray[np.void], best_lag: int,
                values: NDArray[np.complex128], power: NDArray[np.float64], refined: NDArray[np.float64]) -> None:
    """Direct z of ``row * scale - d`` at ``best_lag - reach .. best_lag + reach`` (reach =
    values.size // 2; 0 outside [lag_lo, lag_hi]) into ``values``, and ``matched.refine``'s
    vertex of the largest |z| among them, the outer two excepted, into ``refined`` (fractional
    lag, |z|^2)."""
    p = search[0]
    scale, analytic_offset, lag_lo, lag_hi = p.scale, p.analytic_offset, p.lag_lo, p.lag_hi
    n = row.size
    m_a = taps.shape[1] - 1
    n_lags = values.size
    reach = n_lags // 2
    groups = (n_lags + 3) // 4
    # The record under the lags, float64, 0 outside it, four lags at a time (``_four_lags``);
    # then scaled and the DC folded (``_folded``).
    origin = best_lag - reach - analytic_offset
    stretch = np.empty(4 * groups - 1 + m_a)
    for i in range(stretch.size):
        index = origin + i
        stretch[i] = row[index] if 0 <= index < n else 0.0
    for g in range(groups):
        sums = _four_lags(stretch, 4 * g, 1, taps)
        for q in range(min(4, n_lags - 4 * g)):
            j = 4 * g + q
            lag = best_lag - reach + j
            if lag < lag_lo or lag > lag_hi:
                values[j] = 0.0
            else:
                re, im = _folded(sums[2 * q], sums[2 * q + 1], lag - analytic_offset, n, scale, d, taps)
                values[j] = complex(re, im)
            power[j] = values[j].real ** 2 + values[j].imag ** 2
    top = 0
    for j in range(1, n_lags):
        if power[j] > power[top]:
            top = j
    top = min(max(top, 1), n_lags - 2)
    offset, peak = _log_parabolic(power[top - 1], power[top], power[top + 1])
    refined[0] = best_lag - reach + top + offset
    refined[1] = peak


@njit(cache=True, nogil=True)
def echo_rows(refined: NDArray[np.float64], sigma: NDArray[np.float64], constants: NDArray[np.void],
              echoes: NDArray[np.void]) -> None:
    """TOF, amplitude, SNR, score and TOF std of each row's refined peak: ``matched.echo_values``
    (with ``matched.white_noise_power`` for the noise) compiled for a few rows, the same
    operations in the same order (``tests/parity/test_detection_local_kernels.py``).

    Parameters
    ----------
    refined : ndarray, shape (n_rows, 2)
        Fractional lag and |z|^2 at the vertex (``local_peaks``).
    sigma : ndarray, shape (n_rows,)
        Noise standard deviation of each row (V, ``noise.noise_sigma``: floored).
    constants : ndarray of ``kernel_types.ECHO_CONSTANTS``, shape (1,)
    echoes : ndarray of ``kernel_types.ECHO``, shape (n_rows,), written
    """
    c = constants[0]
    t0_s, fs, template_t0_s, gain = c.t0_s, c.sample_rate_hz, c.template_t0_s, c.noise_gain
    peak_response, peak_abs, rms_bandwidth, factor = c.peak_response, c.peak_abs, c.rms_bandwidth_hz, c.threshold_factor
    for r in range(refined.shape[0]):
        lag = refined[r, 0]
        power = refined[r, 1]
        noise_mean = max(sigma[r] * sigma[r] * gain, 1e-20 * power)
        snr = max(2.0 * power / noise_mean - 2.0, 1e-3)
        echo = echoes[r]
        echo.tof_s = t0_s + lag / fs - template_t0_s
        echo.amplitude = np.sqrt(power) / peak_response * peak_abs
        echo.snr_db = 10.0 * np.log10(snr)
        echo.score = power / (factor * noise_mean)
        echo.tof_std_s = 1.0 / (2.0 * np.pi * rms_bandwidth * np.sqrt(snr))


@njit(cache=True, nogil=True, fastmath=True)
def _four_lags(x: NDArray[np.float64], first: int, stride: int, taps: NDArray[np.float64]) -> tuple:
    """sum_t x[first + stride i + t] taps[:, t], t < m_a, for i = 0 .. 3: real and imaginary parts.

    Four lags at once, eight independent multiply-add chains over the taps (as ``block_powers``).
    fastmath: finite sums only. ``x`` must hold samples up to first + 3 stride + m_a - 1.
    """
    m_a = taps.shape[1] - 1
    c = taps[0]
    s = taps[1]
    x0 = x[first: first + m_a]
    x1 = x[first + stride: first + stride + m_a]
    x2 = x[first + 2 * stride: first + 2 * stride + m_a]
    x3 = x[first + 3 * stride: first + 3 * stride + m_a]
    r0 = r1 = r2 = r3 = 0.0
    i0 = i1 = i2 = i3 = 0.0
    for q in range(m_a):
        cq = c[q]
        sq = s[q]
        r0 += x0[q] * cq
        r1 += x1[q] * cq
        r2 += x2[q] * cq
        r3 += x3[q] * cq
        i0 += x0[q] * sq
        i1 += x1[q] * sq
        i2 += x2[q] * sq
        i3 += x3[q] * sq
    return r0, i0, r1, i1, r2, i2, r3, i3


@njit(cache=True, nogil=True, fastmath=True)
def _four_lags32(x: NDArray[np.float32], first: int, stride: int, taps: NDArray[np.float32]) -> tuple:
    """``_four_lags`` in single precision (twice the lanes per vector): float32 samples and taps
    (rows 0-1 of ``taps``), float32 sums. For the search of ``local_echoes`` only, which picks
    the lag the float64 refinement starts from."""
    m_a = taps.shape[1] - 1
    c = taps[0]
    s = taps[1]
    x0 = x[first: first + m_a]
    x1 = x[first + stride: first + stride + m_a]
    x2 = x[first + 2 * stride: first + 2 * stride + m_a]
    x3 = x[first + 3 * stride: first + 3 * stride + m_a]
    r0 = r1 = r2 = r3 = np.float32(0.0)
    i0 = i1 = i2 = i3 = np.float32(0.0)
    for q in range(m_a):
        cq = c[q]
        sq = s[q]
        r0 += x0[q] * cq
        r1 += x1[q] * cq
        r2 += x2[q] * cq
        r3 += x3[q] * cq
        i0 += x0[q] * sq
        i1 += x1[q] * sq
        i2 += x2[q] * sq
        i3 += x3[q] * sq
    return r0, i0, r1, i1, r2, i2, r3, i3


@njit(cache=True, nogil=True)
def local_echoes(
    samples: NDArray,
    dc_v: NDArray[np.float64],
    sigma: NDArray[np.float64],
    lanes: NDArray,
    taps: NDArray[np.float64],
    taps32: NDArray[np.float32],
    search: NDArray[np.void],
    constants: NDArray[np.void],
    echoes: NDArray[np.void],
    extremes: NDArray[np.float64],
) -> None:
    """The whole local matched filter of every row in one call: ``coarse_starts``, the search
    of each pick's stretch, ``_refine_row``, ``echo_rows``.

    The search: |z| at every ``stride``-th lag of each stretch (lags ``start + stride j``,
    ``stride j <= 2 half``, those in [lag_lo, lag_hi]), each by a direct dot product with the
    analytic template (the refinement's z at that lag, in single precision: float32 stretch and
    taps, float32 sums of ~1,000 terms, errors ~1e-6 of the stretch's largest |z|); the largest
    picks the lag the float64 refinement starts from. The FFT route
    (``local.candidate_correlations`` then ``local_peaks``) samples the same lags with the
    band-limited z, also in float32 (errors ~1e-6 of the peak, plus the Hilbert tails beyond
    the stretch, ~1e-5): the two pick the same lag unless two sampled lags have |z| within
    ~1e-5 of each other, and then the same refined peak whenever both lie within
    ``stride - 1`` lags of it (two lattice lags straddling one peak), so the same echoes
    (``tests/parity/test_detection_local_kernels.py``). The direct search costs (2 half / stride + 1)
    dot products of the m_a analytic taps per pick, four lags at a time (``_four_lags32``) on a
    float32 copy of the stretch, in one call with no FFT.

    Parameters
    ----------
    samples, dc_v, lanes
        As for ``coarse_starts``.
    sigma : ndarray, shape (n_rows,)
        Noise standard deviation of each row (V, floored), as for ``echo_rows``.
    taps : ndarray, shape (4, m_a + 1)
        As for ``local_peaks``.
    taps32 : ndarray of float32, shape (2, m_a + 1)
        Its first two rows in single precision (``LocalPlan.tap_parts32``), for the search.
    search : ndarray of ``kernel_types.LOCAL_SEARCH``, shape (1,)
        All its fields: ``coarse_starts``', and analytic_offset, stride and reach (direct lags
        each side of the searched peak: ``local.REFINE_HALF_WIDTH + stride - 1``).
    constants : ndarray of ``kernel_types.ECHO_CONSTANTS``, shape (1,)
    echoes : ndarray of ``kernel_types.ECHO``, shape (n_rows,), written (``echo_rows``)
    extremes : ndarray, shape (n_rows, 2) or (0, 2), written (``coarse_starts``)
    """
    p = search[0]
    lag_lo, lag_hi, candidates, half = p.lag_lo, p.lag_hi, p.candidates, p.half
    scale, analytic_offset, stride, reach = p.scale, p.analytic_offset, p.stride, p.reach
    n_rows, n = samples.shape
    m_a = taps.shape[1] - 1
    starts = np.empty(n_rows * candidates, dtype=np.int64)
    coarse_starts(samples, dc_v, lanes, search, starts, extremes)
    width = 2 * half + 1
    count = (width + stride - 1) // stride  # searched lags per stretch: start + stride j
    groups = (count + 3) // 4
    # The record under all searched lags of a stretch (four per group, the last group's extra
    # lags computed and ignored), as float32, 0 outside the record, converted once (~1,200
    # conversions per pick instead of ~40,000).
    stretch = np.empty((4 * groups - 1) * stride + m_a, dtype=np.float32)
    z = np.empty(8)
    values = np.empty(2 * reach + 1, dtype=np.complex128)
    power = np.empty(2 * reach + 1)
    refined = np.empty((n_rows, 2))
    for r in range(n_rows):
        row = samples[r]
        d = dc_v[r]
        best_lag = 0
        best = -2.0
        for k in range(candidates):
            start = starts[r * candidates + k]
            origin = start - analytic_offset  # record sample under tap 0 at lag ``start``
            for i in range(stretch.size):
                index = origin + i
                stretch[i] = np.float32(row[index]) if 0 <= index < n else np.float32(0.0)
            for g in range(groups):
                z[0], z[1], z[2], z[3], z[4], z[5], z[6], z[7] = _four_lags32(stretch, 4 * g * stride, stride, taps32)
                for q in range(min(4, count - 4 * g)):
                    lag = start + stride * (4 * g + q)
                    p = -1.0
                    if lag_lo <= lag <= lag_hi:
                        re, im = _folded(z[2 * q], z[2 * q + 1], lag - analytic_offset, n, scale, d, taps)
                        p = re * re + im * im
                    if p > best:
                        best = p
                        best_lag = lag
        _refine_row(row, d, taps, search, best_lag, values, power, refined[r])
    echo_rows(refined, sigma, constants, echoes)
