"""Per-scene work done once and reused for every sonar pose: checks, Embree scene, mirrors.

:func:`prepare` validates the meshes (no zero-area faces, closed shells), builds the
:class:`~acoustisim.propagation.raycast.RayCaster`, the planar mirrors and the list of curved
reflectors. :func:`acoustisim.propagation.solve` accepts a :class:`PreparedScene` in place of a
scene, so that many poses of one scene pay for this once.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from functools import cached_property
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from acoustisim.errors import InputError
from acoustisim.geometry import CylinderPrimitive, SpherePrimitive
from acoustisim.materials import Material
from acoustisim.propagation.curved import CurvedSet
from acoustisim.propagation.image_source import PlanarMirrors, is_polyhedral
from acoustisim.propagation.raycast import RayCaster
from acoustisim.propagation.smooth_mesh import SmoothMesh
from acoustisim.resources import SceneMeasures

if TYPE_CHECKING:
    from acoustisim.propagation.edge_extraction import DiffractingEdges, SharpEdges
    from acoustisim.propagation.obstacles import SmoothObstacles
from acoustisim.scene import Scene, SceneObject

MIN_FACE_AREA_FRACTION = 1e-14
"""A face whose area is below this fraction of the mesh's squared extent is degenerate (zero
area up to float64 round-off of the vertex coordinates)."""


@dataclass(frozen=True, eq=False)
class CurvedReflector:
    """An object traced on its analytic primitive.

    Attributes
    ----------
    surface : int
        Index into ``scene.surface_names``.
    patch : int
        The ray caster's patch label of the whole object (excluded by legs touching it).
    primitive : SpherePrimitive or CylinderPrimitive
    material : Material
    seen_by : ndarray of bool, shape (n_mirrors,)
        Mirrors with some vertex of the object strictly in front of them (a necessary
        condition for a leg between the mirror and the object).
    """

    surface: int
    patch: int
    primitive: SpherePrimitive | CylinderPrimitive
    material: Material
    seen_by: NDArray[np.bool_] = field(repr=False)


@dataclass(frozen=True, eq=False)
class SmoothReflector:
    """A user mesh without a primitive, too finely faceted to be a set of mirrors, traced through
    its interpolated normals (:mod:`acoustisim.propagation.smooth_mesh`).

    Attributes
    ----------
    surface : int
        Index into ``scene.surface_names``.
    material : Material
    mesh : SmoothMesh
    patch : ndarray of int64, shape (t,)
        The ray caster's patch label of each of ``mesh``'s triangles.
    seen_by : ndarray of bool, shape (n_mirrors,)
        Mirrors with some vertex of the mesh strictly in front of them.
    """

    surface: int
    material: Material
    mesh: SmoothMesh
    patch: NDArray[np.int64] = field(repr=False)
    seen_by: NDArray[np.bool_] = field(repr=False)


@dataclass(frozen=True, eq=False)
class PreparedScene:
    """A scene with its validated geometry, Embree scene, mirrors and curved reflectors.

    ``curved_set`` stacks the reflectors' primitives (same order as ``curved``) for batched
    specular-point solves; ``curved_seen_by`` (r, m) stacks their ``seen_by`` rows;
    ``object_bounds`` (n_objects, 2, 3) the objects' axis-aligned bounds (m). ``memo`` keeps
    what the solve's steps derive from the scene alone (and from the water or the pulse, which
    are part of their keys), computed on the first pose and reused by every later one.
    """

    scene: Scene
    raycaster: RayCaster
    mirrors: PlanarMirrors
    curved: tuple[CurvedReflector, ...]
    curved_set: CurvedSet = field(repr=False)
    curved_seen_by: NDArray[np.bool_] = field(repr=False)
    smooth: tuple[SmoothReflector, ...] = ()
    object_bounds: NDArray[np.float64] = field(default_factory=lambda: np.zeros((0, 2, 3)), repr=False)
    memo: dict[Any, Any] = field(default_factory=dict, repr=False)

    @cached_property
    def resource_measures(self) -> SceneMeasures:
        """The scene's :class:`~acoustisim.resources.SceneMeasures` (objects, triangles, reflecting
        surfaces, sharp-edge length, each measured on first use): the pre-flight of every pose
        reads them (:func:`acoustisim.preflight.preflight`)."""
        return SceneMeasures(self.scene)

    @cached_property
    def sharp_edges(self) -> "SharpEdges":
        """The scene's sharp edges (for edge diffraction), extracted once per prepared scene."""
        from acoustisim.propagation.edge_extraction import sharp_edges

        return sharp_edges(self.raycaster, self.scene)

    @cached_property
    def diffracting_edges(self) -> "DiffractingEdges":
        """The per-scene part of edge diffraction (the edges that diffract, their lengths,
        wedge indices, chain joints and visibility-probe offsets), built once per prepared
        scene on first use and reused by every pose and both engines."""
        from acoustisim.propagation.edge_extraction import DiffractingEdges

        return DiffractingEdges.build(self.sharp_edges, self.scene)

    @cached_property
    def smooth_obstacles(self) -> "SmoothObstacles":
        """The smooth convex obstacles (spheres, cylinders) that cast diffracted shadows, and
        the ray caster without them, built once per prepared scene on first use."""
        from acoustisim.propagation.obstacles import SmoothObstacles

        return SmoothObstacles.build(self.scene.boundaries, [(r.surface, r.primitive) for r in self.curved],
                                     self.raycaster)

    def without_smooth_obstacles(self) -> "PreparedScene":
        """This scene with the ray caster of :attr:`smooth_obstacles` (the scene without the
        obstacles' triangles): where the specular mechanism tests its legs when the obstacles
        cast diffracted shadows rather than hard ones."""
        obstacles = self.smooth_obstacles
        return self if obstacles.count == 0 else replace(self, raycaster=obstacles.raycaster)


