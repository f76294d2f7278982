"""A scene file's own [[materials]]: loading, naming from objects and tank, round trip, bad entries."""

from dataclasses import replace

import pytest

from acoustisim.materials import Material
from scenes.errors import SceneFileError
from scenes.scene_file import load_scene, save_scene, scene_to_toml

LAB = """
[[materials]]
name = "pvc-lab"
density_kg_m3 = 1380.0
compressional_speed_m_s = 2380.0
shear_speed_m_s = 1060.0
compressional_loss_factor = 0.03   # eta: k = (w / c) (1 + i eta / 2)
shear_loss_factor = 0.05
roughness_rms_m = 0.0
diffuse_mu = 0.003

[[materials]]
name = "rough-concrete"
density_kg_m3 = 2300.0
compressional_speed_m_s = 4000.0
roughness_rms_m = 0.0005
"""

TANK = """
[tank]
length_m = 9.0
width_m = 3.0
water_depth_m = 1.0
wall_material = "rough-concrete"
floor_material = "rough-concrete"

[[objects]]
kind = "post"
center_m = [3.0, 1.2]
radius_m = 0.025
material = "pvc-lab"

[[objects]]
kind = "sphere"
center_m = [5.0, 1.0, 0.5]
radius_m = 0.05
"""


def write(tmp_path, text, name="scene.toml"):
    path = tmp_path / name
    path.write_text(text)
    return path


def test_scene_materials_load_and_are_named_by_objects_walls_and_floor(tmp_path):
    scene = load_scene(write(tmp_path, LAB + TANK))
    post, sphere = scene.objects
    assert post.material == Material("pvc-lab", 1380.0, 2380.0, 1060.0, "elastic", diffuse_mu=0.003,
                                     compressional_loss_factor=0.03, shear_loss_factor=0.05)
    assert sphere.material.name == "steel"  # the built-in default stays available
    floor = next(b for b in scene.tank.boundaries if b.name == "floor")
    wall = next(b for b in scene.tank.boundaries if b.kind == "wall")
    assert floor.material.roughness_rms_m == 0.0005 and wall.material.name == "rough-concrete"
    assert floor.material.shear_speed_m_s == 0.0  # omitted keys default to 0
    # Without reflection_model a solid reflects elastically (as the built-in solids), a fluid as a fluid.
    assert floor.material.model == "fluid"


@pytest.mark.parametrize(
    "lines, model, fixed",
    [
        ('reflection_model = "fluid"', "fluid", 0.0),
        ('reflection_model = "elastic"', "elastic", 0.0),
        ('reflection_model = "rigid"', "rigid", 0.0),
        ('reflection_model = "pressure-release"', "pressure-release", 0.0),
        ('reflection_model = "fixed"\nfixed_reflection = -0.9', "fixed", -0.9),
    ],
)
def test_a_scene_material_chooses_its_reflection_model_and_keeps_it_through_save(tmp_path, lines, model, fixed):
    scene = load_scene(write(tmp_path, LAB.replace("diffuse_mu = 0.003", "diffuse_mu = 0.003\n" + lines, 1) + TANK))
    material = scene.objects[0].material
    assert (material.model, material.fixed_reflection) == (model, fixed)
    save_scene(scene, tmp_path / "again.toml")
    assert load_scene(tmp_path / "again.toml").objects[0].material == material


def test_scene_materials_round_trip_through_save(tmp_path):
    scene = load_scene(write(tmp_path, LAB + TANK))
    save_scene(scene, tmp_path / "again.toml")
    again = load_scene(tmp_path / "again.toml")
    assert again == scene and again.tank.materials == scene.tank.materials
    assert again.objects[0].material == scene.objects[0].material
    # saving twice gives the same text (every value explicit)
    assert scene_to_toml(again) == scene_to_toml(scene)


def test_a_file_without_materials_writes_none(tmp_path):
    scene = load_scene(write(tmp_path, TANK.replace('"rough-concrete"', '"concrete"').replace('"pvc-lab"', '"pvc"')))
    assert "[[materials]]" not in scene_to_toml(scene)


