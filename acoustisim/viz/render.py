"""The viewer's Python API, for notebooks and the ``acoustisim view`` command.

Every function takes the scene first, as a :class:`~acoustisim.scene.Scene`, a built-in
scene's name or a scene file's path:

>>> from acoustisim.propagation import solve                      # doctest: +SKIP
>>> scene = load_scene("thesis-tank")                             # doctest: +SKIP
>>> export_html(scene, "tank.html", solve(scene))                 # doctest: +SKIP
>>> show_scene(scene, solve(scene)).show()                        # doctest: +SKIP

In a notebook, :func:`acoustisim.viz.notebook.view` returns an object that displays itself;
:mod:`acoustisim.viz.snapshot` makes the PNG pictures.

A PNG (:mod:`acoustisim.viz.snapshot`: ``render_png``, ``render_image``, ``render_picture``) is
a picture designed for reading. The interactive window (:func:`show_scene`) and the HTML page
(:func:`export_html`) carry the same layers, the object names and a legend box.

Without a display (``DISPLAY``/``WAYLAND_DISPLAY`` unset on Linux) rendering is off-screen
through EGL (Mesa's software rasteriser is enough); with one, ``show_scene(...).show()`` opens
an interactive window.
"""

from __future__ import annotations

import os
import sys
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from acoustisim.errors import InputError, InputTypeError
from acoustisim.propagation.paths import Paths
from acoustisim.scene import Scene
from acoustisim.sonar import SonarHead
from acoustisim.viz.actors import (
    EstimateMarker,
    TruthMarker,
    beam_layers,
    estimate_layers,
    object_layers,
    path_layers,
    scene_bounds,
    sonar_layers,
    tank_layers,
    tof_layers,
)
from acoustisim.viz.cameras import CameraPreset, apply_camera, camera_preset
from acoustisim.viz.layers import RGBA_ARRAY, Layer

if TYPE_CHECKING:
    import pyvista as pv

ResultsInput = Sequence[EstimateMarker] | str | os.PathLike[str] | None
SceneInput = Scene | str | os.PathLike[str]

BEYOND_TANK_M = 0.5
"""How far past the tank's walls a view reaches to frame an estimate (m)."""


def resolve_scene(scene: SceneInput) -> Scene:
    """A Scene from a Scene, a built-in scene's name or a scene file's path.

    Raises
    ------
    InputError
        An unknown name or a bad scene file (the message names it).
    InputTypeError
        Anything else.
    """
    if isinstance(scene, Scene):
        return scene
    if isinstance(scene, (str, os.PathLike)):
        from scenes.scene_file import load_scene

        return load_scene(scene)
    raise InputTypeError(f"scene: expected a Scene, a built-in scene name or a scene file path, got "
                         f"{type(scene).__name__} (the scene comes first: render_png(scene, 'out.png', ...))")


@dataclass(frozen=True)
class ViewOptions:
    """What to draw and how.

    Attributes
    ----------
    channels : tuple of int
        Receiver channels whose paths are drawn (0 left, 1 centre, 2 right).
    max_paths : int or None
        Draw only this many strongest path rows (None: all).
    max_diffuse : int or None
        Of those, draw only this many strongest diffuse rows (None: all; see
        :func:`acoustisim.viz.actors.path_layers`).
    edge_elements : bool
        Draw each edge-diffraction element instead of one polyline per edge arrival.
    dynamic_range_db : float
        Paths this far below the strongest echo are drawn at the minimum opacity (dB).
    echo : int or str or None
        Draw the time-of-flight ellipsoids of this echo: its rank by delay among the centre
        channel's specular and edge echoes, or a surface name (its first single-bounce echo).
    show_beam : bool
        Draw the transmit beam's -3 dB and side-lobe cones.
    n_sigma : float
        Error ellipsoids' size in standard deviations.
    magnification : float or None
        Error ellipsoids' drawing scale (None: automatic, stated in the legend).
    labels : bool
        Write the objects' names on the picture.
    """

    channels: tuple[int, ...] = (0, 1, 2)
    max_paths: int | None = 10_000
    max_diffuse: int | None = 400
    edge_elements: bool = False
    dynamic_range_db: float = 40.0
    echo: int | str | None = None
    show_beam: bool = True
    n_sigma: float = 2.0
    magnification: float | None = None
    labels: bool = True


