"""A scene file's own materials: the ``[[materials]]`` array of tables.

Each table defines one material that objects, walls, floor and surface may name
(``conventions.md``, "Materials defined in a scene file")::

    [[materials]]
    name = "pvc-lab"
    density_kg_m3 = 1380.0
    compressional_speed_m_s = 2380.0
    shear_speed_m_s = 1060.0           # 0 for a fluid
    compressional_loss_factor = 0.03   # k = (w / c)(1 + i eta / 2), time dependence exp(-i w t)
    shear_loss_factor = 0.05
    roughness_rms_m = 0.0
    diffuse_mu = 0.003
    reflection_model = "elastic"       # optional: "elastic" if shear_speed_m_s > 0, else "fluid"

``name``, ``density_kg_m3`` and ``compressional_speed_m_s`` are required; the numbers default
to 0. A scene material may not reuse a built-in name (a file that says "steel" means the
library's steel) nor another scene material's name. ``reflection_model`` chooses the plane-wave
coefficient of :class:`acoustisim.materials.Material` (``elastic``, ``fluid``, ``rigid``,
``pressure-release``, ``fixed``); without it a solid (c_S > 0) reflects as the built-in solids
do (``elastic``) and a fluid as a fluid. ``fixed_reflection`` (in [-1, 1]) is the coefficient
of the ``fixed`` model, required by it and refused by the others. The elastic parameters also
serve the exact scattering of :mod:`acoustisim.scattering`.

Every mistake raises :class:`scenes.errors.SceneFileError` with one line naming the file, the
key (``materials[1].shear_speed_m_s``) and the value. :func:`materials_to_toml` writes tables
that :func:`read_materials_table` reads back to equal materials.
"""

from __future__ import annotations

import math
from types import MappingProxyType
from typing import Any, Sequence

from acoustisim.errors import InputError
from acoustisim.materials import REFLECTION_MODELS, Material, material_library
from scenes.errors import SceneFileError

__all__ = ("MATERIAL_KEYS", "default_reflection_model", "materials_to_toml", "read_materials_table")

MATERIAL_KEYS = MappingProxyType({
    # scene-file key -> (Material field, required)
    "name": ("name", True),
    "density_kg_m3": ("density_kg_m3", True),
    "compressional_speed_m_s": ("sound_speed_m_s", True),
    "shear_speed_m_s": ("shear_speed_m_s", False),
    "compressional_loss_factor": ("compressional_loss_factor", False),
    "shear_loss_factor": ("shear_loss_factor", False),
    "roughness_rms_m": ("roughness_rms_m", False),
    "diffuse_mu": ("diffuse_mu", False),
    "reflection_model": ("model", False),
    "fixed_reflection": ("fixed_reflection", False),
})
"""The keys of one ``[[materials]]`` table, with the :class:`Material` field each fills."""


def default_reflection_model(shear_speed_m_s: float) -> str:
    """The reflection model of a ``[[materials]]`` table without ``reflection_model``:
    ``elastic`` for a solid (c_S > 0), ``fluid`` for a fluid."""
    return "elastic" if shear_speed_m_s > 0.0 else "fluid"


def _show(value: Any) -> str:
    return str(value) if isinstance(value, float) and not math.isfinite(value) else repr(value)


def _error(source: str, key: str, value: Any, problem: str) -> SceneFileError:
    return SceneFileError(f"{source}: {key} = {_show(value)}: {problem}")


def _read_one(source: str, index: int, table: Any, taken: set[str]) -> Material:
    prefix = f"materials[{index}]"
    if not isinstance(table, dict):
        raise _error(source, prefix, table, "expected a table")
    for key, value in table.items():
        if key not in MATERIAL_KEYS:
            raise _error(source, f"{prefix}.{key}", value, f"unknown key (known: {', '.join(MATERIAL_KEYS)})")
    for key, (_, required) in MATERIAL_KEYS.items():
        if required and key not in table:
            raise SceneFileError(f"{source}: {prefix}.{key}: missing (required)")
    name = table["name"]
    if not isinstance(name, str) or not name.strip():
        raise _error(source, f"{prefix}.name", name, "expected a non-empty string")
    if name in material_library():
        raise _error(source, f"{prefix}.name", name, "is a built-in material name; choose another name")
    if name in taken:
        raise _error(source, f"{prefix}.name", name, "defined twice in [[materials]]")
    values: dict[str, Any] = {"name": name}
    for key, (field, _) in MATERIAL_KEYS.items():
        if key in ("name", "reflection_model") or key not in table:
            continue
        value = table[key]
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise _error(source, f"{prefix}.{key}", value, "expected a number")
        if not math.isfinite(value):
            raise _error(source, f"{prefix}.{key}", value, "must be finite")
        values[field] = float(value)
    model = table.get("reflection_model", default_reflection_model(values.get("shear_speed_m_s", 0.0)))
    if model not in REFLECTION_MODELS:
        raise _error(source, f"{prefix}.reflection_model", model, f"expected one of {', '.join(REFLECTION_MODELS)}")
    if model == "fixed" and "fixed_reflection" not in table:
        raise SceneFileError(f"{source}: {prefix}.fixed_reflection: missing (required by reflection_model = 'fixed')")
    if model != "fixed" and "fixed_reflection" in table:
        raise _error(source, f"{prefix}.fixed_reflection", table["fixed_reflection"],
                     f"only the 'fixed' reflection model takes it (reflection_model = {model!r})")
    try:
        return Material(model=model, **values)
    except InputError as exc:
        # Material names the offending attribute; point at its scene-file key instead.
        message = str(exc).split(": ", 1)[-1]
        key = next((k for k, (field, _) in MATERIAL_KEYS.items() if k != "name" and field in message), None)
        if key is None:
            raise SceneFileError(f"{source}: {prefix}: {message}") from None
        raise _error(source, f"{prefix}.{key}", table.get(key), message) from None


def read_materials_table(data: Any, source: str) -> tuple[Material, ...]:
    """Check and build a scene file's ``[[materials]]``.

    Parameters
    ----------
    data : list of dict
        The parsed array of tables (``[]`` when the file has none).
    source : str
        The file, named in error messages.

    Returns
    -------
    tuple of Material
        In file order, each with its ``reflection_model`` (by default :func:`default_reflection_model`).

    Raises
    ------
    SceneFileError
        Not an array of tables, an unknown or missing key, a bad value, a name that is built in
        or defined twice.
    """
    if not isinstance(data, list):
        raise _error(source, "materials", data, "expected an array of tables [[materials]]")
    taken: set[str] = set()
    materials = []
    for index, table in enumerate(data):
        material = _read_one(source, index, table, taken)
        taken.add(material.name)
        materials.append(material)
    return tuple(materials)


def materials_to_toml(materials: Sequence[Material], source: str) -> list[dict[str, Any]]:
    """The ``[[materials]]`` tables of scene materials (every key explicit, but
    ``fixed_reflection``, written for the ``fixed`` model only).

    Raises
    ------
    SceneFileError
        A material of another model with a nonzero ``fixed_reflection`` (a scene file cannot
        express it: the key belongs to the ``fixed`` model).
    """
    tables = []
    for material in materials:
        fixed = material.model == "fixed"
        if not fixed and material.fixed_reflection != 0.0:
            raise SceneFileError(
                f"{source}: material {material.name!r}: fixed_reflection = {material.fixed_reflection!r} with "
                f"model {material.model!r} cannot be written to a scene file (the key is the 'fixed' model's)"
            )
        tables.append({key: getattr(material, field) for key, (field, _) in MATERIAL_KEYS.items()
                       if fixed or key != "fixed_reflection"})
    return tables
