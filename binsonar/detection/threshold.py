"""Simple threshold detector (seed section 4.1.1): the first time |x| reaches a level.

The TOF is the crossing time (linearly interpolated between the two samples around it) minus
an optional calibrated offset. Because the echo needs its rise time to reach the level, the
crossing comes later, relative to the echo's start, as the echo gets weaker: a constant offset
calibrated at one amplitude cannot remove the bias at another (the seed's point). The offset can
be calibrated on the template scaled to a reference amplitude (``calibrate_amplitude_v``).
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from binsonar.detection.noise import noise_sigma
from binsonar.recording import RecordingError, Template

# The search for the first crossing proceeds in blocks of _BLOCK samples (all channels at
# once) and stops at the first block where every channel has crossed. A block of a row is
# viewed as (_BLOCK // _COLUMNS, _COLUMNS) samples, i.e. parts of _COLUMNS contiguous samples,
# whose maxima and minima are taken (SIMD reductions, no temporaries the size of the block);
# only the first part whose extremes cross is then scanned sample by sample.
_COLUMNS = 1024
_BLOCK = 16 * _COLUMNS


def first_crossings(
    rows: NDArray[np.float64], level: NDArray[np.float64], offset: NDArray[np.float64] | None = None
) -> NDArray[np.intp]:
    """Index of the first sample with |x - offset| >= level in each row (-1 where none).

    Parameters
    ----------
    rows : ndarray, shape (n_rows, n_samples)
    level : ndarray, shape (n_rows,)
    offset : ndarray, shape (n_rows,), optional
        DC offset of each row (default 0), subtracted only where needed (no copy of the rows).

    Notes
    -----
    Exact: fl(x - c) is non-decreasing in x, so max(x) - c = max(x - c) and
    c - min(x) = max(c - x) in floating point, and the coarse test on a part's extremes is
    true exactly when some sample of the part satisfies the sample-wise test.
    """
    n_rows, n = rows.shape
    offset = np.zeros(n_rows) if offset is None else np.asarray(offset, dtype=float)
    found = np.full(n_rows, -1, dtype=np.intp)
    pending = np.arange(n_rows)
    dc, threshold = offset[:, np.newaxis], level[:, np.newaxis]  # of the pending rows
    for start in range(0, n, _BLOCK):  # blocks of samples, vectorised inside
        stop = min(start + _BLOCK, n)
        width = stop - start
        columns = _COLUMNS if width % _COLUMNS == 0 else width  # the ragged end: one long row
        # A view while all rows are pending, else a copy of this block of the pending ones.
        source = rows[:, start:stop] if pending.size == n_rows else rows[pending, start:stop]
        view = source.reshape(pending.size, width // columns, columns)
        crossed = (view.max(axis=2) - dc >= threshold) | (dc - view.min(axis=2) >= threshold)  # (rows, parts)
        hit = crossed.any(axis=1)
        if hit.any():
            rows_hit = pending[hit]
            first = start + np.argmax(crossed[hit], axis=1) * columns  # the first part that crosses
            index = first[:, np.newaxis] + np.arange(columns)
            magnitude = rows[rows_hit[:, np.newaxis], index] - offset[rows_hit, np.newaxis]
            above = np.abs(magnitude, out=magnitude) >= level[rows_hit, np.newaxis]
            found[rows_hit] = first + np.argmax(above, axis=1)
            pending = pending[~hit]
            if pending.size == 0:
                break
            dc, threshold = offset[pending, np.newaxis], level[pending, np.newaxis]
    return found


def crossing_time_offset(template: Template, amplitude_v: float, level_v: float) -> float:
    """Crossing time minus reference instant (s) of the noise-free template scaled so that its
    peak |sample| is ``amplitude_v``, for a threshold ``level_v``: the calibrated offset."""
    s = template.samples / np.max(np.abs(template.samples)) * amplitude_v
    if amplitude_v < level_v:
        raise RecordingError(f"calibrate_amplitude_v={amplitude_v!r} is below the threshold level {level_v!r} V")
    i = int(first_crossings(s[np.newaxis], np.array([level_v]))[0])
    frac = crossing_fraction(np.abs(s[i - 1]) if i > 0 else 0.0, np.abs(s[i]), level_v)
    return template.t0_s + (i - 1 + frac) / template.sample_rate_hz


def crossing_fraction(before: NDArray[np.float64] | float, after: NDArray[np.float64] | float,
                      level: NDArray[np.float64] | float) -> NDArray[np.float64]:
    """Linear-interpolation fraction in [0, 1] of the level between two samples."""
    before = np.asarray(before, dtype=float)
    after = np.asarray(after, dtype=float)
    rise = after - before
    return np.clip(np.where(rise > 0, (level - before) / np.where(rise > 0, rise, 1.0), 1.0), 0.0, 1.0)


def crossing_measures(
    rows: NDArray[np.float64], found: NDArray[np.intp], offset: NDArray[np.float64], window: int
) -> NDArray[np.float64]:
    """What the detector measures at each row's crossing: the numpy definition of the compiled
    ``threshold_kernels.crossings``.

    Parameters
    ----------
    rows : ndarray, shape (n_rows, n_samples)
        Volts.
    found : ndarray of int, shape (n_rows,)
        Crossing sample of each row (``first_crossings``; -1: none).
    offset : ndarray, shape (n_rows,)
        DC offset of each row.
    window : int
        Samples measured from the crossing on (indices clipped to the row).

    Returns
    -------
    ndarray, shape (n_rows, 4)
        |x - offset| before the crossing (at it for sample 0) and at it, the largest |x - offset|
        and the sum of (x - offset)^2 over the window; NaN where there is no crossing.
    """
    n_rows, n = rows.shape
    out = np.full((n_rows, 4), np.nan)
    hit = np.flatnonzero(found >= 0)
    i = found[hit]
    out[hit, 0] = np.abs(rows[hit, np.maximum(i - 1, 0)] - offset[hit])
    out[hit, 1] = np.abs(rows[hit, i] - offset[hit])
    segment = rows[hit[:, np.newaxis], np.clip(i[:, np.newaxis] + np.arange(window), 0, n - 1)] - offset[hit, np.newaxis]
    out[hit, 2] = np.abs(segment).max(axis=1)
    out[hit, 3] = (segment ** 2).sum(axis=1)
    return out


def crossing_echo_values(found: NDArray[np.intp], measures: NDArray[np.float64], level: NDArray[np.float64],
                         sigma: NDArray[np.float64], window: int, sample_rate_hz: float, t0_s: float,
                         offset_s: float) -> NDArray[np.float64]:
    """The echo values of each crossing: the numpy definition of the compiled
    ``threshold_kernels.threshold_echoes`` (after ``crossing_measures``).

    The TOF is the crossing linearly interpolated between the samples around it, minus the
    offset; the amplitude the largest |x - dc| over the window; the SNR the window's energy
    above the noise over sigma^2 (at least -30 dB; a noise-free record's capped near 200 dB);
    the score amplitude / level; the TOF std sigma over the crossing's slope.

    Returns
    -------
    ndarray, shape (n_hit, 5)
        tof_s, amplitude, snr_db, score, tof_std_s of the rows that cross, in row order.
    """
    hit = np.flatnonzero(found >= 0)
    i = found[hit]
    before, after, amplitude, total = measures[hit].T
    frac = np.where(i > 0, crossing_fraction(before, after, level[hit]), 0.0)
    tof = t0_s + (i - 1 + frac) / sample_rate_hz - offset_s
    noise_var = np.maximum(sigma[hit] ** 2, 1e-20 * total)
    snr = np.maximum((total - window * sigma[hit] ** 2) / noise_var, 1e-3)
    slope = np.maximum((after - before) * sample_rate_hz, np.finfo(float).tiny)
    return np.stack([tof, amplitude, 10 * np.log10(snr), amplitude / level[hit], sigma[hit] / slope], axis=1)


def detect_threshold(
    rows: NDArray[np.float64],
    *,
    sample_rate_hz: float,
    t0_s: float,
    template: Template | None = None,
    level_v: float | None = None,
    level_sigma: float = 6.0,
    noise_window_s: tuple[float, float] | None = None,
    offset_s: float = 0.0,
    calibrate_amplitude_v: float | None = None,
    search_window_s: tuple[float, float] | None = None,
    where: str = "record",
    noise_floor_v: float = 0.0,
    dc_v: NDArray[np.float64] | None = None,
    robust_sigma_v: NDArray[np.float64] | None = None,
    volts_per_code: float | None = None,
) -> list[list[tuple[float, float, float, float, float]]]:
    """First threshold crossing of each row.

    Parameters
    ----------
    rows : ndarray, shape (n_rows, n_samples)
        Volts, or int16 ADC codes with ``volts_per_code``.
    sample_rate_hz, t0_s : float
    template : Template, optional
        Sets the window (its length) over which amplitude and energy are measured, and is needed
        for ``calibrate_amplitude_v``.
    level_v : float, optional
        Absolute level (V). None: ``level_sigma`` times the noise standard deviation.
    level_sigma : float
        Level relative to the noise floor (default 6: a per-sample false-alarm probability of
        2e-9 for Gaussian noise).
    noise_window_s : (start_s, stop_s), optional
        Noise-only window for the noise floor; None uses a robust estimate over the record.
    offset_s : float
        Calibrated offset subtracted from the crossing time (s).
    calibrate_amplitude_v : float, optional
        Instead of ``offset_s``: the offset of the template scaled to this peak amplitude (V);
        needs ``level_v``.
    search_window_s : (start_s, stop_s), optional
        Only crossings between these times (s after the trigger), e.g. after the
        transmitter's direct cross-talk.
    noise_floor_v : float
        Least noise standard deviation (V), the ADC's quantisation noise: the noise estimate
        is never below it.
    dc_v : ndarray, shape (n_rows,), optional
        DC offset of each row still in ``rows`` (``Signals.dc_v``): folded into the
        comparisons (|x - dc| >= level, block by block) and the measurements, so the result is
        that of ``rows - dc_v`` without a copy of the record.
    robust_sigma_v : ndarray, shape (n_rows,), optional
        The rows' robust noise estimate, already measured (``inputs.Signals.noise_sigma_v``):
        used instead of measuring it again when there is no ``noise_window_s``.
    volts_per_code : float, optional
        ``rows`` are ADC codes of this step (V): searched as they are (2 bytes a sample), each
        sample compared as the volts code * volts_per_code, so the result is that of the volts.

    Returns
    -------
    list (n_rows) of list of (tof_s, amplitude, snr_db, score, tof_std_s)
        amplitude: peak |x| within one template length after the crossing (V); snr_db: energy
        there above the noise, over sigma^2 (2E/N0); score: amplitude / level; tof_std_s: the
        noise's jitter of the crossing, sigma / slope.
    """
    fs = sample_rate_hz
    sigma = noise_sigma(rows, sample_rate_hz=fs, t0_s=t0_s, noise_window_s=noise_window_s, where=where,
                        floor_v=noise_floor_v, offset_v=dc_v, robust_v=robust_sigma_v, volts_per_code=volts_per_code)
    offset = np.zeros(rows.shape[0]) if dc_v is None else np.ascontiguousarray(dc_v, dtype=float).reshape(rows.shape[0])
    if level_v is not None:
        if not (math.isfinite(level_v) and level_v > 0):
            raise RecordingError(f"{where}: level_v must be > 0, got {level_v!r}")
        level = np.full(rows.shape[0], float(level_v))
    else:
        if not (math.isfinite(level_sigma) and level_sigma > 0):
            raise RecordingError(f"{where}: level_sigma must be > 0, got {level_sigma!r}")
        level = level_sigma * sigma
    if calibrate_amplitude_v is not None:
        if template is None or level_v is None:
            raise RecordingError(f"{where}: calibrate_amplitude_v needs a template and an absolute level_v")
        offset_s = crossing_time_offset(template, float(calibrate_amplitude_v), float(level_v))
    window = template.samples.size if template is not None else max(16, int(round(10e-6 * fs)))
    n_rows, n = rows.shape
    first, stop = 0, n
    if search_window_s is not None:
        try:
            start_s, stop_s = (float(v) for v in search_window_s)
        except (TypeError, ValueError):
            raise RecordingError(f"{where}: search_window_s must be (start_s, stop_s), got {search_window_s!r}") from None
        first = max(0, int(math.ceil((start_s - t0_s) * fs))) if math.isfinite(start_s) else 0
        stop = min(n, int(math.floor((stop_s - t0_s) * fs)) + 1) if math.isfinite(stop_s) else n
        if stop - first < 2:
            raise RecordingError(f"{where}: search_window_s={search_window_s!r} holds fewer than 2 samples of the record")
    from binsonar.detection.kernel_types import CROSSING_SEARCH, ECHO, record
    from binsonar.detection.threshold_kernels import threshold_echoes

    # ``first_crossings``, ``crossing_measures`` and ``crossing_echo_values``, compiled in one
    # call: each searched sample read once, up to the crossing.
    samples = np.ascontiguousarray(rows, dtype=np.int16 if volts_per_code is not None else float)
    search = record(CROSSING_SEARCH, scale=1.0 if volts_per_code is None else volts_per_code, first=first, stop=stop,
                    window=window, sample_rate_hz=fs, t0_s=t0_s, offset_s=offset_s)
    found = np.empty(n_rows, dtype=np.int64)
    echoes = np.empty(n_rows, dtype=ECHO)
    threshold_echoes(samples, offset, level, sigma, search, found, echoes)  # contiguous float64 rows of values
    # One conversion to Python values for all rows (``tolist``: tuples of floats).
    return [[echo] if i >= 0 else [] for echo, i in zip(echoes.tolist(), found.tolist())]
