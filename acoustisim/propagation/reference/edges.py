"""First-order edge diffraction: the Biot-Tolstoy-Medwin rows of every sharp edge of a scene.

Physics
-------
A wedge of exterior (water-side) angle theta_w, nu = pi / theta_w, diffracts a point source's
field into every direction; for a straight edge from z = 0 to z = L, in cylindrical coordinates
about it (r, theta from face 1 through the water, z), the diffracted impulse response relative
to the source's pressure at 1 m is the line integral of Svensson, Fred & Vanderkooy (1999),
``physics.md`` section 4::

    h(t) = -(nu / 4 pi) Int_0^L delta(t - (m + l) / c) beta(z) / (m l) dz
    m = sqrt(rS^2 + (z - zS)^2),  l = sqrt(rR^2 + (z - zR)^2)
    beta = sum_i s_i sin(nu phi_i) / (cosh(nu eta) - cos(nu phi_i)),
    phi_i in (pi + thS + thR, pi + thS - thR, pi - thS + thR, pi - thS - thR)
    cosh(eta) = (m l + (z - zS)(z - zR)) / (rS rR)

with s = (+, +, +, +) for a rigid wedge and (-, +, +, -) for a pressure-release one; for an
infinite edge it is Medwin's (1981) closed form, starting at the least-time ("apex") point
with a 1 / sqrt(t - tau0) singularity (:mod:`.btm` has both, and the treatment of the shadow
and reflection boundaries of Svensson & Calamia 2006). A sharp edge seen along its bisector
echoes the half-integrated pulse, falling as r^-3/2.

Boundary conditions (:func:`~acoustisim.propagation.edge_extraction.is_pressure_release`):
pressure-release materials (and ``fixed`` ones with a negative coefficient) diffract as
pressure-release wedges; every other material, the ``fluid`` ones (steel, PVC, concrete)
included, as a rigid wedge, the solution existing for the two ideal conditions only.

Method
------
For one pose, per (edge, receiver) pair (:func:`edge_pairs`) of the scene's diffracting edges
(:class:`~acoustisim.propagation.edge_extraction.DiffractingEdges`: integer-nu wedges such as
the tank's corners, and object edges lying in a tank boundary, are left out there), leaving out
pairs whose transmitter or receiver lies within :data:`MIN_DISTANCE_M` of the edge line or in
the wedge's solid angular range (behind both faces):

1. the edge is cut into elements about its least-time point (:mod:`.edge_elements`): delay
   step 1/(:data:`DELAY_STEPS_PER_PERIOD` f0) (22.5 degrees of phase at 2 f0, the top of the
   pulse's band), lengths capped at ``config.edge_segment_m``; with ``config.edge_adaptive``
   (the default) the graded discretisation (one step near each branch's onset, refined to
   1/128 step, and ends; doubling every :data:`GRADING` elements up to 2^:data:`COARSENING_LEVELS`
   steps, a quarter period, whose two rows lie at most 250 ns apart, denser than the Nyquist
   spacing of the pulse's band (580 ns for its -20 dB edge at 860 kHz); the cap growing by
   :data:`CAP_GROWTH` of the distance from the apex), else the fine one (one step everywhere);
2. an element counts when its centre, moved
   :data:`~acoustisim.propagation.edge_extraction.VISIBILITY_OFFSET_M` into the water along the
   wedge's bisector, sees the transmitter and its receiver: one batched Embree query
   (:meth:`~acoustisim.propagation.raycast.RayCaster.occluded`) of every leg;
3. each visible element's integral (:mod:`.btm`) becomes two impulses at its Gauss points
   (graded) or one at its mean delay (fine), each one ``PATH_DTYPE`` row: ``kind = EDGE``,
   ``order = 1``, ``path_length_m`` m + l, ``geometric_gain`` the (signed) weight, the point
   on the edge, the unit legs; the rows of one chain (a polygonal rim) and receiver share a
   ``path_id``, numbered densely in (chain, receiver) order from ``context.first_path_id``;
4. rows weaker than :data:`ELEMENT_FLOOR` of the strongest are dropped.

Accuracy
--------
Against a four times finer uniform reference (1/64-period steps, 0.15 mm elements), the
band-limited echo of the graded discretisation differs by -68 dB of each channel's strongest
edge echo, on an oblique free-edge prism and on the thesis tank's prism and polygonal pipe rim
alike, with 42 % and 48 % of the fine discretisation's rows; the fine discretisation by -81 and
-73 dB (``tests/physics/test_edges_adaptive.py``). Against Medwin's closed form: 1e-4 per 1 us
bin (:mod:`.btm`). Neglected: diffraction of higher order (edge to edge, edge to specular
surfaces), the finite impedance of ``fluid`` materials (treated as rigid), partial occlusion
within an element (its probe decides for it) and diffraction of the diffracted field by an
occluder (a hidden element contributes nothing), curved rims beyond their tessellation
(polygonal chains), and the dropped rows (-120 dB, far below a 12-bit ADC's 72 dB).
"""

