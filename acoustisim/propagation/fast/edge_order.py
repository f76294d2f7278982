"""The edge rows in the solver's order: a stable sort by (channel, delay), on one packed key.

The reference assembly orders rows by a stable ``np.lexsort`` on (channel, delay
``path_length / c``). :func:`solver_order` gives the same order with one stable ``argsort`` of
a packed unsigned 64-bit key: the bits of a non-negative IEEE double, read as an unsigned
integer, are ordered as the doubles are, and a double below 2 s has its top two bits clear, so
``channel << 62 | bits(delay)`` orders by channel, then delay, exactly, for up to four
channels (the keys are built in one compiled pass). Outside those bounds (more channels, a
delay of 0 or of 2 s or more) it falls back to ``np.lexsort``. Either way the order is the
unique stable one.
"""

from __future__ import annotations

import numpy as np
from numba import njit
from numpy.typing import NDArray

CHANNEL_SHIFT = 62
"""Bit position of the channel in the packed key (two bits: up to four channels)."""


@njit(cache=True, nogil=True, error_model="numpy")
def packed_keys(keep: NDArray[np.int64], point_pair: NDArray[np.int64], path_length_m: NDArray[np.float64],
                pair_receiver: NDArray[np.int64], sound_speed_m_s: float) -> tuple[NDArray[np.uint64], bool]:
    """The packed keys ``channel << 62 | bits(path_length / c)`` of the kept points (one pass),
    and whether every delay lies in (0, 2) s and every channel in 0 .. 3 (else the keys do not
    order the points)."""
    k = keep.size
    delay = np.empty(k)
    channel = np.empty(k, dtype=np.uint64)
    ok = True
    for r in range(k):
        i = keep[r]
        d = path_length_m[i] / sound_speed_m_s
        delay[r] = d
        ch = pair_receiver[point_pair[i]]
        ok &= (d > 0.0) & (d < 2.0) & (ch >= 0) & (ch < 4)
        channel[r] = ch
    key = delay.view(np.uint64)
    for r in range(k):
        key[r] |= channel[r] << np.uint64(CHANNEL_SHIFT)
    return key, ok


def solver_order(keep: NDArray[np.int64], point_pair: NDArray[np.int64], path_length_m: NDArray[np.float64],
                 pair_receiver: NDArray[np.int64], sound_speed_m_s: float, n_receivers: int) -> NDArray[np.int64]:
    """``keep`` in the order of a stable sort by (channel, ``path_length_m / sound_speed_m_s``).

    Parameters
    ----------
    keep : ndarray of int64, shape (k,)
        Indices of the kept points, increasing.
    point_pair, path_length_m : ndarray, shape (n,)
        Every point's pair and m + l (m, > 0).
    pair_receiver : ndarray of int64, shape (p,)
        Each pair's receiver (channel), 0 .. n_receivers - 1.
    sound_speed_m_s : float
        c (m/s): the delay is ``path_length_m / c``, as the assembly computes it.
    n_receivers : int

    Returns
    -------
    ndarray of int64, shape (k,)
    """
    if keep.size and n_receivers <= 1 << (64 - CHANNEL_SHIFT):
        key, ok = packed_keys(keep, point_pair, path_length_m, pair_receiver, float(sound_speed_m_s))
        if ok:
            return keep[np.argsort(key, kind="stable")]
    return keep[np.lexsort((path_length_m[keep] / float(sound_speed_m_s), pair_receiver[point_pair[keep]]))]


__all__ = ("CHANNEL_SHIFT", "packed_keys", "solver_order")
