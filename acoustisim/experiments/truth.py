"""What a localiser should report for each object of a scene, seen from a sonar pose.

A localiser reports, per target, a range from the transmitter to the reflecting surface and a
bearing in the head frame (``binsonar.localization.Target``). The truth for each kind:

- ``edge``: the sharp vertical edge at the sonar's height, a point target;
- ``post`` / vertical ``cylinder``: the axis at the sonar's height; range |C - T| - a (the
  nearest surface), bearing of the axis; class ``cylinder``;
- ``sphere``: its centre; range |C - T| - a; class ``cylinder`` in the horizontal plane;
- anything else: the mesh's nearest point, class ``unknown``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from acoustisim.geometry import CylinderPrimitive, SpherePrimitive
from acoustisim.scene import Scene, SceneObject
from acoustisim.sonar import SonarHead


@dataclass(frozen=True)
class ObjectTruth:
    """Truth of one object seen from one pose.

    Attributes
    ----------
    name, kind, cls : str
        Object name and kind, and the class a localiser should give.
    position_tank_m : ndarray (3,)
        The reference point (edge point or axis point at the sonar's height) in the tank frame.
    range_m : float
        Transmitter to the reflecting surface (m).
    bearing_deg : float
        Bearing in the head frame (deg), positive toward the right receiver.
    radius_m : float
        Curvature radius in the horizontal plane (0 for a point, NaN when not defined).
    """

    name: str
    kind: str
    cls: str
    position_tank_m: NDArray[np.float64]
    range_m: float
    bearing_deg: float
    radius_m: float


def _head_range_bearing(sonar: SonarHead, point: NDArray[np.float64]) -> tuple[float, float, NDArray[np.float64]]:
    head = sonar.tank_to_head(point[None, :])[0] - sonar.channel_positions_head[1]
    return float(np.linalg.norm(head)), math.degrees(math.atan2(head[0], head[1])), head


def object_truth(scene: Scene, sonar: SonarHead, obj: SceneObject) -> ObjectTruth:
    """The truth of one object from one pose (see the module docstring)."""
    tx = sonar.transmitter_position
    prim = obj.primitive
    if obj.kind == "edge":
        x, y = obj.parameter("edge_m")
        point = np.array([x, y, tx[2]])
        r, b, _ = _head_range_bearing(sonar, point)
        return ObjectTruth(obj.name, obj.kind, "point", point, r, b, 0.0)
    if isinstance(prim, CylinderPrimitive) and abs(prim.axis[2]) > 0.999:
        point = np.array([prim.center_m[0], prim.center_m[1], tx[2]])
        r, b, _ = _head_range_bearing(sonar, point)
        return ObjectTruth(obj.name, obj.kind, "cylinder", point, r - prim.radius_m, b, prim.radius_m)
    if isinstance(prim, SpherePrimitive):
        point = np.asarray(prim.center_m, dtype=float)
        r, b, _ = _head_range_bearing(sonar, point)
        return ObjectTruth(obj.name, obj.kind, "cylinder", point, r - prim.radius_m, b, prim.radius_m)
    nearest = obj.mesh.nearest.on_surface(tx[None, :])[0][0]
    r, b, _ = _head_range_bearing(sonar, np.asarray(nearest))
    return ObjectTruth(obj.name, obj.kind, "unknown", np.asarray(nearest, dtype=float), r, b, float("nan"))


def scene_truth(scene: Scene, sonar: SonarHead | None = None) -> list[ObjectTruth]:
    """The truth of every object of a scene from ``sonar`` (default the scene's)."""
    sonar = scene.sonar if sonar is None else sonar
    return [object_truth(scene, sonar, obj) for obj in scene.objects]
