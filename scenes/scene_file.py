"""The scene file (TOML): load, validate, save.

The format is the one ``conventions.md`` shows: tables ``[medium]``, ``[tank]``, ``[sonar]``
and an array ``[[objects]]`` whose ``kind`` is ``post``, ``edge``, ``cylinder``, ``sphere``,
``plate`` or ``mesh``. Beyond that example:

- top level ``name`` (default: the file's stem) and ``free_field = true`` (no ``[tank]``: a
  free-field scene; without it ``[tank]`` is required);
- ``[medium]``: ``depth_m``, ``ph``, ``formula`` (``auto``, ``marczak``, ``mackenzie``,
  ``unesco``) and the optional ``sound_speed_m_s`` override;
- ``[tank]``: ``surface_material`` (default ``pressure-release``);
- ``[[materials]]``: the file's own materials (:mod:`scenes.materials_table`), which objects,
  walls, floor and surface may name besides the built-in ones;
- ``[sonar]``: ``pitch_deg``, ``roll_deg``, ``source_level_pa``, ``channel_positions_m``
  (three rows of three numbers, head frame); missing keys take the default sonar's values
  (:func:`scenes.builders.default_sonar`); a custom sampled pulse is not stored;
- objects: ``name`` (default ``<kind>-<n>``), ``material`` (default per kind), and for
  ``post``/``edge`` ``bottom_m`` and ``top_m`` (default the floor and the surface; required in
  free field); ``plate`` takes ``center_m``, ``normal``, ``width_m``, ``height_m``,
  ``thickness_m`` and optional ``up``; a ``cylinder`` may be a pipe: ``wall_thickness_m`` and
  ``fill`` (``"air"`` or ``"water"``) together; ``mesh`` takes ``path`` (relative to the scene file),
  ``position_m`` and optional ``yaw_deg``, ``pitch_deg``, ``roll_deg``, ``scale``.

Every mistake raises :class:`SceneFileError` with one line naming the file, the key and the
value. Saving writes every value explicitly, so that load -> save -> load gives an equal scene.
"""

from __future__ import annotations

import errno
import math
import os
import re
import tomllib
from dataclasses import dataclass
from pathlib import Path
from types import MappingProxyType
from typing import Any, Callable, Mapping

import tomli_w

from acoustisim.checks import shown
from acoustisim.errors import InputError
from acoustisim.materials import Material, get_material, material_library
from acoustisim.medium import Medium
from acoustisim.scattering.bodies import PIPE_FILLS
from acoustisim.scene import Scene, SceneObject, Tank
from acoustisim.sonar import SonarHead
from scenes import builders
from scenes.builtin import builtin_scene, builtin_scene_names
from acoustisim.preflight import check_resources
from acoustisim.ranges import INTERIOR_ANGLE_DEG, LENGTH_M
from acoustisim.resources import ResourceEstimate, current_limits
from scenes.errors import SceneFileError
from scenes.materials_table import materials_to_toml, read_materials_table
from scenes.file_access import lookup, path_text, read_regular_file, shown_path
from scenes.tessellation import circle_segments, icosphere_subdivisions
from scenes.validation import validate_scene

__all__ = ["load_scene", "read_scene_file", "save_scene", "scene_to_toml", "scene_from_toml"]


# --------------------------------------------------------------------------- value checks
MAX_SCENE_FILE_BYTES = 16 << 20
"""Largest scene file read (bytes): 16 MiB hold some 100,000 objects, ten times the default limit."""

MAX_TOML_DEPTH = 16
"""Deepest nesting of tables and arrays accepted (the format itself needs 4: objects, a table,
channel_positions_m, a row)."""

MAX_NAME_CHARS = 200
"""Longest scene or object name (a label in tables and messages)."""


def _show(value: Any) -> str:
    return shown(value)


@dataclass(frozen=True)
class _Field:
    """One key of a table: its check and whether it must be present."""

    check: Callable[["_Context", str, Any], Any]
    required: bool = False


