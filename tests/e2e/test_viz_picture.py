"""The viewer's pictures: palette, layout, labels, framing, markers on top, and the scene-first
Python API with its notebook display."""

from __future__ import annotations

import itertools
from pathlib import Path

import numpy as np
import pytest

from acoustisim.errors import InputError, InputTypeError
from acoustisim.propagation.paths import PathKind
from acoustisim.viz.actors import (
    BEAM_COLOR,
    CHANNEL_COLORS,
    ESTIMATE_COLOR,
    KIND_COLORS,
    EstimateMarker,
    TruthMarker,
    cone_lines,
    path_layers,
)
from acoustisim.viz.picture import place_labels

THESIS_OBJECTS = ("edge-1", "post-1", "post-2", "post-3", "pipe-1")


# ---------------------------------------------------------------------------------------- palette
def test_every_meaning_has_a_colour_distinct_under_colour_vision_deficiencies():
    """Each pair of colours that mean different things (path kinds, receivers, beam,
    estimates) stays at least 10 CAM02-UCS units apart for normal vision and for the three
    dichromacies simulated at full severity (Machado, Oliveira & Fernandes 2009). 10 units
    is about the step between the Okabe-Ito colours that are hardest to tell apart; the
    previous palette had two meanings on one green (0 units) and edge paths 1.7 units from the
    centre transducer under deuteranopia."""
    colorspacious = pytest.importorskip("colorspacious")
    colours = {f"{kind.label} paths": KIND_COLORS[kind] for kind in PathKind}
    colours |= {f"channel {k}": colour for k, colour in enumerate(CHANNEL_COLORS)}
    colours |= {"beam": BEAM_COLOR, "estimates": ESTIMATE_COLOR}
    names = list(colours)
    rgb = np.array([colours[name] for name in names], dtype=float)
    for cvd in (None, "protanomaly", "deuteranomaly", "tritanomaly"):
        seen = rgb if cvd is None else np.clip(colorspacious.cspace_convert(
            rgb, {"name": "sRGB1+CVD", "cvd_type": cvd, "severity": 100}, "sRGB1"), 0.0, 1.0)
        ucs = colorspacious.cspace_convert(seen, "sRGB1", "CAM02-UCS")
        for i, j in itertools.combinations(range(len(names)), 2):
            distance = float(np.linalg.norm(ucs[i] - ucs[j]))
            assert distance >= 10.0, f"{names[i]} and {names[j]} are {distance:.1f} apart ({cvd or 'normal vision'})"


# ----------------------------------------------------------------------------------------- layers
def test_diffuse_paths_are_drawn_first_and_capped_and_the_legend_counts_both():
    from support.viz_paths import fan_of_paths

    paths, sonar = fan_of_paths(n_diffuse=2000, n_edge=50, n_specular=20)
    layers = path_layers(paths, sonar, max_paths=None, max_diffuse=300, edge_elements=True)
    names = [layer.name for layer in layers]
    assert names.index("paths-diffuse") < names.index("paths-specular") < names.index("paths-edge")
    diffuse = next(layer for layer in layers if layer.name == "paths-diffuse")
    assert "300 strongest of 2,000" in diffuse.label
    # The strongest 300 are the ones kept (each row here is one segment pair: 2 cells).
    assert diffuse.mesh.n_cells == 2 * 300
    edge = next(layer for layer in layers if layer.name == "paths-edge")
    assert edge.label == "edge paths (50)"
    everything = path_layers(paths, sonar, max_paths=None, max_diffuse=None)
    assert next(layer for layer in everything if layer.name == "paths-diffuse").label == "diffuse paths (2,000)"


def test_beam_cone_lines_are_generators_and_a_rim_inside_the_box():
    bounds = np.array([[0.0, 0.0, 0.0], [9.0, 3.0, 1.0]])
    apex = np.array([1.0, 1.5, 0.5])
    axis = np.array([1.0, 0.0, 0.0])
    lines = cone_lines(apex, axis, 4.6, bounds)
    points = np.asarray(lines.points)
    assert np.all(points >= bounds[0] - 1e-9) and np.all(points <= bounds[1] + 1e-9)
    # The 4 generators start at the apex and make 4.6 degrees with the axis.
    cells = lines.lines.reshape(-1, 3)[:, 1:]
    generators = [points[b] - points[a] for a, b in cells if np.allclose(points[a], apex)]
    assert len(generators) == 4
    for g in generators:
        angle = np.degrees(np.arccos(g @ axis / np.linalg.norm(g)))
        assert angle == pytest.approx(4.6, abs=1e-9)
    # In plan, the horizontal generators leave through the far wall at y = 1.5 +/- 8 tan(4.6 deg).
    far = [points[b] for a, b in cells if np.allclose(points[a], apex) and abs(points[b][2] - 0.5) < 1e-9]
    np.testing.assert_allclose(sorted(p[1] for p in far), 1.5 + np.array([-1, 1]) * 8.0 * np.tan(np.radians(4.6)))


