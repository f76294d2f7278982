"""A hostile-input corpus for the command lines: run a few hundred bad inputs, classify each run.

Usage
-----
    python benchmarks/hostile_corpus.py [--tree DIR] [--jobs 2] [--timeout 60] [--memory-gb 8]
                                        [--kinds toml,files,...] [--show BAD] [--json OUT.json]
                                        [--fuzz N [--seed S]]

Each case is one command (``acoustisim ...`` or ``binsonar ...``) run in a subprocess whose
``PYTHONPATH`` is ``--tree`` (default: this checkout; pass ``/work/wt/baseline`` for the code
before), in a scratch folder holding the fixtures (scene files, meshes, a FIFO, long names),
with a wall-clock timeout and an address-space limit (``RLIMIT_AS``). Inputs are hand-written
by kind:

- ``toml``: broken or pathological TOML (nesting 10,000 deep, 5,000-digit integers, NUL bytes,
  invalid UTF-8, dotted keys 5,000 deep);
- ``schema``: unknown and missing keys, wrong types and tables where values belong;
- ``float-edges``: every numeric key of the scene file at 1e300, -1e300, 1e-300, 5e-324, 0,
  nan, +-inf, 1e308 and a 400-digit integer;
- ``geometry``: objects outside the tank, crossing each other, coincident transducers, 2,000
  objects, the sonar inside an object;
- ``files``: the scene file or a mesh as a FIFO, ``/dev/zero``, a directory, a symlink loop,
  a 5,000-character path, a 300-character name, ``/etc/passwd``, a mesh with NaN vertices;
- ``resources``: a 1 TS/s digitiser, a 10^6 s record, 10^9 pings, long records and many pings;
- ``arguments``: option values (empty, negative, nan, inf, 1e300, huge integers) and argparse
  errors for ``scene``, ``simulate``, ``demo``, ``dataset`` and ``binsonar``;
- ``spec``: dataset specifications at the same edges;
- ``valid``: inputs that must succeed (exit 0), so the corpus also catches over-refusal;
- with ``--fuzz N``: ``fuzz-scenes``, N seeded mutations of the conventions example and a
  free-field scene (float edges, wrong types, deleted and added keys, 40-deep nesting, scaled
  numbers, duplicated objects) through ``scene validate``, and ``fuzz-arguments``, N seeded
  ``simulate`` argument lists; these run in-process, 50 to a child process, each under a
  ``SIGALRM`` timeout (a child stuck in C past it is killed and its case counts as a timeout).

Each run is classified as ``clean-2`` (exit 2, one line on stderr, no usage block), ``ok-0``
(exit 0 on an input that may succeed), ``accepted`` (exit 0 on an input that must be
refused), ``refused`` (exit 2 on a valid input), ``traceback``, ``timeout`` (hang, or past the
time limit, or killed), ``multi-line`` (an error spread over several lines), ``usage`` (an
argparse usage block) or ``other-exit``. The table gives the counts per kind.
"""

from __future__ import annotations

import argparse
import concurrent.futures
import json
import os
import resource
import shutil
import signal
import struct
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]

ACOUSTISIM = "import sys; from acoustisim.cli.main import main; sys.exit(main())"
BINSONAR = "import sys; from binsonar.cli.main import main; sys.exit(main())"

CLASSES = ("clean-2", "ok-0", "accepted", "refused", "traceback", "timeout", "multi-line", "usage", "other-exit")

BASE_SCENE: dict[str, Any] = {
    "medium": {"water": "fresh", "temperature_c": 20.0, "salinity_ppt": 0.0},
    "tank": {"length_m": 9.0, "width_m": 3.0, "water_depth_m": 1.0, "wall_material": "concrete",
             "floor_material": "concrete"},
    "sonar": {"position_m": [1.0, 1.5, 0.5], "yaw_deg": 0.0, "separation_m": 0.065, "transducer_diameter_m": 0.019,
              "centre_frequency_hz": 500e3, "pulse_duration_s": 5e-6, "sample_rate_hz": 20e6, "adc_bits": 12,
              "record_length_s": 0.0125},
    "objects": [
        {"kind": "post", "name": "post-1", "center_m": [3.0, 1.2], "radius_m": 0.025, "material": "pvc"},
        {"kind": "edge", "name": "edge-1", "edge_m": [2.5, 1.5], "interior_angle_deg": 60, "facing_deg": 180,
         "size_m": 0.10, "material": "steel"},
        {"kind": "cylinder", "name": "pipe-1", "center_m": [4.0, 2.0, 0.5], "axis": [0.0, 0.0, 1.0], "radius_m": 0.3,
         "length_m": 0.6, "material": "pvc"},
        {"kind": "sphere", "name": "ball-1", "center_m": [5.0, 1.0, 0.5], "radius_m": 0.05, "material": "steel"},
        {"kind": "mesh", "name": "rock", "path": "rock.stl", "position_m": [6.0, 1.5, 0.2], "yaw_deg": 30.0,
         "material": "concrete"},
    ],
}
"""The scene file of conventions.md, as data."""

SHORT_RECORD_S = 1.0e-3
"""Record length of the scenes that ``simulate`` runs (keeps each run to seconds)."""

BASE_SPEC = """
[dataset]
n_samples = 2
seed = 1
n_pings = 1
[sonar]
record_length_s = 0.001
[solver]
max_order = 1
mechanisms = ["direct", "specular"]
[[objects]]
kind = "sphere"
count = 1
radius_m = 0.05
"""


@dataclass(frozen=True)
class Case:
    """One command of the corpus.

    ``expect``: "error" (must be refused: exit 2), "ok" (must succeed: exit 0) or "any"
    (a legal extreme: either is fine, as long as it is clean).
    """

    kind: str
    label: str
    argv: tuple[str, ...]
    expect: str = "error"
    program: str = "acoustisim"


@dataclass
class Outcome:
    case: Case
    code: int | None
    seconds: float
    stderr: str = field(repr=False)
    verdict: str = ""


# ----------------------------------------------------------------------------- fixtures
def _set(data: Any, path: str, value: Any) -> None:
    keys = path.split(".")
    node = data
    for key in keys[:-1]:
        node = node[int(key)] if isinstance(node, list) else node[key]
    last = keys[-1]
    if isinstance(node, list):
        node[int(last)] = value
    else:
        node[last] = value


