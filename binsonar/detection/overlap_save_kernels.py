"""Compiled loop of the overlap-save envelope (numba, cached on disk, GIL released).

Imported by :mod:`binsonar.detection.overlap_save` when a matched filter runs (never by
``import binsonar``). numpy can gather the overlapping blocks from a strided view, but its
float64 -> float32 cast with the offset subtracted goes through a buffered loop (several
passes); this loop gathers, converts and subtracts in one pass.
"""

from __future__ import annotations

import numpy as np
from numba import njit
from numpy.typing import NDArray


@njit(cache=True, nogil=True, fastmath=True)
def gather_blocks(samples: NDArray, dc_v: NDArray[np.float64], scale: float, layout: NDArray[np.void],
                  out: NDArray[np.floating]) -> None:
    """``out[r, b, j] = samples[r, b hop - lead + j] scale - dc_v[r]``, 0 where the index is
    outside the row.

    Parameters
    ----------
    samples : ndarray, shape (n_rows, n_samples)
        float64 volts or int16 ADC codes.
    dc_v : ndarray, shape (n_rows,)
        Each row's DC offset (V) still in the samples.
    scale : float
        Volts per unit of ``samples`` (1.0 for volts).
    layout : ndarray of ``kernel_types.BLOCK_LAYOUT``, shape (1,)
    out : ndarray, shape (n_rows, n_blocks, block), float32 or float64, written
    """
    hop, lead = layout[0].hop, layout[0].lead
    n_rows, n = samples.shape
    n_blocks, block = out.shape[1], out.shape[2]
    for r in range(n_rows):
        d = dc_v[r]
        for b in range(n_blocks):
            start = b * hop - lead
            lo = min(max(-start, 0), block)  # block samples [lo, hi) lie inside the row
            hi = max(min(n - start, block), lo)
            for j in range(lo):
                out[r, b, j] = 0.0
            source = samples[r, start + lo: start + hi]
            target = out[r, b, lo:hi]
            for j in range(hi - lo):
                target[j] = source[j] * scale - d
            for j in range(hi, block):
                out[r, b, j] = 0.0
