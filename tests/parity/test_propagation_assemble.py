"""The fast engine's assemble_rows (in-place sorting, merging, floor by bounds) gives the reference
engine's rows: the same rows in the same order, the derived columns within their rounding."""

from __future__ import annotations

import numpy as np
import pytest

from acoustisim.propagation import SolverConfig, prepare
from acoustisim.propagation.context import SolveContext
from acoustisim.propagation.reference.edge_paths import edge_rows as reference_edge_rows
from acoustisim.propagation.fast import FastEngine, assemble
from acoustisim.propagation.fast.assemble import (SortKeys, assemble_rows, compact_records, is_sorted,
                                                  merge_destinations, permute_records, scatter_records)
from acoustisim.propagation.fast.columns import column_inputs, complete_columns, fill_columns
from acoustisim.propagation.paths import PATH_DTYPE, PathKind
from acoustisim.propagation.reference import columns as reference_columns
from scenes.builtin import builtin_scene

EXACT = ("path_id", "channel", "kind", "order", "delay_s", "path_length_m", "geometric_gain", "phase_rad",
         "angle_tx_rad", "angle_rx_rad", "absorption_db", "departure_dir", "arrival_dir", "object_ids", "points_m")
"""Fields the fast assembly moves or computes exactly as the reference does (the angles: the
same products and sums, numpy's arctan2)."""


def spread_records(records: np.ndarray, destination: np.ndarray) -> None:
    """Move records 0 .. h-1 (rows of raw bytes) to ``destination`` (h increasing places,
    ``destination[i] >= i``), in place; the places no record moves onto keep their bytes."""
    records[destination] = records[:destination.size].copy()


def _engine_parts(prepared, context: SolveContext, config: SolverConfig) -> list[np.ndarray]:
    """The fast engine's mechanism parts of one pose, in the solver's order and numbering."""
    engine = FastEngine()
    out, next_id = [], 0
    for make in (lambda c: engine.direct_rows(c),
                 lambda c: engine.specular_rows(c, prepared, config.max_order, config.max_curved_per_path),
                 lambda c: engine.edge_rows(c, config, prepared), lambda c: engine.diffuse_rows(c, config, prepared)):
        rows = make(context.with_first_path_id(next_id))
        out.append(rows)
        next_id = int(rows["path_id"].max()) + 1
    return out


def assert_assembled_alike(got: np.ndarray, expected: np.ndarray) -> None:
    """Same rows in the same order; directivities within 2e-14 (sin(angle) formed as
    |d x a| / hypot instead of np.sin: a few ulp of the argument, |D'| < 1/4, x < 21) and
    amplitudes within 5e-14 of |g| 10^(-A/20) (that, plus a few ulp of the exponential)."""
    assert got.dtype == PATH_DTYPE and got.size == expected.size
    for name in EXACT:
        np.testing.assert_array_equal(got[name], expected[name], err_msg=name)
    for name in ("directivity_tx", "directivity_rx"):
        np.testing.assert_allclose(got[name], expected[name], rtol=0, atol=2e-14, err_msg=name)
    scale = np.abs(expected["geometric_gain"]) * 10.0 ** (-expected["absorption_db"] / 20.0)
    assert np.all(np.abs(got["amplitude"] - expected["amplitude"]) <= 5e-14 * scale)


@pytest.fixture(scope="module")
def parts() -> tuple[SolveContext, list[np.ndarray]]:
    """The thesis tank's mechanism parts (direct, specular to order 2, edges, 2000 diffuse rays)."""
    prepared = prepare(builtin_scene("thesis-tank"))
    context = SolveContext.build(prepared.scene, prepared.scene.sonar, prepared.raycaster)
    return context, _engine_parts(prepared, context, SolverConfig(max_order=2, diffuse_rays=2000, threads=1))


def _reference(parts: list[np.ndarray], context: SolveContext, floor_db: float | None) -> np.ndarray:
    return reference_columns.assemble_rows([part.copy() for part in parts], context, floor_db)


@pytest.mark.parametrize("in_place", [True, False])
@pytest.mark.parametrize("floor_db", [None, -40.0, -80.0])
def test_assembled_rows_are_the_reference_rows(parts, floor_db, in_place, monkeypatch):
    """Both ways of sorting: in the largest part's buffer and scattered into a new one."""
    context, pieces = parts
    monkeypatch.setattr(assemble, "IN_PLACE_MAX_BYTES", 1 << 40 if in_place else 0)
    expected = _reference(pieces, context, floor_db)
    got = assemble_rows([part.copy() for part in pieces], context, floor_db)
    assert got.flags.c_contiguous and got.flags.owndata and got.base is None
    assert_assembled_alike(got, expected)
    if floor_db is not None:
        assert got.size < sum(part.size for part in pieces)
    kinds = set(np.unique(got["kind"]).tolist())
    assert {int(PathKind.SPECULAR), int(PathKind.EDGE), int(PathKind.DIFFUSE)} <= kinds


