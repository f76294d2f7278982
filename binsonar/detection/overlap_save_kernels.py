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

from binsonar.detection.kernel_types import BlockLayout, CodedRows


@njit(cache=True, nogil=True, fastmath=True)
def gather_blocks(rows: CodedRows, layout: BlockLayout, out: NDArray[np.floating]) -> None:
    """``out[r, b, j] = samples[r, b hop - lead + j] scale - dc_v[r]``, 0 where the index is
    outside the row.

    Parameters
    ----------
    rows : CodedRows
    layout : BlockLayout
    out : ndarray, shape (n_rows, n_blocks, block), float32 or float64, written
    """
    samples, scale = rows.samples, rows.scale
    hop, lead = layout.hop, layout.lead
    n_rows, n = samples.shape
    n_blocks, block = out.shape[1], out.shape[2]
    for r in range(n_rows):
        d = rows.dc_v[r]
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
