"""Discretisation of the BTM line integral: edges cut into elements of graded delay steps.

Physics
-------
The integrand of the BTM line integral (:mod:`.btm`, equation (1)) is a delta in time at the
path length m + l of each point z of the edge. The path length is least at the apex z*
(where h(t) starts, with a 1 / sqrt(t - tau0) singularity) and grows monotonically along the
two branches z < z* and z > z*; a point of path length d lies on the prolate spheroid
m + l = d with foci at the source and the receiver. What a band-limited echo needs of a
discretisation is that neighbouring impulses differ in delay by well under a period of the
band's highest frequency (``physics.md`` section 4); the integrand's weight varies slowly except
near the apex.

Method
------
Each (edge, receiver) pair's edge is split at the apex (clipped to the edge) into two
branches. Nodes are placed at equal *path-length* increments along each branch, so that
neighbouring elements differ in delay by one step whatever their length: node k of a branch
starting at path length d0 is the root on that branch of m + l = d0 + k step, a quadratic in z
(squaring 2 D l = D^2 + l^2 - m^2, right side linear in z: both roots are genuine since
|m - l| <= |S - R| < D). Elements are the intervals between consecutive nodes, split evenly
where longer than a length cap.

* Fine discretisation (``coarsening_levels = 0``): a node every step.
* Graded discretisation (``coarsening_levels = J > 0``): a node m steps from the branch's
  start belongs to level j = min(J, the largest j with grading 2^j <= min(m0 + m, span - m))
  and is kept when m is a multiple of 2^j; elements are one step long within ``grading`` steps
  of either end of the branch and double every ``grading`` elements away from both, up to 2^J
  steps, every node on the uniform grid (:func:`graded_intervals`). m0 counts the steps from
  the apex of the edge's line to a branch starting at a *joint* of a polygonal chain (an edge
  continuing into its neighbour, its apex beyond that end), where the summed response has no
  step and so needs no refinement; elsewhere m0 = 0.
* Onset nodes: between a branch's start and its first step, nodes at 1/128, 1/64, ..., 1/2 of
  a step (``onset_nodes`` of them, the first only at a joint), so that the elements resolve
  the onset's singularity geometrically and the earliest element's delay is the least time
  to within a nanosecond.
* The length cap is ``max_element_m + cap_growth d``, d the element's distance from the apex
  along the edge.

Accuracy
--------
The nodes are exact roots (to float64 rounding) and the elements tile each edge exactly; the
discretisation's effect on the echo is that of the quadrature on these elements, measured
against a four times finer uniform reference in :mod:`.edges`.
"""

from __future__ import annotations

import math
from typing import Any, NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

ONSET_FRACTION = 1.0 / 128.0
"""The first onset node's offset from a branch's start, as a fraction of the step."""


class PairGeometry(NamedTuple):
    """Per (edge, receiver) pair, shape (p,) each: the edge from z = 0 to ``length_m`` and the
    source's and receiver's coordinates ``r_s, z_s, r_r, z_r`` (m, r > 0) in its frame;
    ``open_start`` (``open_end``): the edge continues past z = 0 (z = L) into a neighbour of its
    chain that is diffracted too (a joint)."""

    length_m: NDArray[np.float64]
    r_s: NDArray[np.float64]
    z_s: NDArray[np.float64]
    r_r: NDArray[np.float64]
    z_r: NDArray[np.float64]
    open_start: NDArray[np.bool_]
    open_end: NDArray[np.bool_]

    def as_arrays(self) -> "PairGeometry":
        """The same pairs as C-contiguous float64 (bool) arrays of one shape (p,) (scalars and
        sequences broadcast; arrays that are so already are kept)."""
        p = np.size(self.length_m)

        def column(value: ArrayLike, dtype: type) -> NDArray[Any]:
            array = np.asarray(value, dtype=dtype)
            if array.shape == (p,) and array.flags.c_contiguous:
                return array
            return np.ascontiguousarray(np.broadcast_to(array, (p,)))

        return PairGeometry(*(column(v, float) for v in (self.length_m, self.r_s, self.z_s, self.r_r, self.z_r)),
                            column(self.open_start, bool), column(self.open_end, bool))