def test_ties_keep_the_parts_order(parts):
    """Rows with equal channel and delay come out in the parts' order (a stable sort)."""
    context, pieces = parts
    first = pieces[1][:5].copy()
    second = first.copy()
    second["path_id"] += 1000
    expected = _reference([first, second], context, None)
    got = assemble_rows([first, second], context, None)  # takes the parts over
    assert_assembled_alike(got, expected)
    assert np.any(np.diff(got["path_id"]) != 0)


def test_empty_parts():
    prepared = prepare(builtin_scene("thesis-tank"))
    context = SolveContext.build(prepared.scene, prepared.scene.sonar, prepared.raycaster)
    empty = np.zeros(0, dtype=PATH_DTYPE)
    assert assemble_rows([], context, -80.0).size == 0
    assert assemble_rows([empty, empty], context, None).size == 0


def test_record_kernels():
    rng = np.random.default_rng(1)
    source = rng.integers(0, 255, (6, 5), dtype=np.uint8)
    out = np.zeros((6, 5), dtype=np.uint8)
    destination = np.array([3, 0, 5, 1, 4, 2], dtype=np.int64)
    scatter_records(source, destination, out)
    np.testing.assert_array_equal(out[destination], source)
    records = source.copy()
    kept = np.array([1, 2, 4], dtype=np.int64)
    compact_records(records, kept)
    np.testing.assert_array_equal(records[:3], source[kept])
    np.testing.assert_array_equal(records[3:], source[3:])  # untouched beyond the kept ones


def test_permute_records_is_the_scatter():
    rng = np.random.default_rng(2)
    for n in (1, 2, 7, 500):
        records = rng.integers(0, 255, (n, 9), dtype=np.uint8)
        destination = rng.permutation(n).astype(np.int64)
        expected = np.empty_like(records)
        expected[destination] = records
        permute_records(records, destination)
        np.testing.assert_array_equal(records, expected)


@pytest.fixture(scope="module")
def sorted_parts() -> tuple[SolveContext, list[np.ndarray]]:
    """The parts of a deterministic pose as the solver makes them: edge rows already sorted."""
    prepared = prepare(builtin_scene("thesis-tank"))
    context = SolveContext.build(prepared.scene, prepared.scene.sonar, prepared.raycaster)
    return context, _engine_parts(prepared, context, SolverConfig(max_order=3, mechanisms=("direct", "specular",
                                                                                          "edge")))[:3]


def test_sorted_edge_rows_are_the_default_rows_in_solve_order(sorted_parts):
    context, (_, specular, edge) = sorted_parts
    prepared = prepare(builtin_scene("thesis-tank"))
    first = int(specular["path_id"].max()) + 1
    default = reference_edge_rows(context.with_first_path_id(first), SolverConfig(max_order=3), prepared)
    delay = default["path_length_m"] / context.sound_speed_m_s
    assert edge.tobytes() == default[np.lexsort((delay, default["channel"]))].tobytes()


@pytest.mark.parametrize("floor_db", [None, -60.0])
def test_merging_into_the_sorted_edge_rows_gives_the_reference_rows(sorted_parts, floor_db):
    context, pieces = sorted_parts
    expected = _reference(pieces, context, floor_db)
    got = assemble_rows([part.copy() for part in pieces], context, floor_db)
    assert got.flags.owndata and got.base is None
    assert_assembled_alike(got, expected)


def test_merge_destinations_is_the_stable_sort():
    """Random keys with many ties, within and across parts: the merge gives lexsort's places."""
    rng = np.random.default_rng(5)
    for trial in range(20):
        sizes = rng.integers(0, 40, 4)
        host = int(np.argmax(sizes))
        channel = rng.integers(0, 3, sizes.sum()).astype(np.int8)
        delay = rng.integers(0, 6, sizes.sum()).astype(float)  # ties galore
        offsets = np.cumsum(np.r_[0, sizes])
        lo, hi = offsets[host], offsets[host + 1]
        inside = np.lexsort((delay[lo:hi], channel[lo:hi]))
        channel[lo:hi], delay[lo:hi] = channel[lo:hi][inside], delay[lo:hi][inside]
        order = np.lexsort((delay, channel))
        expected = np.empty(order.size, dtype=np.int64)
        expected[order] = np.arange(order.size)
        canonical = np.r_[np.arange(lo), np.arange(hi, offsets[-1])].astype(np.int64)
        other_channel = np.concatenate([channel[:lo], channel[hi:]])
        other_delay = np.concatenate([delay[:lo], delay[hi:]])
        host_destination, destination = merge_destinations(
            SortKeys(channel[lo:hi], delay[lo:hi]), int(lo), SortKeys(other_channel, other_delay), canonical,
            np.lexsort((other_delay, other_channel)).astype(np.int64))
        np.testing.assert_array_equal(host_destination, expected[lo:hi])
        np.testing.assert_array_equal(destination, np.r_[expected[:lo], expected[hi:]])
        # the host's records spread to their places in one buffer, in place
        records = np.zeros((sizes.sum(), 3), dtype=np.uint8)
        records[:hi - lo, 0] = np.arange(hi - lo) + 1
        spread_records(records, host_destination)
        np.testing.assert_array_equal(records[host_destination, 0], np.arange(hi - lo) + 1)


