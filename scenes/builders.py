"""Builders of scene objects: posts, edges, cylinders, spheres, plates and user meshes.

Every builder returns an :class:`acoustisim.scene.SceneObject` whose mesh is watertight with
outward normals (positive volume, consistent winding), in the tank frame (m). Curved objects
keep their analytic primitive (:class:`CylinderPrimitive`, :class:`SpherePrimitive`); their
meshes are tessellated under the sagitta criterion of :mod:`scenes.tessellation`.

``parameters`` holds the object's scene-file table in canonical form (floats, tuples), so
that a scene saved and loaded again compares equal.

Bad arguments raise :class:`acoustisim.errors.InputError` naming the object and the value.
"""

from __future__ import annotations

import io
import math
import os
from pathlib import Path
from typing import Any, Sequence

import numpy as np
import trimesh
from numpy.typing import NDArray

from acoustisim import checks, ranges
from acoustisim.errors import InputError
from acoustisim.ranges import PhysicalRange
from acoustisim.geometry import CylinderPrimitive, SpherePrimitive
from acoustisim.materials import Material, get_material
from acoustisim.scattering.bodies import PIPE_FILLS
from acoustisim.scene import SceneObject
from acoustisim.sonar import SonarHead
from scenes.tessellation import circle_segments, icosphere_subdivisions


# --------------------------------------------------------------------------- argument checks
def _number(owner: str, key: str, value: Any, *, positive: bool = False,
            allowed: PhysicalRange | None = None) -> float:
    """A finite number (> 0 with ``positive``, inside ``allowed`` when given)."""
    if positive and allowed is None:
        allowed = ranges.LENGTH_M
    return checks.real(owner, key, value, allowed, positive=positive)


def _owner(name: Any) -> str:
    """The object's name, which prefixes its messages."""
    return checks.text("object", "name", name)


def _vector(owner: str, key: str, value: Any, n: int, *, unit: bool = False) -> tuple[float, ...]:
    """``n`` finite numbers: a position (inside the coordinate range) or, with ``unit``, a
    non-zero direction."""
    if unit:
        return checks.vector(owner, key, value, n, nonzero=True)
    return checks.vector(owner, key, value, n, ranges.COORDINATE_M)


def _material(owner: str, material: str | Material) -> Material:
    if isinstance(material, Material):
        return material
    name = checks.text(owner, "material", material)
    try:
        return get_material(name)
    except (KeyError, InputError) as exc:
        raise checks.value_error(owner, "material", name, str(exc.args[0]) if exc.args else "unknown material") from None


# --------------------------------------------------------------------------- mesh helpers
def _rotation_between(a: NDArray[np.float64], b: NDArray[np.float64]) -> NDArray[np.float64]:
    """A rotation matrix (3, 3) taking unit vector ``a`` to unit vector ``b``."""
    a = a / np.linalg.norm(a)
    b = b / np.linalg.norm(b)
    v = np.cross(a, b)
    c = float(np.dot(a, b))
    if c < -1.0 + 1e-12:  # opposite: half turn about any axis normal to a
        axis = np.cross(a, [1.0, 0.0, 0.0])
        if np.linalg.norm(axis) < 1e-6:
            axis = np.cross(a, [0.0, 1.0, 0.0])
        axis /= np.linalg.norm(axis)
        return 2.0 * np.outer(axis, axis) - np.eye(3)
    vx = np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])
    return np.eye(3) + vx + vx @ vx / (1.0 + c)


def _transform(rotation: NDArray[np.float64], translation: Sequence[float]) -> NDArray[np.float64]:
    matrix = np.eye(4)
    matrix[:3, :3] = rotation
    matrix[:3, 3] = translation
    return matrix