def check_mesh(obj: SceneObject) -> None:
    """Raise :class:`InputError` if an object's mesh is degenerate or open.

    Degenerate: no faces, non-finite vertices, zero-area faces. Open: not watertight (an open
    shell has no inside, so occlusion and scattering from it are ill-defined).
    """
    mesh = obj.mesh
    if len(mesh.faces) == 0:
        raise InputError(f"object {obj.name!r}: mesh has no faces")
    vertices = np.asarray(mesh.vertices, dtype=float)
    if not np.all(np.isfinite(vertices)):
        raise InputError(f"object {obj.name!r}: mesh has non-finite vertex coordinates")
    extent = float(np.max(np.ptp(vertices, axis=0)))
    areas = np.asarray(mesh.area_faces, dtype=float)
    tiny = areas <= MIN_FACE_AREA_FRACTION * extent * extent
    if np.any(tiny):
        raise InputError(
            f"object {obj.name!r}: mesh has {int(tiny.sum())} zero-area face(s), first is face {int(np.argmax(tiny))}"
        )
    if not mesh.is_watertight:
        raise InputError(f"object {obj.name!r}: mesh is not a closed shell (open edges); close it or give it thickness")


def _seen_by(mirrors: PlanarMirrors, vertices: NDArray[np.float64]) -> NDArray[np.bool_]:
    """Mirrors (m,) with some of ``vertices`` (v, 3) strictly (1e-9 m) in front of them."""
    if mirrors.count == 0:
        return np.zeros(0, dtype=bool)
    height = vertices @ mirrors.normal.T - np.einsum("ik,ik->i", mirrors.point, mirrors.normal)
    return np.any(height > 1e-9, axis=0)


def prepare(scene: Scene) -> PreparedScene:
    """Validate ``scene``'s meshes and build everything the solver reuses across poses.

    Raises
    ------
    InputError
        Degenerate or open meshes, or an empty scene.
    """
    if isinstance(scene, PreparedScene):
        return scene
    for obj in scene.objects:
        check_mesh(obj)
    raycaster = RayCaster.from_scene(scene)
    mirrors = PlanarMirrors.from_scene(scene, raycaster)
    n_boundaries = len(scene.boundaries)
    curved = []
    for j, obj in enumerate(scene.objects):
        if isinstance(obj.primitive, (SpherePrimitive, CylinderPrimitive)):
            s = n_boundaries + j
            faces = np.flatnonzero(raycaster.surface_index == s)
            seen_by = _seen_by(mirrors, raycaster.vertices[np.unique(raycaster.faces[faces])])
            curved.append(
                CurvedReflector(s, int(raycaster.patch_index[faces[0]]), obj.primitive, obj.material, seen_by))
    seen_by = np.array([r.seen_by for r in curved], dtype=bool).reshape(len(curved), mirrors.count)
    curved_set = CurvedSet.from_primitives([r.primitive for r in curved])
    smooth = []
    for j, obj in enumerate(scene.objects):
        s = n_boundaries + j
        if obj.primitive is None and not is_polyhedral(obj, raycaster, s):
            offset = int(np.flatnonzero(raycaster.surface_index == s)[0])
            mesh = SmoothMesh.from_mesh(obj.mesh)
            smooth.append(SmoothReflector(s, obj.material, mesh, raycaster.patch_index[offset + mesh.source_face],
                                          _seen_by(mirrors, np.asarray(obj.mesh.vertices, dtype=float))))
    bounds = np.array([obj.bounds_m for obj in scene.objects], dtype=float).reshape(-1, 2, 3)
    return PreparedScene(scene, raycaster, mirrors, tuple(curved), curved_set, seen_by, tuple(smooth), bounds)


__all__ = ["CurvedReflector", "PreparedScene", "SmoothReflector", "check_mesh", "prepare"]
