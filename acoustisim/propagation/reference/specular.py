"""Specular paths: chains of planar mirrors and up to two curved surfaces, with their amplitudes.

Physics
-------
Geometric acoustics (physics.md section 3). A specular path of order k is
transmitter -> k reflection points -> receiver, each point where the surface's normal bisects
the incoming and outgoing legs. Its pressure factor relative to the source's pressure at 1 m is

    g = prod_j R_j(theta_j) x spreading,

with R_j the plane-wave reflection coefficient of reflection j's material at its incidence
angle theta_j (``Material.reflection_coefficient``: the liquid / elastic-solid coefficient of
the solids, the fluid-fluid Rayleigh formula of fluids, complex with losses and beyond the
critical angles; -1 for the pressure-release free surface; physics.md sections 1 and 3) and the
spreading

* 1 / L for chains of planar mirrors (the image source at L, :mod:`.image_source`);
* the geometric-optics factor cos(theta_i) / (r1 r2 sqrt|det H|) of the curved specular point
  for chains through one curved surface, with r1, r2 the unfolded distances from the images
  on either side (:mod:`.curved`);
* the ray-tube (Deschamps) factor of chains through two curved primitives, in the frame
  unfolded across every mirror of the chain (:mod:`.curved_pairs`).

``Material`` returns coefficients in the physics convention exp(-i omega t); ``phase_rad`` is
applied as exp(+j phase) on positive frequencies of the engineering (FFT) convention, so a
complex product R gives ``geometric_gain = |R| x spreading`` and ``phase_rad = -arg(R)``; a real
one keeps its sign in ``geometric_gain``. The stationary-point phase of a smooth mesh (saddles,
focusing concave patches) is added to the same phase.

Method
------
1. Candidate chains (each checked against its polygons, discs and lit sides):
   planar chains of 1..``max_order`` mirrors (:func:`.image_source.planar_chains`); chains
   [n_before mirrors, one curved primitive (sphere, cylinder side), n_after mirrors] of every
   split with n_before + 1 + n_after <= ``max_order``: the transmitter is unfolded across the
   mirrors before the surface, every receiver across the mirrors after it (backwards), the
   specular point is solved on the true surface between the two images (:mod:`.curved`) and
   the planar points are back-traced from it; the same chains through smooth user meshes,
   whose specular points (possibly several per pair) come from their interpolated normals
   (:class:`~acoustisim.propagation.smooth_mesh.SmoothMesh`); with ``max_curved_per_path`` = 2,
   chains [mirrors, curved primitive, mirrors, curved primitive, mirrors] of every split
   (:mod:`.pair_chains`: post to post, post via a wall to a post, sphere to post), their two
   specular points solved jointly (:mod:`.curved_pairs`).
2. Occlusion: every leg of every candidate in one batched Embree query
   (:meth:`~acoustisim.propagation.raycast.RayCaster.occluded`); a leg ending on a mirror or a
   curved object ignores that surface's patch. A chain with a blocked leg is dropped.
3. Duplicates: reflections on perpendicular planes commute, so a path through a right-angle
   corner line (a tank corner, a post meeting the free surface or the floor) is found in both
   orders with coincident points: one row is kept per (channel, ordered interaction points to
   1 nm, set of surfaces). Reciprocal twins of a monostatic path ([wall-x0, wall-x1] and
   [wall-x1, wall-x0]) visit their points in opposite orders and stay.
4. Reflection coefficients at each reflection's incidence angle (a zero-length leg, two
   reflections on a corner line, arrives along the previous leg mirrored by the previous
   surface), multiplied per chain; the rows written.

Accuracy
--------
Geometric optics: exact for the image sources of plane mirrors; the curved-surface factor
neglects O(1 / (k a)) terms (7e-5 for a 5 cm sphere at 500 kHz against a Kirchhoff integral).
Not modelled: edge diffraction at the mirrors' rims (:mod:`acoustisim.propagation.edges`),
chains through three or more curved surfaces, chains through a smooth mesh and another curved
surface (a smooth mesh reflects at most once per path), and the plane-wave reflection
coefficient's error for spherical waves near the critical angle. A leg is
blocked by any surface more than ``DEFAULT_EPS_M`` (1e-7 m) from its ends.
"""

from __future__ import annotations

from typing import Any, NamedTuple

import numpy as np
from numpy.typing import NDArray

