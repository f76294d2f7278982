"""The PNG picture of a view: VTK renders the scene area, :mod:`acoustisim.viz.picture` does the rest.

Every function takes the scene first (a Scene, a built-in scene's name or a scene file's path):

>>> render_png("thesis-tank", "tank.png", camera="top")           # doctest: +SKIP
>>> render_png(scene, "paths.png", solve(scene), camera="top")    # doctest: +SKIP

Flow: the layers (:func:`acoustisim.viz.render.build_layers`) and the region the camera frames
(:func:`acoustisim.viz.render.view_region`) set the picture's size
(:func:`acoustisim.viz.picture.scene_area`: a parallel view's scene area takes the region's
shape, the legend panel sits beside it); VTK renders the scene area off-screen without the
overlay layers (:data:`OVERLAY_LAYERS`), with an exact parallel camera whose image maps to
metres (:func:`parallel_camera`) or the perspective preset aimed by :func:`frame_everything`;
:func:`acoustisim.viz.picture.compose` then adds the axes or the tank's dimensions, the markers
on top, the object names, the legend and the numbered estimates.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path
from types import MappingProxyType
from typing import TYPE_CHECKING, Mapping

import numpy as np
from numpy.typing import NDArray

from acoustisim.errors import InputError, InputTypeError
from acoustisim.propagation.paths import Paths
from acoustisim.scene import Scene
from acoustisim.sonar import SonarHead
from acoustisim.viz.actors import ESTIMATE_COLOR, EstimateMarker, TruthMarker
from acoustisim.viz.cameras import CAMERA_NAMES, CameraPreset, apply_camera, camera_preset
from acoustisim.viz.layers import Layer
from acoustisim.viz.render import (
    ResultsInput,
    SceneInput,
    ViewOptions,
    build_layers,
    default_truths,
    estimate_markers,
    frame_limits,
    label_anchor,
    make_plotter,
    points_of,
    resolve_scene,
    view_region,
    view_title,
)

if TYPE_CHECKING:
    import pyvista as pv

    from acoustisim.viz.picture import ComposedPicture, Picture, Projection

PARALLEL_CAMERAS: tuple[str, ...] = ("top", "side", "targets")
"""Cameras with a parallel projection: their picture has axes in metres and a scale bar."""

OVERLAY_LAYERS: tuple[str, ...] = ("estimates", "truth", "estimate-errors", "echo-point", "sonar-marker")
"""Layers a PNG draws as markers on top of the render (:mod:`acoustisim.viz.picture`), so that
no surface or path hides them; the window and the HTML page draw them in 3-D."""

CAMERA_SUBTITLES: Mapping[str, str] = MappingProxyType({
    "top": "plan view (from above)",
    "side": "elevation (looking along +y)",
    "sonar": "from behind the sonar, along its boresight",
    "perspective": "perspective",
    "targets": "plan view of the sonar, the estimates and the true positions",
})

FRAME_PAD = 0.04
"""Fraction of the region added on every side of a parallel view."""

def box_corners(bounds_m: NDArray[np.float64]) -> NDArray[np.float64]:
    """The 8 corners (8, 3) of an axis-aligned box given by its bounds (2, 3)."""
    lo, hi = np.asarray(bounds_m, dtype=float)
    return np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])


def parallel_camera(name: str, region: NDArray[np.float64], scene_px: tuple[int, int]) -> tuple[CameraPreset,
                                                                                                 "Projection"]:
    """The camera of a parallel view filling the scene area exactly, and its projection to
    metres along the view's axes."""
    from acoustisim.viz.picture import Projection

    horizontal, vertical = (0, 2) if name == "side" else (0, 1)
    lo, hi = region
    centre = 0.5 * (lo + hi)
    extent = hi - lo
    aspect = scene_px[0] / scene_px[1]
    height = max(extent[vertical], extent[horizontal] / aspect) * (1.0 + 2.0 * FRAME_PAD)
    width = height * aspect
    distance = 4.0 * float(np.linalg.norm(extent)) + 1.0
    offset = np.array([0.0, -distance, 0.0]) if name == "side" else np.array([0.0, 0.0, distance])
    up = (0.0, 0.0, 1.0) if name == "side" else (0.0, 1.0, 0.0)
    preset = CameraPreset(name, tuple(float(v) for v in centre + offset), tuple(float(v) for v in centre), up, True,
                          0.5 * height)
    ch, cv = centre[horizontal], centre[vertical]

    def to_data(points: NDArray[np.float64]) -> NDArray[np.float64]:
        return np.asarray(points, dtype=float).reshape(-1, 3)[:, [horizontal, vertical]]

    projection = Projection(to_data, (ch - 0.5 * width, ch + 0.5 * width, cv - 0.5 * height, cv + 0.5 * height), True,
                            ("xyz"[horizontal], "xyz"[vertical]))
    return preset, projection