@dataclass(frozen=True)
class _Context:
    """Where we are, for messages."""

    source: str
    materials: tuple[Material, ...] = ()  # the file's own [[materials]]

    def error(self, key: str, value: Any, problem: str) -> SceneFileError:
        return SceneFileError(f"{self.source}: {key} = {_show(value)}: {problem}")


def _is_number(value: Any) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def _number(ctx: _Context, key: str, value: Any) -> float:
    if not _is_number(value):
        raise ctx.error(key, value, "expected a number")
    try:
        x = float(value)
    except OverflowError:
        raise ctx.error(key, value, "too large for a floating-point number") from None
    if not math.isfinite(x):
        raise ctx.error(key, value, "must be finite")
    return x


def _positive(ctx: _Context, key: str, value: Any) -> float:
    x = _number(ctx, key, value)
    if x <= 0.0:
        raise ctx.error(key, value, "must be > 0")
    return x


def _non_negative(ctx: _Context, key: str, value: Any) -> float:
    x = _number(ctx, key, value)
    if x < 0.0:
        raise ctx.error(key, value, "must be >= 0")
    return x


def _integer(ctx: _Context, key: str, value: Any) -> int:
    if not isinstance(value, int) or isinstance(value, bool):
        raise ctx.error(key, value, "expected an integer")
    return int(value)


def _boolean(ctx: _Context, key: str, value: Any) -> bool:
    if not isinstance(value, bool):
        raise ctx.error(key, value, "expected true or false")
    return value


def _string(ctx: _Context, key: str, value: Any) -> str:
    if not isinstance(value, str) or not value.strip():
        raise ctx.error(key, value, "expected a non-empty string")
    return value


def _name(ctx: _Context, key: str, value: Any) -> str:
    name = _string(ctx, key, value)
    if len(name) > MAX_NAME_CHARS or not name.isprintable():
        raise ctx.error(key, value, f"a name is at most {MAX_NAME_CHARS} printable characters")
    return name


def _choice(*options: str) -> Callable[[_Context, str, Any], str]:
    def check(ctx: _Context, key: str, value: Any) -> str:
        if value not in options:
            raise ctx.error(key, value, f"expected one of {', '.join(map(repr, options))}")
        return value

    return check


def _material(ctx: _Context, key: str, value: Any) -> str:
    name = _string(ctx, key, value)
    known = {*material_library(), *(m.name for m in ctx.materials)}
    if name not in known:
        raise ctx.error(key, value, f"unknown material (known: {', '.join(sorted(known))})")
    return name


def _vector(n: int, *, nonzero: bool = False) -> Callable[[_Context, str, Any], tuple[float, ...]]:
    def check(ctx: _Context, key: str, value: Any) -> tuple[float, ...]:
        if not isinstance(value, list) or len(value) != n or not all(_is_number(v) for v in value):
            raise ctx.error(key, value, f"expected a list of {n} numbers")
        numbers = tuple(_number(ctx, key, v) if not isinstance(v, float) else v for v in value)
        if not all(math.isfinite(v) for v in numbers):
            raise ctx.error(key, value, "must be finite")
        if nonzero and all(v == 0 for v in numbers):
            raise ctx.error(key, value, "must be a non-zero vector")
        return tuple(float(v) for v in numbers)

    return check


def _rows3x3(ctx: _Context, key: str, value: Any) -> tuple[tuple[float, ...], ...]:
    if not isinstance(value, list) or len(value) != 3:
        raise ctx.error(key, value, "expected three rows [x, y, z] (left, centre, right)")
    return tuple(_vector(3)(ctx, f"{key}[{i}]", row) for i, row in enumerate(value))


def _angle_interior(ctx: _Context, key: str, value: Any) -> float:
    x = _number(ctx, key, value)
    if not INTERIOR_ANGLE_DEG.contains(x):
        raise ctx.error(key, value, INTERIOR_ANGLE_DEG.describe())
    return x


