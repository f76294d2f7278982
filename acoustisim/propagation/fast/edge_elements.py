"""The discretisation of :mod:`acoustisim.propagation.reference.edge_elements`, compiled.

:func:`discretise_edges` returns the reference's elements (the same values: every operation is
the reference's, in its order), with the per-branch work in two compiled loops: the branches'
ends and path lengths (:func:`branch_ends`), then each branch's nodes, their spheroid roots
and the elements between them, split to the length cap (:func:`branch_elements`). The graded
grid's intervals and the onset nodes come from the reference's numpy (per branch, a few
hundred of them). numba, cached on disk, GIL released; no ``fastmath`` (it would reorder sums).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit
from numpy.typing import NDArray

from acoustisim.propagation.reference.edge_elements import (
    Branches,
    Discretisation,
    EdgeElements,
    GradedIntervals,
    PairGeometry,
    check_discretisation,
    graded_intervals,
    onset_offsets,
)


@njit(cache=True, nogil=True, error_model="numpy")
def _path_length(z: float, r_s: float, z_s: float, r_r: float, z_r: float) -> float:
    return math.hypot(r_s, z - z_s) + math.hypot(r_r, z - z_r)


@njit(cache=True, nogil=True, error_model="numpy")
def _spheroid_root(d: float, r_s: float, z_s: float, r_r: float, z_r: float, upper: bool) -> float:
    """The reference's ``spheroid_root`` of one node."""
    mid = 0.5 * (z_s + z_r)
    zs, zr = z_s - mid, z_r - mid
    a1 = -2.0 * (zr - zs)
    a0 = d * d + r_r * r_r - r_s * r_s + zr * zr - zs * zs
    qa = 4.0 * d * d - a1 * a1
    qb = -(8.0 * d * d * zr + 2.0 * a0 * a1)
    qc = 4.0 * d * d * (r_r * r_r + zr * zr) - a0 * a0
    disc = math.sqrt(max(qb * qb - 4.0 * qa * qc, 0.0))
    root = ((-qb + disc) if upper else (-qb - disc)) / (2.0 * qa)
    return root + mid


@njit(cache=True, nogil=True, error_model="numpy")
def branch_ends(geometry: PairGeometry, grid: Discretisation) -> tuple[Branches, float]:
    """The reference's ``branches`` and ``element_count_bound``, in one loop over the pairs."""
    p = geometry.length_m.size
    nb = 2 * p
    pair = np.empty(nb, dtype=np.int64)
    upper = np.empty(nb, dtype=np.bool_)
    start_z = np.empty(nb)
    end_z = np.empty(nb)
    start_path = np.empty(nb)
    end_path = np.empty(nb)
    span = np.empty(nb)
    has_length = np.empty(nb, dtype=np.bool_)
    joint_start = np.zeros(nb, dtype=np.bool_)
    start_steps = np.zeros(nb)
    step = grid.path_step_m
    coarse_step = step * 2.0**grid.coarsening_levels
    graded = grid.coarsening_levels > 0
    bound = 0.0
    for k in range(p):
        length = geometry.length_m[k]
        rs, zs, rr, zr = geometry.r_s[k], geometry.z_s[k], geometry.r_r[k], geometry.z_r[k]
        z_star = zs + (zr - zs) * rs / (rs + rr)
        z_apex = min(max(z_star, 0.0), length)
        apex_path = math.hypot(rs + rr, zr - zs)
        for side in range(2):
            b = 2 * k + side
            start = z_apex
            end = length if side == 1 else 0.0
            d_start = _path_length(start, rs, zs, rr, zr)
            d_end = _path_length(end, rs, zs, rr, zr)
            pair[b], upper[b] = k, side == 1
            start_z[b], end_z[b], start_path[b], end_path[b] = start, end, d_start, d_end
            span[b] = max(d_end - d_start, 0.0)
            has_length[b] = abs(end - start) > 0.0
            coarse = np.ceil(span[b] / coarse_step) if has_length[b] else 0.0
            bound += max(coarse, np.ceil(abs(end - start) / grid.max_element_m))
            if graded:
                if side == 1:
                    joint = (z_star < 0.0) & geometry.open_start[k]
                else:
                    joint = (z_star > length) & geometry.open_end[k]
                joint_start[b] = joint
                if joint:
                    start_steps[b] = (d_start - apex_path) / step
    return Branches(pair, upper, start_z, end_z, start_path, end_path, span, has_length, joint_start,
                    start_steps), bound