from acoustisim.materials import Material
from acoustisim.propagation.context import SolveContext
from acoustisim.propagation.image_source import PlanarMirrors, mirror_sequences
from acoustisim.propagation.paths import MAX_INTERACTIONS, PathKind, empty_paths_array
from acoustisim.propagation.prepared import PreparedScene
from acoustisim.propagation.raycast import RayCaster
from acoustisim.propagation.reference.chains import Chains
from acoustisim.propagation.reference.curved import go_amplitude, specular_points
from acoustisim.propagation.reference.image_source import backtrace, planar_chains, unfold
from acoustisim.propagation.reference.pair_chains import pair_chains

REAL_TOLERANCE = 1e-12
"""|Im R| below this fraction of |R| counts as a real coefficient (its sign kept in the gain)."""

DUPLICATE_RESOLUTION_M = 1e-9
"""Interaction points closer than this (m) count as the same point when finding duplicates."""


class MaterialTable(NamedTuple):
    """The materials of every reflecting surface of a scene, one code each.

    Mirror material j has code j, curved reflector r code ``curved_offset + r``, smooth mesh i
    code ``smooth_offset + i``.
    """

    materials: tuple[Material, ...]
    curved_offset: int
    smooth_offset: int


def material_table(prepared: PreparedScene) -> MaterialTable:
    """The :class:`MaterialTable` of ``prepared``."""
    mirrors = prepared.mirrors.materials
    curved = tuple(r.material for r in prepared.curved)
    smooth = tuple(r.material for r in prepared.smooth)
    return MaterialTable(mirrors + curved + smooth, len(mirrors), len(mirrors) + len(curved))


class Candidates(NamedTuple):
    """Chains [n_before mirrors, one reflector, n_after mirrors] whose images are valid (n of them).

    Attributes
    ----------
    reflector : ndarray of int64, shape (n,)
        Which curved reflector (or smooth mesh).
    channel : ndarray of int64, shape (n,)
        Receiver.
    chain : ndarray of int64, shape (n,)
        ``(before * sa + after) * c + reflector`` (before and after sequence numbers, sa after
        sequences, c reflectors).
    images_before : ndarray, shape (n, n_before + 1, 3)
        The transmitter and its images across the mirrors before the reflector (m).
    images_after : ndarray, shape (n, n_after + 1, 3)
        The receiver and its images across the mirrors after the reflector, from the receiver
        back (m).
    sequences_before, sequences_after : ndarray of int64, shape (n, n_before), (n, n_after)
        The mirrors before and after the reflector, in path order.
    chain_count : int
        Chain numbers this split uses (sb x sa x c).
    """

    reflector: NDArray[np.int64]
    channel: NDArray[np.int64]
    chain: NDArray[np.int64]
    images_before: NDArray[np.float64]
    images_after: NDArray[np.float64]
    sequences_before: NDArray[np.int64]
    sequences_after: NDArray[np.int64]
    chain_count: int

    def select(self, rows: NDArray[np.intp]) -> "Candidates":
        """The candidates ``rows``."""
        return Candidates(*(field[rows] for field in self[:-1]), self.chain_count)


def candidates(context: SolveContext, mirrors: PlanarMirrors, seen_by: NDArray[np.bool_], n_before: int,
               n_after: int, first: NDArray[np.bool_], last: NDArray[np.bool_]) -> Candidates:
    """Every (before sequence, after sequence, receiver, reflector) with valid images on both
    sides, whose mirrors next to the reflector may see it (``seen_by`` (c, m)); nested in that
    order."""
    n_reflectors = seen_by.shape[0]
    n_receivers = context.receivers_m.shape[0]
    seen = np.any(seen_by, axis=0)
    before = mirror_sequences(mirrors.sees, n_before, first, seen)
    after = mirror_sequences(mirrors.sees, n_after, seen, last)  # in path order
    images_before, ok_before = unfold(mirrors, context.transmitter_m, before)
    # the receiver side, unfolded from each receiver backwards: row q r + i is sequence q, receiver i
    after_of_row = np.repeat(np.arange(after.shape[0]), n_receivers)
    receiver_of_row = np.tile(np.arange(n_receivers), after.shape[0])
    images_after, ok_after = unfold(mirrors, context.receivers_m[receiver_of_row], after[after_of_row][:, ::-1])
    b, ar, r = (g.ravel() for g in np.meshgrid(np.flatnonzero(ok_before), np.flatnonzero(ok_after),
                                               np.arange(n_reflectors), indexing="ij"))
    allowed = np.ones(b.size, dtype=bool)
    if n_before:
        allowed &= seen_by[r, before[b, -1]]
    if n_after:
        allowed &= seen_by[r, after[after_of_row[ar], 0]]
    b, ar, r = b[allowed], ar[allowed], r[allowed]
    a = after_of_row[ar]
    return Candidates(reflector=r, channel=receiver_of_row[ar], chain=(b * after.shape[0] + a) * n_reflectors + r,
                      images_before=images_before[b], images_after=images_after[ar], sequences_before=before[b],
                      sequences_after=after[a], chain_count=before.shape[0] * after.shape[0] * n_reflectors)