def _read_table(
    ctx: _Context, prefix: str, table: Any, fields: Mapping[str, _Field]
) -> dict[str, Any]:
    """Check a table's keys and values; returns the canonical values of the keys present."""
    if not isinstance(table, dict):
        raise ctx.error(prefix, table, "expected a table")
    for key in table:
        if key not in fields:
            raise ctx.error(f"{prefix}.{key}", table[key], f"unknown key (known: {', '.join(fields)})")
    values: dict[str, Any] = {}
    for key, spec in fields.items():
        if key in table:
            values[key] = spec.check(ctx, f"{prefix}.{key}", table[key])
        elif spec.required:
            raise SceneFileError(f"{ctx.source}: {prefix}.{key}: missing (required)")
    return values


# --------------------------------------------------------------------------- schema
_TOP_KEYS = ("name", "free_field", "medium", "tank", "sonar", "materials", "objects")

_MEDIUM = MappingProxyType({
    "water": _Field(_choice("fresh", "sea")),
    "temperature_c": _Field(_number),
    "salinity_ppt": _Field(_non_negative),
    "depth_m": _Field(_non_negative),
    "ph": _Field(_positive),
    "sound_speed_m_s": _Field(_positive),
    "formula": _Field(_choice("auto", "marczak", "mackenzie", "unesco")),
})

_TANK = MappingProxyType({
    "length_m": _Field(_positive, required=True),
    "width_m": _Field(_positive, required=True),
    "water_depth_m": _Field(_positive, required=True),
    "wall_material": _Field(_material),
    "floor_material": _Field(_material),
    "surface_material": _Field(_material),
})

_SONAR = MappingProxyType({
    "position_m": _Field(_vector(3)),
    "yaw_deg": _Field(_number),
    "pitch_deg": _Field(_number),
    "roll_deg": _Field(_number),
    "separation_m": _Field(_positive),
    "transducer_diameter_m": _Field(_positive),
    "centre_frequency_hz": _Field(_positive),
    "pulse_duration_s": _Field(_positive),
    "source_level_pa": _Field(_positive),
    "sample_rate_hz": _Field(_positive),
    "adc_bits": _Field(_integer),
    "record_length_s": _Field(_positive),
    "channel_positions_m": _Field(_rows3x3),
})

_COMMON = MappingProxyType({"kind": _Field(_string, required=True), "name": _Field(_name), "material": _Field(_material)})
_VERTICAL = MappingProxyType({"bottom_m": _Field(_number), "top_m": _Field(_number)})

_OBJECTS: Mapping[str, Mapping[str, _Field]] = MappingProxyType({
    "post": {**_COMMON, "center_m": _Field(_vector(2), True), "radius_m": _Field(_positive, True), **_VERTICAL},
    "edge": {
        **_COMMON,
        "edge_m": _Field(_vector(2), True),
        "interior_angle_deg": _Field(_angle_interior, True),
        "facing_deg": _Field(_number, True),
        "size_m": _Field(_positive, True),
        **_VERTICAL,
    },
    "cylinder": {
        **_COMMON,
        "center_m": _Field(_vector(3), True),
        "axis": _Field(_vector(3, nonzero=True), True),
        "radius_m": _Field(_positive, True),
        "length_m": _Field(_positive, True),
        "wall_thickness_m": _Field(_positive),  # a pipe (with fill): scenes.builders.cylinder
        "fill": _Field(_choice(*PIPE_FILLS)),
    },
    "sphere": {**_COMMON, "center_m": _Field(_vector(3), True), "radius_m": _Field(_positive, True)},
    "plate": {
        **_COMMON,
        "center_m": _Field(_vector(3), True),
        "normal": _Field(_vector(3, nonzero=True), True),
        "width_m": _Field(_positive, True),
        "height_m": _Field(_positive, True),
        "thickness_m": _Field(_positive, True),
        "up": _Field(_vector(3, nonzero=True)),
    },
    "mesh": {
        **_COMMON,
        "path": _Field(_string, True),
        "position_m": _Field(_vector(3), True),
        "yaw_deg": _Field(_number),
        "pitch_deg": _Field(_number),
        "roll_deg": _Field(_number),
        "scale": _Field(_positive),
    },
})

