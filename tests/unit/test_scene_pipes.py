"""Pipes in scene files and builders: a cylinder's wall_thickness_m and fill."""

from __future__ import annotations

import re

import pytest

from acoustisim.errors import InputError
from acoustisim.scattering.bodies import AIR, Elastic, Fluid, Rigid, Shell
from acoustisim.scattering.echo import object_body
from scenes.builders import cylinder
from scenes.builtin import PIPE_FILL, PIPE_WALL_M, builtin_scene
from scenes.errors import SceneFileError
from scenes.scene_file import load_scene, save_scene

WATER = Fluid(998.2, 1482.4)

SCENE = """
[tank]
length_m = 9.0
width_m = 3.0
water_depth_m = 1.0

[[objects]]
kind = "cylinder"
name = "pipe"
center_m = [4.0, 2.0, 0.5]
axis = [0.0, 0.0, 1.0]
radius_m = 0.075
length_m = 0.6
material = "pvc"
"""


def write(tmp_path, extra: str):
    path = tmp_path / "scene.toml"
    path.write_text(SCENE + extra)
    return path


def test_a_pipe_loads_saves_and_loads_equal(tmp_path) -> None:
    scene = load_scene(write(tmp_path, 'wall_thickness_m = 0.004\nfill = "water"\n'))
    pipe = scene.objects[0]
    assert pipe.parameter("wall_thickness_m") == 0.004 and pipe.parameter("fill") == "water"
    body = object_body(pipe, WATER)
    assert body == Shell(Elastic(1380.0, 2380.0, 1060.0, 0.03, 0.05), 0.004, WATER)
    save_scene(scene, tmp_path / "saved.toml")
    assert "wall_thickness_m = 0.004" in (tmp_path / "saved.toml").read_text()
    assert load_scene(tmp_path / "saved.toml").objects == scene.objects
    # a solid cylinder stays one (no keys written)
    solid = load_scene(write(tmp_path, ""))
    save_scene(solid, tmp_path / "solid.toml")
    assert "fill" not in (tmp_path / "solid.toml").read_text()
    assert isinstance(object_body(solid.objects[0], WATER), Elastic)


@pytest.mark.parametrize("extra, message", [
    ("wall_thickness_m = 0.004\n", "objects[0].fill: missing"),
    ('fill = "air"\n', "objects[0].wall_thickness_m: missing"),
    ('wall_thickness_m = 0.08\nfill = "air"\n', "wall_thickness_m = 0.08: must be below radius_m"),
    ('wall_thickness_m = -0.001\nfill = "air"\n', "wall_thickness_m = -0.001: must be > 0"),
    ('wall_thickness_m = 0.004\nfill = "oil"\n', "fill = 'oil': expected one of 'air', 'water'"),
    ('wall_thickness_m = 0.004\nfill = "air"\n', "material = 'sand': a pipe's wall must be a solid"),
])
def test_bad_pipe_keys_are_named(tmp_path, extra: str, message: str) -> None:
    path = write(tmp_path, extra)
    if "sand" in message:  # a fluid wall
        path.write_text(path.read_text().replace('material = "pvc"', 'material = "sand"'))
    with pytest.raises(SceneFileError, match=re.escape(message)):
        load_scene(path)


def test_builders_and_the_thesis_tank_pipe() -> None:
    pipe = cylinder("p", (0, 0, 0), (0, 0, 1), 0.075, 0.6, "pvc", wall_thickness_m=0.004, fill="air")
    assert object_body(pipe, WATER) == Shell(Elastic(1380.0, 2380.0, 1060.0, 0.03, 0.05), 0.004, AIR)
    assert isinstance(object_body(cylinder("r", (0, 0, 0), (0, 0, 1), 0.075, 0.6, "rigid", wall_thickness_m=0.004,
                                           fill="air"), WATER), Rigid)
    with pytest.raises(InputError, match="p.fill"):
        cylinder("p", (0, 0, 0), (0, 0, 1), 0.075, 0.6, "pvc", wall_thickness_m=0.004)
    tank_pipe = builtin_scene("thesis-tank").object("pipe-1")
    assert (tank_pipe.parameter("wall_thickness_m"), tank_pipe.parameter("fill")) == (PIPE_WALL_M, PIPE_FILL)
    assert object_body(tank_pipe, WATER).fill == AIR
