"""The reference's edge diffraction combined with reflections, with compiled kernels and a screen.

:func:`reflected_impulses` is
:func:`acoustisim.propagation.reference.edge_reflections.reflected_impulses` (the same
orchestration: mirror sequences and images, pairs, specular points on curved reflectors,
reflection coefficients) with this engine's per-element steps (:func:`fast_kernels`):

1. the discretisation and the quadrature: the first-order edges' kernels
   (:mod:`.edge_elements`, :mod:`.edge_gains`);
2. the reflection points: :func:`.mirror_kernels.backtrace_chains` (the specular chains'
   compiled back-tracing, the reference's arithmetic), and on curved reflectors
   :func:`.curved_kernels.specular_points`;
3. the visibility: :func:`screen_path_legs` decides the legs without Embree where it can (the
   walls of the tank box, but for the boundary a leg starts or ends on, which it ignores as
   Embree's exclusion does; the objects by :func:`.edge_visibility.screen_legs`'s boxes and
   convex face planes), each with the screen's float32 margin; the legs it leaves undecided go
   to :meth:`~acoustisim.propagation.raycast.RayCaster.occluded` as the reference asks them,
   one batch per split;
4. the rows: :func:`fill_reflected_rows` writes them where the solver's order puts them
   (:mod:`.edges` orders first-order and reflected rows together).
"""

from __future__ import annotations

import math
from typing import Any, NamedTuple

import numpy as np
from numba import njit
from numpy.typing import NDArray

from acoustisim.propagation.config import SolverConfig
from acoustisim.propagation.context import SolveContext
from acoustisim.propagation.fast.curved_kernels import specular_points
from acoustisim.propagation.fast.edge_elements import discretise_edges
from acoustisim.propagation.fast.edge_gains import edge_impulses
from acoustisim.propagation.fast.edge_visibility import (BLOCKED, CLEAR, MASK_BITS, OTHERS_BIT, UNDECIDED,
                                                         ScreenGeometry, scene_screen, screen_legs)
from acoustisim.propagation.fast.mirror_kernels import backtrace_chains, mirror_arrays
from acoustisim.propagation.fast.row_columns import write_path_columns
from acoustisim.propagation.paths import MAX_INTERACTIONS
from acoustisim.propagation.prepared import PreparedScene
from acoustisim.propagation.raycast import DEFAULT_EPS_M
from acoustisim.propagation.reference.edge_reflections import ElementKernels, ReflectedParts, SplitImpulses
from acoustisim.propagation.reference.edge_reflections import reflected_impulses as reference_reflected_impulses


GRAZING_SINE = 0.05
"""A leg leaving the tank boundary it starts or ends on at a sine below this goes to Embree:
there float32 rounding can make Embree hit that (ignored) face again and again along the leg,
and the ray caster's exclusion passes then call the leg blocked. Such hits need the ray within
about 1e-6 m of the face over its first 0.1 mm (the ``eps`` it starts after), i.e. a sine
below about 0.01: 0.05 leaves a factor of five."""


@njit(cache=True, nogil=True, error_model="numpy")
def shrunk_legs(vertices: NDArray[np.float64], face: NDArray[np.int64], water_lo: NDArray[np.float64],
                water_hi: NDArray[np.float64], eps_m: float, grazing_sine: float
                ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.int8]]:
    """Every leg of every path (n paths of v vertices, (n, v, 3)) as Embree is asked about it (its
    ends moved ``eps_m`` inwards), and the walls' verdict: CLEAR when it is never blocked (not
    longer than 2 eps) or both moved ends lie in the water box shrunk by the screen's margin
    (``water_lo``, ``water_hi``) but for the box faces its vertices lie on (``face`` (n, v), -1
    none: a leg ignores the boundary it starts or ends on, as Embree's exclusion does, unless
    it leaves that face at a sine below ``grazing_sine``), UNDECIDED otherwise.

    Returns
    -------
    p0, p1 : ndarray, shape (n (v - 1), 3)
    walls : ndarray of int8, shape (n (v - 1),)
    """
    n, v = vertices.shape[0], vertices.shape[1]
    legs = n * (v - 1)
    p0 = np.empty((legs, 3))
    p1 = np.empty((legs, 3))
    walls = np.empty(legs, dtype=np.int8)
    for i in range(n):
        for j in range(v - 1):
            q = i * (v - 1) + j
            s0 = vertices[i, j + 1, 0] - vertices[i, j, 0]
            s1 = vertices[i, j + 1, 1] - vertices[i, j, 1]
            s2 = vertices[i, j + 1, 2] - vertices[i, j, 2]
            length = math.sqrt((s0 * s0 + s1 * s1) + s2 * s2)
            if not length > 2.0 * eps_m:  # never blocked
                for c in range(3):
                    p0[q, c] = vertices[i, j, c]
                    p1[q, c] = vertices[i, j, c]
                walls[q] = CLEAR
                continue
            d = (s0 / length, s1 / length, s2 / length)
            far = length - eps_m
            for c in range(3):
                p0[q, c] = vertices[i, j, c] + eps_m * d[c]
                p1[q, c] = vertices[i, j, c] + far * d[c]
            verdict = CLEAR
            for c in range(3):
                for side in range(2):
                    f = 2 * c + side
                    if f == face[i, j] or f == face[i, j + 1]:
                        if abs(d[c]) < grazing_sine:  # Embree may graze the ignored face: ask it
                            verdict = UNDECIDED
                        continue
                    if side == 0:
                        inside = (p0[q, c] >= water_lo[c]) & (p1[q, c] >= water_lo[c])
                    else:
                        inside = (p0[q, c] <= water_hi[c]) & (p1[q, c] <= water_hi[c])
                    if not inside:
                        verdict = UNDECIDED
            walls[q] = verdict
    return p0, p1, walls


