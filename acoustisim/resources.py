"""Resource limits and the estimate of what a simulation will need.

A legal scene can still be too big for the machine: a 1 TS/s digitiser, a million pings, two
thousand plates reflecting one another. :func:`estimate_resources` predicts, before any work,
the memory of the recording and the synthesis (pings x channels x samples), of the path table
and of the meshes, the number of triangles, of diffuse ray-bounces and of specular
reflector sequences; :class:`ResourceLimits` holds the bounds they are compared with.

Limits in force
---------------
:func:`current_limits` returns the limits of the innermost ``with resource_limits(...)``
block, else those of the environment (``ACOUSTISIM_MAX_MEMORY_GB``, ``ACOUSTISIM_MAX_TRIANGLES``,
``ACOUSTISIM_MAX_RAYS``, ``ACOUSTISIM_MAX_CHAINS``, ``ACOUSTISIM_MAX_OBJECTS``), else the
defaults. The command line's ``--max-memory-gb``, ``--max-triangles``, ``--max-rays``,
``--max-chains`` and ``--max-objects`` open such a block
around the command; a Python caller opens one itself. The block is a context variable, so it
is local to a thread or task and ends with the ``with``.

Memory model (bytes)
--------------------
Measured with ``tracemalloc`` on ``simulate`` (free-sphere and thesis-tank scenes, 20 k to
4 M samples per channel, 1 to 40 pings): a fixed 8 MiB, 48 B per channel-sample of working
spectra and signals, per ping 20 B per channel-sample (float64 volts, int16 codes, the inverse
FFT's output) and 1 KiB (its random generator); 730 B per path-table row (243 B rows, kept
three times: solver parts, sorted table, arrivals); 1 KiB per triangle (trimesh caches, the
Embree scene, the solver's per-face arrays: 2,000 spheres of 1,280 triangles held 2.7 GB).
The estimate is within a factor of two of the peak, which is what a refusal needs.
"""

from __future__ import annotations

import contextlib
import math
import os
from contextvars import ContextVar
from dataclasses import dataclass, fields, replace
from functools import cached_property
from types import MappingProxyType
from typing import TYPE_CHECKING, Any, Iterator, Mapping

import numpy as np

from acoustisim.errors import InputError

if TYPE_CHECKING:
    from acoustisim.propagation.config import SolverConfig
    from acoustisim.scene import Scene
    from acoustisim.sonar import SonarHead

GIB = float(1 << 30)

FIXED_BYTES = 8 << 20
"""Memory of a synthesis that does not grow with the record (plans, tables)."""
WORKSPACE_BYTES_PER_SAMPLE = 48
"""Working spectra and signals per channel-sample, once per simulation."""
PING_BYTES_PER_SAMPLE = 20
"""Per ping and channel-sample: float64 volts, int16 codes, the inverse FFT's output."""
RECORDING_BYTES_PER_SAMPLE = 10
"""Of which the recording itself: float64 volts and int16 codes."""
PING_OVERHEAD_BYTES = 1024
"""Per ping: its random generator and bookkeeping."""
PATH_ROW_BYTES = 3 * 243
"""Per path-table row: 243 B, kept three times (solver parts, sorted table, arrivals)."""
TRIANGLE_BYTES = 1024
"""Per triangle: trimesh caches, the Embree scene, the solver's per-face arrays."""
EDGE_ROWS_PER_METRE = 2000
"""Path rows per metre of an object's sharp edges and per channel. Measured: the free-field
60 degree prism (3.6 m of edges, 1 m ahead) makes 1,500; the free cylinder's rims 2,200;
the thesis tank's objects (5.5 m) 960. The tank's own corners are left out: far from the
sonar and graded coarsely, its 52 m of corners add a few thousand rows."""
SHARP_ANGLE_DEG = 30.0
"""A mesh edge whose faces turn by more than this diffracts (the solver's default)."""
MAX_POLYHEDRON_FACES = 4096
"""A mesh without a primitive and with more faces counts as one smooth reflector, not as planar mirrors."""


