"""The viewer's Python API, for notebooks and the ``acoustisim view`` command.

>>> from scenes.builtin import builtin_scene                       # doctest: +SKIP
>>> from acoustisim.propagation import solve                      # doctest: +SKIP
>>> scene = builtin_scene("thesis-tank")                          # doctest: +SKIP
>>> plotter = show_scene(scene, solve(scene), camera="top")       # doctest: +SKIP
>>> plotter.show()                                                # doctest: +SKIP
>>> render_png("tank.png", scene, solve(scene))                   # doctest: +SKIP
>>> export_html("tank.html", scene, solve(scene))                 # doctest: +SKIP

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

from acoustisim.errors import InputError
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


@dataclass(frozen=True)
class ViewOptions:
    """What to draw and how.

    Attributes
    ----------
    channels : tuple of int
        Receiver channels whose paths are drawn (0 left, 1 centre, 2 right).
    max_paths : int or None
        Draw only this many strongest path rows (None: all).
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
    """

    channels: tuple[int, ...] = (0, 1, 2)
    max_paths: int | None = 10_000
    edge_elements: bool = False
    dynamic_range_db: float = 40.0
    echo: int | str | None = None
    show_beam: bool = True
    n_sigma: float = 2.0
    magnification: float | None = None


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


def targets_bounds(layers: Sequence[Layer], sonar: SonarHead, region: NDArray[np.float64], pad_m: float = 0.3,
                   match_radius_m: float = 0.25) -> NDArray[np.float64]:
    """What the "targets" camera frames (2, 3) (m): the sonar, the estimates inside ``region``
    and the true targets within ``match_radius_m`` of one (all true targets when there is no
    estimate), padded by ``pad_m`` and widened toward +x for the legend box."""
    by_name = {layer.name: np.asarray(layer.mesh.points, dtype=float) for layer in layers
               if layer.name in ("estimates", "truth")}
    estimates = by_name.get("estimates", np.empty((0, 3)))
    truths = by_name.get("truth", np.empty((0, 3)))
    inside = estimates[np.all((estimates >= region[0]) & (estimates <= region[1]), axis=1)]
    if inside.size and truths.size:
        near = np.min(np.linalg.norm(truths[:, None, :] - inside[None, :, :], axis=2), axis=1) <= match_radius_m
        truths = truths[near]
    points = np.vstack([sonar.receiver_positions, inside, truths])
    lo, hi = points.min(axis=0) - pad_m, points.max(axis=0) + pad_m
    # Room on the +x side for the legend box (lower-right corner, about 30 % of the width).
    hi[0] += 0.35 * (hi[0] - lo[0])
    return np.array([lo, hi])


def _camera(camera: str | CameraPreset, scene: Scene, sonar: SonarHead, layers: Sequence[Layer],
            window_size: tuple[int, int]) -> CameraPreset:
    if isinstance(camera, CameraPreset):
        return camera
    bounds = scene_bounds(scene, sonar)
    if camera == "targets":
        bounds = targets_bounds(layers, sonar, bounds)
    return camera_preset(camera, bounds, aspect=window_size[0] / window_size[1], sonar=sonar)


def default_truths(scene: Scene) -> list[TruthMarker]:
    """True target positions from the scene: each object's bounding-box centre (m)."""
    return [TruthMarker(obj.bounds_m.mean(axis=0), obj.name) for obj in scene.objects]