class Discretisation(NamedTuple):
    """How edges are cut (see the module's Method).

    Attributes
    ----------
    path_step_m : float
        The fine path-length (m + l) step between neighbouring nodes (m): the delay step times c.
    max_element_m : float
        The length cap at the apex (m).
    coarsening_levels : int
        J: elements grow up to 2^J steps (0: the fine discretisation).
    grading : int
        Elements per doubling (>= 1).
    cap_growth : float
        Growth of the length cap per metre from the apex.
    onset_nodes : int
        Nodes below one step after a branch's start.
    max_elements : float
        Refuse (``ValueError``) to make more elements than this.
    """

    path_step_m: float
    max_element_m: float
    coarsening_levels: int = 0
    grading: int = 4
    cap_growth: float = 0.0
    onset_nodes: int = 1
    max_elements: float = math.inf

    def as_numbers(self) -> "Discretisation":
        """The same parameters as Python floats and ints."""
        return Discretisation(float(self.path_step_m), float(self.max_element_m), int(self.coarsening_levels),
                              int(self.grading), float(self.cap_growth), int(self.onset_nodes),
                              float(self.max_elements))


class EdgeElements(NamedTuple):
    """Elements of discretised edges, one row each, ordered by pair, then branch (from the apex
    down to z = 0, then up to z = L), then outwards from the apex.

    ``pair`` (int64) the (edge, receiver) pair each belongs to, ``z_start_m < z_end_m`` its ends
    along the edge (m), ``path_length_m`` the mean of its ends' path lengths m + l (m).
    """

    pair: NDArray[np.int64]
    z_start_m: NDArray[np.float64]
    z_end_m: NDArray[np.float64]
    path_length_m: NDArray[np.float64]

    def select(self, mask: NDArray[np.bool_]) -> "EdgeElements":
        """The elements where ``mask`` is true."""
        return EdgeElements(self.pair[mask], self.z_start_m[mask], self.z_end_m[mask], self.path_length_m[mask])


class Branches(NamedTuple):
    """The two branches of every pair, branch 2 k from pair k's apex down to z = 0, branch
    2 k + 1 up to z = L, shape (2 p,) each.

    ``pair``, ``upper`` (z increasing from the apex), ``start_z``, ``end_z`` (m), their path
    lengths ``start_path``, ``end_path`` (m), ``span`` the path-length span (m, >= 0),
    ``has_length`` whether start and end differ, ``joint_start`` whether the branch starts at a
    joint, ``start_steps`` the steps m0 from the line's apex to a joint start (0 elsewhere).
    """

    pair: NDArray[np.int64]
    upper: NDArray[np.bool_]
    start_z: NDArray[np.float64]
    end_z: NDArray[np.float64]
    start_path: NDArray[np.float64]
    end_path: NDArray[np.float64]
    span: NDArray[np.float64]
    has_length: NDArray[np.bool_]
    joint_start: NDArray[np.bool_]
    start_steps: NDArray[np.float64]


def check_discretisation(grid: Discretisation) -> None:
    """Raise ``ValueError`` for non-positive steps or caps, J < 0 or grading < 1."""
    if not (grid.path_step_m > 0.0 and grid.max_element_m > 0.0):
        raise ValueError(f"path_step_m and max_element_m must be > 0, got {grid.path_step_m!r}, {grid.max_element_m!r}")
    if grid.coarsening_levels < 0 or grid.grading < 1:
        raise ValueError(f"coarsening_levels must be >= 0 and grading >= 1, got {grid.coarsening_levels!r}, "
                         f"{grid.grading!r}")


def path_length(z: NDArray[np.float64], r_s: NDArray[np.float64], z_s: NDArray[np.float64],
                r_r: NDArray[np.float64], z_r: NDArray[np.float64]) -> NDArray[np.float64]:
    """m + l at points z of the edge (m)."""
    return np.hypot(r_s, z - z_s) + np.hypot(r_r, z - z_r)