def chains_through(context: SolveContext, mirrors: PlanarMirrors, candidates: Candidates,
                   point: NDArray[np.float64], normal: NDArray[np.float64], surface: NDArray[np.int64],
                   patch: NDArray[np.int64], material: NDArray[np.int64], spreading: NDArray[np.float64],
                   phase: NDArray[np.float64], chain: NDArray[np.int64]) -> Chains:
    """The chains of ``candidates`` through their reflector's specular ``point`` (n, 3) whose
    planar points back-trace validly on both sides.

    ``normal`` (n, 3), ``surface``, ``patch``, ``material`` (table codes), ``spreading``,
    ``phase`` and ``chain`` (n,) describe each candidate's reflection and chain; the chain's
    length is |X - A| + |X - B| between the two last images A and B.
    """
    before_points, ok_before = backtrace(mirrors, candidates.images_before, candidates.sequences_before, point)
    after_points, ok_after = backtrace(mirrors, candidates.images_after, candidates.sequences_after[:, ::-1], point)
    keep = np.flatnonzero(ok_before & ok_after)
    c = candidates.select(keep)
    x = point[keep]
    n = keep.size
    receiver = context.receivers_m[c.channel]
    vertices = np.concatenate([np.broadcast_to(context.transmitter_m, (n, 1, 3)), before_points[keep],
                               x[:, None, :], after_points[keep][:, ::-1], receiver[:, None, :]], axis=1)
    length = np.linalg.norm(x - c.images_before[:, -1], axis=1) + np.linalg.norm(x - c.images_after[:, -1], axis=1)
    b, a = c.sequences_before, c.sequences_after
    return Chains(
        vertices=vertices,
        surface=np.concatenate([mirrors.surface[b], surface[keep, None], mirrors.surface[a]], axis=1),
        patch=np.concatenate([mirrors.patch[b], patch[keep, None], mirrors.patch[a]], axis=1),
        normal=np.concatenate([mirrors.normal[b], normal[keep, None, :], mirrors.normal[a]], axis=1),
        material=np.concatenate([mirrors.material[b], material[keep, None], mirrors.material[a]], axis=1),
        length=length, spreading=spreading[keep], phase=phase[keep], channel=c.channel, chain=chain[keep])


def splits(max_order: int) -> list[tuple[int, int]]:
    """(n_before, n_after) of every chain through one reflector of order <= ``max_order``,
    lexicographic."""
    return [(n_before, n_after) for n_before in range(max_order) for n_after in range(max_order - n_before)]


def curved_chains(context: SolveContext, prepared: PreparedScene, max_order: int, first: NDArray[np.bool_],
                  last: NDArray[np.bool_], table: MaterialTable, chain_base: int) -> tuple[list[Chains], int]:
    """Chains [n_before mirrors, one curved primitive, n_after mirrors] of every split; and the
    next free chain number."""
    mirrors = prepared.mirrors
    surface_of = np.array([r.surface for r in prepared.curved], dtype=np.int64)
    patch_of = np.array([r.patch for r in prepared.curved], dtype=np.int64)
    groups = []
    for n_before, n_after in splits(max_order):
        c = candidates(context, mirrors, prepared.curved_seen_by, n_before, n_after, first, last)
        a, b = c.images_before[:, -1], c.images_after[:, -1]
        x = specular_points(prepared.curved_set, c.reflector, a, b)
        spreading, phase = go_amplitude(a, b, x.point, x.normal, x.e1, x.e2, x.k11, x.k22, x.k12)
        lit = np.flatnonzero(x.valid)
        r = c.reflector
        groups.append(chains_through(context, mirrors, c.select(lit), x.point[lit], x.normal[lit],
                                     surface_of[r[lit]], patch_of[r[lit]], table.curved_offset + r[lit],
                                     spreading[lit], np.zeros(lit.size), chain_base + c.chain[lit]))
        chain_base += c.chain_count
    return groups, chain_base