from __future__ import annotations

from typing import Any, NamedTuple

import numpy as np
from numpy.typing import NDArray

from acoustisim.errors import InputError
from acoustisim.propagation.config import SolverConfig
from acoustisim.propagation.context import SolveContext
from acoustisim.propagation.edge_extraction import DiffractingEdges
from acoustisim.propagation.paths import PathKind, empty_paths_array
from acoustisim.propagation.prepared import PreparedScene
from acoustisim.propagation.reference.btm import (
    PairConstants,
    WedgePairs,
    element_gains,
    pair_constants,
    quadrature_points,
)
from acoustisim.propagation.reference.edge_elements import Discretisation, EdgeElements, PairGeometry, discretise_edges

DELAY_STEPS_PER_PERIOD = 16
"""The fine delay step is 1 / (DELAY_STEPS_PER_PERIOD f0)."""

COARSENING_LEVELS = 2
"""Graded discretisation: elements grow up to 2^2 = 4 delay steps (a quarter period)."""

GRADING = 4
"""Graded discretisation: elements per doubling of their length, counted from a branch's ends."""

CAP_GROWTH = 0.1
"""Graded discretisation: an element's length cap grows by this fraction of its distance from
the apex (``config.edge_segment_m`` at the apex)."""

ONSET_NODES = 7
"""Graded discretisation: nodes at 1/128, 1/64, ..., 1/2 of a step after each branch's start."""

ELEMENT_FLOOR = 1e-6
"""Rows weaker than this fraction of the strongest edge row are dropped."""

MAX_ELEMENTS = 20_000_000
"""Most edge elements one solve may make (about 4 GB of rows): beyond it the configuration is
refused rather than exhausting memory."""

MIN_DISTANCE_M = 1e-6
"""A transmitter or receiver closer than this to an edge line is not diffracted by it (m)."""

ANGLE_TOLERANCE_RAD = 1e-12
"""A transmitter or receiver up to this beyond face 2 (theta > theta_w) still counts as on it."""


class EdgePairs(NamedTuple):
    """The (edge, receiver) pairs that diffract for one pose, shape (p,) each.

    ``edge`` (index into ``DiffractingEdges.edges``) and ``receiver`` (channel) of each pair;
    ``wedge`` its wedge and the two ends' coordinates in the wedge's frame; ``geometry`` the
    same for the discretisation, with the chain joints at its edge's ends.
    """

    edge: NDArray[np.int64]
    receiver: NDArray[np.int64]
    wedge: WedgePairs
    geometry: PairGeometry


def open_ends(scene_edges: DiffractingEdges, edge: NDArray[np.int64], receiver: NDArray[np.int64],
              included: NDArray[np.bool_]) -> tuple[NDArray[np.bool_], NDArray[np.bool_]]:
    """Whether each pair's edge continues past its start (its end) into another edge of its
    chain whose pair with that receiver is also ``included`` (shape (n_edges, n_rx)): a joint
    of a polygonal chain, where the summed response has no step. Shapes (p,)."""
    n = len(scene_edges.edges)
    partner_at_start = scene_edges.partner[edge]
    partner_at_end = scene_edges.partner[n + edge]
    open_start = (partner_at_start >= 0) & included[np.maximum(partner_at_start, 0), receiver]
    open_end = (partner_at_end >= 0) & included[np.maximum(partner_at_end, 0), receiver]
    return open_start, open_end