# ------------------------------------------------------------------------------------------ labels
def test_labels_are_placed_without_overlapping_each_other_or_the_markers():
    rng = np.random.default_rng(3)
    anchors = rng.uniform([100, 100], [300, 160], (12, 2))  # a crowded strip
    sizes = np.tile([60.0, 18.0], (12, 1))
    markers = rng.uniform([100, 100], [300, 160], (6, 2))
    offsets = place_labels(anchors, sizes, np.vstack([markers, anchors]), (0, 0, 800, 600))
    centres = anchors + offsets
    boxes = np.column_stack([centres - 0.5 * sizes, centres + 0.5 * sizes])
    for a, b in itertools.combinations(boxes, 2):
        assert not (a[0] < b[2] and b[0] < a[2] and a[1] < b[3] and b[1] < a[3]), "labels overlap"
    for box in boxes:
        inside = (markers[:, 0] > box[0]) & (markers[:, 0] < box[2]) & (markers[:, 1] > box[1]) & (
            markers[:, 1] < box[3])
        assert not inside.any(), "a label covers a marker"
        assert box[0] >= 0 and box[1] >= 0 and box[2] <= 800 and box[3] <= 600


# -------------------------------------------------------------------------------------- pictures
@pytest.fixture(scope="module")
def thesis_tank():
    from scenes.builtin import builtin_scene

    return builtin_scene("thesis-tank")


def _background_rows(image: np.ndarray) -> float:
    """Fraction of the image's rows that are white from edge to edge."""
    return float(np.mean(np.all(image.reshape(image.shape[0], -1) >= 250, axis=1)))


def test_top_view_legend_beside_the_tank_names_axes_and_no_blank_band(thesis_tank):
    from acoustisim.viz.snapshot import render_picture

    picture = render_picture(thesis_tank, camera="top")
    height, width, _ = picture.image.shape
    scene, legend = picture.scene_box_px, picture.legend_box_px
    assert legend[0] > scene[2], "the legend is right of the scene"
    # The plan keeps the tank's 3:1 shape and the picture has no blank band (the legend sits
    # beside the scene, not under it).
    assert (scene[2] - scene[0]) / (scene[3] - scene[1]) == pytest.approx(9.0 / 3.0, rel=0.1)
    assert _background_rows(picture.image) < 0.15
    # Every object is named, inside the scene area, and no two labels overlap.
    assert len(picture.label_boxes_px) == len(THESIS_OBJECTS) + 1  # and "sonar"
    for a, b in itertools.combinations(picture.label_boxes_px, 2):
        assert not (a[0] < b[2] and b[0] < a[2] and a[1] < b[3] and b[1] < a[3])
    for box in picture.label_boxes_px:
        assert scene[0] <= box[0] and box[2] <= scene[2] and scene[1] <= box[1] and box[3] <= scene[3]
    # Every object of the tank is inside the frame.
    anchors = picture.to_pixels(np.array([obj.bounds_m.mean(axis=0) for obj in thesis_tank.objects]))
    assert np.all((anchors[:, 0] > scene[0]) & (anchors[:, 0] < scene[2]))
    assert np.all((anchors[:, 1] > scene[1]) & (anchors[:, 1] < scene[3]))


