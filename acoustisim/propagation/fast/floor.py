"""The amplitude floor of the fast engine: the reference rule
(:mod:`acoustisim.propagation.reference.floor`), decided mostly from bounds.

The rule (:func:`~acoustisim.propagation.reference.floor.band_levels`): an arrival (a row, or
the rows of an edge diffraction sharing ``path_id`` and channel) has as level its strongest pulse-weighted level over a few band
frequencies (:func:`floor_frequencies`); it is dropped when that is below
``SolverConfig.amplitude_floor_db`` relative to the strongest non-direct arrival. Direct paths
are always kept. :func:`floor_mask` applies the rule, deciding most arrivals from bounds
computed in the compiled passes of :mod:`acoustisim.propagation.fast.floor_kernels` and evaluating
the rule itself (in numpy) only on the few the bounds leave open.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from acoustisim.propagation.context import SolveContext
from acoustisim.propagation.fast.floor_kernels import (BandTable, BoundSettings, DirectivityTable, angle_envelope,
                                                       arrival_bounds, directivity_table, floor_fields,
                                                       interpolation_error, table_levels)
from acoustisim.propagation.paths import PathKind
from acoustisim.propagation.reference.floor import band_levels, floor_frequencies

def floor_mask(rows: NDArray[Any], floor_db: float | None, context: SolveContext,
               band_hz: tuple[float, float] | None = None) -> NDArray[np.bool_]:
    """Which rows survive the amplitude floor (whole arrivals are kept or dropped).

    An arrival (a row, or the rows of an edge diffraction sharing ``path_id`` and channel) is
    dropped when its strongest level across the band (:func:`band_levels`) is below
    ``floor_db`` relative to the strongest such level of any non-direct arrival; direct paths
    are always kept. Judging across the band, not at the centre frequency alone, keeps an
    echo that sits near the pistons' first null at f0 (about 11 deg off axis for the seed's
    19 mm, 500 kHz pistons) but is strong at the band's lower frequencies.

    The band levels are computed only where needed, in three tiers:

    1. every arrival's level lies between its level at the centre frequency (one of the band
       frequencies; from the ``amplitude``-side columns, no Bessel function) and an upper
       bound (the sum of |g| times the directivity envelopes, times the absorption at the
       band's least-absorbed frequency; pulse weights <= 1)
       (:func:`~acoustisim.propagation.fast.floor_kernels.arrival_bounds`);
    2. arrivals these leave open get an interval of width about 1e-5 of their terms around
       the level, with 2 J1(x)/x interpolated from a table with a proven error bound
       (:func:`~acoustisim.propagation.fast.floor_kernels.table_levels`);
    3. arrivals still open (within that of the threshold, or competing for the strongest)
       are evaluated by :func:`band_levels`.

    Each bound contains the level numpy computes (the rounding of both is covered by
    :data:`~acoustisim.propagation.fast.floor_kernels.ROUNDING_SLACK`), so the kept rows are those
    of :func:`band_levels` applied to every arrival (``tests/physics/test_propagation_floor.py``).

    Parameters
    ----------
    rows : structured ndarray of PATH_DTYPE, shape (n,)
        With the derived columns filled.
    floor_db : float or None
        None keeps every row.
    context : SolveContext
    band_hz : (float, float) or None
        ``SolverConfig.amplitude_floor_band_hz``.

    Returns
    -------
    ndarray of bool, shape (n,)
    """
    keep = np.ones(rows.size, dtype=bool)
    if floor_db is None or rows.size == 0:
        return keep
    frequencies, weights = floor_frequencies(context, band_hz)
    c, a = context.sound_speed_m_s, context.piston_radius_m
    centre_weight = float(weights[np.searchsorted(frequencies, context.centre_frequency_hz)])
    alpha = np.asarray(context.scene.medium.absorption_db_per_m(frequencies), dtype=float)
    # k a at each frequency, formed as piston_directivity forms x / sin(angle)
    scales = 2.0 * np.pi * frequencies / float(c) * float(a)
    table, step = directivity_table(float(scales.max()))
    envelope = angle_envelope(table, step, float(scales[0]) / step)  # from the lowest frequency up

    fields = floor_fields(rows)
    arrivals = arrival_bounds(fields, BoundSettings(envelope, float(alpha.min()), centre_weight,
                                                    2.0 * np.pi * context.centre_frequency_hz, int(PathKind.DIRECT),
                                                    int(PathKind.EDGE)))
    single_rows, group_start, group_rows, lower, upper = arrivals
    n_single = single_rows.size
    # frequencies increasing (floor_frequencies sorts them); singles visit them highest pulse
    # weight first (early exits); edge groups step the phase factor across evenly spaced ones
    visit = np.argsort(-weights, kind="stable").astype(np.int64)
    steps = np.diff(frequencies)
    step_hz = float(steps.max(initial=0.0))
    chained = np.r_[False, np.abs(steps - step_hz) <= 1e-9 * step_hz]
    band = BandTable(scales, weights, alpha, 2.0 * np.pi * frequencies, visit, chained, 2.0 * np.pi * step_hz)
    directivity = DirectivityTable(table, 1.0 / step, interpolation_error(step))

    def intervals(which: NDArray[np.intp], threshold: float) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        return table_levels(which.astype(np.int64), arrivals, fields, band, directivity, threshold)

    def exact(which: NDArray[np.intp]) -> NDArray[np.float64]:
        """Band levels of arrivals (singles 0 .. n_single - 1, then edge groups) by the rule."""
        levels = np.empty(which.size)
        is_single = which < n_single
        picked = single_rows[which[is_single]]
        levels[is_single] = band_levels(np.take(rows, picked), np.arange(picked.size), picked.size, context,
                                        frequencies, weights)
        chosen = which[~is_single] - n_single
        if chosen.size:
            sizes = group_start[chosen + 1] - group_start[chosen]
            members = np.concatenate([group_rows[group_start[g]:group_start[g + 1]] for g in chosen])
            levels[~is_single] = band_levels(np.take(rows, members), np.repeat(np.arange(chosen.size), sizes),
                                             chosen.size, context, frequencies, weights)
        return levels

    # the strongest level: only arrivals that may exceed every lower bound compete
    # (single rows first: their intervals are cheap and may raise the known level above the
    # edge groups' bounds)
    known = float(lower.max(initial=0.0))
    contenders = np.flatnonzero(upper >= known)
    finalists = []
    for part in (contenders[contenders < n_single], contenders[contenders >= n_single]):
        part = part[upper[part] >= known]
        low, high = intervals(part, np.inf)
        known = max(known, float(low.max(initial=0.0)))
        finalists.append(part[high >= known])
    finalists = np.concatenate(finalists)
    finalists = finalists[upper[finalists] >= known]
    strongest = max(known, float(exact(finalists).max(initial=0.0)))
    threshold = strongest * 10.0 ** (floor_db / 20.0)

    verdict = lower >= threshold
    undecided = np.flatnonzero(~verdict & (upper >= threshold))
    low, high = intervals(undecided, threshold)
    verdict[undecided[low >= threshold]] = True
    still_open = undecided[(low < threshold) & (high >= threshold)]
    verdict[still_open] = exact(still_open) >= threshold
    keep[single_rows] = verdict[:n_single]
    keep[group_rows] = np.repeat(verdict[n_single:], np.diff(group_start))
    return keep


__all__ = ("floor_mask",)
