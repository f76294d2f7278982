"""``acoustisim scene show NAME --toml``: the scene file of any scene, built-in or from a file,
loads back as the same scene."""

from __future__ import annotations

from pathlib import Path

import pytest

from acoustisim.cli.main import main
from scenes.builtin import builtin_scene_names
from scenes.scene_file import load_scene, scene_to_dict

EXAMPLE = Path(__file__).resolve().parents[2] / "scenes" / "data" / "example.toml"


@pytest.mark.parametrize("name", [*builtin_scene_names(), str(EXAMPLE)])
def test_scene_show_toml_writes_a_file_that_loads_as_the_same_scene(name: str, tmp_path: Path,
                                                                    capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["scene", "show", name, "--toml"]) == 0
    text = capsys.readouterr().out
    path = tmp_path / "scene.toml"
    path.write_text(text)
    again = load_scene(path)
    original = load_scene(name)
    # Every value explicit in both: the scene file round-trips exactly (meshes by absolute path).
    assert scene_to_dict(again) == scene_to_dict(original)
    assert again.triangle_count == original.triangle_count


def test_scene_show_toml_and_json_are_exclusive(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["scene", "show", "thesis-tank", "--toml", "--json"]) == 2  # argparse's error, as one line
    err = capsys.readouterr().err
    assert "not allowed with" in err and len(err.strip().splitlines()) == 1