def camera_projection(plotter: "pv.Plotter", scene_px: tuple[int, int]) -> "Projection":
    """The projection of the plotter's current camera to scene-image pixels (origin lower left;
    NaN for points behind the eye)."""
    from acoustisim.viz.picture import Projection

    w, h = scene_px
    matrix = plotter.camera.GetCompositeProjectionTransformMatrix(w / h, -1.0, 1.0)
    m = np.array([[matrix.GetElement(i, j) for j in range(4)] for i in range(4)])

    def to_data(points: NDArray[np.float64]) -> NDArray[np.float64]:
        points = np.asarray(points, dtype=float).reshape(-1, 3)
        clip = np.c_[points, np.ones(len(points))] @ m.T
        with np.errstate(divide="ignore", invalid="ignore"):
            ndc = clip[:, :2] / clip[:, 3:4]
        ndc[clip[:, 3] <= 0] = np.nan  # behind the eye: not on the picture
        return (ndc + 1.0) * 0.5 * np.array([w, h])

    return Projection(to_data, (0.0, float(w), 0.0, float(h)), False)


def frame_everything(plotter: "pv.Plotter", points_m: NDArray[np.float64], scene_px: tuple[int, int],
                     fill: float = 0.92, steps: int = 8) -> None:
    """Aim a perspective camera so that every point projects inside the scene area, centred,
    their extent filling ``fill`` of the tighter dimension (the tank's corners, the objects'
    bounding boxes, the sonar, the markers: nothing of the scene is cut off, and little of the
    area is left empty). The viewing direction is kept; the camera slides sideways to centre
    and along its view to scale (the projected size of a scene far from the eye goes as the
    inverse of the distance, so a few steps converge)."""
    camera = plotter.camera
    size = np.array(scene_px, dtype=float)
    for _ in range(steps):
        plotter.renderer.reset_camera_clipping_range()
        px = camera_projection(plotter, scene_px).to_data(points_m)
        px = px[np.all(np.isfinite(px), axis=1)]
        if not px.size:
            break
        lo, hi = px.min(axis=0), px.max(axis=0)
        focal = np.asarray(camera.focal_point, dtype=float)
        position = np.asarray(camera.position, dtype=float)
        distance = float(np.linalg.norm(position - focal))
        forward = (focal - position) / distance
        up = np.asarray(camera.up, dtype=float)
        right = np.cross(forward, up)
        right /= np.linalg.norm(right)
        up = np.cross(right, forward)
        # World size of one pixel at the focal distance.
        metres_per_px = 2.0 * distance * np.tan(np.radians(0.5 * camera.view_angle)) / size[1]
        shift = (0.5 * (lo + hi) - 0.5 * size) * metres_per_px
        move = shift[0] * right + shift[1] * up
        scale = max((hi - lo)[0] / (fill * size[0]), (hi - lo)[1] / (fill * size[1]))
        focal = focal + move
        camera.focal_point = tuple(focal)
        camera.position = tuple(focal - forward * distance * scale)
        if abs(scale - 1.0) < 0.01 and np.all(np.abs(shift / metres_per_px) < 2.0):
            break
    plotter.renderer.reset_camera_clipping_range()


def _legend(layers: Sequence[Layer]) -> tuple:
    from acoustisim.viz.picture import LegendEntry

    entries = []
    for layer in layers:
        if not layer.label:
            continue
        if layer.name == "estimates":  # numbered on the picture, listed under the legend
            entries.append(LegendEntry(layer.label.removesuffix(")") + ", numbered)", (0.0, 0.0, 0.0), "marker",
                                       layer.group, "o", ESTIMATE_COLOR))
        elif layer.name == "truth":
            entries.append(LegendEntry(layer.label, (0.0, 0.0, 0.0), "marker", layer.group, "s", None))
        elif layer.name == "echo-point":
            entries.append(LegendEntry(layer.label, (0.0, 0.0, 0.0), "marker", layer.group, "X", (0.0, 0.0, 0.0)))
        elif layer.style in ("lines", "wireframe"):
            entries.append(LegendEntry(layer.label, layer.color, "line", layer.group))
        elif layer.style == "points":
            entries.append(LegendEntry(layer.label, layer.color, "marker", layer.group, "o", layer.color))
        else:
            entries.append(LegendEntry(layer.label, layer.color, "patch", layer.group, alpha=max(layer.opacity, 0.35)))
    return tuple(entries)


