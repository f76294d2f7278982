"""The fast engine's Lambert diffuse tracer: the reference tracer's rows, from compiled loops.

Computes what :mod:`acoustisim.propagation.reference.diffuse` computes (read it for the physics,
the estimator and the random numbers), with the same counter-based random numbers, tables and
float64 hit points, so that the rows agree to rounding. What is added is speed:

* the chunks of :data:`~acoustisim.propagation.reference.diffuse.CHUNK_RAYS` rays are traced on
  a small thread pool (:mod:`~acoustisim.propagation.fast.ray_threads`; Embree and the compiled
  loops release the GIL), each drawing its numbers inside the loops that use them
  (:mod:`~acoustisim.propagation.fast.diffuse_sampling`);
* in a box tank whose objects are convex, first hits are found without Embree
  (:mod:`~acoustisim.propagation.fast.diffuse_hits`), and the legs hit -> receiver are screened
  by the objects' boxes and decided by the convex objects' face planes
  (:mod:`~acoustisim.propagation.fast.diffuse_screen`); Embree is asked only about the rest;
* the per-hit and per-pair arithmetic runs in one compiled loop writing the solve's output
  arrays directly (:mod:`~acoustisim.propagation.fast.diffuse_kernels`), each chunk at its final
  place when it can (:mod:`~acoustisim.propagation.fast.diffuse_output`); buffers are reused
  chunk after chunk by each thread.

The rows are the same for any number of threads.
"""

from __future__ import annotations

import math
import threading
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from acoustisim.propagation.config import SolverConfig
from acoustisim.propagation.context import SolveContext
from acoustisim.propagation.fast.diffuse_hits import BoxTank, box_tank, first_hits
from acoustisim.propagation.fast.diffuse_kernels import (
    BounceCursor,
    Continuation,
    EventArrays,
    PairBuffers,
    RayBatch,
    ReceiverSet,
    RoughTable,
    SpeckleLattice,
    TriangleSet,
    clear_blocked,
    pack_rows,
    scatter_and_pair,
    write_receptions,
)
from acoustisim.propagation.fast.diffuse_output import ChunkPlacement, event_arrays
from acoustisim.propagation.fast.diffuse_sampling import (
    LobeTable,
    draw_lambert_directions,
    draw_transmit_directions,
    lobe_table,
    stream_key,
)
from acoustisim.propagation.fast.diffuse_screen import LegScreen, leg_screen
from acoustisim.propagation.fast.ray_threads import resolve_threads, run_in_order
from acoustisim.propagation.paths import PATH_DTYPE, PathKind, empty_paths_array
from acoustisim.propagation.raycast import DEFAULT_EPS_M, RayCaster
from acoustisim.propagation.reference.diffuse import (
    CHUNK_RAYS,
    OFFSET_M,
    SPECKLE_CELL_M,
    RoughScattering,
    check_ray_budget,
    chunk_sizes,
    ray_counts,
    rough_scattering,
    seed_hash,
    tested_receivers,
    transmitter_frame,
    triangle_mu,
    uniform_count,
)

PACK_ROWS = 1 << 15
"""Rows packed per task by :func:`diffuse_rows`."""


@dataclass(frozen=True, eq=False)
class DiffuseEvents:
    """The fast tracer's scattering events and receptions, before row packing.

    Attributes
    ----------
    events : EventArrays
        Events (m,): hit ``point`` and ray ``departure`` (m, 3), ``surface``, ``parent`` (the
        previous event of the ray, -1 for a first hit), ``bounce`` (1 = first hit),
        ``travelled`` (m, to the point), speckle ``phase`` (rad); receptions (n,): ``event``,
        ``channel``, ``gain`` (geometric_gain).
    receivers_m : ndarray, shape (n_rx, 3)
    embree_legs : int
        Legs hit -> receiver sent to Embree's occlusion query.
    convex_legs : int
        Legs decided by the face planes of the convex objects whose boxes they cross.
    embree_rays : int
        Rays (all bounces) whose first hit Embree found.
    """

    events: EventArrays
    receivers_m: NDArray[np.float64]
    embree_legs: int = 0
    convex_legs: int = 0
    embree_rays: int = 0


