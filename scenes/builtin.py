"""Named built-in scenes: the thesis tank and the single-object free-field validation scenes.

``thesis-tank``
    The 9 m x 3 m x 1 m concrete tank of fresh water at 20 C, the default sonar at
    (1.0, 1.5, 0.5) m looking down +x, and targets like the seed's figures 3-8 and 4-12: a
    machined-steel 60-degree edge prism 1.5 m ahead on the boresight, pointing at the sonar; two PVC
    posts at about 8.5 deg right and 9 deg left (inside the +/-11 deg first null at 500 kHz);
    an air-filled PVC pipe (150 mm, 4 mm wall, capped) at 6.5 deg left behind them, clear of
    their shadows; and a third post far
    off axis (seen from other poses). Every object is at least 5 cm from the walls and from
    the others. The record is ``THESIS_TANK_RECORD_S`` long: every path the default solver keeps
    lands in it.
``free-sphere``, ``free-plane``, ``free-post``, ``free-edge``, ``free-cylinder``
    Free field (no tank), the default sonar at the origin looking along +x, and one rigid
    (R = 1) object on the boresight whose front is 1.0 m ahead. The free-field post and edge
    are 1 m tall, centred on the sonar's height.
"""

from __future__ import annotations

from dataclasses import replace
from types import MappingProxyType
from typing import Callable

from acoustisim.errors import InputError
from acoustisim.medium import Medium
from acoustisim.scene import Scene, Tank
from scenes.builders import cylinder, default_sonar, edge_prism, plate, post, sphere

THESIS_TANK_RECORD_S = 0.020
"""Record length of the thesis tank's sonar (s). The default solver (specular paths to order 3,
edges, diffuse) keeps arrivals up to 19.6 ms after the ping from the default pose: third-order
multipaths between the far wall (8 m ahead), the targets and the near wall, 17-38 dB under the
strongest target echo and well above the receiver noise, so they are part of what the hydrophones
would record. The default sonar's 12.5 ms would cut them off (and ``simulate`` would warn that it
did, on every run); 20 ms holds every one of them, so a default run drops nothing and warns about
nothing. It costs about 60 % more samples per channel (400,000 at 20 MS/s)."""

PIPE_WALL_M = 0.004
"""The thesis tank's pipe: a 150 mm PVC pipe of sewer class (SDR 33-41: 3.7-4.5 mm walls; EN 1401's
160 mm SN4 pipe has 4.0 mm)."""

PIPE_FILL = "air"
"""The pipe is a closed section (the scene's cylinder has caps) hung at mid-depth: capped, it holds
air."""

FREE_FIELD_MATERIAL = "rigid"
"""Material of the validation objects (R = +1, so analytic answers need no coefficient)."""


def _thesis_tank() -> Scene:
    tank = Tank(length_m=9.0, width_m=3.0, water_depth_m=1.0, wall_material="concrete", floor_material="concrete")
    depth = tank.water_depth_m
    objects = (
        edge_prism("edge-1", (2.5, 1.5), 60.0, 180.0, 0.10, depth, "steel-machined"),
        post("post-1", (3.0, 1.2), 0.025, depth, "pvc"),
        post("post-2", (3.2, 1.85), 0.025, depth, "pvc"),
        post("post-3", (6.5, 0.6), 0.025, depth, "pvc"),
        cylinder("pipe-1", (4.5, 1.9, 0.5), (0.0, 0.0, 1.0), 0.075, 0.6, "pvc", wall_thickness_m=PIPE_WALL_M,
                 fill=PIPE_FILL),
    )
    return Scene(
        name="thesis-tank",
        medium=Medium(water="fresh", temperature_c=20.0, salinity_ppt=0.0, depth_m=0.5),
        sonar=replace(default_sonar(), record_length_s=THESIS_TANK_RECORD_S),
        tank=tank,
        objects=objects,
    )


def _free_field(name: str, obj_factory: Callable[[], object]) -> Callable[[], Scene]:
    def build() -> Scene:
        return Scene(
            name=name,
            medium=Medium(water="fresh", temperature_c=20.0, salinity_ppt=0.0, depth_m=0.5),
            sonar=replace(default_sonar(), position_m=(0.0, 0.0, 0.0)),
            tank=None,
            objects=(obj_factory(),),  # type: ignore[arg-type]
        )

    return build


_BUILDERS: MappingProxyType[str, Callable[[], Scene]] = MappingProxyType({
    "thesis-tank": _thesis_tank,
    "free-sphere": _free_field("free-sphere", lambda: sphere("sphere", (1.05, 0.0, 0.0), 0.05, FREE_FIELD_MATERIAL)),
    "free-plane": _free_field(
        "free-plane",
        lambda: plate("plane", (1.025, 0.0, 0.0), (-1.0, 0.0, 0.0), 2.0, 2.0, 0.05, FREE_FIELD_MATERIAL),
    ),
    "free-post": _free_field(
        "free-post", lambda: post("post", (1.025, 0.0), 0.025, 0.5, FREE_FIELD_MATERIAL, bottom_m=-0.5)
    ),
    "free-edge": _free_field(
        "free-edge",
        lambda: edge_prism("edge", (1.0, 0.0), 60.0, 180.0, 0.10, 0.5, FREE_FIELD_MATERIAL, bottom_m=-0.5),
    ),
    "free-cylinder": _free_field(
        "free-cylinder",
        lambda: cylinder("cylinder", (1.1, 0.0, 0.0), (0.0, 0.0, 1.0), 0.1, 0.6, FREE_FIELD_MATERIAL),
    ),
})


def builtin_scene_names() -> tuple[str, ...]:
    """Names of the built-in scenes, thesis tank first."""
    return tuple(_BUILDERS)


def builtin_scene(name: str) -> Scene:
    """Build a built-in scene by name.

    Raises
    ------
    InputError
        Unknown name (the message lists the known ones).
    """
    try:
        factory = _BUILDERS[name]
    except KeyError:
        raise InputError(
            f"unknown built-in scene {name!r} (known: {', '.join(builtin_scene_names())})"
        ) from None
    return factory()
