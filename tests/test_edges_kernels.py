"""The compiled edge kernels against the numpy reference they replace in ``edge_paths``.

The reference is kept here verbatim (numpy's element_gains with per_point, gauss_points, the
path lengths at the points, the amplitude floor and the row filling of the former
``edge_paths``). Tolerance 1e-12 relative: the kernels do the same arithmetic in the same
order, and differ only where libm's elementary functions (sinh, log1p, atan2, hypot) and
numpy's SIMD loops round differently (a few ulp, measured 1e-15 on the thesis tank); a wrong
term, sign or order of operations would show at 1e-3 or above.
"""

from __future__ import annotations

import numpy as np
import pytest

from acoustisim.propagation import SolverConfig, btm, prepare
from acoustisim.propagation import edges as edges_module
from acoustisim.propagation.context import SolveContext
from acoustisim.propagation.edge_kernels import gauss_point_gains
from acoustisim.propagation.paths import PathKind, empty_paths_array
from scenes.builtin import builtin_scene

C = 1482.38
STEP_M = C / (16 * 500e3)
RTOL = 1e-12  # see the module docstring


def _numpy_points(elements, args):
    """The former numpy path: gains, points and path lengths at the two Gauss points."""
    rs, zs, r_r, z_r = args[1], args[3], args[4], args[6]
    gains2 = btm.element_gains(elements, *args, per_point=True, points=2)
    pair2 = np.broadcast_to(elements.pair[:, None], gains2.shape)
    z2 = btm.gauss_points(elements, 2)
    path2 = np.hypot(rs[pair2], z2 - zs[pair2]) + np.hypot(r_r[pair2], z2 - z_r[pair2])
    return gains2, z2, path2


def _numpy_rows(pair, gains, path_length, z_point, pair_edge, pair_rx, chain, surface, start, direction, tx, rx,
                first_path_id):
    """The former numpy row filling (floor included)."""
    keep = np.abs(gains) > edges_module.ELEMENT_FLOOR * np.max(np.abs(gains))
    pair, gains, path_length, z_point = pair[keep], gains[keep], path_length[keep], z_point[keep]
    e = pair_edge[pair]
    points = start[e] + z_point[:, None] * direction[e]
    receivers = rx[pair_rx[pair]]
    channel = pair_rx[pair]
    n_rx = rx.shape[0]
    rows = empty_paths_array(points.shape[0])
    chain_key = chain[e] * n_rx + channel
    present = np.zeros(int(chain_key.max()) + 1, dtype=np.int64)
    present[chain_key] = 1
    rows["path_id"] = first_path_id + (np.cumsum(present) - 1)[chain_key]
    rows["channel"] = channel
    rows["kind"] = int(PathKind.EDGE)
    rows["order"] = 1
    rows["path_length_m"] = path_length
    rows["geometric_gain"] = gains
    rows["phase_rad"] = 0.0
    leg1 = points - tx
    leg2 = receivers - points
    rows["departure_dir"] = leg1 / np.sqrt(np.einsum("ij,ij->i", leg1, leg1))[:, None]
    rows["arrival_dir"] = leg2 / np.sqrt(np.einsum("ij,ij->i", leg2, leg2))[:, None]
    rows["object_ids"][:, 0] = surface[e]
    rows["points_m"][:, 0, :] = points
    return rows


def _kernel(elements, args):
    k = btm.pair_constants(*args)
    x, w = btm.gauss_rule(2)
    return gauss_point_gains(elements.pair, elements.z_start_m, elements.z_end_m, k.nu, k.r_s, k.z_s, k.r_r,
                             k.z_r, k.nk, k.ml_star, k.z_star, k.num, k.gap, k.coef, k.s_gap, x, w)


GEOMETRIES = [
    # nu, rs, ts, zs, rr, tr, zr, soft: a prism edge monostatic and bistatic, near grazing, a
    # receiver on a reflection boundary (nu phi = 2 pi: the apex model's zero term), soft
    (np.pi / (5 * np.pi / 3), 2.0, 5 * np.pi / 6, 1.5, 2.0, 5 * np.pi / 6, 1.5, False),
    (np.pi / (5 * np.pi / 3), 1.0, 1.0, 1.5, 0.7, 2.5, 1.8, False),
    (np.pi / (5 * np.pi / 3), 0.5, 0.05, 1.3, 1.5, 4.9, 1.6, True),
    (np.pi / (3 * np.pi / 2), 0.8, 0.3, 0.4, 0.9, np.pi + 0.3 - 0.3, 0.6, False),
    (np.pi / (7 * np.pi / 4), 0.3, 2.0, -0.2, 0.4, 3.0, 1.1, True),
]


