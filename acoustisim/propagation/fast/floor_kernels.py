"""Compiled passes of the amplitude floor (numba, cached on disk, GIL released).

:func:`acoustisim.propagation.fast.floor.floor_mask` judges every arrival (a row, or the rows of an
edge diffraction sharing ``path_id`` and channel) by its strongest pulse-weighted level over a
few band frequencies (:func:`~acoustisim.propagation.reference.floor.band_levels`, the rule). The full
default solve has some 60 000 rows, and the rule costs two Bessel functions, an exponential
and, for edge groups, a phase per row and frequency. These loops decide almost every arrival
from bounds instead, each one pass over the rows
(read in place from the structured array's strided fields):

1. :func:`arrival_bounds`: per arrival, a lower bound (its level at the centre frequency, from
   the columns already filled) and an upper bound (``|g|`` times the directivity envelopes
   times the weakest absorption, summed over an edge group's rows);
2. :func:`table_levels`: for the arrivals the first bounds leave open, an interval
   [lo, hi] around the rule's level, with the directivity 2 J1(x)/x read from a table by linear
   interpolation (:func:`directivity_table`) and a proven bound on the error
   (:func:`interpolation_error`).

What the intervals still leave open (levels within about 1e-6 of the threshold, or of the
strongest level) goes to the numpy rule itself. No ``fastmath`` (it would reassociate sums).
"""

from __future__ import annotations

import math
from typing import Any, NamedTuple

import numpy as np
from numba import njit
from numpy.typing import NDArray

from acoustisim.propagation.fast.bundles import plain_tuple_arguments

ENVELOPE_CELLS = 4096
"""Angle cells of the directivity envelope over [0, pi/2] (:func:`angle_envelope`)."""

DIRECTIVITY_TABLE_INTERVALS = 8192
"""Intervals of the directivity table over [0, x_max] (x_max = k a at the band's highest
frequency, about 69 for the seed's pistons: step 8.4e-3, interpolation error <= 2.2e-6)."""

ROUNDING_SLACK = 1e-10
"""Relative slack added to every table-interval bound (of the sum of the magnitudes of the
terms): covers the rounding of the kernel's and numpy's arithmetic (sums of up to a few
thousand terms, phases of a few thousand radians: about 1e-12), so that an interval always
contains the level numpy computes."""

_HALF_PI = 0.5 * math.pi
_NEPER_PER_DB = -math.log(10.0) / 20.0
"""10^(-L / 20) = exp(L * _NEPER_PER_DB) (the exponential: within a few ulp of the power, and
several times cheaper)."""
_EDGE_DIRECTIVITY_COS = 1e-12
"""Rows whose angle has |cos| below this (within 1e-12 rad of 90 deg, where the piston's front
test flips) get no table interval: they go to the numpy rule."""


def directivity_table(x_max: float, intervals: int = DIRECTIVITY_TABLE_INTERVALS
                      ) -> tuple[NDArray[np.float64], float]:
    """2 J1(x)/x on ``intervals + 1`` evenly spaced points of [0, x_max] and the step.

    Returns
    -------
    table : ndarray, shape (intervals + 1,)
        D(x_i) = 2 J1(x_i) / x_i (1 at x = 0), from scipy's J1 (the one
        :func:`~acoustisim.propagation.directivity.piston_directivity` uses).
    step : float
        x_{i+1} - x_i.
    """
    from scipy.special import j1

    grid = np.linspace(0.0, x_max, intervals + 1)
    safe = np.where(grid > 0, grid, 1.0)
    return np.where(grid > 0, 2.0 * j1(safe) / safe, 1.0), float(grid[1])


def interpolation_error(step: float) -> float:
    """Bound of |D(x) - linear interpolation of the table| for a table step ``step``.

    D(x) = 2 J1(x)/x = (2/pi) int_0^pi sin^2(t) cos(x cos t) dt (Poisson's integral), so
    |D''(x)| <= (2/pi) int_0^pi sin^2(t) cos^2(t) dt = 1/4 for every x, and linear interpolation
    errs by at most step^2 max|D''| / 8 = step^2 / 32. 1e-13 more covers the table's own
    rounding (scipy's J1, ~1e-16) and arguments beyond the last point by rounding.
    """
    return step * step / 32.0 + 1e-13