def spheroid_root(path_m: NDArray[np.float64], r_s: NDArray[np.float64], z_s: NDArray[np.float64],
                  r_r: NDArray[np.float64], z_r: NDArray[np.float64], upper: NDArray[np.bool_]) -> NDArray[np.float64]:
    """z on the edge line where m + l = ``path_m`` (m): the root above the apex where ``upper``,
    below it elsewhere (coordinates taken about the foci's mid-height, to keep the
    coefficients small)."""
    d = path_m
    mid = 0.5 * (z_s + z_r)
    zs, zr = z_s - mid, z_r - mid
    a1 = -2.0 * (zr - zs)
    a0 = d * d + r_r * r_r - r_s * r_s + zr * zr - zs * zs
    qa = 4.0 * d * d - a1 * a1
    qb = -(8.0 * d * d * zr + 2.0 * a0 * a1)
    qc = 4.0 * d * d * (r_r * r_r + zr * zr) - a0 * a0
    disc = np.sqrt(np.maximum(qb * qb - 4.0 * qa * qc, 0.0))
    return np.where(upper, (-qb + disc), (-qb - disc)) / (2.0 * qa) + mid


def branches(geometry: PairGeometry, grid: Discretisation) -> Branches:
    """The branches of every pair (see :class:`Branches`; ``geometry`` as arrays)."""
    length, rs, zs, rr, zr = geometry.length_m, geometry.r_s, geometry.z_s, geometry.r_r, geometry.z_r
    p = length.size
    pair = np.repeat(np.arange(p), 2)
    upper = np.tile(np.array([False, True]), p)
    z_star = zs + (zr - zs) * rs / (rs + rr)
    start = np.clip(z_star, 0.0, length)[pair]
    end = np.where(upper, length[pair], 0.0)
    start_path = path_length(start, rs[pair], zs[pair], rr[pair], zr[pair])
    end_path = path_length(end, rs[pair], zs[pair], rr[pair], zr[pair])
    # a branch starts at a joint when its apex lies beyond the edge's end it starts from
    graded = grid.coarsening_levels > 0
    joint_start = graded & np.where(upper, ((z_star < 0.0) & geometry.open_start)[pair],
                                    ((z_star > length) & geometry.open_end)[pair])
    apex_path = np.hypot(rs + rr, zr - zs)[pair]
    start_steps = np.where(joint_start, (start_path - apex_path) / grid.path_step_m, 0.0)
    return Branches(pair, upper, start, end, start_path, end_path, np.maximum(end_path - start_path, 0.0),
                    np.abs(end - start) > 0.0, joint_start, start_steps)


def element_count_bound(branch: Branches, grid: Discretisation) -> float:
    """A lower bound on the element count (the coarsest nodes or the length cap, per branch),
    counted in floating point so that an absurd cap gives a huge number, not an overflow."""
    coarse = np.where(branch.has_length, np.ceil(branch.span / (grid.path_step_m * 2.0**grid.coarsening_levels)),
                      0.0)
    capped = np.ceil(np.abs(branch.end_z - branch.start_z) / grid.max_element_m)
    return float(np.sum(np.maximum(coarse, capped)))


class GradedIntervals(NamedTuple):
    """The interior nodes of every branch as intervals of the graded grid (levels 0..J from
    the branch's start, then J - 1..0 towards its end, q = 2 J + 1 intervals).

    ``first`` (nb, q): each interval's first node, in units of its spacing; ``count`` (nb, q),
    int64: its number of nodes; ``spacing`` (q,): the intervals' node spacings (steps). Node k
    of interval i of branch b lies ``(first[b, i] + k) spacing[i]`` steps from the branch's start.
    """

    first: NDArray[np.float64]
    count: NDArray[np.int64]
    spacing: NDArray[np.float64]