def has_display() -> bool:
    """Whether an interactive window can open (always assumed on Windows and macOS)."""
    if sys.platform.startswith(("win", "darwin")):
        return True
    return bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))


def _prefer_egl_without_display() -> None:
    """Make VTK open an EGL (headless) window directly instead of failing on X first.

    Sets ``VTK_DEFAULT_OPENGL_WINDOW`` for this process only when there is no display and the
    user has not chosen a window class.
    """
    if not has_display():
        os.environ.setdefault("VTK_DEFAULT_OPENGL_WINDOW", "vtkEGLRenderWindow")


def points_of(layers: Sequence[Layer], name: str) -> NDArray[np.float64]:
    for layer in layers:
        if layer.name == name:
            return np.asarray(layer.mesh.points, dtype=float).reshape(-1, 3)
    return np.empty((0, 3))


def _within(points: NDArray[np.float64], limits: NDArray[np.float64] | None) -> NDArray[np.float64]:
    """``points`` moved into ``limits`` (2, 3) (m), when given."""
    return points if limits is None or not points.size else np.clip(points, limits[0], limits[1])


def frame_limits(scene: Scene) -> NDArray[np.float64] | None:
    """How far a view may reach: the tank grown by ``BEYOND_TANK_M`` (None in free field). An
    estimate farther out (a ghost of a multipath) would shrink the tank to a corner of the
    picture: it is marked at the picture's edge instead, pointing toward it."""
    if scene.tank is None:
        return None
    lo, hi = scene.tank.bounds_m
    return np.array([lo - BEYOND_TANK_M, hi + BEYOND_TANK_M])


def targets_bounds(layers: Sequence[Layer], sonar: SonarHead, pad_m: float = 0.3,
                   limits: NDArray[np.float64] | None = None) -> NDArray[np.float64]:
    """What the "targets" camera frames (2, 3) (m): the sonar, every estimate and every true
    target (those beyond ``limits`` at the limit), padded by ``pad_m``."""
    points = np.vstack([sonar.receiver_positions, points_of(layers, "estimates"), points_of(layers, "truth")])
    points = _within(points, limits)
    return np.array([points.min(axis=0) - pad_m, points.max(axis=0) + pad_m])


def view_region(camera: str, scene: Scene, sonar: SonarHead, layers: Sequence[Layer]) -> NDArray[np.float64]:
    """The region (2, 3) (m) a camera preset frames: the tank (or, in free field, the objects
    and the sonar) grown to hold every estimate and true target up to ``BEYOND_TANK_M`` past
    the walls; for "targets" the sonar, the estimates and the true targets only."""
    limits = frame_limits(scene)
    if camera == "targets":
        return targets_bounds(layers, sonar, limits=limits)
    bounds = scene_bounds(scene, sonar)
    extra = _within(np.vstack([points_of(layers, "estimates"), points_of(layers, "truth")]), limits)
    if extra.size:
        bounds = np.array([np.minimum(bounds[0], extra.min(axis=0)), np.maximum(bounds[1], extra.max(axis=0))])
    return bounds


def _camera(camera: str | CameraPreset, scene: Scene, sonar: SonarHead, layers: Sequence[Layer],
            window_size: tuple[int, int]) -> CameraPreset:
    if isinstance(camera, CameraPreset):
        return camera
    return camera_preset(camera, view_region(camera, scene, sonar, layers), aspect=window_size[0] / window_size[1],
                         sonar=sonar)