def euler_rotation(yaw_deg: float, pitch_deg: float, roll_deg: float) -> NDArray[np.float64]:
    """Rotation matrix (3, 3) of a placed object, R = Rz(yaw) Ry(-pitch) Rx(roll).

    The object's own +x axis is its "forward": yaw turns it counter-clockwise seen from above
    (like the sonar's yaw), positive pitch raises its nose (+x toward +z), roll turns about it.
    """
    y, p, r = (math.radians(v) for v in (yaw_deg, pitch_deg, roll_deg))
    rz = np.array([[math.cos(y), -math.sin(y), 0.0], [math.sin(y), math.cos(y), 0.0], [0.0, 0.0, 1.0]])
    ry = np.array([[math.cos(-p), 0.0, math.sin(-p)], [0.0, 1.0, 0.0], [-math.sin(-p), 0.0, math.cos(-p)]])
    rx = np.array([[1.0, 0.0, 0.0], [0.0, math.cos(r), -math.sin(r)], [0.0, math.sin(r), math.cos(r)]])
    return rz @ ry @ rx


def _outward(mesh: trimesh.Trimesh, owner: str) -> trimesh.Trimesh:
    """Check a closed mesh and wind it so its normals point outward (positive volume)."""
    if not mesh.is_watertight or not mesh.is_winding_consistent:
        raise InputError(f"{owner}: the mesh is not watertight")
    if mesh.volume < 0.0:
        mesh.invert()
    if not mesh.volume > 0.0:
        raise InputError(f"{owner}: the mesh encloses no volume")
    return mesh


def _vertical_extent(owner: str, bottom_m: float, top_m: float) -> tuple[float, float]:
    bottom = _number(owner, "bottom_m", bottom_m, allowed=ranges.COORDINATE_M)
    top = _number(owner, "top_m", top_m, allowed=ranges.COORDINATE_M)
    if top <= bottom:
        raise InputError(f"{owner}.top_m = {top!r}: must be above bottom_m = {bottom!r}")
    return bottom, top


# --------------------------------------------------------------------------- builders
def _pipe(owner: str, radius: float, material: Material, wall_thickness_m: float | None,
          fill: str | None) -> tuple[tuple[str, Any], ...]:
    """The checked pipe keys of a cylinder (empty for a solid one)."""
    if wall_thickness_m is None and fill is None:
        return ()
    if wall_thickness_m is None or fill is None:
        missing = "wall_thickness_m" if wall_thickness_m is None else "fill"
        raise InputError(f"{owner}.{missing}: missing (a pipe needs both wall_thickness_m and fill)")
    wall = _number(owner, "wall_thickness_m", wall_thickness_m, positive=True)
    if not wall < radius:
        raise InputError(f"{owner}.wall_thickness_m = {wall_thickness_m!r}: must be below radius_m = {radius!r}")
    if fill not in PIPE_FILLS:
        raise InputError(f"{owner}.fill = {fill!r}: expected one of {', '.join(map(repr, PIPE_FILLS))}")
    if material.model not in ("rigid", "pressure-release") and not material.is_solid:
        raise InputError(f"{owner}.material = {material.name!r}: a pipe's wall must be a solid (shear_speed_m_s > 0)")
    return (("wall_thickness_m", wall), ("fill", fill))


