"""Every mistake a user can make in a scene file: one line naming file, key and value; exit 2."""

import copy
import math
import shutil
from pathlib import Path

import pytest
import tomli_w
import trimesh

from acoustisim.cli.main import main
from acoustisim.errors import InputError
from scenes.errors import SceneFileError
from scenes.scene_file import load_scene

DATA = Path(__file__).resolve().parents[2] / "scenes" / "data"

BASE = {
    "medium": {"water": "fresh", "temperature_c": 20.0, "salinity_ppt": 0.0},
    "tank": {"length_m": 9.0, "width_m": 3.0, "water_depth_m": 1.0, "wall_material": "concrete",
             "floor_material": "concrete"},
    "sonar": {"position_m": [1.0, 1.5, 0.5], "yaw_deg": 0.0, "separation_m": 0.065},
    "objects": [
        {"kind": "post", "name": "post-1", "center_m": [3.0, 1.2], "radius_m": 0.025, "material": "pvc"},
        {"kind": "sphere", "name": "ball-1", "center_m": [5.0, 1.0, 0.5], "radius_m": 0.05, "material": "steel"},
        {"kind": "mesh", "name": "rock", "path": "rock.stl", "position_m": [6.0, 1.5, 0.2], "yaw_deg": 30.0},
        {"kind": "edge", "name": "edge-1", "edge_m": [2.5, 1.5], "interior_angle_deg": 60, "facing_deg": 180,
         "size_m": 0.1},
    ],
}


def _set(path: str, value):
    """A mutation setting one key, addressed as 'objects.1.radius_m'."""

    def mutate(data, directory):
        keys = path.split(".")
        node = data
        for key in keys[:-1]:
            node = node[int(key)] if isinstance(node, list) else node[key]
        node[keys[-1]] = value

    return mutate


def _delete(path: str):
    def mutate(data, directory):
        keys = path.split(".")
        node = data
        for key in keys[:-1]:
            node = node[int(key)] if isinstance(node, list) else node[key]
        del node[keys[-1]]

    return mutate


def _add_object(obj: dict):
    def mutate(data, directory):
        data["objects"].append(obj)

    return mutate


def _bad_mesh(content: str | None):
    def mutate(data, directory):
        if content == "open":
            sphere = trimesh.creation.icosphere(subdivisions=2, radius=0.1)
            keep = sphere.triangles_center[:, 2] < 0.05
            trimesh.Trimesh(sphere.vertices, sphere.faces[keep]).export(directory / "bowl.stl")
        elif content is not None:
            (directory / "bowl.stl").write_text(content)
        data["objects"][2]["path"] = "bowl.stl"

    return mutate


def _unreadable_mesh(data, directory):
    path = directory / "secret.stl"
    shutil.copy(DATA / "rock.stl", path)
    path.chmod(0)
    data["objects"][2]["path"] = "secret.stl"


