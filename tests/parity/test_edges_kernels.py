"""The fast engine's edge kernels against the reference engine's functions they compute.

The discretisation (:mod:`acoustisim.propagation.fast.edge_elements`) and the quadrature
(:mod:`acoustisim.propagation.fast.edge_gains`) do the reference's arithmetic in its order;
the rows (:mod:`acoustisim.propagation.fast.edges`) are the reference's, ordered as the
assembly orders rows. Elements, points and path lengths are held to 1e-14 relative and gains
to 1e-12: the two evaluate the same expressions with libm's ``hypot`` and numpy's vectorised
``log1p``, ``sinh`` and ``arctan2`` (identical on the development machine; numpy may pick
different SIMD paths for different array shapes on other CPUs, a few ulp), while a wrong term,
sign or order of operations shows at 1e-3 or above.
"""

from __future__ import annotations

import numpy as np
import pytest

from acoustisim.propagation import SolverConfig, prepare
from acoustisim.propagation.context import SolveContext
from acoustisim.propagation.fast import edge_elements as fast_elements
from acoustisim.propagation.fast import edge_gains as fast_gains
from acoustisim.propagation.fast.edges import edge_rows as fast_edge_rows
from acoustisim.propagation.reference import btm
from acoustisim.propagation.reference import edge_elements as reference_elements
from acoustisim.propagation.reference import edge_paths as reference_edge_paths
from acoustisim.propagation.reference import edges as reference_edges
from acoustisim.propagation.reference.edge_elements import Discretisation, PairGeometry

C = 1482.38
STEP_M = C / (16 * 500e3)
POSITION_RTOL = 1e-14
GAIN_RTOL = 1e-12  # see the module docstring

GRIDS = {
    "fine": Discretisation(STEP_M, 5e-4),
    "graded": Discretisation(STEP_M, 5e-4, coarsening_levels=2, grading=4, cap_growth=0.1, onset_nodes=7),
    "graded, 3 levels of 2": Discretisation(STEP_M, 5e-3, coarsening_levels=3, grading=2, onset_nodes=7),
    "graded, long elements": Discretisation(STEP_M, 5e-3, coarsening_levels=2, grading=4, cap_growth=0.1,
                                            onset_nodes=7),
}


def random_pairs(seed: int, p: int = 60) -> tuple[PairGeometry, btm.WedgePairs]:
    """Pairs with the apex inside the edge, before its start and beyond its end, joints at
    random, rigid and pressure-release wedges of exterior angles from 189 to 360 degrees, and
    receivers anywhere in the water's angular range (on boundaries included)."""
    rng = np.random.default_rng(seed)
    length = rng.uniform(0.02, 2.0, p)
    r_s, r_r = rng.uniform(0.01, 2.0, p), rng.uniform(0.01, 2.0, p)
    z_s, z_r = rng.uniform(-1.0, 3.0, p), rng.uniform(-1.0, 3.0, p)
    nu = np.pi / rng.uniform(1.05 * np.pi, 2.0 * np.pi, p)
    theta_s = rng.uniform(0.0, 1.0, p) * np.pi / nu
    theta_r = rng.uniform(0.0, 1.0, p) * np.pi / nu
    theta_r[:5] = np.pi - theta_s[:5]  # on face 1's reflection boundary: the model's zero term
    geometry = PairGeometry(length, r_s, z_s, r_r, z_r, rng.random(p) < 0.5, rng.random(p) < 0.5)
    return geometry, btm.WedgePairs(nu, r_s, theta_s, z_s, r_r, theta_r, z_r, rng.random(p) < 0.5)


def assert_same_elements(got, want) -> None:
    np.testing.assert_array_equal(got.pair, want.pair)
    for name in ("z_start_m", "z_end_m", "path_length_m"):
        np.testing.assert_allclose(getattr(got, name), getattr(want, name), rtol=POSITION_RTOL, atol=0.0,
                                   err_msg=name)


@pytest.mark.parametrize("grid", GRIDS.values(), ids=list(GRIDS))
def test_discretisation_matches_the_reference(grid):
    for seed in range(4):
        geometry, _ = random_pairs(seed)
        got = fast_elements.discretise_edges(geometry, grid)
        want = reference_elements.discretise_edges(geometry, grid)
        assert got.pair.size > 1000
        assert_same_elements(got, want)


