"""First-order edge diffraction of a scene: the Biot-Tolstoy-Medwin rows of every sharp edge.

For each sharp edge (:mod:`acoustisim.propagation.edge_extraction`) and each receiver, the
edge is discretised about its least-time point (:mod:`acoustisim.propagation.btm`) and every
element whose centre is visible from the transmitter and from the receiver becomes two
``PATH_DTYPE`` rows, at its two Gauss points (``config.edge_adaptive``, the default), or one
row (the fine discretisation):
``kind = EDGE``, ``order = 1``, delay ``(m + l) / c``, ``geometric_gain`` the element's
integral of ``-(nu / 4 pi) beta / (m l) dz`` (signed), so that the sum of the rows of one edge
and receiver is its band-limited impulse response relative to the source's pressure at 1 m.
All elements of one (polygonal) edge and one receiver share a ``path_id``.

Boundary conditions (:func:`~acoustisim.propagation.edge_extraction.is_pressure_release`):
pressure-release materials (and ``fixed`` ones with a negative coefficient) diffract as
pressure-release wedges; every other material, the ``fluid`` ones (steel, PVC, concrete)
included, as a rigid wedge, the BTM solution existing for the two ideal conditions only.

Discretisation: the fine step between neighbouring element boundaries is a delay of 1/(16 f0)
(22.5 degrees of phase at 2 f0, the top of the pulse's band), elements at most
``config.edge_segment_m`` long. The graded discretisation (default) keeps that step near each
branch's onset (refined geometrically down to 1/128 step) and ends, and doubles it every
:data:`GRADING` elements away from them up to 2^:data:`COARSENING_LEVELS` steps (1/4 period:
rows every 125 ns on average, above the Nyquist rate of the pulse's band, so its aliases stay
out of it); the length cap grows by :data:`CAP_GROWTH` times the distance from the apex. A
branch starting at a joint of a polygonal chain (a rim segment whose apex lies beyond its end)
grades from its line's apex. Each element is two impulses at its Gauss points, a quadrature of
the band-limited response exact to third order in the phase across an element (one impulse per
box-integrated element, as in the fine discretisation, low-passes the response by
sinc(f dt): -0.06 dB at 500 kHz for dt = 1/(16 f0)). Measured against a 4x finer uniform
reference (``tests/physics/test_edges_adaptive.py``), the band-limited echo differs by -68 dB (oblique
free-edge prism; fine discretisation -75 dB) and -49 dB (thesis tank's prism and pipe rim;
fine: -52 dB) of each channel's strongest edge echo, with 48 % of the fine discretisation's
rows on the thesis tank.

Edges left out, each for a physical reason:

* wedges whose index nu = pi / theta_w is an integer (the tank's 90-degree corners, nu = 2):
  beta vanishes identically there (the four terms cancel in pairs), the image-source field
  being exact;
* object edges lying in a tank boundary plane (a prism's or a post's rim standing on the floor
  or touching the free surface): they are not wedges in the water;
* pairs whose transmitter or receiver lies within 1 um of the edge line or inside the wedge's
  solid angular range (behind both faces).

Elements whose gain is below 1e-6 of the strongest element (-120 dB, far below a 12-bit
ADC's 72 dB) are dropped.

The per-element work (discretisation, visibility segments, Gauss-point gains, rows) runs in the
compiled loops of :mod:`acoustisim.propagation.edge_kernels`. Visibility: the legs that can be
decided exactly without Embree are (:mod:`acoustisim.propagation.edge_visibility`: all of them
on the thesis tank), the others go to Embree in one batch, with the same answers. With
``sort_rows`` the rows come out in the solver's order (:mod:`acoustisim.propagation.edge_order`).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from acoustisim.errors import InputError
from acoustisim.propagation.btm import EdgeElements, discretise_edges, gauss_rule, pair_constants
from acoustisim.propagation.config import SolverConfig
from acoustisim.propagation.context import SolveContext
from acoustisim.propagation.edge_extraction import SharpEdges, sharp_edges
from acoustisim.propagation.edge_kernels import fill_edge_rows, gauss_point_gains, visibility_rays32
from acoustisim.propagation.edge_order import solver_order
from acoustisim.propagation.edge_visibility import VisibilityScreen, screened_visibility_rays32
from acoustisim.propagation.paths import PATH_DTYPE, PathKind, empty_paths_array
from acoustisim.propagation.raycast import DEFAULT_EPS_M
from acoustisim.scene import Scene

DELAY_STEPS_PER_PERIOD = 16
"""Element delay step = 1 / (DELAY_STEPS_PER_PERIOD f0)."""

COARSENING_LEVELS = 2
"""Graded discretisation (``config.edge_adaptive``): elements grow up to 2^3 delay steps."""

GRADING = 4
"""Graded discretisation: elements per doubling of their length, counted from a branch's ends."""

