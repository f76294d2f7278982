"""The reference's edge-diffraction rows, computed with compiled kernels and a visibility screen.

:func:`edge_rows` follows :func:`acoustisim.propagation.reference.edge_paths.edge_rows` step for
step, sharing its per-pair set-up (a few hundred pairs: the pairs, their wedge coordinates and
chain joints, the discretisation's parameters and the quadrature's per-pair constants) and
replacing its per-element steps:

1. the discretisation: :mod:`.edge_elements`;
2. the visibility: :mod:`.edge_visibility` decides nearly every leg without Embree and asks
   Embree about the rest in one batch;
3. the quadrature: :func:`.edge_gains.edge_impulses`;
4. the rows: the element floor, then the kept impulses ordered as the assembly orders rows
   (:mod:`.edge_order`), so that the assembly need not move them, and written by one compiled
   loop (:func:`fill_rows`) into an uninitialised buffer (every field written once).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numba import njit
from numpy.typing import NDArray

from acoustisim.propagation.config import SolverConfig
from acoustisim.propagation.context import SolveContext
from acoustisim.propagation.fast.edge_elements import discretise_edges
from acoustisim.propagation.fast.edge_gains import edge_impulses
from acoustisim.propagation.fast.edge_order import solver_order
from acoustisim.propagation.fast.edge_reflections import fast_kernels, fill_reflected_rows, reflected_impulses, row_inputs
from acoustisim.propagation.reference.edge_apex import apex_parts, apex_rows
from acoustisim.propagation.fast.edge_visibility import EdgeLines, LegTargets, element_visibility
from acoustisim.propagation.fast.row_columns import write_path_columns
from acoustisim.propagation.paths import PATH_DTYPE, PathKind
from acoustisim.propagation.prepared import PreparedScene
from acoustisim.propagation.reference.btm import pair_constants
from acoustisim.propagation.reference.edge_reflections import pair_path_index
from acoustisim.propagation.reference.edges import (
    ELEMENT_FLOOR,
    EdgeImpulses,
    discretisation,
    edge_pairs,
    too_many_elements,
)

EDGE_KIND = int(PathKind.EDGE)
"""``PathKind.EDGE`` as the compiled loop writes it."""


@njit(cache=True, nogil=True, error_model="numpy")
def fill_rows(rows: NDArray[Any], keep: NDArray[np.int64], impulses: EdgeImpulses, pair_edge: NDArray[np.int64],
              pair_receiver: NDArray[np.int64], lines: EdgeLines, targets: LegTargets, first_path_id: int,
              destination: NDArray[np.int64]) -> int:
    """Write the rows of the impulses ``keep`` (shape (k,)) at ``rows[destination]`` (PATH_DTYPE,
    uninitialised there): the reference's ``impulse_rows``, every field written (the derived
    ones 0, the padding -1 and NaN). Returns the number of path ids used."""
    k = keep.size
    n_receivers = targets.receivers.shape[0]
    # path ids: the dense rank of each kept impulse's (chain, receiver) key
    max_key = 0
    for r in range(k):
        p = impulses.pair[keep[r]]
        max_key = max(max_key, lines.chain[pair_edge[p]] * n_receivers + pair_receiver[p])
    rank = np.zeros(max_key + 1, dtype=np.int64)
    for r in range(k):
        p = impulses.pair[keep[r]]
        rank[lines.chain[pair_edge[p]] * n_receivers + pair_receiver[p]] = 1
    count = 0
    for key in range(max_key + 1):
        count += rank[key]
        rank[key] = count - 1
    tx = targets.transmitter
    for r in range(k):
        i = keep[r]
        p = impulses.pair[i]
        e = pair_edge[p]
        ch = pair_receiver[p]
        row = rows[destination[r]]
        write_path_columns(row, first_path_id + rank[lines.chain[e] * n_receivers + ch], ch, EDGE_KIND, 1,
                           impulses.path_length_m[i], impulses.gain[i], 0.0)
        z = impulses.z_m[i]
        x0 = lines.start[e, 0] + z * lines.direction[e, 0]
        x1 = lines.start[e, 1] + z * lines.direction[e, 1]
        x2 = lines.start[e, 2] + z * lines.direction[e, 2]
        l0, l1, l2 = x0 - tx[0], x1 - tx[1], x2 - tx[2]
        norm = math.sqrt(l0 * l0 + l1 * l1 + l2 * l2)
        row.departure_dir[0], row.departure_dir[1], row.departure_dir[2] = l0 / norm, l1 / norm, l2 / norm
        m0, m1, m2 = targets.receivers[ch, 0] - x0, targets.receivers[ch, 1] - x1, targets.receivers[ch, 2] - x2
        norm = math.sqrt(m0 * m0 + m1 * m1 + m2 * m2)
        row.arrival_dir[0], row.arrival_dir[1], row.arrival_dir[2] = m0 / norm, m1 / norm, m2 / norm
        row.object_ids[0] = lines.surface[e]
        row.points_m[0, 0], row.points_m[0, 1], row.points_m[0, 2] = x0, x1, x2
        for j in range(1, row.object_ids.shape[0]):
            row.object_ids[j] = -1
            row.points_m[j, 0] = np.nan
            row.points_m[j, 1] = np.nan
            row.points_m[j, 2] = np.nan
    return count


def edge_rows(context: SolveContext, config: SolverConfig, prepared: PreparedScene) -> NDArray[Any]:
    """The reference's :func:`~acoustisim.propagation.reference.edge_paths.edge_rows`, in the order
    the assembly gives rows (channel, then delay ``path_length_m / c``, ties in the reference's
    row order: first-order rows, then those combined with reflections,
    :mod:`.edge_reflections`).

    Raises
    ------
    InputError
        As the reference.
    """
    scene_edges = prepared.diffracting_edges
    pairs = edge_pairs(context, scene_edges)
    impulses = EdgeImpulses(np.zeros(0, dtype=np.int64), np.zeros(0), np.zeros(0), np.zeros(0))
    if pairs.edge.size:
        try:
            elements = discretise_edges(pairs.geometry, discretisation(config, context))
        except ValueError as error:
            raise too_many_elements(config, error) from None
        visible = element_visibility(context, prepared, elements, pairs)
        if not np.all(visible):
            elements = elements.select(visible)
        impulses = edge_impulses(elements, pair_constants(pairs.wedge), config.edge_adaptive)
    parts = reflected_impulses(context, config, prepared)
    reflected = parts.impulses
    apex = apex_rows(context, prepared, apex_parts(context, prepared, parts.far, fast_kernels()), 0)
    apex = apex[np.lexsort((apex["path_length_m"] / context.sound_speed_m_s, apex["channel"]))]
    strongest = max([float(np.max(np.abs(impulses.gain), initial=0.0))]
                    + [float(np.max(np.abs(part.impulses.gain))) for part in reflected])
    if strongest == 0.0:
        impulses = EdgeImpulses(np.zeros(0, dtype=np.int64), np.zeros(0), np.zeros(0), np.zeros(0))
        reflected = []
    floor = ELEMENT_FLOOR * strongest
    keep = np.flatnonzero(np.abs(impulses.gain) > floor)
    kept = [np.flatnonzero(np.abs(part.impulses.gain) > floor) for part in reflected]
    # one stable order by (channel, delay) over the first-order and the reflected impulses, in
    # the reference's row order
    pair_offset = np.cumsum([0, pairs.edge.size] + [part.pairs.edge.size for part in reflected])
    impulse_offset = np.cumsum([0, impulses.gain.size] + [part.impulses.gain.size for part in reflected])
    point_pair = np.concatenate([impulses.pair] + [part.impulses.pair + pair_offset[j + 1]
                                                   for j, part in enumerate(reflected)])
    path_length = np.concatenate([impulses.path_length_m] + [part.impulses.path_length_m for part in reflected])
    pair_receiver = np.concatenate([pairs.receiver] + [part.pairs.receiver for part in reflected])
    every = np.concatenate([keep] + [k + impulse_offset[j + 1] for j, k in enumerate(kept)])
    ordered = solver_order(every, point_pair, path_length, pair_receiver, context.sound_speed_m_s,
                           context.receivers_m.shape[0])
    position, apex_position = interleaved(pair_receiver[point_pair[ordered]],
                                          path_length[ordered] / context.sound_speed_m_s, apex["channel"],
                                          apex["path_length_m"] / context.sound_speed_m_s)
    rows = np.empty(ordered.size + apex.size, dtype=PATH_DTYPE)
    lines, targets = EdgeLines.of(scene_edges), LegTargets.of(context)
    if not reflected:  # first order only: the rows in the solver's order, written in turn
        used = fill_rows(rows, ordered, impulses, pairs.edge, pairs.receiver, lines, targets,
                         int(context.first_path_id), position)
        next_id = int(context.first_path_id) + used
    else:
        destination = np.empty(impulse_offset[-1], dtype=np.int64)
        destination[ordered] = position
        # each part's rows written in increasing destination (sequential writes)
        mine = keep[np.argsort(destination[keep], kind="stable")]
        used = fill_rows(rows, mine, impulses, pairs.edge, pairs.receiver, lines, targets,
                         int(context.first_path_id), destination[mine])
        path_index = pair_path_index(reflected, kept, scene_edges.edges.chain)
        next_id = int(context.first_path_id) + used
        for j, (part, k) in enumerate(zip(reflected, kept)):  # a loop over the few splits
            where = destination[k + impulse_offset[j + 1]]
            order = np.argsort(where, kind="stable")
            fill_reflected_rows(rows, where[order], k[order],
                                row_inputs(context, prepared, part, next_id + path_index[j]), EDGE_KIND)
        next_id += max(int(index.max(initial=-1)) for index in path_index) + 1
    if apex.size:  # Keller's apex rows, path ids after the others in the reference's pair order
        apex["path_id"] += next_id
        rows[apex_position] = apex
    return rows


def interleaved(channel: NDArray[Any], delay_s: NDArray[np.float64], apex_channel: NDArray[Any],
                apex_delay_s: NDArray[np.float64]) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """The places of the element rows (sorted by channel then delay, (n,)) and of the apex rows
    (sorted so too, (k,)) in their merge by channel then delay, ties to the element rows first
    (the order a stable sort of the element rows followed by the apex rows gives)."""
    position = np.arange(delay_s.size, dtype=np.int64)
    apex_position = np.arange(apex_delay_s.size, dtype=np.int64)
    for ch in np.unique(apex_channel):  # a loop over the few channels
        lo, hi = np.searchsorted(channel, ch, side="left"), np.searchsorted(channel, ch, side="right")
        a_lo, a_hi = np.searchsorted(apex_channel, ch, side="left"), np.searchsorted(apex_channel, ch, side="right")
        position[lo:hi] += np.searchsorted(apex_delay_s[a_lo:a_hi], delay_s[lo:hi], side="left")
        position[hi:] += a_hi - a_lo
        apex_position[a_lo:a_hi] += lo + np.searchsorted(delay_s[lo:hi], apex_delay_s[a_lo:a_hi], side="right")
    return position, apex_position


__all__ = ("EDGE_KIND", "edge_rows", "fill_rows")