def default_truths(scene: Scene) -> list[TruthMarker]:
    """True target positions from the scene: each object's bounding-box centre (m)."""
    return [TruthMarker(obj.bounds_m.mean(axis=0), obj.name) for obj in scene.objects]


def estimate_markers(results: ResultsInput, sonar: SonarHead) -> list[EstimateMarker] | None:
    """The estimates to draw: the given markers, or those of a results file (None: none)."""
    from acoustisim.viz.results_file import load_results

    if results is None:
        return None
    if isinstance(results, (str, os.PathLike)):
        return load_results(results, sonar)
    return list(results)


def build_layers(scene: SceneInput, paths: Paths | None = None, results: ResultsInput = None, *,
                 sonar: SonarHead | None = None, truths: Sequence[TruthMarker] | None = None,
                 options: ViewOptions = ViewOptions()) -> list[Layer]:
    """Every layer of the view, in drawing order: opaque things, then the translucent ones
    from the faintest background (tank, diffuse paths) to what must stay on top (echo paths,
    beam lines, ellipsoids, markers).

    Parameters
    ----------
    scene : Scene, built-in name or scene file path
    paths : Paths, optional
        Traced paths (``acoustisim.propagation.solve``) or a ping's true arrivals.
    results : sequence of EstimateMarker, or path of a results JSON, optional
        Localisation estimates (see :mod:`acoustisim.viz.results_file`).
    sonar : SonarHead, optional
        The sonar and pose to draw (default ``scene.sonar``); paths are closed at its transducers.
    truths : sequence of TruthMarker, optional
        True targets; with results and no truths, the objects' centres.
    options : ViewOptions

    Raises
    ------
    InputError
        A bad results file, or an echo number beyond the paths' echoes.
    """
    scene = resolve_scene(scene)
    sonar = scene.sonar if sonar is None else sonar
    bounds = scene_bounds(scene, sonar)
    layers: list[Layer] = []
    layers += object_layers(scene)
    layers += sonar_layers(sonar)
    layers += tank_layers(scene)
    if paths is not None:
        layers += path_layers(paths, sonar, channels=options.channels, max_paths=options.max_paths,
                              dynamic_range_db=options.dynamic_range_db, edge_elements=options.edge_elements,
                              max_diffuse=options.max_diffuse)
    if options.show_beam:
        layers += beam_layers(sonar, scene.medium.sound_speed, bounds)
    if options.echo is not None:
        if paths is None:
            raise InputError("echo: time-of-flight ellipsoids need paths (a ping file or traced paths)")
        try:
            layers += tof_layers(paths, sonar, options.echo, bounds)
        except IndexError as exc:
            raise InputError(f"echo: {exc}") from None
    markers = estimate_markers(results, sonar)
    if markers is not None:
        true_targets = list(truths) if truths is not None else default_truths(scene)
        layers += estimate_layers(markers, true_targets, n_sigma=options.n_sigma, magnification=options.magnification,
                                  view_size_m=float(np.linalg.norm(bounds[1] - bounds[0])))
    elif truths:
        layers += estimate_layers([], list(truths))
    return layers


def legend_entries(layers: Sequence[Layer]) -> list[tuple[str, tuple[float, float, float]]]:
    """(label, colour) of every labelled layer, in order."""
    return [(layer.label, layer.color) for layer in layers if layer.label]


def add_layers(plotter: "pv.Plotter", layers: Sequence[Layer]) -> None:
    """Add each layer to ``plotter`` as one actor named after it."""
    for layer in layers:
        if layer.mesh.n_points == 0:
            continue
        common = dict(name=layer.name, reset_camera=False, show_scalar_bar=False)
        if layer.has_rgba:
            colour = dict(scalars=RGBA_ARRAY, rgba=True, preference="cell")
        else:
            colour = dict(color=layer.color, opacity=layer.opacity)
        if layer.style == "points":
            plotter.add_mesh(layer.mesh, style="points", point_size=layer.point_size,
                             render_points_as_spheres=not layer.flat_points,
                             **colour, **common)
        elif layer.style in ("lines", "wireframe"):
            plotter.add_mesh(layer.mesh, style="wireframe", line_width=layer.line_width, lighting=False,
                             **colour, **common)
        else:
            plotter.add_mesh(layer.mesh, style="surface", smooth_shading=False, **colour, **common)