def object_mask(n_objects: int) -> int:
    """The :func:`.edge_visibility.screen_legs` mask testing every object and no wall."""
    mask = (1 << min(n_objects, MASK_BITS)) - 1
    if n_objects > MASK_BITS:
        mask |= 1 << OTHERS_BIT
    return mask


def screen_path_legs(context: SolveContext, screen: ScreenGeometry, vertices: NDArray[np.float64],
                     patches: NDArray[np.int64], faces: NDArray[np.int64]) -> NDArray[np.bool_]:
    """Whether every leg of each path is clear, (n,): the reference's
    :func:`~acoustisim.propagation.reference.edge_reflections.reflected_visibility` answers.

    Parameters
    ----------
    vertices : ndarray, shape (n, v, 3)
        Each path's vertices (transmitter, reflection points, the element's probe, reflection
        points, receiver) (m).
    patches : ndarray of int64, shape (n, v)
        The patch each vertex lies on (its mirror's; -1 for the others): excluded by the legs
        ending there.
    faces : ndarray of int64, shape (n, v)
        The tank box face each vertex lies on (-1: none).
    """
    n, v = vertices.shape[0], vertices.shape[1]
    vertices = np.ascontiguousarray(vertices)
    p0, p1, walls = shrunk_legs(vertices, np.ascontiguousarray(faces), screen.water_lo, screen.water_hi,
                                DEFAULT_EPS_M, GRAZING_SINE)
    mask = np.full(p0.shape[0], object_mask(screen.box_lo.shape[0]), dtype=np.int64)
    objects = screen_legs(p0, p1, mask, screen)
    blocked = objects == BLOCKED
    leg_path = np.repeat(np.arange(n), v - 1)
    path_blocked = np.zeros(n, dtype=bool)
    path_blocked[leg_path[blocked]] = True
    undecided = np.flatnonzero(((objects == UNDECIDED) | (walls == UNDECIDED)) & ~blocked & ~path_blocked[leg_path])
    if undecided.size:
        origins = vertices[:, :-1].reshape(-1, 3)[undecided]
        targets = vertices[:, 1:].reshape(-1, 3)[undecided]
        exclude = np.stack([patches[:, :-1], patches[:, 1:]], axis=2).reshape(-1, 2)[undecided]
        hit = context.raycaster.occluded(origins, targets, exclude_patches=exclude)
        path_blocked[leg_path[undecided[hit]]] = True
    return ~path_blocked


