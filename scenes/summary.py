"""A JSON-ready summary of a scene (what ``acoustisim scene show`` prints)."""

from __future__ import annotations

from typing import Any

import numpy as np

from acoustisim.geometry import CylinderPrimitive, SpherePrimitive
from acoustisim.scene import Scene, SceneObject


def _floats(values: Any, digits: int = 9) -> Any:
    """Nested lists of Python floats rounded to ``digits`` (removes float noise from the output)."""
    arr = np.asarray(values, dtype=float)
    return np.round(arr, digits).tolist()


def _primitive(obj: SceneObject) -> dict[str, Any] | None:
    p = obj.primitive
    if isinstance(p, SpherePrimitive):
        return {"type": "sphere", "center_m": _floats(p.center_m), "radius_m": p.radius_m}
    if isinstance(p, CylinderPrimitive):
        return {
            "type": "cylinder",
            "center_m": _floats(p.center_m),
            "axis": _floats(p.axis),
            "radius_m": p.radius_m,
            "length_m": p.length_m,
        }
    return None


def object_summary(obj: SceneObject) -> dict[str, Any]:
    """One object: name, kind, material, bounds (m), triangle count, primitive, parameters."""
    return {
        "name": obj.name,
        "kind": obj.kind,
        "material": obj.material.name,
        "bounds_m": _floats(obj.bounds_m),
        "triangles": int(len(obj.mesh.faces)),
        "watertight": bool(obj.mesh.is_watertight),
        "primitive": _primitive(obj),
        "parameters": {k: (list(v) if isinstance(v, tuple) else v) for k, v in obj.parameters},
    }


def scene_summary(scene: Scene) -> dict[str, Any]:
    """The scene as a JSON-ready mapping.

    Keys: ``name``, ``medium`` (with the sound speed in m/s, density in kg/m^3 and the
    absorption in dB/m at the sonar's centre frequency), ``tank`` (None in free field),
    ``boundaries``, ``sonar`` (pose, transducer positions in the tank frame, boresight),
    ``objects`` and ``triangle_count``.
    """
    medium = scene.medium
    sonar = scene.sonar
    f0 = sonar.centre_frequency_hz
    tank = scene.tank
    return {
        "name": scene.name,
        "medium": {
            "water": medium.water,
            "temperature_c": medium.temperature_c,
            "salinity_ppt": medium.salinity_ppt,
            "depth_m": medium.depth_m,
            "formula": medium.formula,
            "sound_speed_m_s": round(medium.sound_speed, 6),
            "sound_speed_overridden": medium.sound_speed_m_s is not None,
            "density_kg_m3": round(medium.density, 6),
            "absorption_db_per_m_at_centre_frequency": round(float(medium.absorption_db_per_m(f0)), 9),
        },
        "tank": None
        if tank is None
        else {
            "length_m": tank.length_m,
            "width_m": tank.width_m,
            "water_depth_m": tank.water_depth_m,
            "wall_material": tank.wall_material,
            "floor_material": tank.floor_material,
            "surface_material": tank.surface_material,
            "bounds_m": _floats(tank.bounds_m),
        },
        "boundaries": [{"name": b.name, "kind": b.kind, "material": b.material.name} for b in scene.boundaries],
        "sonar": {
            "position_m": list(sonar.position_m),
            "yaw_deg": sonar.yaw_deg,
            "pitch_deg": sonar.pitch_deg,
            "roll_deg": sonar.roll_deg,
            "boresight": _floats(sonar.boresight),
            "separation_m": sonar.separation_m,
            "transducer_diameter_m": sonar.transducer_diameter_m,
            "centre_frequency_hz": f0,
            "pulse_duration_s": sonar.pulse_duration_s,
            "sample_rate_hz": sonar.sample_rate_hz,
            "adc_bits": sonar.adc_bits,
            "record_length_s": sonar.record_length_s,
            "n_samples": sonar.n_samples,
            "transducers": [
                {"name": t.name, "role": t.role, "position_m": pos}
                for t, pos in zip(sonar.transducers, _floats(sonar.receiver_positions))
            ],
        },
        "objects": [object_summary(o) for o in scene.objects],
        "triangle_count": int(scene.triangle_count),
    }