@pytest.mark.parametrize("grid", [GRIDS["fine"], GRIDS["graded, long elements"]], ids=["fine", "graded"])
def test_quadrature_matches_the_reference(grid):
    geometry, wedge = random_pairs(7)
    elements = reference_elements.discretise_edges(geometry, grid)
    constants = btm.pair_constants(wedge)
    got, want = fast_gains.quadrature_points(elements, constants), btm.quadrature_points(elements, constants)
    for name in ("z_m", "path_length_m"):
        np.testing.assert_allclose(getattr(got, name), getattr(want, name), rtol=POSITION_RTOL, err_msg=name)
    scale = np.max(np.abs(want.gain))
    np.testing.assert_allclose(got.gain, want.gain, rtol=GAIN_RTOL, atol=GAIN_RTOL * scale)
    whole = btm.element_gains(elements, constants)
    np.testing.assert_allclose(fast_gains.element_gains(elements, constants), whole, rtol=GAIN_RTOL,
                               atol=GAIN_RTOL * np.max(np.abs(whole)))


@pytest.fixture(scope="module")
def prepared_tank(thesis_tank):
    return prepare(thesis_tank)


def thesis_tank_poses(prepared, count: int, seed: int):
    """The default pose and ``count`` others moved up to 30 cm and turned up to 20 degrees."""
    rng = np.random.default_rng(seed)
    sonar = prepared.scene.sonar
    yield sonar
    for _ in range(count):
        yield sonar.with_pose(position_m=tuple(np.asarray(sonar.position_m) + rng.uniform(-0.3, 0.3, 3)),
                              yaw_deg=float(sonar.yaw_deg + rng.uniform(-20, 20)))


@pytest.mark.parametrize("adaptive", [True, False], ids=["graded", "fine"])
def test_thesis_tank_elements_and_gains_match_the_reference(prepared_tank, adaptive):
    """On the thesis tank's own pairs (its prism, and its pipe rim with chain joints)."""
    prepared = prepared_tank
    config = SolverConfig(edge_adaptive=adaptive)
    for sonar in thesis_tank_poses(prepared, 2, seed=3):
        context = SolveContext.build(prepared.scene, sonar, prepared.raycaster)
        pairs = reference_edges.edge_pairs(context, prepared.diffracting_edges)
        grid = reference_edges.discretisation(config, context)
        elements = reference_elements.discretise_edges(pairs.geometry, grid)
        assert elements.pair.size > 5000
        assert_same_elements(fast_elements.discretise_edges(pairs.geometry, grid), elements)
        constants = btm.pair_constants(pairs.wedge)
        got = fast_gains.quadrature_points(elements, constants).gain
        want = btm.quadrature_points(elements, constants).gain
        np.testing.assert_allclose(got, want, rtol=GAIN_RTOL, atol=GAIN_RTOL * np.max(np.abs(want)))


@pytest.mark.parametrize("adaptive", [True, False], ids=["graded", "fine"])
def test_thesis_tank_rows_are_the_reference_rows_in_the_assembly_order(prepared_tank, adaptive):
    """Every field of every row, the fast rows already in the order the reference assembly's
    stable sort by (channel, delay) gives the reference rows."""
    prepared = prepared_tank
    config = SolverConfig(edge_adaptive=adaptive)
    for sonar in thesis_tank_poses(prepared, 2, seed=4):
        context = SolveContext.build(prepared.scene, sonar, prepared.raycaster, first_path_id=7)
        got = fast_edge_rows(context, config, prepared)
        want = reference_edge_paths.edge_rows(context, config, prepared)
        assert want.size > 10_000
        want = want[np.lexsort((want["path_length_m"] / context.sound_speed_m_s, want["channel"]))]
        assert got.shape == want.shape
        for name in want.dtype.names:
            if np.issubdtype(want[name].dtype, np.floating):
                scale = np.nanmax(np.abs(want[name])) if want[name].size else 0.0
                rtol = GAIN_RTOL if name == "geometric_gain" else POSITION_RTOL
                np.testing.assert_allclose(got[name], want[name], rtol=rtol, atol=rtol * scale, equal_nan=True,
                                           err_msg=name)
            else:
                np.testing.assert_array_equal(got[name], want[name], err_msg=name)


def test_no_pairs_give_no_rows(builtin_scenes):
    """A scene without sharp edges: both engines return an empty, well-typed array."""
    prepared = prepare(builtin_scenes("free-sphere"))
    context = SolveContext.build(prepared.scene, prepared.scene.sonar, prepared.raycaster)
    for rows in (fast_edge_rows(context, SolverConfig(), prepared),
                 reference_edge_paths.edge_rows(context, SolverConfig(), prepared)):
        assert rows.size == 0 and rows.dtype.names is not None


def test_diffracting_edges_are_built_once_per_prepared_scene(prepared_tank):
    prepared = prepared_tank
    assert prepared.diffracting_edges is prepared.diffracting_edges
    assert len(prepared.diffracting_edges.edges) > 60  # the prism's vertical edges and the pipe's two rims
