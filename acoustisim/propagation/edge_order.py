"""The edge rows in the solver's order: channel, then delay, ties in the default order.

:func:`~acoustisim.propagation.edges.edge_paths` with ``sort_rows`` returns its rows in the
order of a stable sort of the kept points by (channel, delay ``path_length / c``), formerly
``np.lexsort`` (two stable passes, some 0.7-1.1 ms for the thesis tank's 16 000 points). Here
the two keys are packed into one unsigned 64-bit key, sorted by one stable ``argsort`` (about
half the time): the bits of a non-negative IEEE double, read as an unsigned integer, are
ordered as the doubles are, and a double below 2 s has its top two bits clear, so
``channel << 62 | bits(delay)`` orders by channel, then delay, exactly, for up to four
channels. Outside those bounds (more channels, a delay of 2 s or more) the rows are ordered by
``np.lexsort`` as before. Either way the order is the unique stable one: the same rows.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

_CHANNEL_SHIFT = 62
"""Bit position of the channel in the packed key (two bits: up to four channels)."""


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
    delay = path_length[keep] / float(sound_speed)
    channel = pair_rx[point_pair[keep]]
    if n_rx <= 1 << (64 - _CHANNEL_SHIFT) and delay.size and np.all(delay >= 0.0) and np.max(delay) < 2.0:
        key = delay.view(np.uint64) | (channel.astype(np.uint64) << np.uint64(_CHANNEL_SHIFT))
        return keep[np.argsort(key, kind="stable")]
    return keep[np.lexsort((delay, channel))]


__all__ = ["solver_order"]
