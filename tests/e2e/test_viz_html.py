"""The standalone HTML export: its embedded data, and a real render in headless Chromium."""

from __future__ import annotations

import base64
import json
import re
import shutil
import subprocess

import numpy as np
import pytest

from acoustisim.propagation.paths import PathKind, Paths, empty_paths_array
from acoustisim.scene import Scene, SceneObject, Tank
from acoustisim.sonar import SonarHead
from acoustisim.viz.actors import EstimateMarker
from acoustisim.viz.render import ViewOptions, build_layers, export_html
from acoustisim.viz.webgl import page_data


def _scene_and_paths() -> tuple[Scene, Paths]:
    import trimesh

    from acoustisim.materials import get_material

    ball = trimesh.creation.icosphere(3, 0.1)
    ball.apply_translation([4.0, 1.2, 0.5])
    scene = Scene("html-test", sonar=SonarHead(), tank=Tank(), objects=(
        SceneObject("ball", "sphere", get_material("steel"), ball),))
    rng = np.random.default_rng(7)
    n = 300
    rows = empty_paths_array(n)
    rows["channel"] = rng.integers(0, 3, n)
    rows["kind"] = rng.choice([PathKind.SPECULAR, PathKind.EDGE, PathKind.DIFFUSE], n)
    rows["order"] = 1
    rows["points_m"][:, 0] = rng.uniform([0.5, 0.2, 0.1], [8.5, 2.8, 0.9], (n, 3))
    rows["object_ids"][:, 0] = 6
    rows["amplitude"] = 10 ** rng.uniform(-3, -1, n)
    rows["path_id"] = np.arange(n)
    rows["delay_s"] = rng.uniform(1e-3, 1e-2, n)
    return scene, Paths(rows, scene.surface_names)


def test_page_data_holds_every_layer_with_consistent_arrays():
    scene, paths = _scene_and_paths()
    layers = build_layers(scene, paths, [EstimateMarker(np.array([4.0, 1.2, 0.5]), np.eye(3) * 1e-6)],
                          options=ViewOptions(echo=0))
    from acoustisim.viz.cameras import camera_preset

    data = page_data(layers, camera_preset("perspective", scene.tank.bounds_m), "t")
    names = {item["name"] for item in data["items"]}
    assert {"tank-walls", "paths-specular", "paths-edge", "paths-diffuse", "beam-3db", "tof-centre", "estimates",
            "estimate-ellipsoids", "object:ball"} <= names
    for item in data["items"]:
        count = item["count"]
        assert len(base64.b64decode(item["pos"])) == 12 * count  # float32 xyz per vertex
        assert len(base64.b64decode(item["col"])) == 4 * count  # RGBA bytes per vertex
        if item["mode"] == "triangles":
            assert count % 3 == 0 and len(base64.b64decode(item["nrm"])) == 12 * count
        if item["mode"] == "lines":
            assert count % 2 == 0
    # Every drawn path row is in the page: one segment per leg (tx -> point -> receiver).
    segments = sum(item["count"] // 2 for item in data["items"] if item["name"].startswith("paths-"))
    assert segments == 2 * len(paths)
    # The page closes no script element early.
    assert "</script" not in json.dumps(data).replace("</", "<\\/")


def _chromium() -> str | None:
    return shutil.which("chromium") or shutil.which("chromium-browser") or shutil.which("google-chrome")


CHROMIUM_FLAGS = (
    "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
    "--disable-background-networking", "--disable-component-update", "--disable-sync",
    # Software WebGL (SwiftShader) must be asked for explicitly without a GPU; the page is local.
    "--enable-unsafe-swiftshader", "--enable-logging=stderr", "--v=0", "--window-size=900,600",
)


@pytest.mark.skipif(_chromium() is None, reason="Chromium is not installed (Debian package 'chromium', "
                                                "listed in .ci/apt-packages)")
def test_html_export_renders_in_headless_chromium(tmp_path):
    from PIL import Image

    scene, paths = _scene_and_paths()
    page = export_html(scene, tmp_path / "view.html", paths, [EstimateMarker(np.array([4.0, 1.2, 0.5]), None)],
                       options=ViewOptions(echo=0), camera="perspective")
    text = page.read_text()
    # Self-contained: no external script, stylesheet or fetch (it must open offline).
    assert not re.search(r"<script[^>]+src=|<link[^>]+href=|https?://|fetch\(|XMLHttpRequest", text)
    url = page.resolve().as_uri()
    browser = _chromium()

    def run(*extra: str, profile: str) -> subprocess.CompletedProcess:
        return subprocess.run([browser, *CHROMIUM_FLAGS, f"--user-data-dir={tmp_path / profile}", *extra, url],
                              capture_output=True, text=True, timeout=180)

    dom = run("--dump-dom", profile="dom")
    status = re.search(r'<body[^>]*data-status="([^"]*)"', dom.stdout)
    assert status is not None, dom.stdout[:500]
    assert status.group(1) == "rendered", status.group(1)
    # The legend was built from the embedded data.
    assert "specular paths" in dom.stdout and "time-of-flight ellipse, centre" in dom.stdout
    # No script error in the browser's console log (Chromium logs console messages as
    # "CONSOLE" lines; uncaught exceptions start with "Uncaught"; our page logs "WebGL is not
    # available" with console.error when it cannot draw).
    console = [line for line in dom.stderr.splitlines() if "CONSOLE" in line]
    bad = [line for line in console if "Uncaught" in line or "WebGL is not available" in line]
    assert not bad, bad

    shot = tmp_path / "shot.png"
    capture = run(f"--screenshot={shot}", profile="shot")
    assert shot.exists(), capture.stderr[-2000:]
    image = np.asarray(Image.open(shot).convert("RGB"))
    assert image.shape[:2] == (600, 900)
    # Not blank: the canvas shows the tank, paths and beam (many colours, strong variance); a
    # white page with only the HTML legend has a few dozen colours at most.
    quantised = (image // 32).reshape(-1, 3)
    assert image.std() > 15
    assert len(np.unique(quantised, axis=0)) > 40
    # The canvas itself (left half, clear of the legend) is not uniform.
    assert image[100:500, 50:450].std() > 10
