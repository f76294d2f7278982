"""Edge diffraction combined with reflections: the Biot-Tolstoy-Medwin integral between images.

Physics
-------
A plane mirror reflects a point source's field as if it came from the source's mirror image
(the image method, physics.md section 3), and so it does the field an edge diffracts, every
point of the edge being a secondary source on the edge's line integral. The path transmitter
-> b mirrors -> edge -> a mirrors -> receiver is therefore the BTM line integral of the edge
(:mod:`.btm`, equation (1); physics.md section 4)

    h(t) = -(nu / 4 pi) Int delta(t - (m' + l') / c) beta(z; T_b, R_a) R(z) / (m' l') dz,

between the transmitter's image T_b across the b mirrors before the edge (in path order) and
the receiver's image R_a across the a mirrors after it (from the receiver back), m' and l' the
distances from the edge point to the two images (the unfolded legs), and R(z) the product of
the plane-wave reflection coefficients (``Material.reflection_coefficient``, as for specular
paths: physics convention, complex beyond a critical angle) at the point's reflection points.
A point of the edge takes part when its reflection points, traced back from it toward the
images, lie inside their mirrors (polygons, the exact discs of cylinder caps) and the path's
legs are clear.

This is exact, within first-order diffraction, for mirrors of infinite extent: e.g. a
half-plane standing on a rigid plane, edge perpendicular to it, is by images the half-plane
extended through the plane with the transmitter's image as a second source, whose field the
paths edge -> plane and plane -> edge give with the first-order path and the path plane ->
edge -> plane (``tests/physics/test_edge_reflections.py``). A finite mirror contributes where
its specular points are; its own rim diffracts on another path. Reflections on the wedge's own
faces are in the wedge's solution already: a mirror containing the edge is left out.

A curved reflector (sphere, cylinder side: :mod:`.curved`) reflects each edge point's wavelet
from its own specular point X (between the edge point and the receiver, or the transmitter and
the edge point). Tangent to the surface at X, a plane mirror would give the image R* = X +
|R - X| u (u the unit vector from the edge point to X): the element is integrated as above
between the transmitter and its own R* (the wavelet's direction and delay, exact), times the
divergence of the curved reflection relative to that plane mirror, D = g (r1 + r2), g the
geometric-optics factor of X (:func:`.curved.go_amplitude`, r1 and r2 the legs' lengths), and
the material's reflection coefficient at X (the same with the source's image before the edge).

Selection
---------
Near a geometric boundary (the straight path between the images, which the edge's wedge may
block, or its reflection in a face of the wedge) the diffracted field is of the order of the
geometric one and varies fast; away from all of them it is Keller's ray from the apex. The
Fresnel-Kirchhoff parameter of a pair (:func:`fresnel_parameter`)

    v = 2 sqrt(delta / lambda0),   delta = min over the edge of (m + l) - D,

D the length of the nearest such geometric path and lambda0 = c / f0, says which: the uniform
theory's transition function is 1 + j / (2 X) + O(X^-2), X = pi v^2 / 2 (Kouyoumjian & Pathak
1974). Pairs with |v| <= ``config.edge_reflection_fresnel_v`` (default 3: the shadows and
transition zones of sharp objects, e.g. the field diffracted around a prism into the shadow it
casts on a wall and back) are integrated here; the others are one row each at their apex
(:mod:`.edge_apex`, within 0.06 dB of this integral at |v| >= 3), unless the apex lies off the
edge or within an end's Fresnel zone (:func:`.edge_apex.stationary_points`): those are left out.
``edge_reflection_fresnel_v = None`` integrates every pair.

Method
------
For every split (b, a) of 1 <= b + a <= ``config.edge_reflections`` reflections:

1. the mirror sequences before the edge (the first facing the transmitter, the last facing a
   diffracting edge) and after it (the first facing an edge, the last a receiver), consecutive
   mirrors seeing each other (:meth:`~acoustisim.propagation.image_source.PlanarMirrors.sequences`),
   and their images (:func:`.image_source.unfold`: the transmitter forwards, each receiver
   backwards);
2. the pairs (edge, sequence before, sequence after, receiver) whose mirrors next to the edge
   have the edge in front of them, and whose images lie farther than
   :data:`~.edges.MIN_DISTANCE_M` from the edge line and in the wedge's water range (as
   :func:`.edges.edge_pairs` for the transducers);
3. the edges cut between the images as first-order edges are between the transducers
   (:func:`.edges.discretisation`, :mod:`.edge_elements`; chain joints where the neighbouring
   edge's pair with the same sequences is included);
4. each element's reflection points: :func:`.image_source.backtrace` from the element's centre
   on the edge to the images; elements whose points leave a mirror are dropped;
5. visibility: every leg transmitter -> reflection points -> the element's probe
   (:func:`.edges.element_probes`) -> reflection points -> receiver, in one batched Embree
   query (:meth:`~acoustisim.propagation.raycast.RayCaster.occluded`), a leg ending on a mirror
   ignoring that mirror's patch;
6. impulses as first order (:func:`.edges.edge_impulses`), each times its element's reflection
   product R (a real R keeps its sign in the gain; a complex one gives |R| and the phase -arg R);
7. rows (:func:`reflected_rows`): ``kind = EDGE``, ``order = 1 + b + a``, the reflection points
   and the edge point in path order in ``points_m`` and their surfaces in ``object_ids``; one
   ``path_id`` per (split, sequences, chain, receiver). The element floor is the first-order
   edges' (:data:`~.edges.ELEMENT_FLOOR` of the strongest edge impulse of the solve).

Curved reflectors (order 2, one reflection before or after the edge, :func:`curved_impulses`):
per (edge, reflector, receiver), a representative specular point (the first valid of the
edge's points at 1/2, 1/4, 3/4, 0 and 1 of its length) gives the image that places the
pair's elements and decides whether the pair diffracts (as step 2); each element then gets its
own specular point (dropped when there is none), image, wedge coordinates (dropped outside the
water range), legs (step 5, ignoring the reflector's patch at X), divergence and coefficient,
and is integrated with its own constants (:func:`.btm.pair_constants` of its image).

The per-element steps that only compute (discretisation, quadrature, back-tracing, leg tests)
come from :class:`ElementKernels`: :func:`reference_kernels` here, the fast engine's compiled
ones in :mod:`acoustisim.propagation.fast.edge_reflections`, around one orchestration.

Accuracy
--------
That of first-order BTM (:mod:`.edges`) for the discretisation and the quadrature, the image
method being exact for plane mirrors: against the exact half-plane standing on a rigid plane,
0.06 dB (``tests/physics/test_edge_reflections.py``). Approximations: the reflection points and
coefficients of an element are those of its centre (both of its impulses share them; the
coefficient's variation across an element is below 1e-4); plane-wave reflection coefficients
for the diffracted wave's local direction; an element's visibility is its probe's. Curved
reflectors: geometric optics at each element's specular point (the echo of a curved surface's
own edges and its creeping waves are not modelled), the element integrated with the image of
its centre's specular point (second order in the element's length). Not modelled: diffraction
by two edges, curved reflectors combined with planar mirrors around an edge.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any, NamedTuple

import numpy as np
from numpy.typing import NDArray

from acoustisim.propagation.config import SolverConfig
from acoustisim.propagation.context import SolveContext
from acoustisim.propagation.edge_extraction import DiffractingEdges
from acoustisim.propagation.image_source import PlanarMirrors
from acoustisim.propagation.paths import MAX_INTERACTIONS, PathKind, empty_paths_array
from acoustisim.propagation.prepared import PreparedScene
from acoustisim.propagation.reference.btm import WedgePairs, pair_constants, wedge_phis
from acoustisim.propagation.reference.curved import go_amplitude, specular_points
from acoustisim.propagation.reference.edge_elements import EdgeElements, PairGeometry, discretise_edges
from acoustisim.propagation.reference.edges import (ANGLE_TOLERANCE_RAD, MIN_DISTANCE_M, EdgeImpulses,
                                                    discretisation, edge_impulses, open_ends, too_many_elements)
from acoustisim.propagation.reference.image_source import backtrace, unfold
from acoustisim.propagation.reference.specular import REAL_TOLERANCE

FACING_TOLERANCE_M = 1e-9
"""An edge is in front of a mirror when an end lies more than this (m) in front of its plane."""

REPRESENTATIVE_FRACTIONS = (0.5, 0.25, 0.75, 0.0, 1.0)
"""Curved reflectors: the points of an edge (fractions of its length) tried in turn for the
pair's representative specular point."""