def smooth_chains(context: SolveContext, prepared: PreparedScene, max_order: int, first: NDArray[np.bool_],
                  last: NDArray[np.bool_], table: MaterialTable, chain_base: int) -> tuple[list[Chains], int]:
    """Chains [n_before mirrors, one smooth mesh, n_after mirrors] of every split: a pair may
    have several specular points on a non-convex mesh, each a chain of its own (its own chain
    number)."""
    mirrors = prepared.mirrors
    seen_by = np.array([r.seen_by for r in prepared.smooth], dtype=bool).reshape(len(prepared.smooth), mirrors.count)
    groups = []
    for n_before, n_after in splits(max_order):
        c = candidates(context, mirrors, seen_by, n_before, n_after, first, last)
        for i, reflector in enumerate(prepared.smooth):  # a loop over meshes (a few), vectorised inside
            mine = c.select(np.flatnonzero(c.reflector == i))
            a, b = mine.images_before[:, -1], mine.images_after[:, -1]
            pair, triangle, x, normal, e1, e2, k11, k22, k12 = reflector.mesh.specular_points(a, b)
            spreading, phase = go_amplitude(a[pair], b[pair], x, normal, e1, e2, k11, k22, k12)
            n = pair.size
            groups.append(chains_through(context, mirrors, mine.select(pair), x, normal,
                                         np.full(n, reflector.surface), reflector.patch[triangle],
                                         np.full(n, table.smooth_offset + i), spreading, phase,
                                         chain_base + np.arange(n)))
            chain_base += n
    return groups, chain_base


def unblocked(groups: list[Chains], raycaster: RayCaster) -> list[Chains]:
    """The chains of ``groups`` none of whose legs is occluded: one batched query over every leg
    (a leg ignores the patches of the reflections at its ends)."""
    groups = [chains for chains in groups if chains.count]
    if not groups:
        return []
    origins, targets, exclude = [], [], []
    for chains in groups:
        none = np.full((chains.count, 1), -1, dtype=np.int64)
        origins.append(chains.vertices[:, :-1].reshape(-1, 3))
        targets.append(chains.vertices[:, 1:].reshape(-1, 3))
        start_patch = np.concatenate([none, chains.patch], axis=1)  # the patch at each leg's start
        end_patch = np.concatenate([chains.patch, none], axis=1)
        exclude.append(np.stack([start_patch, end_patch], axis=2).reshape(-1, 2))
    blocked = raycaster.occluded(np.concatenate(origins), np.concatenate(targets),
                                 exclude_patches=np.concatenate(exclude))
    live, start = [], 0
    for chains in groups:
        legs = chains.order + 1
        chain_blocked = blocked[start:start + chains.count * legs].reshape(chains.count, legs).any(axis=1)
        start += chains.count * legs
        live.append(chains.select(~chain_blocked))
    return live


def incidence_cosines(chains: Chains) -> NDArray[np.float64]:
    """|cos| of the incidence angle (n, k) at each reflection of ``chains``.

    A zero-length leg (two reflections on a corner line) arrives along the previous leg's
    direction mirrored by the previous surface.
    """
    cosines = np.empty((chains.count, chains.order))
    previous = np.zeros((chains.count, 3))
    for j in range(chains.order):
        leg = chains.vertices[:, j + 1] - chains.vertices[:, j]
        norm = np.linalg.norm(leg, axis=1, keepdims=True)
        incoming = leg / np.where(norm > 0, norm, 1.0)
        if j > 0:
            n_previous = chains.normal[:, j - 1]
            mirrored = previous - 2.0 * np.einsum("ij,ij->i", previous, n_previous)[:, None] * n_previous
            incoming = np.where(norm > 1e-12, incoming, mirrored)
        previous = incoming
        cosines[:, j] = np.abs(np.einsum("ij,ij->i", incoming, chains.normal[:, j]))
    return cosines


def reflection_products(chains: Chains, table: MaterialTable, context: SolveContext) -> NDArray[np.complex128]:
    """prod over each chain's reflections of R(cos theta_i), times exp(-i phase) of its
    stationary point (both in the physics convention exp(-i omega t)): (n,) complex."""
    cosines = incidence_cosines(chains)
    factors = np.ones(cosines.shape, dtype=complex)
    for code, material in enumerate(table.materials):
        on = chains.material == code
        if on.any():
            factors[on] = material.reflection_coefficient(cosines[on], context.density_kg_m3, context.sound_speed_m_s)
    product = np.ones(chains.count, dtype=complex)
    for j in range(chains.order):
        product *= factors[:, j]
    return product * np.exp(-1j * chains.phase)