# (id, mutation, key that must be named, value that must be named)
CASES = [
    ("unknown-top-key", _set("colour", "red"), "colour", "'red'"),
    ("unknown-medium-key", _set("medium.temprature_c", 20.0), "medium.temprature_c", "20.0"),
    ("unknown-object-key", _set("objects.0.radius", 0.1), "objects[0].radius", "0.1"),
    ("unknown-kind", _set("objects.1.kind", "cone"), "objects[1].kind", "'cone'"),
    ("missing-kind", _delete("objects.1.kind"), "objects[1].kind", "missing"),
    ("missing-size", _delete("objects.1.radius_m"), "objects[1].radius_m", "missing"),
    ("wrong-type-string", _set("objects.0.radius_m", "big"), "objects[0].radius_m", "'big'"),
    ("wrong-type-bool", _set("objects.0.radius_m", True), "objects[0].radius_m", "True"),
    ("wrong-length", _set("objects.0.center_m", [3.0]), "objects[0].center_m", "[3.0]"),
    ("wrong-type-table", _set("sonar", 3), "sonar", "3"),
    ("wrong-type-int", _set("sonar.adc_bits", 12.5), "sonar.adc_bits", "12.5"),
    ("wrong-water", _set("medium.water", "lake"), "medium.water", "'lake'"),
    ("negative-size", _set("objects.1.radius_m", -0.05), "objects[1].radius_m", "-0.05"),
    ("zero-size", _set("objects.3.size_m", 0), "objects[3].size_m", "0"),
    ("zero-tank", _set("tank.width_m", 0.0), "tank.width_m", "0.0"),
    ("bad-angle", _set("objects.3.interior_angle_deg", 200), "objects[3].interior_angle_deg", "200"),
    ("nan", _set("objects.1.radius_m", math.nan), "objects[1].radius_m", "nan"),
    ("inf", _set("tank.length_m", math.inf), "tank.length_m", "inf"),
    ("nan-in-vector", _set("sonar.position_m", [1.0, math.nan, 0.5]), "sonar.position_m", "nan"),
    ("medium-out-of-range", _set("medium.temperature_c", 200.0), "medium.temperature_c", "200.0"),
    ("unknown-material", _set("objects.1.material", "wood"), "objects[1].material", "'wood'"),
    ("unknown-wall-material", _set("tank.wall_material", "cheese"), "tank.wall_material", "'cheese'"),
    ("object-above-surface", _set("objects.1.center_m", [5.0, 1.0, 1.2]), "objects[1].center_m", "1.2"),
    ("object-below-floor", _set("objects.1.center_m", [5.0, 1.0, 0.01]), "objects[1].center_m", "0.01"),
    ("object-outside-tank", _set("objects.1.center_m", [12.0, 1.0, 0.5]), "objects[1].center_m", "12.0"),
    ("object-into-wall", _set("objects.0.center_m", [3.0, 0.01]), "objects[0].center_m", "0.01"),
    ("post-above-surface", _set("objects.0.top_m", 1.5), "objects[0].top_m", "1.5"),
    ("edge-below-floor", _set("objects.3.bottom_m", -0.2), "objects[3].bottom_m", "-0.2"),
    ("objects-intersect",
     _add_object({"kind": "sphere", "name": "ball-2", "center_m": [5.05, 1.0, 0.5], "radius_m": 0.05}),
     "objects[4].center_m", "5.05"),
    ("object-inside-object",
     _add_object({"kind": "cylinder", "name": "big", "center_m": [5.0, 1.0, 0.5], "axis": [0, 0, 1],
                  "radius_m": 0.2, "length_m": 0.6}),
     "objects[4].center_m", "5.0"),
    ("post-crosses-edge", _set("objects.0.center_m", [2.55, 1.5]), "objects[3]", "2.5"),
    ("post-upside-down", _set("objects.0.top_m", -0.5), "objects[0].top_m", "-0.5"),
    ("plate-up-along-normal",
     _add_object({"kind": "plate", "name": "lid", "center_m": [7.0, 1.5, 0.5], "normal": [0, 0, 1],
                  "width_m": 0.5, "height_m": 0.5, "thickness_m": 0.02}),
     "objects[4].up", "(0.0, 0.0, 1.0)"),
    ("zero-axis",
     _add_object({"kind": "cylinder", "name": "c", "center_m": [7.0, 1.5, 0.5], "axis": [0, 0, 0],
                  "radius_m": 0.1, "length_m": 0.2}),
     "objects[4].axis", "[0, 0, 0]"),
    ("duplicate-name", _set("objects.1.name", "post-1"), "objects[1].name", "'post-1'"),
    ("reserved-name", _set("objects.1.name", "floor"), "objects[1].name", "'floor'"),
    ("sonar-above-water", _set("sonar.position_m", [1.0, 1.5, 1.5]), "sonar.position_m", "1.5"),
    ("side-transducer-in-wall", _set("sonar.position_m", [1.0, 2.95, 0.5]), "sonar.position_m", "2.95"),
    ("sonar-inside-object", _set("sonar.position_m", [5.0, 1.0, 0.5]), "sonar.position_m", "5.0"),
    ("sonar-touching-object", _set("sonar.position_m", [5.0, 1.12, 0.5]),  # right transducer 5 mm off the ball
     "sonar.position_m", "1.12"),
    ("missing-mesh-file", _set("objects.2.path", "nowhere.stl"), "objects[2].path", "'nowhere.stl'"),
    ("garbage-mesh-file", _bad_mesh("this is not a mesh"), "objects[2].path", "bowl.stl"),
    ("truncated-mesh-file", lambda d, directory: (
        (directory / "cut.stl").write_bytes((DATA / "rock.stl").read_bytes()[:1000]),
        d["objects"][2].update(path="cut.stl")), "objects[2].path", "cut.stl"),
    ("open-mesh", _bad_mesh("open"), "objects[2].path", "bowl.stl"),
    ("unreadable-mesh-file", _unreadable_mesh, "objects[2].path", "'secret.stl'"),
    ("free-field-post-without-top", lambda d, _: (d.pop("tank"), d.update(free_field=True)),
     "objects[0].bottom_m", "missing"),
    ("missing-tank", lambda d, _: d.pop("tank"), "tank", "missing"),
    ("bad-channel-rows", _set("sonar.channel_positions_m", [[0, 0, 0]]), "sonar.channel_positions_m", "[[0, 0, 0]]"),
    # numbers at the edges of floating point, and values no simulation can use
    ("sphere-radius-1e300", _set("objects.1.radius_m", 1e300), "objects[1].radius_m", "1e+300"),
    ("sphere-radius-1e-300", _set("objects.1.radius_m", 1e-300), "objects[1].radius_m", "1e-300"),
    ("post-radius-1e300", _set("objects.0.radius_m", 1e300), "objects[0].radius_m", "1e+300"),
    ("post-radius-1e308", _set("objects.0.radius_m", 1e308), "objects[0].radius_m", "1e+308"),
    ("radius-400-digits", _set("objects.1.radius_m", 10**400), "objects[1].radius_m", "too large"),
    ("pulse-1e300", _set("sonar.pulse_duration_s", 1e300), "sonar.pulse_duration_s", "1e+300"),
    ("pulse-1e-300", _set("sonar.pulse_duration_s", 1e-300), "sonar.pulse_duration_s", "1e-300"),
    ("ph-1e300", _set("medium.ph", 1e300), "medium.ph", "1e+300"),
    ("depth-1e300", _set("medium.depth_m", 1e300), "medium.depth_m", "1e+300"),
    ("centre-frequency-1e300", _set("sonar.centre_frequency_hz", 1e300), "sonar.centre_frequency_hz", "1e+300"),
    ("centre-frequency-above-nyquist", _set("sonar.centre_frequency_hz", 15e6), "sonar.centre_frequency_hz",
     "1.5e+07"),
    ("source-level-1e300", _set("sonar.source_level_pa", 1e300), "sonar.source_level_pa", "1e+300"),
    ("sample-rate-1e12", _set("sonar.sample_rate_hz", 1e12), "sonar.sample_rate_hz", "1000000000000.0"),
    ("record-1e6", _set("sonar.record_length_s", 1e6), "sonar.record_length_s", "1000000.0"),
    ("record-1e-12", _set("sonar.record_length_s", 1e-12), "sonar.record_length_s", "1e-12"),
    ("tank-1e300", _set("tank.length_m", 1e300), "tank.length_m", "1e+300"),
    ("yaw-1e300", _set("sonar.yaw_deg", 1e300), "sonar.yaw_deg", "1e+300"),
    ("edge-angle-1e-10", _set("objects.3.interior_angle_deg", 1e-10), "objects[3].interior_angle_deg", "1e-10"),
    ("coincident-channels", _set("sonar.channel_positions_m", [[0, 0, 0], [0, 0, 0], [0.065, 0, 0]]),
     "sonar.channel_positions_m", "coincides with the centre"),
    ("separation-1e-300", _set("sonar.separation_m", 1e-300), "sonar.separation_m", "1e-300"),
    ("name-1000-chars", _set("objects.0.name", "n" * 1000), "objects[0].name", "at most 200"),
    ("mesh-nan-vertices", lambda d, directory: (
        (directory / "nan.stl").write_text(_NAN_STL), d["objects"][2].update(path="nan.stl")),
     "objects[2].path", "non-finite"),
    ("mesh-dev-zero", _set("objects.2.path", "/dev/zero"), "objects[2].path", "character device"),
    ("mesh-directory", _set("objects.2.path", "."), "objects[2].path", "directory"),
    ("mesh-300-char-name", _set("objects.2.path", "m" * 300 + ".stl"), "objects[2].path", "File name too long"),
    ("mesh-5000-char-path", _set("objects.2.path", "m" * 5000 + ".stl"), "objects[2].path", "File name too long"),
    ("mesh-not-a-mesh-format", lambda d, directory: (
        (directory / "notes.txt").write_text("not a mesh"), d["objects"][2].update(path="notes.txt")),
     "objects[2].path", "unknown mesh format"),
]


