"""Edge diffraction combined with reflections, away from every geometric boundary: Keller's apex.

Physics
-------
Near its onset tau0 = L / c (L = sqrt((rS + rR)^2 + (zR - zS)^2), the least path via the edge
line, through the apex z* = zS + (zR - zS) rS / (rS + rR)), Medwin's closed form for the
infinite wedge (:mod:`.btm`, equation (2); physics.md section 4) has cosh(eta) - 1 =
c^2 (t^2 - tau0^2) / (2 rS rR), so eta ~ c sqrt(2 tau0 (t - tau0) / (rS rR)) and

    h(t) ~ -(nu beta0 / 2 pi) / sqrt(rS rR 2 tau0 (t - tau0)),   t > tau0,

beta0 = beta at eta = 0 = sum_i s_i cot(nu phi_i / 2). Its Fourier transform (engineering
convention, a delay d is exp(-j 2 pi f d)) is Keller's geometrical theory of diffraction
(Keller 1962, J. Opt. Soc. Am. 52, 116) for a point source, in BTM's normalisation:

    H(f) = A sqrt(f0 / f) exp(-j pi / 4) exp(-j 2 pi f tau0),
    A = -(nu beta0 / 2 pi) sqrt(pi c / (2 L rS rR 2 pi f0)),

the half-integrated pulse (-3 dB per octave, -45 deg) of a sharp edge. A diffracted wave that
comes back via planar mirrors is this between the images (the image method, as in
:mod:`.edge_reflections`), times the mirrors' reflection coefficients at the apex's reflection
points; via a curved reflector, between the transmitter and the image R* of the apex's own
specular point X, times the divergence D = g (r1 + r2) and the coefficient at X (g
:func:`.curved.go_amplitude`).

The expansion holds where beta0 is bounded, away from the geometric boundaries (the straight
path between the images, its reflections in the wedge's faces) where a term of beta is
singular: the uniform theory's transition function F(X), X = k L a = pi v^2 / 2 (v the
Fresnel-Kirchhoff parameter of :func:`.edge_reflections.fresnel_parameter`), is 1 + j / (2 X)
+ O(X^-2) (Kouyoumjian & Pathak 1974, Proc. IEEE 62, 1448), so beyond |v| = 3 (X = 14) Keller
is within 4 % (0.3 dB) of the uniform field. This module takes the pairs that
:mod:`.edge_reflections` does not integrate (``SolverConfig.edge_reflection_fresnel_v``).

Method
------
Per pair beyond reach (:func:`.edge_reflections.reflected_pairs` and
:func:`.edge_reflections.curved_pairs`: ``ReflectedParts.far``), its stationary point
(:func:`stationary_points`): the apex z* of its edge's line in the frame of its images, kept
when it lies on the segment (half-open, [0, L)) clear of both ends (each end's path longer by
delta with 2 sqrt(delta / lambda0) above the reach: a nearer end cuts a branch of the apex's
response within its Fresnel zone); a polygonal chain's joints are no ends, and a chain's
minimum may sit at a joint (the path shortening to the segment's end and lengthening along the
next). The amplitude is the stationary-phase form of the line integral (1) of :mod:`.btm`,

    A = -(nu beta0 / 4 pi) (1 / (m l)) sqrt(2 pi c / (w0 P'')),

P'' = rS^2 / m^3 + rR^2 / l^3 + kappa n . (u_S + u_R) the second derivative of the path length
along the edge (kappa n the chain's curvature vector from its tangents, u the unit vectors from
the images to the point); for a straight edge it is the A above. Points where P'' falls below
:data:`MIN_CURVATURE_RATIO` of the straight edge's (near a caustic of a rim) are left out. The
point's reflection points (back-traced toward the images as for an element), its visibility
(the element probe's legs), the product of the reflection coefficients and A make one row: kind
``edge``, order 1 + b + a, delay (m + l) / c, ``geometric_gain`` A (sign kept; times |R| and the
phase -arg R for a complex R), ``phase_rad`` -pi / 4, ``response_id``
:data:`~acoustisim.propagation.apex_response.APEX_RESPONSE_ID` (the solver's
:class:`~acoustisim.propagation.apex_response.ApexResponse` gives its sqrt(f0 / f)). On a
curved reflector the point and its specular point are found together: X from the
representative pair's point, the image R* of X, the point of the new image,
:data:`APEX_ITERATIONS` times.

Accuracy
--------
Against the BTM line integral of a long straight edge (``tests/physics/test_edge_apex.py``, a
half-plane and a 60-degree prism edge, the receiver swept towards the shadow boundary): at
|v| >= 3 the echo's peak within 0.06 dB and its waveform within 5 % rms (the line integral's own
accuracy); nearer the boundary Keller fails (0.8 dB at v = 1, 5.4 dB at v = 0.35), where the
pairs are integrated instead. On the thesis tank's default pose, against the same paths with
every pair integrated (``python benchmarks/edge_reflection_reach.py``): the ten strongest
Keller rows (the prism's apex and corners via the posts and the pipe) within 0.15 dB, the median
-0.11 dB; 80 % of the 158 rows within -2.4 and +4.0 dB. The largest differences are weak paths
where the apex row is not the whole arrival: the prism's edges via the side walls (-2.6 dB, the
edge's end arriving within 50 us of its apex) and the pipe's rims via the floor and the surface
(up to +6.7 dB: the polygon's 1.5 cm segments are as long as the rim's Fresnel zone, so the
integral sees straight pieces where the curvature term sees a smooth rim). Not modelled: an edge's
ends (each cuts a branch, a step in h(t) that Keller's apex lacks: a separate, weaker arrival
when the end lies many periods after the apex); pairs whose stationary point lies off their
edge or within an end's Fresnel zone (left out: at the thesis tank's default pose the strongest
is 36.9 dB below the strongest echo); and the low frequencies where k rS or k rR < 1
(sqrt(f0 / f) is held constant below
:data:`~acoustisim.propagation.apex_response.LOWEST_FREQUENCY_FRACTION` f0, where the seed's
pulse is 60 dB down).
"""

