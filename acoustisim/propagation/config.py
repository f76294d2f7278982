"""The solver's fidelity knobs, independent of the scene and of the sensor."""

from __future__ import annotations

import math
from dataclasses import dataclass

from acoustisim.errors import InputError
from acoustisim.propagation.paths import MAX_INTERACTIONS

MAX_CURVED_PER_PATH = 2
"""The most curved reflections a specular path may hold (``SolverConfig.max_curved_per_path``)."""

MECHANISMS: tuple[str, ...] = ("direct", "specular", "edge", "diffuse")
"""Every mechanism name :func:`acoustisim.propagation.solve` knows."""

MAX_EDGE_REFLECTIONS = 2
"""Most reflections combined with one edge diffraction (an edge path of order 3)."""

DEFAULT_EDGE_REFLECTION_FRESNEL_V = 3.0
"""Default reach of the integrated edge-and-reflection paths
(``SolverConfig.edge_reflection_fresnel_v``): beyond it Keller's apex row is within 0.3 dB of
the uniform field (the transition function 1 + j / (2 X), X = pi v^2 / 2 = 14) and measured
within 0.06 dB of the line integral (``tests/physics/test_edge_apex.py``)."""

BACKENDS: tuple[str, ...] = ("fast", "reference")
"""The engines (:mod:`acoustisim.propagation.engine`): "fast" (compiled kernels, the default) and
"reference" (one plain-numpy module per mechanism; the same rows, slower)."""

VISIBILITY_MODES: tuple[str, ...] = ("exact", "centre")
"""How the legs scattering point -> receiver are tested for occlusion: "exact" tests every
receiver's leg; ``"centre"`` tests only the leg to the receiver nearest the receivers' centroid
(the thesis sonar's centre transducer) and shares the answer with the other receivers (an
approximation: a point can be hidden from one receiver and not from another 65 mm away; the
side channels' diffuse energy changes by 0.003 % at the thesis tank's default pose, by up to
1.2 % with the sonar among the posts)."""