def _estimate_notes(markers: Sequence[EstimateMarker], truths: Sequence[TruthMarker],
                    match_radius_m: float = 0.25, limits: NDArray[np.float64] | None = None) -> tuple[str, ...]:
    """One line per numbered estimate: its class, position and the nearest true target."""
    if not markers:
        return ()
    lines = [f"Estimates ({len(markers)}, all marked), and the", "nearest object's centre within 0.25 m:"]
    truth_xyz = np.array([t.position_m for t in truths], dtype=float).reshape(-1, 3)
    for k, marker in enumerate(markers, start=1):
        x, y, _ = (float(v) for v in marker.position_m)
        text = f"{k:>2} {marker.cls[:8]:<8} {x:6.3f}, {y:6.3f} m"
        if truth_xyz.size:
            distance = np.linalg.norm(truth_xyz - np.asarray(marker.position_m, dtype=float), axis=1)
            nearest = int(np.argmin(distance))
            if distance[nearest] <= match_radius_m:
                name = truths[nearest].name or f"target {nearest + 1}"
                text += f"  {name[:8]} {distance[nearest] * 1e3:5.1f} mm"
            else:
                text += "  -"
        if limits is not None and np.any((marker.position_m < limits[0]) | (marker.position_m > limits[1])):
            text = text.removesuffix("  -") + "  (arrow: beyond)"
        lines.append(text)
    return tuple(lines)


def _picture(scene: Scene, sonar: SonarHead, layers: Sequence[Layer], markers: Sequence[EstimateMarker] | None,
             truths: Sequence[TruthMarker], camera: str, title: str | None, options: ViewOptions,
             region: NDArray[np.float64]) -> "Picture":
    from acoustisim.viz.picture import Marker, Picture, Segments

    overlay: list[Marker] = []
    points = {name: points_of(layers, name) for name in ("estimates", "truth", "echo-point")}
    if points["truth"].size:
        overlay.append(Marker(points["truth"], "s", 13.0, (0.0, 0.0, 0.0), None))
    if points["echo-point"].size:
        overlay.append(Marker(points["echo-point"], "X", 10.0, (1.0, 1.0, 1.0), (0.0, 0.0, 0.0)))
    if points["estimates"].size:
        overlay.append(Marker(points["estimates"], "o", 8.0, (0.0, 0.0, 0.0), ESTIMATE_COLOR, numbered=True))
    segments = []
    for layer in layers:
        if layer.name == "estimate-errors":
            ends = np.asarray(layer.mesh.points, dtype=float)
            half = len(ends) // 2
            segments.append(Segments(ends[:half], ends[half:], (0.15, 0.15, 0.15), 1.2))
    names: list[tuple[str, NDArray[np.float64]]] = []
    if options.labels:
        names = [(obj.name, label_anchor(obj.bounds_m)) for obj in scene.objects]
        names.append(("sonar", np.asarray(sonar.transmitter_position, dtype=float)))
    subtitle = CAMERA_SUBTITLES.get(camera, camera)
    return Picture(
        title=view_title(scene, title),
        subtitle=subtitle,
        names=tuple(names),
        markers=tuple(overlay),
        segments=tuple(segments),
        legend=_legend(layers),
        notes=_estimate_notes(markers or [], truths, limits=frame_limits(scene) if camera in PARALLEL_CAMERAS
                              else None),
        tank_bounds_m=None if scene.tank is None else scene.tank.bounds_m,
        region_m=region,
        scale_start_m=_scale_start(scene, sonar),
    )


def _scale_start(scene: Scene, sonar: SonarHead) -> NDArray[np.float64] | None:
    """Free field: the scale bar starts under the transmitter, below the lowest object."""
    if scene.tank is None and scene.objects:
        bottom = min(float(obj.bounds_m[0, 2]) for obj in scene.objects)
        tx = np.asarray(sonar.transmitter_position, dtype=float)
        return np.array([tx[0], tx[1], min(bottom, tx[2]) - 0.05])
    return None


def render_image(scene: SceneInput, paths: Paths | None = None, results: ResultsInput = None,
                 **kwargs: object) -> NDArray[np.uint8]:
    """The view as a finished picture, (height, width, 3) uint8 (keyword arguments as
    :func:`render_picture`)."""
    return render_picture(scene, paths, results, **kwargs).image  # type: ignore[arg-type]


