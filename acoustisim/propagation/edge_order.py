"""The edge rows in the solver's order: channel, then delay, ties in the default order.

:func:`~acoustisim.propagation.edges.edge_paths` with ``sort_rows`` returns its rows in the
order of a stable sort of the kept points by (channel, delay ``path_length / c``), formerly
``np.lexsort`` (two stable passes, some 0.7-1.1 ms for the thesis tank's 16 000 points). Here
the two keys are packed into one unsigned 64-bit key, sorted by one stable ``argsort`` (about
half the time): the bits of a non-negative IEEE double, read as an unsigned integer, are
ordered as the doubles are, and a double below 2 s has its top two bits clear, so
``channel << 62 | bits(delay)`` orders by channel, then delay, exactly, for up to four
channels (the keys are built in one compiled pass). Outside those bounds (more channels, a
delay of 0 or of 2 s or more) the rows are ordered by ``np.lexsort`` as before. Either way the
order is the unique stable one: the same rows.
"""

from __future__ import annotations

import numpy as np
from numba import njit
from numpy.typing import NDArray

_CHANNEL_SHIFT = 62
"""Bit position of the channel in the packed key (two bits: up to four channels)."""


@njit(cache=True, nogil=True, error_model="numpy")
def _packed_keys(keep: NDArray[np.int64], point_pair: NDArray[np.int64], path_length: NDArray[np.float64],
                 pair_rx: NDArray[np.int64], sound_speed: float) -> tuple[NDArray[np.uint64], bool]:
    """The packed keys ``channel << 62 | bits(path_length / sound_speed)`` of the kept points
    (one pass), and whether every delay lies in (0, 2) s and every channel in 0 .. 3 (else the
    keys do not order the points)."""
    k = keep.size
    delay = np.empty(k)
    channel = np.empty(k, dtype=np.uint64)
    ok = True
    for r in range(k):
        i = keep[r]
        d = path_length[i] / sound_speed
        delay[r] = d
        ch = pair_rx[point_pair[i]]
        ok &= (d > 0.0) & (d < 2.0) & (ch >= 0) & (ch < 4)
        channel[r] = ch
    key = delay.view(np.uint64)
    for r in range(k):
        key[r] |= channel[r] << np.uint64(_CHANNEL_SHIFT)
    return key, ok


def solver_order(keep: NDArray[np.int64], point_pair: NDArray[np.int64], path_length: NDArray[np.float64],
                 pair_rx: NDArray[np.int64], sound_speed: float, n_rx: int) -> NDArray[np.int64]:
    """``keep`` in the order of a stable sort by (channel, ``path_length / sound_speed``).

    Parameters
    ----------
    keep : ndarray of int64, shape (k,)
        Indices of the kept points, increasing.
    point_pair, path_length : ndarray, shape (n,)
        Every point's pair and m + l (m, > 0).
    pair_rx : ndarray of int64, shape (p,)
        Each pair's receiver (channel), 0 .. n_rx - 1.
    sound_speed : float
        c (m/s): the delay is ``path_length / c``, as the solver computes it.
    n_rx : int
        Number of channels.

    Returns
    -------
    ndarray of int64, shape (k,)
    """
    if keep.size and n_rx <= 1 << (64 - _CHANNEL_SHIFT):
        key, ok = _packed_keys(keep, point_pair, path_length, pair_rx, float(sound_speed))
        if ok:
            return keep[np.argsort(key, kind="stable")]
    return keep[np.lexsort((path_length[keep] / float(sound_speed), pair_rx[point_pair[keep]]))]


__all__ = ["solver_order"]
