"""Analytic surfaces kept beside the meshes, so curved objects are traced on their true surface.

Tessellated curved surfaces must never be used as mirrors: a sphere's or a cylinder's facets
give the wrong spreading. Objects that have one of these primitives are traced on it for
specular points and curvature; their mesh serves occlusion and diffuse scattering only.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from acoustisim import checks, ranges


def _vec3(owner: str, name: str, value: object) -> tuple[float, float, float]:
    return checks.vector(owner, name, value, 3, ranges.COORDINATE_M)  # type: ignore[return-value]


def _unit3(owner: str, name: str, value: object) -> tuple[float, float, float]:
    return checks.direction(owner, name, value, 3)  # type: ignore[return-value]


@dataclass(frozen=True)
class PlanePrimitive:
    """A bounded plane rectangle: ``point_m`` + s u + t v, |s| <= half_extent_m[0], |t| <= half_extent_m[1].

    ``normal`` points into the water (the reflecting side).
    """

    point_m: tuple[float, float, float]
    normal: tuple[float, float, float]
    u: tuple[float, float, float]
    half_extent_m: tuple[float, float]

    def __post_init__(self) -> None:
        object.__setattr__(self, "point_m", _vec3("plane", "point_m", self.point_m))
        object.__setattr__(self, "normal", _unit3("plane", "normal", self.normal))
        object.__setattr__(self, "u", _unit3("plane", "u", self.u))

    @property
    def v(self) -> tuple[float, float, float]:
        """Second in-plane unit vector, n x u."""
        w = np.cross(self.normal, self.u)
        return (float(w[0]), float(w[1]), float(w[2]))


@dataclass(frozen=True)
class SpherePrimitive:
    """A sphere of ``radius_m`` centred at ``center_m`` (tank frame, m). Curvature I / a."""

    center_m: tuple[float, float, float]
    radius_m: float

    def __post_init__(self) -> None:
        object.__setattr__(self, "center_m", _vec3("sphere", "center_m", self.center_m))
        object.__setattr__(self, "radius_m", checks.real("sphere", "radius_m", self.radius_m, ranges.LENGTH_M))

    def outward_normal(self, points_m: NDArray[np.float64]) -> NDArray[np.float64]:
        """Unit outward normals (n, 3) at points (n, 3) on or near the surface."""
        d = np.asarray(points_m, dtype=float) - np.asarray(self.center_m)
        return d / np.linalg.norm(d, axis=-1, keepdims=True)


@dataclass(frozen=True)
class CylinderPrimitive:
    """A finite circular cylinder with flat caps.

    Attributes
    ----------
    center_m : tuple of 3 float
        Centre of the axis segment (tank frame, m).
    axis : tuple of 3 float
        Unit axis direction.
    radius_m, length_m : float
        Radius and length (m). Curvature of the side: diag(1/a, 0) (across, along the axis).
    """

    center_m: tuple[float, float, float]
    axis: tuple[float, float, float]
    radius_m: float
    length_m: float

    def __post_init__(self) -> None:
        object.__setattr__(self, "center_m", _vec3("cylinder", "center_m", self.center_m))
        object.__setattr__(self, "axis", _unit3("cylinder", "axis", self.axis))
        for name in ("radius_m", "length_m"):
            object.__setattr__(self, name, checks.real("cylinder", name, getattr(self, name), ranges.LENGTH_M))

    def outward_normal(self, points_m: NDArray[np.float64]) -> NDArray[np.float64]:
        """Unit outward normals (n, 3) of the curved side at points (n, 3)."""
        d = np.asarray(points_m, dtype=float) - np.asarray(self.center_m)
        a = np.asarray(self.axis)
        radial = d - np.outer(d @ a, a)
        return radial / np.linalg.norm(radial, axis=-1, keepdims=True)


Primitive = PlanePrimitive | SpherePrimitive | CylinderPrimitive