_DEFAULT_MATERIAL = MappingProxyType({"post": "pvc", "edge": "steel", "cylinder": "pvc", "sphere": "steel", "plate": "steel",
                     "mesh": "concrete"})


# --------------------------------------------------------------------------- reading
def _planned_triangles(table: Any) -> int:
    """Triangles an object table will make, from its kind and size alone (0 when unknown:
    the built mesh is counted again by the pre-flight)."""
    if not isinstance(table, dict):
        return 0
    kind, radius = table.get("kind"), table.get("radius_m")
    if kind in ("edge", "plate"):
        return 8 if kind == "edge" else 12
    if kind in ("post", "cylinder", "sphere") and _is_number(radius):
        try:
            r = float(radius)
        except OverflowError:
            return 0
        if not LENGTH_M.contains(r):
            return 0  # refused when the object is built
        return 20 * 4 ** icosphere_subdivisions(r) if kind == "sphere" else 4 * circle_segments(r)
    return 0


def _check_planned_size(ctx: _Context, objects_data: list[Any], sonar: SonarHead) -> None:
    """Refuse, before any mesh is built, more objects or triangles than the limits in force."""
    planned = ResourceEstimate(objects=len(objects_data),
                               triangles=sum(_planned_triangles(table) for table in objects_data))
    try:
        check_resources(planned, current_limits(), sonar, source=ctx.source)
    except InputError as exc:
        raise SceneFileError(str(exc)) from None


def _medium(ctx: _Context, table: Any) -> Medium:
    values = _read_table(ctx, "medium", table, _MEDIUM)
    try:
        return Medium(**values)
    except ValueError as exc:
        raise SceneFileError(f"{ctx.source}: {exc}") from None


def _tank(ctx: _Context, table: Any) -> Tank:
    values = _read_table(ctx, "tank", table, _TANK)
    try:
        return Tank(**values, materials=ctx.materials)
    except InputError as exc:
        raise SceneFileError(f"{ctx.source}: {exc}") from None


def _sonar(ctx: _Context, table: Any) -> SonarHead:
    values = _read_table(ctx, "sonar", table, _SONAR)
    defaults = builders.default_sonar()
    try:
        return SonarHead(**{**{k: getattr(defaults, k) for k in _SONAR if k != "channel_positions_m"}, **values})
    except ValueError as exc:
        raise SceneFileError(f"{ctx.source}: {exc}") from None


def _vertical(ctx: _Context, prefix: str, values: dict[str, Any], tank: Tank | None) -> tuple[float, float]:
    if tank is None:
        for key in ("bottom_m", "top_m"):
            if key not in values:
                raise SceneFileError(f"{ctx.source}: {prefix}.{key}: missing (required in a free-field scene)")
        bottom, top = values["bottom_m"], values["top_m"]
    else:
        bottom = values.get("bottom_m", 0.0)
        top = values.get("top_m", tank.water_depth_m)
    if top <= bottom:
        raise ctx.error(f"{prefix}.top_m", top, f"must be above bottom_m = {bottom!r}")
    return bottom, top