def edge_pairs(context: SolveContext, scene_edges: DiffractingEdges) -> EdgePairs:
    """Every (edge, receiver) pair that diffracts, edge-major: both ends farther than
    :data:`MIN_DISTANCE_M` from the edge line and in the water's angular range of the wedge."""
    edges = scene_edges.edges
    n_edges = len(edges)
    tx = np.asarray(context.transmitter_m, dtype=float)
    rx = np.asarray(context.receivers_m, dtype=float)
    n_rx = rx.shape[0]
    r_s, theta_s, z_s = edges.local_coordinates(np.broadcast_to(tx, (n_edges, 3)))
    edge = np.repeat(np.arange(n_edges), n_rx)
    receiver = np.tile(np.arange(n_rx), n_edges)
    r_r, theta_r, z_r = edges.select(edge).local_coordinates(rx[receiver])
    theta_w = edges.wedge_angle_rad[edge]
    included = ((r_s[edge] > MIN_DISTANCE_M) & (r_r > MIN_DISTANCE_M)
                & (theta_s[edge] <= theta_w + ANGLE_TOLERANCE_RAD) & (theta_r <= theta_w + ANGLE_TOLERANCE_RAD))
    edge, receiver = edge[included], receiver[included]
    r_r, theta_r, z_r = r_r[included], theta_r[included], z_r[included]
    open_start, open_end = open_ends(scene_edges, edge, receiver, included.reshape(n_edges, n_rx))
    wedge = WedgePairs(scene_edges.nu[edge], r_s[edge], theta_s[edge], z_s[edge], r_r, theta_r, z_r,
                       edges.pressure_release[edge])
    geometry = PairGeometry(scene_edges.length_m[edge], wedge.r_s, wedge.z_s, r_r, z_r, open_start, open_end)
    return EdgePairs(edge, receiver, wedge, geometry)


def discretisation(config: SolverConfig, context: SolveContext) -> Discretisation:
    """The graded (``config.edge_adaptive``) or fine discretisation of the solve."""
    step = context.sound_speed_m_s / (DELAY_STEPS_PER_PERIOD * context.centre_frequency_hz)
    if config.edge_adaptive:
        return Discretisation(step, config.edge_segment_m, COARSENING_LEVELS, GRADING, CAP_GROWTH, ONSET_NODES,
                              MAX_ELEMENTS)
    return Discretisation(step, config.edge_segment_m, 0, GRADING, 0.0, 1, MAX_ELEMENTS)


def too_many_elements(config: SolverConfig, error: ValueError) -> InputError:
    """The error of a configuration whose elements would exceed :data:`MAX_ELEMENTS`."""
    return InputError(f"solver.edge_segment_m = {config.edge_segment_m!r}: {error}; use a larger value")


class EdgeImpulses(NamedTuple):
    """The impulses the visible elements make, shape (n,) each: ``pair``, ``gain`` (1/m,
    signed), position ``z_m`` along the edge (m) and ``path_length_m`` m + l (m)."""

    pair: NDArray[np.int64]
    gain: NDArray[np.float64]
    z_m: NDArray[np.float64]
    path_length_m: NDArray[np.float64]


def element_probes(scene_edges: DiffractingEdges, elements: EdgeElements, pairs: EdgePairs) -> NDArray[np.float64]:
    """Each element's visibility probe: its centre moved along the wedge's bisector (m), (n, 3)."""
    edge = pairs.edge[elements.pair]
    centre = 0.5 * (elements.z_start_m + elements.z_end_m)
    edges = scene_edges.edges
    return edges.start_m[edge] + centre[:, None] * edges.direction[edge] + scene_edges.probe_offset_m[edge]


def element_visibility(context: SolveContext, prepared: PreparedScene, elements: EdgeElements,
                       pairs: EdgePairs) -> NDArray[np.bool_]:
    """Whether each element's probe sees the transmitter and its receiver, shape (n,): one
    batched Embree query of every leg (a receiver at the transmitter has no leg of its own)."""
    n = elements.pair.size
    probes = element_probes(prepared.diffracting_edges, elements, pairs)
    tx = np.asarray(context.transmitter_m, dtype=float)
    rx = np.asarray(context.receivers_m, dtype=float)
    receiver = pairs.receiver[elements.pair]
    own_leg = ~np.all(rx == tx, axis=1)[receiver]
    origins = np.concatenate([probes, probes[own_leg]])
    targets = np.concatenate([np.broadcast_to(tx, probes.shape), rx[receiver[own_leg]]])
    blocked = context.raycaster.occluded(origins, targets)
    visible = ~blocked[:n]
    visible[own_leg] &= ~blocked[n:]
    return visible