_NAN_STL = """solid t
facet normal 0 0 0
outer loop
vertex nan 0 0
vertex 0.1 0 0
vertex 0 0.1 0
endloop
endfacet
endsolid t
"""


def _write(tmp_path: Path, mutate) -> Path:
    shutil.copy(DATA / "rock.stl", tmp_path / "rock.stl")
    data = copy.deepcopy(BASE)
    mutate(data, tmp_path)
    path = tmp_path / "scene.toml"
    path.write_text(tomli_w.dumps(data))
    return path


def test_base_scene_is_valid(tmp_path):
    assert len(load_scene(_write(tmp_path, lambda d, _: None)).objects) == 4


@pytest.mark.parametrize("case", CASES, ids=[c[0] for c in CASES])
def test_bad_input_message_and_exit_code(tmp_path, capsys, case):
    name, mutate, key, value = case
    path = _write(tmp_path, mutate)
    if name == "unreadable-mesh-file" and _can_read_anyway(path):
        pytest.skip("running as a user who can read mode-000 files (root)")
    with pytest.raises(SceneFileError) as info:
        load_scene(path)
    message = str(info.value)
    assert isinstance(info.value, InputError)
    assert "\n" not in message
    assert message.startswith(str(path))
    assert key in message, message
    assert value in message, message
    # The command line: one line on stderr, nothing on stdout, exit 2, no traceback.
    capsys.readouterr()
    assert main(["scene", "validate", str(path)]) == 2
    out, err = capsys.readouterr()
    assert out == ""
    assert err.count("\n") == 1 and "Traceback" not in err and key in err