def graded_intervals(span_steps: NDArray[np.float64], has_length: NDArray[np.bool_], start_steps: NDArray[np.float64],
                     grid: Discretisation) -> GradedIntervals:
    """The graded grid of every branch (see the module's Method).

    Parameters
    ----------
    span_steps : ndarray, shape (nb,)
        Each branch's span in steps (>= 0.5 where it has a length).
    has_length : ndarray of bool, shape (nb,)
    start_steps : ndarray, shape (nb,)
        m0, the steps from the line's apex to the branch's start.
    grid : Discretisation
        Its ``coarsening_levels`` J and ``grading``.
    """
    levels = grid.coarsening_levels
    nb = span_steps.size
    span = np.where(has_length, span_steps, 0.0)
    j = np.arange(levels + 1)
    needed = grid.grading * (2.0**j)  # level j needs at least this many steps to both ends
    needed[0] = 0.0
    m0 = np.where(has_length, start_steps, 0.0)
    from_start = np.maximum(needed[None, :] - m0[:, None], 0.0)  # (nb, J + 1)
    from_start[:, 0] = 0.0
    from_end = np.broadcast_to(needed, (nb, levels + 1))
    none_above = np.full((nb, 1), np.inf)
    from_start_next = np.concatenate([from_start[:, 1:], none_above], axis=1)
    from_end_next = np.concatenate([from_end[:, 1:], none_above], axis=1)
    s = span[:, None]
    # level j's nodes: multiples of 2^j in [from_start_j, min(from_start_{j+1}, span - from_end_j))
    # and in [max(span - from_end_{j+1}, from_start_{j+1}), span - from_end_j), the intervals
    # ordered along the branch
    rising_lo, rising_hi = from_start, np.minimum(from_start_next, s - from_end)
    falling_lo, falling_hi = np.maximum(s - from_end_next, from_start_next), s - from_end
    lo = np.concatenate([rising_lo, falling_lo[:, ::-1][:, 1:]], axis=1)
    hi = np.concatenate([rising_hi, falling_hi[:, ::-1][:, 1:]], axis=1)
    d = 2.0**j
    spacing = np.concatenate([d, d[::-1][1:]])
    first = np.ceil(lo / spacing)
    count = np.maximum(np.ceil(hi / spacing) - first, 0.0).astype(np.int64)
    count[~has_length] = 0
    return GradedIntervals(first, count, spacing)


def onset_offsets(branch: Branches, grid: Discretisation) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
    """The onset nodes' path-length offsets from a branch's start (m), shape (o,), and which of
    them each branch gets, shape (nb, o): those below its span, only the first at a joint."""
    step = grid.path_step_m
    onsets = ONSET_FRACTION * step * 2.0 ** np.arange(grid.onset_nodes)
    onsets = onsets[onsets < step]
    wanted = (onsets[None, :] < branch.span[:, None]) & (~branch.joint_start[:, None]
                                                         | (np.arange(onsets.size) == 0)[None, :])
    return onsets, branch.has_length[:, None] & wanted


def ragged_index(counts: NDArray[np.int64]) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """For groups of the given sizes laid end to end: each item's group and index within it."""
    group = np.repeat(np.arange(counts.size), counts)
    starts = np.cumsum(counts) - counts
    return group, np.arange(group.size) - starts[group]


def branch_nodes(geometry: PairGeometry, branch: Branches, grid: Discretisation
                 ) -> tuple[NDArray[np.int64], NDArray[np.float64], NDArray[np.float64]]:
    """Every branch's nodes in order from its start: the start, the onset nodes, the graded grid,
    the end.

    Returns
    -------
    node_branch : ndarray of int64, shape (k,)
    node_z, node_path : ndarray, shape (k,)
        Position along the edge (m) and path length (m) of each node.
    """
    step = grid.path_step_m
    has = branch.has_length
    span_steps = np.where(has, np.maximum(branch.span / step, 0.5), 0.0)
    intervals = graded_intervals(span_steps, has, branch.start_steps, grid)
    interval, k = ragged_index(intervals.count.reshape(-1))
    spacing = intervals.spacing
    grid_branch = interval // spacing.size
    grid_offset = (intervals.first.reshape(-1)[interval] + k) * np.tile(spacing, has.size)[interval] * step
    onsets, wanted = onset_offsets(branch, grid)
    onset_branch, onset = np.nonzero(wanted)
    # the onset nodes go after each branch's first grid node (its start, offset 0), its end
    # after its last (np.insert places equal indices in the given order)
    onset_at = np.searchsorted(grid_branch, onset_branch) + 1
    with_length = np.flatnonzero(has)
    end_at = np.searchsorted(grid_branch, with_length, side="right")
    node_branch = np.insert(grid_branch, np.r_[onset_at, end_at], np.r_[onset_branch, with_length])
    node_offset = np.insert(grid_offset, np.r_[onset_at, end_at], np.r_[onsets[onset], branch.span[has]])
    n_nodes = np.bincount(node_branch, minlength=has.size)
    _, index = ragged_index(n_nodes)
    is_start, is_end = index == 0, index == n_nodes[node_branch] - 1
    pair = branch.pair[node_branch]
    node_path = branch.start_path[node_branch] + node_offset
    root = spheroid_root(node_path, geometry.r_s[pair], geometry.z_s[pair], geometry.r_r[pair], geometry.z_r[pair],
                         branch.upper[node_branch])
    node_z = np.where(is_start, branch.start_z[node_branch], np.where(is_end, branch.end_z[node_branch], root))
    # keep the roots on their own branch (round-off near the apex)
    lowest = np.minimum(branch.start_z, branch.end_z)[node_branch]
    highest = np.maximum(branch.start_z, branch.end_z)[node_branch]
    node_z = np.clip(node_z, lowest, highest)
    node_path = np.where(is_start, branch.start_path[node_branch],
                         np.where(is_end, branch.end_path[node_branch], node_path))
    return node_branch, node_z, node_path