class ElementKernels(NamedTuple):
    """The per-element steps an engine supplies.

    ``discretise_edges(geometry, grid) -> EdgeElements``; ``edge_impulses(elements, constants,
    adaptive) -> EdgeImpulses``; ``backtrace(prepared, images, sequences, end) -> (points,
    valid)`` (:func:`.image_source.backtrace` on ``prepared.mirrors``); ``path_visibility(context,
    prepared, vertices (n, v, 3), patches (n, v), faces (n, v)) -> (n,) bool``: whether every leg
    of each path is clear, a leg ignoring the patches at its ends (``faces``: the tank box face
    each vertex lies on, -1 none, for screens); ``specular_points(curved_set, which, a, b) ->
    SurfacePoints`` (:func:`.curved.specular_points`).
    """

    discretise_edges: Callable[..., EdgeElements]
    edge_impulses: Callable[..., EdgeImpulses]
    backtrace: Callable[..., tuple[NDArray[np.float64], NDArray[np.bool_]]]
    path_visibility: Callable[..., NDArray[np.bool_]]
    specular_points: Callable[..., Any]


def reference_backtrace(prepared: PreparedScene, images: NDArray[np.float64], sequences: NDArray[np.int64],
                        end: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
    """:func:`.image_source.backtrace` on the prepared scene's mirrors."""
    return backtrace(prepared.mirrors, images, sequences, end)


def reference_path_visibility(context: SolveContext, prepared: PreparedScene, vertices: NDArray[np.float64],
                              patches: NDArray[np.int64], faces: NDArray[np.int64]) -> NDArray[np.bool_]:
    """Whether every leg of each path (n, v, 3) is clear: one batched Embree query
    (:meth:`~acoustisim.propagation.raycast.RayCaster.occluded`), a leg ignoring the patches
    (n, v) at its ends (``faces`` unused)."""
    n, v = vertices.shape[0], vertices.shape[1]
    exclude = np.stack([patches[:, :-1], patches[:, 1:]], axis=2).reshape(-1, 2)
    blocked = context.raycaster.occluded(vertices[:, :-1].reshape(-1, 3), vertices[:, 1:].reshape(-1, 3),
                                         exclude_patches=exclude)
    return ~blocked.reshape(n, v - 1).any(axis=1)


def reference_kernels() -> ElementKernels:
    """The reference engine's per-element steps."""
    return ElementKernels(discretise_edges, edge_impulses, reference_backtrace, reference_path_visibility,
                          specular_points)


class ImageSides(NamedTuple):
    """The mirror sequences around the edge for one split (b, a) and their images.

    Attributes
    ----------
    before : ndarray of int64, shape (sb, b)
        Sequences before the edge, in path order (one empty sequence when b = 0).
    source_images : ndarray, shape (sb, b + 1, 3)
        The transmitter and its images across them (m).
    source_valid : ndarray of bool, shape (sb,)
    after : ndarray of int64, shape (sa, a)
        Sequences after the edge, in path order.
    receiver_images : ndarray, shape (sa, n_rx, a + 1, 3)
        Each receiver and its images across them read backwards (m).
    receiver_valid : ndarray of bool, shape (sa, n_rx)
    """

    before: NDArray[np.int64]
    source_images: NDArray[np.float64]
    source_valid: NDArray[np.bool_]
    after: NDArray[np.int64]
    receiver_images: NDArray[np.float64]
    receiver_valid: NDArray[np.bool_]


class ReflectedPairs(NamedTuple):
    """The pairs of one split that diffract, shape (p,) each: ``edge``, ``receiver``, ``before``
    and ``after`` (planar splits: rows of :class:`ImageSides`' sequences; curved ones: the
    reflector on its side, -1 on the other); ``wedge`` and ``geometry`` as in
    :class:`~.edges.EdgePairs`, with the images in place of the transducers."""

    edge: NDArray[np.int64]
    receiver: NDArray[np.int64]
    before: NDArray[np.int64]
    after: NDArray[np.int64]
    wedge: WedgePairs
    geometry: PairGeometry


class SplitImpulses(NamedTuple):
    """The impulses of one split (b, a), with what their rows need.

    ``split`` (b, a); ``pairs``; ``surfaces`` (p, b + 1 + a) each pair's surfaces in path order
    (the mirrors before, the edge, the mirrors after); ``impulses``
    (:class:`~.edges.EdgeImpulses`, ``pair`` into ``pairs``, gains already times |R| or R);
    ``phase`` (n,) -arg R of complex factors (0 for real ones); ``element`` (n,) the element each
    impulse belongs to; ``before_points`` (e, b, 3) and ``after_points`` (e, a, 3) each
    element's reflection points in path order (m).
    """

    split: tuple[int, int]
    pairs: ReflectedPairs
    surfaces: NDArray[np.int64]
    impulses: EdgeImpulses
    phase: NDArray[np.float64]
    element: NDArray[np.int64]
    before_points: NDArray[np.float64]
    after_points: NDArray[np.float64]


def reflection_splits(max_reflections: int) -> list[tuple[int, int]]:
    """(b, a) of every split with 1 <= b + a <= ``max_reflections``, by order then b descending."""
    return [(total - a, a) for total in range(1, max_reflections + 1) for a in range(total + 1)]


def edges_facing(mirrors: PlanarMirrors, scene_edges: DiffractingEdges) -> NDArray[np.bool_]:
    """(m, e): some end of edge e lies more than :data:`FACING_TOLERANCE_M` in front of mirror m
    (a mirror containing the edge, one of its wedge's faces, does not face it)."""
    edges = scene_edges.edges
    offset = np.einsum("ik,ik->i", mirrors.point, mirrors.normal)
    ends = np.stack([edges.start_m, edges.end_m])  # (2, e, 3)
    height = np.einsum("sek,mk->mse", ends, mirrors.normal) - offset[:, None, None]
    return np.any(height > FACING_TOLERANCE_M, axis=1)


def boundary_faces(prepared: PreparedScene) -> NDArray[np.int64]:
    """The tank box face (2 axis + side; side 0 at the low bound) each mirror lies in, (m,); -1
    for mirrors that are not tank boundaries."""
    mirrors = prepared.mirrors
    axis = np.argmax(np.abs(mirrors.normal), axis=1)
    side = (mirrors.normal[np.arange(mirrors.count), axis] < 0.0).astype(np.int64)
    return np.where(mirrors.surface < len(prepared.scene.boundaries), 2 * axis + side, -1).astype(np.int64)


def image_sides(context: SolveContext, mirrors: PlanarMirrors, split: tuple[int, int],
                facing_any: NDArray[np.bool_]) -> ImageSides:
    """The sequences and images of ``split`` (see :class:`ImageSides`); ``facing_any`` (m,):
    mirrors some diffracting edge lies in front of."""
    n_before, n_after = split
    tx = np.asarray(context.transmitter_m, dtype=float)
    rx = np.asarray(context.receivers_m, dtype=float)
    n_rx = rx.shape[0]
    tx_front = mirrors.signed_distance(np.broadcast_to(tx, (mirrors.count, 3)), np.arange(mirrors.count)) > 0
    rx_front = np.any(np.einsum("rmk,mk->rm", rx[:, None, :] - mirrors.point, mirrors.normal) > 0, axis=0)
    before = mirrors.sequences(n_before, tx_front, facing_any)
    source_images, source_valid = unfold(mirrors, tx, before)
    after = mirrors.sequences(n_after, facing_any, rx_front)
    sequence = np.repeat(np.arange(after.shape[0]), n_rx)
    receiver = np.tile(np.arange(n_rx), after.shape[0])
    images, valid = unfold(mirrors, rx[receiver], after[sequence][:, ::-1])
    return ImageSides(before, source_images, source_valid, after,
                      images.reshape(after.shape[0], n_rx, n_after + 1, 3), valid.reshape(after.shape[0], n_rx))


def diffracting(scene_edges: DiffractingEdges, edge: NDArray[np.int64], source: NDArray[np.float64],
                receiver: NDArray[np.float64]) -> tuple[NDArray[np.bool_], WedgePairs]:
    """Whether each (edge, source, receiver) diffracts (both off the edge line, in the water's
    angular range: :func:`.edges.edge_pairs`' rule), and their wedge coordinates."""
    edges = scene_edges.edges.select(edge)
    r_s, theta_s, z_s = edges.local_coordinates(source)
    r_r, theta_r, z_r = edges.local_coordinates(receiver)
    theta_w = edges.wedge_angle_rad
    ok = ((r_s > MIN_DISTANCE_M) & (r_r > MIN_DISTANCE_M) & (theta_s <= theta_w + ANGLE_TOLERANCE_RAD)
          & (theta_r <= theta_w + ANGLE_TOLERANCE_RAD))
    return ok, WedgePairs(scene_edges.nu[edge], r_s, theta_s, z_s, r_r, theta_r, z_r, edges.pressure_release)


def fresnel_parameter(wedge: WedgePairs, length_m: NDArray[np.float64], wavelength_m: float) -> NDArray[np.float64]:
    """The smallest Fresnel-Kirchhoff parameter |v| of each pair's edge over the geometric
    boundaries of its wedge (Selection), shape (p,), >= 0.

    Each term of beta (:mod:`.btm`, phi one of pi +/- thS +/- thR) is singular on a boundary,
    nu phi = 2 pi k: the straight path between the source and the receiver (images) or its
    reflection in a face of the wedge grazes the edge there. phi' = phi - 2 pi k / nu (k the
    nearest) measures the distance from it: that geometric path is D = sqrt(L^2 - 2 rS rR
    (1 - cos phi')) long, L = sqrt((rS + rR)^2 + (zR - zS)^2), and v = 2 sqrt(delta / lambda),
    delta = L_e - D, L_e the least path via the finite edge (the apex clipped to [0,
    ``length_m``]). A term with |phi'| >= pi is far from every boundary it has (its cotangent
    is bounded there) and does not count.
    """
    dz = wedge.z_r - wedge.z_s
    z_apex = np.clip(wedge.z_s + dz * wedge.r_s / (wedge.r_s + wedge.r_r), 0.0, length_m)
    via_edge = np.hypot(wedge.r_s, z_apex - wedge.z_s) + np.hypot(wedge.r_r, wedge.z_r - z_apex)
    nu = wedge.nu[:, None]
    phi = wedge_phis(wedge.theta_s, wedge.theta_r)
    offset = phi - (2.0 * np.pi / nu) * np.round(nu * phi / (2.0 * np.pi))
    least = np.hypot(wedge.r_s + wedge.r_r, dz)[:, None]
    rsr = (wedge.r_s * wedge.r_r)[:, None]
    straight = np.sqrt(np.maximum(least**2 - 2.0 * rsr * (1.0 - np.cos(offset)), 0.0))
    v = 2.0 * np.sqrt(np.maximum(via_edge[:, None] - straight, 0.0) / wavelength_m)
    return np.min(np.where(np.abs(offset) < np.pi, v, np.inf), axis=1)


def within_reach(config: SolverConfig, context: SolveContext, scene_edges: DiffractingEdges, edge: NDArray[np.int64],
                 wedge: WedgePairs) -> NDArray[np.bool_]:
    """Whether each pair lies within ``config.edge_reflection_fresnel_v`` of a geometric
    boundary (Selection), (p,); every pair when it is None."""
    if config.edge_reflection_fresnel_v is None:
        return np.ones(edge.size, dtype=bool)
    wavelength = context.sound_speed_m_s / context.centre_frequency_hz
    return fresnel_parameter(wedge, scene_edges.length_m[edge], wavelength) <= config.edge_reflection_fresnel_v


def joint_geometry(scene_edges: DiffractingEdges, edge: NDArray[np.int64], combo: NDArray[np.int64], n_combos: int,
                   wedge: WedgePairs) -> PairGeometry:
    """The pairs' discretisation geometry, chain joints open where the neighbouring edge's pair
    with the same ``combo`` (images and receiver) diffracts too."""
    table = np.zeros((len(scene_edges.edges), n_combos), dtype=bool)
    table[edge, combo] = True
    open_start, open_end = open_ends(scene_edges, edge, combo, table)
    return PairGeometry(scene_edges.length_m[edge], wedge.r_s, wedge.z_s, wedge.r_r, wedge.z_r, open_start, open_end)


def reflected_pairs(config: SolverConfig, context: SolveContext, scene_edges: DiffractingEdges,
                    facing: NDArray[np.bool_], sides: ImageSides) -> tuple[ReflectedPairs, ReflectedPairs]:
    """The (edge, before, after, receiver) pairs of one planar split that diffract (Method, step
    2), edge-major, then before, after, receiver: those within reach and those beyond
    (Selection), each with its own chain joints."""
    n_edges = len(scene_edges.edges)
    n_before, n_after = sides.before.shape[1], sides.after.shape[1]
    n_rx = sides.receiver_valid.shape[1]
    e, b, a, r = (g.ravel() for g in np.meshgrid(np.arange(n_edges), np.arange(sides.before.shape[0]),
                                                 np.arange(sides.after.shape[0]), np.arange(n_rx), indexing="ij"))
    keep = sides.source_valid[b] & sides.receiver_valid[a, r]
    if n_before:
        keep &= facing[sides.before[b, -1], e]
    if n_after:
        keep &= facing[sides.after[a, 0], e]
    e, b, a, r = e[keep], b[keep], a[keep], r[keep]
    ok, wedge = diffracting(scene_edges, e, sides.source_images[b, -1], sides.receiver_images[a, r, -1])
    near = within_reach(config, context, scene_edges, e, wedge)
    n_combos = sides.before.shape[0] * sides.after.shape[0] * n_rx

    def subset(chosen: NDArray[np.bool_]) -> ReflectedPairs:
        e_, b_, a_, r_ = e[chosen], b[chosen], a[chosen], r[chosen]
        wedge_ = WedgePairs(*(column[chosen] for column in wedge))
        geometry = joint_geometry(scene_edges, e_, (b_ * sides.after.shape[0] + a_) * n_rx + r_, n_combos, wedge_)
        return ReflectedPairs(e_, r_, b_, a_, wedge_, geometry)

    return subset(ok & near), subset(ok & ~near)


def element_centres(scene_edges: DiffractingEdges, elements: EdgeElements, pairs: ReflectedPairs
                    ) -> NDArray[np.float64]:
    """Each element's centre on its edge (m), (n, 3)."""
    edge = pairs.edge[elements.pair]
    z = 0.5 * (elements.z_start_m + elements.z_end_m)
    return scene_edges.edges.start_m[edge] + z[:, None] * scene_edges.edges.direction[edge]


def reflection_points(prepared: PreparedScene, sides: ImageSides, pairs: ReflectedPairs,
                      element_pair: NDArray[np.int64], centres: NDArray[np.float64], kernels: ElementKernels
                      ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.bool_]]:
    """Each element's reflection points before and after the edge, in path order, (n, b, 3)
    and (n, a, 3) (m), and whether all lie inside their mirrors (n,)."""
    b, a, r = pairs.before[element_pair], pairs.after[element_pair], pairs.receiver[element_pair]
    centres = np.ascontiguousarray(centres)
    before_points, ok_before = kernels.backtrace(prepared, np.ascontiguousarray(sides.source_images[b]),
                                                 np.ascontiguousarray(sides.before[b]), centres)
    after_points, ok_after = kernels.backtrace(prepared, np.ascontiguousarray(sides.receiver_images[a, r]),
                                               np.ascontiguousarray(sides.after[a][:, ::-1]), centres)
    return before_points, after_points[:, ::-1], ok_before & ok_after


