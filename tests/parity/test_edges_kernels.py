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
from numpy.typing import ArrayLike, NDArray

from acoustisim.propagation import SolverConfig, btm, prepare
from acoustisim.propagation import edges as edges_module
from acoustisim.propagation.context import SolveContext
from acoustisim.propagation.edge_kernels import gauss_point_gains
from acoustisim.propagation.paths import PathKind, empty_paths_array
from scenes.builtin import builtin_scene

C = 1482.38
STEP_M = C / (16 * 500e3)
RTOL = 1e-12  # see the module docstring


# --- the numpy reference of before the kernels (verbatim but for the module prefixes) ---


def _group_arange(counts: NDArray[np.int64]) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """(group index, index within group) for groups of the given sizes, flattened."""
    group = np.repeat(np.arange(counts.size), counts)
    starts = np.cumsum(counts) - counts
    return group, np.arange(group.size) - starts[group]


def _graded_offsets(span_steps, has, levels, grading, start_steps=None):
    """The former expansion of the graded grid into (branch, offset) node arrays."""
    nb = span_steps.size
    first, count, dd = btm._graded_intervals(span_steps, has, levels, grading, start_steps)
    interval, k = _group_arange(count.reshape(-1))
    offset = (first.reshape(-1)[interval] + k) * np.tile(dd, nb)[interval]
    return interval // dd.size, offset


def _solve_on_spheroid(
    path_m: NDArray[np.float64],
    r_s: NDArray[np.float64],
    z_s: NDArray[np.float64],
    r_r: NDArray[np.float64],
    z_r: NDArray[np.float64],
    upper: NDArray[np.bool_],
) -> NDArray[np.float64]:
    """z on the edge line where m + l = ``path_m`` (upper or lower root).

    Squaring ``2 D l = D^2 + l^2 - m^2`` (right side linear in z) gives a quadratic in z whose
    two roots are both genuine because ``|m - l| <= |S - R| < D``.
    """
    d = path_m
    # work relative to the apex-free midpoint to keep the coefficients small
    mid = 0.5 * (z_s + z_r)
    zs, zr = z_s - mid, z_r - mid
    a1 = -2.0 * (zr - zs)
    a0 = d * d + r_r * r_r - r_s * r_s + zr * zr - zs * zs
    qa = 4.0 * d * d - a1 * a1
    qb = -(8.0 * d * d * zr + 2.0 * a0 * a1)
    qc = 4.0 * d * d * (r_r * r_r + zr * zr) - a0 * a0
    disc = np.sqrt(np.maximum(qb * qb - 4.0 * qa * qc, 0.0))
    root = np.where(upper, (-qb + disc), (-qb - disc)) / (2.0 * qa)
    return root + mid


