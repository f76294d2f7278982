"""How finely curved objects are tessellated.

The facets of a curved object are never used as mirrors (the analytic primitive serves
specular points), but they do serve occlusion and diffuse scattering, so their deviation from
the true surface should stay well below a wavelength. The criterion is the sagitta (the gap
between a chord and its arc): s = a (1 - cos(pi / n)) for a circle of radius a cut into n
segments. With lambda = 3 mm (500 kHz in water) and s <= lambda / 8 = 0.375 mm, a 25 mm post
needs 19 segments and a 0.3 m pipe 63.
"""

from __future__ import annotations

import math

SAGITTA_TOLERANCE_M: float = 3.0e-3 / 8.0
"""Largest chord-to-arc gap (m): lambda / 8 at 500 kHz with lambda = 3 mm."""

MIN_SEGMENTS: int = 24
"""Fewest segments around any circle (keeps small posts round to the eye and to diffuse rays)."""

MAX_SEGMENTS: int = 512
"""Most segments around a circle: a 1 m radius already meets the sagitta criterion with 163."""

MAX_ICOSPHERE_SUBDIVISIONS: int = 6
"""Most icosphere subdivisions (81920 triangles); a 0.5 m sphere meets the criterion with 5."""


def circle_segments(radius_m: float, sagitta_m: float = SAGITTA_TOLERANCE_M) -> int:
    """Segments around a circle of ``radius_m`` so that no chord is farther than ``sagitta_m`` from the arc.

    Parameters
    ----------
    radius_m : float
        Circle radius a (m), > 0.
    sagitta_m : float
        Largest allowed chord sagitta (m), > 0.

    Returns
    -------
    int
        n in [MIN_SEGMENTS, MAX_SEGMENTS] with a (1 - cos(pi / n)) <= sagitta_m where the cap allows.
    """
    if sagitta_m >= radius_m:
        return MIN_SEGMENTS
    half_angle = math.acos(1.0 - sagitta_m / radius_m)
    if half_angle <= math.pi / MAX_SEGMENTS:  # (also 0 when the ratio rounds away) the cap applies
        return MAX_SEGMENTS
    n = math.ceil(math.pi / half_angle)
    return int(min(max(n, MIN_SEGMENTS), MAX_SEGMENTS))


def icosphere_subdivisions(radius_m: float, sagitta_m: float = SAGITTA_TOLERANCE_M) -> int:
    """Icosphere subdivision level for a sphere of ``radius_m`` under the sagitta criterion.

    An icosahedron's edge subtends 1.107 rad at the centre; each subdivision halves it. The
    sagitta is bounded by a (1 - cos(theta)) with theta the edge's full central angle (the
    facet centre is farther from the sphere than an edge midpoint, at most by that amount).

    Returns
    -------
    int
        Subdivision level in [2, MAX_ICOSPHERE_SUBDIVISIONS].
    """
    edge_angle = 1.1071487177940904  # rad, central angle of an icosahedron edge
    for level in range(2, MAX_ICOSPHERE_SUBDIVISIONS + 1):
        if radius_m * (1.0 - math.cos(edge_angle / 2**level)) <= sagitta_m:
            return level
    return MAX_ICOSPHERE_SUBDIVISIONS
