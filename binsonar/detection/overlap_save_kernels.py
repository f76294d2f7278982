"""Compiled loop of the overlap-save envelope (numba, cached on disk, GIL released).

Imported by :mod:`binsonar.detection.overlap_save` when a matched filter runs (never by
``import binsonar``). numpy can gather the overlapping blocks from a strided view, but its
float64 -> float32 cast with the offset subtracted goes through a buffered loop at ~3x the
cost of a read of the record; this loop does it in one pass.
"""

from __future__ import annotations

import numpy as np
from numba import njit
from numpy.typing import NDArray


@njit(cache=True, nogil=True, fastmath=True)
def gather_blocks(rows: NDArray, dc: NDArray[np.float64], scale: float, hop: int, lead: int,
                  out: NDArray[np.floating]) -> None:
    """``out[r, b, j] = rows[r, b hop - lead + j] scale - dc[r]``, 0 where the index is outside
    the row.

    Parameters
    ----------
    rows : ndarray, shape (n_rows, n_samples), float64 volts or int16 ADC codes
    dc : ndarray, shape (n_rows,)
    scale : float
        Volts per unit of ``rows`` (1.0 for volts).
    hop, lead : int
        Block b starts at sample b hop - lead.
    out : ndarray, shape (n_rows, n_blocks, block), float32 or float64, written
    """
    n_rows, n = rows.shape
    n_blocks, block = out.shape[1], out.shape[2]
    for r in range(n_rows):
        d = dc[r]
        for b in range(n_blocks):
            start = b * hop - lead
            lo = min(max(-start, 0), block)  # block samples [lo, hi) lie inside the row
            hi = max(min(n - start, block), lo)
            for j in range(lo):
                out[r, b, j] = 0.0
            source = rows[r, start + lo: start + hi]
            target = out[r, b, lo:hi]
            for j in range(hi - lo):
                target[j] = source[j] * scale - d
            for j in range(hi, block):
                out[r, b, j] = 0.0
