"""Bad input to the propagation solver: clear InputErrors, no hangs."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
import trimesh

from acoustisim.errors import InputError
from acoustisim.materials import get_material
from acoustisim.medium import Medium
from acoustisim.propagation import SolverConfig, solve
from acoustisim.scene import Scene, SceneObject, Tank
from acoustisim.sonar import SonarHead
from scenes.builders import post, sphere

DETERMINISTIC = SolverConfig(mechanisms=("direct", "specular"))


def _scene(objects=(), sonar=SonarHead()) -> Scene:
    return Scene("bad", Medium(), sonar, Tank(9.0, 3.0, 1.0), tuple(objects))


@pytest.mark.parametrize(
    "kwargs, field",
    [
        ({"max_order": 0}, "max_order"),
        ({"max_order": 2.5}, "max_order"),
        ({"max_order": 5}, "max_order"),
        ({"max_curved_per_path": 0}, "max_curved_per_path"),
        ({"max_curved_per_path": 3}, "max_curved_per_path"),
        ({"max_curved_per_path": 2.0}, "max_curved_per_path"),
        ({"max_curved_per_path": True}, "max_curved_per_path"),
        ({"diffuse_rays": -1}, "diffuse_rays"),
        ({"diffuse_bounces": 0}, "diffuse_bounces"),
        ({"edge_segment_m": 0.0}, "edge_segment_m"),
        ({"edge_segment_m": float("nan")}, "edge_segment_m"),
        ({"edge_adaptive": "yes"}, "edge_adaptive"),
        ({"amplitude_floor_db": 10.0}, "amplitude_floor_db"),
        ({"mechanisms": ("direct", "magic")}, "mechanisms"),
        ({"mechanisms": "direct"}, "mechanisms"),
        ({"seed": -3}, "seed"),
        ({"threads": 0}, "threads"),
        ({"threads": 1.5}, "threads"),
        ({"threads": True}, "threads"),
        ({"diffuse_visibility": "approximate"}, "diffuse_visibility"),
        ({"diffuse_visibility": None}, "diffuse_visibility"),
        ({"amplitude_floor_band_hz": (7e5, 3e5)}, "amplitude_floor_band_hz"),
        ({"amplitude_floor_band_hz": (0.0, 3e5)}, "amplitude_floor_band_hz"),
        ({"amplitude_floor_band_hz": "wide"}, "amplitude_floor_band_hz"),
    ],
)
def test_bad_config_names_the_field(kwargs, field):
    with pytest.raises(InputError, match=field):
        SolverConfig(**kwargs)


def test_zero_area_faces_are_rejected():
    mesh = trimesh.creation.box(extents=(0.2, 0.2, 0.2))
    vertices = np.vstack([mesh.vertices, mesh.vertices[:1]])
    faces = np.vstack([mesh.faces, [[0, 1, len(vertices) - 1]]])  # a face with two equal vertices
    bad = trimesh.Trimesh(vertices + (3.0, 1.5, 0.5), faces, process=False)
    obj = SceneObject("crumb", "mesh", get_material("steel"), bad)
    with pytest.raises(InputError, match="crumb.*zero-area"):
        solve(_scene([obj]), config=DETERMINISTIC)


def test_open_shell_is_rejected():
    mesh = trimesh.creation.box(extents=(0.2, 0.2, 0.2))
    open_mesh = trimesh.Trimesh(mesh.vertices + (3.0, 1.5, 0.5), mesh.faces[:-2], process=False)
    obj = SceneObject("lid-off", "mesh", get_material("steel"), open_mesh)
    with pytest.raises(InputError, match="lid-off.*closed shell"):
        solve(_scene([obj]), config=DETERMINISTIC)


def test_sonar_touching_the_wall_or_outside_the_water():
    with pytest.raises(InputError, match="tank boundary"):
        solve(_scene(sonar=SonarHead(position_m=(0.005, 1.5, 0.5))), config=DETERMINISTIC)
    with pytest.raises(InputError, match="outside the water"):
        solve(_scene(sonar=SonarHead(position_m=(1.0, 1.5, 1.5))), config=DETERMINISTIC)


def test_sonar_touching_or_inside_an_object():
    ball = sphere("ball", (1.5, 1.5, 0.5), 0.1)
    with pytest.raises(InputError, match="ball"):
        solve(_scene([ball], SonarHead(position_m=(1.5, 1.5, 0.5))), config=DETERMINISTIC)
    pole = post("pole", (1.0, 1.5 - 0.065 - 0.012), 0.01, 1.0)  # 2 mm from the right receiver
    with pytest.raises(InputError, match="pole"):
        solve(_scene([pole]), config=DETERMINISTIC)


def test_receiver_coincident_with_transmitter():
    """Two transducers on one spot are refused when the head is described, before any solve."""
    with pytest.raises(InputError, match="channel_positions_m.*left transducer coincides with the centre"):
        replace(SonarHead(), channel_positions_m=((0.0, 0.0, 0.0), (0.0, 0.0, 0.0), (0.065, 0.0, 0.0)))
    with pytest.raises(InputError, match="left transducer coincides with the right"):
        replace(SonarHead(), channel_positions_m=((0.1, 0.0, 0.0), (0.0, 0.0, 0.0), (0.1, 0.0, 0.001)))


def test_wrong_config_type():
    with pytest.raises(InputError, match="SolverConfig"):
        solve(_scene(), config={"max_order": 2})  # type: ignore[arg-type]