def discretise_edges(geometry: PairGeometry, grid: Discretisation) -> EdgeElements:
    """Cut every pair's edge into elements (see the module's Method).

    Raises
    ------
    ValueError
        A bad ``grid`` (:func:`check_discretisation`), or more than ``grid.max_elements``
        elements (checked on a lower bound before anything is allocated).
    """
    check_discretisation(grid)
    geometry, grid = geometry.as_arrays(), grid.as_numbers()
    branch = branches(geometry, grid)
    bound = element_count_bound(branch, grid)
    if bound > grid.max_elements:
        raise ValueError(f"the edges need at least {bound:.3g} elements (limit {grid.max_elements:.0f})")
    node_branch, node_z, node_path = branch_nodes(geometry, branch, grid)
    # an element from every node but each branch's last to the next node
    starts = np.flatnonzero(node_branch[:-1] == node_branch[1:])
    element_branch = node_branch[starts]
    za, zb = node_z[starts], node_z[starts + 1]
    # split evenly to the length cap, which grows with the distance from the apex
    cap = grid.max_element_m
    if grid.cap_growth > 0.0:
        apex = branch.start_z[element_branch]
        cap = grid.max_element_m + grid.cap_growth * np.minimum(np.abs(za - apex), np.abs(zb - apex))
    pieces = np.maximum(np.ceil(np.abs(zb - za) / cap).astype(np.int64), 1)
    parent, j = ragged_index(pieces)
    n = pieces[parent]
    z0 = za[parent] + (zb[parent] - za[parent]) * (j / n)
    z1 = za[parent] + (zb[parent] - za[parent]) * ((j + 1) / n)
    pair = branch.pair[element_branch[parent]]
    # path lengths: the nodes' where a piece ends on a node, else evaluated
    p = pair
    inner_start = (n > 1) & (j > 0)
    inner_end = (n > 1) & (j < n - 1)
    d0 = np.where(inner_start, path_length(z0, geometry.r_s[p], geometry.z_s[p], geometry.r_r[p], geometry.z_r[p]),
                  node_path[starts][parent])
    d1 = np.where(inner_end, path_length(z1, geometry.r_s[p], geometry.z_s[p], geometry.r_r[p], geometry.z_r[p]),
                  node_path[starts + 1][parent])
    keep = z1 != z0
    return EdgeElements(pair[keep], np.minimum(z0, z1)[keep], np.maximum(z0, z1)[keep], (0.5 * (d0 + d1))[keep])


__all__ = ("Branches", "Discretisation", "EdgeElements", "GradedIntervals", "ONSET_FRACTION", "PairGeometry",
           "branch_nodes", "branches", "check_discretisation", "discretise_edges", "element_count_bound",
           "graded_intervals", "onset_offsets", "path_length", "ragged_index", "spheroid_root")
