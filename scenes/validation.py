"""Checks that a scene is physically possible: objects in the water, apart, the sonar clear.

Rules
-----
- Object names are unique and differ from the tank's boundary names.
- In a tank every object lies in the water: at least ``WALL_CLEARANCE_M`` from the four walls,
  and between the floor and the free surface (touching them is allowed: posts and edges span
  floor to surface by design, and an object may rest on the floor).
- No two objects intersect (their closed meshes neither cross nor contain one another).
- Each of the sonar's three transducer faces lies in the water at least one piston radius
  from every boundary, outside every object and at least one piston radius from its surface.
- The sample rate carries the pulse and the receiver's band-pass, and the record holds the
  pulse (:func:`acoustisim.preflight.check_sampling`).

Objects are tested for intersection only where their bounding boxes overlap (sort and sweep,
:func:`overlapping_pairs`), so thousands of scattered objects validate in well under a second.
"""

from __future__ import annotations

import numpy as np
import trimesh

from acoustisim import checks
from acoustisim.errors import InputError
from acoustisim.scene import Scene, SceneObject
from acoustisim.sonar import CHANNEL_NAMES
from scenes.errors import SceneFileError

WALL_CLEARANCE_M: float = 1.0e-3
"""Least gap (m) between an object and a tank wall: contact would make degenerate geometry."""

VERTICAL_TOLERANCE_M: float = 1.0e-9
"""Rounding allowance (m) for objects that touch the floor or the surface."""

_PLACEMENT_KEYS: tuple[str, ...] = ("center_m", "edge_m", "position_m")


def _placement(index: int, obj: SceneObject) -> str:
    """``objects[i].<key> = <value>`` for the key that places the object."""
    for key in _PLACEMENT_KEYS:
        value = obj.parameter(key)
        if value is not None:
            return f"objects[{index}].{key} = {list(value)!r}"
    return f"objects[{index}].name = {obj.name!r}"


def _fmt_point(point: np.ndarray) -> str:
    return "(" + ", ".join(f"{v:.4g}" for v in point) + ")"


def _boxes_overlap(a: np.ndarray, b: np.ndarray, pad: float = 0.0) -> bool:
    return bool(np.all(a[0] - pad <= b[1]) and np.all(b[0] - pad <= a[1]))


def _edges_cross(a: trimesh.Trimesh, b: trimesh.Trimesh) -> bool:
    """Whether any edge of ``a`` crosses the surface of ``b`` (ray cast along each edge)."""
    edges = a.vertices[a.edges_unique]  # (n, 2, 3)
    lo, hi = b.bounds
    keep = np.all(edges.min(axis=1) <= hi, axis=1) & np.all(edges.max(axis=1) >= lo, axis=1)
    edges = edges[keep]
    if len(edges) == 0:
        return False
    vectors = edges[:, 1] - edges[:, 0]
    lengths = np.linalg.norm(vectors, axis=1)
    usable = lengths > 0
    origins, vectors, lengths = edges[usable, 0], vectors[usable], lengths[usable]
    locations, index_ray, _ = b.ray.intersects_location(origins, vectors / lengths[:, None], multiple_hits=False)
    if len(index_ray) == 0:
        return False
    distances = np.linalg.norm(locations - origins[index_ray], axis=1)
    return bool(np.any(distances <= lengths[index_ray]))


def meshes_intersect(a: trimesh.Trimesh, b: trimesh.Trimesh) -> bool:
    """Whether two closed meshes intersect (surfaces cross, or one lies inside the other).

    Two closed triangle surfaces that cross have an edge of one piercing a face of the other;
    if none does, they intersect only when one contains the other, found by testing a vertex.
    """
    if not _boxes_overlap(a.bounds, b.bounds):
        return False
    if bool(b.contains(a.vertices[:1])[0]) or bool(a.contains(b.vertices[:1])[0]):
        return True
    return _edges_cross(a, b) or _edges_cross(b, a)


def _check_names(scene: Scene, source: str) -> None:
    seen: dict[str, int] = {}
    boundary_names = {b.name for b in scene.boundaries}
    for index, obj in enumerate(scene.objects):
        if obj.name in boundary_names:
            raise SceneFileError(
                f"{source}: objects[{index}].name = {obj.name!r}: reserved for a tank boundary"
            )
        if obj.name in seen:
            raise SceneFileError(
                f"{source}: objects[{index}].name = {obj.name!r}: already used by objects[{seen[obj.name]}]"
            )
        seen[obj.name] = index


def _check_in_water(scene: Scene, source: str) -> None:
    tank = scene.tank
    if tank is None:
        return
    lo_water, hi_water = tank.bounds_m
    for index, obj in enumerate(scene.objects):
        lo, hi = obj.bounds_m
        lateral_ok = np.all(lo[:2] >= lo_water[:2] + WALL_CLEARANCE_M) and np.all(
            hi[:2] <= hi_water[:2] - WALL_CLEARANCE_M
        )
        vertical_ok = lo[2] >= -VERTICAL_TOLERANCE_M and hi[2] <= hi_water[2] + VERTICAL_TOLERANCE_M
        if not (lateral_ok and vertical_ok):
            where = _placement(index, obj)
            if lateral_ok and obj.parameter("top_m") is not None:  # a post or edge too tall or too low
                key = "top_m" if hi[2] > hi_water[2] + VERTICAL_TOLERANCE_M else "bottom_m"
                where = f"objects[{index}].{key} = {obj.parameter(key)!r}"
            raise SceneFileError(
                f"{source}: {where}: object {obj.name!r} spans {_fmt_point(lo)}..{_fmt_point(hi)} m,"
                f" outside the water or into a wall (water {_fmt_point(lo_water)}..{_fmt_point(hi_water)} m,"
                f" {WALL_CLEARANCE_M * 1e3:g} mm from the walls)"
            )