def cylinder(
    name: str,
    center_m: Sequence[float],
    axis: Sequence[float],
    radius_m: float,
    length_m: float,
    material: str | Material = "pvc",
    *,
    wall_thickness_m: float | None = None,
    fill: str | None = None,
) -> SceneObject:
    """A finite circular cylinder with flat caps: solid, or a pipe (a wall around a fill).

    Parameters
    ----------
    name : str
        Object name.
    center_m : sequence of 3 float
        Centre of the axis segment (tank frame, m).
    axis : sequence of 3 float
        Axis direction (any length, normalised).
    radius_m, length_m : float
        Radius and length (m), > 0.
    material : str or Material
        Material name in the library, or a Material; a pipe's is its wall's (a solid).
    wall_thickness_m : float, keyword-only, optional
        A pipe's wall thickness (m), 0 < h < radius_m; with ``fill``. Its elastic echo
        (:mod:`acoustisim.propagation.elastic_echoes`) is the shell's; the geometry (a closed
        cylinder, caps included) is the same.
    fill : {"air", "water"}, keyword-only, optional
        What fills the pipe (:func:`acoustisim.scattering.bodies.pipe_fill`).
    """
    owner = _owner(name)
    center = _vector(owner, "center_m", center_m, 3)
    direction = _vector(owner, "axis", axis, 3, unit=True)
    radius = _number(owner, "radius_m", radius_m, positive=True)
    length = _number(owner, "length_m", length_m, positive=True)
    mat = _material(owner, material)
    pipe = _pipe(owner, radius, mat, wall_thickness_m, fill)
    primitive = CylinderPrimitive(center, direction, radius, length)
    rotation = _rotation_between(np.array([0.0, 0.0, 1.0]), np.asarray(primitive.axis))
    mesh = trimesh.creation.cylinder(
        radius=radius, height=length, sections=circle_segments(radius), transform=_transform(rotation, center)
    )
    return SceneObject(
        name,
        "cylinder",
        mat,
        _outward(mesh, owner),
        primitive,
        (("center_m", center), ("axis", direction), ("radius_m", radius), ("length_m", length)) + pipe,
    )


def post(
    name: str,
    center_m: Sequence[float],
    radius_m: float,
    water_depth_m: float,
    material: str | Material = "pvc",
    *,
    bottom_m: float = 0.0,
) -> SceneObject:
    """A vertical post: a cylinder from the floor (z = ``bottom_m``, default 0) to the surface.

    Parameters
    ----------
    name : str
    center_m : sequence of 2 float
        (x, y) of the axis (tank frame, m).
    radius_m : float
        Radius (m), > 0.
    water_depth_m : float
        z of the top (m): the free surface in a tank; in free field, the top of the post.
    material : str or Material
    bottom_m : float, keyword-only
        z of the bottom (m): 0 (the floor) in a tank.
    """
    owner = _owner(name)
    center = _vector(owner, "center_m", center_m, 2)
    radius = _number(owner, "radius_m", radius_m, positive=True)
    bottom, top = _vertical_extent(owner, bottom_m, water_depth_m)
    obj = cylinder(name, (center[0], center[1], 0.5 * (bottom + top)), (0.0, 0.0, 1.0), radius, top - bottom, material)
    parameters = (("center_m", center), ("radius_m", radius), ("bottom_m", bottom), ("top_m", top))
    return SceneObject(name, "post", obj.material, obj.mesh, obj.primitive, parameters)


def edge_prism(
    name: str,
    edge_m: Sequence[float],
    interior_angle_deg: float,
    facing_deg: float,
    size_m: float,
    water_depth_m: float,
    material: str | Material = "steel",
    *,
    bottom_m: float = 0.0,
) -> SceneObject:
    """A vertical triangular prism whose sharp vertical edge is a point target in 2-D.

    Parameters
    ----------
    name : str
    edge_m : sequence of 2 float
        (x, y) of the sharp vertical edge (tank frame, m).
    interior_angle_deg : float
        Interior angle of the prism at that edge (degrees), in (0, 180).
    facing_deg : float
        Direction the edge points (degrees, tank frame, counter-clockwise from +x like yaw):
        the prism lies behind the edge, symmetric about the opposite direction.
    size_m : float
        Length of the two faces that meet at the edge (m), > 0.
    water_depth_m : float
        z of the top (m): the free surface in a tank.
    material : str or Material
    bottom_m : float, keyword-only
        z of the bottom (m): 0 (the floor) in a tank.
    """
    owner = _owner(name)
    edge = _vector(owner, "edge_m", edge_m, 2)
    angle = _number(owner, "interior_angle_deg", interior_angle_deg, allowed=ranges.INTERIOR_ANGLE_DEG)
    facing = _number(owner, "facing_deg", facing_deg, allowed=ranges.ANGLE_DEG)
    size = _number(owner, "size_m", size_m, positive=True)
    bottom, top = _vertical_extent(owner, bottom_m, water_depth_m)
    mat = _material(owner, material)
    back = math.radians(facing) + math.pi  # from the edge into the prism
    half = math.radians(angle) / 2.0
    corners = np.array(
        [
            edge,
            (edge[0] + size * math.cos(back + half), edge[1] + size * math.sin(back + half)),
            (edge[0] + size * math.cos(back - half), edge[1] + size * math.sin(back - half)),
        ]
    )
    vertices = np.vstack([np.column_stack([corners, np.full(3, bottom)]), np.column_stack([corners, np.full(3, top)])])
    faces = np.array([[0, 2, 1], [3, 4, 5], [0, 1, 4], [0, 4, 3], [1, 2, 5], [1, 5, 4], [2, 0, 3], [2, 3, 5]])
    mesh = trimesh.Trimesh(vertices, faces, process=True)
    parameters = (
        ("edge_m", edge),
        ("interior_angle_deg", angle),
        ("facing_deg", facing),
        ("size_m", size),
        ("bottom_m", bottom),
        ("top_m", top),
    )
    return SceneObject(name, "edge", mat, _outward(mesh, owner), None, parameters)