from __future__ import annotations

from typing import Any, NamedTuple

import numpy as np
from numpy.typing import NDArray

from acoustisim.propagation.context import SolveContext
from acoustisim.propagation.edge_extraction import DiffractingEdges
from acoustisim.propagation.apex_response import APEX_RESPONSE_ID
from acoustisim.propagation.paths import empty_paths_array
from acoustisim.propagation.prepared import PreparedScene
from acoustisim.propagation.reference.btm import WedgePairs, beta, least_time
from acoustisim.propagation.reference.edge_reflections import (EdgePathBlock, ElementKernels, FarPairs, ReflectedPairs,
                                                               boundary_faces, curved_factor, curved_images, diffracting,
                                                               edge_path_rows, path_vertices, reflection_points,
                                                               reflection_products, times_factor)

APEX_ITERATIONS = 3
"""Curved reflectors: rounds of (apex -> specular point -> image -> apex)."""

MIN_CURVATURE_RATIO = 0.1
"""A chain's stationary point is a ray of its own while the path's second derivative along it
is above this fraction of a straight edge's: nearer a caustic (the rim focusing the path)
stationary phase fails (the amplitude would exceed sqrt(10) times the straight edge's)."""


class ApexRows(NamedTuple):
    """The apex arrivals of one split, shape (p,) each unless said: ``split`` (b, a); ``pairs``;
    ``surfaces`` (p, b + 1 + a) in path order; ``gain`` A times the reflections' factor (1/m,
    signed); ``phase`` (rad, -pi / 4 - arg of a complex factor); ``z_m`` the apex on its edge
    (m); ``path_length_m`` L (m); ``before_points`` (p, b, 3) and ``after_points`` (p, a, 3) the
    reflection points in path order (m)."""

    split: tuple[int, int]
    pairs: ReflectedPairs
    surfaces: NDArray[np.int64]
    gain: NDArray[np.float64]
    phase: NDArray[np.float64]
    z_m: NDArray[np.float64]
    path_length_m: NDArray[np.float64]
    before_points: NDArray[np.float64]
    after_points: NDArray[np.float64]

    def select(self, keep: NDArray[np.intp]) -> "ApexRows":
        """The pairs ``keep``."""
        pairs = ReflectedPairs(*(column[keep] for column in self.pairs[:4]),
                               WedgePairs(*(column[keep] for column in self.pairs.wedge)),
                               type(self.pairs.geometry)(*(column[keep] for column in self.pairs.geometry)))
        return ApexRows(self.split, pairs, self.surfaces[keep], self.gain[keep], self.phase[keep], self.z_m[keep],
                        self.path_length_m[keep], self.before_points[keep], self.after_points[keep])


class StationaryPoints(NamedTuple):
    """Where each pair's edge path is stationary, shape (p,) each: ``z_m`` along the edge (m),
    ``path_length_m`` m + l there (m), ``amplitude`` A (1/m, Physics, before the phase
    -pi / 4), ``ok`` whether it is a ray of its own (Method)."""

    z_m: NDArray[np.float64]
    path_length_m: NDArray[np.float64]
    amplitude: NDArray[np.float64]
    ok: NDArray[np.bool_]