def add_legend(plotter: "pv.Plotter", entries: Sequence[tuple[str, tuple[float, float, float]]],
               window_size: tuple[int, int]) -> object:
    """A legend box (actor named "legend") in the lower-right corner of the interactive
    window: coloured squares, black text, room between them.

    Returns
    -------
    vtkLegendBoxActor
    """
    import pyvista as pv
    from vtkmodules.vtkRenderingAnnotation import vtkLegendBoxActor

    legend = vtkLegendBoxActor()
    legend.SetNumberOfEntries(len(entries))
    # A square swatch followed by blank space: the symbol's bounds set its width in the entry,
    # so the empty right part keeps the text clear of the colour.
    square = pv.PolyData(np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.0, 1.0, 0.0],
                                   [1.8, 0.5, 0.0]]), faces=np.array([4, 0, 1, 2, 3]))
    for i, (label, color) in enumerate(entries):
        # The swatch carries its colour as scalars so that the entry colour (black) only
        # colours the text; light colours are unreadable on white otherwise.
        symbol = square.copy()
        symbol.point_data.set_array(np.tile(np.round(np.asarray(color) * 255.0).astype(np.uint8), (5, 1)), "swatch")
        symbol.point_data.active_scalars_name = "swatch"
        legend.SetEntry(i, symbol, label, (0.0, 0.0, 0.0))
    legend.SetScalarVisibility(True)
    width = min(0.45, 360.0 / window_size[0])
    height = min(0.9, (19.0 * len(entries) + 8.0) / window_size[1])
    legend.GetPositionCoordinate().SetCoordinateSystemToNormalizedViewport()
    legend.GetPositionCoordinate().SetValue(1.0 - width - 0.01, 0.01)
    legend.GetPosition2Coordinate().SetCoordinateSystemToNormalizedViewport()
    legend.GetPosition2Coordinate().SetValue(width, height)
    legend.SetPadding(4)
    legend.UseBackgroundOn()
    legend.SetBackgroundColor(1.0, 1.0, 1.0)
    legend.SetBackgroundOpacity(0.85)
    legend.BorderOn()
    legend.GetEntryTextProperty().SetFontSize(14)
    legend.GetEntryTextProperty().SetColor(0.0, 0.0, 0.0)
    plotter.add_actor(legend, name="legend", reset_camera=False)
    return legend


def label_anchor(bounds_m: NDArray[np.float64]) -> NDArray[np.float64]:
    """Where an object's name points: the top centre of its bounding box (m)."""
    lo, hi = np.asarray(bounds_m, dtype=float)
    return np.array([0.5 * (lo[0] + hi[0]), 0.5 * (lo[1] + hi[1]), hi[2]])


def view_title(scene: Scene, title: str | None) -> str:
    return scene.name if title is None else title


def make_plotter(layers: Sequence[Layer], window_size: tuple[int, int], off_screen: bool, background: str,
             multi_samples: int) -> "pv.Plotter":
    import pyvista as pv

    if off_screen:
        _prefer_egl_without_display()
    plotter = pv.Plotter(off_screen=off_screen, window_size=list(window_size))
    plotter.ren_win.SetMultiSamples(int(multi_samples))
    plotter.set_background(background)
    add_layers(plotter, layers)
    return plotter