def sphere(
    name: str, center_m: Sequence[float], radius_m: float, material: str | Material = "steel"
) -> SceneObject:
    """A sphere (icosphere mesh under the sagitta criterion, exact primitive kept).

    Parameters
    ----------
    name : str
    center_m : sequence of 3 float
        Centre (tank frame, m).
    radius_m : float
        Radius (m), > 0.
    material : str or Material
    """
    owner = _owner(name)
    center = _vector(owner, "center_m", center_m, 3)
    radius = _number(owner, "radius_m", radius_m, positive=True)
    mat = _material(owner, material)
    mesh = trimesh.creation.icosphere(subdivisions=icosphere_subdivisions(radius), radius=radius)
    mesh.apply_translation(center)
    return SceneObject(
        name,
        "sphere",
        mat,
        _outward(mesh, owner),
        SpherePrimitive(center, radius),
        (("center_m", center), ("radius_m", radius)),
    )


def plate(
    name: str,
    center_m: Sequence[float],
    normal: Sequence[float],
    width_m: float,
    height_m: float,
    thickness_m: float,
    material: str | Material = "steel",
    up: Sequence[float] = (0.0, 0.0, 1.0),
) -> SceneObject:
    """A flat plate: a thin box.

    Parameters
    ----------
    name : str
    center_m : sequence of 3 float
        Centre of the box (tank frame, m).
    normal : sequence of 3 float
        Normal of the two large faces (any length).
    width_m, height_m, thickness_m : float
        Extent across ``up``, along ``up`` and along ``normal`` (m), > 0.
    material : str or Material
    up : sequence of 3 float
        The direction of the height, projected onto the plate's plane; must not be parallel
        to ``normal``.
    """
    owner = _owner(name)
    center = _vector(owner, "center_m", center_m, 3)
    n = np.asarray(checks.direction(owner, "normal", normal))
    up_vec = np.asarray(checks.direction(owner, "up", up))
    width = _number(owner, "width_m", width_m, positive=True)
    height = _number(owner, "height_m", height_m, positive=True)
    thickness = _number(owner, "thickness_m", thickness_m, positive=True)
    mat = _material(owner, material)
    v = up_vec - np.dot(up_vec, n) * n
    if np.linalg.norm(v) < 1e-6 * np.linalg.norm(up_vec):
        raise InputError(f"{owner}.up = {tuple(up)!r}: must not be parallel to normal = {tuple(normal)!r}")
    v /= np.linalg.norm(v)
    u = np.cross(v, n)
    rotation = np.column_stack([u, v, n])
    mesh = trimesh.creation.box(extents=(width, height, thickness), transform=_transform(rotation, center))
    parameters = (
        ("center_m", center),
        ("normal", _vector(owner, "normal", normal, 3, unit=True)),
        ("width_m", width),
        ("height_m", height),
        ("thickness_m", thickness),
        ("up", _vector(owner, "up", up, 3, unit=True)),
    )
    return SceneObject(name, "plate", mat, _outward(mesh, owner), None, parameters)