def stationary_points(scene_edges: DiffractingEdges, edge: NDArray[np.int64], wedge: WedgePairs,
                      source: NDArray[np.float64], receiver: NDArray[np.float64], sound_speed_m_s: float,
                      centre_frequency_hz: float, reach_v: float) -> StationaryPoints:
    """Each pair's stationary point and Keller amplitude (Physics, Method), between ``source``
    and ``receiver`` (the images, (p, 3), m) whose coordinates in the edge's frame ``wedge``
    holds."""
    edges = scene_edges.edges
    n_edges = len(edges)
    length = scene_edges.length_m[edge]
    start_partner, end_partner = scene_edges.partner[edge], scene_edges.partner[n_edges + edge]
    joint_start, joint_end = start_partner >= 0, end_partner >= 0
    tangent = edges.direction[edge]
    z_star, _ = least_time(wedge.r_s, wedge.z_s, wedge.r_r, wedge.z_r)

    def unit(v: NDArray[np.float64]) -> NDArray[np.float64]:
        return v / np.linalg.norm(v, axis=1, keepdims=True)

    # a chain's minimum at the joint after this segment: the path shortens to its end, then
    # lengthens along the next segment
    vertex = edges.end_m[edge]
    towards = unit(vertex - source) + unit(vertex - receiver)
    # the neighbours' tangents oriented along this segment's (a chain's segments may run either way)
    following = np.maximum(end_partner, 0)
    onwards = np.where(np.linalg.norm(edges.start_m[following] - vertex, axis=1)
                       <= np.linalg.norm(edges.end_m[following] - vertex, axis=1), 1.0, -1.0)
    next_tangent = onwards[:, None] * edges.direction[following]
    preceding = np.maximum(start_partner, 0)
    inwards = np.where(np.linalg.norm(edges.end_m[preceding] - edges.start_m[edge], axis=1)
                       <= np.linalg.norm(edges.start_m[preceding] - edges.start_m[edge], axis=1), 1.0, -1.0)
    slope_end = np.einsum("ij,ij->i", tangent, towards)
    slope_next = np.einsum("ij,ij->i", next_tangent, towards)
    at_joint = joint_end & (slope_end < 0.0) & (slope_next >= 0.0)
    inside = (z_star >= 0.0) & (z_star < length)
    z = np.where(inside, z_star, length)
    m, l = np.hypot(wedge.r_s, z - wedge.z_s), np.hypot(wedge.r_r, z - wedge.z_r)
    path = m + l
    wavelength = sound_speed_m_s / centre_frequency_hz
    clear = inside | at_joint
    for end, joint in ((np.zeros_like(length), joint_start), (length, joint_end)):  # a chain's joints are no ends
        via_end = np.hypot(wedge.r_s, end - wedge.z_s) + np.hypot(wedge.r_r, wedge.z_r - end)
        clear &= joint | (2.0 * np.sqrt(np.maximum(via_end - path, 0.0) / wavelength) > reach_v)
    # the chain's curvature vector kappa n at the point (central differences of its tangents)
    prev_tangent = np.where(joint_start[:, None], inwards[:, None] * edges.direction[preceding], tangent)
    after_tangent = np.where(joint_end[:, None], next_tangent, tangent)
    prev_length = np.where(joint_start, scene_edges.length_m[np.maximum(start_partner, 0)], 0.0)
    next_length = np.where(joint_end, scene_edges.length_m[np.maximum(end_partner, 0)], 0.0)
    curvature = np.where(at_joint[:, None], (after_tangent - tangent) / (0.5 * (length + next_length))[:, None],
                         (after_tangent - prev_tangent) / (0.5 * (prev_length + next_length) + length)[:, None])
    point = edges.start_m[edge] + z[:, None] * tangent
    straight = wedge.r_s**2 / m**3 + wedge.r_r**2 / l**3
    second = straight + np.einsum("ij,ij->i", curvature, unit(point - source) + unit(point - receiver))
    clear &= second > MIN_CURVATURE_RATIO * straight
    beta0 = beta(wedge.nu, np.zeros_like(wedge.r_s), wedge.theta_s, wedge.theta_r, wedge.pressure_release)
    omega0 = 2.0 * np.pi * centre_frequency_hz
    amplitude = -(wedge.nu * beta0 / (4.0 * np.pi)) / (m * l) * np.sqrt(
        2.0 * np.pi * sound_speed_m_s / (omega0 * np.maximum(second, MIN_CURVATURE_RATIO * straight)))
    return StationaryPoints(z, path, amplitude, clear)