@dataclass(frozen=True)
class ResourceLimits:
    """Bounds on what one simulation may use; raise them for a bigger machine or a bigger job.

    Attributes
    ----------
    max_memory_gb : float
        Estimated peak memory (GiB): recording, synthesis, path table, meshes.
    max_triangles : int
        Triangles over all objects.
    max_rays : int
        Diffuse ray-bounces (rays x bounces) of the propagation solver.
    max_chains : float
        Upper bound on the specular reflector sequences the image-source method may examine,
        sum over k <= max_order of M (M - 1)^(k - 1) for M reflecting surfaces.
    max_objects : int
        Objects in a scene (each takes about a millisecond to build and check: 10,000 take 10 s).
    """

    max_memory_gb: float = 4.0
    max_triangles: int = 2_000_000
    max_rays: int = 2_000_000
    max_chains: float = 1.0e10
    max_objects: int = 10_000

    def __post_init__(self) -> None:
        for item in fields(self):
            value = getattr(self, item.name)
            if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)) \
                    or not math.isfinite(value) or value <= 0:
                raise InputError(f"limits.{item.name} = {value!r}: must be a finite number > 0")

    @classmethod
    def from_environment(cls, environ: Mapping[str, str] | None = None) -> "ResourceLimits":
        """The defaults, overridden by the environment variables of :data:`ENVIRONMENT`.

        Raises
        ------
        InputError
            A variable that is not a finite number > 0 (the message names it).
        """
        env = os.environ if environ is None else environ
        values: dict[str, float] = {}
        for name, variable in ENVIRONMENT.items():
            text = env.get(variable)
            if text is None or not text.strip():
                continue
            try:
                value = float(text)
            except ValueError:
                raise InputError(f"{variable} = {text[:40]!r}: expected a number") from None
            if not (math.isfinite(value) and value > 0):
                raise InputError(f"{variable} = {text[:40]!r}: must be a finite number > 0")
            values[name] = value
        if not values and cls is ResourceLimits:
            return DEFAULT_LIMITS  # the usual case, on every solve: no variable set
        return cls(**values)  # type: ignore[arg-type]

    def raised(self, **overrides: float | None) -> "ResourceLimits":
        """A copy with the given limits replaced (``None`` keeps the current one)."""
        return replace(self, **{k: v for k, v in overrides.items() if v is not None})


DEFAULT_LIMITS = ResourceLimits()
"""The limits when no environment variable or block sets any (immutable)."""

ENVIRONMENT: Mapping[str, str] = MappingProxyType({
    "max_memory_gb": "ACOUSTISIM_MAX_MEMORY_GB",
    "max_triangles": "ACOUSTISIM_MAX_TRIANGLES",
    "max_rays": "ACOUSTISIM_MAX_RAYS",
    "max_chains": "ACOUSTISIM_MAX_CHAINS",
    "max_objects": "ACOUSTISIM_MAX_OBJECTS",
})
"""The environment variable of each limit."""

FLAGS: Mapping[str, str] = MappingProxyType({
    "max_memory_gb": "--max-memory-gb",
    "max_triangles": "--max-triangles",
    "max_rays": "--max-rays",
    "max_chains": "--max-chains",
    "max_objects": "--max-objects",
})
"""The command-line option of each limit."""

_ACTIVE_LIMITS: ContextVar[ResourceLimits | None] = ContextVar("acoustisim_resource_limits", default=None)


def current_limits() -> ResourceLimits:
    """The limits in force: the innermost :func:`resource_limits` block's, else the environment's."""
    active = _ACTIVE_LIMITS.get()
    return active if active is not None else ResourceLimits.from_environment()


@contextlib.contextmanager
def resource_limits(limits: ResourceLimits) -> Iterator[ResourceLimits]:
    """Make ``limits`` the limits in force inside the ``with`` block (this thread or task only)."""
    if not isinstance(limits, ResourceLimits):
        raise InputError(f"resource_limits: expected ResourceLimits, got {type(limits).__name__}")
    token = _ACTIVE_LIMITS.set(limits)
    try:
        yield limits
    finally:
        _ACTIVE_LIMITS.reset(token)