MESH_FILE_BYTES_PER_TRIANGLE = 300
"""Bytes a mesh file may hold per triangle the limits allow (ASCII STL takes about 250)."""

MIN_MESH_FILE_LIMIT_BYTES = 1 << 20
"""A mesh file may always hold 1 MiB, whatever the triangle limit."""


def load_mesh_file(path: str | os.PathLike[str], owner: str = "mesh", *, label: str | None = None) -> trimesh.Trimesh:
    """Read a mesh file (STL, OBJ, PLY, GLB, ... anything trimesh reads from one file), repaired when possible.

    Only the named regular file is read (:mod:`scenes.file_access`), at most
    ``MESH_FILE_BYTES_PER_TRIANGLE`` bytes per triangle the limits in force allow
    (:func:`acoustisim.resources.current_limits`); trimesh parses its bytes, so a format that
    refers to other files (an OBJ's material library, a glTF's buffers) gets none of them.
    Holes are filled and normals made consistent and outward when trimesh can; a mesh that
    stays open, or has non-finite vertices, or more triangles than the limit, is rejected.

    Parameters
    ----------
    path : str or path-like
    owner : str
        The object's name, which prefixes messages.
    label : str, optional
        The message prefix instead of ``"<owner>.path = '<path>'"``.

    Raises
    ------
    InputError
        Missing, unreadable, non-regular, oversized or empty file, or a bad mesh.
    """
    from acoustisim.resources import current_limits
    from scenes.errors import SceneFileError
    from scenes.file_access import path_text, read_regular_file

    text = path_text(path, f"{owner}.path")
    where = label if label is not None else f"{owner}.path = {checks.shown(text)}"
    limits = current_limits()
    max_bytes = max(MIN_MESH_FILE_LIMIT_BYTES, int(limits.max_triangles * MESH_FILE_BYTES_PER_TRIANGLE))
    try:
        data = read_regular_file(text, max_bytes=max_bytes, label=where)
    except SceneFileError as exc:
        raise InputError(str(exc)) from None
    suffix = Path(text).suffix.lower().lstrip(".")
    if suffix not in trimesh.available_formats():
        raise InputError(f"{where}: unknown mesh format {suffix!r} (the file name must end in one of"
                         f" .stl, .obj, .ply, .off, .glb, ...)")
    try:
        loaded = trimesh.load(io.BytesIO(data), file_type=suffix, force="mesh", process=False)
    except Exception as exc:  # noqa: BLE001 - any reader failure is a bad file
        problem = " ".join(str(exc).split())[:200]
        raise InputError(f"{where}: cannot read the mesh ({type(exc).__name__}: {problem})") from None
    if not isinstance(loaded, trimesh.Trimesh) or len(loaded.faces) == 0:
        raise InputError(f"{where}: the file holds no triangles")
    if len(loaded.faces) > limits.max_triangles:
        raise InputError(f"{where}: {len(loaded.faces):,} triangles, more than the limit of"
                         f" {limits.max_triangles:,.0f} (raise it with --max-triangles or ACOUSTISIM_MAX_TRIANGLES)")
    vertices = np.asarray(loaded.vertices, dtype=float)
    if not np.all(np.isfinite(vertices)):
        raise InputError(f"{where}: the mesh has non-finite (NaN or infinite) vertex coordinates")
    faces = np.asarray(loaded.faces)
    if faces.size and (faces.min() < 0 or faces.max() >= len(vertices)):
        raise InputError(f"{where}: the mesh's faces refer to vertices it does not have")
    mesh = trimesh.Trimesh(vertices, faces, process=True)
    if len(mesh.faces) == 0:
        raise InputError(f"{where}: the file holds no usable triangles")
    if not (mesh.is_watertight and mesh.is_winding_consistent):
        mesh.merge_vertices()
        mesh.update_faces(mesh.nondegenerate_faces())
        mesh.update_faces(mesh.unique_faces())
        mesh.remove_unreferenced_vertices()
        trimesh.repair.fill_holes(mesh)
        trimesh.repair.fix_normals(mesh)
    if not (mesh.is_watertight and mesh.is_winding_consistent):
        raise InputError(f"{where}: the mesh is not watertight and trimesh cannot repair it")
    if mesh.volume < 0.0:
        mesh.invert()
    return mesh