def fast_backtrace(prepared: PreparedScene, images: NDArray[np.float64], sequences: NDArray[np.int64],
                   end: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
    """The reference's back-tracing by :func:`.mirror_kernels.backtrace_chains`."""
    return backtrace_chains(mirror_arrays(prepared.mirrors), images, sequences, end)


def fast_path_visibility(context: SolveContext, prepared: PreparedScene, vertices: NDArray[np.float64],
                         patches: NDArray[np.int64], faces: NDArray[np.int64]) -> NDArray[np.bool_]:
    """:func:`screen_path_legs` with the prepared scene's screen."""
    return screen_path_legs(context, scene_screen(prepared), vertices, patches, faces)


def fast_kernels() -> ElementKernels:
    """The fast engine's per-element steps (the quadrature: :func:`.edge_gains.edge_impulses`)."""
    return ElementKernels(discretise_edges, edge_impulses, fast_backtrace, fast_path_visibility, specular_points)


def reflected_impulses(context: SolveContext, config: SolverConfig, prepared: PreparedScene) -> ReflectedParts:
    """The reference's :func:`~acoustisim.propagation.reference.edge_reflections.reflected_impulses`
    with the fast kernels."""
    return reference_reflected_impulses(context, config, prepared, fast_kernels())


class ReflectedRowInputs(NamedTuple):
    """What :func:`fill_reflected_rows` reads for one split.

    ``gain``, ``phase``, ``z_m``, ``path_length_m`` (i,), ``pair`` (i,) and ``element`` (i,) of
    its impulses; per pair ``edge``, ``receiver``, ``path_id`` (p,) and ``surfaces`` (p, b + 1 + a)
    (the mirrors' before, the edge's, the mirrors' after); per element ``before_points`` (e, b, 3)
    and ``after_points`` (e, a, 3); the edges' ``start`` and ``direction`` (n_edges, 3);
    ``transmitter`` (3,) and ``receivers`` (n_rx, 3).
    """

    gain: NDArray[np.float64]
    phase: NDArray[np.float64]
    z_m: NDArray[np.float64]
    path_length_m: NDArray[np.float64]
    pair: NDArray[np.int64]
    element: NDArray[np.int64]
    edge: NDArray[np.int64]
    receiver: NDArray[np.int64]
    path_id: NDArray[np.int64]
    surfaces: NDArray[np.int64]
    before_points: NDArray[np.float64]
    after_points: NDArray[np.float64]
    start: NDArray[np.float64]
    direction: NDArray[np.float64]
    transmitter: NDArray[np.float64]
    receivers: NDArray[np.float64]


@njit(cache=True, nogil=True, error_model="numpy")
def fill_reflected_rows(rows: NDArray[Any], destination: NDArray[np.int64], keep: NDArray[np.int64],
                        inputs: ReflectedRowInputs, edge_kind: int) -> None:
    """Write the rows of the impulses ``keep`` (k,) of one split at ``rows[destination]``
    (PATH_DTYPE, uninitialised there): the reference's
    :func:`~acoustisim.propagation.reference.edge_reflections.reflected_rows`, every field
    written (the derived ones 0, the padding -1 and NaN)."""
    n_before = inputs.before_points.shape[1]
    n_after = inputs.after_points.shape[1]
    order = 1 + n_before + n_after
    stored = min(order, MAX_INTERACTIONS)
    points = np.empty((order, 3))
    for r in range(keep.size):
        i = keep[r]
        p = inputs.pair[i]
        e = inputs.edge[p]
        el = inputs.element[i]
        ch = inputs.receiver[p]
        row = rows[destination[r]]
        write_path_columns(row, inputs.path_id[p], ch, edge_kind, order, inputs.path_length_m[i], inputs.gain[i],
                           inputs.phase[i])
        for j in range(n_before):
            for c in range(3):
                points[j, c] = inputs.before_points[el, j, c]
        z = inputs.z_m[i]
        for c in range(3):
            points[n_before, c] = inputs.start[e, c] + z * inputs.direction[e, c]
        for j in range(n_after):
            for c in range(3):
                points[n_before + 1 + j, c] = inputs.after_points[el, j, c]
        d0 = points[0, 0] - inputs.transmitter[0]
        d1 = points[0, 1] - inputs.transmitter[1]
        d2 = points[0, 2] - inputs.transmitter[2]
        norm = math.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
        row.departure_dir[0], row.departure_dir[1], row.departure_dir[2] = d0 / norm, d1 / norm, d2 / norm
        a0 = inputs.receivers[ch, 0] - points[order - 1, 0]
        a1 = inputs.receivers[ch, 1] - points[order - 1, 1]
        a2 = inputs.receivers[ch, 2] - points[order - 1, 2]
        norm = math.sqrt(a0 * a0 + a1 * a1 + a2 * a2)
        row.arrival_dir[0], row.arrival_dir[1], row.arrival_dir[2] = a0 / norm, a1 / norm, a2 / norm
        for j in range(row.object_ids.shape[0]):
            if j < stored:
                row.object_ids[j] = inputs.surfaces[p, j]
                for c in range(3):
                    row.points_m[j, c] = points[j, c]
            else:
                row.object_ids[j] = -1
                for c in range(3):
                    row.points_m[j, c] = np.nan


def row_inputs(context: SolveContext, prepared: PreparedScene, part: SplitImpulses,
               pair_path_id: NDArray[np.int64]) -> ReflectedRowInputs:
    """The :class:`ReflectedRowInputs` of one split, path ids ``pair_path_id`` (p,)."""
    edges = prepared.diffracting_edges.edges
    impulses = part.impulses
    return ReflectedRowInputs(
        impulses.gain, part.phase, impulses.z_m, impulses.path_length_m, impulses.pair, part.element, part.pairs.edge,
        part.pairs.receiver, np.ascontiguousarray(pair_path_id, dtype=np.int64),
        np.ascontiguousarray(part.surfaces, dtype=np.int64), np.ascontiguousarray(part.before_points),
        np.ascontiguousarray(part.after_points), edges.start_m, edges.direction,
        np.asarray(context.transmitter_m, dtype=float), np.ascontiguousarray(context.receivers_m, dtype=float))


__all__ = ("GRAZING_SINE", "ReflectedRowInputs", "fast_backtrace", "fast_kernels", "fast_path_visibility",
           "fill_reflected_rows", "object_mask", "reflected_impulses", "row_inputs", "screen_path_legs", "shrunk_legs")