def _object(ctx: _Context, index: int, table: Any, tank: Tank | None, base_dir: Path) -> SceneObject:
    prefix = f"objects[{index}]"
    if not isinstance(table, dict):
        raise ctx.error(prefix, table, "expected a table")
    if "kind" not in table:
        raise SceneFileError(f"{ctx.source}: {prefix}.kind: missing (required)")
    kind = table["kind"]
    if not isinstance(kind, str) or kind not in _OBJECTS:
        raise ctx.error(f"{prefix}.kind", kind, f"unknown kind (known: {', '.join(_OBJECTS)})")
    v = _read_table(ctx, prefix, table, _OBJECTS[kind])
    name = v.get("name", f"{kind}-{index + 1}")
    material = get_material(v.get("material", _DEFAULT_MATERIAL[kind]), ctx.materials)
    try:
        if kind == "post":
            bottom, top = _vertical(ctx, prefix, v, tank)
            return builders.post(name, v["center_m"], v["radius_m"], top, material, bottom_m=bottom)
        if kind == "edge":
            bottom, top = _vertical(ctx, prefix, v, tank)
            return builders.edge_prism(
                name, v["edge_m"], v["interior_angle_deg"], v["facing_deg"], v["size_m"], top, material,
                bottom_m=bottom,
            )
        if kind == "cylinder":
            return builders.cylinder(name, v["center_m"], v["axis"], v["radius_m"], v["length_m"], material,
                                     wall_thickness_m=v.get("wall_thickness_m"), fill=v.get("fill"))
        if kind == "sphere":
            return builders.sphere(name, v["center_m"], v["radius_m"], material)
        if kind == "plate":
            return builders.plate(
                name, v["center_m"], v["normal"], v["width_m"], v["height_m"], v["thickness_m"], material,
                v.get("up", (0.0, 0.0, 1.0)),
            )
        path = Path(os.path.expanduser(v["path"])) if v["path"].startswith("~") else Path(v["path"])
        resolved = path if path.is_absolute() else base_dir / path
        label = f"{ctx.source}: {prefix}.path = {shown(v['path'])}"
        if len(str(resolved)) != len(v["path"]):
            label += f" ({shown_path(str(resolved))})"
        try:
            mesh = builders.load_mesh_file(resolved, name, label=label)
        except InputError as exc:
            raise SceneFileError(str(exc)) from None
        return builders.user_mesh(
            name, resolved, v["position_m"], v.get("yaw_deg", 0.0), v.get("pitch_deg", 0.0),
            v.get("roll_deg", 0.0), v.get("scale", 1.0), material, mesh=mesh,
        )
    except SceneFileError:
        raise
    except InputError as exc:
        message = str(exc)
        if message.startswith(f"{name}."):
            message = message[len(name):]  # "<name>.key = ..." -> ".key = ..."
            raise SceneFileError(f"{ctx.source}: {prefix}{message}") from None
        if message.startswith(f"{name}:"):
            message = message[len(name) + 1:]
        raise SceneFileError(f"{ctx.source}: {prefix} ({name!r}):{message}") from None


def scene_from_toml(
    data: Mapping[str, Any], source: str = "<scene>", base_dir: str | os.PathLike[str] = ".",
    default_name: str = "scene", validate: bool = True,
) -> Scene:
    """Build a scene from parsed TOML.

    Parameters
    ----------
    data : mapping
        The parsed file (``tomllib.loads``).
    source : str
        Named in error messages (the file path).
    base_dir : path-like
        Directory that relative mesh paths are relative to.
    default_name : str
        The scene's name when the file gives none.
    validate : bool
        Run :func:`scenes.validation.validate_scene` on the result.

    Raises
    ------
    SceneFileError
    """
    if not isinstance(data, Mapping):
        raise _Context(source).error("scene", data, "expected a table (the parsed scene file)")
    ctx = _Context(source, read_materials_table(data.get("materials", []), source))
    for key in data:
        if key not in _TOP_KEYS:
            raise ctx.error(key, data[key], f"unknown key (known: {', '.join(_TOP_KEYS)})")
    name = _name(ctx, "name", data["name"]) if "name" in data else default_name
    free_field = _boolean(ctx, "free_field", data["free_field"]) if "free_field" in data else False
    if free_field and "tank" in data:
        raise ctx.error("free_field", True, "a free-field scene cannot have a [tank] table")
    if not free_field and "tank" not in data:
        raise SceneFileError(f"{source}: tank: missing (required unless free_field = true)")
    medium = _medium(ctx, data.get("medium", {}))
    tank = None if free_field else _tank(ctx, data["tank"])
    sonar = _sonar(ctx, data.get("sonar", {}))
    objects_data = data.get("objects", [])
    if not isinstance(objects_data, list):
        raise ctx.error("objects", objects_data, "expected an array of tables [[objects]]")
    _check_planned_size(ctx, objects_data, sonar)
    objects = tuple(_object(ctx, i, table, tank, Path(base_dir)) for i, table in enumerate(objects_data))
    scene = Scene(name=name, medium=medium, sonar=sonar, tank=tank, objects=objects)
    if validate:
        validate_scene(scene, source)
    return scene