def _delete(data: Any, path: str) -> None:
    keys = path.split(".")
    node = data
    for key in keys[:-1]:
        node = node[int(key)] if isinstance(node, list) else node[key]
    del node[keys[-1]]


def _scene(mutations: dict[str, Any] | None = None, deletions: tuple[str, ...] = (), *,
           record_length: float | None = None) -> dict[str, Any]:
    data = json.loads(json.dumps(BASE_SCENE))
    if record_length is not None:
        data["sonar"]["record_length_s"] = record_length
    for path, value in (mutations or {}).items():
        _set(data, path, value)
    for path in deletions:
        _delete(data, path)
    return data


def _toml_value(value: Any) -> str:
    """A TOML literal, including the ones tomli_w refuses to write (nan, inf, huge integers)."""
    if isinstance(value, float):
        if value != value:
            return "nan"
        if value in (float("inf"), float("-inf")):
            return "inf" if value > 0 else "-inf"
        return repr(value)
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, str):
        return json.dumps(value)
    if isinstance(value, list):
        return "[" + ", ".join(_toml_value(v) for v in value) + "]"
    if isinstance(value, dict):
        return "{" + ", ".join(f"{json.dumps(k)} = {_toml_value(v)}" for k, v in value.items()) + "}"
    raise TypeError(type(value))


def _toml(data: dict[str, Any]) -> str:
    """Scene data as TOML text (hand-written so that nan, inf and 400-digit integers survive)."""
    lines = []
    for key, value in data.items():
        if not isinstance(value, (dict, list)) or (isinstance(value, list) and not all(isinstance(v, dict) for v in value)):
            lines.append(f"{json.dumps(key)} = {_toml_value(value)}")
    for key, value in data.items():
        if isinstance(value, dict):
            lines.append(f"[{json.dumps(key)}]")
            lines.extend(f"{json.dumps(k)} = {_toml_value(v)}" for k, v in value.items())
        elif isinstance(value, list) and value and all(isinstance(v, dict) for v in value):
            for item in value:
                lines.append(f"[[{json.dumps(key)}]]")
                lines.extend(f"{json.dumps(k)} = {_toml_value(v)}" for k, v in item.items())
    return "\n".join(lines) + "\n"


def _ascii_stl(triangles: list[tuple[tuple[float, float, float], ...]]) -> str:
    out = ["solid t"]
    for tri in triangles:
        out.append("facet normal 0 0 0\nouter loop")
        out.extend(f"vertex {x!r} {y!r} {z!r}" for x, y, z in tri)
        out.append("endloop\nendfacet")
    out.append("endsolid t")
    return "\n".join(out).replace("nan", "nan") + "\n"


def _tetra(scale: float = 0.1) -> list[tuple[tuple[float, float, float], ...]]:
    a, b, c, d = (0.0, 0.0, 0.0), (scale, 0.0, 0.0), (0.0, scale, 0.0), (0.0, 0.0, scale)
    return [(a, c, b), (a, b, d), (a, d, c), (b, c, d)]


def make_fixtures(folder: Path, tree: Path) -> None:
    """Write every file the cases name into ``folder`` (the runs' working directory)."""
    rock = tree / "scenes" / "data" / "rock.stl"
    shutil.copy(rock, folder / "rock.stl")
    (folder / "out").mkdir()
    (folder / "a_folder").mkdir()
    os.mkfifo(folder / "fifo.toml")
    os.mkfifo(folder / "fifo.stl")
    os.mkfifo(folder / "fifo_spec.toml")
    os.symlink("loop_b.toml", folder / "loop_a.toml")
    os.symlink("loop_a.toml", folder / "loop_b.toml")
    os.symlink("loop_b.stl", folder / "loop_a.stl")
    os.symlink("loop_a.stl", folder / "loop_b.stl")
    (folder / "nan.stl").write_text(_ascii_stl([((float("nan"), 0.0, 0.0), (0.1, 0.0, 0.0), (0.0, 0.1, 0.0))]
                                               + _tetra()[1:]))
    (folder / "inf.stl").write_text(_ascii_stl([((float("inf"), 0.0, 0.0), (0.1, 0.0, 0.0), (0.0, 0.1, 0.0))]
                                               + _tetra()[1:]))
    (folder / "huge.stl").write_text(_ascii_stl(_tetra(1e300)))
    (folder / "tiny.stl").write_text(_ascii_stl(_tetra(1e-300)))
    (folder / "garbage.stl").write_bytes(b"\x00\xff" * 5000)
    (folder / "empty.stl").write_bytes(b"")
    (folder / "lying.stl").write_bytes(b"\0" * 80 + struct.pack("<I", 1_000_000_000) + b"\0" * 100)
    (folder / "flat.stl").write_text(_ascii_stl([((0.0, 0.0, 0.0), (0.1, 0.0, 0.0), (0.0, 0.1, 0.0))]))
    (folder / "spec.toml").write_text(BASE_SPEC)
    (folder / "base.toml").write_text(_toml(_scene()))


# ----------------------------------------------------------------------------- cases
FLOAT_EDGES: tuple[tuple[str, Any], ...] = (
    ("1e300", 1e300), ("-1e300", -1e300), ("1e-300", 1e-300), ("5e-324", 5e-324), ("0", 0.0), ("nan", float("nan")),
    ("inf", float("inf")), ("-inf", float("-inf")), ("1e308", 1e308), ("int400", 10**400),
)

# key -> values (by label) that are legal physics (the rest must be refused)
NUMERIC_KEYS: dict[str, tuple[str, ...]] = {
    "medium.temperature_c": ("1e-300", "5e-324", "0"),
    "medium.salinity_ppt": ("1e-300", "5e-324", "0"),
    "medium.depth_m": ("1e-300", "5e-324", "0"),
    "medium.ph": ("1e-300", "5e-324", "0"),
    "medium.sound_speed_m_s": (),
    "tank.length_m": (),
    "tank.width_m": (),
    "tank.water_depth_m": (),
    "sonar.yaw_deg": ("1e-300", "5e-324", "0"),
    "sonar.separation_m": (),
    "sonar.transducer_diameter_m": (),
    "sonar.centre_frequency_hz": (),
    "sonar.pulse_duration_s": (),
    "sonar.source_level_pa": (),
    "sonar.sample_rate_hz": (),
    "sonar.record_length_s": (),
    "sonar.adc_bits": (),
    "objects.0.radius_m": (),
    "objects.0.center_m.0": (),
    "objects.1.size_m": (),
    "objects.1.interior_angle_deg": (),
    "objects.1.facing_deg": ("1e-300", "5e-324", "0"),
    "objects.2.radius_m": (),
    "objects.2.length_m": (),
    "objects.3.radius_m": (),
    "objects.3.center_m.2": (),
    "objects.4.scale": (),
    "objects.4.yaw_deg": ("1e-300", "5e-324", "0"),
}


