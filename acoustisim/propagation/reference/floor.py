"""The amplitude floor: which arrivals are strong enough to keep, judged across the pulse band.

Physics
-------
Not physics but a fidelity knob: arrivals far below the strongest echo cannot be seen after
the 12-bit ADC (72 dB of dynamic range) and only cost time downstream. An arrival's level is
its strongest pulse-weighted level across the band,

    level = max over f of  w(f) | sum over its rows of  g D_tx(f) D_rx(f) 10^(-alpha(f) L / 20)
                                  exp(j (phase - 2 pi f dtau)) |,

with g the row's ``geometric_gain``, D the piston directivities (2 J1(x)/x, x = k a sin angle)
at the row's off-axis angles, alpha(f) the medium's absorption (dB/m) over the path length L,
w(f) = |Q(f)| / max |Q| the pulse's relative spectrum, and dtau each row's delay relative to
one row of the arrival (edge elements of one edge and receiver add up coherently; every other
row is an arrival of its own).

Method
------
An arrival is dropped when its level is below ``SolverConfig.amplitude_floor_db`` relative to
the strongest level of any non-direct arrival; direct paths are always kept. Levels are
evaluated at :data:`FLOOR_BAND_FREQUENCIES` frequencies evenly spread over the band where the
pulse spectrum is within :data:`FLOOR_BAND_DB` of its peak, plus the centre frequency.
Judging across the band, not at the centre frequency alone, keeps an echo that sits near the
pistons' first null at f0 (about 11 deg off axis for the seed's 19 mm, 500 kHz pistons) but is
strong at the band's lower frequencies.

Accuracy
--------
The rule is evaluated exactly as written; what it neglects is the level between the sampled
frequencies (8 points across a band about 700 kHz wide: a directivity null narrower than the
100 kHz spacing can make an arrival look a few dB weaker than its true band maximum).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from acoustisim.propagation.context import SolveContext
from acoustisim.propagation.directivity import piston_directivity
from acoustisim.propagation.paths import PathKind
from acoustisim.sonar import SonarHead

FLOOR_BAND_DB = -20.0
"""Default judging band of the amplitude floor: where the pulse spectrum is within this of its
peak (dB)."""

FLOOR_BAND_FREQUENCIES = 7
"""Frequencies, evenly spread over the band (plus the centre frequency), at which the floor
judges an arrival's level."""


def pulse_band_hz(sonar: SonarHead, level_db: float = FLOOR_BAND_DB) -> tuple[float, float]:
    """(lowest, highest) frequency (Hz) where the sonar's pulse spectrum |Q(f)| is within
    ``level_db`` of its peak, on a grid of step f0 / 1000 over (0, 4 f0] (the seed's 5 us Gaussian
    pulse at 500 kHz: about 141-859 kHz at -20 dB)."""
    f0 = float(sonar.centre_frequency_hz)
    grid = np.linspace(0.0, 4.0 * f0, 4001)[1:]
    magnitude = np.abs(sonar.pulse.spectrum(grid))
    inside = np.flatnonzero(magnitude >= magnitude.max() * 10.0 ** (level_db / 20.0))
    return float(grid[inside[0]]), float(grid[inside[-1]])


