"""complete_columns (compiled) against the per-column numpy formulation it replaced."""

from __future__ import annotations

import numpy as np
import pytest

from acoustisim.propagation import PathKind, SolverConfig, prepare, solve
from acoustisim.propagation.columns import complete_columns
from acoustisim.propagation.context import SolveContext
from acoustisim.propagation.fast.diffuse import diffuse_rows as diffuse_paths
from acoustisim.propagation.directivity import piston_directivity
from acoustisim.propagation.paths import empty_paths_array
from scenes.builtin import builtin_scene

DERIVED = ("delay_s", "angle_tx_rad", "angle_rx_rad", "directivity_tx", "directivity_rx", "absorption_db",
           "amplitude")


def _angle(directions, axis):
    """atan2(|d x a|, d . a) with numpy, per row (the previous formulation)."""
    return np.arctan2(np.linalg.norm(np.cross(directions, axis), axis=1), directions @ axis)


def _reference(rows, context):
    """The previous numpy formulation of the derived columns."""
    out = {}
    c, f0, a = context.sound_speed_m_s, context.centre_frequency_hz, context.piston_radius_m
    out["delay_s"] = rows["path_length_m"] / c
    out["angle_tx_rad"] = _angle(rows["departure_dir"], context.boresight)
    out["angle_rx_rad"] = _angle(-rows["arrival_dir"], context.boresight)
    out["directivity_tx"] = piston_directivity(out["angle_tx_rad"], f0, a, c)
    out["directivity_rx"] = piston_directivity(out["angle_rx_rad"], f0, a, c)
    out["absorption_db"] = rows["path_length_m"] * context.absorption_db_per_m
    out["amplitude"] = (np.abs(rows["geometric_gain"] * out["directivity_tx"] * out["directivity_rx"])
                        * 10.0 ** (-out["absorption_db"] / 20.0))
    return out


@pytest.fixture(scope="module")
def solved():
    prepared = prepare(builtin_scene("thesis-tank"))
    paths = solve(prepared, config=SolverConfig(max_order=2, diffuse_rays=3000, amplitude_floor_db=None))
    context = SolveContext.build(prepared.scene, prepared.scene.sonar, prepared.raycaster)
    return paths, context


def test_columns_match_the_numpy_formulation(solved):
    paths, context = solved
    # the solved rows (sorted by channel and delay) and the diffuse tracer's own rows, where
    # the receivers of one scattering event are adjacent (runs of one departure direction)
    raw = diffuse_paths(context, SolverConfig(diffuse_rays=3000, seed=1))
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
    _, context = solved
    rows = empty_paths_array(0)
    assert complete_columns(rows, context).size == 0