def angle_envelope(table: NDArray[np.float64], step: float, scale: float, cells: int = ENVELOPE_CELLS
                   ) -> NDArray[np.float64]:
    """Upper bounds of |D(x')| for all x' >= scale sin(angle), per cell of angle.

    Entry k bounds |D(x')| for every angle >= theta_k = k (pi/2) / cells (up to pi/2) and
    every x' from ``scale`` sin(angle) to the table's end (every frequency from the one
    ``scale`` = k a / step belongs to upwards): the reverse running maximum of |D| at the table
    points, plus L step / 2 with L = max |D'| <= (2/pi) int_0^pi sin^2(t) |cos t| dt = 4 / (3 pi)
    (Poisson's integral): between two points |D| exceeds the larger of its end values by at
    most L step / 2 < step / 4; capped at 1 (|D| <= 1). sin is increasing on [0, pi/2], so the
    bound at theta_k holds over the whole cell.

    Parameters
    ----------
    table, step
        :func:`directivity_table`.
    scale : float
        x per unit sin(angle), in table steps (k a / step at the lowest frequency judged).
    cells : int
        Angle cells over [0, pi/2].

    Returns
    -------
    ndarray, shape (cells + 1,)
    """
    envelope = np.minimum(np.maximum.accumulate(np.abs(table)[::-1])[::-1] + 0.25 * step, 1.0)
    index = (scale * np.sin(np.linspace(0.0, 0.5 * np.pi, cells + 1))).astype(np.intp)
    return envelope[np.minimum(index, envelope.size - 1)]


@njit(cache=True, nogil=True, error_model="numpy")
def _interpolate(x: float, table: NDArray[np.float64], inverse_step: float) -> float:
    """Linear interpolation of ``table`` at x >= 0 (clamped to its last interval)."""
    u = x * inverse_step
    last = table.size - 2
    i = int(u)
    if i > last:
        i = last
    t = u - i
    return table[i] + t * (table[i + 1] - table[i])


@njit(cache=True, nogil=True, error_model="numpy")
def _envelope(angle: float, envelope: NDArray[np.float64]) -> float:
    """:func:`angle_envelope`'s bound at ``angle``; 0 behind the piston."""
    if angle > _HALF_PI:
        return 0.0
    cells = envelope.size - 1
    k = int(angle * (cells / _HALF_PI))
    if k > cells:
        k = cells
    return envelope[k]


@njit(cache=True, nogil=True, error_model="numpy")
def _edge_groups(kind: NDArray[np.int8], path_id: NDArray[np.int64], channel: NDArray[np.int8], edge_kind: int
                 ) -> tuple[NDArray[np.int64], int]:
    """The arrival group (0 .. n_groups - 1) of every edge row, -1 for other rows: edge rows
    with equal (path_id, channel) form one group (:func:`arrival_bounds`' grouping when the
    edge rows' path ids are sparse: by sorting the keys)."""
    n = kind.size
    lowest = np.iinfo(np.int64).max
    highest = np.iinfo(np.int64).min
    n_edge = 0
    for i in range(n):
        if kind[i] == edge_kind:
            n_edge += 1
            lowest = min(lowest, path_id[i])
            highest = max(highest, path_id[i])
    groups = np.full(n, -1, dtype=np.int64)
    if n_edge == 0:
        return groups, 0
    n_groups = 0
    rows = np.empty(n_edge, dtype=np.int64)
    keys = np.empty(n_edge, dtype=np.int64)
    e = 0
    for i in range(n):
        if kind[i] == edge_kind:
            rows[e] = i
            keys[e] = (path_id[i] - lowest) * 8 + channel[i]
            e += 1
    order = np.argsort(keys, kind="mergesort")
    for e in range(n_edge):
        if e > 0 and keys[order[e]] != keys[order[e - 1]]:
            n_groups += 1
        groups[rows[order[e]]] = n_groups
    return groups, n_groups + 1


