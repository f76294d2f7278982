"""Randomised cluttered tank scenes for the ``clutter`` experiment (no ``NAME``: a helper).

The thesis tank (9 m x 3 m x 1 m of fresh water, concrete walls) with a rough sand floor
(``sand``'s larger Lambert strength makes floor reverberation) and ``n_objects`` objects drawn
from a seeded generator in the sonar's field of view: vertical posts (radius 1-5 cm, floor to
surface), 60-degree steel edge prisms (faces 10-20 cm, the sharp edge toward the sonar), short
vertical cylinders (radius 2-6 cm, 20-40 cm long, centred at the sonar's height) and spheres
(radius 2-6 cm, centre within 5 cm of the sonar's height). Ranges are uniform in
``RANGE_M``, bearings in +/- ``BEARING_DEG`` (the main lobe of the 19 mm transducers is about
+/- 5 deg at -3 dB, the first null at 11 deg), and any two objects keep ``MIN_GAP_M`` between
their reference points so that their echoes stay distinct and no two meshes intersect.
"""

from __future__ import annotations

import math
from dataclasses import replace
from typing import Any

import numpy as np

KINDS: tuple[str, ...] = ("post", "edge", "cylinder", "sphere")
RANGE_M: tuple[float, float] = (0.8, 3.2)
"""Range of the objects' reference points from the transmitter (m)."""
BEARING_DEG = 8.0
"""Objects' bearings are uniform in +/- this (deg)."""
MIN_GAP_M = 0.25
"""Least distance between two objects' reference points (m): larger than any two objects' sizes."""
FLOOR_MATERIAL = "sand"
WALL_MATERIAL = "concrete"


def tank() -> Any:
    """The thesis tank with a rough sand floor."""
    from acoustisim.scene import Tank

    return Tank(length_m=9.0, width_m=3.0, water_depth_m=1.0, wall_material=WALL_MATERIAL,
                floor_material=FLOOR_MATERIAL)


def _draw_object(kind: str, name: str, xy: tuple[float, float], facing_deg: float, z_m: float,
                 depth_m: float, rng: np.random.Generator) -> Any:
    from scenes.builders import cylinder, edge_prism, post, sphere

    if kind == "post":
        return post(name, xy, float(rng.uniform(0.01, 0.05)), depth_m, "pvc")
    if kind == "edge":
        return edge_prism(name, xy, 60.0, facing_deg, float(rng.uniform(0.1, 0.2)), depth_m, "steel")
    if kind == "cylinder":
        return cylinder(name, (xy[0], xy[1], z_m), (0.0, 0.0, 1.0), float(rng.uniform(0.02, 0.06)),
                        float(rng.uniform(0.2, 0.4)), "pvc")
    return sphere(name, (xy[0], xy[1], z_m + float(rng.uniform(-0.05, 0.05))), float(rng.uniform(0.02, 0.06)),
                  "steel")


def cluttered_scene(n_objects: int, rng: np.random.Generator, record_length_s: float) -> Any:
    """A random cluttered tank scene seen from the default pose.

    Parameters
    ----------
    n_objects : int
        Objects to place (>= 1); kinds cycle through ``KINDS`` from a random start so that every
        density has a mix.
    rng : numpy.random.Generator
        The source of every random choice.
    record_length_s : float
        The sonar's record length (s).

    Returns
    -------
    Scene
        Named objects ``<kind>-<i>``; the sonar at the default pose (1.0, 1.5, 0.5) m facing +x.
    """
    from acoustisim.medium import Medium
    from acoustisim.scene import Scene
    from scenes.builders import default_sonar

    if n_objects < 1:
        raise ValueError(f"n_objects must be >= 1, got {n_objects}")
    sonar = replace(default_sonar(), record_length_s=record_length_s)
    tx = np.asarray(sonar.transmitter_position, dtype=float)
    yaw = math.radians(sonar.yaw_deg)
    first = int(rng.integers(len(KINDS)))
    placed: list[np.ndarray] = []
    objects = []
    for i in range(n_objects):
        kind = KINDS[(first + i) % len(KINDS)]
        for _ in range(1000):
            r = float(rng.uniform(*RANGE_M))
            b = math.radians(float(rng.uniform(-BEARING_DEG, BEARING_DEG)))
            # bearing is positive toward the right receiver, i.e. clockwise from the boresight
            xy = tx[:2] + r * np.array([math.cos(yaw - b), math.sin(yaw - b)])
            if all(np.linalg.norm(xy - p) >= MIN_GAP_M for p in placed):
                break
        else:  # pragma: no cover - 1000 draws always find room for the densities used
            raise RuntimeError(f"no room for object {i} after 1000 draws")
        placed.append(xy)
        facing = math.degrees(math.atan2(tx[1] - xy[1], tx[0] - xy[0]))
        objects.append(_draw_object(kind, f"{kind}-{i}", (float(xy[0]), float(xy[1])), facing, float(tx[2]), 1.0,
                                    rng))
    medium = Medium(water="fresh", temperature_c=20.0, salinity_ppt=0.0, depth_m=0.5)
    return Scene(name=f"clutter-{n_objects}", medium=medium, sonar=sonar, tank=tank(), objects=tuple(objects))