def user_mesh(
    name: str,
    path: str | os.PathLike[str],
    position_m: Sequence[float],
    yaw_deg: float = 0.0,
    pitch_deg: float = 0.0,
    roll_deg: float = 0.0,
    scale: float = 1.0,
    material: str | Material = "concrete",
    *,
    mesh: trimesh.Trimesh | None = None,
) -> SceneObject:
    """A mesh from a file, scaled, rotated (:func:`euler_rotation`) and moved.

    Parameters
    ----------
    name : str
    path : str or path-like
        Mesh file; stored in ``parameters`` as an absolute path.
    position_m : sequence of 3 float
        Where the mesh's own origin goes (tank frame, m).
    yaw_deg, pitch_deg, roll_deg : float
        Orientation (degrees), see :func:`euler_rotation`.
    scale : float
        Uniform scale applied first (the file's units to metres), > 0.
    material : str or Material
    mesh : trimesh.Trimesh, keyword-only, optional
        The file's mesh as :func:`load_mesh_file` returned it (read here when not given).
    """
    owner = _owner(name)
    position = _vector(owner, "position_m", position_m, 3)
    yaw = _number(owner, "yaw_deg", yaw_deg, allowed=ranges.ANGLE_DEG)
    pitch = _number(owner, "pitch_deg", pitch_deg, allowed=ranges.ANGLE_DEG)
    roll = _number(owner, "roll_deg", roll_deg, allowed=ranges.ANGLE_DEG)
    factor = _number(owner, "scale", scale, allowed=ranges.SCALE)
    mat = _material(owner, material)
    source = load_mesh_file(path, owner) if mesh is None else checks.instance(
        owner, "mesh", mesh, trimesh.Trimesh, "a trimesh.Trimesh")
    placed = source.copy()
    placed.apply_scale(factor)
    placed.apply_transform(_transform(euler_rotation(yaw, pitch, roll), position))
    lo, hi = np.asarray(placed.bounds, dtype=float)
    reach = float(np.max(np.abs(placed.vertices)))
    if reach > ranges.COORDINATE_M.high:
        raise checks.value_error(owner, "scale", factor, f"the placed mesh reaches {reach:.3g} m from the origin;"
                                 f" coordinates {ranges.COORDINATE_M.describe()}")
    if float(np.max(hi - lo)) < ranges.LENGTH_M.low:
        raise checks.value_error(owner, "scale", factor, f"the placed mesh is {float(np.max(hi - lo)):.3g} m across;"
                                 f" sizes {ranges.LENGTH_M.describe()}")
    parameters = (
        ("path", str(Path(path).resolve())),
        ("position_m", position),
        ("yaw_deg", yaw),
        ("pitch_deg", pitch),
        ("roll_deg", roll),
        ("scale", factor),
    )
    return SceneObject(name, "mesh", mat, _outward(placed, owner), None, parameters)


def default_sonar() -> SonarHead:
    """The thesis tank's sonar: d = 65 mm, 19 mm pistons, 500 kHz, T = 5 us, 20 MS/s, 12 bits.

    Pose: (1.0, 1.5, 0.5) m, yaw 0 (looking down the tank's length, +x), mid-depth.
    """
    return SonarHead(
        position_m=(1.0, 1.5, 0.5),
        yaw_deg=0.0,
        pitch_deg=0.0,
        roll_deg=0.0,
        separation_m=0.065,
        transducer_diameter_m=0.019,
        centre_frequency_hz=500e3,
        pulse_duration_s=5e-6,
        source_level_pa=1.0e5,
        sample_rate_hz=20e6,
        adc_bits=12,
        record_length_s=0.0125,
    )
