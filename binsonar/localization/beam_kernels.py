"""Compiled line integral of the beam-weighted vertical edge (numba, cached on disk, GIL released).

Imported by :mod:`binsonar.localization.beam_model` only when an edge's response is computed on
equally spaced frequencies (never by ``import binsonar``). It evaluates exactly the sum of
``beam_model``'s numpy path,

    H_c(f_k) = sum_n w_cn D(x_tx,cnk) D(x_rx,cnk) exp(-j 2 pi f_k e_cn),   x = (2 pi f_k / c) a sin(theta),

D read from the same linearly interpolated 2 J1(x)/x table, but without the (3, points, bins)
temporaries: per point the delay phase advances by one complex multiplication per bin
(exp(-j 2 pi df e) is the step between neighbouring bins; the recurrence's rounding stays below
1e-13 over a few hundred bins). ``tests/unit/test_beam_refine.py`` checks it against the numpy path.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit
from numpy.typing import NDArray

from binsonar.localization.beam_types import EdgePoints, FrequencyLattice, JincTable, PistonRadii


@njit(cache=True, nogil=True, fastmath=True)
def edge_line_integral(points: EdgePoints, radii: PistonRadii, frequencies: FrequencyLattice, sound_speed_m_s: float,
                       jinc: JincTable) -> NDArray[np.complex128]:
    """H (c, n_bins) of the line integral at f_k = f0 + k df (see the module docstring).

    Parameters
    ----------
    points : EdgePoints
        C-contiguous arrays.
    radii : PistonRadii
    frequencies : FrequencyLattice
    sound_speed_m_s : float
    jinc : JincTable
    """
    weight, excess_s, sin_tx, sin_rx = points.weight, points.excess_s, points.sin_tx, points.sin_rx
    radius_tx_m, radius_rx_m = radii.transmitter_m, radii.receivers_m
    f0_hz, df_hz, n_bins = frequencies.f0_hz, frequencies.df_hz, frequencies.n_bins
    table_step, table = jinc.step, jinc.values
    n_ch, n_pts = weight.shape
    out = np.zeros((n_ch, n_bins), dtype=np.complex128)
    last = table.size - 1
    kappa0 = 2.0 * math.pi * f0_hz / sound_speed_m_s
    dkappa = 2.0 * math.pi * df_hz / sound_speed_m_s
    for ch in range(n_ch):
        for i in range(n_pts):
            w = weight[ch, i]
            if w == 0.0:
                continue
            a_tx = radius_tx_m * sin_tx[ch, i] / table_step
            a_rx = radius_rx_m[ch] * sin_rx[ch, i] / table_step
            e = excess_s[ch, i]
            phase = w * complex(math.cos(2.0 * math.pi * f0_hz * e), -math.sin(2.0 * math.pi * f0_hz * e))
            step = complex(math.cos(2.0 * math.pi * df_hz * e), -math.sin(2.0 * math.pi * df_hz * e))
            for k in range(n_bins):
                kappa = kappa0 + k * dkappa
                u = kappa * a_tx
                j = int(u)
                if j >= last:
                    d_tx = table[last]
                else:
                    d_tx = table[j] + (u - j) * (table[j + 1] - table[j])
                u = kappa * a_rx
                j = int(u)
                if j >= last:
                    d_rx = table[last]
                else:
                    d_rx = table[j] + (u - j) * (table[j + 1] - table[j])
                out[ch, k] += phase * (d_tx * d_rx)
                phase *= step
    return out