CAP_GROWTH = 0.1
"""Graded discretisation: an element's length cap grows by this fraction of its distance from
the apex (``config.edge_segment_m`` at the apex)."""

ONSET_NODES = 7
"""Graded discretisation: nodes at 1/128, 1/64, ..., 1/2 of a step after each branch's start."""

GAUSS_POINTS = 2
"""Graded discretisation: impulses (Gauss-Legendre points) per element."""

ELEMENT_FLOOR = 1e-6
"""Elements weaker than this fraction of the strongest element are dropped."""

VISIBILITY_OFFSET_M = 2e-4
"""Element points are moved this far into the water along the wedge bisector before the
visibility tests, so that the wedge's own faces never block a leg (float32 Embree round-off is
about 5e-7 m in the tank)."""

MAX_ELEMENTS = 20_000_000
"""Most edge elements one solve may make (about 4 GB of rows): beyond it the configuration is
refused rather than exhausting memory."""

_ZEROED_FIELDS = ("delay_s", "phase_rad", "angle_tx_rad", "angle_rx_rad", "directivity_tx", "directivity_rx",
                  "absorption_db", "amplitude")
"""The PATH_DTYPE fields edge rows leave zero (no extra phase; the derived columns, which the
solver fills)."""

_MIN_DISTANCE_M = 1e-6
_ON_PLANE_M = 1e-6


def diffracting_edges(edges: SharpEdges, context: SolveContext | Scene) -> SharpEdges:
    """The edges that diffract (see the module docstring for what is left out), of the scene
    (or the solve context's scene)."""
    scene = context.scene if isinstance(context, SolveContext) else context
    nu = edges.nu
    integer_nu = np.abs(nu - np.round(nu)) < 1e-9
    embedded = np.zeros(len(edges), dtype=bool)
    n_boundaries = len(scene.boundaries)
    for boundary in scene.boundaries:  # a loop over the six tank planes
        p = np.asarray(boundary.plane.point_m, dtype=float)
        n = np.asarray(boundary.plane.normal, dtype=float)
        on = (np.abs((edges.start_m - p) @ n) < _ON_PLANE_M) & (np.abs((edges.end_m - p) @ n) < _ON_PLANE_M)
        embedded |= on & (edges.surface >= n_boundaries)
    return edges.select(~integer_nu & ~embedded & (edges.length_m > 0.0))


def _endpoint_partners(edges: SharpEdges) -> NDArray[np.int64]:
    """For each endpoint of ``edges`` ([starts; ends], shape (2 n,)), the other edge of its
    chain sharing that exact point (shared vertices are bit-identical), or -1."""
    n = len(edges)
    # endpoints [starts; ends], keyed by chain and position
    points = np.concatenate([edges.start_m, edges.end_m])
    keys = np.concatenate([np.tile(edges.chain, 2)[:, None].astype(float), points], axis=1)
    _, inverse, counts = np.unique(keys, axis=0, return_inverse=True, return_counts=True)
    inverse = inverse.reshape(-1)
    order = np.argsort(inverse, kind="stable")
    partner = np.full(2 * n, -1, dtype=np.int64)
    shared = counts[inverse[order]] == 2
    # endpoints of a group of two are consecutive in ``order``: pair them up
    first = order[shared][0::2]
    second = order[shared][1::2]
    partner[first], partner[second] = second % n, first % n
    return partner