@dataclass(frozen=True)
class SolverConfig:
    """How hard the propagation solver works.

    Attributes
    ----------
    max_order : int
        Most reflections per specular path, 1 to ``paths.MAX_INTERACTIONS`` (4). Default 3.
    mechanisms : tuple of str
        Which of "direct", "specular", "edge", "diffuse" to run.
    diffuse_rays : int
        Monte Carlo rays of the diffuse reverberation tracer (>= 0; 0 turns it off).
    diffuse_bounces : int
        Diffuse scattering events per ray (>= 1).
    edge_segment_m : float
        Length of the elements of a discretised diffracting edge (m, > 0).
    edge_adaptive : bool
        True (default): edge elements are one delay step (1/16 period) long near each branch's
        onset and ends and grow away from them
        (:data:`acoustisim.propagation.reference.edges.COARSENING_LEVELS`); False: every
        element is one delay step (the fine reference discretisation).
    edge_reflections : int
        Most reflections combined with one edge diffraction (0 to
        :data:`MAX_EDGE_REFLECTIONS`): 0, first-order edge diffraction only; 1 (default), also
        the paths edge -> reflection and reflection -> edge (kind ``edge``, order 2; planar
        mirrors by the image method, curved surfaces at their specular point from each edge
        element: the field diffracted around a prism into the shadow it casts on a post or a
        wall, an edge heard via the floor or the surface); 2, also two planar reflections
        before, after or around the edge (order 3).
        :mod:`acoustisim.propagation.reference.edge_reflections`. Each such path is a line
        integral of about as many rows as a first-order edge's.
    edge_reflection_fresnel_v : float or None
        Reach of the integrated edge-and-reflection paths: an (edge, mirrors) pair whose edge
        lies within this Fresnel-Kirchhoff parameter |v| of a geometric boundary of its wedge
        (the straight path between the images, shadowed or lit, or its reflection in a face;
        v = 2 sqrt(detour / wavelength) at the centre frequency) is integrated as a line
        integral of elements; beyond, it is one row at its apex by Keller's geometrical theory
        of diffraction (within 0.06 dB of the integral at |v| >= 3;
        :mod:`acoustisim.propagation.reference.edge_apex`). Default
        :data:`DEFAULT_EDGE_REFLECTION_FRESNEL_V` = 3. None or inf (``inf`` in a TOML ``[solver]`` table)
        integrates every pair (on the thesis tank about 14 times the first-order edge rows; see
        :mod:`acoustisim.propagation.reference.edge_reflections`, Selection).
    shadows : bool
        True (default): a specular leg passing near or blocked by a smooth convex obstacle
        (sphere, cylinder) is weighted by the field diffracted around it (a Kirchhoff-Fresnel
        factor per frequency, :mod:`acoustisim.propagation.shadows`) instead of being kept
        whole or dropped; False: such legs are cut by the obstacle's mesh (a hard shadow).
    amplitude_floor_db : float or None
        Arrivals weaker than this (dB, <= 0) relative to the strongest non-direct arrival are
        dropped; None keeps every path.
    amplitude_floor_band_hz : tuple of 2 float or None
        (lowest, highest) frequency (Hz) over which an arrival's level is judged against the
        floor; None (default): the band where the sonar's pulse spectrum is within 20 dB of
        its peak. See :func:`acoustisim.propagation.reference.floor.band_levels`.
    seed : int
        Seed of the diffuse tracer's random draws (>= 0).
    threads : int or None
        Worker threads of the diffuse tracer (>= 1); None (default): every available core.
        The paths are the same for any value.
    diffuse_visibility : str
        "exact" (default): every scattering point's leg to each receiver is tested for
        occlusion; "centre": only the leg to the centre receiver is tested and its answer
        reused for the side receivers (faster, approximate; see :data:`VISIBILITY_MODES`).
    backend : str
        "fast" (default) or "reference": which engine computes the rows
        (:mod:`acoustisim.propagation.engine`). Both give the same rows; the reference engine
        is the readable one, the fast one the one to run.
    max_curved_per_path : int
        Most reflections on curved surfaces per specular path, within ``max_order``: 2
        (default) adds the chains between two objects (post to post, post via a wall or the
        floor to another post or back to itself, sphere to post: two curved primitives with
        planar mirrors before, between and after them; :mod:`acoustisim.propagation.reference.curved_pairs`);
        1 keeps at most one curved surface (a sphere, a cylinder's side or a smooth mesh) per
        path. Planar reflections (walls, floor, surface, facets of polyhedra, cylinder caps)
        are not counted.
    elastic_echoes : bool
        True (default): echo rows off elastic posts, cylinders, spheres and pipes carry the
        exact elastic echo's transfer function (specular echo, internal and circumferential
        arrivals; :mod:`acoustisim.propagation.elastic_echoes`) and their ``amplitude`` its
        level at the centre frequency. False: every object echoes as today's geometric-optics
        row of its material's plane-wave reflection coefficient.
    """

    max_order: int = 3
    mechanisms: tuple[str, ...] = MECHANISMS
    diffuse_rays: int = 20_000
    diffuse_bounces: int = 1
    edge_segment_m: float = 5e-4
    edge_adaptive: bool = True
    edge_reflections: int = 1
    edge_reflection_fresnel_v: float | None = DEFAULT_EDGE_REFLECTION_FRESNEL_V
    shadows: bool = True
    amplitude_floor_db: float | None = -80.0
    amplitude_floor_band_hz: tuple[float, float] | None = None
    seed: int = 0
    threads: int | None = None
    diffuse_visibility: str = "exact"
    backend: str = "fast"
    max_curved_per_path: int = 2
    elastic_echoes: bool = True

    def __post_init__(self) -> None:
        def integer(name: str, minimum: int) -> None:
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < minimum:
                raise InputError(f"solver.{name} = {value!r}: must be an integer >= {minimum}")

        integer("max_order", 1)
        if self.max_order > MAX_INTERACTIONS:
            raise InputError(
                f"solver.max_order = {self.max_order!r}: at most {MAX_INTERACTIONS} (interaction points stored per path)"
            )
        integer("max_curved_per_path", 1)
        if self.max_curved_per_path > MAX_CURVED_PER_PATH:
            raise InputError(
                f"solver.max_curved_per_path = {self.max_curved_per_path!r}: at most {MAX_CURVED_PER_PATH} "
                "(chains through three curved surfaces are not modelled)"
            )
        integer("diffuse_rays", 0)
        integer("diffuse_bounces", 1)
        integer("seed", 0)
        if isinstance(self.mechanisms, str):
            raise InputError(f"solver.mechanisms = {self.mechanisms!r}: must be a sequence of names")
        mechanisms = tuple(self.mechanisms)
        unknown = [m for m in mechanisms if m not in MECHANISMS]
        if unknown:
            raise InputError(
                f"solver.mechanisms = {mechanisms!r}: unknown {unknown[0]!r} (known: {', '.join(MECHANISMS)})"
            )
        object.__setattr__(self, "mechanisms", mechanisms)
        segment = self.edge_segment_m
        if isinstance(segment, bool) or not isinstance(segment, (int, float)) or not (
            math.isfinite(segment) and segment > 0
        ):
            raise InputError(f"solver.edge_segment_m = {segment!r}: must be a finite number > 0")
        if not isinstance(self.edge_adaptive, bool):
            raise InputError(f"solver.edge_adaptive = {self.edge_adaptive!r}: must be true or false")
        integer("edge_reflections", 0)
        if self.edge_reflections > MAX_EDGE_REFLECTIONS:
            raise InputError(f"solver.edge_reflections = {self.edge_reflections!r}: at most {MAX_EDGE_REFLECTIONS}")
        reach = self.edge_reflection_fresnel_v
        if reach is not None and (isinstance(reach, bool) or not isinstance(reach, (int, float)) or not reach >= 0):
            raise InputError(f"solver.edge_reflection_fresnel_v = {reach!r}: must be a number >= 0 (inf integrates "
                             "every pair) or None")
        if not isinstance(self.shadows, bool):
            raise InputError(f"solver.shadows = {self.shadows!r}: must be true or false")
        floor = self.amplitude_floor_db
        if floor is not None and (
            isinstance(floor, bool) or not isinstance(floor, (int, float)) or not (math.isfinite(floor) and floor <= 0)
        ):
            raise InputError(f"solver.amplitude_floor_db = {floor!r}: must be a finite number <= 0 or None")
        band = self.amplitude_floor_band_hz
        if band is not None:
            try:
                low, high = (float(v) for v in band)
            except (TypeError, ValueError):
                low = high = math.nan
            if isinstance(band, str) or not (math.isfinite(low) and math.isfinite(high) and 0 < low <= high):
                raise InputError(
                    f"solver.amplitude_floor_band_hz = {band!r}: must be two finite frequencies 0 < low <= high (Hz) "
                    "or None (the pulse's -20 dB band)"
                )
            object.__setattr__(self, "amplitude_floor_band_hz", (low, high))
        threads = self.threads
        if threads is not None and (isinstance(threads, bool) or not isinstance(threads, int) or threads < 1):
            raise InputError(f"solver.threads = {threads!r}: must be an integer >= 1 or None (every available core)")
        if not isinstance(self.diffuse_visibility, str) or self.diffuse_visibility not in VISIBILITY_MODES:
            raise InputError(
                f"solver.diffuse_visibility = {self.diffuse_visibility!r}: must be one of {', '.join(VISIBILITY_MODES)}"
            )
        if not isinstance(self.backend, str) or self.backend not in BACKENDS:
            raise InputError(f"solver.backend = {self.backend!r}: must be one of {', '.join(BACKENDS)}")
        if not isinstance(self.elastic_echoes, bool):
            raise InputError(f"solver.elastic_echoes = {self.elastic_echoes!r}: must be true or false")


__all__ = ["BACKENDS", "MAX_CURVED_PER_PATH", "MAX_EDGE_REFLECTIONS", "MECHANISMS", "SolverConfig", "VISIBILITY_MODES"]
