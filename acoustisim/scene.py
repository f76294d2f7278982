"""The scene: medium, tank, sonar and objects, as frozen descriptions.

Solvers (``acoustisim.propagation``) and results are separate from these descriptions.
Builders that make the objects' meshes live in the ``scenes`` package.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property
from typing import Any, Literal

import numpy as np
import trimesh

from acoustisim import checks, ranges
from acoustisim.errors import InputError
from acoustisim.geometry import CylinderPrimitive, PlanePrimitive, SpherePrimitive
from acoustisim.materials import Material, get_material
from acoustisim.medium import Medium
from acoustisim.sonar import SonarHead

BoundaryKind = Literal["wall", "floor", "surface"]


@dataclass(frozen=True)
class SceneObject:
    """One object in the water.

    Attributes
    ----------
    name : str
        Unique name; labels every path that touches it.
    kind : str
        "post", "edge", "cylinder", "sphere", "plate", "mesh", ...
    material : Material
    mesh : trimesh.Trimesh
        Watertight triangle mesh with outward normals (tank frame, m). Not compared.
    primitive : SpherePrimitive or CylinderPrimitive or None
        The exact surface of a curved object (None for polyhedra and user meshes).
    parameters : tuple of (str, value)
        The object's table as written in the scene file (for saving and display).
    """

    name: str
    kind: str
    material: Material
    mesh: trimesh.Trimesh = field(compare=False, repr=False)
    primitive: SpherePrimitive | CylinderPrimitive | None = None
    parameters: tuple[tuple[str, Any], ...] = ()

    def __post_init__(self) -> None:
        owner = checks.text("scene object", "name", self.name)
        checks.text(owner, "kind", self.kind)
        checks.instance(owner, "material", self.material, Material, "a Material (acoustisim.materials.get_material)")
        checks.instance(owner, "mesh", self.mesh, trimesh.Trimesh, "a trimesh.Trimesh")
        if self.primitive is not None:
            checks.instance(owner, "primitive", self.primitive, (SpherePrimitive, CylinderPrimitive),
                            "a SpherePrimitive, a CylinderPrimitive or None")
        checks.instance(owner, "parameters", self.parameters, tuple, "a tuple of (key, value) pairs")
        vertices = np.asarray(self.mesh.vertices)
        faces = np.asarray(self.mesh.faces)
        if faces.ndim != 2 or faces.shape[0] == 0:
            raise checks.value_error(owner, "mesh", self.mesh, "has no triangles")
        if vertices.dtype.kind != "f" or not np.all(np.isfinite(vertices)):
            raise checks.value_error(owner, "mesh", self.mesh, "has non-finite (NaN or infinite) vertex coordinates")
        extent = ranges.COORDINATE_M
        if vertices.size and (vertices.min() < extent.low or vertices.max() > extent.high):
            raise checks.value_error(owner, "mesh", self.mesh, f"reaches {np.abs(vertices).max():.3g} m from the origin:"
                                     f" every vertex coordinate {extent.describe()}")

    @property
    def bounds_m(self) -> np.ndarray:
        """Axis-aligned bounds (2, 3) of the mesh (m)."""
        return np.asarray(self.mesh.bounds, dtype=float)

    def parameter(self, key: str, default: Any = None) -> Any:
        """The value of one scene-file key."""
        return dict(self.parameters).get(key, default)


@dataclass(frozen=True)
class Boundary:
    """A planar boundary of the tank: a wall, the floor or the free surface.

    ``plane.normal`` points into the water.
    """

    name: str
    kind: BoundaryKind
    material: Material
    plane: PlanePrimitive

    @cached_property
    def mesh(self) -> trimesh.Trimesh:
        """The rectangle as two triangles, wound so the face normal points into the water."""
        p = np.asarray(self.plane.point_m)
        u = np.asarray(self.plane.u) * self.plane.half_extent_m[0]
        v = np.asarray(self.plane.v) * self.plane.half_extent_m[1]
        vertices = np.array([p - u - v, p + u - v, p + u + v, p - u + v])
        faces = np.array([[0, 1, 2], [0, 2, 3]])
        mesh = trimesh.Trimesh(vertices, faces, process=False)
        if np.dot(mesh.face_normals[0], self.plane.normal) < 0:
            mesh = trimesh.Trimesh(vertices, faces[:, ::-1], process=False)
        return mesh


@dataclass(frozen=True)
class Tank:
    """A rectangular tank, tank frame origin at a floor corner (m).

    The free surface is the plane z = ``water_depth_m`` (pressure release, R = -1). The
    ``*_material`` names are looked up among ``materials`` (a scene file's ``[[materials]]``)
    first, then in the built-in library.
    """

    length_m: float = 9.0
    width_m: float = 3.0
    water_depth_m: float = 1.0
    wall_material: str = "concrete"
    floor_material: str = "concrete"
    surface_material: str = "pressure-release"
    materials: tuple[Material, ...] = ()

    def __post_init__(self) -> None:
        for name in ("length_m", "width_m", "water_depth_m"):
            object.__setattr__(self, name, checks.real("tank", name, getattr(self, name), ranges.LENGTH_M))
        for name in ("wall_material", "floor_material", "surface_material"):
            material_name = checks.text("tank", name, getattr(self, name))
            try:
                get_material(material_name, self.materials)
            except (KeyError, InputError) as exc:
                problem = exc.args[0] if exc.args else "unknown material"
                raise checks.value_error("tank", name, material_name, str(problem)) from None

    def material(self, which: str) -> Material:
        """The material named by ``which`` ("wall_material", "floor_material" or
        "surface_material"): a scene-file material of ``materials`` or a built-in one."""
        return get_material(getattr(self, which), self.materials)

    @property
    def bounds_m(self) -> np.ndarray:
        """The water volume's bounds (2, 3) (m)."""
        return np.array([[0.0, 0.0, 0.0], [self.length_m, self.width_m, self.water_depth_m]])

    def contains(self, points_m: np.ndarray, margin_m: float = 0.0) -> np.ndarray:
        """Whether points (n, 3) lie in the water at least ``margin_m`` from every boundary."""
        p = np.atleast_2d(np.asarray(points_m, dtype=float))
        lo, hi = self.bounds_m
        return np.all((p >= lo + margin_m) & (p <= hi - margin_m), axis=1)

    @cached_property
    def boundaries(self) -> tuple[Boundary, ...]:
        """The six planar boundaries: four walls, the floor and the free surface."""
        length, width, depth = self.length_m, self.width_m, self.water_depth_m
        wall = self.material("wall_material")
        spec = (
            ("wall-x0", "wall", wall, (0.0, width / 2, depth / 2), (1, 0, 0), (0, 1, 0), (width / 2, depth / 2)),
            ("wall-x1", "wall", wall, (length, width / 2, depth / 2), (-1, 0, 0), (0, 1, 0), (width / 2, depth / 2)),
            ("wall-y0", "wall", wall, (length / 2, 0.0, depth / 2), (0, 1, 0), (1, 0, 0), (length / 2, depth / 2)),
            ("wall-y1", "wall", wall, (length / 2, width, depth / 2), (0, -1, 0), (1, 0, 0), (length / 2, depth / 2)),
            ("floor", "floor", self.material("floor_material"), (length / 2, width / 2, 0.0), (0, 0, 1), (1, 0, 0),
             (length / 2, width / 2)),
            ("surface", "surface", self.material("surface_material"), (length / 2, width / 2, depth), (0, 0, -1),
             (1, 0, 0), (length / 2, width / 2)),
        )
        return tuple(
            Boundary(name, kind, material, PlanePrimitive(point, normal, u, half))  # type: ignore[arg-type]
            for name, kind, material, point, normal, u, half in spec
        )


@dataclass(frozen=True)
class Scene:
    """Everything the simulator needs to know about the world.

    Attributes
    ----------
    name : str
        A label (the built-in name or the file's stem).
    medium : Medium
    sonar : SonarHead
        The default sonar and pose (solvers accept another).
    tank : Tank or None
        None for free-field scenes (no boundaries).
    objects : tuple of SceneObject
    """

    name: str = "scene"
    medium: Medium = field(default_factory=Medium)
    sonar: SonarHead = field(default_factory=SonarHead)
    tank: Tank | None = field(default_factory=Tank)
    objects: tuple[SceneObject, ...] = ()

    def __post_init__(self) -> None:
        owner = "scene"
        checks.text(owner, "name", self.name)
        checks.instance(owner, "medium", self.medium, Medium, "a Medium")
        checks.instance(owner, "sonar", self.sonar, SonarHead, "a SonarHead")
        if self.tank is not None:
            checks.instance(owner, "tank", self.tank, Tank, "a Tank or None (free field)")
        if not isinstance(self.objects, (tuple, list)):
            raise checks.type_error(owner, "objects", self.objects, "a tuple of SceneObject")
        for index, obj in enumerate(self.objects):
            checks.instance(owner, f"objects[{index}]", obj, SceneObject, "a SceneObject (see scenes.builders)")
        object.__setattr__(self, "objects", tuple(self.objects))

    @property
    def boundaries(self) -> tuple[Boundary, ...]:
        """The tank's planar boundaries (empty in free field)."""
        return () if self.tank is None else self.tank.boundaries

    def object(self, name: str) -> SceneObject:
        """Look an object up by name."""
        for obj in self.objects:
            if obj.name == name:
                return obj
        raise KeyError(f"no object named {name!r} in scene {self.name!r}")

    @property
    def surface_names(self) -> tuple[str, ...]:
        """Names of every reflecting thing: boundaries then objects (the index used in paths)."""
        return tuple(b.name for b in self.boundaries) + tuple(o.name for o in self.objects)

    @property
    def triangle_count(self) -> int:
        """Triangles over all objects and boundaries."""
        return sum(len(o.mesh.faces) for o in self.objects) + 2 * len(self.boundaries)


__all__ = ["Boundary", "BoundaryKind", "Scene", "SceneObject", "Tank"]