def _open_ends(
    edges: SharpEdges, pair_edge: NDArray[np.int64], pair_rx: NDArray[np.int64], included: NDArray[np.bool_],
    partner: NDArray[np.int64] | None = None,
) -> tuple[NDArray[np.bool_], NDArray[np.bool_]]:
    """For each (edge, receiver) pair, whether its edge continues past its start (its end) into
    another edge of its chain whose pair with that receiver is also included: a joint of a
    polygonal chain, where the summed response has no step.

    Parameters
    ----------
    edges : SharpEdges
        The diffracting edges, n of them.
    pair_edge, pair_rx : ndarray of int64, shape (p,)
        The pairs' edges and receivers.
    included : ndarray of bool, shape (n, n_rx)
        Which (edge, receiver) pairs are diffracted at all.
    partner : ndarray of int64, shape (2 n,), optional
        :func:`_endpoint_partners` of ``edges`` (computed when None).

    Returns
    -------
    open_start, open_end : ndarray of bool, shape (p,)
    """
    n = len(edges)
    if partner is None:
        partner = _endpoint_partners(edges)
    open_start = np.zeros(pair_edge.size, dtype=bool)
    open_end = np.zeros(pair_edge.size, dtype=bool)
    for out, side in ((open_start, 0), (open_end, 1)):
        other = partner[side * n + pair_edge]
        out[:] = (other >= 0) & included[np.maximum(other, 0), pair_rx]
    return open_start, open_end


@dataclass(frozen=True, eq=False)
class DiffractingEdges:
    """The per-scene part of edge diffraction, built once per prepared scene
    (:attr:`~acoustisim.propagation.prepared.PreparedScene.diffracting_edges`) and reused by
    every pose.

    Attributes
    ----------
    edges : SharpEdges
        The edges that diffract (:func:`diffracting_edges`), n of them.
    length_m : ndarray, shape (n,)
        Their lengths (m).
    nu : ndarray, shape (n,)
        Their wedge indices pi / theta_w.
    partner : ndarray of int64, shape (2 n,)
        :func:`_endpoint_partners`: the chain joints.
    probe_offset_m : ndarray, shape (n, 3)
        :data:`VISIBILITY_OFFSET_M` along each wedge's bisector (m): the visibility probes'
        offset from the edge into the water.
    screen : VisibilityScreen
        The scene's part of the visibility screen
        (:mod:`~acoustisim.propagation.edge_visibility`).
    """

    edges: SharpEdges
    length_m: NDArray[np.float64] = field(repr=False)
    nu: NDArray[np.float64] = field(repr=False)
    partner: NDArray[np.int64] = field(repr=False)
    probe_offset_m: NDArray[np.float64] = field(repr=False)
    screen: VisibilityScreen = field(repr=False)

    @classmethod
    def build(cls, sharp: SharpEdges, scene: Scene) -> "DiffractingEdges":
        """From a scene's sharp edges (:func:`~acoustisim.propagation.edge_extraction.sharp_edges`)."""
        edges = diffracting_edges(sharp, scene)
        half = 0.5 * edges.wedge_angle_rad
        bisector = np.cos(half)[:, None] * edges.face_dir + np.sin(half)[:, None] * edges.face_normal
        return cls(edges, edges.length_m, edges.nu, _endpoint_partners(edges), VISIBILITY_OFFSET_M * bisector,
                   VisibilityScreen.create(scene))


