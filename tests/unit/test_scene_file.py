"""The scene file: the conventions example loads, scenes round-trip, paths are relative."""

import shutil
import tomllib
from pathlib import Path

import pytest

from acoustisim.scene import Scene
from scenes.builtin import builtin_scene, builtin_scene_names
from scenes.scene_file import load_scene, save_scene, scene_to_toml

DATA = Path(__file__).resolve().parents[2] / "scenes" / "data"
EXAMPLE = DATA / "example.toml"


@pytest.fixture()
def example_dir(tmp_path) -> Path:
    shutil.copy(EXAMPLE, tmp_path / "example.toml")
    shutil.copy(DATA / "rock.stl", tmp_path / "rock.stl")
    return tmp_path


def test_conventions_example_loads_as_written(example_dir):
    scene = load_scene(example_dir / "example.toml")
    assert scene.name == "example"
    assert [(o.name, o.kind, o.material.name) for o in scene.objects] == [
        ("post-1", "post", "pvc"),
        ("edge-1", "edge", "steel"),
        ("pipe-1", "cylinder", "pvc"),
        ("ball-1", "sphere", "steel"),
        ("rock", "mesh", "concrete"),
    ]
    assert scene.medium.sound_speed == pytest.approx(1482.38, abs=0.005)
    assert scene.tank is not None and scene.tank.water_depth_m == 1.0
    assert scene.sonar.centre_frequency_hz == 500e3 and scene.sonar.adc_bits == 12
    post = scene.object("post-1")
    assert post.bounds_m[0, 2] == 0.0 and post.bounds_m[1, 2] == 1.0  # floor to surface by default
    rock = scene.object("rock")
    assert rock.parameter("path") == str((example_dir / "rock.stl").resolve())
    assert rock.mesh.is_watertight and rock.mesh.volume > 0


def test_shipped_example_matches_conventions_when_available():
    conventions = Path("/work/shared/conventions.md")
    if not conventions.is_file():
        pytest.skip("conventions.md is outside this checkout")
    text = conventions.read_text()
    block = text.split("```toml\n", 1)[1].split("```", 1)[0]
    assert EXAMPLE.read_text().endswith(block)


@pytest.mark.parametrize("name", builtin_scene_names())
def test_builtin_scenes_round_trip(tmp_path, name):
    scene = builtin_scene(name)
    path = tmp_path / f"{name}.toml"
    save_scene(scene, path)
    again = load_scene(path)
    assert again == scene
    assert again.surface_names == scene.surface_names
    # Saving again gives the same text: the file is a fixed point.
    assert scene_to_toml(again, tmp_path) == path.read_text()


def test_example_round_trips_with_relative_mesh_path(example_dir, tmp_path):
    scene = load_scene(example_dir / "example.toml")
    elsewhere = tmp_path / "out" / "nested"
    elsewhere.mkdir(parents=True)
    target = elsewhere / "copy.toml"
    save_scene(scene, target)
    data = tomllib.loads(target.read_text())
    assert data["objects"][4]["path"] == "../../rock.stl"  # relative to the new file
    assert load_scene(target) == scene


def test_round_trip_compares_unequal_when_something_changes(tmp_path):
    scene = builtin_scene("thesis-tank")
    path = tmp_path / "t.toml"
    save_scene(scene, path)
    path.write_text(path.read_text().replace("radius_m = 0.025", "radius_m = 0.03", 1))
    assert load_scene(path) != scene  # the equality used above can fail


def test_load_scene_accepts_builtin_names():
    assert load_scene("thesis-tank") == builtin_scene("thesis-tank")


def test_minimal_file_takes_defaults(tmp_path):
    path = tmp_path / "small.toml"
    path.write_text('[tank]\nlength_m = 4\nwidth_m = 2\nwater_depth_m = 0.8\n'
                    '[[objects]]\nkind = "post"\ncenter_m = [3, 1]\nradius_m = 0.02\n')
    scene = load_scene(path)
    assert scene.name == "small"
    assert scene.objects[0].name == "post-1" and scene.objects[0].material.name == "pvc"
    assert scene.objects[0].bounds_m[1, 2] == pytest.approx(0.8)  # the post reaches the surface
    assert scene.sonar.position_m == (1.0, 1.5, 0.5)  # the default sonar
    assert scene.tank.wall_material == "concrete"
    assert scene.medium.water == "fresh"


def test_free_field_file_and_overrides(tmp_path):
    path = tmp_path / "free.toml"
    path.write_text(
        'name = "my free edge"\nfree_field = true\n'
        '[medium]\nwater = "sea"\nsalinity_ppt = 35\nsound_speed_m_s = 1500.0\n'
        '[sonar]\nposition_m = [0, 0, 0]\nchannel_positions_m = [[-0.04, 0, 0], [0, 0, 0], [0.04, 0, 0.01]]\n'
        '[[objects]]\nkind = "edge"\nedge_m = [1, 0]\ninterior_angle_deg = 90\nfacing_deg = 180\n'
        'size_m = 0.2\nbottom_m = -0.3\ntop_m = 0.3\nmaterial = "rigid"\n'
    )
    scene = load_scene(path)
    assert scene.name == "my free edge" and scene.tank is None
    assert scene.medium.sound_speed == 1500.0
    assert scene.sonar.channel_positions_m[2] == (0.04, 0.0, 0.01)
    save_scene(scene, tmp_path / "again.toml")
    assert load_scene(tmp_path / "again.toml") == scene


def test_every_kind_loads(tmp_path):
    shutil.copy(DATA / "rock.stl", tmp_path / "rock.stl")
    path = tmp_path / "all.toml"
    path.write_text(
        '[tank]\nlength_m = 9\nwidth_m = 3\nwater_depth_m = 1\n'
        '[[objects]]\nkind = "plate"\ncenter_m = [7, 1.5, 0.5]\nnormal = [-1, 0, 0]\nwidth_m = 1\n'
        'height_m = 0.5\nthickness_m = 0.02\n'
        '[[objects]]\nkind = "mesh"\npath = "rock.stl"\nposition_m = [5, 1, 0.3]\nscale = 0.5\npitch_deg = 10\n'
    )
    scene = load_scene(path)
    assert [o.kind for o in scene.objects] == ["plate", "mesh"]
    save_scene(scene, tmp_path / "again.toml")
    assert load_scene(tmp_path / "again.toml") == scene


def test_save_leaves_no_file_when_the_scene_cannot_be_written(tmp_path):
    from dataclasses import replace

    from acoustisim.materials import Material
    from scenes.errors import SceneFileError

    scene = builtin_scene("free-sphere")
    # A material that is not the library's is written as [[materials]], unless it takes a
    # built-in name (the file would then mean the library's material).
    odd = replace(scene.objects[0], material=Material("steel", 1000.0, 1500.0))
    with pytest.raises(SceneFileError, match="material 'steel': two different materials"):
        save_scene(Scene(scene.name, scene.medium, scene.sonar, None, (odd,)), tmp_path / "x.toml")
    assert not (tmp_path / "x.toml").exists()