def _validate(path: str) -> tuple[str, ...]:
    return ("scene", "validate", path)


def _simulate(path: str, out: str, *extra: str) -> tuple[str, ...]:
    return ("simulate", path, "-o", f"out/{out}.h5", *extra)


def build_cases() -> tuple[list[Case], dict[str, str]]:
    """The cases, and the scene-file texts they need (file name -> text)."""
    files: dict[str, str] = {}
    cases: list[Case] = []

    def scene_file(name: str, text: str) -> str:
        files[name] = text
        return name

    # --- toml
    toml_texts = {
        "unclosed-table": "[tank\nlength_m = 9\n",
        "duplicate-key": "[tank]\nlength_m = 9\nlength_m = 8\n",
        "bad-escape": 'name = "\\q"\n',
        "nested-arrays-10000": "x = " + "[" * 10000 + "]" * 10000 + "\n",
        "unclosed-arrays-10000": "x = " + "[" * 10000 + "\n",
        "inline-tables-3000": "x = " + "{a = " * 3000 + "1" + "}" * 3000 + "\n",
        "dotted-key-5000": "a" + ".a" * 5000 + " = 1\n",
        "table-header-5000": "[" + ".".join(["t"] * 5000) + "]\n",
        "int-5000-digits": "[tank]\nlength_m = " + "9" * 5000 + "\n",
        "string-4mb": 'name = "' + "x" * 4_000_000 + '"\n',
        "nul-byte": "name = \"a\0b\"\n",
        "only-comments": "# nothing here\n",
        "empty": "",
        "bom": "\ufeff[tank]\nlength_m = 9.0\n",
        "array-of-tables-as-value": "objects = 3\n[tank]\nlength_m = 9.0\nwidth_m = 3.0\nwater_depth_m = 1.0\n",
        "huge-array": "x = [" + ", ".join(["1"] * 200000) + "]\n",
        "objects-200000": "[tank]\nlength_m = 9.0\nwidth_m = 3.0\nwater_depth_m = 1.0\n"
                          + '[[objects]]\nkind = "edge"\n' * 200000,
    }
    for label, text in toml_texts.items():
        cases.append(Case("toml", label, _validate(scene_file(f"toml_{label}.toml", text))))
    files["toml_latin1.toml"] = "name = \"caf\xe9\"\n"  # written as Latin-1 below
    cases.append(Case("toml", "latin1", _validate("toml_latin1.toml")))

    # --- schema
    schema: list[tuple[str, dict[str, Any], tuple[str, ...]]] = [
        ("unknown-top", {"colour": "red"}, ()),
        ("unknown-medium", {"medium.temprature_c": 20.0}, ()),
        ("unknown-object-key", {"objects.0.radius": 0.1}, ()),
        ("unknown-kind", {"objects.1.kind": "cone"}, ()),
        ("kind-number", {"objects.1.kind": 3}, ()),
        ("missing-kind", {}, ("objects.1.kind",)),
        ("missing-radius", {}, ("objects.0.radius_m",)),
        ("missing-tank", {}, ("tank",)),
        ("missing-tank-length", {}, ("tank.length_m",)),
        ("medium-is-number", {"medium": 3}, ()),
        ("sonar-is-list", {"sonar": [1, 2]}, ()),
        ("objects-is-table", {"objects": {"kind": "post"}}, ()),
        ("object-is-number", {"objects.0": 5}, ()),
        ("radius-string", {"objects.0.radius_m": "big"}, ()),
        ("radius-bool", {"objects.0.radius_m": True}, ()),
        ("radius-list", {"objects.0.radius_m": [0.1]}, ()),
        ("radius-table", {"objects.0.radius_m": {"a": 1}}, ()),
        ("center-short", {"objects.0.center_m": [3.0]}, ()),
        ("center-strings", {"objects.0.center_m": ["a", "b"]}, ()),
        ("center-nested", {"objects.0.center_m": [[3.0], [1.0]]}, ()),
        ("adc-float", {"sonar.adc_bits": 12.5}, ()),
        ("adc-zero", {"sonar.adc_bits": 0}, ()),
        ("adc-huge", {"sonar.adc_bits": 10**30}, ()),
        ("water-lake", {"medium.water": "lake"}, ()),
        ("water-number", {"medium.water": 1}, ()),
        ("material-unknown", {"objects.0.material": "wood"}, ()),
        ("material-number", {"objects.0.material": 7}, ()),
        ("wall-material-unknown", {"tank.wall_material": "cheese"}, ()),
        ("name-empty", {"objects.0.name": ""}, ()),
        ("name-10000", {"objects.0.name": "n" * 10000}, ()),
        ("name-number", {"objects.0.name": 5}, ()),
        ("name-duplicate", {"objects.1.name": "post-1"}, ()),
        ("name-reserved", {"objects.1.name": "floor"}, ()),
        ("free-field-and-tank", {"free_field": True}, ()),
        ("free-field-string", {"free_field": "yes"}, ()),
        ("channel-rows-short", {"sonar.channel_positions_m": [[0, 0, 0]]}, ()),
        ("channel-rows-strings", {"sonar.channel_positions_m": ["a", "b", "c"]}, ()),
        ("formula-unknown", {"medium.formula": "guess"}, ()),
        ("axis-zero", {"objects.2.axis": [0, 0, 0]}, ()),
        ("mesh-path-number", {"objects.4.path": 5}, ()),
        ("mesh-path-empty", {"objects.4.path": ""}, ()),
    ]
    for label, mutations, deletions in schema:
        cases.append(Case("schema", label, _validate(scene_file(f"schema_{label}.toml",
                                                               _toml(_scene(mutations, deletions))))))

    # --- float edges
    for key, legal in NUMERIC_KEYS.items():
        for label, value in FLOAT_EDGES:
            path = scene_file(f"edge_{key.replace('.', '_')}_{label}.toml", _toml(_scene({key: value})))
            cases.append(Case("float-edges", f"{key}={label}", _validate(path), "any" if label in legal else "error"))

    # --- geometry
    def posts(n: int) -> list[dict[str, Any]]:
        return [{"kind": "post", "name": f"p{i}", "center_m": [2.0 + 0.06 * (i // 40), 0.3 + 0.06 * (i % 40)],
                 "radius_m": 0.01} for i in range(n)]

    geometry = [
        ("object-outside-tank", _toml(_scene({"objects.3.center_m": [12.0, 1.0, 0.5]})), "error", "validate"),
        ("object-in-wall", _toml(_scene({"objects.0.center_m": [3.0, 0.01]})), "error", "validate"),
        ("objects-cross", _toml(_scene({"objects.3.center_m": [4.0, 2.0, 0.5]})), "error", "validate"),
        ("sonar-in-object", _toml(_scene({"sonar.position_m": [5.0, 1.0, 0.5]})), "error", "validate"),
        ("sonar-above-water", _toml(_scene({"sonar.position_m": [1.0, 1.5, 1.5]})), "error", "validate"),
        ("coincident-channels", _toml(_scene({"sonar.channel_positions_m": [[0, 0, 0], [0, 0, 0], [0.065, 0, 0]]})),
         "error", "validate"),
        ("left-on-right", _toml(_scene({"sonar.channel_positions_m": [[0.1, 0, 0], [0, 0, 0], [0.1, 0, 0]]})),
         "error", "validate"),
        ("overlapping-pistons", _toml(_scene({"sonar.transducer_diameter_m": 0.2})), "error", "validate"),
        ("tank-1e300", _toml(_scene({"tank.length_m": 1e300})), "error", "validate"),
        ("tank-1e6", _toml(_scene({"tank.length_m": 1e6})), "error", "validate"),
        ("sea-tank-10km", _toml(_scene({"tank.length_m": 1e4, "tank.width_m": 1e4, "tank.water_depth_m": 100.0,
                                        "medium.water": "sea", "medium.salinity_ppt": 35.0})), "any", "validate"),
        ("free-field-far-sphere", _toml({"free_field": True, "sonar": {"position_m": [0, 0, 0]},
                                         "objects": [{"kind": "sphere", "center_m": [5000.0, 0, 0], "radius_m": 2.0}]}),
         "any", "validate"),
        ("2000-posts-validate", _toml(_scene({"objects": posts(2000)})), "any", "validate"),
        ("2000-posts-simulate", _toml(_scene({"objects": posts(2000)}, record_length=SHORT_RECORD_S)), "any",
         "simulate"),
        ("mesh-nan", _toml(_scene({"objects.4.path": "nan.stl"})), "error", "validate"),
        ("mesh-inf", _toml(_scene({"objects.4.path": "inf.stl"})), "error", "validate"),
        ("mesh-1e300", _toml(_scene({"objects.4.path": "huge.stl"})), "error", "validate"),
        ("mesh-1e-300", _toml(_scene({"objects.4.path": "tiny.stl"})), "error", "validate"),
        ("mesh-flat", _toml(_scene({"objects.4.path": "flat.stl"})), "error", "validate"),
        ("mesh-scale-1e300", _toml(_scene({"objects.4.scale": 1e300})), "error", "validate"),
        ("edge-angle-1e-10", _toml(_scene({"objects.1.interior_angle_deg": 1e-10})), "error", "validate"),
        ("edge-angle-179.9999999", _toml(_scene({"objects.1.interior_angle_deg": 179.9999999})), "any", "validate"),
        ("plate-up-along-normal", _toml(_scene({"objects.3": {"kind": "plate", "center_m": [7.0, 1.5, 0.5],
                                                              "normal": [0, 0, 1], "width_m": 0.5, "height_m": 0.5,
                                                              "thickness_m": 0.02}})), "error", "validate"),
    ]
    for label, text, expect, verb in geometry:
        path = scene_file(f"geo_{label}.toml", text)
        argv = _validate(path) if verb == "validate" else _simulate(path, f"geo_{label}")
        cases.append(Case("geometry", label, argv, expect))

    # --- files
    long_name = "b" * 300 + ".toml"
    long_path = "/".join(["d" * 200] * 25) + "/scene.toml"
    for label, target in (("scene-fifo", "fifo.toml"), ("scene-dev-zero", "/dev/zero"), ("scene-dev-null", "/dev/null"),
                          ("scene-folder", "a_folder"), ("scene-missing", "missing.toml"),
                          ("scene-loop", "loop_a.toml"), ("scene-5000-chars", "a" * 5000 + ".toml"),
                          ("scene-300-char-name", long_name), ("scene-5000-char-path", long_path),
                          ("scene-etc-passwd", "/etc/passwd"), ("scene-proc-self", "/proc/self/environ"),
                          ("scene-empty-arg", "")):
        cases.append(Case("files", label, _validate(target)))
        if label in ("scene-fifo", "scene-dev-zero", "scene-5000-chars"):
            cases.append(Case("files", label + "-show", ("scene", "show", target, "--json")))
            cases.append(Case("files", label + "-simulate", _simulate(target, label)))
    for label, target in (("mesh-fifo", "fifo.stl"), ("mesh-dev-zero", "/dev/zero"), ("mesh-folder", "a_folder"),
                          ("mesh-loop", "loop_a.stl"), ("mesh-5000-chars", "m" * 5000 + ".stl"),
                          ("mesh-300-char-name", "m" * 300 + ".stl"), ("mesh-etc-passwd", "/etc/passwd"),
                          ("mesh-garbage", "garbage.stl"), ("mesh-empty", "empty.stl"),
                          ("mesh-lying-count", "lying.stl"), ("mesh-missing", "missing.stl"),
                          ("mesh-proc-self", "/proc/self/maps")):
        path = scene_file(f"files_{label}.toml", _toml(_scene({"objects.4.path": target})))
        cases.append(Case("files", label, _validate(path)))

    # --- resources
    resources = [
        ("sample-rate-1e12", {"sonar.sample_rate_hz": 1e12}, "validate", ()),
        ("sample-rate-1e12-simulate", {"sonar.sample_rate_hz": 1e12}, "simulate", ()),
        ("record-1e6", {"sonar.record_length_s": 1e6}, "validate", ()),
        ("record-1e6-simulate", {"sonar.record_length_s": 1e6}, "simulate", ()),
        ("record-1e-12-simulate", {"sonar.record_length_s": 1e-12}, "simulate", ()),
        ("record-1000-simulate", {"sonar.record_length_s": 1000.0}, "simulate", ()),
        ("source-level-1e300-simulate", {"sonar.source_level_pa": 1e300, "sonar.record_length_s": SHORT_RECORD_S},
         "simulate", ()),
        ("centre-frequency-1e300", {"sonar.centre_frequency_hz": 1e300}, "validate", ()),
        ("pulse-1e300", {"sonar.pulse_duration_s": 1e300}, "validate", ()),
        ("pulse-1e-300", {"sonar.pulse_duration_s": 1e-300}, "validate", ()),
    ]
    for label, mutations, verb, extra in resources:
        path = scene_file(f"res_{label}.toml", _toml(_scene(mutations)))
        cases.append(Case("resources", label, _validate(path) if verb == "validate" else _simulate(path, label, *extra)))
    short = scene_file("res_short.toml", _toml(_scene(record_length=SHORT_RECORD_S)))
    for label, extra in (("pings-1e9", ("--pings", "1000000000")), ("pings-1e6", ("--pings", "1000000")),
                         ("pings-1e20", ("--pings", "100000000000000000000")),
                         ("max-order-4-2000-posts", ("--max-order", "4"))):
        target = short if "posts" not in label else "geo_2000-posts-simulate.toml"
        cases.append(Case("resources", label, _simulate(target, label, *extra)))

    # --- arguments
    sim = ("simulate", short, "-o")
    arguments: list[tuple[str, tuple[str, ...], str, str]] = [
        ("no-verb", (), "error", "acoustisim"),
        ("bogus-flag", ("--bogus",), "error", "acoustisim"),
        ("bogus-verb", ("frobnicate",), "error", "acoustisim"),
        ("scene-no-action", ("scene",), "error", "acoustisim"),
        ("scene-bogus-action", ("scene", "bogus"), "error", "acoustisim"),
        ("validate-no-file", ("scene", "validate"), "error", "acoustisim"),
        ("validate-two-files", ("scene", "validate", "thesis-tank", "free-sphere"), "error", "acoustisim"),
        ("validate-unknown-name", ("scene", "validate", "thesis-pool"), "error", "acoustisim"),
        ("show-no-file", ("scene", "show", "--json"), "error", "acoustisim"),
        ("list-extra", ("scene", "list", "--bogus"), "error", "acoustisim"),
        ("simulate-no-output", ("simulate", short), "error", "acoustisim"),
        ("simulate-output-empty", (*sim, ""), "error", "acoustisim"),
        ("simulate-unknown-scene", ("simulate", "nowhere", "-o", "out/x.h5"), "error", "acoustisim"),
        ("simulate-backend", (*sim, "out/b.h5", "--backend", "gpu"), "error", "acoustisim"),
        ("simulate-snr-echo", (*sim, "out/e.h5", "--snr-db", "10", "--snr-echo", "nothing"), "error", "acoustisim"),
        ("simulate-keep-all-value", (*sim, "out/k.h5", "--keep-all-paths=yes"), "error", "acoustisim"),
        ("demo-record-negative", ("demo", "--record-length", "-1", "--out", "out/demo1"), "error", "acoustisim"),
        ("demo-record-zero", ("demo", "--record-length", "0", "--out", "out/demo2"), "error", "acoustisim"),
        ("demo-record-nan", ("demo", "--record-length", "nan", "--out", "out/demo3"), "error", "acoustisim"),
        ("demo-record-1e6", ("demo", "--record-length", "1e6", "--out", "out/demo4"), "error", "acoustisim"),
        ("demo-record-1e-12", ("demo", "--record-length", "1e-12", "--out", "out/demo5"), "error", "acoustisim"),
        ("demo-pings-0", ("demo", "--pings", "0", "--out", "out/demo6"), "error", "acoustisim"),
        ("demo-pings-1e9", ("demo", "--pings", "1000000000", "--out", "out/demo7"), "error", "acoustisim"),
        ("demo-seed-negative", ("demo", "--seed", "-1", "--out", "out/demo8"), "error", "acoustisim"),
        ("demo-method", ("demo", "--method", "magic", "--out", "out/demo9"), "error", "acoustisim"),
        ("demo-scene", ("demo", "--scene", "nowhere", "--out", "out/demo10"), "error", "acoustisim"),
        ("demo-out-empty", ("demo", "--out", "", "--pings", "1", "--record-length", "0.002"), "error", "acoustisim"),
        ("demo-backend", ("demo", "--backend", "gpu", "--out", "out/demo11"), "error", "acoustisim"),
        ("demo-snr-flag", ("demo", "--snr-db", "1e300"), "error", "acoustisim"),
        ("dataset-no-action", ("dataset",), "error", "acoustisim"),
        ("dataset-missing-spec", ("dataset", "generate", "missing.toml", "--out", "out/d1.zarr"), "error",
         "acoustisim"),
        ("dataset-spec-fifo", ("dataset", "generate", "fifo_spec.toml", "--out", "out/d2.zarr"), "error", "acoustisim"),
        ("dataset-spec-dev-zero", ("dataset", "generate", "/dev/zero", "--out", "out/d3.zarr"), "error", "acoustisim"),
        ("dataset-spec-folder", ("dataset", "generate", "a_folder", "--out", "out/d4.zarr"), "error", "acoustisim"),
        ("dataset-spec-5000", ("dataset", "generate", "s" * 5000, "--out", "out/d5.zarr"), "error", "acoustisim"),
        ("dataset-workers-negative", ("dataset", "generate", "spec.toml", "--out", "out/d6.zarr", "--workers", "-1"),
         "error", "acoustisim"),
        ("dataset-out-empty", ("dataset", "generate", "spec.toml", "--out", ""), "error", "acoustisim"),
        ("dataset-verify-missing", ("dataset", "verify", "missing.zarr"), "error", "acoustisim"),
        ("binsonar-no-verb", (), "error", "binsonar"),
        ("binsonar-bogus-flag", ("--bogus",), "error", "binsonar"),
        ("binsonar-detect-no-file", ("detect",), "error", "binsonar"),
        ("binsonar-detect-bogus-option", ("detect", "x.h5", "--frobnicate"), "error", "binsonar"),
        ("binsonar-localize-no-file", ("localize",), "error", "binsonar"),
        ("binsonar-detect-missing", ("detect", "missing.h5", "--json"), "error", "binsonar"),
    ]
    for option in ("--pings", "--seed", "--max-order", "--snr-db"):
        for label, value in (("empty", ""), ("negative", "-1"), ("zero", "0"), ("nan", "nan"), ("inf", "inf"),
                             ("1e300", "1e300"), ("1e309", "1e309"), ("text", "abc"), ("digits-5000", "9" * 5000),
                             ("huge", "99999999999999999999999")):
            legal = (option == "--seed" and label == "zero") or (option == "--snr-db" and label in ("negative", "zero"))
            arguments.append((f"simulate{option}={label}", (*sim, f"out/a{option}{label}.h5", option, value),
                              "any" if legal else "error", "acoustisim"))
    for label, argv, expect, program in arguments:
        cases.append(Case("arguments", label, argv, expect, program))

    # --- spec
    spec_edits = {
        "n-samples-1e12": BASE_SPEC.replace("n_samples = 2", "n_samples = 1000000000000"),
        "n-pings-1e9": BASE_SPEC.replace("n_pings = 1", "n_pings = 1000000000"),
        "record-1e6": BASE_SPEC.replace("record_length_s = 0.001", "record_length_s = 1e6"),
        "sample-rate-1e12": BASE_SPEC.replace("[sonar]", "[sonar]\nsample_rate_hz = 1e12"),
        "radius-1e300": BASE_SPEC.replace("radius_m = 0.05", "radius_m = 1e300"),
        "radius-int400": BASE_SPEC.replace("radius_m = 0.05", "radius_m = " + "9" * 400),
        "count-1e9": BASE_SPEC.replace("count = 1", "count = 1000000000"),
        "max-arrivals-1e12": BASE_SPEC.replace("n_pings = 1", "n_pings = 1\nmax_arrivals = 1000000000000"),
        "chunk-1e9": BASE_SPEC.replace("n_pings = 1", "n_pings = 1\nsamples_per_chunk = 1000000000"),
        "rays-1e12": BASE_SPEC.replace('mechanisms = ["direct", "specular"]', 'diffuse_rays = 1000000000000'),
        "nested-10000": "x = " + "[" * 10000 + "]" * 10000 + "\n",
        "not-toml": "[dataset\n",
        "tank-1e300": BASE_SPEC + "[tank]\nlength_m = 1e300\n",
        "seed-huge": BASE_SPEC.replace("seed = 1", "seed = 99999999999999999999999"),
    }
    for label, text in spec_edits.items():
        name = scene_file(f"spec_{label}.toml", text)
        cases.append(Case("spec", label, ("dataset", "generate", name, "--out", f"out/spec_{label}.zarr",
                                          "--workers", "0", "--no-progress")))

    # --- valid (must succeed)
    valid = [
        ("validate-builtin", ("scene", "validate", "thesis-tank")),
        ("validate-example", _validate("base.toml")),
        ("show-json", ("scene", "show", "base.toml", "--json")),
        ("list", ("scene", "list")),
        ("simulate-short", _simulate(short, "valid1")),
        ("simulate-snr", _simulate(scene_file("valid_snr.toml", _toml(_scene(record_length=5e-3))), "valid2",
                                   "--snr-db", "20", "--pings", "3")),
        ("simulate-sea", _simulate(scene_file("valid_sea.toml", _toml(_scene(
            {"medium.water": "sea", "medium.salinity_ppt": 35.0, "medium.temperature_c": 4.0},
            record_length=SHORT_RECORD_S))), "valid3")),
        ("demo-tiny", ("demo", "--pings", "1", "--record-length", "0.002", "--out", "out/demo-valid", "--json")),
        ("dataset-tiny", ("dataset", "generate", "spec.toml", "--out", "out/valid.zarr", "--workers", "0",
                          "--no-progress")),
        ("help", ("--help",)),
        ("simulate-help", ("simulate", "--help")),
    ]
    for label, argv in valid:
        cases.append(Case("valid", label, argv, "ok"))
    cases.append(Case("valid", "binsonar-help", ("--help",), "ok", "binsonar"))
    return cases, files


# ----------------------------------------------------------------------------- fuzz
FUZZ_EDGES: tuple[Any, ...] = (1e300, -1e300, 1e-300, -1e-300, 5e-324, 0.0, -0.0, float("nan"), float("inf"),
                               float("-inf"), 1e308, 10**400, -(10**30), 2**64, 0, 1, -1, 1e-12, 1e12, "", "x" * 300,
                               True, [], {}, [[1.0]], {"a": 1})
FUZZ_BASES: tuple[dict[str, Any], ...] = (
    BASE_SCENE,
    {"free_field": True, "sonar": {"position_m": [0.0, 0.0, 0.0], "record_length_s": 0.002},
     "objects": [{"kind": "sphere", "name": "ball", "center_m": [1.05, 0.0, 0.0], "radius_m": 0.05},
                 {"kind": "edge", "name": "edge", "edge_m": [2.0, 0.5], "interior_angle_deg": 60.0,
                  "facing_deg": 180.0, "size_m": 0.1, "bottom_m": -0.5, "top_m": 0.5}]},
)


def _fuzz_paths(node: Any, prefix: tuple = ()) -> list[tuple]:
    found = [prefix] if prefix else []
    if isinstance(node, dict):
        for key, child in node.items():
            found += _fuzz_paths(child, prefix + (key,))
    elif isinstance(node, list):
        for index, child in enumerate(node):
            found += _fuzz_paths(child, prefix + (index,))
    return found


def fuzz_scene_texts(count: int, seed: int) -> list[str]:
    """``count`` mutated scene files (seeded): values set to float edges and wrong types, keys
    deleted or added, values nested deep, numbers scaled by 10^k, objects duplicated."""
    import random

    rng = random.Random(seed)
    texts = []
    for _ in range(count):
        doc = json.loads(json.dumps(rng.choice(FUZZ_BASES)))
        for _ in range(rng.randint(1, 3)):
            paths = _fuzz_paths(doc)
            path = rng.choice(paths)
            parent = doc
            for key in path[:-1]:
                parent = parent[key]
            key = path[-1]
            operation = rng.choice(("edge", "edge", "scale", "delete", "add", "nest", "duplicate"))
            if operation == "edge":
                parent[key] = rng.choice(FUZZ_EDGES)
            elif operation == "scale" and isinstance(parent[key], (int, float)) and not isinstance(parent[key], bool):
                try:
                    parent[key] = float(parent[key]) * 10.0 ** rng.randint(-330, 330)
                except OverflowError:
                    parent[key] = float("inf")
            elif operation == "delete":
                del parent[key]
            elif operation == "add":
                (parent[key] if isinstance(parent[key], dict) else doc)[f"extra{rng.randint(0, 9)}"] = rng.choice(FUZZ_EDGES)
            elif operation == "nest":
                value = parent[key]
                for _ in range(rng.randint(1, 40)):
                    value = [value] if rng.random() < 0.5 else {"k": value}
                parent[key] = value
            elif operation == "duplicate" and isinstance(doc.get("objects"), list) and doc["objects"]:
                doc["objects"] = doc["objects"] * rng.randint(2, 40)
        try:
            texts.append(_toml(doc))
        except (TypeError, ValueError):
            texts.append(_toml(json.loads(json.dumps(rng.choice(FUZZ_BASES)))))
    return texts


def fuzz_argument_lists(count: int, seed: int, scene: str) -> list[tuple[str, ...]]:
    """``count`` argument lists for ``simulate`` on a short-record scene (seeded)."""
    import random

    rng = random.Random(seed)
    values = ("", "-1", "0", "1", "3", "nan", "inf", "1e300", "1e-300", "1e309", "abc", "9" * 30, "9" * 5000,
              "--pings", "free-sphere")
    options = ("--seed", "--snr-db", "--snr-echo", "--pings", "--max-order", "--backend", "--max-memory-gb")
    lists = []
    for index in range(count):
        argv = ["simulate", rng.choice((scene, scene, "", "nowhere", "a_folder")), "-o",
                rng.choice((f"out/fuzz{index}.h5", ""))]
        for _ in range(rng.randint(0, 3)):
            argv += [rng.choice(options), rng.choice(values)]
        if rng.random() < 0.3:
            argv.append(rng.choice(("--keep-all-paths", "--average", "--json", "--bogus")))
        lists.append(tuple(argv))
    return lists


_BATCH_DRIVER = """
import contextlib, io, json, resource, signal, sys, time, traceback
limit, timeout = int(sys.argv[1]), float(sys.argv[2])
resource.setrlimit(resource.RLIMIT_AS, (limit, limit))
from acoustisim.cli.main import main
class Expired(BaseException):
    pass
def expire(signum, frame):
    raise Expired()
signal.signal(signal.SIGALRM, expire)
for argv in json.loads(sys.stdin.read()):
    out, err = io.StringIO(), io.StringIO()
    start = time.perf_counter()
    print(json.dumps({"start": argv}), flush=True)
    signal.setitimer(signal.ITIMER_REAL, timeout)
    try:
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            code = main(list(argv))
    except Expired:
        code = None
    except SystemExit as exc:  # argparse's exit in older trees: its code, after its output
        code = exc.code if isinstance(exc.code, int) else (0 if exc.code is None else 2)
    except BaseException:
        code, err = 1, io.StringIO(err.getvalue() + "Traceback (most recent call last):\\n" + traceback.format_exc())
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0.0)
    text = err.getvalue()
    print(json.dumps({"argv": argv, "code": code, "err": text if len(text) < 4000 else text[:1000] + text[-3000:],
                      "seconds": time.perf_counter() - start}), flush=True)
"""


def run_batch(cases: list[Case], folder: Path, tree: Path, timeout_s: float, memory_bytes: int) -> list[Outcome]:
    """Run many ``acoustisim`` cases in one child process (in-process calls of ``main``), each
    under a ``SIGALRM`` timeout; a child stuck past every timeout is killed, its current case
    counts as a timeout and the rest run in a new child."""
    outcomes: list[Outcome] = []
    pending = list(cases)
    env = {k: v for k, v in os.environ.items() if not k.startswith("ACOUSTISIM_MAX_")}
    env.update(PYTHONPATH=str(tree), MPLBACKEND="Agg", PYTHONWARNINGS="ignore")
    while pending:
        process = subprocess.Popen([sys.executable, "-c", _BATCH_DRIVER, str(memory_bytes), str(timeout_s)],
                                   cwd=folder, env=env, text=True, stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                   stderr=subprocess.PIPE, start_new_session=True)
        try:
            stdout, stderr = process.communicate(json.dumps([list(c.argv) for c in pending]),
                                                 timeout=timeout_s * (len(pending) + 2))
        except subprocess.TimeoutExpired:
            os.killpg(process.pid, signal.SIGKILL)
            stdout, stderr = process.communicate()
        done = [json.loads(line) for line in stdout.splitlines() if line.startswith("{")]
        if not done:  # the driver itself failed before its first case: a bug here, not a verdict
            raise RuntimeError(f"the batch driver did not start: {stderr[-2000:]}")
        finished = [d for d in done if "argv" in d]
        for case, result in zip(pending, finished):
            outcomes.append(Outcome(case, result["code"], result["seconds"], result["err"]))
        pending = pending[len(finished):]
        if pending:  # the child died or hung inside this case (no Python-level timeout possible)
            outcomes.append(Outcome(pending[0], None, timeout_s, "killed"))
            pending = pending[1:]
    return outcomes


# ----------------------------------------------------------------------------- running
def _limit_memory(limit_bytes: int) -> None:
    os.setsid()
    resource.setrlimit(resource.RLIMIT_AS, (limit_bytes, limit_bytes))


def run_case(case: Case, folder: Path, tree: Path, timeout_s: float, memory_bytes: int) -> Outcome:
    """Run one case in ``folder`` with the tree on PYTHONPATH; never raises."""
    env = {k: v for k, v in os.environ.items() if not k.startswith("ACOUSTISIM_MAX_")}
    env["PYTHONPATH"] = str(tree)
    env["MPLBACKEND"] = "Agg"
    env["PYTHONWARNINGS"] = "ignore"
    code = ACOUSTISIM if case.program == "acoustisim" else BINSONAR
    start = time.perf_counter()
    process = subprocess.Popen([sys.executable, "-c", code, *case.argv], cwd=folder, env=env,
                               stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, stdin=subprocess.DEVNULL,
                               preexec_fn=lambda: _limit_memory(memory_bytes))
    try:
        _, err = process.communicate(timeout=timeout_s)
        returncode: int | None = process.returncode
    except subprocess.TimeoutExpired:
        os.killpg(process.pid, signal.SIGKILL)
        _, err = process.communicate()
        returncode = None
    seconds = time.perf_counter() - start
    return Outcome(case, returncode, seconds, err.decode("utf-8", "replace"))


def classify(outcome: Outcome) -> str:
    """One of :data:`CLASSES`."""
    err, code, expect = outcome.stderr, outcome.code, outcome.case.expect
    if code is None or code < 0:
        return "timeout"
    if "Traceback (most recent call last)" in err:
        return "traceback"
    if code == 0:
        return "accepted" if expect == "error" else "ok-0"
    if code == 2:
        lines = [line for line in err.splitlines() if line.strip()]
        if any(line.startswith("usage:") for line in lines):
            return "usage"
        if len(lines) != 1:
            return "multi-line"
        return "refused" if expect == "ok" else "clean-2"
    return "other-exit"


def table(outcomes: list[Outcome]) -> str:
    """Counts per kind and class, as a fixed-width table."""
    kinds = list(dict.fromkeys(o.case.kind for o in outcomes))
    width = max(len(k) for k in kinds + ["total"])
    head = f"{'kind':<{width}} {'runs':>5} " + " ".join(f"{c:>10}" for c in CLASSES)
    rows = [head, "-" * len(head)]
    for kind in kinds + ["total"]:
        selected = [o for o in outcomes if kind == "total" or o.case.kind == kind]
        cells = [sum(1 for o in selected if o.verdict == c) for c in CLASSES]
        rows.append(f"{kind:<{width}} {len(selected):>5} " + " ".join(f"{n:>10}" for n in cells))
    return "\n".join(rows)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--tree", type=Path, default=ROOT, help="source tree to test (default this checkout)")
    parser.add_argument("--jobs", type=int, default=2, help="runs in parallel (default 2)")
    parser.add_argument("--timeout", type=float, default=60.0, help="seconds before a run counts as a hang")
    parser.add_argument("--memory-gb", type=float, default=8.0, help="address-space limit per run (GiB)")
    parser.add_argument("--kinds", default=None, help="comma-separated kinds to run (default all)")
    parser.add_argument("--show", default="", help="comma-separated classes whose runs are listed with stderr")
    parser.add_argument("--json", type=Path, default=None, help="write every outcome to this JSON file")
    parser.add_argument("--fuzz", type=int, default=0, metavar="N",
                        help="also N seeded mutated scene files (scene validate) and N simulate argument lists,"
                             " run in-process in batches (kinds fuzz-scenes, fuzz-arguments)")
    parser.add_argument("--seed", type=int, default=18, help="seed of the fuzz inputs (default 18)")
    args = parser.parse_args(argv)

    cases, files = build_cases()
    batched: list[Case] = []
    if args.fuzz:
        for index, text in enumerate(fuzz_scene_texts(args.fuzz, args.seed)):
            files[f"fuzz_{index}.toml"] = text
            batched.append(Case("fuzz-scenes", f"fuzz_{index}", _validate(f"fuzz_{index}.toml"), "any"))
        for index, argv_ in enumerate(fuzz_argument_lists(args.fuzz, args.seed, "res_short.toml")):
            batched.append(Case("fuzz-arguments", f"args_{index}", argv_, "any"))
    if args.kinds:
        wanted = set(args.kinds.split(","))
        cases = [c for c in cases if c.kind in wanted]
        batched = [c for c in batched if c.kind in wanted]
    tree = args.tree.resolve()
    with tempfile.TemporaryDirectory(prefix="hostile-") as scratch:
        folder = Path(scratch)
        make_fixtures(folder, tree)
        for name, text in files.items():
            if name == "toml_latin1.toml":
                (folder / name).write_bytes(text.encode("latin-1"))
            else:
                (folder / name).write_text(text, encoding="utf-8")
        started = time.perf_counter()
        memory = int(args.memory_gb * 2**30)
        with concurrent.futures.ThreadPoolExecutor(max_workers=args.jobs) as pool:
            outcomes = list(pool.map(lambda c: run_case(c, folder, tree, args.timeout, memory), cases))
            batches = [batched[i:i + 50] for i in range(0, len(batched), 50)]
            for result in pool.map(lambda b: run_batch(b, folder, tree, args.timeout, memory), batches):
                outcomes += result
        elapsed = time.perf_counter() - started
    for outcome in outcomes:
        outcome.verdict = classify(outcome)
    print(f"tree {tree}: {len(outcomes)} runs in {elapsed:.0f} s (timeout {args.timeout:g} s,"
          f" {args.memory_gb:g} GiB address space per run)")
    print(table(outcomes))
    shown = set(filter(None, args.show.split(",")))
    for outcome in outcomes:
        if outcome.verdict in shown:
            last = [line for line in outcome.stderr.splitlines() if line.strip()][-3:]
            print(f"\n[{outcome.verdict}] {outcome.case.kind}/{outcome.case.label} exit {outcome.code}"
                  f" in {outcome.seconds:.1f} s")
            for line in last:
                print(f"    {line[:300]}")
    if args.json is not None:
        args.json.write_text(json.dumps([
            {"kind": o.case.kind, "label": o.case.label, "argv": [a[:200] for a in o.case.argv],
             "expect": o.case.expect, "exit": o.code, "seconds": round(o.seconds, 2), "verdict": o.verdict,
             "stderr": o.stderr[-2000:]}
            for o in outcomes], indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