def test_localisation_view_marks_every_estimate_on_top_and_frames_everything(thesis_tank):
    """Eight estimates: two just beyond the far wall, two 86 mm apart, one 3 m outside the
    tank (a multipath ghost), and a truth inside the opaque pipe. Every estimate is drawn (its
    yellow at its place; the ghost as an arrow at the picture's edge, the view staying on the
    tank), every truth marker is visible (black at its outline), post-3 far from every estimate
    is in frame, and the notes list all eight."""
    from acoustisim.viz.render import BEYOND_TANK_M
    from acoustisim.viz.snapshot import render_picture

    positions = [(2.500, 1.500), (2.586, 1.500), (2.976, 1.210), (3.175, 1.846), (4.425, 1.893), (9.133, 1.512),
                 (9.149, 1.501), (7.427, 6.337)]
    estimates = [EstimateMarker(np.array([x, y, 0.5]), np.diag([1e-6, 4e-6, 0.0]), "point") for x, y in positions]
    truths = [TruthMarker(obj.bounds_m.mean(axis=0), obj.name) for obj in thesis_tank.objects]
    picture = render_picture(thesis_tank, None, estimates, truths=truths, camera="targets")
    image = picture.image.astype(int)
    scene = picture.scene_box_px
    yellow = np.round(np.asarray(ESTIMATE_COLOR) * 255)

    def yellow_near(col: float, row: float, radius: int = 3) -> bool:
        patch = image[int(row) - radius:int(row) + radius + 1, int(col) - radius:int(col) + radius + 1]
        return bool(np.any(np.all(np.abs(patch - yellow) < 30, axis=-1)))

    pixels = picture.to_pixels(np.array([e.position_m for e in estimates]))
    # Estimates 6 and 7 are 16 mm apart: their markers overlap, so look within 3 pixels of each centre.
    for k, (col, row) in enumerate(pixels[:-1], start=1):
        assert scene[0] < col < scene[2] and scene[1] < row < scene[3], f"estimate {k} out of frame"
        assert yellow_near(col, row), f"estimate {k} not drawn"
    ghost_col, ghost_row = pixels[-1]
    assert ghost_row < scene[1], "the ghost lies above the picture: the view did not grow to hold it"
    assert yellow_near(ghost_col, scene[1] + 8, radius=6), "the ghost has no arrow at the top edge"
    top_of_view = picture.to_pixels(np.array([[0.0, 3.0 + BEYOND_TANK_M + 0.2, 0.5]]))[0, 1]
    assert top_of_view < scene[1] + 0.2 * (scene[3] - scene[1])  # the view reaches just past the wall
    for truth, (col, row) in zip(truths, picture.to_pixels(np.array([t.position_m for t in truths]))):
        assert scene[0] < col < scene[2] and scene[1] < row < scene[3], f"{truth.name} out of frame"
        ring = image[int(row) - 10:int(row) + 11, int(col) - 10:int(col) + 11]
        assert np.any(np.all(ring < 40, axis=-1)), f"the truth marker of {truth.name} is hidden"


def test_perspective_view_frames_every_object_and_the_tank(thesis_tank):
    from acoustisim.viz.snapshot import render_picture

    picture = render_picture(thesis_tank, camera="perspective", window_size=(900, 560))
    assert picture.image.shape == (560, 900, 3)
    scene = picture.scene_box_px
    lo, hi = thesis_tank.tank.bounds_m
    corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
    for points in [corners] + [obj.bounds_m for obj in thesis_tank.objects]:
        px = picture.to_pixels(points)
        assert np.all((px[:, 0] >= scene[0]) & (px[:, 0] <= scene[2]) & (px[:, 1] >= scene[1])
                      & (px[:, 1] <= scene[3]))
    # The tank fills the scene area (the framing is tight, not a far-away thumbnail).
    px = picture.to_pixels(corners)
    spread = (px.max(axis=0) - px.min(axis=0)) / np.array([scene[2] - scene[0], scene[3] - scene[1]])
    assert spread.max() > 0.85


# ------------------------------------------------------------------------------------------- API
def test_the_api_takes_the_scene_first_as_a_scene_a_name_or_a_file(thesis_tank, tmp_path: Path):
    from PIL import Image

    from acoustisim.viz import export_html, render_png, show_scene
    from scenes.scene_file import save_scene

    by_name = render_png("thesis-tank", tmp_path / "api.png", camera="top")
    assert Image.open(by_name).size[0] == 1400
    scene_file = tmp_path / "tank.toml"
    save_scene(thesis_tank, scene_file)
    assert render_png(str(scene_file), tmp_path / "file.png", camera="top", window_size=(700, 300)).exists()
    assert Image.open(tmp_path / "file.png").size == (700, 300)
    page = export_html("free-sphere", tmp_path / "page.html")
    assert "free-sphere" in page.read_text()
    plotter = show_scene("free-sphere", off_screen=True, window_size=(320, 240))
    try:
        assert "labels-labels" in plotter.actors and "legend" in plotter.actors
    finally:
        plotter.close()
    with pytest.raises(InputTypeError, match="the scene comes first"):
        render_png(tmp_path / "x.png", thesis_tank)  # path first: refused
    with pytest.raises(InputError, match="no such scene file or built-in scene"):
        render_png("no-such-scene", tmp_path / "x.png")
    with pytest.raises(InputTypeError, match="expected a Scene"):
        render_png(42, tmp_path / "x.png")


def test_scene_view_displays_itself_in_jupyter(tmp_path: Path):
    from acoustisim.viz import SceneView, view

    shown = view("free-sphere", camera="side", window_size=(640, 360))
    assert isinstance(shown, SceneView) and "free-sphere" in repr(shown)
    png = shown._repr_png_()
    assert png.startswith(b"\x89PNG\r\n\x1a\n")
    assert shown._repr_png_() is not None and shown.image() is shown.image()  # rendered once, then kept
    frame = shown.interactive(height_px=300)._repr_html_()
    assert frame.startswith("<iframe srcdoc=") and "height:300px" in frame and "&lt;canvas" in frame
    assert shown.save(tmp_path / "v.png").read_bytes() == png
    assert "<canvas" in shown.save_html(tmp_path / "v.html").read_text()
