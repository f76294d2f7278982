"""Spectra of time-limited responses at any frequencies: the DTFT of their samples, by chirp-z.

A response h(t) sampled at t_m = t_0 + m dt (m = 0..M-1) has the spectrum (engineering
convention, a delay d is exp(-j 2 pi f d))

    X(f) = sum_m h_m exp(-j 2 pi f t_m).

It equals the response's true spectrum wherever h is band-limited below 1 / (2 dt) and held
by the M samples (Shannon); the samples of a spectrum known on a grid of spacing 1 / (M dt)
(its inverse FFT) thus give it between the grid's points. Used for the elastic echoes of rows
whose transfer function is another row's at the frequencies f cos(e)
(:mod:`acoustisim.propagation.elastic_responses`).

Method
------
Each row r is evaluated at f_k = f_0 + k df scaled by its own factor s_r: Bluestein's chirp-z
(k m = (k^2 + m^2 - (k - m)^2) / 2 turns the sum into a convolution, done by FFTs of length
>= M + K - 1, all rows at once). Frequencies that are not such a grid: the sum itself, in
blocks of rows.

Accuracy
--------
Rounding: the chirp phases pi s df dt n^2 are reduced modulo 2 pi in float64 before the
exponential; the result matches the direct sum to about 1e-12 of sum |h_m|
(``tests/physics/test_elastic_echo_series.py``).
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import fft

__all__ = ("response_spectrum", "uniform_grid")

_DIRECT_BLOCK = 1 << 22
"""Elements of the (rows, samples, frequencies) exponential table built at once by the direct sum."""


def uniform_grid(frequency_hz: NDArray[np.float64]) -> tuple[float, float] | None:
    """(f_0, df) when ``frequency_hz`` is a uniform increasing grid (to 1e-9 of df), else None."""
    f = np.asarray(frequency_hz, dtype=float)
    if f.ndim != 1 or f.size < 2:
        return None
    step = (f[-1] - f[0]) / (f.size - 1)
    if not step > 0.0:
        return None
    if np.max(np.abs(f - (f[0] + step * np.arange(f.size)))) > 1e-9 * step:
        return None
    return float(f[0]), float(step)


def _chirp(phase_rate: NDArray[np.float64], n: NDArray[np.float64]) -> NDArray[np.complex128]:
    """exp(-j pi rate n^2) for rows of rates (R,) and indices n (L,): (R, L), phase reduced mod 2."""
    # rate n^2 as an exact product of float64 terms reduced modulo 2 (periods of exp(-j pi x))
    turns = np.mod(phase_rate[:, None] * (n * n)[None, :], 2.0)
    return np.exp(-1j * math.pi * turns)


def _bluestein(samples: NDArray[np.complex128], rate: NDArray[np.float64], count: int) -> NDArray[np.complex128]:
    """X_rk = sum_m x_rm w_r^{k m}, w_r = exp(-j 2 pi rate_r), k = 0..count-1: (R, count)."""
    rows, m_count = samples.shape
    length = fft.next_fast_len(m_count + count - 1)
    m = np.arange(m_count, dtype=float)
    k = np.arange(count, dtype=float)
    a = samples * _chirp(rate, m)
    lags = np.concatenate([np.arange(count, dtype=float), np.arange(-(m_count - 1), 0, dtype=float)])
    kernel = np.zeros((rows, length), dtype=complex)
    kernel[:, :count] = np.conj(_chirp(rate, lags[:count]))
    kernel[:, length - (m_count - 1):] = np.conj(_chirp(rate, lags[count:])) if m_count > 1 else kernel[:, :0]
    product = fft.ifft(fft.fft(a, n=length, axis=1) * fft.fft(kernel, axis=1), axis=1)
    return _chirp(rate, k) * product[:, :count]


def response_spectrum(samples: ArrayLike, start_s: float, step_s: float, frequency_hz: ArrayLike,
                      scale: ArrayLike | None = None) -> NDArray[np.complex128]:
    """X_r(s_r f_k) = sum_m h_rm exp(-j 2 pi s_r f_k (start + m step)) for every row r and frequency k.

    Parameters
    ----------
    samples : array_like, shape (R, M)
        Each row's response h_rm at t_m = ``start_s`` + m ``step_s`` (real or complex).
    start_s, step_s : float
        Time of the first sample and the sampling step (s).
    frequency_hz : array_like, shape (K,)
        Frequencies f_k (Hz).
    scale : array_like, shape (R,), optional
        Each row's factor s_r on the frequencies (default 1).

    Returns
    -------
    ndarray of complex, shape (R, K)
    """
    h = np.atleast_2d(np.asarray(samples))
    f = np.asarray(frequency_hz, dtype=float).ravel()
    s = np.ones(h.shape[0]) if scale is None else np.asarray(scale, dtype=float).ravel()
    grid = uniform_grid(f)
    if grid is not None:
        f0, df = grid
        # sum_m x_m e^{-j 2 pi s (f0 + k df)(t0 + m dt)}: the factors of k alone and m alone come out
        start = s[:, None] * f0
        x = h * np.exp(-2j * math.pi * np.mod(start * (step_s * np.arange(h.shape[1]))[None, :], 1.0))
        out = _bluestein(x, np.mod(s * df * step_s, 2.0), f.size)
        return out * np.exp(-2j * math.pi * np.mod(np.multiply.outer(s, f) * start_s, 1.0))
    out = np.empty((h.shape[0], f.size), dtype=complex)
    times = start_s + step_s * np.arange(h.shape[1])
    per_row = max(1, _DIRECT_BLOCK // max(1, h.shape[1] * f.size))
    for lo in range(0, h.shape[0], per_row):
        rows = slice(lo, lo + per_row)
        phase = np.mod(np.multiply.outer(np.multiply.outer(s[rows], f), times), 1.0)
        out[rows] = np.einsum("rkm,rm->rk", np.exp(-2j * math.pi * phase), h[rows])
    return out