@dataclass(frozen=True, eq=False)
class ThreadBuffers:
    """One tracing thread's buffers, reused chunk after chunk (fresh memory costs more, in page
    faults, than the kernels that fill it): a chunk's transmitted ``directions`` (3 capacity)
    and ``solid_angle``; a bounce's hit ``triangle`` and ``pending`` rays; its pairs' ``state``
    and ``gain`` (capacity x receivers)."""

    directions: NDArray[np.float64]
    solid_angle: NDArray[np.float64]
    triangle: NDArray[np.int32]
    pending: NDArray[np.int64]
    state: NDArray[np.int8]
    gain: NDArray[np.float64]

    @classmethod
    def create(cls, capacity: int, n_rx: int) -> "ThreadBuffers":
        """Uninitialised buffers for ``capacity`` rays and ``n_rx`` receivers."""
        return cls(np.empty(3 * capacity), np.empty(capacity), np.empty(capacity, dtype=np.int32),
                   np.empty(capacity, dtype=np.int64), np.empty(capacity * n_rx, dtype=np.int8),
                   np.empty(capacity * n_rx))


@dataclass(frozen=True, eq=False)
class Tracer:
    """What every chunk of one solve reads (shared, read-only, by the threads).

    Attributes
    ----------
    raycaster : RayCaster
    lobe : LobeTable
    triangles : TriangleSet
    rough : RoughTable
        Per surface, the coherent-roughness loss the hits scatter (all k0 h = 0: none).
    lattice : SpeckleLattice
    receivers : ReceiverSet
        With row 0 of the tested receivers (first hits); :attr:`later_receivers` has row 1.
    later_receivers : ReceiverSet
    screen : LegScreen
    tank : BoxTank or None
        First hits without Embree (None: a tank that is not a box; Embree finds them all).
    transmitter : ndarray, shape (3, 1)
    origins32 : ndarray of float32, shape (min(n_rays, CHUNK_RAYS), 3)
        The transmitter in Embree's frame, repeated: the origins of a chunk's first rays.
    frame : ndarray, shape (3, 3)
        Rows e1, e2, axis of the transmitter's frame.
    n_rays, bounces : int
    buffers : threading.local
        Each thread's :class:`ThreadBuffers` (attribute ``buffers``).
    placement : ChunkPlacement
    """

    raycaster: RayCaster
    lobe: LobeTable
    triangles: TriangleSet
    rough: RoughTable
    lattice: SpeckleLattice
    receivers: ReceiverSet
    later_receivers: ReceiverSet
    screen: LegScreen
    tank: BoxTank | None
    transmitter: NDArray[np.float64]
    origins32: NDArray[np.float32]
    frame: NDArray[np.float64]
    n_rays: int
    bounces: int
    buffers: threading.local
    placement: ChunkPlacement

    @classmethod
    def create(cls, context: SolveContext, config: SolverConfig) -> "Tracer | None":
        """The tracer of ``config``'s rays in ``context`` (None: no surface scatters)."""
        raycaster = context.raycaster
        mu = triangle_mu(context)
        rough = rough_scattering(context)
        n_rays = int(config.diffuse_rays)
        if n_rays <= 0 or raycaster.triangle_count == 0 or (rough is None and not np.any(mu > 0.0)):
            return None
        rx = np.ascontiguousarray(context.receivers_m, dtype=float)
        tx = np.asarray(context.transmitter_m, dtype=float)
        tested = tested_receivers(context, config.diffuse_visibility)
        shared = config.diffuse_visibility == "centre"
        screen = leg_screen(context.scene, rx, raycaster.convex_planes)

        def receivers(row: int) -> ReceiverSet:
            return ReceiverSet(rx, np.ascontiguousarray(tested[row]), shared, raycaster.shift_m, DEFAULT_EPS_M)

        return cls(
            raycaster=raycaster,
            lobe=lobe_table(context, ray_counts(n_rays)),
            triangles=TriangleSet(mu, np.ascontiguousarray(raycaster.face_normals.T), raycaster.plane_offset,
                                  raycaster.surface_index),
            rough=rough_table(rough, len(context.scene.surface_names)),
            lattice=SpeckleLattice(1.0 / SPECKLE_CELL_M, seed_hash(int(config.seed))),
            receivers=receivers(0),
            later_receivers=receivers(1),
            screen=screen,
            tank=box_tank(raycaster),
            transmitter=np.ascontiguousarray(tx[:, None]),
            origins32=_float32_rows(tx[:, None], raycaster.shift_m, min(n_rays, CHUNK_RAYS)),
            frame=np.array(transmitter_frame(context.boresight)),
            n_rays=n_rays,
            bounces=int(config.diffuse_bounces),
            buffers=threading.local(),
            placement=ChunkPlacement(n_rays, int(config.diffuse_bounces), rx.shape[0], CHUNK_RAYS),
        )

    def thread_buffers(self) -> ThreadBuffers:
        """The calling thread's buffers (made on its first chunk of this solve)."""
        buffers = getattr(self.buffers, "buffers", None)
        if buffers is None:
            buffers = self.buffers.buffers = ThreadBuffers.create(min(self.n_rays, CHUNK_RAYS),
                                                                  self.receivers.position.shape[0])
        return buffers