@njit(cache=True, nogil=True, error_model="numpy")
def branch_elements(geometry: PairGeometry, branch: Branches, intervals: GradedIntervals,
                    onsets: NDArray[np.float64], onset_wanted: NDArray[np.bool_], grid: Discretisation
                    ) -> EdgeElements:
    """The reference's ``branch_nodes`` and the elements between them, per branch.

    ``onsets`` (o,) and ``onset_wanted`` (nb, o) are the reference's ``onset_offsets``.
    """
    nb = branch.has_length.size
    q = intervals.spacing.size
    n_onsets = onsets.size
    step = grid.path_step_m
    # nodes of every branch: grid offset 0, the onset nodes, the rest of the grid, the end
    n_nodes = np.zeros(nb, dtype=np.int64)
    for b in range(nb):
        if branch.has_length[b]:
            count = 1
            for i in range(q):
                count += intervals.count[b, i]
            for o in range(n_onsets):
                if onset_wanted[b, o]:
                    count += 1
            n_nodes[b] = count
    total = 0
    for b in range(nb):
        total += n_nodes[b]
    node_z = np.empty(total)
    node_path = np.empty(total)
    node_offset = np.empty(total)
    at = 0
    for b in range(nb):
        if not branch.has_length[b]:
            continue
        k = branch.pair[b]
        first_at = at
        for i in range(q):
            for j in range(intervals.count[b, i]):
                node_offset[at] = (intervals.first[b, i] + j) * intervals.spacing[i] * step
                at += 1
                if at == first_at + 1:  # the onset nodes follow the branch's start
                    for o in range(n_onsets):
                        if onset_wanted[b, o]:
                            node_offset[at] = onsets[o]
                            at += 1
        node_offset[at] = branch.span[b]
        at += 1
        last_at = at - 1
        lowest = min(branch.start_z[b], branch.end_z[b])
        highest = max(branch.start_z[b], branch.end_z[b])
        for m in range(first_at, at):
            d = branch.start_path[b] + node_offset[m]
            z = _spheroid_root(d, geometry.r_s[k], geometry.z_s[k], geometry.r_r[k], geometry.z_r[k], branch.upper[b])
            if m == first_at:
                z, d = branch.start_z[b], branch.start_path[b]
            elif m == last_at:
                z, d = branch.end_z[b], branch.end_path[b]
            node_z[m] = min(max(z, lowest), highest)
            node_path[m] = d
    # elements between consecutive nodes, split to the (growing) length cap
    pieces = np.ones(max(total - 1, 0), dtype=np.int64)
    bound = 0
    at = 0
    for b in range(nb):
        for m in range(at, at + n_nodes[b] - 1):
            za, zb = node_z[m], node_z[m + 1]
            cap = grid.max_element_m
            if grid.cap_growth > 0.0:
                apex = branch.start_z[b]
                cap = grid.max_element_m + grid.cap_growth * min(abs(za - apex), abs(zb - apex))
            pieces[m] = max(np.int64(math.ceil(abs(zb - za) / cap)), 1)
            bound += pieces[m]
        at += n_nodes[b]
    pair = np.empty(bound, dtype=np.int64)
    z_start = np.empty(bound)
    z_end = np.empty(bound)
    mean_path = np.empty(bound)
    i = 0
    at = 0
    for b in range(nb):
        k = branch.pair[b]
        rs, zs, rr, zr = geometry.r_s[k], geometry.z_s[k], geometry.r_r[k], geometry.z_r[k]
        for m in range(at, at + n_nodes[b] - 1):
            za, zb = node_z[m], node_z[m + 1]
            n = pieces[m]
            for j in range(n):
                z0 = za + (zb - za) * (j / n)
                z1 = za + (zb - za) * ((j + 1) / n)
                if z1 == z0:
                    continue
                pair[i] = k
                z_start[i] = min(z0, z1)
                z_end[i] = max(z0, z1)
                d0 = _path_length(z0, rs, zs, rr, zr) if n > 1 and j > 0 else node_path[m]
                d1 = _path_length(z1, rs, zs, rr, zr) if n > 1 and j < n - 1 else node_path[m + 1]
                mean_path[i] = 0.5 * (d0 + d1)
                i += 1
        at += n_nodes[b]
    return EdgeElements(pair[:i].copy(), z_start[:i].copy(), z_end[:i].copy(), mean_path[:i].copy())


def discretise_edges(geometry: PairGeometry, grid: Discretisation) -> EdgeElements:
    """The reference's :func:`~acoustisim.propagation.reference.edge_elements.discretise_edges`.

    Raises
    ------
    ValueError
        As the reference.
    """
    check_discretisation(grid)
    geometry, grid = geometry.as_arrays(), grid.as_numbers()
    branch, bound = branch_ends(geometry, grid)
    if bound > grid.max_elements:
        raise ValueError(f"the edges need at least {bound:.3g} elements (limit {grid.max_elements:.0f})")
    span_steps = np.where(branch.has_length, np.maximum(branch.span / grid.path_step_m, 0.5), 0.0)
    intervals = graded_intervals(span_steps, branch.has_length, branch.start_steps, grid)
    onsets, wanted = onset_offsets(branch, grid)
    return branch_elements(geometry, branch, intervals, onsets, wanted, grid)


__all__ = ("branch_elements", "branch_ends", "discretise_edges")
