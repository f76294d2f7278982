"""Noise-floor estimates from a noise-only part of a record.

Two ways, both per channel: the standard deviation over an explicit noise-only time window, or a
robust estimate over the whole record (the median absolute value, which a few echoes occupying
a small fraction of the record barely move: an echo filling 1 % of the samples shifts the median
of |x| by about 1 %).
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from binsonar.recording import RecordingError

# median(|x|) = 0.6745 sigma for zero-mean Gaussian noise.
MAD_TO_SIGMA = 1.0 / 0.6744897501960817

# Robust estimates use at most this many samples per channel, in ROBUST_SEGMENTS contiguous
# stretches spread evenly over the record (cache-friendly, and no single stretch dominates):
# the median of |x| over 4096 Gaussian samples has a relative standard error of about 2 %.
ROBUST_SAMPLES = 4096
ROBUST_SEGMENTS = 16
# Least noise estimate (V): replaces an exactly zero one (sqrt of the smallest normal float).
_TINY_SIGMA = float(np.finfo(float).tiny) ** 0.5


def window_indices(
    noise_window_s: tuple[float, float], n_samples: int, sample_rate_hz: float, t0_s: float, where: str = "record"
) -> slice:
    """Sample slice of a noise window given in recording time (s after the trigger).

    Raises
    ------
    RecordingError
        A window that is not inside the record or holds fewer than 16 samples.
    """
    try:
        start_s, stop_s = (float(v) for v in noise_window_s)
    except (TypeError, ValueError):
        raise RecordingError(f"{where}: noise_window_s must be (start_s, stop_s), got {noise_window_s!r}") from None
    start = int(math.ceil((start_s - t0_s) * sample_rate_hz))
    stop = int(math.floor((stop_s - t0_s) * sample_rate_hz))
    if not (math.isfinite(start_s) and math.isfinite(stop_s)) or start < 0 or stop > n_samples or stop - start < 16:
        raise RecordingError(
            f"{where}: noise_window_s={noise_window_s!r} must lie inside the record "
            f"[{t0_s:.9g}, {t0_s + n_samples / sample_rate_hz:.9g}] s and hold >= 16 samples"
        )
    return slice(start, stop)


def robust_subsample(rows: NDArray[np.float64]) -> NDArray[np.float64]:
    """At most ROBUST_SAMPLES samples per row, in ROBUST_SEGMENTS evenly spread stretches.

    Parameters
    ----------
    rows : ndarray, shape (n_rows, n_samples)

    Returns
    -------
    ndarray, shape (n_rows, k), k <= ROBUST_SAMPLES (a view when it can be)
    """
    n_rows, n = rows.shape
    if n <= ROBUST_SAMPLES:
        return rows
    period = n // ROBUST_SEGMENTS
    length = ROBUST_SAMPLES // ROBUST_SEGMENTS
    return rows[:, : period * ROBUST_SEGMENTS].reshape(n_rows, ROBUST_SEGMENTS, period)[:, :, :length]


def row_median(values: NDArray[np.float64]) -> NDArray[np.float64]:
    """Median along the last axis (the upper of the two middle values for an even count).

    A single ``partition``: several times cheaper than ``numpy.median`` on short rows, and
    for the noise statistics here the half-sample difference is far below their scatter.
    """
    flat = values.reshape(values.shape[0], -1) if values.ndim > 2 else values
    k = flat.shape[-1] // 2
    return np.partition(flat, k, axis=-1)[..., k]


def noise_sigma(
    rows: NDArray[np.float64],
    *,
    sample_rate_hz: float,
    t0_s: float,
    noise_window_s: tuple[float, float] | None = None,
    where: str = "record",
    floor_v: float = 0.0,
    offset_v: NDArray[np.float64] | None = None,
    robust_v: NDArray[np.float64] | None = None,
    volts_per_code: float | None = None,
) -> NDArray[np.float64]:
    """Noise standard deviation per row (V).

    Parameters
    ----------
    rows : ndarray, shape (n_rows, n_samples)
    sample_rate_hz, t0_s : float
        Sampling of the rows.
    noise_window_s : (start_s, stop_s), optional
        A noise-only window in recording time: the sample standard deviation there. None: the
        robust estimate 1.4826 median(|x|) over stretches spread over the whole record.
    floor_v : float
        Least noise the rows can carry (V), e.g. the ADC's quantisation noise q / sqrt(12)
        (``Signals.noise_floor_v``): the estimate is never below it.
    offset_v : ndarray, shape (n_rows,), optional
        DC offset of each row still in ``rows`` (``Signals.dc_v``): subtracted from the samples
        the estimate uses (the robust estimate's few thousand, not the whole row), so the
        result is that of ``rows - offset_v``.
    robust_v : ndarray, shape (n_rows,), optional
        The robust estimate already measured for these rows (``inputs.Signals.noise_sigma_v``,
        from ``inputs.robust_offsets``): used as it is, floored, when there is no noise window.
    volts_per_code : float, optional
        ``rows`` are ADC codes of this step (V); ``offset_v`` and the result stay in volts.

    Returns
    -------
    ndarray, shape (n_rows,)
        Strictly positive (a tiny floor replaces an exactly zero estimate), >= ``floor_v``.
    """
    scale = 1.0 if volts_per_code is None else float(volts_per_code)  # codes: only the samples measured in volts
    if noise_window_s is not None:
        segment = rows[:, window_indices(noise_window_s, rows.shape[1], sample_rate_hz, t0_s, where)]
        if volts_per_code is not None:
            segment = segment * scale
        sigma = segment.std(axis=1)  # the standard deviation ignores a constant offset
    elif robust_v is not None:
        sigma = np.asarray(robust_v, dtype=float).reshape(rows.shape[0])
    else:
        sample = robust_subsample(rows)
        if volts_per_code is not None:
            sample = sample * scale
        if offset_v is not None:
            sample = sample - offset_v.reshape((-1,) + (1,) * (sample.ndim - 1))
        sigma = MAD_TO_SIGMA * row_median(np.abs(sample))
    floor = max(_TINY_SIGMA, float(floor_v))
    return np.maximum(sigma, floor)
