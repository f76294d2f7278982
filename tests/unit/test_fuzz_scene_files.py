"""Property-based fuzzing of scene files: every mutated file gets exit 0 or one clear line.

Starting points: the scene file of conventions.md (``scenes/data/example.toml``) and every
built-in scene's TOML. Mutations: values replaced by hostile ones (numbers at the edges of
floating point, strings, booleans, lists, tables), keys deleted or added, values nested deep,
numbers scaled by 10^k, objects duplicated, and byte-level edits of the text. Each file goes
through ``acoustisim scene validate`` and ``scene show --json`` in this process (seeded,
derandomised; under ``-m slow`` many more examples), and a valid one through ``simulate``
with a short record.
"""

from __future__ import annotations

import copy
import math
import shutil
import tomllib
from pathlib import Path
from typing import Any

import pytest
import tomli_w
from hypothesis import HealthCheck, given, seed, settings
from hypothesis import strategies as st

from scenes.builtin import builtin_scene, builtin_scene_names
from scenes.scene_file import scene_to_toml
from support.cli_contract import check_contract, run_in_process

DATA = Path(__file__).resolve().parents[2] / "scenes" / "data"
SHORT_RECORD_S = 2.0e-4
"""Record length of the simulated fuzz scenes (keeps a run to a fraction of a second)."""

FAST = settings(derandomize=True, database=None, deadline=None, max_examples=30,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
DEEP = settings(database=None, deadline=None, max_examples=600,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])


def _bases() -> list[dict[str, Any]]:
    bases = [tomllib.loads((DATA / "example.toml").read_text())]
    bases += [tomllib.loads(scene_to_toml(builtin_scene(name))) for name in builtin_scene_names()]
    return bases


BASES = _bases()
SIMULATED_BASES = [tomllib.loads(scene_to_toml(builtin_scene(name))) for name in ("free-sphere", "free-post")]
"""Small scenes for the fuzzed simulations (a fraction of a second each)."""

EDGE_NUMBERS = (1e300, -1e300, 1e-300, -1e-300, 5e-324, 0.0, -0.0, math.nan, math.inf, -math.inf, 1e308,
                1.7976931348623157e308, 10**400, -(10**30), 2**63, 2**64, 0, 1, -1, 1e-12, 1e12, 360.0, 1e6)
numbers = st.one_of(st.sampled_from(EDGE_NUMBERS), st.floats(allow_nan=True, allow_infinity=True),
                    st.integers(-(10**20), 10**20))
leaves = st.one_of(numbers, st.text(max_size=12), st.booleans(), st.sampled_from(["", "x" * 5000, "rock.stl"]))
values = st.recursive(leaves, lambda inner: st.one_of(st.lists(inner, max_size=4),
                                                       st.dictionaries(st.text(max_size=6), inner, max_size=3)),
                      max_leaves=8)


def _paths(node: Any, prefix: tuple = ()) -> list[tuple]:
    """Every path (tuple of keys and indices) into the document, tables and leaves alike."""
    found = [prefix] if prefix else []
    if isinstance(node, dict):
        for key, child in node.items():
            found += _paths(child, prefix + (key,))
    elif isinstance(node, list):
        for index, child in enumerate(node):
            found += _paths(child, prefix + (index,))
    return found


def _parent(doc: Any, path: tuple) -> Any:
    node = doc
    for key in path[:-1]:
        node = node[key]
    return node


def _mutate(doc: dict[str, Any], data: st.DataObject) -> dict[str, Any]:
    for _ in range(data.draw(st.integers(1, 3), label="mutations")):
        paths = _paths(doc)
        if not paths:
            doc["name"] = data.draw(values)
            continue
        path = data.draw(st.sampled_from(paths), label="path")
        parent, key = _parent(doc, path), path[-1]
        operation = data.draw(st.sampled_from(["set", "edge", "scale", "delete", "add", "nest", "duplicate"]),
                              label="operation")
        if operation == "set":
            parent[key] = data.draw(values, label="value")
        elif operation == "edge":
            parent[key] = data.draw(st.sampled_from(EDGE_NUMBERS), label="edge")
        elif operation == "scale" and isinstance(parent[key], (int, float)) and not isinstance(parent[key], bool):
            exponent = data.draw(st.integers(-330, 330), label="exponent")
            try:
                parent[key] = float(parent[key]) * 10.0 ** exponent
            except OverflowError:
                parent[key] = math.inf
        elif operation == "delete":
            del parent[key]
        elif operation == "add":
            target = parent[key] if isinstance(parent[key], dict) else doc
            target[data.draw(st.text(min_size=1, max_size=10), label="new key")] = data.draw(values)
        elif operation == "nest":
            value = parent[key]
            for _ in range(data.draw(st.integers(1, 40), label="depth")):
                value = [value] if data.draw(st.booleans()) else {"k": value}
            parent[key] = value
        elif operation == "duplicate" and isinstance(doc.get("objects"), list) and doc["objects"]:
            doc["objects"] = doc["objects"] * data.draw(st.integers(2, 40), label="copies")
    return doc