def path_vertices(context: SolveContext, receiver: NDArray[np.int64], before_points: NDArray[np.float64],
                  edge_points: NDArray[np.float64], after_points: NDArray[np.float64]) -> NDArray[np.float64]:
    """Transmitter, reflection points before, the edge point, reflection points after, receiver:
    (n, b + a + 3, 3) (m)."""
    n = edge_points.shape[0]
    tx = np.broadcast_to(np.asarray(context.transmitter_m, dtype=float), (n, 1, 3))
    rx = np.asarray(context.receivers_m, dtype=float)[receiver][:, None, :]
    return np.concatenate([tx, before_points, edge_points[:, None, :], after_points, rx], axis=1)


def coefficients(context: SolveContext, materials: tuple[Any, ...], codes: NDArray[np.int64],
                 cosine: NDArray[np.float64]) -> NDArray[np.complex128]:
    """R(cos theta_i) of each reflection (physics convention), ``codes`` indexing ``materials``."""
    factor = np.ones(cosine.size, dtype=complex)
    for code in np.unique(codes):  # a loop over the few materials
        on = codes == code
        factor[on] = materials[code].reflection_coefficient(cosine[on], context.density_kg_m3, context.sound_speed_m_s)
    return factor


def reflection_products(context: SolveContext, mirrors: PlanarMirrors, sequence: NDArray[np.int64],
                        n_before: int, vertices: NDArray[np.float64]) -> NDArray[np.complex128]:
    """prod over each path's planar reflections of R(cos theta_i) (physics convention), (n,)
    complex; ``sequence`` (n, b + a) its mirrors in path order, ``vertices`` its path
    (:func:`path_vertices`)."""
    at = np.r_[np.arange(1, 1 + n_before), np.arange(n_before + 2, vertices.shape[1] - 1)]  # reflection vertices
    product = np.ones(vertices.shape[0], dtype=complex)
    for j, vertex in enumerate(at):  # a loop over the path's one or two reflections
        incoming = vertices[:, vertex] - vertices[:, vertex - 1]
        length = np.linalg.norm(incoming, axis=1)
        cosine = np.abs(np.einsum("ij,ij->i", incoming, mirrors.normal[sequence[:, j]])) / np.where(length > 0,
                                                                                                  length, 1.0)
        product *= coefficients(context, mirrors.materials, mirrors.material[sequence[:, j]], cosine)
    return product