@pytest.mark.parametrize(
    "edit, message",
    [
        (("shear_speed_m_s = 1060.0", "shear_speed_m_s = -5.0"), r"materials\[0\]\.shear_speed_m_s = -5\.0: .*>= 0"),
        (("shear_speed_m_s = 1060.0", "shear_speed_m_s = 3000.0"),
         r"materials\[0\]\.shear_speed_m_s = 3000\.0: .*sqrt\(3\)/2"),
        (("shear_loss_factor = 0.05", 'shear_loss_factor = "high"'),
         r"materials\[0\]\.shear_loss_factor = 'high': expected a number"),
        (("diffuse_mu = 0.003", "diffuse_mu = 0.5"), r"materials\[0\]\.diffuse_mu = 0\.5: .*1/pi"),
        (("diffuse_mu = 0.003", "diffuse_mux = 0.003"), r"materials\[0\]\.diffuse_mux = 0\.003: unknown key"),
        (('name = "pvc-lab"', 'name = "steel"'), r"materials\[0\]\.name = 'steel': is a built-in"),
        (('name = "rough-concrete"', 'name = "pvc-lab"'), r"materials\[1\]\.name = 'pvc-lab': defined twice"),
        (("density_kg_m3 = 1380.0\n", ""), r"materials\[0\]\.density_kg_m3: missing"),
        (("density_kg_m3 = 1380.0", "density_kg_m3 = 0.0"), r"materials\[0\]\.density_kg_m3 = 0\.0: .*> 0"),
        (("diffuse_mu = 0.003", 'diffuse_mu = 0.003\nreflection_model = "elasticc"'),
         r"materials\[0\]\.reflection_model = 'elasticc': expected one of elastic, fluid"),
        (("diffuse_mu = 0.003", 'diffuse_mu = 0.003\nreflection_model = "fixed"'),
         r"materials\[0\]\.fixed_reflection: missing \(required by reflection_model = 'fixed'\)"),
        (("diffuse_mu = 0.003", "diffuse_mu = 0.003\nfixed_reflection = 0.5"),
         r"materials\[0\]\.fixed_reflection = 0\.5: only the 'fixed' reflection model takes it"),
        (("diffuse_mu = 0.003", 'diffuse_mu = 0.003\nreflection_model = "fixed"\nfixed_reflection = 1.5'),
         r"materials\[0\]\.fixed_reflection = 1\.5: .*\[-1, 1\]"),
    ],
)
def test_bad_entries_get_one_line_naming_file_key_and_value(tmp_path, edit, message):
    old, new = edit
    path = write(tmp_path, (LAB + TANK).replace(old, new, 1))
    with pytest.raises(SceneFileError, match=message) as info:
        load_scene(path)
    text = str(info.value)
    assert text.startswith(str(path)) and "\n" not in text


def test_an_object_naming_an_undefined_material_lists_the_scene_ones(tmp_path):
    path = write(tmp_path, LAB + TANK.replace('material = "pvc-lab"', 'material = "pvc-lob"'))
    with pytest.raises(SceneFileError, match=r"objects\[0\]\.material = 'pvc-lob': unknown material .*pvc-lab"):
        load_scene(path)


def test_materials_must_be_an_array_of_tables(tmp_path):
    path = write(tmp_path, 'materials = 3\n' + TANK.replace('"rough-concrete"', '"concrete"').replace('"pvc-lab"', '"pvc"'))
    with pytest.raises(SceneFileError, match="materials = 3: expected an array of tables"):
        load_scene(path)


def test_a_fixed_coefficient_outside_the_fixed_model_cannot_be_saved(tmp_path):
    # The file keeps fixed_reflection for the fixed model only; a material that carries one with
    # another model would not load back equal, so saving refuses it, naming the material.
    scene = load_scene(write(tmp_path, LAB + TANK))
    lab = replace(scene.objects[0].material, fixed_reflection=0.5)
    tank = replace(scene.tank, materials=tuple(lab if m.name == lab.name else m for m in scene.tank.materials))
    odd = replace(scene, tank=tank, objects=(replace(scene.objects[0], material=lab), *scene.objects[1:]))
    with pytest.raises(SceneFileError, match=r"'pvc-lab': fixed_reflection = 0\.5 with model 'elastic'"):
        scene_to_toml(odd)
