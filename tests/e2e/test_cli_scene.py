"""``acoustisim scene list | validate | show``."""

import json
import subprocess
import sys
from pathlib import Path

import pytest

from acoustisim.cli.main import main
from scenes.builtin import builtin_scene_names

DATA = Path(__file__).resolve().parents[2] / "scenes" / "data"


def test_list(capsys):
    assert main(["scene", "list"]) == 0
    assert capsys.readouterr().out.split() == list(builtin_scene_names())
    assert main(["scene", "list", "--json"]) == 0
    assert json.loads(capsys.readouterr().out) == {"scenes": list(builtin_scene_names())}


@pytest.mark.parametrize("name", builtin_scene_names())
def test_validate_builtin(capsys, name):
    assert main(["scene", "validate", name]) == 0
    assert "valid" in capsys.readouterr().out


def test_validate_file(capsys):
    assert main(["scene", "validate", str(DATA / "example.toml"), "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["valid"] is True and report["objects"] == 5


def test_show_json_is_one_object_with_the_facts(capsys):
    assert main(["scene", "show", "thesis-tank", "--json"]) == 0
    out, err = capsys.readouterr()
    summary = json.loads(out)  # the whole of stdout is one JSON object
    assert err == ""
    assert summary["name"] == "thesis-tank"
    assert summary["medium"]["sound_speed_m_s"] == pytest.approx(1482.38, abs=0.005)
    assert summary["sonar"]["position_m"] == [1.0, 1.5, 0.5] and summary["sonar"]["yaw_deg"] == 0.0
    assert [t["name"] for t in summary["sonar"]["transducers"]] == ["left", "centre", "right"]
    assert summary["tank"]["bounds_m"] == [[0.0, 0.0, 0.0], [9.0, 3.0, 1.0]]
    assert len(summary["boundaries"]) == 6
    objects = {o["name"]: o for o in summary["objects"]}
    assert objects["edge-1"]["kind"] == "edge" and objects["edge-1"]["material"] == "steel-machined"
    assert objects["edge-1"]["triangles"] == 8
    assert objects["pipe-1"]["primitive"]["type"] == "cylinder"
    assert summary["triangle_count"] == sum(o["triangles"] for o in summary["objects"]) + 12


def test_show_text(capsys):
    assert main(["scene", "show", "free-sphere"]) == 0
    out = capsys.readouterr().out
    assert "free field" in out and "sphere" in out and "1482.38 m/s" in out


def _acoustisim() -> list[str]:
    """The installed console script, as a new user runs it; else the same entry point via -c."""
    script = Path(sys.executable).with_name("acoustisim")
    if script.is_file():
        return [str(script)]
    return [sys.executable, "-c", "import sys; from acoustisim.cli import main; sys.exit(main())"]


def test_console_script_end_to_end():
    # A separate process: real exit codes and streams.
    ok = subprocess.run([*_acoustisim(), "scene", "show", "thesis-tank", "--json"], capture_output=True, text=True)
    assert ok.returncode == 0, ok.stderr
    assert json.loads(ok.stdout)["name"] == "thesis-tank"
    bad = subprocess.run([*_acoustisim(), "scene", "validate", "no-such-scene"], capture_output=True, text=True)
    assert bad.returncode == 2
    assert bad.stdout == "" and "Traceback" not in bad.stderr and bad.stderr.count("\n") == 1
    assert "no-such-scene" in bad.stderr