def times_factor(gain: NDArray[np.float64], factor: NDArray[np.complex128]) -> tuple[NDArray[np.float64],
                                                                                    NDArray[np.float64]]:
    """``gain`` times a complex ``factor`` as a row holds it: a real factor keeps its sign in the
    gain, a complex one gives |factor| and the phase -arg(factor) (rad); both (n,)."""
    real = np.abs(factor.imag) <= REAL_TOLERANCE * np.abs(factor)
    return gain * np.where(real, factor.real, np.abs(factor)), np.where(real, 0.0, -np.angle(factor))


def weighted(impulses: EdgeImpulses, element: NDArray[np.int64], factor: NDArray[np.complex128]
             ) -> tuple[EdgeImpulses, NDArray[np.float64]]:
    """``impulses`` times their element's complex ``factor`` (:func:`times_factor`), and their
    phases."""
    gain, phase = times_factor(impulses.gain, factor[element])
    return EdgeImpulses(impulses.pair, gain, impulses.z_m, impulses.path_length_m), phase


def split_impulses(context: SolveContext, config: SolverConfig, prepared: PreparedScene, split: tuple[int, int],
                   sides: ImageSides, pairs: ReflectedPairs, kernels: ElementKernels) -> SplitImpulses | None:
    """The impulses of one planar split's ``pairs`` within reach (Method, steps 3-6), or None
    when it has none."""
    scene_edges, mirrors = prepared.diffracting_edges, prepared.mirrors
    if pairs.edge.size == 0:
        return None
    try:
        elements = kernels.discretise_edges(pairs.geometry, discretisation(config, context))
    except ValueError as error:
        raise too_many_elements(config, error) from None
    centres = element_centres(scene_edges, elements, pairs)
    before_points, after_points, inside = reflection_points(prepared, sides, pairs, elements.pair, centres, kernels)
    alive = np.flatnonzero(inside)
    pair = elements.pair[alive]
    probes = centres[alive] + scene_edges.probe_offset_m[pairs.edge[pair]]
    sequence_b, sequence_a = sides.before[pairs.before[pair]], sides.after[pairs.after[pair]]
    none = np.full((alive.size, 1), -1, dtype=np.int64)
    faces = boundary_faces(prepared)
    visible = np.zeros(elements.pair.size, dtype=bool)
    vertices = path_vertices(context, pairs.receiver[pair], before_points[alive], probes, after_points[alive])
    visible[alive] = kernels.path_visibility(
        context, prepared, vertices,
        np.concatenate([none, mirrors.patch[sequence_b], none, mirrors.patch[sequence_a], none], axis=1),
        np.concatenate([none, faces[sequence_b], none, faces[sequence_a], none], axis=1))
    keep = np.flatnonzero(visible)
    if keep.size == 0:
        return None
    elements = elements.select(visible)
    before_points, after_points, centres = before_points[keep], after_points[keep], centres[keep]
    sequence = np.concatenate([sides.before[pairs.before[elements.pair]], sides.after[pairs.after[elements.pair]]],
                              axis=1)
    product = reflection_products(context, mirrors, sequence, split[0],
                                  path_vertices(context, pairs.receiver[elements.pair], before_points, centres,
                                                after_points))
    impulses = kernels.edge_impulses(elements, pair_constants(pairs.wedge), config.edge_adaptive)
    element = np.repeat(np.arange(elements.pair.size), impulses.gain.size // elements.pair.size)
    impulses, phase = weighted(impulses, element, product)
    surfaces = np.concatenate([mirrors.surface[sides.before[pairs.before]],
                               scene_edges.edges.surface[pairs.edge][:, None],
                               mirrors.surface[sides.after[pairs.after]]], axis=1)
    return SplitImpulses(split, pairs, surfaces, impulses, phase, element, before_points, after_points)


def curved_images(prepared: PreparedScene, reflector: NDArray[np.int64], edge_points: NDArray[np.float64],
                  far: NDArray[np.float64], after: bool, kernels: ElementKernels) -> tuple[NDArray[np.float64], Any]:
    """The image of ``far`` (the receiver after the edge, or the transmitter before it) across the
    tangent plane of its specular point on ``reflector`` from ``edge_points`` (each (n, 3)):
    X + |far - X| u, u the unit vector from the edge point to X; and the specular points
    (:class:`~acoustisim.propagation.curved.SurfacePoints`)."""
    a, b = (edge_points, far) if after else (far, edge_points)
    found = kernels.specular_points(prepared.curved_set, np.ascontiguousarray(reflector, dtype=np.int64),
                                    np.ascontiguousarray(a), np.ascontiguousarray(b))
    towards = found.point - edge_points
    towards /= np.linalg.norm(towards, axis=1, keepdims=True)
    return found.point + np.linalg.norm(far - found.point, axis=1)[:, None] * towards, found


def curved_pairs(config: SolverConfig, context: SolveContext, prepared: PreparedScene, after: bool,
                 kernels: ElementKernels) -> tuple[ReflectedPairs, ReflectedPairs]:
    """The (edge, reflector, receiver) pairs of one curved side that diffract, at a
    representative specular point (Method, curved reflectors), edge-major: those within reach
    and those beyond (Selection), each with its own chain joints."""
    scene_edges = prepared.diffracting_edges
    edges = scene_edges.edges
    tx = np.asarray(context.transmitter_m, dtype=float)
    rx = np.asarray(context.receivers_m, dtype=float)
    n_rx, n_curved = rx.shape[0], len(prepared.curved)
    e, c, r = (g.ravel() for g in np.meshgrid(np.arange(len(edges)), np.arange(n_curved), np.arange(n_rx),
                                              indexing="ij"))
    far = rx[r] if after else np.broadcast_to(tx, (e.size, 3))
    image = np.full((e.size, 3), np.nan)
    for fraction in REPRESENTATIVE_FRACTIONS:  # a few trial points per edge, vectorised over pairs
        todo = np.flatnonzero(np.isnan(image[:, 0]))
        point = edges.start_m[e[todo]] + fraction * (edges.end_m[e[todo]] - edges.start_m[e[todo]])
        trial, found = curved_images(prepared, c[todo], point, far[todo], after, kernels)
        image[todo[found.valid]] = trial[found.valid]
    live = np.flatnonzero(~np.isnan(image[:, 0]))
    e, c, r, image = e[live], c[live], r[live], image[live]
    source, receiver = (np.broadcast_to(tx, image.shape), image) if after else (image, rx[r])
    ok, wedge = diffracting(scene_edges, e, source, receiver)
    near = within_reach(config, context, scene_edges, e, wedge)

    def subset(chosen: NDArray[np.bool_]) -> ReflectedPairs:
        e_, c_, r_ = e[chosen], c[chosen], r[chosen]
        wedge_ = WedgePairs(*(column[chosen] for column in wedge))
        geometry = joint_geometry(scene_edges, e_, c_ * n_rx + r_, n_curved * n_rx, wedge_)
        none = np.full(e_.size, -1, dtype=np.int64)
        return ReflectedPairs(e_, r_, none if after else c_, c_ if after else none, wedge_, geometry)

    return subset(ok & near), subset(ok & ~near)


def curved_factor(context: SolveContext, prepared: PreparedScene, reflector: NDArray[np.int64], found: Any,
                  keep: NDArray[np.intp], a: NDArray[np.float64], b: NDArray[np.float64]) -> NDArray[np.complex128]:
    """The curved reflection's factor relative to the plane mirror of its tangent plane (Physics):
    D R exp(-j phase), D = g (r1 + r2) the divergence, R the coefficient at the specular point,
    for the points ``keep`` of ``found`` (:class:`~acoustisim.propagation.curved.SurfacePoints`)
    on ``reflector`` (k,) between ``a`` and ``b`` (k, 3) (m); complex, (k,)."""
    x = found.point[keep]
    spreading, go_phase = go_amplitude(a, b, x, found.normal[keep], found.e1[keep], found.e2[keep], found.k11[keep],
                                       found.k22[keep], found.k12[keep])
    r1, r2 = np.linalg.norm(x - a, axis=1), np.linalg.norm(x - b, axis=1)
    cosine = np.abs(np.einsum("ij,ij->i", x - a, found.normal[keep])) / r1
    materials = tuple(item.material for item in prepared.curved)
    return coefficients(context, materials, reflector, cosine) * spreading * (r1 + r2) * np.exp(-1j * go_phase)


def curved_impulses(context: SolveContext, config: SolverConfig, prepared: PreparedScene, after: bool,
                    pairs: ReflectedPairs, kernels: ElementKernels) -> SplitImpulses | None:
    """The impulses of the edge -> curved reflector (``after``) or curved reflector -> edge
    ``pairs`` within reach (Method, curved reflectors), or None when there are none."""
    scene_edges = prepared.diffracting_edges
    edges = scene_edges.edges
    if pairs.edge.size == 0:
        return None
    try:
        elements = kernels.discretise_edges(pairs.geometry, discretisation(config, context))
    except ValueError as error:
        raise too_many_elements(config, error) from None
    tx = np.asarray(context.transmitter_m, dtype=float)
    rx = np.asarray(context.receivers_m, dtype=float)
    reflector = (pairs.after if after else pairs.before)[elements.pair]
    edge = pairs.edge[elements.pair]
    receiver = pairs.receiver[elements.pair]
    centres = element_centres(scene_edges, elements, pairs)
    far = rx[receiver] if after else np.broadcast_to(tx, centres.shape)
    image, found = curved_images(prepared, reflector, centres, far, after, kernels)
    source, target = (np.broadcast_to(tx, image.shape), image) if after else (image, rx[receiver])
    ok, wedge = diffracting(scene_edges, edge, source, target)
    alive = np.flatnonzero(found.valid & ok)
    probes = centres[alive] + scene_edges.probe_offset_m[edge[alive]]
    x = found.point[alive]
    patch = np.array([item.patch for item in prepared.curved], dtype=np.int64)[reflector[alive]]
    n = alive.size
    tx_column = np.broadcast_to(tx, (n, 1, 3))
    rx_column = rx[receiver[alive]][:, None, :]
    middle = [probes[:, None, :], x[:, None, :]] if after else [x[:, None, :], probes[:, None, :]]
    none = np.full(n, -1, dtype=np.int64)
    patches = np.column_stack([none, none, patch, none] if after else [none, patch, none, none])
    visible = np.zeros(elements.pair.size, dtype=bool)
    visible[alive] = kernels.path_visibility(context, prepared, np.concatenate([tx_column, *middle, rx_column], axis=1),
                                             patches, np.full(patches.shape, -1, dtype=np.int64))
    keep = np.flatnonzero(visible)
    if keep.size == 0:
        return None
    a, b = (centres[keep], rx[receiver[keep]]) if after else (np.broadcast_to(tx, (keep.size, 3)), centres[keep])
    factor = curved_factor(context, prepared, reflector[keep], found, keep, a, b)
    x = found.point[keep]
    # each element integrated with its own image: its own constants
    own = EdgeElements(np.arange(keep.size), elements.z_start_m[keep], elements.z_end_m[keep],
                       elements.path_length_m[keep])
    impulses = kernels.edge_impulses(own, pair_constants(WedgePairs(*(column[keep] for column in wedge))),
                                     config.edge_adaptive)
    element = impulses.pair
    impulses = EdgeImpulses(elements.pair[keep][element], impulses.gain, impulses.z_m, impulses.path_length_m)
    impulses, phase = weighted(impulses, element, factor)
    surfaces_curved = np.array([item.surface for item in prepared.curved], dtype=np.int64)
    reflector_of_pair = surfaces_curved[pairs.after if after else pairs.before]
    edge_surface = edges.surface[pairs.edge]
    surfaces = np.column_stack([edge_surface, reflector_of_pair] if after else [reflector_of_pair, edge_surface])
    points = x[:, None, :]
    empty = np.zeros((keep.size, 0, 3))
    return SplitImpulses((0, 1) if after else (1, 0), pairs, surfaces, impulses, phase, element,
                         empty if after else points, points if after else empty)


class FarPairs(NamedTuple):
    """The pairs of one split beyond reach (Selection; :mod:`.edge_apex` makes their rows):
    ``split`` (b, a); ``sides`` the planar split's :class:`ImageSides` (None for a curved
    reflector); ``after`` (curved: the reflector after the edge); ``pairs``; the reach
    (``config.edge_reflection_fresnel_v``) they were selected with."""

    split: tuple[int, int]
    sides: ImageSides | None
    after: bool
    pairs: ReflectedPairs
    reach_v: float


class ReflectedParts(NamedTuple):
    """What :func:`reflected_impulses` finds: the impulses of the pairs within reach, one
    :class:`SplitImpulses` per split that has some, and the pairs beyond, one :class:`FarPairs`
    per split that has some."""

    impulses: list[SplitImpulses]
    far: list[FarPairs]


def reflected_impulses(context: SolveContext, config: SolverConfig, prepared: PreparedScene,
                       kernels: ElementKernels | None = None) -> ReflectedParts:
    """The impulses of every split of up to ``config.edge_reflections`` reflections within reach,
    and the pairs beyond: planar splits by :func:`reflection_splits`, then the curved reflector
    after, then before, the edge."""
    kernels = reference_kernels() if kernels is None else kernels
    scene_edges, mirrors = prepared.diffracting_edges, prepared.mirrors
    found: list[SplitImpulses | None] = []
    far: list[FarPairs] = []
    if len(scene_edges.edges) == 0 or config.edge_reflections == 0:
        return ReflectedParts([], [])
    reach = math.inf if config.edge_reflection_fresnel_v is None else float(config.edge_reflection_fresnel_v)
    if mirrors.count:
        facing = edges_facing(mirrors, scene_edges)
        for split in reflection_splits(config.edge_reflections):  # a loop over the few splits
            sides = image_sides(context, mirrors, split, np.any(facing, axis=1))
            near_pairs, far_pairs = reflected_pairs(config, context, scene_edges, facing, sides)
            found.append(split_impulses(context, config, prepared, split, sides, near_pairs, kernels))
            far.append(FarPairs(split, sides, False, far_pairs, reach))
    if prepared.curved:
        for after in (True, False):
            near_pairs, far_pairs = curved_pairs(config, context, prepared, after, kernels)
            found.append(curved_impulses(context, config, prepared, after, near_pairs, kernels))
            far.append(FarPairs((0, 1) if after else (1, 0), None, after, far_pairs, reach))
    return ReflectedParts([part for part in found if part is not None],
                          [part for part in far if part.pairs.edge.size])


def pair_path_index(parts: list[SplitImpulses], kept: list[NDArray[np.int64]], chain: NDArray[np.int64]
                    ) -> list[NDArray[np.int64]]:
    """Per part, each pair's path index (dense from 0 over the pairs with a kept impulse, in
    (part, before, after, chain, receiver) order; -1 for the others), shape (p,); ``kept`` the
    kept impulses of each part, ``chain`` each diffracting edge's chain."""
    used, keys = [], []
    for index, (part, keep) in enumerate(zip(parts, kept)):  # a loop over the few splits
        p = part.pairs
        mine = np.flatnonzero(np.bincount(part.impulses.pair[keep], minlength=p.edge.size) > 0)
        used.append(mine)
        keys.append(np.column_stack([np.full(mine.size, index), p.before[mine], p.after[mine], chain[p.edge[mine]],
                                     p.receiver[mine]]))
    out = [np.full(part.pairs.edge.size, -1, dtype=np.int64) for part in parts]
    stacked = np.concatenate(keys) if keys else np.zeros((0, 5), dtype=np.int64)
    if stacked.shape[0] == 0:
        return out
    _, index = np.unique(stacked, axis=0, return_inverse=True)
    index = index.reshape(-1)
    start = 0
    for mine, pair_index in zip(used, out):
        pair_index[mine] = index[start:start + mine.size]
        start += mine.size
    return out


class EdgePathBlock(NamedTuple):
    """Rows of edge paths of one split, shape (n,) each unless said: ``path_id``, ``receiver``,
    ``path_length_m`` (m), ``gain`` (1/m), ``phase`` (rad), ``response_id`` (-1: none);
    ``surfaces`` (n, order) and ``vertices`` (n, order + 2, 3) (:func:`path_vertices`, m) in path
    order."""

    path_id: NDArray[np.int64]
    receiver: NDArray[np.int64]
    path_length_m: NDArray[np.float64]
    gain: NDArray[np.float64]
    phase: NDArray[np.float64]
    response_id: NDArray[np.int64] | int
    surfaces: NDArray[np.int64]
    vertices: NDArray[np.float64]


def edge_path_rows(block: EdgePathBlock) -> NDArray[Any]:
    """The PATH_DTYPE rows (kind ``edge``, order from the vertices) of ``block``, the mechanism's
    columns only (the derived ones are left to the assembly)."""
    vertices = block.vertices
    order = vertices.shape[1] - 2
    rows = empty_paths_array(vertices.shape[0])
    rows["path_id"] = block.path_id
    rows["channel"] = block.receiver
    rows["kind"] = PathKind.EDGE
    rows["order"] = order
    rows["path_length_m"] = block.path_length_m
    rows["geometric_gain"] = block.gain
    rows["phase_rad"] = block.phase
    rows["response_id"] = block.response_id
    departure = vertices[:, 1] - vertices[:, 0]
    arrival = vertices[:, -1] - vertices[:, -2]
    rows["departure_dir"] = departure / np.linalg.norm(departure, axis=1, keepdims=True)
    rows["arrival_dir"] = arrival / np.linalg.norm(arrival, axis=1, keepdims=True)
    stored = min(order, MAX_INTERACTIONS)
    rows["object_ids"][:, :stored] = block.surfaces[:, :stored]
    rows["points_m"][:, :stored] = vertices[:, 1:1 + stored]
    return rows


def reflected_rows(context: SolveContext, prepared: PreparedScene, parts: list[SplitImpulses], floor: float,
                   first_path_id: int) -> NDArray[Any]:
    """The rows of the impulses of ``parts`` stronger than ``floor`` (|gain|), in (part, impulse)
    order, path ids from ``first_path_id`` (:func:`pair_path_index`)."""
    edges = prepared.diffracting_edges.edges
    kept = [np.flatnonzero(np.abs(part.impulses.gain) > floor) for part in parts]
    path_index = pair_path_index(parts, kept, edges.chain)
    blocks = []
    for part, strong, pair_index in zip(parts, kept, path_index):  # a loop over the few splits
        p = part.pairs
        pair = part.impulses.pair[strong]
        edge = p.edge[pair]
        element = part.element[strong]
        edge_points = edges.start_m[edge] + part.impulses.z_m[strong][:, None] * edges.direction[edge]
        vertices = path_vertices(context, p.receiver[pair], part.before_points[element], edge_points,
                                 part.after_points[element])
        blocks.append(edge_path_rows(EdgePathBlock(
            first_path_id + pair_index[pair], p.receiver[pair], part.impulses.path_length_m[strong],
            part.impulses.gain[strong], part.phase[strong], -1, part.surfaces[pair], vertices)))
    return np.concatenate(blocks) if blocks else empty_paths_array(0)


__all__ = ("EdgePathBlock", "ElementKernels", "FACING_TOLERANCE_M", "FarPairs", "ImageSides",
           "REPRESENTATIVE_FRACTIONS", "ReflectedPairs", "ReflectedParts", "SplitImpulses", "boundary_faces",
           "coefficients", "curved_factor", "curved_images", "curved_impulses", "curved_pairs", "diffracting",
           "edge_path_rows", "edges_facing", "element_centres", "fresnel_parameter", "image_sides", "joint_geometry",
           "pair_path_index", "path_vertices", "reference_backtrace", "reference_kernels", "reference_path_visibility",
           "reflected_impulses", "reflected_pairs", "reflected_rows", "reflection_points", "reflection_products",
           "reflection_splits", "split_impulses", "times_factor", "weighted", "within_reach")
