"""The typed bundles of the beam-weighted edge line integral (``beam_model``, ``beam_kernels``).

This module imports numpy only, so that ``beam_model`` (which builds them) and the compiled
``beam_kernels`` (which reads them) share them without importing each other.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray


class EdgePoints(NamedTuple):
    """The quadrature points along the edge, per channel.

    Attributes
    ----------
    weight : ndarray, shape (c, n)
        Quadrature weight of each point (BTM's 1 / (m l) dz times the taper and the wedge's
        beta; 0 behind a baffle).
    excess_s : ndarray, shape (c, n)
        Delay of each point's path beyond the least-time path (s).
    sin_tx, sin_rx : ndarray, shape (c, n)
        Sine of the transmitter's and the channel's receiver's off-axis angles.
    """

    weight: NDArray[np.float64]
    excess_s: NDArray[np.float64]
    sin_tx: NDArray[np.float64]
    sin_rx: NDArray[np.float64]


class PistonRadii(NamedTuple):
    """The pistons' radii (m): the transmitter's, and each channel's receiver's, shape (c,)."""

    transmitter_m: float
    receivers_m: NDArray[np.float64]


class FrequencyLattice(NamedTuple):
    """Equally spaced frequencies f_k = f0_hz + k df_hz, k < n_bins."""

    f0_hz: float
    df_hz: float
    n_bins: int


class JincTable(NamedTuple):
    """2 J1(x)/x tabulated at x = i step (read by linear interpolation, held beyond its end).

    Attributes
    ----------
    step : float
    grid : ndarray, shape (k,)
        The nodes i step.
    values : ndarray, shape (k,)
    """

    step: float
    grid: NDArray[np.float64]
    values: NDArray[np.float64]