def numpy_discretise_edges(
    length_m: ArrayLike,
    r_s: ArrayLike,
    z_s: ArrayLike,
    r_r: ArrayLike,
    z_r: ArrayLike,
    path_step_m: float,
    max_element_m: float,
    max_elements: int | None = None,
    *,
    coarsening_levels: int = 0,
    grading: int = 4,
    cap_growth: float = 0.0,
    onset_nodes: int = 1,
    path_lengths: bool = True,
    open_start: ArrayLike | None = None,
    open_end: ArrayLike | None = None,
) -> btm.EdgeElements:
    """The numpy discretisation of before the kernel (see btm.discretise_edges)."""
    if not (path_step_m > 0.0 and max_element_m > 0.0):
        raise ValueError(f"path_step_m and max_element_m must be > 0, got {path_step_m!r}, {max_element_m!r}")
    if coarsening_levels < 0 or grading < 1:
        raise ValueError(f"coarsening_levels must be >= 0 and grading >= 1, got {coarsening_levels!r}, {grading!r}")
    length, rs, zs, rr, zr = (np.atleast_1d(np.asarray(v, dtype=float)) for v in (length_m, r_s, z_s, r_r, z_r))
    p = length.size
    z_star, _ = btm.least_time(rs, zs, rr, zr)
    z_apex = np.clip(z_star, 0.0, length)

    def path(z: NDArray[np.float64], idx: NDArray[np.int64]) -> NDArray[np.float64]:
        return np.hypot(rs[idx], z - zs[idx]) + np.hypot(rr[idx], z - zr[idx])

    pairs = np.arange(p)
    # branch 0 runs from the apex down to z = 0, branch 1 from the apex up to z = L
    b_pair = np.repeat(pairs, 2)
    b_upper = np.tile(np.array([False, True]), p)
    b_end = np.where(b_upper, length[b_pair], 0.0)
    b_start = z_apex[b_pair]
    d_start = path(b_start, b_pair)
    d_end = path(b_end, b_pair)
    span = np.maximum(d_end - d_start, 0.0)
    has = np.abs(b_end - b_start) > 0.0
    # onset nodes: btm.ONSET_FRACTION step, then (graded) doubling up to half a step
    onsets = btm.ONSET_FRACTION * path_step_m * 2.0 ** np.arange(onset_nodes)
    onsets = onsets[onsets < path_step_m]
    if max_elements is not None:
        # a lower bound on the element count before allocating: the graded nodes (at least
        # span / (2^J step)), and the length cap
        n_graded = np.where(has, np.ceil(span / (path_step_m * 2.0**coarsening_levels)), 0.0)
        cap_count = np.ceil(np.abs(b_end - b_start) / max_element_m)
        estimate = float(np.sum(np.maximum(n_graded, cap_count)))
        if estimate > max_elements:
            raise ValueError(f"the edges need at least {estimate:.3g} elements (limit {max_elements})")
    # nodes of each branch: its start (offset 0), the onset node, the graded grid nodes below
    # the span, and its end
    # (a branch with a zero span, up to round-off, still gets its start node)
    span_steps = np.where(has, np.maximum(span / path_step_m, 0.5), 0.0)
    start_steps = None
    joint_start = np.zeros(2 * p, dtype=bool)
    if coarsening_levels > 0 and (open_start is not None or open_end is not None):
        o_start = np.broadcast_to(np.asarray(False if open_start is None else open_start, dtype=bool), (p,))
        o_end = np.broadcast_to(np.asarray(False if open_end is None else open_end, dtype=bool), (p,))
        # branch 0 starts at z = L when the apex lies beyond L, branch 1 at z = 0 when the apex
        # lies before 0. (Not refining towards a joint at a branch's end as well would save
        # another 5 % of the thesis tank's rows, but it costs 7 dB of band-limited accuracy on
        # its polygonal pipe rim, where neighbouring segments' integrands differ at the joint.)
        joint_start = np.where(b_upper, ((z_star < 0.0) & o_start)[b_pair], ((z_star > length) & o_end)[b_pair])
        _, d_line = btm.least_time(rs, zs, rr, zr)
        start_steps = np.where(joint_start, (d_start - d_line[b_pair]) / path_step_m, 0.0)
    grid_branch, grid_offset = _graded_offsets(span_steps, has, coarsening_levels, grading, start_steps)
    # per branch, the onset nodes below its span, after its start (m = 0)
    # (only the first where the branch starts at a joint: no singularity there)
    wanted = (onsets[None, :] < span[:, None]) & (~joint_start[:, None] | (np.arange(onsets.size) == 0)[None, :])
    onset_branch, i_onset = np.nonzero(has[:, None] & wanted)
    onset_at = np.searchsorted(grid_branch, onset_branch) + 1
    ends_at = np.searchsorted(grid_branch, np.flatnonzero(has), side="right")
    # np.insert places equal indices in the given order: a branch's onset nodes before its end
    node_branch = np.insert(grid_branch, np.r_[onset_at, ends_at], np.r_[onset_branch, np.flatnonzero(has)])
    node_d_off = np.insert(grid_offset * path_step_m, np.r_[onset_at, ends_at], np.r_[onsets[i_onset], span[has]])
    n_nodes = np.bincount(node_branch, minlength=2 * p)
    _, k = _group_arange(n_nodes)
    last = k == n_nodes[node_branch] - 1
    node_d = d_start[node_branch] + node_d_off
    bp = b_pair[node_branch]
    node_z = _solve_on_spheroid(node_d, rs[bp], zs[bp], rr[bp], zr[bp], b_upper[node_branch])
    node_z = np.where(k == 0, b_start[node_branch], np.where(last, b_end[node_branch], node_z))
    # keep the roots on their own branch (round-off near the apex)
    node_z = np.where(
        b_upper[node_branch],
        np.clip(node_z, b_start[node_branch], b_end[node_branch]),
        np.clip(node_z, b_end[node_branch], b_start[node_branch]),
    )
    node_d = np.where(k == 0, d_start[node_branch], np.where(last, d_end[node_branch], node_d))
    # elements between consecutive nodes of a branch
    start_node = np.flatnonzero(~last)  # every node but a branch's last starts an element
    e_branch = node_branch[start_node]
    za, zb = node_z[start_node], node_z[start_node + 1]
    da, db = node_d[start_node], node_d[start_node + 1]
    # split long elements evenly; the cap grows with the distance from the apex
    cap = max_element_m
    if cap_growth > 0.0:
        cap = max_element_m + cap_growth * np.minimum(np.abs(za - b_start[e_branch]), np.abs(zb - b_start[e_branch]))
    n_sub = np.maximum(np.ceil(np.abs(zb - za) / cap).astype(np.int64), 1)
    parent, j = _group_arange(n_sub)
    frac0 = j / n_sub[parent]
    frac1 = (j + 1) / n_sub[parent]
    z0 = za[parent] + (zb[parent] - za[parent]) * frac0
    z1 = za[parent] + (zb[parent] - za[parent]) * frac1
    sub_pair = b_pair[e_branch[parent]]
    split = n_sub[parent] > 1
    keep = z1 != z0
    lo, hi, sub_pair = np.minimum(z0, z1)[keep], np.maximum(z0, z1)[keep], sub_pair[keep]
    if path_lengths:
        d0 = np.where(split & (j > 0), path(z0, b_pair[e_branch[parent]]), da[parent])
        d1 = np.where(split & (j < n_sub[parent] - 1), path(z1, b_pair[e_branch[parent]]), db[parent])
        mean_path = (0.5 * (d0 + d1))[keep]
    else:
        mean_path = np.full(lo.size, np.nan)
    return btm.EdgeElements(sub_pair, lo, hi, mean_path)


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


