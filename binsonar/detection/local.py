"""Local matched processing (seed section 4.2.4, method 9).

1. Coarse peaks: the centres of the few (default 5) stretches of record, a quarter template
   long, holding the most energy (block sums of x^2, then a moving sum of blocks; the seed's
   "peak point of the echo signal", made robust: the largest single |x| is often noise at
   2E/N0 = 20 dB, while the energy over the pulse's length gains much of the matched filter's
   SNR). Their lags are those samples minus the index of the template's envelope maximum.
2. The analytic correlation with the template is computed only for the lags within half a
   template length of the best coarse lag (see 3), i.e. over a stretch of record about twice
   the template's length (a short FFT of that stretch; no FFT of the record).
3. The candidates are ranked by |z| at five lags around each (direct dot products); around
   the best, the log-parabolic vertex of |z|^2 at its maximum gives the sub-sample lag. The
   window's offset is calibrated out exactly: lags are counted from sample 0 of the record
   (the window's start index is added back), and the template's own t0_s is subtracted as
   for the full matched filter, so both give the same TOF whenever the echo is among the
   candidates.

Cost per channel: one pass over the samples (block energies), a few dot products of the
analytic template's length, and one FFT of ~2 template lengths.

A row's DC offset (``dc_v``, still in the samples) is folded in rather than removed from a
copy of the record: the block energies are those of x - dc (subtracted block-chunk by
block-chunk in a cache-sized buffer), and each correlation value z(lag), computed on x, has
dc times the sum of the analytic taps that overlap the record at that lag subtracted, which
is exactly the correlation of the constant dc (the FFT and direct correlations treat samples
outside the record as 0).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from binsonar.detection.matched import (
    MatchedPlan,
    check_pfa,
    echo_values,
    lag_range,
    lags_by_fft,
    lags_time_domain,
    refine,
    white_noise_power,
)
from binsonar.detection.noise import noise_sigma
from binsonar.recording import RecordingError

# Block energies are computed this many blocks at a time (per row: 1024 blocks of ~12 samples,
# ~100 kB, stays in cache), offset-subtracted and squared in one buffer, summed by a matrix
# product with ones (BLAS): no record-sized temporary.
_ENERGY_CHUNK = 1024
# Offsets up to this fraction of the noise standard deviation are left in the coarse block
# energies (see ``detect_local_matched``); larger ones are subtracted (``block_energies``).
_DC_IGNORED_IN_ENERGY = 0.1


def block_energies(
    rows: NDArray[np.float64], block: int, n_blocks: int, dc: NDArray[np.float64] | None = None
) -> NDArray[np.float64]:
    """Energy sum((x - dc)^2) of each of the first ``n_blocks`` blocks of ``block`` samples.

    Parameters
    ----------
    rows : ndarray, shape (n_rows, n_samples), n_samples >= block * n_blocks
    block, n_blocks : int
    dc : ndarray, shape (n_rows,), optional
        Offset of each row (default 0).

    Returns
    -------
    ndarray, shape (n_rows, n_blocks), V^2
    """
    n_rows = rows.shape[0]
    part = rows[:, : n_blocks * block].reshape(n_rows, n_blocks, block)
    offset = np.zeros((n_rows, 1, 1)) if dc is None else np.asarray(dc, dtype=float).reshape(n_rows, 1, 1)
    energy = np.empty((n_rows, n_blocks))
    ones = np.ones(block)
    buffer = np.empty((n_rows, min(_ENERGY_CHUNK, n_blocks), block))
    for start in range(0, n_blocks, _ENERGY_CHUNK):  # chunks of blocks (cache-sized), not samples
        stop = min(start + _ENERGY_CHUNK, n_blocks)
        chunk = buffer[:, : stop - start]
        np.subtract(part[:, start:stop], offset, out=chunk)
        np.square(chunk, out=chunk)
        np.matmul(chunk, ones, out=energy[:, start:stop])
    return energy


def dc_correlation(
    plan: MatchedPlan, n_samples: int, dc: NDArray[np.float64], lags: NDArray[np.intp]
) -> NDArray[np.complex128]:
    """Analytic correlation of constant rows (value ``dc``) with the template, at ``lags``,
    samples outside the record counting as 0 (as in ``lags_time_domain`` / ``lags_by_fft``).

    Parameters
    ----------
    dc : ndarray, shape (k,)
    lags : ndarray of int, shape (k, w)

    Returns
    -------
    ndarray, shape (k, w), complex
    """
    taps = plan.analytic_template_conj
    partial = np.concatenate([[0.0], np.cumsum(taps)])
    first = lags - plan.analytic_offset  # record sample under tap 0
    lo = np.clip(-first, 0, taps.size)
    hi = np.clip(n_samples - first, 0, taps.size)
    return dc[:, np.newaxis] * np.where(hi > lo, partial[hi] - partial[lo], 0.0)


def detect_local_matched(
    rows: NDArray[np.float64],
    plan: MatchedPlan,
    *,
    t0_s: float,
    pfa: float = 1e-3,
    search_window_s: tuple[float, float] | None = None,
    noise_window_s: tuple[float, float] | None = None,
    candidates: int = 5,
    where: str = "record",
    noise_floor_v: float = 0.0,
    dc_v: NDArray[np.float64] | None = None,
) -> list[list[tuple[float, float, float, float, float]]]:
    """Local matched filter around the most energetic stretches of each row.

    Parameters
    ----------
    rows : ndarray, shape (n_rows, n_samples)
    plan : MatchedPlan
        Plain (white-noise) plan: only its analytic template and constants are used.
    t0_s : float
    pfa : float
        Design false-alarm probability per record (same threshold as ``detect_matched``).
    search_window_s : (start_s, stop_s), optional
        Only TOFs in this window (s after the trigger); as for ``detect_matched``, lags where
        the template would stick out of the record are never searched.
    noise_window_s : (start_s, stop_s), optional
        Noise-only window for the noise floor (default: robust estimate over the record).
    candidates : int
        Number of coarse peaks (the most energetic windows, a template length apart) tried;
        the one with the strongest correlation near it wins.
    noise_floor_v : float
        Least noise standard deviation (V), the ADC's quantisation noise: the noise estimate
        is never below it.
    dc_v : ndarray, shape (n_rows,), optional
        DC offset of each row still in ``rows`` (``Signals.dc_v``), folded in (module notes):
        the result is that of ``rows - dc_v`` to rounding, without a copy of the record.

    Returns
    -------
    list (n_rows) of list of (tof_s, amplitude, snr_db, score, tof_std_s)
    """
    pfa = check_pfa(pfa)
    fs = plan.sample_rate_hz
    n_rows, n = rows.shape
    if not (isinstance(candidates, (int, np.integer)) and 1 <= candidates <= 16):
        raise RecordingError(f"{where}: candidates must be an integer in [1, 16], got {candidates!r}")
    m = plan.template_length
    lag_lo, lag_hi = lag_range(plan, t0_s, search_window_s, where)
    # Blocks of ~m/16 samples, windows of 4 blocks (~m/4, about 4 RMS durations of a Gaussian
    # pulse truncated at 1e-6, i.e. most of its energy and little more noise).
    block = max(1, m // 16)
    n_blocks = n // block
    dc = None if dc_v is None else np.asarray(dc_v, dtype=float).reshape(n_rows)
    sigma = noise_sigma(rows, sample_rate_hz=fs, t0_s=t0_s, noise_window_s=noise_window_s, where=where,
                        floor_v=noise_floor_v, offset_v=dc)
    if dc is None or np.all(np.abs(dc) <= _DC_IGNORED_IN_ENERGY * sigma):
        # The energies of x, not x - dc: they differ by block * dc^2 (the same for every
        # window: no effect on the ranking) and by -2 dc sum(x), whose standard deviation over
        # a window of noise is 2 |dc| sigma sqrt(w), at most sqrt(2) * 0.1 = 14 % of the
        # window energies' own noise scatter (sigma^2 sqrt(2 w)). That can only reorder
        # windows of noise whose energies are within a fraction of that scatter of each
        # other, not rank an echo window (its energy many scatters above the noise's) below
        # them; the correlations that decide and refine the TOF fold dc in exactly.
        part = rows[:, : n_blocks * block].reshape(n_rows, n_blocks, block)
        energy = np.einsum("rbk,rbk->rb", part, part)
    else:
        energy = block_energies(rows, block, n_blocks, dc)
    span = min(4, n_blocks)
    # Moving sum of ``span`` blocks as ``span`` shifted slices (a few adds over the block
    # energies; no padded copy, no running sum and its cancellation).
    n_windows = n_blocks - span + 1
    window_energy = energy[:, :n_windows].copy()
    for k in range(1, span):  # at most 3 slices
        window_energy += energy[:, k:k + n_windows]
    taps = plan.analytic_template_conj
    reference = int(np.argmax(np.abs(taps))) - plan.analytic_offset  # template envelope maximum
    # Lag of each window (its centre minus the template's envelope maximum): only those where
    # the full matched filter looks too (the template inside the record, in the search window).
    window_lag = np.arange(window_energy.shape[1]) * block + (span * block) // 2 - reference
    window_energy[:, (window_lag < lag_lo) | (window_lag > lag_hi)] = -np.inf
    # The strongest few windows at least a template length apart: the echo need only be among
    # them (noise alone can top the energy at 20 dB in a 250,000-sample record).
    exclusion = max(1, m // block)
    r = np.arange(n_rows)
    picks = np.zeros((n_rows, int(candidates)), dtype=np.intp)
    for k in range(int(candidates)):  # a few candidates per row, not samples
        best = np.argmax(window_energy, axis=1)
        picks[:, k] = best
        for row, b in enumerate(best):  # blank the neighbourhood of each pick (a slice per row)
            window_energy[row, max(b - exclusion, 0): b + exclusion + 1] = -np.inf
    coarse_lag = np.clip(window_lag[picks], lag_lo, lag_hi)  # (n_rows, candidates)
    if candidates > 1:
        # Rank the candidates by |z| at a few lags around each (spaced by a quarter of the
        # coarse window, well inside the response's main lobe), then keep the best.
        step = max(1, (span * block) // 4)
        probe_lags = coarse_lag.reshape(-1, 1) + np.arange(-2, 3) * step
        probe_rows = np.repeat(r, int(candidates))
        probe_values = lags_time_domain(plan, rows, probe_rows, probe_lags, stride=step)
        if dc is not None:
            probe_values -= dc_correlation(plan, n, dc[probe_rows], probe_lags)
        strength = np.max(np.abs(probe_values), axis=1).reshape(n_rows, int(candidates))
        coarse_lag = coarse_lag[r, np.argmax(strength, axis=1)]
    else:
        coarse_lag = coarse_lag[:, 0]
    half = m // 2
    lags = coarse_lag[:, np.newaxis] + np.arange(-half, half + 1)
    values = lags_by_fft(plan, rows, r, lags)
    if dc is not None:
        values -= dc_correlation(plan, n, dc, lags)
    values[(lags < lag_lo) | (lags > lag_hi)] = 0.0  # the same lags as the full filter
    lag, power = refine(values, lags)
    noise_mean = white_noise_power(plan, sigma)  # 2 sigma^2 sum s^2: white noise through the filter
    values_out = echo_values(plan, lag, power, noise_mean, plan.threshold_factor(pfa), t0_s)
    out: list[list[tuple[float, float, float, float, float]]] = []
    for k in range(n_rows):
        echo = tuple(float(v[k]) for v in values_out)
        out.append([echo] if echo[3] >= 1.0 else [])  # type: ignore[list-item]
    return out