def _can_read_anyway(path: Path) -> bool:
    try:
        (path.parent / "secret.stl").read_bytes()
        return True
    except PermissionError:
        return False


def test_invalid_toml_syntax(tmp_path, capsys):
    path = tmp_path / "broken.toml"
    path.write_text("[tank\nlength_m = 9\n")
    with pytest.raises(SceneFileError, match=r"broken\.toml: not valid TOML.*line 1"):
        load_scene(path)
    assert main(["scene", "show", str(path), "--json"]) == 2
    out, err = capsys.readouterr()
    assert out == "" and err.count("\n") == 1


def test_not_a_file_nor_a_builtin(tmp_path, capsys):
    with pytest.raises(SceneFileError, match="no such scene file or built-in scene"):
        load_scene(tmp_path / "absent.toml")
    with pytest.raises(SceneFileError, match="is a directory"):
        load_scene(tmp_path)
    assert main(["scene", "show", "thesis-pool"]) == 2


def test_not_utf8(tmp_path):
    path = tmp_path / "latin.toml"
    path.write_bytes(b'name = "caf\xe9"\n')
    with pytest.raises(SceneFileError, match="cannot read"):
        load_scene(path)


def test_unreadable_mesh_branch(tmp_path, monkeypatch):
    # As root a mode-000 file stays readable, so make the open itself fail as it would for a user.
    import scenes.file_access as file_access

    path = _write(tmp_path, lambda d, _: None)
    real_open = file_access.os.open

    def refuse(name, *args, **kwargs):
        if str(name).endswith("rock.stl"):
            raise PermissionError(13, "Permission denied")
        return real_open(name, *args, **kwargs)

    monkeypatch.setattr(file_access.os, "open", refuse)
    with pytest.raises(SceneFileError, match=r"objects\[2\]\.path = 'rock.stl'.*cannot open \(Permission denied\)"):
        load_scene(path)