class FloorFields(NamedTuple):
    """The fields of the rows the floor reads (views of the structured array, any strides)."""

    kind: NDArray[np.int8]
    path_id: NDArray[np.int64]
    channel: NDArray[np.int8]
    geometric_gain: NDArray[np.float64]
    angle_tx_rad: NDArray[np.float64]
    angle_rx_rad: NDArray[np.float64]
    path_length_m: NDArray[np.float64]
    delay_s: NDArray[np.float64]
    phase_rad: NDArray[np.float64]
    amplitude: NDArray[np.float64]
    directivity_tx: NDArray[np.float64]
    directivity_rx: NDArray[np.float64]
    absorption_db: NDArray[np.float64]


def floor_fields(rows: NDArray[Any]) -> FloorFields:
    """The :class:`FloorFields` views of PATH_DTYPE ``rows`` (derived columns filled)."""
    return FloorFields(*(rows[name] for name in FloorFields._fields))


class BoundSettings(NamedTuple):
    """What :func:`arrival_bounds` needs besides the rows.

    Attributes
    ----------
    envelope : ndarray, shape (c + 1,)
        :func:`angle_envelope` at the band's lowest frequency.
    alpha_min_db_per_m : float
        Smallest absorption over the band frequencies (dB/m).
    centre_weight : float
        Pulse weight at the centre frequency.
    two_pi_f0 : float
        2 pi f0 (rad/s).
    direct_kind, edge_kind : int
        ``PathKind.DIRECT`` and ``PathKind.EDGE``.
    """

    envelope: NDArray[np.float64]
    alpha_min_db_per_m: float
    centre_weight: float
    two_pi_f0: float
    direct_kind: int
    edge_kind: int


class Arrivals(NamedTuple):
    """The arrivals of some rows and first bounds of their band levels (:func:`arrival_bounds`).

    Attributes
    ----------
    single_rows : ndarray of int64, shape (s,)
        Rows of the single-row arrivals (neither direct nor edge), increasing; arrivals 0 .. s-1.
    group_start : ndarray of int64, shape (g + 1,)
        g the number of edge groups.
    group_rows : ndarray of int64, shape (e,)
        Rows of edge group g: ``group_rows[group_start[g]:group_start[g + 1]]``, increasing;
        the group is arrival s + g.
    lower, upper : ndarray, shape (s + g,)
        ``lower``: the level at the centre frequency times its pulse weight (for a group, of
        the coherent sum of its rows, ``amplitude``-side columns with the phase
        2 pi f0 (delay - first row's delay)); ``upper``: the sum over the arrival's rows of
        |g| envelope(angle_tx) envelope(angle_rx) 10^(-alpha_min L / 20) (pulse weights <= 1).
    """

    single_rows: NDArray[np.int64]
    group_start: NDArray[np.int64]
    group_rows: NDArray[np.int64]
    lower: NDArray[np.float64]
    upper: NDArray[np.float64]


class BandTable(NamedTuple):
    """The band frequencies as :func:`table_levels` reads them (m of them, increasing).

    Attributes
    ----------
    scales, weights, alpha_db_per_m, two_pi_f : ndarray, shape (m,)
        k a = 2 pi f a / c, pulse weight, absorption (dB/m) and 2 pi f.
    visit : ndarray of int64, shape (m,)
        The order in which single-row arrivals visit the frequencies (highest weight first).
    chained : ndarray of bool, shape (m,)
        Whether f_j - f_(j-1) is the step (to 1e-9 of it).
    two_pi_step : float
        2 pi times the step (rad/s).
    """

    scales: NDArray[np.float64]
    weights: NDArray[np.float64]
    alpha_db_per_m: NDArray[np.float64]
    two_pi_f: NDArray[np.float64]
    visit: NDArray[np.int64]
    chained: NDArray[np.bool_]
    two_pi_step: float