def build_layers(scene: Scene, paths: Paths | None = None, results: ResultsInput = None, *,
                 sonar: SonarHead | None = None, truths: Sequence[TruthMarker] | None = None,
                 options: ViewOptions = ViewOptions()) -> list[Layer]:
    """Every layer of the view, in drawing order (opaque things first).

    Parameters
    ----------
    scene : Scene
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
    from acoustisim.viz.results_file import load_results

    sonar = scene.sonar if sonar is None else sonar
    bounds = scene_bounds(scene, sonar)
    layers: list[Layer] = []
    layers += object_layers(scene)
    layers += sonar_layers(sonar)
    if paths is not None:
        layers += path_layers(paths, sonar, channels=options.channels, max_paths=options.max_paths,
                              dynamic_range_db=options.dynamic_range_db, edge_elements=options.edge_elements)
    if results is not None:
        markers = list(results) if not isinstance(results, (str, os.PathLike)) else load_results(results, sonar)
        true_targets = list(truths) if truths is not None else default_truths(scene)
        layers += estimate_layers(markers, true_targets, n_sigma=options.n_sigma,
                                  magnification=options.magnification,
                                  view_size_m=float(np.linalg.norm(bounds[1] - bounds[0])))
    elif truths:
        layers += estimate_layers([], list(truths))
    if options.echo is not None:
        if paths is None:
            raise InputError("echo: time-of-flight ellipsoids need paths (a ping file or traced paths)")
        try:
            layers += tof_layers(paths, sonar, options.echo, bounds)
        except IndexError as exc:
            raise InputError(f"echo: {exc}") from None
    layers += tank_layers(scene)
    if options.show_beam:
        layers += beam_layers(sonar, scene.medium.sound_speed, bounds)
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
    """A legend box (actor named "legend") in the lower-right corner: coloured squares, black text.

    Returns
    -------
    vtkLegendBoxActor
    """
    import pyvista as pv
    from vtkmodules.vtkRenderingAnnotation import vtkLegendBoxActor

    legend = vtkLegendBoxActor()
    legend.SetNumberOfEntries(len(entries))
    square = pv.PolyData(np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.0, 1.0, 0.0]]),
                         faces=np.array([4, 0, 1, 2, 3]))
    for i, (label, color) in enumerate(entries):
        # The swatch carries its colour as scalars so that the entry colour (black) only
        # colours the text; light colours are unreadable on white otherwise.
        symbol = square.copy()
        symbol.point_data.set_array(np.tile(np.round(np.asarray(color) * 255.0).astype(np.uint8), (4, 1)), "swatch")
        symbol.point_data.active_scalars_name = "swatch"
        legend.SetEntry(i, symbol, label, (0.0, 0.0, 0.0))
    legend.SetScalarVisibility(True)
    width = min(0.45, 330.0 / window_size[0])
    height = min(0.9, (19.0 * len(entries) + 8.0) / window_size[1])
    legend.GetPositionCoordinate().SetCoordinateSystemToNormalizedViewport()
    legend.GetPositionCoordinate().SetValue(1.0 - width - 0.01, 0.01)
    legend.GetPosition2Coordinate().SetCoordinateSystemToNormalizedViewport()
    legend.GetPosition2Coordinate().SetValue(width, height)
    legend.UseBackgroundOn()
    legend.SetBackgroundColor(1.0, 1.0, 1.0)
    legend.SetBackgroundOpacity(0.85)
    legend.BorderOn()
    legend.GetEntryTextProperty().SetFontSize(14)
    legend.GetEntryTextProperty().SetColor(0.0, 0.0, 0.0)
    plotter.add_actor(legend, name="legend", reset_camera=False)
    return legend


def _title(scene: Scene, title: str | None) -> str:
    return scene.name if title is None else title


def show_scene(scene: Scene, paths: Paths | None = None, results: ResultsInput = None, *,
               sonar: SonarHead | None = None, truths: Sequence[TruthMarker] | None = None,
               options: ViewOptions = ViewOptions(), camera: str | CameraPreset = "perspective",
               off_screen: bool | None = None, window_size: tuple[int, int] = (1200, 800),
               title: str | None = None, legend: bool = True, background: str = "white",
               multi_samples: int = 4) -> "pv.Plotter":
    """A pyvista plotter holding the view (call ``.show()`` for a window, ``.screenshot()`` off-screen).

    Parameters
    ----------
    scene, paths, results, sonar, truths, options
        See :func:`build_layers`.
    camera : {"top", "side", "sonar", "perspective", "targets"} or CameraPreset
        "targets" is a top view of the sonar and the true targets (or the estimates).
    off_screen : bool or None
        None: off-screen exactly when there is no display.
    window_size : (int, int)
        Pixels (width, height).
    title : str, optional
        Text in the upper-left corner (default: the scene's name and the number of paths).
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
        Actors are named after the layers ("tank-walls", "paths-specular", ...).
    """
    import pyvista as pv

    if off_screen is None:
        off_screen = not has_display()
    if off_screen:
        _prefer_egl_without_display()
    sonar = scene.sonar if sonar is None else sonar
    layers = build_layers(scene, paths, results, sonar=sonar, truths=truths, options=options)
    plotter = pv.Plotter(off_screen=off_screen, window_size=list(window_size))
    plotter.ren_win.SetMultiSamples(int(multi_samples))
    plotter.set_background(background)
    add_layers(plotter, layers)
    apply_camera(plotter, _camera(camera, scene, sonar, layers, window_size))
    entries = legend_entries(layers)
    if legend and entries:
        add_legend(plotter, entries, window_size)
    plotter.add_text(_title(scene, title), position="lower_left", font_size=11, color="black",
                     name="title")
    return plotter


def render_png(path: str | os.PathLike[str], scene: Scene, paths: Paths | None = None, results: ResultsInput = None,
               **kwargs: object) -> Path:
    """Render the view off-screen to a PNG file (keyword arguments as :func:`show_scene`).

    Returns
    -------
    Path
        The written file.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    kwargs["off_screen"] = True
    plotter = show_scene(scene, paths, results, **kwargs)  # type: ignore[arg-type]
    try:
        plotter.screenshot(str(path))
    finally:
        plotter.close()
    return path


def export_html(path: str | os.PathLike[str], scene: Scene, paths: Paths | None = None, results: ResultsInput = None,
                *, sonar: SonarHead | None = None, truths: Sequence[TruthMarker] | None = None,
                options: ViewOptions = ViewOptions(), camera: str | CameraPreset = "perspective",
                title: str | None = None, window_size: tuple[int, int] = (1200, 800)) -> Path:
    """Write the view as one self-contained HTML page with an embedded WebGL viewer (no network,
    no extra package): drag to rotate, right-drag or shift-drag to pan, wheel to zoom.

    Returns
    -------
    Path
        The written file.
    """
    from acoustisim.viz.webgl import write_webgl_html

    sonar = scene.sonar if sonar is None else sonar
    layers = build_layers(scene, paths, results, sonar=sonar, truths=truths, options=options)
    return write_webgl_html(path, layers, _camera(camera, scene, sonar, layers, window_size),
                            title=_title(scene, title))