def edge_impulses(elements: EdgeElements, constants: PairConstants, adaptive: bool) -> EdgeImpulses:
    """The elements' impulses: two at each element's Gauss points (``adaptive``, the graded
    discretisation) or one at its centre and mean path length (the fine one)."""
    if adaptive:
        points = quadrature_points(elements, constants)
        return EdgeImpulses(np.repeat(elements.pair, points.gain.shape[1]), points.gain.reshape(-1),
                            points.z_m.reshape(-1), points.path_length_m.reshape(-1))
    return EdgeImpulses(elements.pair, element_gains(elements, constants),
                        0.5 * (elements.z_start_m + elements.z_end_m), elements.path_length_m)


def impulse_rows(context: SolveContext, scene_edges: DiffractingEdges, pairs: EdgePairs,
                 impulses: EdgeImpulses) -> NDArray[Any]:
    """The ``PATH_DTYPE`` rows of ``impulses``, path ids dense in (chain, receiver) order."""
    edges = scene_edges.edges
    edge = pairs.edge[impulses.pair]
    channel = pairs.receiver[impulses.pair]
    tx = np.asarray(context.transmitter_m, dtype=float)
    rx = np.asarray(context.receivers_m, dtype=float)
    points = edges.start_m[edge] + impulses.z_m[:, None] * edges.direction[edge]
    departure = points - tx
    arrival = rx[channel] - points
    _, path_index = np.unique(edges.chain[edge] * rx.shape[0] + channel, return_inverse=True)
    rows = empty_paths_array(impulses.gain.size)
    rows["path_id"] = context.first_path_id + path_index.reshape(-1)
    rows["channel"] = channel
    rows["kind"] = PathKind.EDGE
    rows["order"] = 1
    rows["path_length_m"] = impulses.path_length_m
    rows["geometric_gain"] = impulses.gain
    rows["departure_dir"] = departure / np.linalg.norm(departure, axis=1)[:, None]
    rows["arrival_dir"] = arrival / np.linalg.norm(arrival, axis=1)[:, None]
    rows["object_ids"][:, 0] = edges.surface[edge]
    rows["points_m"][:, 0] = points
    return rows


def first_order_impulses(context: SolveContext, config: SolverConfig, prepared: PreparedScene
                         ) -> tuple[EdgePairs, EdgeImpulses]:
    """Steps 1-3 of the module docstring: the (edge, receiver) pairs of one pose and the
    impulses of their visible elements, before the element floor.

    Raises
    ------
    InputError
        If ``config.edge_segment_m`` would make more than :data:`MAX_ELEMENTS` elements.
    """
    pairs = edge_pairs(context, prepared.diffracting_edges)
    impulses = EdgeImpulses(np.zeros(0, dtype=np.int64), np.zeros(0), np.zeros(0), np.zeros(0))
    if pairs.edge.size:
        try:
            elements = discretise_edges(pairs.geometry, discretisation(config, context))
        except ValueError as error:
            raise too_many_elements(config, error) from None
        elements = elements.select(element_visibility(context, prepared, elements, pairs))
        impulses = edge_impulses(elements, pair_constants(pairs.wedge), config.edge_adaptive)
    return pairs, impulses


__all__ = ("ANGLE_TOLERANCE_RAD", "CAP_GROWTH", "COARSENING_LEVELS", "DELAY_STEPS_PER_PERIOD", "ELEMENT_FLOOR",
           "EdgeImpulses", "EdgePairs", "GRADING", "MAX_ELEMENTS", "MIN_DISTANCE_M", "ONSET_NODES", "discretisation",
           "edge_impulses", "edge_pairs", "element_probes", "element_visibility", "first_order_impulses",
           "impulse_rows",
           "open_ends", "too_many_elements")