class DirectivityTable(NamedTuple):
    """2 J1(x)/x tabulated (:func:`directivity_table`), 1 / its step, and the interpolation's
    error bound (:func:`interpolation_error`)."""

    values: NDArray[np.float64]
    inverse_step: float
    error: float


@plain_tuple_arguments
@njit(cache=True, nogil=True, error_model="numpy")
def arrival_bounds(rows_fields: tuple, settings_fields: tuple) -> Arrivals:
    """The :class:`Arrivals` of ``rows`` (edge rows with equal (path_id, channel) form one
    arrival; direct rows none) and first bounds of their band levels."""
    rows, settings = FloorFields(*rows_fields), BoundSettings(*settings_fields)
    kind, path_id, channel, gain = rows.kind, rows.path_id, rows.channel, rows.geometric_gain
    angle_tx, angle_rx, length, delay, phase = (rows.angle_tx_rad, rows.angle_rx_rad, rows.path_length_m,
                                                rows.delay_s, rows.phase_rad)
    amplitude, directivity_tx, directivity_rx, absorption_db = (rows.amplitude, rows.directivity_tx,
                                                                rows.directivity_rx, rows.absorption_db)
    envelope, alpha_min_db_per_m, centre_weight = settings.envelope, settings.alpha_min_db_per_m, settings.centre_weight
    two_pi_f0, direct_kind, edge_kind = settings.two_pi_f0, settings.direct_kind, settings.edge_kind
    alpha_min_neper = -alpha_min_db_per_m * _NEPER_PER_DB  # >= 0: nepers per metre
    n = kind.size
    # pass 1 (kind and path_id only): counts, and the edge keys' range
    n_single = 0
    n_edge = 0
    lowest = np.iinfo(np.int64).max
    highest = np.iinfo(np.int64).min
    for i in range(n):
        k = kind[i]
        if k == edge_kind:
            n_edge += 1
            lowest = min(lowest, path_id[i])
            highest = max(highest, path_id[i])
        elif k != direct_kind:
            n_single += 1
    dense = n_edge > 0 and highest - lowest <= 64 * n_edge + 1024
    if dense:  # groups numbered in order of first appearance, through a key table
        slot = np.full((highest - lowest + 1) * 8, -1, dtype=np.int64)
        groups = np.empty(0, dtype=np.int64)
        n_groups = n_edge  # at most; trimmed below
    else:
        slot = np.empty(0, dtype=np.int64)
        groups, n_groups = _edge_groups(kind, path_id, channel, edge_kind)
    single_rows = np.empty(n_single, dtype=np.int64)
    edge_rows = np.empty(n_edge, dtype=np.int64)
    edge_group = np.empty(n_edge, dtype=np.int64)
    lower = np.zeros(n_single + n_groups)
    upper = np.zeros(n_single + n_groups)
    re = np.zeros(n_groups)
    im = np.zeros(n_groups)
    magnitude = np.zeros(n_groups)
    reference = np.empty(n_groups)
    count = np.zeros(n_groups + 1, dtype=np.int64)
    s = 0
    e = 0
    found = 0
    # pass 2: the bounds
    for i in range(n):
        k = kind[i]
        if k == direct_kind:
            continue
        bound = abs(gain[i])
        bound *= _envelope(angle_tx[i], envelope)
        bound *= _envelope(angle_rx[i], envelope)
        # exp(-y) <= 1 / (1 + y + y^2 / 2) for y >= 0 (a division, no exponential)
        y = alpha_min_neper * length[i]
        bound *= (1.0 + ROUNDING_SLACK) / (1.0 + y + 0.5 * (y * y))
        if k != edge_kind:
            single_rows[s] = i
            lower[s] = amplitude[i] * centre_weight
            upper[s] = bound
            s += 1
            continue
        if dense:
            key = (path_id[i] - lowest) * 8 + channel[i]
            g = slot[key]
            if g < 0:
                g = found
                slot[key] = g
                found += 1
                reference[g] = delay[i]
        else:
            g = groups[i]
            if count[g + 1] == 0:
                reference[g] = delay[i]
        edge_rows[e] = i
        edge_group[e] = g
        e += 1
        count[g + 1] += 1
        factor = gain[i] * directivity_tx[i] * directivity_rx[i] * math.exp(absorption_db[i] * _NEPER_PER_DB)
        angle = phase[i] - two_pi_f0 * (delay[i] - reference[g])
        re[g] += factor * math.cos(angle)
        im[g] += factor * math.sin(angle)
        magnitude[g] += abs(factor)
        upper[n_single + g] += bound
    if dense:
        n_groups = found
        lower = lower[:n_single + n_groups].copy()
        upper = upper[:n_single + n_groups].copy()
    group_start = np.zeros(n_groups + 1, dtype=np.int64)
    for g in range(n_groups):
        lower[n_single + g] = max(math.hypot(re[g], im[g]) - ROUNDING_SLACK * magnitude[g], 0.0) * centre_weight
        group_start[g + 1] = group_start[g] + count[g + 1]
    # the edge rows by group (a counting sort; rows stay increasing within a group)
    group_rows = np.empty(n_edge, dtype=np.int64)
    fill = group_start[:n_groups].copy()
    for r in range(n_edge):
        g = edge_group[r]
        group_rows[fill[g]] = edge_rows[r]
        fill[g] += 1
    return Arrivals(single_rows, group_start, group_rows, lower, upper)