def read_scene_file(path: str | os.PathLike[str], validate: bool = True) -> Scene:
    """Load a scene file (TOML); relative mesh paths are relative to the file.

    Raises
    ------
    SceneFileError
        Missing, unreadable or invalid file; any bad key or value.
    """
    text_path = path_text(path, "scene file")
    source = shown_path(text_path)
    raw = read_regular_file(text_path, max_bytes=MAX_SCENE_FILE_BYTES, label=source)
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise SceneFileError(f"{source}: cannot read (not UTF-8 text: {exc.reason} at byte {exc.start})") from None
    data = parse_toml(text, source)
    file = Path(text_path)
    return scene_from_toml(data, source, file.resolve().parent, file.stem, validate)


def load_scene(path_or_name: str | os.PathLike[str], validate: bool = True) -> Scene:
    """Load a scene file, or build a built-in scene by name (``thesis-tank``, ``free-sphere``, ...).

    An existing file wins over a built-in name.

    Raises
    ------
    SceneFileError
        Neither a file nor a built-in name, or a bad file.
    """
    text = path_text(path_or_name, "scene")
    status = lookup(text)
    if not isinstance(status, OSError):  # an existing file wins over a built-in name
        return read_scene_file(text, validate)
    if text in builtin_scene_names():
        scene = builtin_scene(text)
        if validate:
            validate_scene(scene, text)
        return scene
    if status.errno not in (errno.ENOENT, errno.ENOTDIR):
        raise SceneFileError(f"{shown_path(text)}: cannot open ({status.strerror or type(status).__name__})")
    raise SceneFileError(
        f"{shown_path(text)}: no such scene file or built-in scene (built-in: {', '.join(builtin_scene_names())})"
    )


def _depth(data: Any) -> int:
    """Deepest nesting of dicts and lists in ``data`` (iterative: no recursion limit)."""
    deepest = 0
    stack = [(data, 0)]
    while stack:
        node, level = stack.pop()
        if isinstance(node, dict):
            children = node.values()
        elif isinstance(node, list):
            children = node
        else:
            continue
        level += 1
        deepest = max(deepest, level)
        if deepest > MAX_TOML_DEPTH:
            return deepest
        stack.extend((child, level) for child in children)
    return deepest


def parse_toml(text: str, source: str) -> dict[str, Any]:
    """Parse scene-file text, refusing nesting deeper than :data:`MAX_TOML_DEPTH`.

    Raises
    ------
    SceneFileError
        Not TOML, nested too deeply, or an integer literal too long to convert.
    """
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise SceneFileError(f"{source}: not valid TOML: {exc}") from None
    except RecursionError:
        raise SceneFileError(f"{source}: not a scene file: tables or arrays nested too deeply"
                             f" (at most {MAX_TOML_DEPTH} levels)") from None
    except ValueError as exc:  # e.g. an integer literal of more than 4300 digits
        raise SceneFileError(f"{source}: not valid TOML: {' '.join(str(exc).split())[:200]}") from None
    if _depth(data) > MAX_TOML_DEPTH:
        raise SceneFileError(f"{source}: not a scene file: tables or arrays nested more than"
                             f" {MAX_TOML_DEPTH} levels deep")
    return data


# --------------------------------------------------------------------------- writing
def _plain(value: Any) -> Any:
    if isinstance(value, (tuple, list)):
        return [_plain(v) for v in value]
    return value


def _scene_materials(scene: Scene) -> tuple[Material, ...]:
    """The materials of ``scene`` that are not the library's (written as [[materials]]).

    Raises
    ------
    SceneFileError
        Two different materials under one name (a file names materials uniquely).
    """
    library = material_library()
    used = [*(scene.tank.materials if scene.tank is not None else ()), *(obj.material for obj in scene.objects)]
    own: dict[str, Material] = {}
    for material in used:
        if library.get(material.name) == material:
            continue
        if material.name in library or own.setdefault(material.name, material) != material:
            raise SceneFileError(
                f"{scene.name}: material {material.name!r}: two different materials share this name"
                " (a scene file stores materials by name)"
            )
    return tuple(own.values())