def rough_table(rough: RoughScattering | None, n_surfaces: int) -> RoughTable:
    """The compiled loops' :class:`RoughTable` of the reference's description (None: every
    surface smooth, k0 h = 0)."""
    k0h = np.zeros(n_surfaces)
    constant = np.ones(n_surfaces)
    impedance = np.ones(n_surfaces)
    index_sq = np.ones(n_surfaces)
    elastic = np.zeros(n_surfaces, dtype=bool)
    density_ratio = np.ones(n_surfaces)
    index_l = np.ones(n_surfaces, dtype=complex)
    index_s = np.zeros(n_surfaces, dtype=complex)
    if rough is not None:
        k0h[:] = rough.k0 * rough.rms_height_m
        z1 = rough.density_kg_m3 * rough.sound_speed_m_s
        for s, material in enumerate(rough.material):  # a loop over the scene's surfaces
            if material.model == "fluid":
                constant[s] = np.nan
                impedance[s] = material.density_kg_m3 * material.sound_speed_m_s / z1
                ratio = material.sound_speed_m_s / rough.sound_speed_m_s
                index_sq[s] = ratio * ratio
            elif material.model == "elastic":
                constant[s] = np.nan
                elastic[s] = True
                density_ratio[s] = material.density_kg_m3 / rough.density_kg_m3
                index_l[s] = material.refraction_index(rough.sound_speed_m_s, "compressional")
                if material.is_solid:
                    index_s[s] = material.refraction_index(rough.sound_speed_m_s, "shear")
            elif material.model == "fixed":
                constant[s] = material.fixed_reflection * material.fixed_reflection
    return RoughTable(k0h, constant, impedance, index_sq, elastic, density_ratio, index_l, index_s)


def _float32_rows(components: NDArray[np.float64], shift: NDArray[np.float64] | None, n: int) -> NDArray[np.float32]:
    """A C-contiguous float32 (n, 3) array of components (3, n) (or (3, 1), broadcast) minus
    ``shift``, each rounded once from float64 (as the ray caster rounds its queries)."""
    out = np.empty((n, 3), dtype=np.float32)
    for k in range(3):  # the three coordinates
        if shift is None:
            out[:, k] = components[k]
        else:
            np.subtract(components[k], shift[k], out=out[:, k], casting="unsafe")
    return out