def show_scene(scene: SceneInput, paths: Paths | None = None, results: ResultsInput = None, *,
               sonar: SonarHead | None = None, truths: Sequence[TruthMarker] | None = None,
               options: ViewOptions = ViewOptions(), camera: str | CameraPreset = "perspective",
               off_screen: bool | None = None, window_size: tuple[int, int] | None = (1200, 800),
               title: str | None = None, legend: bool = True, background: str = "white",
               multi_samples: int = 4) -> "pv.Plotter":
    """A pyvista plotter holding the view (call ``.show()`` for a window, ``.screenshot()`` off-screen).

    Parameters
    ----------
    scene : Scene, built-in name or scene file path
    paths, results, sonar, truths, options
        See :func:`build_layers`.
    camera : {"top", "side", "sonar", "perspective", "targets"} or CameraPreset
        "targets" is a top view of the sonar, the estimates and the true targets.
    off_screen : bool or None
        None: off-screen exactly when there is no display.
    window_size : (int, int)
        Pixels (width, height); None: 1200 x 800.
    title : str, optional
        Text in the upper-left corner (default: the scene's name).
    legend : bool
        Draw the legend (labelled layers).
    background : str
        Background colour.
    multi_samples : int
        MSAA samples per pixel (pyvista's default 8 costs about a third more time in Mesa's
        software rasteriser for little visible gain on lines).

    Returns
    -------
    pyvista.Plotter
        Actors are named after the layers ("tank-walls", "paths-specular", ...), the object
        names "labels-labels".
    """
    scene = resolve_scene(scene)
    window_size = (1200, 800) if window_size is None else window_size
    if off_screen is None:
        off_screen = not has_display()
    sonar = scene.sonar if sonar is None else sonar
    layers = build_layers(scene, paths, results, sonar=sonar, truths=truths, options=options)
    plotter = make_plotter(layers, window_size, off_screen, background, multi_samples)
    apply_camera(plotter, _camera(camera, scene, sonar, layers, window_size))
    if options.labels and scene.objects:
        plotter.add_point_labels(np.array([label_anchor(obj.bounds_m) for obj in scene.objects]),
                                 [obj.name for obj in scene.objects], name="labels", font_size=14,
                                 text_color="black", shape_color="white", shape_opacity=0.8, point_size=1,
                                 always_visible=True, reset_camera=False)
    entries = legend_entries(layers)
    if legend and entries:
        add_legend(plotter, entries, window_size)
    plotter.add_text(view_title(scene, title), position="upper_left", font_size=11, color="black", name="title")
    return plotter


def html_page(scene: SceneInput, paths: Paths | None = None, results: ResultsInput = None, *,
              sonar: SonarHead | None = None, truths: Sequence[TruthMarker] | None = None,
              options: ViewOptions = ViewOptions(), camera: str | CameraPreset = "perspective",
              title: str | None = None, window_size: tuple[int, int] | None = (1200, 800)) -> str:
    """The view as one self-contained HTML page with an embedded WebGL viewer (the text of
    what :func:`export_html` writes)."""
    from acoustisim.viz.webgl import render_page

    scene = resolve_scene(scene)
    window_size = (1200, 800) if window_size is None else window_size
    sonar = scene.sonar if sonar is None else sonar
    layers = build_layers(scene, paths, results, sonar=sonar, truths=truths, options=options)
    return render_page(layers, _camera(camera, scene, sonar, layers, window_size), view_title(scene, title))


def export_html(scene: SceneInput, path: str | os.PathLike[str], paths: Paths | None = None,
                results: ResultsInput = None, **kwargs: object) -> Path:
    """Write the view as one self-contained HTML page with an embedded WebGL viewer (no network,
    no extra package): drag to rotate, right-drag or shift-drag to pan, wheel to zoom. Keyword
    arguments as :func:`html_page`.

    Returns
    -------
    Path
        The written file.
    """
    if isinstance(scene, (str, os.PathLike)) and isinstance(path, Scene):
        raise InputTypeError("export_html(scene, path, ...): the scene comes first")
    text = html_page(scene, paths, results, **kwargs)  # type: ignore[arg-type]
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text, encoding="utf-8")
    return path