def test_centre_frequency_blames_itself_not_the_sample_rate(tmp_path):
    for value in (1e300, 15e6):
        path = _write(tmp_path, _set("sonar.centre_frequency_hz", value))
        with pytest.raises(SceneFileError) as info:
            load_scene(path)
        assert str(info.value).split(": ")[1].startswith("sonar.centre_frequency_hz"), str(info.value)


def test_scene_files_that_are_not_regular_files(tmp_path, capsys):
    for target, needle in ((tmp_path, "is a directory"), (Path("/dev/null"), "is a character device"),
                           (tmp_path / ("b" * 300 + ".toml"), "File name too long"),
                           (tmp_path / ("c" * 5000), "File name too long")):
        with pytest.raises(SceneFileError, match=needle):
            load_scene(target)
        assert main(["scene", "validate", str(target)]) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and needle in err and len(err) < 600  # long paths are shortened
    (tmp_path / "loop_a.toml").symlink_to(tmp_path / "loop_b.toml")
    (tmp_path / "loop_b.toml").symlink_to(tmp_path / "loop_a.toml")
    with pytest.raises(SceneFileError, match="Too many levels of symbolic links"):
        load_scene(tmp_path / "loop_a.toml")


@pytest.mark.parametrize("text, needle", [
    ("x = " + "[" * 10_000 + "]" * 10_000, "nested too deeply"),
    ("x = " + "{a = " * 3_000 + "1" + "}" * 3_000, "nested too deeply"),
    ("a" + ".a" * 5_000 + " = 1", "nested more than 16 levels"),
    ("[tank]\nlength_m = " + "9" * 5_000, "not valid TOML: Exceeds the limit"),
])
def test_toml_nesting_and_number_length_are_bounded(tmp_path, text, needle):
    path = tmp_path / "deep.toml"
    path.write_text(text)
    with pytest.raises(SceneFileError, match=needle):
        load_scene(path)


def test_scene_file_size_is_bounded(tmp_path, monkeypatch):
    import scenes.scene_file as scene_file

    path = _write(tmp_path, lambda d, _: None)
    monkeypatch.setattr(scene_file, "MAX_SCENE_FILE_BYTES", 100)
    with pytest.raises(SceneFileError, match=r"bytes, more than the 100 accepted"):
        load_scene(path)


def test_too_many_objects_are_refused_before_they_are_built(tmp_path):
    from acoustisim.resources import ResourceLimits, resource_limits

    path = _write(tmp_path, lambda d, _: d.update(objects=d["objects"][:1] * 50))
    with resource_limits(ResourceLimits(max_objects=10)), pytest.raises(SceneFileError, match="50 objects"):
        load_scene(path)
    big = _write(tmp_path, lambda d, _: d["objects"][1].update(radius_m=0.4))  # 81,920-triangle icosphere
    with resource_limits(ResourceLimits(max_triangles=1000)), pytest.raises(SceneFileError, match="triangles"):
        load_scene(big)


def test_sample_rate_too_low_for_the_pulse_and_the_receiver(tmp_path, capsys):
    """`scene validate` refuses what `simulate` cannot synthesise (the default chain's 2 MHz
    band-pass corner needs more than 4 MS/s), naming the key and the value."""
    scene = tmp_path / "slow.toml"
    scene.write_text(
        'free_field = true\n[medium]\nwater = "fresh"\ntemperature_c = 20.0\n'
        '[sonar]\nposition_m = [0.0, 0.0, 0.0]\nsample_rate_hz = 1.2e6\n'
    )
    assert main(["scene", "validate", str(scene)]) == 2
    err = capsys.readouterr().err
    assert "sonar.sample_rate_hz = 1.2e+06" in err and err.count("\n") == 1
