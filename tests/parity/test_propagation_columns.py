"""The fast engine's complete_columns (compiled) against the reference engine's (numpy, per column)."""

from __future__ import annotations

import numpy as np
import pytest

from acoustisim.propagation import PathKind, SolverConfig, prepare, solve
from acoustisim.propagation.fast.columns import complete_columns
from acoustisim.propagation.context import SolveContext
from acoustisim.propagation.engine import engine_for
from acoustisim.propagation.paths import empty_paths_array
from acoustisim.propagation.reference import columns as reference_columns
from scenes.builtin import builtin_scene

DERIVED = ("delay_s", "angle_tx_rad", "angle_rx_rad", "directivity_tx", "directivity_rx", "absorption_db",
           "amplitude")


def _reference(rows, context):
    """The reference engine's derived columns of ``rows``."""
    filled = reference_columns.complete_columns(rows.copy(), context)
    return {name: filled[name] for name in DERIVED}


@pytest.fixture(scope="module")
def solved():
    prepared = prepare(builtin_scene("thesis-tank"))
    paths = solve(prepared, config=SolverConfig(max_order=2, diffuse_rays=3000, amplitude_floor_db=None))
    context = SolveContext.build(prepared.scene, prepared.scene.sonar, prepared.raycaster)
    return paths, context, prepared


def test_columns_match_the_reference_engine(solved):
    paths, context, prepared = solved
    # the solved rows (sorted by channel and delay) and the diffuse tracer's own rows, where
    # the receivers of one scattering event are adjacent (runs of one departure direction)
    config = SolverConfig(diffuse_rays=3000, seed=1)
    raw = engine_for(config).diffuse_rows(context, config, prepared)
    rows = np.concatenate([paths.rows, raw])
    for name in DERIVED:
        rows[name] = np.nan
    complete_columns(rows, context)
    reference = _reference(rows, context)
    kinds = set(np.unique(rows["kind"]).tolist())
    assert {int(PathKind.SPECULAR), int(PathKind.EDGE), int(PathKind.DIFFUSE)} <= kinds
    # some rows behind a piston (directivity 0) and runs of shared departure directions
    assert np.any(rows["angle_rx_rad"] > np.pi / 2) and np.any(rows["directivity_rx"] == 0.0)
    dep = rows["departure_dir"]
    assert np.any(np.all(dep[1:] == dep[:-1], axis=1))
    # delay and absorption: the same single operation, exact
    np.testing.assert_array_equal(rows["delay_s"], reference["delay_s"])
    np.testing.assert_array_equal(rows["absorption_db"], reference["absorption_db"])
    # angles: numpy's arctan2 of the same products and sums (identical here); 1e-15 (2 ulp of
    # pi) leaves room for a compiler fusing the products into FMAs
    for name in ("angle_tx_rad", "angle_rx_rad"):
        np.testing.assert_allclose(rows[name], reference[name], rtol=0, atol=1e-15)
    # directivities: sin(angle) as s / hypot(s, c) is a few ulp from np.sin; |d(2 J1(x)/x)/dx|
    # < 1/4 and x < 21, so the directivity moves by < 21 * 4 ulp / 4 ~ 2e-14 at most
    for name in ("directivity_tx", "directivity_rx"):
        np.testing.assert_allclose(rows[name], reference[name], rtol=0, atol=2e-14)
    # amplitude = |g| |D_tx D_rx| 10^(-L/20): the directivity tolerance (|D| <= 1) relative to
    # |g| 10^(-L/20), plus a few ulp of the exponential
    scale = np.abs(rows["geometric_gain"]) * 10.0 ** (-reference["absorption_db"] / 20.0)
    assert np.all(np.abs(rows["amplitude"] - reference["amplitude"]) <= 5e-14 * scale)
    # not a vacuous comparison: the directivities span lobes and nulls
    assert rows["directivity_rx"].min() < 0 < rows["directivity_rx"].max()


def test_empty_rows_are_returned_unchanged(solved):
    _, context, _ = solved
    rows = empty_paths_array(0)
    assert complete_columns(rows, context).size == 0