def with_factor(gain: NDArray[np.float64], factor: NDArray[np.complex128]) -> tuple[NDArray[np.float64],
                                                                                   NDArray[np.float64]]:
    """``gain`` times a complex ``factor`` (:func:`.edge_reflections.times_factor`), the row
    phases with Keller's -pi / 4 added."""
    gain, phase = times_factor(gain, factor)
    return gain, phase - 0.25 * np.pi


def planar_apex_rows(context: SolveContext, prepared: PreparedScene, far: FarPairs, kernels: ElementKernels
                     ) -> ApexRows | None:
    """The apex arrivals of one planar split's pairs beyond reach, or None when it has none."""
    scene_edges, mirrors = prepared.diffracting_edges, prepared.mirrors
    split, sides, pairs = far.split, far.sides, far.pairs
    images = sides.source_images[pairs.before, -1], sides.receiver_images[pairs.after, pairs.receiver, -1]
    points = stationary_points(scene_edges, pairs.edge, pairs.wedge, *images, context.sound_speed_m_s,
                               context.centre_frequency_hz, far.reach_v)
    edges = scene_edges.edges
    apex = edges.start_m[pairs.edge] + points.z_m[:, None] * edges.direction[pairs.edge]
    index = np.arange(pairs.edge.size)
    before_points, after_points, inside = reflection_points(prepared, sides, pairs, index, apex, kernels)
    alive = np.flatnonzero(points.ok & inside)
    sequence_b, sequence_a = sides.before[pairs.before[alive]], sides.after[pairs.after[alive]]
    none = np.full((alive.size, 1), -1, dtype=np.int64)
    faces = boundary_faces(prepared)
    probes = apex[alive] + scene_edges.probe_offset_m[pairs.edge[alive]]
    visible = np.zeros(pairs.edge.size, dtype=bool)
    if alive.size:
        visible[alive] = kernels.path_visibility(
            context, prepared, path_vertices(context, pairs.receiver[alive], before_points[alive], probes,
                                             after_points[alive]),
            np.concatenate([none, mirrors.patch[sequence_b], none, mirrors.patch[sequence_a], none], axis=1),
            np.concatenate([none, faces[sequence_b], none, faces[sequence_a], none], axis=1))
    keep = np.flatnonzero(visible)
    if keep.size == 0:
        return None
    sequence = np.concatenate([sides.before[pairs.before[keep]], sides.after[pairs.after[keep]]], axis=1)
    product = reflection_products(context, mirrors, sequence, split[0],
                                  path_vertices(context, pairs.receiver[keep], before_points[keep], apex[keep],
                                                after_points[keep]))
    gain, phase = with_factor(points.amplitude[keep], product)
    surfaces = np.concatenate([mirrors.surface[sides.before[pairs.before]],
                               scene_edges.edges.surface[pairs.edge][:, None],
                               mirrors.surface[sides.after[pairs.after]]], axis=1)
    full = ApexRows(split, pairs, surfaces, np.zeros(pairs.edge.size), np.zeros(pairs.edge.size), points.z_m,
                    points.path_length_m, before_points, after_points).select(keep)
    return full._replace(gain=gain, phase=phase)