def _hit_triangles(tracer: Tracer, origins: NDArray[np.float64], directions: NDArray[np.float64], first: bool,
                   buffers: ThreadBuffers) -> tuple[NDArray[np.int32], int]:
    """The hit triangle (m,) of each ray from ``origins`` (3, m) (or (3, 1): the transmitter,
    ``first``) along ``directions`` (3, m), and the number of rays Embree was asked about:
    :func:`~acoustisim.propagation.fast.diffuse_hits.first_hits` where the scene allows, Embree
    for the others."""
    raycaster = tracer.raycaster
    shift = raycaster.shift_m
    m = directions.shape[1]
    if tracer.tank is None:
        origins32 = tracer.origins32[:m] if first else _float32_rows(origins, shift, m)
        return raycaster.first_hit_triangles32(origins32, _float32_rows(directions, None, m)), m
    triangle, pending = buffers.triangle[:m], buffers.pending[:m]
    k = first_hits(origins, directions, tracer.tank, triangle, pending)
    if k:
        rays = pending[:k]
        origins32 = tracer.origins32[:k] if first else _float32_rows(origins[:, rays], shift, k)
        triangle[rays] = raycaster.first_hit_triangles32(origins32, _float32_rows(directions[:, rays], None, k))
    return triangle, k


def _trace_chunk(tracer: Tracer, chunk: int) -> tuple[int, int, int]:
    """Trace chunk ``chunk`` through every bounce, writing its events and receptions through
    ``tracer.placement``; return the legs it sent to Embree, the legs the convex objects' planes
    decided, and the rays whose first hit Embree found."""
    n = min(CHUNK_RAYS, tracer.n_rays - chunk * CHUNK_RAYS)
    key = stream_key(tracer.lattice.seed_hash, chunk)
    drawn = 2 * n  # numbers of the chunk's stream used so far
    raycaster = tracer.raycaster
    n_rx = tracer.receivers.position.shape[0]
    out, event_row, reception_row = tracer.placement.start(chunk)
    first_event, first_reception = event_row, reception_row
    buffers = tracer.thread_buffers()
    directions = buffers.directions[:3 * n].reshape(3, n)
    weight = buffers.solid_angle[:n]
    draw_transmit_directions(key, 0, uniform_count(n), tracer.lobe, tracer.frame, directions, weight)
    departure = directions
    origins = tracer.transmitter  # (3, 1) for the first bounce, then (3, h)
    travelled = np.zeros(1)
    parent = np.full(1, -1, dtype=np.int32)  # the transmitter: shared by the first bounce's rays
    embree_legs = convex_legs = embree_rays = 0
    for bounce in range(1, tracer.bounces + 1):
        m = directions.shape[1]
        triangle, asked = _hit_triangles(tracer, origins, directions, bounce == 1, buffers)
        embree_rays += asked
        continues = bounce < tracer.bounces
        continuation = Continuation(np.empty((3, m if continues else 0)), np.empty(m if continues else 0),
                                    np.empty(m if continues else 0))
        legs = m * n_rx if tracer.screen.uses_embree else 0  # no Embree buffers when every leg is decided here
        pairs = PairBuffers(buffers.state[:m * n_rx], buffers.gain[:m * n_rx], np.empty((legs, 3), dtype=np.float32),
                            np.empty((legs, 3), dtype=np.float32), np.empty(legs, dtype=np.float32),
                            np.empty(legs, dtype=np.int64))
        receivers = tracer.receivers if bounce == 1 else tracer.later_receivers
        cursor = BounceCursor(bounce, event_row, -1 if tracer.screen.uses_embree else reception_row, continues)
        rays = RayBatch(triangle, origins, directions, departure, weight, travelled, parent)
        counts = scatter_and_pair(rays, tracer.triangles, tracer.rough, tracer.lattice, receivers, tracer.screen,
                                  cursor, out, continuation, pairs)
        h = counts.hits
        if h == 0:
            break
        embree_legs += counts.embree_legs
        convex_legs += counts.convex_legs
        if not tracer.screen.uses_embree:  # the kernel wrote the receptions
            reception_row += counts.in_view
        else:
            if counts.embree_legs:
                k = counts.embree_legs
                blocked = raycaster.occluded_segments32(pairs.leg_start[:k], pairs.leg_unit[:k], pairs.leg_length[:k])
                clear_blocked(pairs.state, pairs.leg_pair[:k], blocked, receivers.shared, n_rx)
            reception_row = write_receptions(h, n_rx, pairs, event_row, reception_row, out)
        rows = slice(event_row, event_row + h)
        event_row += h
        if not continues:
            break
        # continue in cosine-weighted directions about the normals: weight x (pi mu)
        normal = continuation.normal[:, :h]
        directions = np.empty((3, h))
        draw_lambert_directions(key, drawn, normal, tracer.lobe.azimuth, directions)
        drawn += 2 * h
        parent = np.arange(rows.start, rows.stop, dtype=np.int32)
        departure = np.ascontiguousarray(out.departure[rows].T)
        weight = continuation.weight[:h] * math.pi * continuation.mu[:h]
        travelled = out.travelled[rows]
        # the offset (14 ps) is not added to the path
        origins = np.ascontiguousarray(out.point[rows].T + OFFSET_M * normal)
    tracer.placement.finish(chunk, out, event_row - first_event, reception_row - first_reception)
    return embree_legs, convex_legs, embree_rays


