"""Diffuse reverberation: Monte Carlo rays, Lambert scattering, next-event estimation.

Rays leave the transmitter in directions drawn from a mixture of two densities over the
whole sphere (``physics.md`` section 5)::

    pdf(w) = a / (4 pi) + (1 - a) D(theta)^2 / Z  (theta < 90 deg),    Z = Int D^2 dOmega,

half of them uniform (side lobes, the back, the floor under the head) and half importance
sampled by the forward transmit power directivity D^2 = (2 J1(x)/x)^2 at the centre
frequency (the main lobe; D^2 is tabulated as a density piecewise constant in cos(theta), so
the pdf of each drawn direction is exact). Each ray carries the solid angle ``dOmega = 1 / (N pdf)``
(the two shares are drawn in fixed numbers, see :class:`_LobeTable`). The hit triangles are
found without Embree in a box tank whose objects are convex (the tank's exit face, the objects'
face planes: :mod:`~acoustisim.propagation.diffuse_hits`, exact in float64, Embree's answer but
for rays grazing an edge within its float32 rounding); batched Embree intersect queries find
the others (a tank that is not a box, rays near a non-convex object). The hit points are solved
on the triangles' planes in float64.

Each hit is a point scatterer (next-event estimation): with Lambert's law
``I_s / I_i = mu sin(g_i) sin(g_s) dA / r2^2``, the footprint ``dA = r1^2 dOmega / sin(g_i)``
and the incident intensity 1 / r1^2 (unit pressure at 1 m), the pressure factor toward a
receiver is ``|X| sqrt(mu sin(g_s) dOmega) / r2``, independent of r1, where X is a complex
Gaussian speckle factor (E|X|^2 = 1) frozen to the hit's world position: its value is a hash
of the position quantised to :data:`SPECKLE_CELL_M` and of ``config.seed``, so that it is the
same for every receiver and every ping. |X| sqrt(...) is the row's ``geometric_gain`` and
arg X its ``phase_rad``; directivities and absorption come from the common columns. A row is
emitted when the receiver is in front of the scattering face and the leg hit -> receiver is
not occluded. The tank's boundaries enclose a convex box and cannot block a leg, so a leg
missing every object's bounding box, or crossing only the box of the convex object it starts
on, is clear; a leg crossing the box of a convex object (a closed mesh with every vertex
inside every face plane: the prisms, posts and pipes) is decided exactly by clipping it
against the object's face planes (:mod:`~acoustisim.propagation.convex_occlusion`); only the
legs crossing the box of a non-convex object go to one batched Embree occlusion query per
chunk and bounce (see :class:`ObjectScreen`). The plane test is the exact answer in float64;
Embree's, in float32, differs only for legs grazing a face within its rounding (1e-6 m).

The rays are traced in fixed chunks of :data:`CHUNK_RAYS`, each with its own random stream
(a SplitMix64 sequence keyed by the solver seed and the chunk index, :class:`_ChunkStream`),
on a small thread pool (Embree, the compiled per-hit loops of
:mod:`~acoustisim.propagation.diffuse_kernels` and :mod:`~acoustisim.propagation.diffuse_hits`
and numpy's large-array passes release the GIL): the rows are the same for any number of
threads. Each chunk writes its events and receptions straight into the solve's output arrays
(sized for the most events the rays can make) at their final place when every earlier chunk
is placed before it starts (always on one thread), else into a scratch block reused chunk
after chunk, copied to the output once the chunks before it are placed (see
:class:`_Output`). An approximate visibility mode (``visibility="centre"``, off by default) tests only the leg to
the centre receiver and shares the answer with the side receivers: on the thesis tank at its
default pose it changes the side channels' diffuse energy by 0.003 %, but over 12 random
poses by up to 1.2 % (the sonar among the posts), so exact visibility stays the default.

Further bounces (``config.diffuse_bounces`` > 1) continue each ray in a cosine-weighted
direction about the hit's normal, which multiplies its weight by ``pi mu`` (the Lambert
albedo), and scatter again to every receiver. Scattering is Lambertian only: a surface with
mu = 0 (the free surface, ideal materials) ends the ray, and specular energy is the image
source solver's business.
"""

from __future__ import annotations

import math
import threading
from dataclasses import dataclass
from functools import cached_property
from typing import Any

import numpy as np
from numpy.typing import NDArray

from acoustisim.errors import InputError
from acoustisim.propagation.config import VISIBILITY_MODES, SolverConfig
from acoustisim.propagation.context import SolveContext
from acoustisim.propagation.diffuse_screen import ObjectScreen, receiver_wedges, shared_wedges
from acoustisim.propagation.directivity import piston_directivity
from acoustisim.propagation import diffuse_kernels as kernels
from acoustisim.propagation.diffuse_hits import first_hits
from acoustisim.propagation.paths import PathKind, PATH_DTYPE, empty_paths_array
from acoustisim.propagation.ray_threads import resolve_threads, run_in_order
from acoustisim.propagation.raycast import DEFAULT_EPS_M, RayCaster

UNIFORM_FRACTION = 0.5
"""Share a of the rays drawn uniformly over the sphere; the rest follow D^2."""

SPECKLE_CELL_M = 1e-3
"""Side of the cubes that share one speckle factor (m): a third of a wavelength at 500 kHz."""

OFFSET_M = 2e-5
"""A continuing ray starts this far off its surface (40 float32 ulps in the tank)."""

MAX_RAY_EVENTS = 10_000_000
"""Most rays x bounces one solve may trace (up to three rows each, about 250 bytes a row):
beyond it the configuration is refused rather than exhausting memory."""

_COS_CELLS = 1 << 13  # < 2**15: the guide table holds cell indices as int16
"""Cells of the tabulated lobe density: 2.4e-4 wide in cos(theta), 1.3 degrees at the axis
(the main lobe's -3 dB half width is 4.6 degrees)."""

_GUIDE_BINS = 1 << 16
"""Equiprobable bins of the lobe density's guide table (see :class:`_LobeTable`)."""