@dataclass(frozen=True)
class ResourceEstimate:
    """What one simulation is expected to need.

    Attributes
    ----------
    n_pings, n_samples : int
        Pings, and samples per channel of one record.
    recording_bytes : int
        The recording: pings x 3 channels x samples (volts and codes).
    synthesis_bytes : int
        Everything else the synthesis holds at its peak (working spectra, per-ping temporaries).
    path_rows : int
        Path-table rows expected (direct, diffuse receptions, edge elements).
    path_table_bytes : int
    objects : int
        Objects in the scene.
    triangles : int
        Triangles over all objects.
    mesh_bytes : int
    rays : int
        Diffuse ray-bounces.
    reflectors : int
        Reflecting surfaces M (tank planes, cylinder sides and caps, polyhedron faces, spheres).
    max_order : int
        Most reflections per path the solver looks for.
    chains : float
        Upper bound on the specular reflector sequences (see :class:`ResourceLimits`).
    """

    n_pings: int = 0
    n_samples: int = 0
    recording_bytes: int = 0
    synthesis_bytes: int = 0
    path_rows: int = 0
    path_table_bytes: int = 0
    objects: int = 0
    triangles: int = 0
    mesh_bytes: int = 0
    rays: int = 0
    reflectors: int = 0
    max_order: int = 0
    chains: float = 0.0

    @property
    def memory_bytes(self) -> int:
        """The estimated peak memory (bytes)."""
        return self.recording_bytes + self.synthesis_bytes + self.path_table_bytes + self.mesh_bytes

    def as_dict(self) -> dict[str, Any]:
        """JSON-ready, with the total memory in GiB."""
        data = {item.name: getattr(self, item.name) for item in fields(self)}
        data["memory_gb"] = self.memory_bytes / GIB
        return data


def signal_estimate(sonar: "SonarHead", n_pings: int) -> ResourceEstimate:
    """Memory of synthesising and storing ``n_pings`` pings of ``sonar``'s record.

    Pure arithmetic on Python integers: never overflows, whatever the sample rate and record.
    """
    n_samples = int(round(float(sonar.record_length_s) * float(sonar.sample_rate_hz)))
    channel_samples = 3 * n_samples
    support = sonar.pulse.support_s
    template = int(math.ceil((support[1] - support[0]) * float(sonar.sample_rate_hz))) + 1
    recording = n_pings * channel_samples * RECORDING_BYTES_PER_SAMPLE
    synthesis = (FIXED_BYTES + channel_samples * WORKSPACE_BYTES_PER_SAMPLE + 16 * template
                 + n_pings * (channel_samples * (PING_BYTES_PER_SAMPLE - RECORDING_BYTES_PER_SAMPLE)
                              + PING_OVERHEAD_BYTES))
    return ResourceEstimate(n_pings=n_pings, n_samples=n_samples, recording_bytes=recording, synthesis_bytes=synthesis)


def _caps_off_the_tank(scene: "Scene", primitive: Any) -> int:
    """A cylinder's caps that do not lie on a tank boundary (a post's caps lie on the floor and
    the surface: no wave reflects off them)."""
    tank = scene.tank
    if tank is None:
        return 2
    axis = np.asarray(primitive.axis, dtype=float)
    centre = np.asarray(primitive.center_m, dtype=float)
    extent = np.array([tank.length_m, tank.width_m, tank.water_depth_m])
    caps = 0
    for sign in (-1.0, 1.0):
        cap = centre + sign * 0.5 * primitive.length_m * axis
        on_boundary = any(abs(axis[i]) > 1.0 - 1e-9 and min(abs(cap[i]), abs(cap[i] - extent[i])) <= 1e-9 * max(1.0, extent[i])
                          for i in range(3))
        caps += 0 if on_boundary else 1
    return caps


def reflector_count(scene: "Scene") -> int:
    """Reflecting surfaces M: tank planes, one per sphere, one per cylinder side and one per cap
    off the tank's boundaries, each planar patch of a polyhedral mesh, one per smooth mesh."""
    count = len(scene.boundaries)
    for obj in scene.objects:
        primitive = type(obj.primitive).__name__ if obj.primitive is not None else None
        if primitive == "SpherePrimitive":
            count += 1
        elif primitive == "CylinderPrimitive":
            count += 1 + _caps_off_the_tank(scene, obj.primitive)
        elif len(obj.mesh.faces) > MAX_POLYHEDRON_FACES:
            count += 1
        else:
            facets = obj.mesh.facets
            in_facets = sum(len(f) for f in facets)
            count += len(facets) + len(obj.mesh.faces) - in_facets
    return count