def element_visibility(context: SolveContext, scene_part: DiffractingEdges, elements: EdgeElements,
                       pair_edge: NDArray[np.int64], pair_rx: NDArray[np.int64], *, screen: bool = True
                       ) -> NDArray[np.bool_]:
    """Whether each element's centre is seen from the transmitter and from its receiver.

    Parameters
    ----------
    context : SolveContext
    scene_part : DiffractingEdges
    elements : EdgeElements
        n elements of the pairs ``pair_edge``, ``pair_rx`` (shape (p,)).
    screen : bool, optional
        True (default): the legs that can be decided exactly without Embree are
        (:mod:`~acoustisim.propagation.edge_visibility`), the others go to Embree in one
        batch. False: every leg goes to Embree (the reference; the same answers).

    Returns
    -------
    ndarray of bool, shape (n,)
    """
    edges = scene_part.edges
    tx = np.asarray(context.transmitter_m, dtype=float)
    rx = np.asarray(context.receivers_m, dtype=float)
    own_leg_rx = ~np.all(rx == tx, axis=1)
    raycaster = context.raycaster
    n = elements.pair.size
    if not screen:
        starts32, directions32, lengths32, segment, own_leg = visibility_rays32(
            elements.pair, elements.z_start_m, elements.z_end_m, pair_edge, pair_rx, edges.start_m,
            edges.direction, scene_part.probe_offset_m, tx, rx, own_leg_rx, raycaster.shift_m, DEFAULT_EPS_M,
        )
        blocked = np.zeros(n + own_leg.size, dtype=bool)
        blocked[segment] = raycaster.occluded_segments32(starts32, directions32, lengths32)
        visible = ~blocked[:n]
        visible[own_leg] &= ~blocked[n:]
        return visible
    visible, starts32, directions32, lengths32, element = screened_visibility_rays32(
        elements.pair, elements.z_start_m, elements.z_end_m, pair_edge, pair_rx, edges.start_m, edges.direction,
        scene_part.probe_offset_m, tx, rx, own_leg_rx, raycaster.shift_m, DEFAULT_EPS_M,
        *scene_part.screen.kernel_arguments(raycaster.convex_planes),
    )
    if element.size:
        visible[element[raycaster.occluded_segments32(starts32, directions32, lengths32)]] = False
    return visible