def _kernel(elements, args, whole=False):
    k = btm.pair_constants(*args)
    x, w = btm.gauss_rule(2)
    return gauss_point_gains(elements.pair, elements.z_start_m, elements.z_end_m, k.nu, k.r_s, k.z_s, k.r_r,
                             k.z_r, k.nk, k.ml_star, k.z_star, k.num, k.gap, k.coef, k.s_gap, x, w, whole)


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
    # and one gain per element (the fine discretisation's rows) is the numpy quadrature's
    one = _kernel(elements, args, whole=True)
    assert one[0].shape == (elements.pair.size, 1) and one[1].shape == (elements.pair.size, 0)
    np.testing.assert_allclose(one[0][:, 0], whole, rtol=RTOL, atol=RTOL * np.max(np.abs(whole)))


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


def _assert_same_elements(got, want):
    np.testing.assert_array_equal(got.pair, want.pair)
    for name in ("z_start_m", "z_end_m", "path_length_m"):
        a, b = getattr(got, name), getattr(want, name)
        np.testing.assert_allclose(a, b, rtol=RTOL, atol=0.0, equal_nan=True, err_msg=name)


@pytest.mark.parametrize(
    "options",
    [
        {},  # the fine discretisation
        {"coarsening_levels": 2, "grading": 4, "cap_growth": 0.1, "onset_nodes": 7, "path_lengths": False},
        {"coarsening_levels": 3, "grading": 2, "onset_nodes": 7},
        {"coarsening_levels": 2, "grading": 4, "cap_growth": 0.1, "onset_nodes": 7,
         "open_start": [True, False, True, True, False], "open_end": [True, True, False, True, True]},
    ],
)
def test_discretisation_kernel_matches_the_numpy_reference(options):
    geometries = np.array([g[:7] for g in GEOMETRIES])
    _, rs, _, zs, rr, _, zr = geometries.T
    # lengths putting the apex inside, before 0 (zs, zr < 0 for none: shift) and beyond the end
    length = np.array([3.0, 1.0, 1.2, 0.3, 0.05])
    zs, zr = zs - np.array([0.0, 0.0, 0.0, 0.7, 0.0]), zr - np.array([0.0, 0.0, 0.0, 0.7, 0.0])
    for cap in (5e-4, 5e-3):
        got = btm.discretise_edges(length, rs, zs, rr, zr, STEP_M, cap, **options)
        want = numpy_discretise_edges(length, rs, zs, rr, zr, STEP_M, cap, **options)
        assert got.pair.size > 100
        _assert_same_elements(got, want)