def chain_bound(reflectors: int, max_order: int) -> float:
    """sum over k = 1..max_order of M (M - 1)^(k - 1): sequences with no reflector twice in a row."""
    m = float(reflectors)
    return float(sum(m * max(m - 1.0, 0.0) ** (k - 1) for k in range(1, max_order + 1)))


def sharp_edge_length(scene: "Scene") -> float:
    """Total length (m) of the objects' mesh edges whose faces turn by more than 30 degrees."""
    total = 0.0
    limit = math.radians(SHARP_ANGLE_DEG)
    for obj in scene.objects:
        mesh = obj.mesh
        sharp = np.asarray(mesh.face_adjacency_angles, dtype=float) > limit
        if np.any(sharp):
            ends = np.asarray(mesh.vertices, dtype=float)[np.asarray(mesh.face_adjacency_edges)[sharp]]
            total += float(np.linalg.norm(ends[:, 1] - ends[:, 0], axis=1).sum())
    return total


@dataclass(frozen=True, eq=False)
class SceneMeasures:
    """What the geometry estimate reads from a scene, each measured on first use and kept: a
    prepared scene holds one for every pose it is solved at (``PreparedScene.resource_measures``).

    Attributes
    ----------
    scene : Scene
    """

    scene: "Scene"

    @property
    def objects(self) -> int:
        """Objects in the scene."""
        return len(self.scene.objects)

    @cached_property
    def triangles(self) -> int:
        """Triangles over all objects."""
        return int(sum(len(obj.mesh.faces) for obj in self.scene.objects))

    @cached_property
    def reflectors(self) -> int:
        """Reflecting surfaces M (:func:`reflector_count`)."""
        return reflector_count(self.scene)

    @cached_property
    def sharp_edge_m(self) -> float:
        """Total length of the objects' sharp edges (m, :func:`sharp_edge_length`)."""
        return sharp_edge_length(self.scene)


def geometry_estimate(scene: "Scene", config: "SolverConfig", measures: SceneMeasures | None = None
                      ) -> ResourceEstimate:
    """Triangles, rays, reflector sequences and the path table of solving ``scene`` with ``config``
    (``measures``: the scene's, if kept from an earlier estimate)."""
    measures = SceneMeasures(scene) if measures is None else measures
    triangles = measures.triangles
    mechanisms = tuple(config.mechanisms)
    rays = int(config.diffuse_rays) * int(config.diffuse_bounces) if "diffuse" in mechanisms else 0
    reflectors = measures.reflectors if "specular" in mechanisms else 0
    chains = chain_bound(reflectors, int(config.max_order)) if reflectors else 0.0
    edge_metres = measures.sharp_edge_m if "edge" in mechanisms else 0.0
    rows = 3 + 3 * rays + 3 * int(math.ceil(EDGE_ROWS_PER_METRE * edge_metres))
    return ResourceEstimate(path_rows=rows, path_table_bytes=rows * PATH_ROW_BYTES, objects=len(scene.objects),
                            triangles=triangles,
                            mesh_bytes=triangles * TRIANGLE_BYTES, rays=rays, reflectors=reflectors,
                            max_order=int(config.max_order), chains=chains)


def combined(signal: ResourceEstimate, geometry: ResourceEstimate) -> ResourceEstimate:
    """One estimate from the signal part and the geometry part."""
    return replace(geometry, n_pings=signal.n_pings, n_samples=signal.n_samples,
                   recording_bytes=signal.recording_bytes, synthesis_bytes=signal.synthesis_bytes)


__all__ = (
    "DEFAULT_LIMITS",
    "ENVIRONMENT",
    "FLAGS",
    "ResourceEstimate",
    "ResourceLimits",
    "SceneMeasures",
    "chain_bound",
    "combined",
    "current_limits",
    "geometry_estimate",
    "reflector_count",
    "resource_limits",
    "sharp_edge_length",
    "signal_estimate",
)
