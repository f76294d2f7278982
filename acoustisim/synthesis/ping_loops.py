"""Compiled per-bin and per-sample loops of the per-ping rendering (numba, cached on disk).

Each ping costs one draw of normal deviates, one inverse FFT and these two passes, which numpy
would spread over several temporary arrays of the record's size:

- :func:`scale_noise_bins`: white complex bins times the per-bin noise standard deviation of
  this ping (its electrical level and the thermal floor), plus the ping's deterministic part;
- :func:`digitise`: time-varying gain, rounding to ADC codes, clipping (flagged per channel),
  and the codes back in volts.

Both are sequential, so they are deterministic; see :mod:`acoustisim.synthesis.row_kernels`
for the on-disk cache.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit
from numpy.typing import NDArray


@njit(cache=True, nogil=True)
def scale_noise_bins(
    spectrum: NDArray[np.complex64],
    level_squared: float,
    electrical_var: NDArray[np.float32],
    thermal_var: NDArray[np.float32],
    deterministic: NDArray[np.complex64],
) -> None:
    """``spectrum *= sqrt(level^2 E + T)``, then ``spectrum += deterministic``, in place.

    Parameters
    ----------
    spectrum : (3, K) complex64
        Bins whose real and imaginary parts are independent standard normal deviates.
    level_squared : float
        The ping's electrical-noise power factor.
    electrical_var, thermal_var : (3, K) float32
        Per-bin variance of each part (real or imaginary) of the electrical and thermal noise;
        ``thermal_var`` may be (0, 0) for no thermal noise.
    deterministic : (3, K) complex64, or (0, 0) for none
    """
    n_channels, n_bins = spectrum.shape
    level = np.float32(level_squared)
    has_thermal = thermal_var.size > 0
    has_deterministic = deterministic.size > 0
    for c in range(n_channels):
        for k in range(n_bins):
            variance = level * electrical_var[c, k]
            if has_thermal:
                variance += thermal_var[c, k]
            value = spectrum[c, k] * np.float32(math.sqrt(variance))
            if has_deterministic:
                value += deterministic[c, k]
            spectrum[c, k] = value


@njit(cache=True, nogil=True)
def digitise(
    signal: NDArray[np.floating],
    gain: NDArray[np.float64],
    step_v: float,
    lowest: int,
    highest: int,
    codes: NDArray[np.int16],
    volts: NDArray[np.float64],
    clipped: NDArray[np.bool_],
) -> None:
    """ADC of one ping: ``code = clip(rint(signal[:, :n] gain / step))``, ``volts = code step``.

    Parameters
    ----------
    signal : (3, >= n) float32 or float64
        ADC input before the time-varying gain (V); samples past n are ignored.
    gain : (n,) float64, or (0,) for none
        Time-varying gain per sample.
    step_v : float
        Volts per code.
    lowest, highest : int
        The code range.
    codes : (3, n) int16, volts : (3, n) float64, clipped : (3,) bool
        Outputs, written in place; ``clipped[c]`` is True when any sample of channel c fell
        outside the code range before clipping.
    """
    n_channels, n = codes.shape
    inverse = 1.0 / step_v
    has_gain = gain.size > 0
    for c in range(n_channels):
        flag = False
        for i in range(n):
            value = np.float64(signal[c, i])
            if has_gain:
                value *= gain[i]
            scaled = np.rint(value * inverse)
            if scaled < lowest:
                scaled = lowest
                flag = True
            elif scaled > highest:
                scaled = highest
                flag = True
            code = np.int16(scaled)
            codes[c, i] = code
            volts[c, i] = code * step_v
        clipped[c] = flag
