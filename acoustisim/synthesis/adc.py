"""The digitiser: rounding to integer codes and clipping, flagged per channel."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from acoustisim.errors import InputError


def adc_step_v(full_scale_v: float, bits: int) -> float:
    """Volts per code of a bipolar ADC with input range +/- ``full_scale_v``: 2 FS / 2^bits."""
    return 2.0 * float(full_scale_v) / float(2**bits)


def adc_code_range(bits: int) -> tuple[int, int]:
    """Lowest and highest code of a ``bits``-bit bipolar ADC stored as int16.

    Raises
    ------
    InputError
        ``bits`` is not an integer in [2, 16].
    """
    if not (isinstance(bits, (int, np.integer)) and 2 <= bits <= 16):
        raise InputError(f"sonar.adc_bits must be an integer in [2, 16] to store int16 codes, got {bits!r}")
    return -(2 ** (int(bits) - 1)), 2 ** (int(bits) - 1) - 1


def quantise(
    volts: NDArray[np.float64], bits: int, full_scale_v: float
) -> tuple[NDArray[np.int16], NDArray[np.bool_], float]:
    """Digitise voltages: code = round(v / step), clipped to [-2^(b-1), 2^(b-1) - 1].

    Parameters
    ----------
    volts : ndarray, shape (..., n_channels, n_samples)
        ADC input (V).
    bits : int
        Resolution (2-16 bits fit int16).
    full_scale_v : float
        Input range +/- this (V).

    Returns
    -------
    codes : int16 ndarray, the shape of ``volts``
    clipped : bool ndarray, shape (..., n_channels)
        True where any sample of the channel was outside the representable range.
    step : float
        Volts per code.
    """
    lo, hi = adc_code_range(bits)
    step = adc_step_v(full_scale_v, int(bits))
    scaled = np.asarray(volts, dtype=float) * (1.0 / step)
    np.rint(scaled, out=scaled)
    clipped = (scaled.min(axis=-1) < lo) | (scaled.max(axis=-1) > hi)
    np.clip(scaled, lo, hi, out=scaled)
    return scaled.astype(np.int16), clipped, step