def scene_to_dict(scene: Scene, base_dir: str | os.PathLike[str] | None = None) -> dict[str, Any]:
    """The scene as a TOML-ready mapping (every value explicit).

    Parameters
    ----------
    scene : Scene
    base_dir : path-like, optional
        Write mesh paths relative to this directory (the target file's); absolute if None.

    Materials that are not the library's are written as ``[[materials]]`` tables.

    Raises
    ------
    SceneFileError
        Two different materials under one name (the file stores materials by name).
    """
    medium = scene.medium
    data: dict[str, Any] = {"name": scene.name}
    if scene.tank is None:
        data["free_field"] = True
    data["medium"] = {
        "water": medium.water,
        "temperature_c": float(medium.temperature_c),
        "salinity_ppt": float(medium.salinity_ppt),
        "depth_m": float(medium.depth_m),
        "ph": float(medium.ph),
        "formula": medium.formula,
    }
    if medium.sound_speed_m_s is not None:
        data["medium"]["sound_speed_m_s"] = float(medium.sound_speed_m_s)
    if scene.tank is not None:
        tank = scene.tank
        data["tank"] = {
            "length_m": float(tank.length_m),
            "width_m": float(tank.width_m),
            "water_depth_m": float(tank.water_depth_m),
            "wall_material": tank.wall_material,
            "floor_material": tank.floor_material,
            "surface_material": tank.surface_material,
        }
    sonar = scene.sonar
    data["sonar"] = {key: _plain(getattr(sonar, key)) for key in _SONAR if getattr(sonar, key) is not None}
    own = _scene_materials(scene)
    if own:
        data["materials"] = materials_to_toml(own, scene.name)
    objects = []
    for obj in scene.objects:
        table: dict[str, Any] = {"kind": obj.kind, "name": obj.name}
        for key, value in obj.parameters:
            if key == "path" and base_dir is not None:
                value = os.path.relpath(value, os.fspath(base_dir))
            table[key] = _plain(value)
        table["material"] = obj.material.name
        objects.append(table)
    if objects:
        data["objects"] = objects
    return data


_NUMBER = r"[-+]?(?:\d[\d_]*(?:\.\d+)?(?:[eE][-+]?\d+)?|inf|nan)"
_NUMERIC_ARRAY = re.compile(r"\[\n((?:[ \t]*" + _NUMBER + r",\n)+)[ \t]*\]")


def _compact_arrays(text: str) -> str:
    """Put tomli_w's one-number-per-line arrays on one line: ``[1.0, 1.5, 0.5]``."""
    return _NUMERIC_ARRAY.sub(
        lambda m: "[" + ", ".join(item.strip().rstrip(",") for item in m.group(1).splitlines()) + "]", text
    )


def scene_to_toml(scene: Scene, base_dir: str | os.PathLike[str] | None = None) -> str:
    """The scene as scene-file text (TOML); see :func:`scene_to_dict`."""
    data = scene_to_dict(scene, base_dir)
    text = tomli_w.dumps(data)
    compact = _compact_arrays(text)
    # Keep the compact form only if it parses back to the same values (it always should).
    return compact if tomllib.loads(compact) == tomllib.loads(text) else text


def save_scene(scene: Scene, path: str | os.PathLike[str]) -> None:
    """Write ``scene`` to a scene file; mesh paths are written relative to the file.

    The text is built completely before the file is opened, so a failure leaves no partial file.
    """
    target = Path(path)
    text = scene_to_toml(scene, target.resolve().parent)
    try:
        target.write_text(text, encoding="utf-8")
    except OSError as exc:
        raise SceneFileError(f"{path}: cannot write ({type(exc).__name__}: {exc})") from None