def overlapping_pairs(bounds: np.ndarray) -> np.ndarray:
    """Index pairs (i, j), i < j, of boxes that overlap, in lexicographic order.

    Sort and sweep along x: each box meets only those whose x interval starts before its own
    ends, so n scattered objects cost O(n log n) rather than n^2 / 2 mesh tests.

    Parameters
    ----------
    bounds : ndarray, shape (n, 2, 3)
        Each box's low and high corners (m).

    Returns
    -------
    ndarray of int64, shape (k, 2)
    """
    n = len(bounds)
    if n < 2:
        return np.empty((0, 2), dtype=np.int64)
    order = np.argsort(bounds[:, 0, 0], kind="stable")
    lo_x = bounds[order, 0, 0]
    stop = np.searchsorted(lo_x, bounds[order, 1, 0], side="right")  # boxes starting before i's end
    pairs = []
    for rank in range(n):
        others = order[rank + 1:stop[rank]]
        if others.size == 0:
            continue
        i = order[rank]
        meet = np.all((bounds[others, 0] <= bounds[i, 1]) & (bounds[i, 0] <= bounds[others, 1]), axis=1)
        pairs.extend((min(i, j), max(i, j)) for j in others[meet])
    if not pairs:
        return np.empty((0, 2), dtype=np.int64)
    result = np.array(pairs, dtype=np.int64)
    return result[np.lexsort((result[:, 1], result[:, 0]))]


def _check_apart(scene: Scene, source: str) -> None:
    objects = scene.objects
    bounds = np.array([obj.bounds_m for obj in objects], dtype=float).reshape(-1, 2, 3)
    for i, j in overlapping_pairs(bounds):
        if meshes_intersect(objects[i].mesh, objects[j].mesh):
            raise SceneFileError(
                f"{source}: {_placement(j, objects[j])}: object {objects[j].name!r} intersects"
                f" objects[{i}] ({objects[i].name!r})"
            )


def _check_sampling(scene: Scene, source: str) -> None:
    """The sample rate must carry the pulse and the default receiver chain's band-pass, and the
    record hold the pulse, as ``acoustisim simulate`` needs (:func:`acoustisim.preflight.check_sampling`)."""
    from acoustisim.preflight import check_sampling

    try:
        check_sampling(scene.sonar, source=source)
    except InputError as exc:
        raise SceneFileError(str(exc)) from None


def _check_sonar(scene: Scene, source: str) -> None:
    sonar = scene.sonar
    margin = sonar.piston_radius_m
    points = sonar.receiver_positions  # (3, 3) rows left, centre, right
    where = f"sonar.position_m = {list(sonar.position_m)!r}"
    if scene.tank is not None:
        inside = scene.tank.contains(points, margin_m=margin)
        for name, point, ok in zip(CHANNEL_NAMES, points, inside):
            if not ok:
                raise SceneFileError(
                    f"{source}: {where}: the {name} transducer at {_fmt_point(point)} m is not in the water"
                    f" at least {margin * 1e3:g} mm from the walls, floor and surface"
                )
    for index, obj in enumerate(scene.objects):
        lo, hi = obj.bounds_m
        near = np.all(points >= lo - margin, axis=1) & np.all(points <= hi + margin, axis=1)
        if not np.any(near):
            continue
        contained = obj.mesh.contains(points[near])
        _, distance, _ = trimesh.proximity.closest_point(obj.mesh, points[near])
        for name, point, is_in, dist in zip(np.asarray(CHANNEL_NAMES)[near], points[near], contained, distance):
            if is_in or dist < margin:
                state = "inside" if is_in else f"{dist * 1e3:.3g} mm from"
                raise SceneFileError(
                    f"{source}: {where}: the {name} transducer at {_fmt_point(point)} m is {state}"
                    f" objects[{index}] ({obj.name!r}); it needs {margin * 1e3:g} mm clearance"
                )


def validate_scene(scene: Scene, source: str | None = None) -> None:
    """Check that ``scene`` is physically possible (see the module docstring).

    Parameters
    ----------
    scene : Scene
    source : str, optional
        What to name in messages (the file path); defaults to the scene's name.

    Raises
    ------
    SceneFileError
        The first problem found, on one line naming the source, the key and the value.
    """
    checks.instance("", "scene", scene, Scene, "a Scene")
    where = source if source is not None else scene.name
    _check_names(scene, where)
    _check_in_water(scene, where)
    _check_apart(scene, where)
    _check_sonar(scene, where)
    _check_sampling(scene, where)