def trace_diffuse(context: SolveContext, config: SolverConfig) -> DiffuseEvents:
    """Trace ``config.diffuse_rays`` rays through ``config.diffuse_bounces`` Lambert scatterings,
    on ``config.threads`` threads (the result is the same for any number).

    Raises
    ------
    InputError
        If ``diffuse_rays x diffuse_bounces`` exceeds
        :data:`~acoustisim.propagation.reference.diffuse.MAX_RAY_EVENTS`.
    """
    check_ray_budget(config)
    threads = resolve_threads(config.threads)
    rx = np.ascontiguousarray(context.receivers_m, dtype=float)
    tracer = Tracer.create(context, config)
    if tracer is None:
        return DiffuseEvents(event_arrays(0, 0, rx.shape[0]), rx)
    counts = run_in_order(lambda chunk: _trace_chunk(tracer, chunk), range(len(chunk_sizes(tracer.n_rays))), threads)
    embree_legs, convex_legs, embree_rays = (sum(column) for column in zip(*counts))
    return DiffuseEvents(tracer.placement.placed(), rx, embree_legs, convex_legs, embree_rays)


def diffuse_rows(context: SolveContext, config: SolverConfig) -> NDArray[Any]:
    """Diffuse reverberation rows for one sonar pose: those of
    :func:`acoustisim.propagation.reference.diffuse.diffuse_rows`, in the same order.

    Returns
    -------
    structured ndarray of PATH_DTYPE, shape (n,)
        One row per (scattering event, receiver) heard, ``kind = DIFFUSE``, ``order`` the
        bounce, ``path_id`` ``context.first_path_id`` plus the event's index (shared by the
        receivers of one event, whose rows are adjacent); the derived columns zeroed.
    """
    if int(config.diffuse_rays) <= 0:
        check_ray_budget(config)
        return empty_paths_array(0)
    traced = trace_diffuse(context, config)
    events = traced.events
    n = events.event.size
    rows = np.empty(n, dtype=PATH_DTYPE)  # every byte is written by pack_rows
    first, kind = int(context.first_path_id), int(PathKind.DIFFUSE)

    def pack(start: int) -> None:
        pack_rows(events, traced.receivers_m, first, kind, start, min(start + PACK_ROWS, n), rows)

    run_in_order(pack, range(0, n, PACK_ROWS), resolve_threads(config.threads))
    return rows


__all__ = ("PACK_ROWS", "DiffuseEvents", "ThreadBuffers", "Tracer", "diffuse_rows", "rough_table", "trace_diffuse")