def _seed_hash(seed: int) -> np.uint64:
    """The seed's contribution to every speckle hash (SplitMix64 of the seed)."""
    return np.uint64(kernels.splitmix64(np.uint64(seed)))


def speckle_polar(points_m: NDArray[np.float64], seed: int) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Magnitude and phase of the speckle factors of :func:`speckle` (no complex arithmetic).

    Returns
    -------
    magnitude : ndarray, shape (n,)
        |X| (Rayleigh distributed, E|X|^2 = 1).
    phase : ndarray, shape (n,)
        arg X in [-pi, pi) (rad), uniform.
    """
    points = np.asarray(points_m, dtype=float).reshape(-1, 3)
    magnitude, phase = np.empty(points.shape[0]), np.empty(points.shape[0])
    x, y, z = (np.ascontiguousarray(points[:, k]) for k in range(3))
    kernels.speckle_into(x, y, z, SPECKLE_CELL_M, _seed_hash(seed), magnitude, phase)
    return magnitude, phase


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


def _tangents(nx: NDArray[np.float64], ny: NDArray[np.float64], nz: NDArray[np.float64]) -> tuple[
        NDArray[np.float64], NDArray[np.float64]]:
    """Orthonormal tangents (3, n) x 2 of unit normals given as columns (n,) x 3.

    t1 = n x h / |n x h| with h = x (or y where |n_x| >= 0.9), t2 = n x t1.
    """
    use_x = np.abs(nx) < 0.9
    # n x (1, 0, 0) = (0, nz, -ny);  n x (0, 1, 0) = (-nz, 0, nx)
    t1 = np.empty((3, nx.size))
    np.multiply(-nz, ~use_x, out=t1[0])
    np.copyto(t1[1], np.where(use_x, nz, 0.0))
    np.copyto(t1[2], np.where(use_x, -ny, nx))
    t1 /= np.sqrt(t1[0] * t1[0] + t1[1] * t1[1] + t1[2] * t1[2])
    t2 = np.empty_like(t1)
    np.subtract(ny * t1[2], nz * t1[1], out=t2[0])
    np.subtract(nz * t1[0], nx * t1[2], out=t2[1])
    np.subtract(nx * t1[1], ny * t1[0], out=t2[2])
    return t1, t2


def _unit_circle(fraction: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """cos(phi), sin(phi) (n,), exactly on the unit circle, of the azimuths phi = 2 pi ``fraction``.

    ``fraction`` is uniform in [0, 1) (a uniform azimuth).

    The trigonometry is done in float32 (seven times faster than float64 in numpy here), then
    the pair is rescaled to unit length in float64: the azimuth moves by ~1e-7 rad, which for a
    uniform azimuth changes nothing but the draw, and the directions stay unit to 1e-16.
    """
    phi32 = fraction.astype(np.float32)
    phi32 *= np.float32(2.0 * np.pi)
    c = np.cos(phi32).astype(np.float64)
    s = np.sin(phi32).astype(np.float64)
    scale = c * c
    scale += s * s
    np.sqrt(scale, out=scale)
    c /= scale
    s /= scale
    return c, s


@dataclass(frozen=True, eq=False)
class _LobeTable:
    """The two sampling densities of the transmitted rays, the lobe one tabulated in cos(theta).

    The lobe density follows D^2 in :data:`_COS_CELLS` cells of equal width in cos(theta): the
    unit interval is cut into :data:`_GUIDE_BINS` equiprobable bins, bin i going to the cell
    that holds the quantile (i + 1/2) / _GUIDE_BINS of the cumulative D^2; a ray draws a bin,
    and the fractional part of its uniform number places cos(theta) uniformly in the bin's
    cell. A cell's probability is then exactly its bin count / _GUIDE_BINS (D^2's share to
    1.5e-5), so the pdf of each direction is exact, at one gather per ray instead of a search. A share :data:`UNIFORM_FRACTION` of the rays is drawn uniformly over the sphere,
    the rest from the lobe density, in fixed numbers (the first of each chunk uniform): with
    N_u and N_l rays from each, a ray's solid angle 1 / (N_u / 4 pi + N_l p_lobe(w)) makes the
    estimator unbiased (the balance heuristic of multiple importance sampling, Veach 1997,
    eq. 9.13); it equals 1 / (N pdf) of the mixture pdf of the module docstring, with less
    variance than drawing each ray's density at random.

    Attributes
    ----------
    edges : ndarray, shape (_COS_CELLS + 1,)
        Cell edges in cos(theta), from the axis (1) backwards (-1).
    guide : ndarray of int16, shape (_GUIDE_BINS,)
        The cell of each equiprobable bin.
    lobe_pdf : ndarray, shape (_COS_CELLS,)
        The lobe pdf (per steradian) of a direction in each cell.
    azimuth : ndarray, shape (2**AZIMUTH_BITS, 2)
        :func:`~acoustisim.propagation.diffuse_kernels.azimuth_table` (the azimuths' cosines
        and sines are rotated from it, without trigonometric calls).
    """

    edges: NDArray[np.float64]
    guide: NDArray[np.int16]
    lobe_pdf: NDArray[np.float64]
    azimuth: NDArray[np.float64]

    @classmethod
    def create(cls, context: SolveContext) -> "_LobeTable":
        """The table for ``context``'s piston radius, centre frequency and sound speed."""
        edges = np.linspace(1.0, -1.0, _COS_CELLS + 1)  # cos(theta) from the axis backwards
        centres = np.arccos(0.5 * (edges[1:] + edges[:-1]))
        # the lobe density covers the forward hemisphere only (2 J1(x)/x, x = k a sin(theta), is
        # symmetric about 90 degrees, a baffled piston radiates nothing behind); the back is
        # left to the uniform share
        forward = centres < 0.5 * np.pi
        power = np.zeros(_COS_CELLS)
        power[forward] = piston_directivity(centres[forward], context.centre_frequency_hz, context.piston_radius_m,
                                            context.sound_speed_m_s) ** 2
        mass = np.cumsum(power)
        # bin i goes to the first cell whose cumulative mass exceeds (i + 1/2) / _GUIDE_BINS of
        # the total (searchsorted(mass, quantiles, side="right"), as one linear merge)
        guide = np.empty(_GUIDE_BINS, dtype=np.int16)  # 128 KiB: gathered at random once per lobe ray
        counts = np.empty(_COS_CELLS, dtype=np.int64)
        kernels.guide_table(mass, guide, counts)
        share = counts / _GUIDE_BINS
        lobe_pdf = share / (2.0 * np.pi * (2.0 / _COS_CELLS))  # per steradian, per cell
        return cls(edges, guide, lobe_pdf, kernels.azimuth_table())

    @staticmethod
    def uniform_count(n: int) -> int:
        """Rays drawn uniformly among ``n`` of one chunk (at least one: a lone ray is uniform)."""
        return max(1, int(round(UNIFORM_FRACTION * n))) if n else 0

    def cells(self, totals: tuple[int, int]) -> NDArray[np.float64]:
        """Per cell (n_cells,): the solid angle of a ray drawn in it, for ``totals`` = (N_u, N_l)
        rays drawn uniformly and from the lobe over the solve (see
        :func:`~acoustisim.propagation.diffuse_kernels.cell_table`)."""
        n_u, n_l = totals
        out = np.empty(self.lobe_pdf.size)
        kernels.cell_table(self.lobe_pdf, n_u / (4.0 * np.pi), float(n_l), out)
        return out

    def draw(self, n: int, totals: tuple[int, int], frame: tuple[NDArray[np.float64], ...],
             rng: "np.random.Generator | _ChunkStream", workspace: "_DrawBuffers | None" = None,
             cells: NDArray[np.float64] | None = None) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Directions of ``n`` rays as components (3, n), and their solid angles (n,) (sr).

        ``workspace``: buffers for at least ``n`` rays, overwritten and returned (views); None:
        new arrays. ``cells``: :meth:`cells` of ``totals`` (None: made here).

        ``frame`` = (e1, e2, boresight): the transmitter's orthonormal frame (see :func:`_basis`).

        The first :meth:`uniform_count` rays are uniform over the sphere, the others follow the
        lobe; ``totals`` = (N_u, N_l) over every chunk of the solve set the solid angles.
        Two random numbers per ray, the next 2n of ``rng`` as an array (2, n): the cell and the
        position in it come from row 0 (its integer and fractional parts in units of a guide
        bin), the azimuth from row 1. From a :class:`_ChunkStream` they are drawn inside the
        compiled loop (:func:`~acoustisim.propagation.diffuse_kernels.draw_transmit_directions`,
        the same numbers, no array of them).
        """
        n_uniform = self.uniform_count(n)
        if workspace is None:
            directions, solid_angle = np.empty((3, n)), np.empty(n)
        else:
            directions, solid_angle = workspace.directions[: 3 * n].reshape(3, n), workspace.solid_angle[:n]
        e1, e2, axis = frame
        cells = self.cells(totals) if cells is None else cells
        width = (self.edges[0] - self.edges[-1]) / self.lobe_pdf.size
        if isinstance(rng, _ChunkStream):
            kernels.draw_transmit_directions(rng.key, rng.drawn, n, n_uniform, self.guide, cells, width, self.azimuth,
                                             e1, e2, axis, directions, solid_angle)
            rng.drawn += 2 * n
        else:
            kernels.transmit_directions(rng.random((2, n)), n_uniform, self.guide, cells, width, self.azimuth,
                                        e1, e2, axis, directions, solid_angle)
        return directions, solid_angle


class _ChunkStream:
    """The uniform numbers one chunk of rays draws: the SplitMix64 sequence keyed by the seed's
    hash and the chunk index, generated in a compiled loop
    (:func:`~acoustisim.propagation.diffuse_kernels.splitmix_uniforms`), with the part of
    :class:`numpy.random.Generator`'s interface the tracer uses (``random``). Cheaper than a
    Generator per chunk (seeding one costs about 0.1 ms) and as reproducible: the numbers
    depend on the seed and the chunk only, so the rows on neither the thread count nor the
    order the chunks run in.

    Parameters
    ----------
    key : numpy.uint64
        The state the sequence starts from.
    """

    __slots__ = ("key", "drawn")

    def __init__(self, key: np.uint64) -> None:
        self.key = key
        self.drawn = 0  # numbers drawn so far

    @classmethod
    def create(cls, seed_hash: np.uint64, chunk: int) -> "_ChunkStream":
        """The stream of chunk ``chunk`` for the seed whose hash is ``seed_hash``."""
        chunk_hash = np.uint64(kernels.splitmix64(np.uint64(chunk)))
        return cls(np.uint64(kernels.splitmix64(np.uint64(seed_hash) ^ chunk_hash)))

    def random(self, size: int | tuple[int, ...] | None = None,
               out: NDArray[np.float64] | None = None) -> NDArray[np.float64]:
        """The next numbers, uniform in [0, 1), shaped ``size`` or written into ``out``
        (C-contiguous float64), as :meth:`numpy.random.Generator.random` returns them."""
        values = np.empty(size) if out is None else out
        if not values.flags.c_contiguous:
            raise ValueError("_ChunkStream.random: out must be C-contiguous")
        flat = values.reshape(-1)  # a view
        kernels.splitmix_uniforms(self.key, self.drawn, flat)
        self.drawn += flat.size
        return values


@dataclass(frozen=True, eq=False)
class _DrawBuffers:
    """Buffers of :meth:`_LobeTable.draw` for up to ``capacity`` rays, and of each bounce's hit
    triangles and pair states, reused by the chunks one tracer thread traces (each is read
    within its bounce, or the chunk's first bounce only: fresh memory costs more, in page
    faults, than the kernels that fill it).

    ``triangle`` and ``pending`` (capacity,) hold a bounce's first hits
    (:func:`~acoustisim.propagation.diffuse_hits.first_hits`); ``state`` and ``pair_gain``
    (capacity x receivers,) its (hit, receiver) pairs
    (:func:`~acoustisim.propagation.diffuse_kernels.scatter_and_pair`)."""

    directions: NDArray[np.float64]
    solid_angle: NDArray[np.float64]
    triangle: NDArray[np.int32] | None = None
    pending: NDArray[np.int64] | None = None
    state: NDArray[np.int8] | None = None
    pair_gain: NDArray[np.float64] | None = None

    @classmethod
    def create(cls, capacity: int, receivers: int = 0) -> "_DrawBuffers":
        """Uninitialised buffers for ``capacity`` rays (the bounce buffers with ``receivers`` > 0)."""
        bounce = receivers > 0
        return cls(np.empty(3 * capacity), np.empty(capacity),
                   np.empty(capacity, dtype=np.int32) if bounce else None,
                   np.empty(capacity, dtype=np.int64) if bounce else None,
                   np.empty(capacity * receivers, dtype=np.int8) if bounce else None,
                   np.empty(capacity * receivers) if bounce else None)


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
    n_uniform = _LobeTable.uniform_count(n)
    axis = np.asarray(boresight, dtype=float)
    directions, solid_angle = _LobeTable.create(context).draw(n, (n_uniform, n - n_uniform), (*_basis(axis), axis),
                                                              rng)
    return np.ascontiguousarray(directions.T), solid_angle


@dataclass(frozen=True)
class DiffuseEvents:
    """The diffuse tracer's output before row packing.

    Scattering events (ray hits) and the receptions (event, receiver) whose leg to the
    receiver is clear and in front of the scattering face.

    Attributes
    ----------
    points_m : ndarray, shape (m, 3)
        Hit point of each event (tank frame, m).
    surface : ndarray of int32, shape (m,)
        Index into ``scene.surface_names`` of the surface hit.
    parent : ndarray of int32, shape (m,)
        The previous event of the same ray (-1 for a first hit).
    bounce : ndarray of int32, shape (m,)
        Scattering order (1 = first hit).
    departure_dir : ndarray, shape (m, 3)
        Unit direction in which the event's ray left the transmitter.
    travelled_m : ndarray, shape (m,)
        Path length transmitter -> ... -> hit of each event (m).
    event_phase_rad : ndarray, shape (m,)
        arg X of each event's speckle factor (rad).
    event : ndarray of int32, shape (n,)
        Event of each reception.
    channel : ndarray of int8 (int32 beyond 127 receivers), shape (n,)
        Receiver of each reception.
    gain : ndarray, shape (n,)
        |X| sqrt(mu sin(g_s) dOmega_eff) / r2 (relative to the source's pressure at 1 m), >= 0.
    receivers_m : ndarray, shape (n_rx, 3)
        The receivers (m).

    The receptions' path lengths, phases and arrival directions are derived from their event
    and receiver on demand (:attr:`path_length_m`, :attr:`phase_rad`, :attr:`arrival_dir`),
    as the row packing derives them: the tracer writes 13 bytes per reception, not 53.
    embree_legs : int
        Legs hit -> receiver the tracer sent to Embree's occlusion query (crossing the box of
        an object without face planes, or all legs when a receiver is outside the water).
    convex_legs : int
        Legs decided exactly by the face planes of the convex objects whose boxes they cross.
    embree_rays : int
        Rays (all bounces) whose first hit Embree found; the others' were found without it
        (:mod:`~acoustisim.propagation.diffuse_hits`, in a box tank with convex objects).
    """

    points_m: NDArray[np.float64]
    surface: NDArray[np.int32]
    parent: NDArray[np.int32]
    bounce: NDArray[np.int32]
    departure_dir: NDArray[np.float64]
    travelled_m: NDArray[np.float64]
    event_phase_rad: NDArray[np.float64]
    event: NDArray[np.int32]
    channel: NDArray[np.int8]
    gain: NDArray[np.float64]
    receivers_m: NDArray[np.float64]
    embree_legs: int = 0
    convex_legs: int = 0
    embree_rays: int = 0

    def _columns(self, length: bool, phase: bool, arrival: bool) -> tuple[NDArray[np.float64], ...]:
        n = self.event.size
        out = (np.empty(n if length else 0), np.empty(n if phase else 0), np.empty((n if arrival else 0, 3)))
        kernels.reception_columns(self.points_m, self.travelled_m, self.event_phase_rad, self.event, self.channel,
                                  self.receivers_m, *out)
        return out

    @cached_property
    def path_length_m(self) -> NDArray[np.float64]:
        """Transmitter -> ... -> hit -> receiver of each reception, shape (n,) (m)."""
        return self._columns(True, False, False)[0]

    @cached_property
    def phase_rad(self) -> NDArray[np.float64]:
        """arg X of each reception (its event's), shape (n,) (rad)."""
        return self._columns(False, True, False)[1]

    @cached_property
    def arrival_dir(self) -> NDArray[np.float64]:
        """Unit direction hit -> receiver of each reception, shape (n, 3)."""
        return self._columns(False, False, True)[2]


CHUNK_RAYS = 1 << 14
"""Rays per chunk of work. Chunks are traced independently (each with its own random stream,
seeded by ``(config.seed, chunk index)``) and their events concatenated in chunk order, so the
result does not depend on the number of threads that trace them."""

FIRST_HIT_MODES: tuple[str, ...] = ("auto", "embree")
"""How the tracer finds each ray's first hit: "auto" without Embree where the scene allows it (a
box tank with convex objects, :mod:`~acoustisim.propagation.diffuse_hits`; the same events as
Embree's but for rays grazing an edge), else Embree INTERSECT; "embree" always Embree (the
general triangle-mesh path, for comparisons and benchmarks)."""



@dataclass(frozen=True, eq=False)
class _Tracer:
    """What every chunk of rays reads (shared, read-only, by the threads).

    Attributes
    ----------
    raycaster : RayCaster
    lobe : _LobeTable
    cells : ndarray, shape (n_cells,)
        ``lobe.cells(totals)``: the solid angle of each cell's rays.
    mu : ndarray, shape (n_triangles,)
        Lambert mu of each triangle's surface.
    plane_offset : ndarray, shape (n_triangles,)
        Each triangle's plane offset (m), see :attr:`RayCaster.plane_offset`.
    normal : ndarray, shape (3, n_triangles)
        Unit normals as components.
    surface : ndarray of int64, shape (n_triangles,)
    transmitter : ndarray, shape (3,)
    origins32 : ndarray of float32, shape (CHUNK_RAYS, 3)
        The transmitter minus the ray caster's shift, repeated: Embree's origins of a chunk's
        first rays.
    frame : tuple of ndarray, shape (3,)
        (e1, e2, boresight): the transmitter's orthonormal frame.
    receivers : ndarray, shape (n_rx, 3)
    screen : tuple
        :meth:`ObjectScreen.kernel_arguments`.
    queues : bool
        Whether any leg may be left to Embree (a receiver outside the water, too many objects
        to screen one by one, or an object without face planes): else the chunks allocate no
        Embree leg buffers.
    tested : ndarray of bool, shape (2, n_rx)
        Receivers whose legs are tested for occlusion from first hits (row 0: not a receiver
        at the transmitter, whose leg is the ray itself) and from later ones (row 1); with
        ``"centre"`` visibility only the reference receiver's.
    shared : bool
        ``"centre"`` visibility: the reference receiver's leg decides for all.
    seed_hash : numpy.uint64
    bounces, n_rays : int
    totals : tuple of int
        Rays drawn uniformly and from the lobe, over all chunks (see :class:`_LobeTable`).
    buffers : threading.local
        Each tracing thread's :class:`_DrawBuffers` (attribute ``draw``), made on its first
        chunk of this solve.
    output : _Output
        The solve's output arrays, into which the chunks write.
    hits : tuple or None
        :meth:`~acoustisim.propagation.diffuse_hits.BoxTankHits.kernel_arguments` of the scene
        (first hits found without Embree), or None (a tank that is not a box: Embree finds
        every first hit).
    no_parent : ndarray of int32, shape (1,)
        -1: the parent of every first hit (read only).
    """

    raycaster: RayCaster
    lobe: _LobeTable
    cells: NDArray[np.float64]
    mu: NDArray[np.float64]
    plane_offset: NDArray[np.float64]
    normal: NDArray[np.float64]
    surface: NDArray[np.int64]
    transmitter: NDArray[np.float64]
    origins32: NDArray[np.float32]
    frame: tuple[NDArray[np.float64], ...]
    receivers: NDArray[np.float64]
    screen: tuple[Any, ...]
    queues: bool
    tested: NDArray[np.bool_]
    shared: bool
    seed_hash: np.uint64
    bounces: int
    n_rays: int
    totals: tuple[int, int]
    buffers: threading.local
    output: "_Output"
    hits: tuple[Any, ...] | None
    no_parent: NDArray[np.int32]


class _ChunkArrays:
    """Event and reception arrays a chunk writes into: the solve's output (:class:`_Output`) or
    a scratch block of one chunk's size, reused chunk after chunk.

    Parameters
    ----------
    events, receptions : int
        Rows of the event arrays (``points``, ``departure``: (events, 3); ``surface``,
        ``parent``, ``bounce``, ``travelled``, ``phase``: (events,)) and of the reception
        arrays (``event``, ``channel``, ``gain``: (receptions,)).
    n_rx : int
        Receivers (the channel dtype: int8 below 128).
    one_block : bool
        Carve the ten arrays out of one allocation (each starting on a 4 KiB page): one
        mapping large enough for numpy's transparent-huge-page advice, so that the pages a
        solve writes for the first time fault in 2 MiB at a time instead of 4 KiB (the
        solve's output: thousands of page faults fewer). Pages no row reaches are never
        touched and cost no memory.
    """

    def __init__(self, events: int, receptions: int, n_rx: int, one_block: bool = False) -> None:
        layout = (((events, 3), np.float64), ((events, 3), np.float64), ((events,), np.int32), ((events,), np.int32),
                  ((events,), np.int32), ((events,), np.float64), ((events,), np.float64), ((receptions,), np.int32),
                  ((receptions,), np.int8 if n_rx < 128 else np.int32), ((receptions,), np.float64))
        if one_block:
            page = 4096
            sizes = [-(-math.prod(shape) * np.dtype(dtype).itemsize // page) * page for shape, dtype in layout]
            block = np.empty(sum(sizes) + page, dtype=np.uint8)
            start = -block.ctypes.data % page  # the first page boundary in the block
            arrays = []
            for (shape, dtype), size in zip(layout, sizes):
                count = math.prod(shape)
                arrays.append(block[start:start + count * np.dtype(dtype).itemsize].view(dtype).reshape(shape))
                start += size
        else:
            arrays = [np.empty(shape, dtype=dtype) for shape, dtype in layout]
        (self.points, self.departure, self.surface, self.parent, self.bounce, self.travelled, self.phase, self.event,
         self.channel, self.gain) = arrays

    def arrays(self) -> tuple[NDArray[Any], ...]:
        """The ten arrays, in :func:`~acoustisim.propagation.diffuse_kernels.copy_chunk`'s order."""
        return (self.points, self.departure, self.surface, self.parent, self.bounce, self.travelled, self.phase,
                self.event, self.channel, self.gain)


class _Output(_ChunkArrays):
    """The solve's output arrays, sized for the most events and receptions the rays can make,
    and where each chunk writes.

    Chunk ``c`` writes its events bounce after bounce, and its receptions likewise: straight
    into the output at their final place when every earlier chunk was placed before it started
    (always on one thread: no copy at all), else into a scratch block of one chunk's size
    (:class:`_ChunkArrays`, from a pool: a block is reused once its chunk is placed, so its
    pages are warm and the output's pages are touched once). A finished chunk is placed once
    every earlier one is: a chunk written in a scratch block is then copied to its final place
    by :func:`~acoustisim.propagation.diffuse_kernels.copy_chunk`, its event indices shifted.
    The chunks' final places depend on their counts only, so the arrays are the same for any
    thread count. The ten arrays are carved out of one block (see :class:`_ChunkArrays`): pages
    that no chunk reaches cost no memory; :meth:`result` returns the leading views of the rows
    written.

    Parameters
    ----------
    n_rays, bounces, n_rx : int
        The solve's rays, bounces and receivers.
    """

    def __init__(self, n_rays: int, bounces: int, n_rx: int) -> None:
        capacity = n_rays * bounces  # one event per ray and bounce at most
        super().__init__(capacity, capacity * n_rx, n_rx, one_block=True)
        self.slot_events = min(CHUNK_RAYS, n_rays) * bounces  # the most a chunk makes
        self.slot_receptions = self.slot_events * n_rx
        self._n_rx = n_rx
        self._lock = threading.Lock()
        self._placed = 0  # chunks placed (every one before it too)
        self._events = 0  # their events and receptions
        self._receptions = 0
        self._finished: dict[int, tuple[_ChunkArrays, int, int]] = {}  # finished, not yet placed
        self._pool: list[_ChunkArrays] = []  # scratch blocks free for a chunk

    def start(self, chunk: int) -> tuple[_ChunkArrays, tuple[int, int]]:
        """Where chunk ``chunk`` writes: the arrays and the rows of its first event and
        reception (the output at the chunk's final place, or a scratch block from row 0)."""
        with self._lock:
            if chunk == self._placed:
                return self, (self._events, self._receptions)
            block = self._pool.pop() if self._pool else None
        if block is None:
            block = _ChunkArrays(self.slot_events, self.slot_receptions, self._n_rx)
        return block, (0, 0)

    def finish(self, chunk: int, target: _ChunkArrays, events: int, receptions: int) -> None:
        """Record that chunk ``chunk`` wrote ``events`` and ``receptions`` into ``target`` (from
        the rows :meth:`start` gave); place every finished chunk whose predecessors are placed."""
        copies = []  # (block, events, receptions, first event, first reception)
        with self._lock:
            self._finished[chunk] = (target, events, receptions)
            while self._placed in self._finished:
                block, n_events, n_receptions = self._finished.pop(self._placed)
                if block is not self:
                    copies.append((block, n_events, n_receptions, self._events, self._receptions))
                self._events += n_events
                self._receptions += n_receptions
                self._placed += 1
        # outside the lock (the other threads start and finish chunks meanwhile): each copy
        # goes to rows no other chunk writes, and its block returns to the pool once copied
        for block, n_events, n_receptions, first_event, first_reception in copies:
            kernels.copy_chunk(n_events, n_receptions, first_event, first_reception, *block.arrays(),
                               *self.arrays())
            with self._lock:
                self._pool.append(block)

    def result(self, receivers: NDArray[np.float64], legs: tuple[int, int, int]) -> "DiffuseEvents":
        """The events and receptions of every chunk (all placed): C-contiguous leading views of
        the output arrays (no copy; the block's pages beyond them were never touched and hold
        no memory)."""
        if self._finished:
            raise RuntimeError("diffuse tracer: a chunk was left unplaced")
        m, n = self._events, self._receptions
        return DiffuseEvents(self.points[:m], self.surface[:m], self.parent[:m], self.bounce[:m], self.departure[:m],
                             self.travelled[:m], self.phase[:m], self.event[:n], self.channel[:n], self.gain[:n],
                             receivers, *legs)


def _float32_rows(components: NDArray[np.float64], shift: NDArray[np.float64] | None, n: int) -> NDArray[np.float32]:
    """A C-contiguous float32 (n, 3) array of components (3, n) (or (3, 1), broadcast) minus ``shift``."""
    out = np.empty((n, 3), dtype=np.float32)
    for k in range(3):  # the three coordinates
        if shift is None:
            out[:, k] = components[k]
        else:
            np.subtract(components[k], shift[k], out=out[:, k], casting="unsafe")
    return out


def _hit_triangles(tracer: _Tracer, origins: NDArray[np.float64], directions: NDArray[np.float64],
                   first: bool, buffers: _DrawBuffers) -> tuple[NDArray[np.int32], int]:
    """The first-hit triangle (m,) of each ray from ``origins`` (3, m) (or (3, 1), shared)
    along ``directions`` (3, m), and the number of rays Embree was asked about.

    Found by :func:`~acoustisim.propagation.diffuse_hits.first_hits` where the scene allows,
    else (and for the rays it leaves pending) by Embree, on float32 rows of the directions
    made here (``first``: the first bounce, whose origin is the transmitter). The triangles
    are written into ``buffers.triangle`` (a view of it is returned) unless Embree finds them
    all.
    """
    raycaster = tracer.raycaster
    shift = raycaster.shift_m
    m = directions.shape[1]
    if tracer.hits is None:
        origins32 = tracer.origins32[:m] if first else _float32_rows(origins, shift, m)
        return raycaster.first_hit_triangles32(origins32, _float32_rows(directions, None, m)), m
    triangle, pending = buffers.triangle[:m], buffers.pending[:m]
    k = first_hits(origins, directions, *tracer.hits, triangle, pending)
    if k:
        rays = pending[:k]
        origins32 = tracer.origins32[:k] if first else _float32_rows(origins[:, rays], shift, k)
        triangle[rays] = raycaster.first_hit_triangles32(origins32, _float32_rows(directions[:, rays], None, k))
    return triangle, k


def _trace_chunk(tracer: _Tracer, chunk: int) -> tuple[int, int, int]:
    """Trace chunk ``chunk`` (rays ``chunk CHUNK_RAYS`` onwards) through every bounce, writing
    its events and receptions into ``tracer.output``; return the legs it sent to Embree, those
    the convex objects' planes decided and the rays whose first hit Embree found."""
    n = min(CHUNK_RAYS, tracer.n_rays - chunk * CHUNK_RAYS)
    rng = _ChunkStream.create(tracer.seed_hash, chunk)
    raycaster = tracer.raycaster
    shift = raycaster.shift_m
    rx = tracer.receivers
    n_rx = rx.shape[0]
    out, base = tracer.output.start(chunk)  # the output at the chunk's final place, or a scratch block
    event_row, reception_row = base  # where the next bounce's events and receptions go
    buffers = getattr(tracer.buffers, "draw", None)  # this thread's, reused chunk after chunk
    if buffers is None:
        buffers = tracer.buffers.draw = _DrawBuffers.create(min(tracer.n_rays, CHUNK_RAYS), n_rx)
    directions, weight = tracer.lobe.draw(n, tracer.totals, tracer.frame, rng, buffers, tracer.cells)
    departure = directions
    origins = tracer.transmitter[:, None]  # (3, 1) for the first bounce, then (3, h)
    travelled = np.zeros(1)
    parent = tracer.no_parent  # (1,): shared by the first bounce's rays
    legs = [0, 0, 0]  # sent to Embree, decided by the convex objects' planes; rays sent to Embree
    for bounce in range(tracer.bounces):  # a handful of bounces
        m = directions.shape[1]
        triangle, embree_rays = _hit_triangles(tracer, origins, directions, bounce == 0, buffers)
        legs[2] += embree_rays
        keep = bounce + 1 < tracer.bounces  # the rays continue
        # the events go straight to the output, from row event_row on
        normal = np.empty((3, m if keep else 0))  # written for continuing rays only
        hit_weight, mu = np.empty(m if keep else 0), np.empty(m if keep else 0)
        # next-event estimation to every receiver; Embree tests the legs that may be blocked
        # by a non-convex object
        pairs = m * n_rx
        state, pair_gain = buffers.state[:pairs], buffers.pair_gain[:pairs]
        legs_max = pairs if tracer.queues else 0  # no Embree buffers when every leg is decided here
        leg_start, leg_unit = np.empty((legs_max, 3), dtype=np.float32), np.empty((legs_max, 3), dtype=np.float32)
        leg_length, leg_pair = np.empty(legs_max, dtype=np.float32), np.empty(legs_max, dtype=np.int64)
        mode, lo, hi, own_box, wedges, point_wedges, plane_start, plane_normal, plane_offset = tracer.screen
        n_hits, n_legs, n_exact, count = kernels.scatter_and_pair(
            triangle, directions, origins, weight, travelled, parent, departure, tracer.mu, tracer.normal,
            tracer.plane_offset, tracer.surface, SPECKLE_CELL_M, tracer.seed_hash,
            rx, tracer.tested[min(bounce, 1)], mode, lo, hi, own_box, wedges, point_wedges, plane_start, plane_normal,
            plane_offset, shift, DEFAULT_EPS_M, tracer.shared, keep, event_row,
            out.points, normal, out.departure, hit_weight, out.travelled, out.parent, out.surface, out.bounce,
            bounce + 1, mu, out.phase,
            state, pair_gain, leg_start, leg_unit, leg_length, leg_pair,
            -1 if tracer.queues else reception_row, out.event, out.channel, out.gain,
        )
        if n_hits == 0:
            break
        legs[0] += n_legs
        legs[1] += n_exact
        if not tracer.queues:  # the kernel wrote the receptions
            reception_row += count
        else:
            if n_legs:
                blocked = raycaster.occluded_segments32(leg_start[:n_legs], leg_unit[:n_legs], leg_length[:n_legs])
                kernels.clear_blocked(state, leg_pair[:n_legs], blocked, tracer.shared, n_rx, n_hits)
            reception_row = kernels.write_receptions(n_hits, n_rx, state, pair_gain, event_row, reception_row,
                                                     out.event, out.channel, out.gain)
        rows = slice(event_row, event_row + n_hits)
        event_row += n_hits
        if bounce + 1 >= tracer.bounces:
            break
        parent = np.arange(rows.start, rows.stop, dtype=np.int32)
        # continue in a cosine-weighted direction about the normal: weight x (pi mu)
        points, normal = out.points[rows].T, normal[:, :n_hits]
        # the next bounce's input: contiguous, as the first's (one compiled specialisation)
        departure = np.ascontiguousarray(out.departure[rows].T)
        u = rng.random((2, n_hits))
        radius = np.sqrt(u[0])
        along_1, along_2 = _unit_circle(u[1])
        along_1 *= radius
        along_2 *= radius
        along_n = np.sqrt(np.maximum(1.0 - u[0], 0.0))
        t1, t2 = _tangents(normal[0], normal[1], normal[2])
        directions = t1
        directions *= along_1
        t2 *= along_2
        directions += t2
        directions += normal * along_n
        weight = hit_weight[:n_hits] * math.pi * mu[:n_hits]
        travelled = out.travelled[rows]
        origins = points + OFFSET_M * normal  # the 2e-5 m offset (14 ps) is not added to the path
    tracer.output.finish(chunk, out, event_row - base[0], reception_row - base[1])
    return legs[0], legs[1], legs[2]


def _setup(context: SolveContext, config: SolverConfig, threads: int | None,
           visibility: str, first_hits: str = "auto") -> _Tracer | None:
    """Validate the knobs and set up the tracer (None: nothing to trace)."""
    n_rays = int(config.diffuse_rays)
    if n_rays * int(config.diffuse_bounces) > MAX_RAY_EVENTS:
        raise InputError(
            f"solver.diffuse_rays = {config.diffuse_rays!r} with diffuse_bounces = {config.diffuse_bounces!r}: "
            f"more than {MAX_RAY_EVENTS} scattering events; use fewer rays"
        )
    resolve_threads(threads)
    if visibility not in VISIBILITY_MODES:
        raise InputError(f"diffuse visibility = {visibility!r}: must be one of {', '.join(VISIBILITY_MODES)}")
    if first_hits not in FIRST_HIT_MODES:
        raise InputError(f"diffuse first_hits = {first_hits!r}: must be one of {', '.join(FIRST_HIT_MODES)}")
    scene = context.scene
    raycaster = context.raycaster
    mu_of_surface = np.array(
        [b.material.diffuse_mu for b in scene.boundaries] + [o.material.diffuse_mu for o in scene.objects], dtype=float
    )
    # No surface scatters (e.g. an empty free field): nothing to trace.
    if n_rays <= 0 or raycaster.triangle_count == 0 or not np.any(mu_of_surface > 0.0):
        return None
    tx = np.asarray(context.transmitter_m, dtype=float)
    rx = np.asarray(context.receivers_m, dtype=float)
    boresight = np.asarray(context.boresight, dtype=float)
    n_rx = rx.shape[0]
    tested = np.ones((2, n_rx), dtype=bool)
    tested[0] = ~np.all(rx == tx, axis=1)  # a first hit's leg back to the transmitter is its ray
    if visibility == "centre":  # only the receiver nearest the centroid is tested, for all
        reference = int(np.argmin(np.linalg.norm(rx - rx.mean(axis=0), axis=1)))
        tested[:, np.arange(n_rx) != reference] = False
    sizes = [CHUNK_RAYS] * (n_rays // CHUNK_RAYS) + ([n_rays % CHUNK_RAYS] if n_rays % CHUNK_RAYS else [])
    n_uniform = sum(_LobeTable.uniform_count(size) for size in sizes)
    screen = ObjectScreen.create(scene, rx, raycaster.convex_planes).kernel_arguments()
    bounces = int(config.diffuse_bounces)
    lobe = _LobeTable.create(context)
    totals = (n_uniform, n_rays - n_uniform)
    return _Tracer(
        raycaster=raycaster,
        lobe=lobe,
        cells=lobe.cells(totals),
        mu=mu_of_surface[raycaster.surface_index],
        plane_offset=raycaster.plane_offset,
        normal=np.ascontiguousarray(raycaster.face_normals.T),
        surface=raycaster.surface_index,
        transmitter=tx,
        origins32=_float32_rows(tx[:, None], raycaster.shift_m, min(n_rays, CHUNK_RAYS)),
        frame=(*_basis(boresight), boresight),
        receivers=np.ascontiguousarray(rx),
        screen=screen,
        queues=screen[0] == 2 or (screen[0] == 1 and (screen[1].shape[0] == 1 or bool(np.any(
            screen[6][1:-1] == screen[6][2:])))),
        tested=tested,
        shared=visibility == "centre",
        seed_hash=_seed_hash(int(config.seed)),
        bounces=bounces,
        n_rays=n_rays,
        totals=totals,
        buffers=threading.local(),
        output=_Output(n_rays, bounces, n_rx),
        hits=None if first_hits == "embree" or raycaster.box_tank_hits is None
        else raycaster.box_tank_hits.kernel_arguments(),
        no_parent=np.full(1, -1, dtype=np.int32),
    )


def trace_diffuse(context: SolveContext, config: SolverConfig, *, threads: int | None = None,
                  visibility: str = "exact", first_hits: str = "auto") -> DiffuseEvents:
    """Trace ``config.diffuse_rays`` rays through ``config.diffuse_bounces`` Lambert scatterings.

    The rays are traced in chunks of :data:`CHUNK_RAYS` on up to ``threads`` threads; the result
    is the same for any thread count.

    Parameters
    ----------
    context : SolveContext
    config : SolverConfig
        ``diffuse_rays``, ``diffuse_bounces``, ``seed``.
    threads : int or None
        Worker threads (>= 1); None: every core available to the process.
    visibility : {"exact", "centre"}
        See :data:`VISIBILITY_MODES`.
    first_hits : {"auto", "embree"}
        See :data:`FIRST_HIT_MODES`.

    Returns
    -------
    DiffuseEvents

    Raises
    ------
    InputError
        If ``diffuse_rays x diffuse_bounces`` exceeds :data:`MAX_RAY_EVENTS`, or ``threads``,
        ``visibility`` or ``first_hits`` is invalid.
    """
    tracer = _setup(context, config, threads, visibility, first_hits)
    rx = np.ascontiguousarray(context.receivers_m, dtype=float)
    if tracer is None:
        return _Output(0, 1, rx.shape[0]).result(rx, (0, 0, 0))
    n_chunks = -(-tracer.n_rays // CHUNK_RAYS)
    legs = run_in_order(lambda chunk: _trace_chunk(tracer, chunk), range(n_chunks), resolve_threads(threads))
    return tracer.output.result(rx, tuple(sum(counts) for counts in zip(*legs)))


_PACK_ROWS = 1 << 15
"""Rows packed per task by :func:`diffuse_paths`."""


def diffuse_paths(context: SolveContext, config: SolverConfig, *, threads: int | None = None,
                  visibility: str = "exact") -> NDArray[Any]:
    """Diffuse reverberation rows for one sonar pose.

    Parameters
    ----------
    context : SolveContext
    config : SolverConfig
        ``diffuse_rays`` (0 gives no rows), ``diffuse_bounces``, ``seed``.
    threads : int or None
        Worker threads tracing and packing the chunks (>= 1); None: every available core.
        The rows are the same for any value.
    visibility : {"exact", "centre"}
        See :data:`VISIBILITY_MODES` ("centre" approximates).

    Returns
    -------
    structured ndarray of PATH_DTYPE, shape (n,)
        One row per (scattering event, receiver) with ``kind = DIFFUSE``, ``order`` the bounce
        number, ``path_id`` from ``context.first_path_id`` upwards, one per scattering event
        (shared by the receivers that see it, whose rows are adjacent), and the other mechanism
        columns; :func:`~acoustisim.propagation.columns.complete_columns`, which
        :func:`~acoustisim.propagation.solve` applies to every mechanism's rows, derives the
        delay, angles, directivities, absorption and amplitude.
    """
    if int(config.diffuse_rays) <= 0:
        return empty_paths_array(0)
    events = trace_diffuse(context, config, threads=threads, visibility=visibility)
    n = events.event.size
    rows = np.empty(n, dtype=PATH_DTYPE)  # every byte is written by pack_rows
    first = int(context.first_path_id)
    e = events

    def pack(a: int) -> None:
        kernels.pack_rows(rows, a, min(a + _PACK_ROWS, n), first, int(PathKind.DIFFUSE), e.event, e.channel,
                          e.gain, e.travelled_m, e.event_phase_rad, e.receivers_m, e.points_m, e.surface, e.parent,
                          e.bounce, e.departure_dir)

    run_in_order(pack, range(0, n, _PACK_ROWS), resolve_threads(threads))
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
    "CHUNK_RAYS",
    "VISIBILITY_MODES",
    "ObjectScreen",
    "receiver_wedges",
    "shared_wedges",
]