@njit(cache=True, nogil=True, error_model="numpy")
def _directivity(front: bool, sine: float, scale: float, table: NDArray[np.float64], inverse_step: float) -> float:
    """Interpolated D at x = scale sin(angle) in front of the piston, 0 behind it."""
    if not front:
        return 0.0
    return _interpolate(scale * sine, table, inverse_step)


@plain_tuple_arguments
@njit(cache=True, nogil=True, error_model="numpy")
def table_levels(arrivals: NDArray[np.int64], groups_fields: tuple, rows_fields: tuple, band_fields: tuple,
                 directivity_fields: tuple, threshold: float) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """An interval [lo, hi] containing the band level of each of ``arrivals`` (q,) (numbered as
    ``groups`` numbers them), by the rule of
    :func:`~acoustisim.propagation.reference.floor.band_levels`.

    Per frequency f_j the arrival's level w_j |sum_i g_i D(x_tx) D(x_rx) A_ij exp(j phi_ij)|
    is evaluated with the interpolated D (each within ``directivity.error`` of the true one, and
    |D| <= 1, so each product within error (2 + error)); with B_j = w_j sum_i |g_i| A_ij the
    level is within B_j (error (2 + error) + :data:`ROUNDING_SLACK`) of the value found. lo and
    hi are the maxima over f_j of the value minus and plus that.

    An edge group's phase factors exp(j (phase - 2 pi f_j dtau)) at frequencies one step above
    the previous (``band.chained``) are the previous one's times exp(-j 2 pi step dtau): a
    complex product instead of a cosine and a sine (a few ulp per step; within the slack).

    A single-row arrival stops at the first frequency where lo reaches ``threshold`` (hi is
    then +inf); pass +inf for complete intervals. hi = +inf (and lo = 0) for an arrival with a
    row within 1e-12 of 90 degrees off a piston's axis (where the front test decides whether D
    is 0).
    """
    groups = Arrivals(*groups_fields)
    rows = FloorFields(*rows_fields)
    band = BandTable(*band_fields)
    directivity = DirectivityTable(*directivity_fields)
    single_rows, group_start, group_rows = groups.single_rows, groups.group_start, groups.group_rows
    gain, angle_tx, angle_rx = rows.geometric_gain, rows.angle_tx_rad, rows.angle_rx_rad
    length, delay, phase = rows.path_length_m, rows.delay_s, rows.phase_rad
    scales, weights, alpha_db_per_m, two_pi_f = band.scales, band.weights, band.alpha_db_per_m, band.two_pi_f
    visit, chained, two_pi_step = band.visit, band.chained, band.two_pi_step
    table, inverse_step, error = directivity.values, directivity.inverse_step, directivity.error
    n_single = single_rows.size
    m = scales.size
    neper = alpha_db_per_m * _NEPER_PER_DB
    product_error = error * (2.0 + error) + ROUNDING_SLACK
    lo = np.zeros(arrivals.size)
    hi = np.zeros(arrivals.size)
    re = np.empty(m)
    im = np.empty(m)
    total = np.empty(m)
    for q in range(arrivals.size):
        a = arrivals[q]
        if a < n_single:
            i = single_rows[a]
            cos_tx = math.cos(angle_tx[i])
            cos_rx = math.cos(angle_rx[i])
            if abs(cos_tx) < _EDGE_DIRECTIVITY_COS or abs(cos_rx) < _EDGE_DIRECTIVITY_COS:
                lo[q] = 0.0
                hi[q] = math.inf
                continue
            sin_tx = math.sin(angle_tx[i])
            sin_rx = math.sin(angle_rx[i])
            magnitude = abs(gain[i])
            best_lo = 0.0
            best_hi = 0.0
            for v in range(m):
                j = visit[v]
                bound = weights[j] * magnitude * math.exp(neper[j] * length[i])
                value = bound * abs(_directivity(cos_tx >= 0.0, sin_tx, scales[j], table, inverse_step)
                                    * _directivity(cos_rx >= 0.0, sin_rx, scales[j], table, inverse_step))
                best_lo = max(best_lo, value - bound * product_error)
                best_hi = max(best_hi, value + bound * product_error)
                if best_lo >= threshold:
                    best_hi = math.inf
                    break
            lo[q] = best_lo
            hi[q] = best_hi
            continue
        g = a - n_single
        first = group_start[g]
        if first == group_start[g + 1]:
            continue
        reference = delay[group_rows[first]]
        re[:] = 0.0
        im[:] = 0.0
        total[:] = 0.0
        uncertain = False
        for r in range(first, group_start[g + 1]):
            i = group_rows[r]
            cos_tx = math.cos(angle_tx[i])
            cos_rx = math.cos(angle_rx[i])
            if abs(cos_tx) < _EDGE_DIRECTIVITY_COS or abs(cos_rx) < _EDGE_DIRECTIVITY_COS:
                uncertain = True
                break
            sin_tx = math.sin(angle_tx[i])
            sin_rx = math.sin(angle_rx[i])
            dtau = delay[i] - reference
            step_angle = two_pi_step * dtau
            step_re = math.cos(step_angle)
            step_im = -math.sin(step_angle)
            z_re = 0.0
            z_im = 0.0
            for j in range(m):
                if j > 0 and chained[j]:
                    z_re, z_im = z_re * step_re - z_im * step_im, z_re * step_im + z_im * step_re
                else:
                    angle = phase[i] - two_pi_f[j] * dtau
                    z_re = math.cos(angle)
                    z_im = math.sin(angle)
                attenuation = math.exp(neper[j] * length[i])
                factor = (gain[i] * _directivity(cos_tx >= 0.0, sin_tx, scales[j], table, inverse_step)
                          * _directivity(cos_rx >= 0.0, sin_rx, scales[j], table, inverse_step) * attenuation)
                re[j] += factor * z_re
                im[j] += factor * z_im
                total[j] += abs(gain[i]) * attenuation
        if uncertain:
            lo[q] = 0.0
            hi[q] = math.inf
            continue
        best_lo = 0.0
        best_hi = 0.0
        for j in range(m):
            value = weights[j] * math.hypot(re[j], im[j])
            slack = weights[j] * total[j] * product_error
            best_lo = max(best_lo, value - slack)
            best_hi = max(best_hi, value + slack)
        lo[q] = best_lo
        hi[q] = best_hi
    return lo, hi


__all__ = ("Arrivals", "BandTable", "BoundSettings", "DIRECTIVITY_TABLE_INTERVALS", "DirectivityTable", "FloorFields",
           "ROUNDING_SLACK", "angle_envelope", "arrival_bounds", "directivity_table", "floor_fields",
           "interpolation_error", "table_levels")