def edge_paths(context: SolveContext, config: SolverConfig,
               edges: DiffractingEdges | SharpEdges | None = None, *, sort_rows: bool = False,
               screen: bool = True) -> NDArray[Any]:
    """Edge-diffraction rows for one sonar pose.

    Parameters
    ----------
    context : SolveContext
    config : SolverConfig
        ``edge_segment_m`` caps the element length.
    edges : DiffractingEdges or SharpEdges, optional
        The scene's diffracting edges (:attr:`PreparedScene.diffracting_edges
        <acoustisim.propagation.prepared.PreparedScene.diffracting_edges>`, reused across
        poses), or its sharp edges, or None (extracted from ``context``).
    sort_rows : bool, optional
        True: the rows in the order :func:`~acoustisim.propagation.solve` returns them
        (channel, then delay ``path_length_m / c``, ties in the default order), so that it
        need not move them (:func:`~acoustisim.propagation.assemble.assemble_rows`). False
        (default): ordered by (edge, receiver) pair, then along the edge.
    screen : bool, optional
        See :func:`element_visibility` (the rows are the same either way).

    Returns
    -------
    structured ndarray of PATH_DTYPE, shape (n,)
        The mechanism's columns (``path_id`` from ``context.first_path_id`` upwards, one per
        (edge chain, receiver), ``path_length_m``, ``geometric_gain``, directions, object and
        point); :func:`~acoustisim.propagation.columns.complete_columns`, which
        :func:`~acoustisim.propagation.solve` applies to every mechanism's rows, derives the
        delay, angles, directivities, absorption and amplitude.

    Raises
    ------
    InputError
        If ``config.edge_segment_m`` would make more than :data:`MAX_ELEMENTS` elements.
    """
    if edges is None:
        edges = sharp_edges(context.raycaster, context.scene)
    scene_part = edges if isinstance(edges, DiffractingEdges) else DiffractingEdges.build(edges, context.scene)
    edges = scene_part.edges
    n_edges = len(edges)
    if n_edges == 0:
        return empty_paths_array(0)
    c = context.sound_speed_m_s
    tx = np.asarray(context.transmitter_m, dtype=float)
    rx = np.asarray(context.receivers_m, dtype=float)
    n_rx = rx.shape[0]

    r_s, th_s, z_s = edges.local_coordinates(np.broadcast_to(tx, (n_edges, 3)))
    # pairs (edge, receiver), edge-major
    pair_edge = np.repeat(np.arange(n_edges), n_rx)
    pair_rx = np.tile(np.arange(n_rx), n_edges)
    sel = edges.select(pair_edge)
    r_r, th_r, z_r = sel.local_coordinates(rx[pair_rx])
    theta_w = edges.wedge_angle_rad[pair_edge]
    ok = (
        (r_s[pair_edge] > _MIN_DISTANCE_M)
        & (r_r > _MIN_DISTANCE_M)
        & (th_s[pair_edge] <= theta_w + 1e-12)
        & (th_r <= theta_w + 1e-12)
    )
    pair_edge, pair_rx, r_r, th_r, z_r = pair_edge[ok], pair_rx[ok], r_r[ok], th_r[ok], z_r[ok]
    if pair_edge.size == 0:
        return empty_paths_array(0)
    rs, ts, zs = r_s[pair_edge], th_s[pair_edge], z_s[pair_edge]
    open_start, open_end = _open_ends(edges, pair_edge, pair_rx, ok.reshape(n_edges, n_rx), scene_part.partner)

    step = c / (DELAY_STEPS_PER_PERIOD * context.centre_frequency_hz)
    try:
        elements = discretise_edges(
            scene_part.length_m[pair_edge], rs, zs, r_r, z_r, step, config.edge_segment_m, MAX_ELEMENTS,
            coarsening_levels=COARSENING_LEVELS if config.edge_adaptive else 0, grading=GRADING,
            cap_growth=CAP_GROWTH if config.edge_adaptive else 0.0,
            onset_nodes=ONSET_NODES if config.edge_adaptive else 1, open_start=open_start, open_end=open_end,
            path_lengths=not config.edge_adaptive,
        )
    except ValueError as error:
        raise InputError(f"solver.edge_segment_m = {config.edge_segment_m!r}: {error}; use a larger value") from None
    # visibility of each element's centre from the transmitter and from its receiver (before
    # the gains: hidden elements cost no quadrature); a receiver at the transmitter (the centre
    # transducer) has the same leg: tested once
    visible = element_visibility(context, scene_part, elements, pair_edge, pair_rx, screen=screen)
    if not np.all(visible):
        elements = EdgeElements(elements.pair[visible], elements.z_start_m[visible], elements.z_end_m[visible],
                                elements.path_length_m[visible])

    # per element: two impulses at its Gauss points (graded, see element_gains with per_point)
    # or one at its centre (fine)
    k = pair_constants(scene_part.nu[pair_edge], rs, ts, zs, r_r, th_r, z_r, edges.pressure_release[pair_edge])
    gauss_x, gauss_w = gauss_rule(GAUSS_POINTS)
    gains2, z2, path2 = gauss_point_gains(
        elements.pair, elements.z_start_m, elements.z_end_m, k.nu, k.r_s, k.z_s, k.r_r, k.z_r, k.nk,
        k.ml_star, k.z_star, k.num, k.gap, k.coef, k.s_gap, gauss_x, gauss_w, not config.edge_adaptive,
    )
    gains = gains2.reshape(-1)
    if config.edge_adaptive:
        pair, z_point, path_length = np.repeat(elements.pair, GAUSS_POINTS), z2.reshape(-1), path2.reshape(-1)
    else:
        pair, z_point, path_length = elements.pair, elements.z_mid_m, elements.path_length_m
    if gains.size == 0:
        return empty_paths_array(0)
    keep = np.flatnonzero(np.abs(gains) > ELEMENT_FLOOR * np.max(np.abs(gains)))
    if keep.size == 0:
        return empty_paths_array(0)
    if sort_rows:  # stable: ties keep the default order
        keep = solver_order(keep, pair, path_length, pair_rx, float(c), n_rx)
    # the kernel writes every field: the mechanism's columns, the padding of empty_paths_array
    # and zeros in the others (no separate zeroing pass over the buffer)
    rows = np.empty(keep.size, dtype=PATH_DTYPE)
    fill_edge_rows(
        rows["path_id"], rows["channel"], rows["kind"], rows["order"], rows["path_length_m"],
        rows["geometric_gain"], rows["departure_dir"], rows["arrival_dir"], rows["object_ids"], rows["points_m"],
        tuple(rows[name] for name in _ZEROED_FIELDS),
        keep, pair, gains, path_length, z_point, pair_edge, pair_rx, edges.chain, edges.surface,
        edges.start_m, edges.direction, tx, rx, int(context.first_path_id), int(PathKind.EDGE),
    )
    return rows


__all__ = ["DELAY_STEPS_PER_PERIOD", "ELEMENT_FLOOR", "MAX_ELEMENTS", "DiffractingEdges", "diffracting_edges",
           "edge_paths"]