def render_picture(scene: SceneInput, paths: Paths | None = None, results: ResultsInput = None, *,
                   sonar: SonarHead | None = None, truths: Sequence[TruthMarker] | None = None,
                   options: ViewOptions = ViewOptions(), camera: str = "perspective",
                   window_size: tuple[int, int] | None = None, title: str | None = None,
                   multi_samples: int = 4) -> "ComposedPicture":
    """The view as a finished picture with where things landed on it (see
    :mod:`acoustisim.viz.picture`).

    Parameters
    ----------
    scene : Scene, built-in name or scene file path
    paths, results, sonar, truths, options
        See :func:`build_layers`.
    camera : {"top", "side", "sonar", "perspective", "targets"}
    window_size : (width, height) or None
        The picture's size (pixels); None: 1400 pixels wide and as tall as the view needs.
    title : str, optional
        Default: the scene's name.
    multi_samples : int

    Returns
    -------
    ComposedPicture
    """
    from acoustisim.viz.picture import compose, nice_length, panel_height, scene_area

    scene = resolve_scene(scene)
    if not isinstance(camera, str) or camera not in CAMERA_NAMES:
        raise InputError(f"camera: unknown preset {camera!r}; choose one of {', '.join(CAMERA_NAMES)}")
    sonar = scene.sonar if sonar is None else sonar
    markers = estimate_markers(results, sonar)
    true_targets = list(truths) if truths is not None else (default_truths(scene) if markers is not None else [])
    layers = build_layers(scene, paths, markers, sonar=sonar, truths=truths, options=options)
    region = view_region(camera, scene, sonar, layers)
    picture = _picture(scene, sonar, layers, markers, true_targets, camera, title, options, region)
    parallel = camera in PARALLEL_CAMERAS
    aspect = None
    if parallel:
        horizontal, vertical = (0, 2) if camera == "side" else (0, 1)
        size = region[1] - region[0]
        aspect = float(size[horizontal] / max(size[vertical], 1e-9))
    fig_w, fig_h, scene_w, scene_h = scene_area(window_size, aspect, panel_height(picture))
    drawn = [layer for layer in layers if layer.name not in OVERLAY_LAYERS]
    plotter = make_plotter(drawn, (scene_w, scene_h), True, "white", multi_samples)
    try:
        if parallel:
            preset, projection = parallel_camera("side" if camera == "side" else "top", region, (scene_w, scene_h))
            apply_camera(plotter, preset)
        else:
            apply_camera(plotter, camera_preset(camera, region, aspect=scene_w / scene_h, sonar=sonar))
            if camera == "perspective":
                # The tank's corners (in free field the objects and the sonar themselves: the
                # region's padding would leave the picture mostly empty).
                boxes = [obj.bounds_m for obj in scene.objects] + ([] if scene.tank is None else [scene.tank.bounds_m])
                corners = [box_corners(box) for box in boxes]
                corners += [points_of(layers, name) for name in ("sonar-head", "estimates", "truth")]
                if picture.scale_start_m is not None:  # the free-field scale bar is part of the picture
                    length = nice_length(region[1][0] - region[0][0], 0.3)
                    corners.append(picture.scale_start_m + np.array([[0.0, 0.0, 0.0], [length, 0.0, 0.0]]))
                frame_everything(plotter, np.vstack(corners), (scene_w, scene_h))
            plotter.renderer.reset_camera_clipping_range()
            projection = camera_projection(plotter, (scene_w, scene_h))
        image = np.asarray(plotter.screenshot(return_img=True))[:, :, :3]
    finally:
        plotter.close()
    return compose(image, picture, projection, (fig_w, fig_h), (scene_w, scene_h))


def render_png(scene: SceneInput, path: str | os.PathLike[str], paths: Paths | None = None,
               results: ResultsInput = None, **kwargs: object) -> Path:
    """Render the view off-screen to a PNG file (keyword arguments as :func:`render_image`).

    Returns
    -------
    Path
        The written file.
    """
    from PIL import Image

    if isinstance(scene, (str, os.PathLike)) and isinstance(path, Scene):
        raise InputTypeError("render_png(scene, path, ...): the scene comes first")
    image = render_image(scene, paths, results, **kwargs)  # type: ignore[arg-type]
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    Image.fromarray(image).save(path, optimize=True)
    return path