@pytest.mark.parametrize("graded", [True, False])
def test_gauss_point_kernel_matches_numpy_element_gains(graded):
    geometries = np.array([g[:7] for g in GEOMETRIES])
    nu, rs, ts, zs, rr, tr, zr = geometries.T
    soft = np.array([g[7] for g in GEOMETRIES])
    length = np.full(nu.size, 1.0)
    elements = btm.discretise_edges(length, rs, zs, rr, zr, STEP_M, 5e-3,
                                    coarsening_levels=2 if graded else 0, onset_nodes=7 if graded else 1)
    args = (nu, rs, ts, zs, rr, tr, zr, soft)
    reference = _numpy_points(elements, args)
    compiled = _kernel(elements, args)
    for want, got in zip(reference, compiled):
        assert got.shape == want.shape
        scale = np.max(np.abs(want))
        np.testing.assert_allclose(got, want, rtol=RTOL, atol=RTOL * scale)
    # the points' gains sum to the element's integral (the un-split numpy quadrature)
    whole = btm.element_gains(elements, *args)
    np.testing.assert_allclose(compiled[0].sum(axis=1), whole, rtol=1e-9, atol=1e-12 * np.max(np.abs(whole)))


@pytest.fixture(scope="module")
def thesis_tank():
    scene = builtin_scene("thesis-tank")
    prepared = prepare(scene)
    context = SolveContext.build(scene, scene.sonar, prepared.raycaster)
    return context, prepared.sharp_edges


def test_thesis_tank_rows_match_the_numpy_reference(thesis_tank, monkeypatch):
    context, sharp = thesis_tank
    config = SolverConfig()
    captured = {}
    original = edges_module.gauss_point_gains

    def spy(pair, z0, z1, *rest):
        captured["elements"] = btm.EdgeElements(pair, z0, z1, np.full(pair.size, np.nan))
        return original(pair, z0, z1, *rest)

    monkeypatch.setattr(edges_module, "gauss_point_gains", spy)
    rows = edges_module.edge_paths(context, config, sharp)
    assert rows.size > 10_000  # the thesis tank's pose: some 16 000 rows
    # the numpy reference on the same visible elements
    rows_ref_args = _reference_inputs(context, sharp)
    elements = captured["elements"]
    gains2, z2, path2 = _numpy_points(elements, rows_ref_args["args"])
    pair = np.repeat(elements.pair, 2)
    reference = _numpy_rows(pair, gains2.reshape(-1), path2.reshape(-1), z2.reshape(-1), **rows_ref_args["fill"])
    assert reference.shape == rows.shape
    for name in reference.dtype.names:
        want, got = reference[name], rows[name]
        if np.issubdtype(want.dtype, np.floating):
            np.testing.assert_allclose(got, want, rtol=RTOL, atol=RTOL * np.nanmax(np.abs(want)), equal_nan=True,
                                       err_msg=name)
        else:
            np.testing.assert_array_equal(got, want, err_msg=name)


def _reference_inputs(context, sharp):
    """The per-pair arrays edge_paths builds before the elements (recomputed as it does)."""
    edges = edges_module.diffracting_edges(sharp, context)
    n_edges = len(edges)
    tx = np.asarray(context.transmitter_m, dtype=float)
    rx = np.asarray(context.receivers_m, dtype=float)
    n_rx = rx.shape[0]
    r_s, th_s, z_s = edges.local_coordinates(np.broadcast_to(tx, (n_edges, 3)))
    pair_edge = np.repeat(np.arange(n_edges), n_rx)
    pair_rx = np.tile(np.arange(n_rx), n_edges)
    r_r, th_r, z_r = edges.select(pair_edge).local_coordinates(rx[pair_rx])
    theta_w = edges.wedge_angle_rad[pair_edge]
    ok = (
        (r_s[pair_edge] > 1e-6) & (r_r > 1e-6) & (th_s[pair_edge] <= theta_w + 1e-12) & (th_r <= theta_w + 1e-12)
    )
    pair_edge, pair_rx, r_r, th_r, z_r = pair_edge[ok], pair_rx[ok], r_r[ok], th_r[ok], z_r[ok]
    args = (edges.nu[pair_edge], r_s[pair_edge], th_s[pair_edge], z_s[pair_edge], r_r, th_r, z_r,
            edges.pressure_release[pair_edge])
    fill = dict(pair_edge=pair_edge, pair_rx=pair_rx, chain=edges.chain, surface=edges.surface,
                start=edges.start_m, direction=edges.direction, tx=tx, rx=rx,
                first_path_id=context.first_path_id)
    return {"args": args, "fill": fill}