@pytest.fixture(scope="module")
def workdir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    folder = tmp_path_factory.mktemp("fuzz")
    shutil.copy(DATA / "rock.stl", folder / "rock.stl")
    return folder


def _check_file(path: Path) -> None:
    for argv in (["scene", "validate", str(path)], ["scene", "show", str(path), "--json"]):
        check_contract(run_in_process(argv, timeout_s=60.0))


def _write(doc: dict[str, Any], path: Path) -> bool:
    try:
        path.write_text(tomli_w.dumps(doc), encoding="utf-8")
    except (TypeError, ValueError, RecursionError):
        return False  # not expressible in TOML (tomli_w refuses it): nothing to test
    return True


def _mutated_files(data: st.DataObject, workdir: Path) -> None:
    doc = _mutate(copy.deepcopy(data.draw(st.sampled_from(BASES), label="base")), data)
    path = workdir / "mutated.toml"
    if _write(doc, path):
        _check_file(path)


def _edited_text(data: st.DataObject, workdir: Path) -> None:
    text = tomli_w.dumps(data.draw(st.sampled_from(BASES), label="base"))
    for _ in range(data.draw(st.integers(1, 4), label="edits")):
        at = data.draw(st.integers(0, len(text)), label="at")
        edit = data.draw(st.sampled_from(["insert", "delete", "repeat-line"]), label="edit")
        if edit == "insert":
            text = text[:at] + data.draw(st.text(alphabet="[]{}=\".,#\n 0123456789eE+-_aznif\\'\x00", max_size=8)) \
                + text[at:]
        elif edit == "delete":
            text = text[:at] + text[at + data.draw(st.integers(1, 20)):]
        else:
            lines = text.splitlines(keepends=True)
            index = min(at, len(lines) - 1)
            lines.insert(index, lines[index] * data.draw(st.integers(1, 3)))
            text = "".join(lines)
    path = workdir / "edited.toml"
    path.write_text(text, encoding="utf-8")
    _check_file(path)


@FAST
@given(data=st.data())
def test_mutated_scene_files_keep_the_contract(data: st.DataObject, workdir: Path) -> None:
    _mutated_files(data, workdir)


@FAST
@given(data=st.data())
def test_edited_scene_text_keeps_the_contract(data: st.DataObject, workdir: Path) -> None:
    _edited_text(data, workdir)


@settings(derandomize=True, database=None, deadline=None, max_examples=6,
          suppress_health_check=[HealthCheck.too_slow])
@given(data=st.data())
def test_mutated_numbers_simulate_or_refuse(data: st.DataObject, workdir: Path) -> None:
    """Numbers at the edges of floating point, through the whole simulation (short records)."""
    doc = copy.deepcopy(data.draw(st.sampled_from(SIMULATED_BASES), label="base"))
    doc["sonar"]["record_length_s"] = SHORT_RECORD_S
    numeric = [p for p in _paths(doc) if isinstance(_parent(doc, p)[p[-1]], (int, float))
               and not isinstance(_parent(doc, p)[p[-1]], bool)]
    path = data.draw(st.sampled_from(numeric), label="path")
    parent, key = _parent(doc, path), path[-1]
    if data.draw(st.booleans(), label="edge or mild"):
        parent[key] = data.draw(st.sampled_from(EDGE_NUMBERS), label="edge")
    else:  # a legal-looking change: most of these simulate
        parent[key] = float(parent[key]) * data.draw(st.sampled_from((0.5, 0.9, 1.1, 2.0)), label="factor")
    scene = workdir / "numbers.toml"
    if _write(doc, scene):
        check_contract(run_in_process(["simulate", str(scene), "-o", str(workdir / "numbers.h5")], timeout_s=120.0))


@pytest.mark.slow
@seed(20260518)
@DEEP
@given(data=st.data())
def test_mutated_scene_files_deep(data: st.DataObject, workdir: Path) -> None:
    _mutated_files(data, workdir)


@pytest.mark.slow
@seed(20260519)
@DEEP
@given(data=st.data())
def test_edited_scene_text_deep(data: st.DataObject, workdir: Path) -> None:
    _edited_text(data, workdir)
