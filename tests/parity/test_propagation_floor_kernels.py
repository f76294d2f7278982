"""The fast engine's amplitude floor: its compiled bounds contain the rule's levels, and it keeps
exactly the arrivals the reference engine's floor (:func:`band_levels` over every arrival) keeps."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest
from scipy.special import j1

from acoustisim.propagation import PathKind, SolverConfig, prepare, solve
from acoustisim.propagation.context import SolveContext
from acoustisim.propagation.fast.floor import floor_mask
from acoustisim.propagation.fast.floor_kernels import (BandTable, BoundSettings, DirectivityTable, angle_envelope,
                                                       arrival_bounds, directivity_table, floor_fields,
                                                       interpolation_error, table_levels)
from acoustisim.propagation.reference import floor as reference_floor
from acoustisim.propagation.reference.floor import band_levels, floor_frequencies
from scenes.builtin import builtin_scene


def _directivity(x: np.ndarray) -> np.ndarray:
    safe = np.where(x > 0, x, 1.0)
    return np.where(x > 0, 2.0 * j1(safe) / safe, 1.0)


@pytest.fixture(scope="module")
def tank() -> tuple[Any, SolveContext, np.ndarray]:
    """The thesis tank's rows (specular to order 2, graded edges, 3000 diffuse rays), keep-all, as
    the floor sees them (before the elastic-echo step, which follows the assembly)."""
    prepared = prepare(builtin_scene("thesis-tank"))
    config = SolverConfig(max_order=2, diffuse_rays=3000, amplitude_floor_db=None, elastic_echoes=False)
    rows = solve(prepared, config=config).rows.copy()
    context = SolveContext.build(prepared.scene, prepared.scene.sonar, prepared.raycaster)
    return prepared, context, rows


def _level_ratio(rows: np.ndarray, floor_db: float, context: SolveContext) -> np.ndarray:
    """Each row's arrival level over the reference floor's threshold."""
    frequencies, weights = floor_frequencies(context, None)
    group, n_groups = reference_floor.arrival_groups(rows)
    levels = band_levels(rows, group, n_groups, context, frequencies, weights)
    direct = np.zeros(n_groups, dtype=bool)
    direct[group[rows["kind"] == int(PathKind.DIRECT)]] = True
    return levels[group] / (levels[~direct].max() * 10.0 ** (floor_db / 20.0))


@pytest.mark.parametrize("floor_db", [-20.0, -60.0, -100.0])
def test_floor_mask_equals_the_rule_on_every_arrival(tank, floor_db):
    _, context, rows = tank
    expected = reference_floor.floor_mask(rows, floor_db, context)
    ratio = _level_ratio(rows, floor_db, context)
    got = floor_mask(rows, floor_db, context)
    # a level within 1e-12 of the threshold may go either way with the summation order
    clear = np.abs(ratio - 1.0) > 1e-12
    np.testing.assert_array_equal(got[clear], expected[clear])
    assert 0 < got.sum() < got.size


def test_floor_groups_sparse_path_ids_the_same(tank):
    """Edge path ids far apart take the kernel's sorting branch: the same kept rows."""
    _, context, rows = tank
    sparse = rows.copy()
    edge = sparse["kind"] == int(PathKind.EDGE)
    sparse["path_id"][edge] = sparse["path_id"][edge] * 1_000_003 + 17
    sparse["path_id"][~edge] += 10**12  # keep them distinct from the edge ids
    np.testing.assert_array_equal(floor_mask(sparse, -60.0, context), floor_mask(rows, -60.0, context))


def test_interpolation_error_bounds_the_table_and_is_tight():
    table, step = directivity_table(69.0, 512)
    x = np.linspace(0.0, 69.0, 400_001)
    i = np.minimum((x / step).astype(int), table.size - 2)
    t = x / step - i
    error = np.max(np.abs(table[i] + t * (table[i + 1] - table[i]) - _directivity(x)))
    bound = interpolation_error(step)
    assert error <= bound
    assert error > 0.3 * bound  # |D''| reaches 1/4 at x = 0: the bound is nearly attained


def test_angle_envelope_bounds_the_directivity_over_the_band():
    scales = np.array([11.0, 30.0, 69.0])  # k a at the low, centre and high frequencies
    table, step = directivity_table(float(scales[-1]))
    envelope = angle_envelope(table, step, float(scales[0]) / step)
    angle = np.linspace(0.0, 0.5 * np.pi, 40_001)
    cells = envelope.size - 1
    bound = envelope[np.minimum((angle * (cells / (0.5 * np.pi))).astype(int), cells)]
    for scale in np.linspace(scales[0], scales[-1], 37):
        assert np.all(np.abs(_directivity(scale * np.sin(angle))) <= bound)
    # not vacuous: past the main lobe at the lowest frequency (x > 6.2) the side lobes are
    # small (|2 J1(x)/x| <= 0.0752 for x >= 6.2), and the bound follows them (+ step / 4)
    assert np.max(bound[angle > 0.6]) < 0.09


def test_table_intervals_contain_the_rule_levels(tank):
    prepared, context, rows = tank
    frequencies, weights = floor_frequencies(context, None)
    c, a = context.sound_speed_m_s, context.piston_radius_m
    alpha = np.asarray(context.scene.medium.absorption_db_per_m(frequencies), dtype=float)
    scales = 2.0 * np.pi * frequencies / c * a
    table, step = directivity_table(float(scales.max()))
    envelope = angle_envelope(table, step, float(scales[0]) / step)
    fields = floor_fields(rows)
    arrivals = arrival_bounds(fields, BoundSettings(
        envelope, float(alpha.min()), float(weights[np.searchsorted(frequencies, context.centre_frequency_hz)]),
        2.0 * np.pi * context.centre_frequency_hz, int(PathKind.DIRECT), int(PathKind.EDGE)))
    single_rows, group_start, group_rows, lower, upper = arrivals
    steps = np.diff(frequencies)
    chained = np.r_[False, np.abs(steps - steps.max()) <= 1e-9 * steps.max()]
    band = BandTable(scales, weights, alpha, 2.0 * np.pi * frequencies, np.argsort(-weights, kind="stable"), chained,
                     2.0 * np.pi * float(steps.max()))
    lo, hi = table_levels(np.arange(lower.size, dtype=np.int64), arrivals, fields, band,
                          DirectivityTable(table, 1.0 / step, interpolation_error(step)), np.inf)
    # the rule's levels, arrival by arrival (singles, then edge groups)
    members = np.concatenate([single_rows, group_rows])
    group = np.concatenate([np.arange(single_rows.size),
                            single_rows.size + np.repeat(np.arange(group_start.size - 1), np.diff(group_start))])
    levels = band_levels(np.take(rows, members), group, lower.size, context, frequencies, weights)
    assert single_rows.size > 1000 and group_start.size > 10
    assert np.all(lower <= levels * (1 + 1e-12)) and np.all(levels <= upper)
    assert np.all(lo <= levels) and np.all(levels <= hi)
    finite = np.isfinite(hi)
    assert finite.mean() > 0.99
    # the intervals are narrow on the arrivals that matter: 2 x 4.4e-6 of the sum of the terms'
    # magnitudes, a few 1e-3 of the level at most where the directivities are small
    strong = finite & (levels > 1e-3 * levels.max())
    width = (hi - lo)[strong] / levels[strong]
    assert np.median(width) < 1e-4 and np.max(width) < 1e-2