def test_parts_that_cannot_be_taken_over_are_copied(sorted_parts):
    """A read-only largest part is copied (left as it was); a borrowed one (a view) gets its
    derived columns filled but is not resized. The result is the same."""
    context, pieces = sorted_parts
    expected = _reference(pieces, context, None)
    read_only = pieces[2].copy()
    read_only.setflags(write=False)
    before = read_only.tobytes()
    got = assemble_rows([pieces[0].copy(), pieces[1].copy(), read_only], context, None)
    assert_assembled_alike(got, expected)
    assert read_only.tobytes() == before
    base = np.concatenate([pieces[2], pieces[2]])
    view = base[:pieces[2].size]
    got = assemble_rows([pieces[0].copy(), pieces[1].copy(), view], context, None)
    assert_assembled_alike(got, expected)
    assert view.size == pieces[2].size and base.size == 2 * view.size


def _is_sorted_numpy(channel: np.ndarray, delay: np.ndarray) -> bool:
    """Sorted by channel then delay: every step raises the channel, or keeps it and does not lower the delay."""
    step = np.diff(channel.astype(np.int64))
    return bool(np.all((step > 0) | ((step == 0) & (delay[1:] >= delay[:-1]))))


def test_is_sorted_is_the_numpy_rule():
    rng = np.random.default_rng(7)
    seen = set()
    for trial in range(400):
        n = int(rng.integers(0, 12))
        channel = np.sort(rng.integers(0, 3, n)).astype(np.int8)
        delay = np.sort(rng.choice([0.0, 1e-3, 2e-3, 3e-3], n))
        delay = np.concatenate([np.sort(delay[channel == k]) for k in range(3)]) if n else delay
        # perturb some trials: a swapped delay, a swapped channel, a NaN, equal delays (ties)
        kind = trial % 5
        if n >= 2 and kind == 1:
            i = int(rng.integers(0, n - 1))
            delay[[i, i + 1]] = delay[[i + 1, i]]
        elif n >= 2 and kind == 2:
            i = int(rng.integers(0, n - 1))
            channel[[i, i + 1]] = channel[[i + 1, i]]
        elif n >= 1 and kind == 3:
            delay[int(rng.integers(0, n))] = np.nan
        expected = _is_sorted_numpy(channel, delay)
        seen.add(expected)
        assert is_sorted(channel, delay) == expected, (channel, delay)
    assert seen == {True, False}  # both answers exercised
    # strided field views (as assemble_rows may pass) read in place
    rows = np.zeros(5, dtype=PATH_DTYPE)
    rows["channel"] = [0, 0, 1, 1, 2]
    rows["delay_s"] = [1.0, 2.0, 0.5, 0.5, 0.1]
    assert is_sorted(rows["channel"], rows["delay_s"])
    rows["delay_s"][0] = 2.5  # within channel 0, later than the next row
    assert not is_sorted(rows["channel"], rows["delay_s"])


def test_columns_filled_while_spread_are_complete_columns_then_spread(sorted_parts):
    """The fused move-and-fill of the sorted host is complete_columns followed by spread_records,
    byte for byte (the records not moved onto beyond the host's rows left alone)."""
    context, (_, _, edge) = sorted_parts
    rng = np.random.default_rng(11)
    n = edge.size + 700
    # increasing destinations >= i, with gaps (other rows' places) anywhere, the first rows kept
    destination = np.sort(rng.choice(np.arange(50, n), edge.size - 50, replace=False))
    destination = np.concatenate([np.arange(50), destination]).astype(np.int64)
    assert np.all(destination >= np.arange(edge.size)) and np.any(destination > np.arange(edge.size))
    filler = np.frombuffer(rng.bytes(n * PATH_DTYPE.itemsize), dtype=PATH_DTYPE)
    expected = filler.copy()
    expected[:edge.size] = edge
    complete_columns(expected[:edge.size], context)
    spread_records(expected.view(np.uint8).reshape(n, -1), destination)
    got = filler.copy()
    got[:edge.size] = edge
    inputs = column_inputs(got[:edge.size], context)
    # the sort keys read with the directions: the delays' very bits, the channels
    assert inputs.delay_s.tobytes() == expected["delay_s"][destination].tobytes()
    assert np.array_equal(inputs.channel, edge["channel"])
    fill_columns(got, inputs, destination)
    # the destinations, and the records beyond the host's rows that nothing moved onto, byte
    # for byte; the places vacated below are the other rows' (scattered there next)
    vacated = np.setdiff1d(np.arange(edge.size), destination)
    compared = np.setdiff1d(np.arange(n), vacated)
    assert vacated.size and got[compared].tobytes() == expected[compared].tobytes()
    # and the derived columns were filled (not left from the edge rows' placeholders)
    assert np.array_equal(got["delay_s"][destination], edge["path_length_m"] / context.sound_speed_m_s)
