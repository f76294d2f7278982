"""Diffuse reverberation: Monte Carlo rays, Lambert scattering, next-event estimation.

Rays leave the transmitter in directions drawn from a mixture of two densities over the
whole sphere (``physics.md`` section 5)::

    pdf(w) = a / (4 pi) + (1 - a) D(theta)^2 / Z  (theta < 90 deg),    Z = Int D^2 dOmega,

half of them uniform (side lobes, the back, the floor under the head) and half importance
sampled by the forward transmit power directivity D^2 = (2 J1(x)/x)^2 at the centre
frequency (the main lobe; D^2 is tabulated as a density piecewise constant in cos(theta), so
the pdf of each drawn direction is exact). Each ray carries the solid angle ``dOmega = 1 / (N pdf)``; one
batched Embree ``intersect`` finds every first hit.

Each hit is a point scatterer (next-event estimation): with Lambert's law
``I_s / I_i = mu sin(g_i) sin(g_s) dA / r2^2``, the footprint ``dA = r1^2 dOmega / sin(g_i)``
and the incident intensity 1 / r1^2 (unit pressure at 1 m), the pressure factor toward a
receiver is ``|X| sqrt(mu sin(g_s) dOmega) / r2``, independent of r1, where X is a complex
Gaussian speckle factor (E|X|^2 = 1) frozen to the hit's world position: its value is a hash
of the position quantised to :data:`SPECKLE_CELL_M` and of ``config.seed``, so that it is the
same for every receiver and every ping. |X| sqrt(...) is the row's ``geometric_gain`` and
arg X its ``phase_rad``; directivities and absorption come from the common columns. A row is
emitted when the receiver is in front of the scattering face and the leg hit -> receiver is
not occluded (one batched Embree ``occluded`` for the legs that may cross an object: the
tank's boundaries enclose a convex box and cannot block a leg, so legs missing every object's
bounding box are clear without a query, see :class:`ObjectScreen`).

Further bounces (``config.diffuse_bounces`` > 1) continue each ray in a cosine-weighted
direction about the hit's normal, which multiplies its weight by ``pi mu`` (the Lambert
albedo), and scatter again to every receiver. Scattering is Lambertian only: a surface with
mu = 0 (the free surface, ideal materials) ends the ray, and specular energy is the image
source solver's business.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from acoustisim.errors import InputError
from acoustisim.propagation.config import SolverConfig
from acoustisim.propagation.context import SolveContext
from acoustisim.propagation.directivity import piston_directivity
from acoustisim.propagation.paths import MAX_INTERACTIONS, PathKind, PATH_DTYPE, empty_paths_array

UNIFORM_FRACTION = 0.5
"""Share a of the rays drawn uniformly over the sphere; the rest follow D^2."""

SPECKLE_CELL_M = 1e-3
"""Side of the cubes that share one speckle factor (m): a third of a wavelength at 500 kHz."""

OFFSET_M = 2e-5
"""A continuing ray starts this far off its surface (40 float32 ulps in the tank)."""

MAX_RAY_EVENTS = 10_000_000
"""Most rays x bounces one solve may trace (up to three rows each, about 250 bytes a row):
beyond it the configuration is refused rather than exhausting memory."""

_COS_CELLS = 1 << 13
"""Cells of the tabulated lobe density: 2.4e-4 wide in cos(theta), 1.3 degrees at the axis
(the main lobe's -3 dB half width is 4.6 degrees)."""

_GOLDEN = np.uint64(0x9E3779B97F4A7C15)
_MIX1 = np.uint64(0xBF58476D1CE4E5B9)
_MIX2 = np.uint64(0x94D049BB133111EB)
_PRIME_X = np.uint64(0x8DA6B343)  # spatial-hash multipliers (Teschner et al. 2003), odd
_PRIME_Y = np.uint64(0xD8163841)
_PRIME_Z = np.uint64(0xCB1AB31F)


def _splitmix64(x: NDArray[np.uint64]) -> NDArray[np.uint64]:
    """SplitMix64 finaliser, element-wise (wrapping uint64 arithmetic)."""
    z = x + _GOLDEN
    z = (z ^ (z >> np.uint64(30))) * _MIX1
    z = (z ^ (z >> np.uint64(27))) * _MIX2
    return z ^ (z >> np.uint64(31))


def speckle_polar(points_m: NDArray[np.float64], seed: int) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Magnitude and phase of the speckle factors of :func:`speckle` (no complex arithmetic).

    Returns
    -------
    magnitude : ndarray, shape (n,)
        |X| (Rayleigh distributed, E|X|^2 = 1).
    phase : ndarray, shape (n,)
        arg X in [-pi, pi) (rad), uniform.
    """
    cells = np.floor(np.asarray(points_m, dtype=float) / SPECKLE_CELL_M).astype(np.int64).view(np.uint64)
    key = (cells[:, 0] * _PRIME_X) ^ (cells[:, 1] * _PRIME_Y) ^ (cells[:, 2] * _PRIME_Z)
    h = _splitmix64(key ^ _splitmix64(np.array([seed], dtype=np.uint64)))
    h2 = _splitmix64(h)
    u1 = (h >> np.uint64(11)).astype(np.float64) * 2.0**-53
    u2 = (h2 >> np.uint64(11)).astype(np.float64) * 2.0**-53
    # |X|^2 ~ Exp(1), phase uniform
    return np.sqrt(-np.log1p(-u1)), 2.0 * np.pi * u2 - np.pi


def speckle(points_m: NDArray[np.float64], seed: int) -> NDArray[np.complex128]:
    """Complex Gaussian speckle factors frozen to world positions.

    Parameters
    ----------
    points_m : ndarray, shape (n, 3)
        Scattering points (tank frame, m).
    seed : int
        The solver seed (>= 0).

    Returns
    -------
    ndarray of complex, shape (n,)
        Circular complex Gaussian values with E|X|^2 = 1; equal for points in the same cube of
        side :data:`SPECKLE_CELL_M`, whatever the receiver, ping or ray that found them (the
        value is a hash of the cube's integer coordinates and the seed).
    """
    magnitude, phase = speckle_polar(points_m, seed)
    return magnitude * np.exp(1j * phase)


def _basis(axis: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Two unit vectors completing ``axis`` to an orthonormal frame."""
    helper = np.array([1.0, 0.0, 0.0]) if abs(axis[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    u = np.cross(axis, helper)
    u /= np.linalg.norm(u)
    return u, np.cross(axis, u)


def _frames(normals: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Per-row orthonormal tangents (n, 3) x 2 of unit normals (n, 3)."""
    helper = np.where(np.abs(normals[:, :1]) < 0.9, np.array([[1.0, 0.0, 0.0]]), np.array([[0.0, 1.0, 0.0]]))
    u = np.cross(normals, helper)
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    return u, np.cross(normals, u)


def sample_directions(
    n: int, boresight: NDArray[np.float64], context: SolveContext, rng: np.random.Generator
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Ray directions from the transmitter and their solid angles.

    Parameters
    ----------
    n : int
        Number of rays.
    boresight : ndarray, shape (3,)
        Unit transmit axis.
    context : SolveContext
        For the piston radius, the centre frequency and c.
    rng : numpy.random.Generator

    Returns
    -------
    directions : ndarray, shape (n, 3)
        Unit vectors.
    solid_angle : ndarray, shape (n,)
        dOmega = 1 / (n pdf) (sr); sums to 4 pi in expectation.
    """
    # the lobe density: D^2 averaged over _COS_CELLS cells of equal width in cos(theta), so
    # that sampling a cell, then cos(theta) uniformly in it, has an exactly known pdf
    edges = np.linspace(1.0, -1.0, _COS_CELLS + 1)  # cos(theta) from the axis backwards
    centres = np.arccos(0.5 * (edges[1:] + edges[:-1]))
    power = piston_directivity(centres, context.centre_frequency_hz, context.piston_radius_m, context.sound_speed_m_s) ** 2
    # the lobe density covers the forward hemisphere only (2 J1(x)/x, x = k a sin(theta), is
    # symmetric about 90 degrees, a baffled piston radiates nothing behind); the back is left
    # to the uniform share
    power = np.where(centres < 0.5 * np.pi, power, 0.0)
    mass = np.cumsum(power)
    width = 2.0 / _COS_CELLS
    lobe_pdf = power / (mass[-1] * 2.0 * np.pi * width)  # per steradian, per cell
    u = rng.random((4, n))
    cos_t = 1.0 - 2.0 * u[1]  # the uniform share
    lobe = np.flatnonzero(u[0] >= UNIFORM_FRACTION)
    cell = np.minimum(np.searchsorted(mass, u[1, lobe] * mass[-1], side="right"), _COS_CELLS - 1)
    cos_t[lobe] = edges[cell] - u[2, lobe] * width
    sin_t = np.sqrt(np.maximum(1.0 - cos_t * cos_t, 0.0))
    phi = 2.0 * np.pi * u[3]
    e1, e2 = _basis(boresight)
    a, b = sin_t * np.cos(phi), sin_t * np.sin(phi)
    # column by column (contiguous 1-D passes; no BLAS matmul, whose threads contend on a
    # busy 2-core machine, and no (n, 3) broadcasts over a length-3 inner axis)
    directions = np.empty((n, 3))
    for k in range(3):  # the three coordinates
        column = a * e1[k]
        column += b * e2[k]
        column += cos_t * boresight[k]
        directions[:, k] = column
    cell_of = np.minimum(((1.0 - cos_t) * (_COS_CELLS / 2.0)).astype(np.int64), _COS_CELLS - 1)
    pdf = UNIFORM_FRACTION / (4.0 * np.pi) + (1.0 - UNIFORM_FRACTION) * lobe_pdf[cell_of]
    return directions, 1.0 / (n * pdf)


@dataclass(frozen=True, eq=False)
class ObjectScreen:
    """Which scattering points' legs to the receivers may be blocked: a conservative screen.

    The tank's boundaries enclose a convex box (or there are none, in free field), so a
    straight leg between two points in the water, a scattering point on a boundary or an
    object and a receiver, never crosses a boundary: only objects can block it. A leg that
    misses every object's axis-aligned box (grown by :data:`SCREEN_MARGIN_M`) is clear, and
    Embree need not test it. The legs from one point to the receivers lie in the hull of the
    point and the receivers' box, so one segment from the point to that box's centre is tested
    against the object boxes grown by its half-size (Minkowski sum): a miss is a miss for
    every receiver. Exact: only legs Embree would report clear are skipped.

    Attributes
    ----------
    centre : ndarray, shape (3,)
        Centre of the receivers' box (m).
    lo, hi : ndarray, shape (k, 3)
        Grown object boxes (m); row 0 the union of all, then each object's (when there are at
        most :data:`SCREEN_MAX_BOXES`). ``None`` when the screen cannot be used (a receiver
        outside the tank's water): every leg is then tested.
    """

    centre: NDArray[np.float64]
    lo: NDArray[np.float64] | None
    hi: NDArray[np.float64] | None

    @classmethod
    def create(cls, scene: Any, receivers_m: NDArray[np.float64]) -> "ObjectScreen":
        """The screen of ``scene``'s objects for the receivers ``receivers_m`` (n_rx, 3)."""
        low, high = receivers_m.min(axis=0), receivers_m.max(axis=0)
        centre, half = 0.5 * (low + high), 0.5 * (high - low)
        if scene.tank is not None and not np.all(scene.tank.contains(receivers_m)):
            return cls(centre, None, None)
        if not scene.objects:
            empty = np.zeros((0, 3))
            return cls(centre, empty, empty)
        bounds = np.array([obj.bounds_m for obj in scene.objects])  # (k, 2, 3)
        grow = half + SCREEN_MARGIN_M
        lo, hi = bounds[:, 0] - grow, bounds[:, 1] + grow
        union_lo, union_hi = lo.min(axis=0, keepdims=True), hi.max(axis=0, keepdims=True)
        if len(scene.objects) > SCREEN_MAX_BOXES:
            return cls(centre, union_lo, union_hi)
        return cls(centre, np.concatenate([union_lo, lo]), np.concatenate([union_hi, hi]))

    def near(self, points_m: NDArray[np.float64]) -> NDArray[np.bool_]:
        """Whether the legs from each point (n, 3) to the receivers may cross an object (n,)."""
        n = points_m.shape[0]
        if self.lo is None:
            return np.ones(n, dtype=bool)
        if self.lo.shape[0] == 0:
            return np.zeros(n, dtype=bool)
        # float32 columns: the rounding (1e-6 m over a 10 m leg) is far inside the margin
        start = [np.ascontiguousarray(points_m[:, k], dtype=np.float32) for k in range(3)]
        span = [np.float32(self.centre[k]) - start[k] for k in range(3)]
        for column in span:  # a (near-)zero span, a leg in a slab's plane: no inf or 0 x inf
            column[np.abs(column) < 1e-30] = np.float32(1e-30)
        inverse = [np.float32(1.0) / column for column in span]
        offset = [-start[k] * inverse[k] for k in range(3)]
        near = _segments_cross_box(inverse, offset, self.lo[0], self.hi[0])
        if self.lo.shape[0] == 1:
            return near
        candidates = np.flatnonzero(near)
        inverse = [column[candidates] for column in inverse]
        offset = [column[candidates] for column in offset]
        crossing = np.zeros(candidates.size, dtype=bool)
        for lo, hi in zip(self.lo[1:], self.hi[1:]):  # a handful of objects
            crossing |= _segments_cross_box(inverse, offset, lo, hi)
        near[candidates] = crossing
        return near


SCREEN_MARGIN_M = 1e-4
"""Growth of the object boxes in :class:`ObjectScreen` (m): 100 times the float32 rounding
of a 10 m leg."""

SCREEN_MAX_BOXES = 16
"""Objects screened box by box; more are screened by their union box only."""


def _segments_cross_box(
    inverse: list[NDArray[np.float32]], offset: list[NDArray[np.float32]], lo: NDArray[np.float64],
    hi: NDArray[np.float64],
) -> NDArray[np.bool_]:
    """Slab test: whether segments start + t span, t in [0, 1], meet the box [lo, hi].

    Per coordinate k, ``inverse[k]`` = 1 / span (n,) and ``offset[k]`` = -start / span: the
    segment is in slab k for t between lo inverse + offset and hi inverse + offset.
    """
    enter = np.zeros(inverse[0].size, dtype=np.float32)
    leave = np.ones(inverse[0].size, dtype=np.float32)
    for k in range(3):  # the three coordinates
        t1 = np.float32(lo[k]) * inverse[k]
        t1 += offset[k]
        t2 = np.float32(hi[k]) * inverse[k]
        t2 += offset[k]
        np.maximum(enter, np.minimum(t1, t2), out=enter)
        np.minimum(leave, np.maximum(t1, t2), out=leave)
    return enter <= leave


@dataclass(frozen=True)
class DiffuseEvents:
    """The diffuse tracer's output before row packing.

    Scattering events (ray hits) and the receptions (event, receiver) whose leg to the
    receiver is clear and in front of the scattering face.

    Attributes
    ----------
    points_m : ndarray, shape (m, 3)
        Hit point of each event (tank frame, m).
    surface : ndarray of int64, shape (m,)
        Index into ``scene.surface_names`` of the surface hit.
    parent : ndarray of int64, shape (m,)
        The previous event of the same ray (-1 for a first hit).
    bounce : ndarray of int64, shape (m,)
        Scattering order (1 = first hit).
    departure_dir : ndarray, shape (m, 3)
        Unit direction in which the event's ray left the transmitter.
    event : ndarray of int64, shape (n,)
        Event of each reception.
    channel : ndarray of int64, shape (n,)
        Receiver of each reception.
    path_length_m : ndarray, shape (n,)
        Transmitter -> ... -> hit -> receiver (m).
    gain : ndarray, shape (n,)
        |X| sqrt(mu sin(g_s) dOmega_eff) / r2 (relative to the source's pressure at 1 m), >= 0.
    phase_rad : ndarray, shape (n,)
        arg X (rad).
    arrival_dir : ndarray, shape (n, 3)
        Unit direction hit -> receiver.
    """

    points_m: NDArray[np.float64]
    surface: NDArray[np.int64]
    parent: NDArray[np.int64]
    bounce: NDArray[np.int64]
    departure_dir: NDArray[np.float64]
    event: NDArray[np.int64]
    channel: NDArray[np.int64]
    path_length_m: NDArray[np.float64]
    gain: NDArray[np.float64]
    phase_rad: NDArray[np.float64]
    arrival_dir: NDArray[np.float64]


def _concatenate(parts: list[NDArray[Any]], empty: NDArray[Any]) -> NDArray[Any]:
    if not parts:
        return empty
    return parts[0] if len(parts) == 1 else np.concatenate(parts)


def trace_diffuse(context: SolveContext, config: SolverConfig) -> DiffuseEvents:
    """Trace ``config.diffuse_rays`` rays through ``config.diffuse_bounces`` Lambert scatterings.

    Parameters
    ----------
    context : SolveContext
    config : SolverConfig
        ``diffuse_rays``, ``diffuse_bounces``, ``seed``.

    Returns
    -------
    DiffuseEvents

    Raises
    ------
    InputError
        If ``diffuse_rays x diffuse_bounces`` exceeds :data:`MAX_RAY_EVENTS`.
    """
    n_rays = int(config.diffuse_rays)
    if n_rays * int(config.diffuse_bounces) > MAX_RAY_EVENTS:
        raise InputError(
            f"solver.diffuse_rays = {config.diffuse_rays!r} with diffuse_bounces = {config.diffuse_bounces!r}: "
            f"more than {MAX_RAY_EVENTS} scattering events; use fewer rays"
        )
    rng = np.random.default_rng(config.seed)
    raycaster = context.raycaster
    scene = context.scene
    mu_of_surface = np.array(
        [b.material.diffuse_mu for b in scene.boundaries] + [o.material.diffuse_mu for o in scene.objects]
    )
    tx = np.asarray(context.transmitter_m, dtype=float)
    rx = np.asarray(context.receivers_m, dtype=float)
    directions, weight = sample_directions(n_rays, np.asarray(context.boresight, dtype=float), context, rng)
    screen = ObjectScreen.create(scene, rx)
    at_transmitter = np.all(rx == tx, axis=1)  # (the thesis sonar's centre transducer)
    departure = directions
    origins = np.broadcast_to(tx, (n_rays, 3))
    travelled = np.zeros(n_rays)
    parent = np.full(n_rays, -1, dtype=np.int64)
    ev: dict[str, list[NDArray[Any]]] = {k: [] for k in ("points", "surface", "parent", "bounce", "departure")}
    rc: dict[str, list[NDArray[Any]]] = {k: [] for k in ("event", "channel", "length", "gain", "phase", "arrival")}
    next_event = 0
    # No surface scatters (e.g. an empty free field): nothing to trace.
    bounces = int(config.diffuse_bounces) if np.any(mu_of_surface > 0.0) else 0
    for bounce in range(bounces):  # a handful of bounces
        hits = raycaster.intersect(origins, directions, unit_directions=True)  # unit by construction
        surface = hits.surface
        mu = mu_of_surface[np.maximum(surface, 0)]
        # a scattering surface hit from its front (a missed ray's normal is NaN: not < 0)
        front = np.einsum("ij,ij->i", directions, hits.normal) < 0.0
        keep = front & (surface >= 0) & (mu > 0.0)
        n_hits = int(np.count_nonzero(keep))
        if n_hits == 0:
            break
        # in a closed tank every ray scatters: then no gathers
        live = None if n_hits == keep.size else np.flatnonzero(keep)

        def alive(values: NDArray[Any]) -> NDArray[Any]:
            return values if live is None else values[live]

        normal, directions, distance, mu = alive(hits.normal), alive(directions), alive(hits.distance_m), alive(mu)
        points = distance[:, None] * directions
        points += alive(origins)
        weight, departure, parent = alive(weight), alive(departure), alive(parent)
        travelled = alive(travelled) + distance
        surface = alive(surface)
        ev["points"].append(points)
        ev["surface"].append(surface)
        ev["parent"].append(parent)
        ev["bounce"].append(np.full(n_hits, bounce + 1, dtype=np.int64))
        ev["departure"].append(departure)

        # next-event estimation to every receiver
        n_rx = rx.shape[0]
        to_rx = rx[None, :, :] - points[:, None, :]  # (n_hits, n_rx, 3)
        r2 = np.sqrt(np.einsum("ijk,ijk->ij", to_rx, to_rx))
        sin_gs = np.einsum("ijk,ik->ij", to_rx, normal) / r2
        magnitude, phase = speckle_polar(points, config.seed)
        gain = (magnitude * np.sqrt(weight * mu))[:, None] * np.sqrt(np.maximum(sin_gs, 0.0)) / r2
        # (hit, receiver) pairs in front of the face; Embree tests only the legs that may
        # cross an object (boundaries cannot block them: see ObjectScreen)
        clear = (sin_gs > 0.0).reshape(-1)
        near = np.repeat(screen.near(points), n_rx).reshape(n_hits, n_rx)
        if bounce == 0:  # a first hit's leg back to a receiver at the transmitter is its own ray
            near[:, at_transmitter] = False
        test = np.flatnonzero(clear & near.reshape(-1))
        if test.size:
            hit_test, rx_test = np.divmod(test, n_rx)
            lengths = r2.reshape(-1)[test]
            unit = to_rx.reshape(-1, 3)[test] / lengths[:, None]
            clear[test] = ~raycaster.occluded_rays(points[hit_test], unit, lengths)
        flat = np.flatnonzero(clear)
        hit_idx, rx_idx = np.divmod(flat, n_rx)
        r2_sel = r2.reshape(-1)[flat]
        rc["event"].append(next_event + hit_idx)
        rc["channel"].append(rx_idx)
        rc["length"].append(travelled[hit_idx] + r2_sel)
        rc["gain"].append(gain.reshape(-1)[flat])
        rc["phase"].append(phase[hit_idx])
        arrival = to_rx.reshape(-1, 3)[flat]
        arrival /= r2_sel[:, None]
        rc["arrival"].append(arrival)
        parent = next_event + np.arange(n_hits)
        next_event += n_hits
        if bounce + 1 >= int(config.diffuse_bounces):
            break
        # continue in a cosine-weighted direction about the normal: weight x (pi mu)
        u = rng.random((n_hits, 2))
        radius = np.sqrt(u[:, 0])
        phi = 2.0 * np.pi * u[:, 1]
        t1, t2 = _frames(normal)
        directions = (
            (radius * np.cos(phi))[:, None] * t1
            + (radius * np.sin(phi))[:, None] * t2
            + np.sqrt(np.maximum(1.0 - u[:, 0], 0.0))[:, None] * normal
        )
        weight = weight * math.pi * mu
        origins = points + OFFSET_M * normal  # the 2e-5 m offset (14 ps) is not added to the path
    i0, f0, v0 = np.zeros(0, np.int64), np.zeros(0), np.zeros((0, 3))
    return DiffuseEvents(
        points_m=_concatenate(ev["points"], v0),
        surface=_concatenate(ev["surface"], i0),
        parent=_concatenate(ev["parent"], i0),
        bounce=_concatenate(ev["bounce"], i0),
        departure_dir=_concatenate(ev["departure"], v0),
        event=_concatenate(rc["event"], i0),
        channel=_concatenate(rc["channel"], i0),
        path_length_m=_concatenate(rc["length"], f0),
        gain=_concatenate(rc["gain"], f0),
        phase_rad=_concatenate(rc["phase"], f0),
        arrival_dir=_concatenate(rc["arrival"], v0),
    )


def diffuse_paths(context: SolveContext, config: SolverConfig) -> NDArray[Any]:
    """Diffuse reverberation rows for one sonar pose.

    Parameters
    ----------
    context : SolveContext
    config : SolverConfig
        ``diffuse_rays`` (0 gives no rows), ``diffuse_bounces``, ``seed``.

    Returns
    -------
    structured ndarray of PATH_DTYPE, shape (n,)
        One row per (scattering event, receiver) with ``kind = DIFFUSE``, ``order`` the bounce
        number, ``path_id`` from ``context.first_path_id`` upwards, one per scattering event
        (shared by the receivers that see it), and the other mechanism columns;
        :func:`~acoustisim.propagation.columns.complete_columns`, which
        :func:`~acoustisim.propagation.solve` applies to every mechanism's rows, derives the
        delay, angles, directivities, absorption and amplitude.
    """
    if int(config.diffuse_rays) <= 0:
        return empty_paths_array(0)
    events = trace_diffuse(context, config)
    e = events.event
    rows = np.zeros(e.size, dtype=PATH_DTYPE)
    rows["path_id"] = context.first_path_id + e
    rows["channel"] = events.channel
    rows["kind"] = int(PathKind.DIFFUSE)
    order = events.bounce[e]
    rows["order"] = order
    rows["path_length_m"] = events.path_length_m
    rows["geometric_gain"] = events.gain
    rows["phase_rad"] = events.phase_rad
    rows["departure_dir"] = events.departure_dir[e]
    rows["arrival_dir"] = events.arrival_dir
    # interaction chains: walk each event's parents back to the first hit
    surfaces = np.full((e.size, MAX_INTERACTIONS), -1, dtype=np.int16)
    points = np.full((e.size, MAX_INTERACTIONS, 3), np.nan)
    current = e.copy()
    level = order - 1
    for _ in range(int(order.max()) if order.size else 0):  # a handful of bounces
        alive = current >= 0
        store = alive & (level < MAX_INTERACTIONS)
        idx = np.flatnonzero(store)
        surfaces[idx, level[idx]] = events.surface[current[idx]]
        points[idx, level[idx]] = events.points_m[current[idx]]
        current = np.where(alive, events.parent[np.maximum(current, 0)], -1)
        level = level - 1
    rows["object_ids"] = surfaces
    rows["points_m"] = points
    return rows


__all__ = [
    "DiffuseEvents",
    "MAX_RAY_EVENTS",
    "OFFSET_M",
    "SPECKLE_CELL_M",
    "UNIFORM_FRACTION",
    "diffuse_paths",
    "sample_directions",
    "speckle",
    "speckle_polar",
    "trace_diffuse",
]