def curved_apex_rows(context: SolveContext, prepared: PreparedScene, far: FarPairs, kernels: ElementKernels
                     ) -> ApexRows | None:
    """The apex arrivals of the edge -> curved reflector (``far.after``) or curved reflector ->
    edge pairs beyond reach, or None when there are none."""
    scene_edges = prepared.diffracting_edges
    edges = scene_edges.edges
    after, pairs, reach = far.after, far.pairs, far.reach_v
    tx = np.asarray(context.transmitter_m, dtype=float)
    rx = np.asarray(context.receivers_m, dtype=float)
    reflector = pairs.after if after else pairs.before
    far_end = rx[pairs.receiver] if after else np.broadcast_to(tx, (pairs.edge.size, 3))
    images = ((np.broadcast_to(tx, far_end.shape), far_end) if after else (far_end, rx[pairs.receiver]))
    points = stationary_points(scene_edges, pairs.edge, pairs.wedge, *images, context.sound_speed_m_s,
                               context.centre_frequency_hz, reach)
    wedge, valid = pairs.wedge, np.ones(pairs.edge.size, dtype=bool)
    for _ in range(APEX_ITERATIONS):  # a fixed few rounds of the point's own specular point
        apex = edges.start_m[pairs.edge] + points.z_m[:, None] * edges.direction[pairs.edge]
        image, found = curved_images(prepared, reflector, apex, far_end, after, kernels)
        valid &= found.valid
        image = np.where(found.valid[:, None], image, far_end)
        source, target = (np.broadcast_to(tx, image.shape), image) if after else (image, rx[pairs.receiver])
        ok, wedge = diffracting(scene_edges, pairs.edge, source, target)
        valid &= ok
        points = stationary_points(scene_edges, pairs.edge, wedge, source, target, context.sound_speed_m_s,
                                   context.centre_frequency_hz, reach)
    apex = edges.start_m[pairs.edge] + points.z_m[:, None] * edges.direction[pairs.edge]
    image, found = curved_images(prepared, reflector, apex, far_end, after, kernels)
    alive = np.flatnonzero(valid & points.ok & found.valid)
    probes = apex[alive] + scene_edges.probe_offset_m[pairs.edge[alive]]
    x = found.point[alive]
    patch = np.array([item.patch for item in prepared.curved], dtype=np.int64)[reflector[alive]]
    n = alive.size
    none = np.full(n, -1, dtype=np.int64)
    middle = [probes[:, None, :], x[:, None, :]] if after else [x[:, None, :], probes[:, None, :]]
    patches = np.column_stack([none, none, patch, none] if after else [none, patch, none, none])
    visible = np.zeros(pairs.edge.size, dtype=bool)
    if n:
        visible[alive] = kernels.path_visibility(
            context, prepared, np.concatenate([np.broadcast_to(tx, (n, 1, 3)), *middle, rx[pairs.receiver[alive]][:, None, :]],
                                              axis=1), patches, np.full(patches.shape, -1, dtype=np.int64))
    keep = np.flatnonzero(visible)
    if keep.size == 0:
        return None
    a, b = (apex[keep], rx[pairs.receiver[keep]]) if after else (np.broadcast_to(tx, (keep.size, 3)), apex[keep])
    factor = curved_factor(context, prepared, reflector[keep], found, keep, a, b)
    gain, phase = with_factor(points.amplitude[keep], factor)
    surfaces_curved = np.array([item.surface for item in prepared.curved], dtype=np.int64)
    edge_surface = edges.surface[pairs.edge]
    surfaces = np.column_stack([edge_surface, surfaces_curved[reflector]] if after
                               else [surfaces_curved[reflector], edge_surface])
    reflection = found.point[:, None, :]
    empty = np.zeros((pairs.edge.size, 0, 3))
    full = ApexRows((0, 1) if after else (1, 0), pairs._replace(wedge=wedge), surfaces, np.zeros(pairs.edge.size),
                    np.zeros(pairs.edge.size), points.z_m, points.path_length_m,
                    empty if after else reflection, reflection if after else empty).select(keep)
    return full._replace(gain=gain, phase=phase)


def apex_parts(context: SolveContext, prepared: PreparedScene, far: list[FarPairs], kernels: ElementKernels
               ) -> list[ApexRows]:
    """The apex arrivals of the pairs beyond reach (``ReflectedParts.far``), one part per split
    that has some, in its order."""
    found = [planar_apex_rows(context, prepared, part, kernels) if part.sides is not None
             else curved_apex_rows(context, prepared, part, kernels) for part in far]
    return [part for part in found if part is not None]


def apex_rows(context: SolveContext, prepared: PreparedScene, parts: list[ApexRows], first_path_id: int
              ) -> NDArray[Any]:
    """The rows of ``parts`` (one per pair, in (part, pair) order), path ids from
    ``first_path_id``."""
    edges = prepared.diffracting_edges.edges
    blocks = []
    next_id = int(first_path_id)
    for part in parts:  # a loop over the few splits
        p = part.pairs
        edge_points = edges.start_m[p.edge] + part.z_m[:, None] * edges.direction[p.edge]
        vertices = path_vertices(context, p.receiver, part.before_points, edge_points, part.after_points)
        blocks.append(edge_path_rows(EdgePathBlock(next_id + np.arange(p.edge.size), p.receiver, part.path_length_m,
                                                   part.gain, part.phase, APEX_RESPONSE_ID, part.surfaces, vertices)))
        next_id += p.edge.size
    return np.concatenate(blocks) if blocks else empty_paths_array(0)


__all__ = ("APEX_ITERATIONS", "ApexRows", "MIN_CURVATURE_RATIO", "StationaryPoints", "apex_parts", "apex_rows",
           "curved_apex_rows", "planar_apex_rows", "stationary_points", "with_factor")