def floor_frequencies(context: SolveContext, band_hz: tuple[float, float] | None
                      ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The frequencies (Hz, shape (m,)) at which the amplitude floor judges levels, and the
    pulse's relative spectrum |Q(f)| / max |Q| at them (shape (m,)).

    :data:`FLOOR_BAND_FREQUENCIES` evenly spaced over ``band_hz`` (None: :func:`pulse_band_hz`)
    plus the centre frequency.
    """
    low, high = pulse_band_hz(context.sonar) if band_hz is None else band_hz
    frequencies = np.unique(np.r_[np.linspace(low, high, FLOOR_BAND_FREQUENCIES), context.centre_frequency_hz])
    magnitude = np.abs(context.sonar.pulse.spectrum(frequencies))
    peak = max(float(magnitude.max()), float(np.abs(context.sonar.pulse.spectrum(context.centre_frequency_hz))))
    return frequencies, magnitude / peak if peak > 0 else np.ones_like(magnitude)


def band_levels(rows: NDArray[Any], group: NDArray[np.intp], n_groups: int, context: SolveContext,
                frequencies_hz: NDArray[np.float64], weights: NDArray[np.float64]) -> NDArray[np.float64]:
    """Each arrival's strongest level across the band: max over f of
    w(f) |sum over its rows of g D_tx(f) D_rx(f) 10^(-alpha(f) L / 20) exp(j (phase - 2 pi f dtau))|
    (dtau: delay relative to any one row of the arrival).

    Parameters
    ----------
    rows : structured ndarray of PATH_DTYPE, shape (n,)
        With the derived angles filled (:func:`complete_columns`).
    group : ndarray of int, shape (n,)
        The arrival (0 .. n_groups - 1) of each row: edge elements of one (path_id, channel)
        add up coherently, with their delays dtau relative to the group's first row.
    n_groups : int
    context : SolveContext
    frequencies_hz, weights : ndarray, shape (m,)
        From :func:`floor_frequencies`.

    Returns
    -------
    ndarray, shape (n_groups,)
        Levels (Pa per Pa at 1 m, the ``amplitude`` column's unit, weighted by the pulse's
        relative spectrum).
    """
    if rows.size == 0:
        return np.zeros(n_groups)
    c, a = context.sound_speed_m_s, context.piston_radius_m
    f = frequencies_hz[None, :]
    alpha = np.asarray(context.scene.medium.absorption_db_per_m(frequencies_hz), dtype=float)[None, :]
    factor = (rows["geometric_gain"][:, None] * piston_directivity(rows["angle_tx_rad"][:, None], f, a, c)
              * piston_directivity(rows["angle_rx_rad"][:, None], f, a, c)
              * 10.0 ** (-alpha * rows["path_length_m"][:, None] / 20.0))
    if n_groups == rows.size and np.array_equal(group, np.arange(n_groups)):
        return np.max(np.abs(factor) * weights, axis=1)
    # delays relative to one row of each group (the magnitude does not depend on which)
    reference = np.empty(n_groups)
    reference[group[::-1]] = rows["delay_s"][::-1]
    phase = rows["phase_rad"][:, None] - 2.0 * np.pi * f * (rows["delay_s"] - reference[group])[:, None]
    total = np.empty((n_groups, frequencies_hz.size), dtype=complex)
    for j in range(frequencies_hz.size):  # a few band frequencies, each a vectorised sum over rows
        total[:, j] = np.bincount(group, factor[:, j] * np.cos(phase[:, j]), n_groups) + 1j * np.bincount(
            group, factor[:, j] * np.sin(phase[:, j]), n_groups)
    return np.max(np.abs(total) * weights, axis=1)


def arrival_groups(rows: NDArray[Any]) -> tuple[NDArray[np.intp], int]:
    """The arrival (0 .. n_groups - 1) of each row: edge rows of one (``path_id``, ``channel``)
    form one arrival, every other row is one; and the number of arrivals."""
    if rows.size == 0:
        return np.zeros(0, dtype=np.intp), 0
    edge = rows["kind"] == PathKind.EDGE
    # rows of other kinds get keys no edge row can have (their own row number, negated)
    key_id = np.where(edge, rows["path_id"], -1 - np.arange(rows.size))
    key_channel = np.where(edge, rows["channel"], 0)
    keys = np.stack([key_id, key_channel.astype(np.int64)], axis=1)
    _, group = np.unique(keys, axis=0, return_inverse=True)
    group = group.reshape(-1).astype(np.intp)
    return group, int(group.max()) + 1


def floor_mask(rows: NDArray[Any], floor_db: float | None, context: SolveContext,
               band_hz: tuple[float, float] | None = None) -> NDArray[np.bool_]:
    """Which rows survive the amplitude floor (whole arrivals are kept or dropped).

    Parameters
    ----------
    rows : structured ndarray of PATH_DTYPE, shape (n,)
        With the derived columns filled.
    floor_db : float or None
        ``SolverConfig.amplitude_floor_db`` (dB, <= 0); None keeps every row.
    context : SolveContext
    band_hz : (float, float) or None
        ``SolverConfig.amplitude_floor_band_hz``; None: :func:`pulse_band_hz`.

    Returns
    -------
    ndarray of bool, shape (n,)
    """
    keep = np.ones(rows.size, dtype=bool)
    if floor_db is None or rows.size == 0:
        return keep
    frequencies, weights = floor_frequencies(context, band_hz)
    group, n_groups = arrival_groups(rows)
    levels = band_levels(rows, group, n_groups, context, frequencies, weights)
    direct = np.zeros(n_groups, dtype=bool)
    direct[group[rows["kind"] == PathKind.DIRECT]] = True
    strongest = float(levels[~direct].max(initial=0.0))
    threshold = strongest * 10.0 ** (floor_db / 20.0)
    kept_groups = direct | (levels >= threshold)
    return kept_groups[group]


__all__ = ["FLOOR_BAND_DB", "FLOOR_BAND_FREQUENCIES", "arrival_groups", "band_levels", "floor_frequencies",
           "floor_mask", "pulse_band_hz"]