def path_rows(chains: Chains, reflection: NDArray[np.complex128], first_path_id: int) -> NDArray[Any]:
    """The PATH_DTYPE rows of ``chains`` with the reflection products ``reflection`` (n,)."""
    rows = empty_paths_array(chains.count)
    if chains.count == 0:
        return rows
    real = np.abs(reflection.imag) <= REAL_TOLERANCE * np.abs(reflection)
    rows["path_id"] = first_path_id + chains.chain
    rows["channel"] = chains.channel
    rows["kind"] = PathKind.SPECULAR
    rows["order"] = chains.order
    rows["path_length_m"] = chains.length
    rows["geometric_gain"] = np.where(real, chains.spreading * reflection.real, chains.spreading * np.abs(reflection))
    rows["phase_rad"] = np.where(real, 0.0, -np.angle(reflection))
    departure = chains.vertices[:, 1] - chains.vertices[:, 0]
    arrival = chains.vertices[:, -1] - chains.vertices[:, -2]
    rows["departure_dir"] = departure / np.linalg.norm(departure, axis=1, keepdims=True)
    rows["arrival_dir"] = arrival / np.linalg.norm(arrival, axis=1, keepdims=True)
    stored = min(chains.order, MAX_INTERACTIONS)
    rows["object_ids"][:, :stored] = chains.surface[:, :stored]
    rows["points_m"][:, :stored] = chains.vertices[:, 1:1 + stored]
    return rows


def duplicate_key(rows: NDArray[Any]) -> NDArray[np.int64]:
    """What makes two rows the same path (n, 2 + 4 MAX_INTERACTIONS): channel, order, the
    surfaces sorted (-1 padding), the interaction points in units of
    :data:`DUPLICATE_RESOLUTION_M` (rounded half to even; 0 padding)."""
    points = np.nan_to_num(rows["points_m"], nan=0.0).reshape(rows.size, -1)
    surfaces = np.sort(rows["object_ids"].astype(np.int64), axis=1)
    key = np.column_stack([rows["channel"], rows["order"], surfaces, np.round(points / DUPLICATE_RESOLUTION_M)])
    return key.astype(np.int64)


def first_distinct(rows: NDArray[Any]) -> NDArray[np.intp]:
    """Indices (increasing) of the first row of each :func:`duplicate_key`."""
    _, first = np.unique(duplicate_key(rows), axis=0, return_index=True)
    return np.sort(first)


def receivers_in_front(context: SolveContext, mirrors: PlanarMirrors) -> NDArray[np.bool_]:
    """Mirrors (m,) with at least one receiver strictly in front of them."""
    ahead = np.einsum("rmk,mk->rm", context.receivers_m[:, None, :] - mirrors.point, mirrors.normal)
    return np.any(ahead > 0, axis=0)


def specular_rows(context: SolveContext, prepared: PreparedScene, max_order: int,
                  max_curved_per_path: int) -> NDArray[Any]:
    """Every unblocked specular path of order 1..``max_order`` to every receiver.

    Parameters
    ----------
    context : SolveContext
    prepared : PreparedScene
        Mirrors and curved reflectors of ``context.scene``.
    max_order : int
        Most reflections per path (>= 1).
    max_curved_per_path : int
        Most reflections on curved surfaces per path: 1 (one curved primitive or smooth mesh)
        or 2 (also chains through two curved primitives, numbered after all the others).

    Returns
    -------
    structured ndarray of PATH_DTYPE
        ``path_id`` = ``context.first_path_id`` + a chain number shared by the receivers.
    """
    mirrors = prepared.mirrors
    table = material_table(prepared)
    # mirrors the transmitter can reach first, and those some receiver can be reached from last
    first = mirrors.signed_distance(np.broadcast_to(context.transmitter_m, (mirrors.count, 3)),
                                    np.arange(mirrors.count)) > 0
    last = receivers_in_front(context, mirrors)
    groups, chain_base = [], 0
    for order in range(1, max_order + 1):
        chains, chain_base = planar_chains(context, mirrors, order, first, last, chain_base)
        groups.append(chains)
    if prepared.curved:
        curved, chain_base = curved_chains(context, prepared, max_order, first, last, table, chain_base)
        groups += curved
    if prepared.smooth:
        smooth, chain_base = smooth_chains(context, prepared, max_order, first, last, table, chain_base)
        groups += smooth
    if prepared.curved and max_curved_per_path >= 2 and max_order >= 2:
        pairs, chain_base = pair_chains(context, prepared, max_order, first, last, table.curved_offset, chain_base)
        groups += pairs
    live = unblocked(groups, prepared.raycaster)
    rows = np.concatenate([empty_paths_array(0)] + [
        path_rows(chains, reflection_products(chains, table, context), context.first_path_id) for chains in live])
    return rows[first_distinct(rows)] if rows.size > 1 else rows


__all__ = ("Candidates", "MaterialTable", "candidates", "chains_through", "curved_chains", "duplicate_key",
           "first_distinct", "incidence_cosines", "material_table", "path_rows", "receivers_in_front", "reflection_products",
           "smooth_chains", "specular_rows", "splits", "unblocked")