def test_thesis_tank_discretisation_matches_the_numpy_reference(thesis_tank, monkeypatch):
    context, sharp = thesis_tank
    calls = []
    original = edges_module.discretise_edges

    def spy(*args, **kwargs):
        calls.append((args, kwargs))
        return original(*args, **kwargs)

    monkeypatch.setattr(edges_module, "discretise_edges", spy)
    for adaptive in (True, False):
        edges_module.edge_paths(context, SolverConfig(edge_adaptive=adaptive), sharp)
    assert len(calls) == 2
    for args, kwargs in calls:
        _assert_same_elements(original(*args, **kwargs), numpy_discretise_edges(*args, **kwargs))


def test_thesis_tank_fine_gains_match_the_numpy_reference(thesis_tank, monkeypatch):
    context, sharp = thesis_tank
    captured = {}
    original = edges_module.gauss_point_gains

    def spy(pair, z0, z1, *rest):
        captured["elements"] = btm.EdgeElements(pair, z0, z1, np.full(pair.size, np.nan))
        captured["result"] = original(pair, z0, z1, *rest)
        return captured["result"]

    monkeypatch.setattr(edges_module, "gauss_point_gains", spy)
    edges_module.edge_paths(context, SolverConfig(edge_adaptive=False), sharp)
    want = btm.element_gains(captured["elements"], *_reference_inputs(context, sharp)["args"])
    got = captured["result"][0][:, 0]
    assert want.size > 10_000
    np.testing.assert_allclose(got, want, rtol=RTOL, atol=RTOL * np.max(np.abs(want)))


def test_prepared_diffracting_edges_give_the_same_rows():
    """The per-scene set-up kept in the PreparedScene (diffracting edges, lengths, wedge indices,
    chain joints, probe offsets) gives the rows of the per-pose set-up from the sharp edges,
    byte for byte, over poses."""
    from dataclasses import replace

    prepared = prepare(builtin_scene("thesis-tank"))
    config = SolverConfig()
    for position in ((0.5, 1.5, 0.5), (2.0, 1.2, 0.3), (4.0, 2.5, 0.7)):
        sonar = replace(prepared.scene.sonar, position_m=position)
        context = SolveContext.build(prepared.scene, sonar, prepared.raycaster)
        cached = edges_module.edge_paths(context, config, prepared.diffracting_edges)
        fresh = edges_module.edge_paths(context, config, prepared.sharp_edges)
        assert cached.size > 1000 and cached.tobytes() == fresh.tobytes()
    assert prepared.diffracting_edges is prepared.diffracting_edges  # built once
