"""The picture around a 3-D render: object names, axes or a scale, markers, a legend beside it.

A PNG of the viewer is composed in two layers. VTK renders the scene (tank, objects, paths,
beam, ellipsoids) into the picture's scene area; matplotlib then draws on top of it what must
stay readable whatever the scene holds, and around it what explains it:

- the object names, each placed next to its object where it overlaps no other label or
  marker (:func:`place_labels`), with a thin leader line;
- the markers (estimates, numbered; true positions; the chosen echo's point), so that no
  surface, path or beam can hide them (a marker inside a pipe is still seen);
- for the plan and elevation views (parallel projection) axes in metres and a scale bar; for
  the perspective views the tank's dimensions written on its edges and the tank frame's axes;
- the legend in a panel beside the scene, by group (objects, sonar, paths, beam, echo,
  localisation), and the list of the numbered estimates;
- the title above.

Everything here works on a :class:`Picture` (what to draw, in tank-frame metres) and a
:class:`Projection` (tank frame to the scene image's pixels), built by
:mod:`acoustisim.viz.render`. Sizes are pixels at ``DPI``.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

RGB = tuple[float, float, float]

DPI = 100
"""Dots per inch of the composed figure: one matplotlib point is DPI / 72 pixels."""
FONT_SIZE = 10.0
"""Points: labels and legend text."""
LEGEND_WIDTH_PX = 340
"""Width of the legend panel beside the scene (pixels)."""
MARGINS_PX = (62, 46, 44, 16)
"""Left, bottom, top, gap before the legend (pixels) around the scene area: room for the
axes' tick labels and the title."""

GROUP_HEADINGS: tuple[tuple[str, str], ...] = (
    ("object", "Objects (material: names)"),
    ("sonar", "Sonar"),
    ("tank", "Tank"),
    ("beam", "Transmit beam"),
    ("paths", "Paths (fainter = weaker, over 40 dB)"),
    ("tof", "Echo"),
    ("estimate", "Localisation"),
    ("truth", "Localisation"),
)
"""Legend headings by layer group, in legend order (estimate and truth share one)."""


@dataclass(frozen=True)
class LegendEntry:
    """One legend line.

    Attributes
    ----------
    label : str
    color : tuple of 3 float
    glyph : {"line", "patch", "marker"}
    group : str
        A key of :data:`GROUP_HEADINGS`.
    marker : str
        matplotlib marker of a "marker" glyph.
    face : tuple of 3 float or None
        Marker face colour (None: hollow).
    alpha : float
        Patch opacity.
    """

    label: str
    color: RGB
    glyph: str
    group: str
    marker: str = "o"
    face: RGB | None = None
    alpha: float = 1.0


@dataclass(frozen=True)
class Marker:
    """Points drawn on top of the scene.

    Attributes
    ----------
    points_m : ndarray, shape (n, 3)
        Tank frame (m).
    marker : str
        matplotlib marker.
    size : float
        Marker size (points).
    edge, face : tuple of 3 float, or None
        Outline and fill colours (face None: hollow).
    numbered : bool
        Write 1..n next to the points (the estimates, listed in the legend panel).
    """

    points_m: NDArray[np.float64]
    marker: str
    size: float
    edge: RGB
    face: RGB | None
    numbered: bool = False


@dataclass(frozen=True)
class Segments:
    """Line segments drawn on top of the scene (tank frame, m): ``starts`` and ``ends`` (n, 3)."""

    starts_m: NDArray[np.float64]
    ends_m: NDArray[np.float64]
    color: RGB
    width: float


@dataclass(frozen=True)
class Picture:
    """What the overlay draws, in the tank frame.

    Attributes
    ----------
    title : str
    subtitle : str
    names : tuple of (str, ndarray (3,))
        Object names and the point each label points at (m).
    markers : tuple of Marker
    segments : tuple of Segments
    legend : tuple of LegendEntry
    notes : tuple of str
        Lines printed under the legend (the numbered estimates).
    tank_bounds_m : ndarray (2, 3) or None
        The tank's water (m), for the dimension labels of perspective views.
    region_m : ndarray (2, 3)
        The region framed (m).
    scale_start_m : ndarray (3,) or None
        Free-field perspective views: where the scale bar starts (m; it runs along +x).
    """

    title: str
    subtitle: str
    names: tuple[tuple[str, NDArray[np.float64]], ...]
    markers: tuple[Marker, ...]
    segments: tuple[Segments, ...]
    legend: tuple[LegendEntry, ...]
    notes: tuple[str, ...]
    tank_bounds_m: NDArray[np.float64] | None
    region_m: NDArray[np.float64]
    scale_start_m: NDArray[np.float64] | None = None


@dataclass(frozen=True)
class Projection:
    """From the tank frame to the scene image.

    Attributes
    ----------
    to_data : callable
        ``(n, 3)`` tank-frame points (m) to ``(n, 2)`` coordinates of the scene axes: metres
        along the view's two axes for a parallel view, pixels from the image's lower-left
        corner for a perspective one.
    extent : tuple of 4 float
        ``(left, right, bottom, top)`` of the image in those coordinates.
    metric : bool
        Parallel view: the axes are in metres, with ticks and a scale bar.
    axis_names : tuple of 2 str
        The tank-frame axes shown horizontally and vertically ("x", "y") for a metric view.
    """

    to_data: Callable[[NDArray[np.float64]], NDArray[np.float64]]
    extent: tuple[float, float, float, float]
    metric: bool
    axis_names: tuple[str, str] = ("x", "y")


def nice_length(span: float, fraction: float = 0.15) -> float:
    """A round length (1, 2 or 5 x 10^n) close to ``fraction`` of ``span`` (for a scale bar)."""
    target = max(span * fraction, 1e-9)
    exponent = math.floor(math.log10(target))
    best = 10.0**exponent
    for step in (1.0, 2.0, 5.0, 10.0):
        if step * 10.0**exponent <= target * 1.5:
            best = step * 10.0**exponent
    return best


def _boxes_overlap(a: NDArray[np.float64], b: NDArray[np.float64]) -> bool:
    return bool(a[0] < b[2] and b[0] < a[2] and a[1] < b[3] and b[1] < a[3])


def place_labels(anchors_px: NDArray[np.float64], sizes_px: NDArray[np.float64], keep_clear_px: NDArray[np.float64],
                 frame_px: tuple[float, float, float, float], *, gap_px: float = 9.0,
                 clear_radius_px: float = 8.0) -> NDArray[np.float64]:
    """Where to put each label: the offset (pixels) of its box's centre from its anchor.

    Greedy, in the order given: each label tries positions around its anchor (right, left,
    above, below, the diagonals, then the directions between, at growing distances) and takes
    the first whose box overlaps no label placed before, covers no point of ``keep_clear_px``
    (markers, other anchors; ``clear_radius_px`` around each) and stays inside ``frame_px``;
    when none does, the one that breaks the fewest of these rules (leaving the frame worst,
    then covering a label, then a marker).

    Parameters
    ----------
    anchors_px : ndarray, shape (n, 2)
        What each label names (display pixels).
    sizes_px : ndarray, shape (n, 2)
        Width and height of each label's box (pixels).
    keep_clear_px : ndarray, shape (m, 2)
        Points no label box may cover.
    frame_px : (x0, y0, x1, y1)
        The area the boxes must stay in.

    Returns
    -------
    ndarray, shape (n, 2)
        Offsets of the boxes' centres from the anchors (pixels).
    """
    anchors_px = np.asarray(anchors_px, dtype=float).reshape(-1, 2)
    sizes_px = np.asarray(sizes_px, dtype=float).reshape(-1, 2)
    clear = np.asarray(keep_clear_px, dtype=float).reshape(-1, 2)
    placed: list[NDArray[np.float64]] = []
    offsets = np.zeros_like(anchors_px)
    directions = [(1, 0), (-1, 0), (0, 1), (0, -1), (1, 1), (-1, 1), (1, -1), (-1, -1)]
    directions += [(np.cos(a), np.sin(a)) for a in np.radians(np.arange(15.0, 360.0, 30.0))]
    for k, (anchor, (w, h)) in enumerate(zip(anchors_px, sizes_px)):
        best, best_cost = np.zeros(2), math.inf
        for scale in (1.0, 2.2, 3.6, 5.5, 8.0):
            for dx, dy in directions:
                offset = np.array([dx * (0.5 * w + gap_px * scale), dy * (0.5 * h + gap_px * scale)])
                centre = anchor + offset
                box = np.array([centre[0] - 0.5 * w, centre[1] - 0.5 * h, centre[0] + 0.5 * w, centre[1] + 0.5 * h])
                cost = 0.0
                if box[0] < frame_px[0] or box[1] < frame_px[1] or box[2] > frame_px[2] or box[3] > frame_px[3]:
                    cost += 100.0
                cost += 10.0 * sum(_boxes_overlap(box, other) for other in placed)
                if clear.size:
                    nearest_x = np.clip(clear[:, 0], box[0], box[2])
                    nearest_y = np.clip(clear[:, 1], box[1], box[3])
                    cost += 3.0 * float(np.count_nonzero(np.hypot(clear[:, 0] - nearest_x, clear[:, 1] - nearest_y)
                                                         < clear_radius_px))
                cost += 0.01 * scale  # prefer near
                if cost < best_cost:
                    best, best_cost = offset, cost
            if best_cost < 1.0:
                break
        offsets[k] = best
        centre = anchor + best
        w, h = sizes_px[k]
        placed.append(np.array([centre[0] - 0.5 * w, centre[1] - 0.5 * h, centre[0] + 0.5 * w, centre[1] + 0.5 * h]))
    return offsets


def legend_handles(entries: Sequence[LegendEntry]) -> tuple[list[Any], list[str], list[int]]:
    """matplotlib handles and labels, with a heading line before each group; the indices of
    the headings (to set in bold)."""
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch

    order = {group: k for k, (group, _) in enumerate(GROUP_HEADINGS)}
    heading_of = dict(GROUP_HEADINGS)
    handles: list[Any] = []
    labels: list[str] = []
    headings: list[int] = []
    last_heading = None
    for entry in sorted(entries, key=lambda e: order.get(e.group, len(order))):
        heading = heading_of.get(entry.group, entry.group.capitalize())
        if heading != last_heading:
            headings.append(len(labels))
            handles.append(Patch(visible=False))
            labels.append(heading)
            last_heading = heading
        if entry.glyph == "line":
            handles.append(Line2D([], [], color=entry.color, linewidth=2.2))
        elif entry.glyph == "marker":
            handles.append(Line2D([], [], linestyle="none", marker=entry.marker, markersize=8,
                                  markeredgecolor=entry.color, markeredgewidth=1.4,
                                  markerfacecolor=entry.face if entry.face is not None else "none"))
        else:
            handles.append(Patch(facecolor=entry.color, edgecolor=tuple(0.6 * c for c in entry.color),
                                 alpha=entry.alpha))
        labels.append(entry.label)
    return handles, labels, headings


LEGEND_LINE_PX = 20.5
"""Height of one legend line (pixels, at ``FONT_SIZE``)."""
NOTE_LINE_PX = 16.0
"""Height of one line of the notes under the legend (pixels)."""


def panel_height(picture: Picture) -> int:
    """Pixels the legend panel needs: its lines (with the group headings) and the notes."""
    _, labels, _ = legend_handles(picture.legend)
    notes = len(picture.notes) * NOTE_LINE_PX + (20 if picture.notes else 0)
    return int(len(labels) * LEGEND_LINE_PX + notes + 20)


def scene_area(window_px: tuple[int, int] | None, region_aspect: float | None,
               panel_px: int = 400) -> tuple[int, int, int, int]:
    """The figure's size and the scene area's size (pixels): ``(fig_w, fig_h, scene_w, scene_h)``.

    Parameters
    ----------
    window_px : (width, height) or None
        The requested picture size; None: 1400 pixels wide, as tall as the scene and the
        legend panel (``panel_px``, :func:`panel_height`) need.
    region_aspect : float or None
        Width / height of the region of a parallel view (the scene area takes exactly that
        shape, fitted in the space left of the legend); None for a perspective view (the
        scene area fills that space).
    """
    left, bottom, top, gap = MARGINS_PX
    fig_w = 1400 if window_px is None else int(window_px[0])
    legend_w = min(LEGEND_WIDTH_PX, int(0.4 * fig_w))
    avail_w = max(16, fig_w - left - gap - legend_w - 8)
    if window_px is None:
        if region_aspect is None:
            scene_w, scene_h = avail_w, int(round(avail_w / 1.75))
        else:
            scene_w, scene_h = avail_w, int(round(avail_w / region_aspect))
        fig_h = max(scene_h + bottom + top, panel_px + top)
        return fig_w, fig_h, scene_w, scene_h
    fig_h = int(window_px[1])
    avail_h = max(16, fig_h - bottom - top)
    if region_aspect is None:
        return fig_w, fig_h, avail_w, avail_h
    scene_w = min(avail_w, int(round(avail_h * region_aspect)))
    return fig_w, fig_h, max(16, scene_w), max(16, int(round(scene_w / region_aspect)))


@dataclass(frozen=True)
class ComposedPicture:
    """A finished picture and where things landed on it.

    Attributes
    ----------
    image : ndarray, shape (height, width, 3) uint8
    to_pixels : callable
        ``(n, 3)`` tank-frame points (m) to ``(n, 2)`` (column, row) pixel positions on ``image``.
    scene_box_px : tuple of 4 float
        ``(left, top, right, bottom)`` of the scene area on ``image`` (pixels).
    legend_box_px : tuple of 4 float
        The legend panel's text, the same way.
    label_boxes_px : tuple of tuple of 4 float
        Each label drawn (object names, estimate numbers), the same way.
    """

    image: NDArray[np.uint8]
    to_pixels: Callable[[NDArray[np.float64]], NDArray[np.float64]]
    scene_box_px: tuple[float, float, float, float]
    legend_box_px: tuple[float, float, float, float]
    label_boxes_px: tuple[tuple[float, float, float, float], ...]


def compose(image: NDArray[np.uint8], picture: Picture, projection: Projection,
            size_px: tuple[int, int], scene_px: tuple[int, int]) -> ComposedPicture:
    """The finished picture: the scene image with the overlay, the legend panel and the title.

    Parameters
    ----------
    image : ndarray, shape (scene_h, scene_w, 3) uint8
        The VTK render of the scene area.
    picture : Picture
    projection : Projection
    size_px : (width, height)
        The whole picture (pixels).
    scene_px : (width, height)
        The scene area (pixels), the size of ``image``.

    Returns
    -------
    ComposedPicture
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig_w, fig_h = size_px
    scene_w, scene_h = scene_px
    left, bottom, top, gap = MARGINS_PX
    fig = Figure(figsize=(fig_w / DPI, fig_h / DPI), dpi=DPI, facecolor="white")
    canvas = FigureCanvasAgg(fig)
    # The scene area: centred vertically in the space under the title.
    y0 = bottom + max(0, (fig_h - top - bottom - scene_h) // 2)
    ax = fig.add_axes((left / fig_w, y0 / fig_h, scene_w / fig_w, scene_h / fig_h))
    ax.imshow(image, extent=projection.extent, origin="upper", interpolation="nearest", aspect="auto", zorder=0)
    ax.set_xlim(projection.extent[0], projection.extent[1])
    ax.set_ylim(projection.extent[2], projection.extent[3])
    if projection.metric:
        ax.set_xlabel(f"{projection.axis_names[0]} (m, tank frame)", fontsize=FONT_SIZE)
        ax.set_ylabel(f"{projection.axis_names[1]} (m)", fontsize=FONT_SIZE)
        ax.tick_params(labelsize=FONT_SIZE - 1, direction="out")
        _scale_bar(ax, projection)
    else:
        ax.set_axis_off()
        _dimension_labels(ax, picture, projection)
    fig.text(left / fig_w, 1.0 - 12 / fig_h, picture.title, fontsize=FONT_SIZE + 3, fontweight="bold", va="top")
    if picture.subtitle:
        fig.text(left / fig_w, 1.0 - 30 / fig_h, picture.subtitle, fontsize=FONT_SIZE - 1, color="0.3", va="top")
    for segment in picture.segments:
        if len(segment.starts_m):
            a, b = projection.to_data(segment.starts_m), projection.to_data(segment.ends_m)
            for p, q in zip(a, b):
                ax.plot([p[0], q[0]], [p[1], q[1]], color=segment.color, linewidth=segment.width, zorder=3)
    keep_clear = []
    numbered = []
    for marker in picture.markers:
        xy = projection.to_data(marker.points_m)
        xy = xy[np.all(np.isfinite(xy), axis=1)]
        inside = np.ones(len(xy), dtype=bool)
        if projection.metric:
            xy, inside = _arrows_for_the_outside(ax, xy, projection, marker)
        if marker.numbered:
            numbered += [(str(k + 1), xy[k]) for k in range(len(xy))]
        ax.scatter(xy[inside, 0], xy[inside, 1], s=marker.size**2, marker=marker.marker, edgecolors=[marker.edge],
                   facecolors="none" if marker.face is None else [marker.face], linewidths=1.5, zorder=4)
        keep_clear.append(xy)
    canvas.draw()
    renderer = canvas.get_renderer()
    texts = [(name, projection.to_data(point[None, :])[0], True) for name, point in picture.names]
    texts += [(number, xy, False) for number, xy in numbered]
    texts = [text for text in texts if _on_picture(text[1], projection)]
    labels = _draw_labels(ax, renderer, texts, keep_clear)
    legend_box = _legend_panel(fig, picture, fig_w, fig_h, left + scene_w + gap)
    canvas.draw()
    rgba = np.asarray(canvas.buffer_rgba())
    renderer = canvas.get_renderer()

    def flip(box: Any) -> tuple[float, float, float, float]:
        return (float(box.x0), float(fig_h - box.y1), float(box.x1), float(fig_h - box.y0))

    def to_pixels(points: NDArray[np.float64]) -> NDArray[np.float64]:
        xy = ax.transData.transform(projection.to_data(points))
        return np.column_stack([xy[:, 0], fig_h - xy[:, 1]])

    return ComposedPicture(
        image=np.ascontiguousarray(rgba[:, :, :3]),
        to_pixels=to_pixels,
        scene_box_px=flip(ax.get_window_extent(renderer)),
        legend_box_px=flip(legend_box.get_window_extent(renderer)) if legend_box is not None else (0, 0, 0, 0),
        label_boxes_px=tuple(flip(artist.get_window_extent(renderer)) for artist in labels),
    )


def _arrows_for_the_outside(ax: Any, xy: NDArray[np.float64], projection: Projection,
                            marker: Marker) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
    """Points outside the picture (a metric view) are drawn at its edge as an arrow head
    pointing toward them; returns every point's drawn position (the others unchanged) and
    which were inside."""
    left, right, bottom, top = projection.extent
    inset = 0.012 * np.array([right - left, top - bottom])
    lo, hi = np.array([left, bottom]) + inset, np.array([right, top]) - inset
    clipped = np.clip(xy, lo, hi)
    outside = np.any(np.abs(clipped - xy) > 0, axis=1)
    for point, edge in zip(xy[outside], clipped[outside]):
        direction = point - edge
        glyph = (">" if direction[0] > 0 else "<") if abs(direction[0]) * (top - bottom) >= abs(direction[1]) * (
            right - left) else ("^" if direction[1] > 0 else "v")
        ax.scatter([edge[0]], [edge[1]], s=(1.4 * marker.size) ** 2, marker=glyph, edgecolors=[marker.edge],
                   facecolors=[marker.face if marker.face is not None else (1.0, 1.0, 1.0)], linewidths=1.5, zorder=4)
    return clipped, ~outside


def _on_picture(xy: NDArray[np.float64], projection: Projection) -> bool:
    """Whether a projected point is finite and inside the scene image."""
    left, right, bottom, top = projection.extent
    return bool(np.all(np.isfinite(xy)) and left <= xy[0] <= right and bottom <= xy[1] <= top)


def _draw_labels(ax: Any, renderer: Any, texts: list[tuple[str, NDArray[np.float64], bool]],
                 keep_clear: list[NDArray[np.float64]]) -> list[Any]:
    """Object names (boxed, with a leader line) and estimate numbers, placed by
    :func:`place_labels`; returns the text artists."""
    if not texts:
        return []
    to_px = ax.transData.transform
    anchors = to_px(np.array([xy for _, xy, _ in texts], dtype=float))
    artists = []
    sizes = []
    for label, _, boxed in texts:
        style = dict(boxstyle="round,pad=0.25", facecolor="white", edgecolor="0.4", linewidth=0.6, alpha=0.9) \
            if boxed else dict(boxstyle="round,pad=0.1", facecolor="white", edgecolor="none", alpha=0.75)
        artist = ax.text(0, 0, label, fontsize=FONT_SIZE if boxed else FONT_SIZE - 1, ha="center", va="center",
                         bbox=style, zorder=6, fontweight="normal" if boxed else "bold")
        artists.append(artist)
        extent = artist.get_window_extent(renderer)
        sizes.append((extent.width + 6, extent.height + 4))
    clear = to_px(np.vstack(keep_clear)) if keep_clear else np.empty((0, 2))
    box = ax.get_window_extent(renderer)
    offsets = place_labels(anchors, np.array(sizes), np.vstack([clear, anchors]) if clear.size else anchors,
                           (box.x0, box.y0, box.x1, box.y1))
    inverse = ax.transData.inverted().transform
    for artist, anchor, offset, (_, _, boxed) in zip(artists, anchors, offsets, texts):
        centre = inverse((anchor + offset)[None, :])[0]
        artist.set_position(centre)
        if boxed:
            start = inverse(anchor[None, :])[0]
            ax.annotate("", xy=start, xytext=centre, zorder=5,
                        arrowprops=dict(arrowstyle="-", color="0.35", linewidth=0.7, shrinkA=8, shrinkB=2))
    return artists


def _scale_bar(ax: Any, projection: Projection) -> None:
    from mpl_toolkits.axes_grid1.anchored_artists import AnchoredSizeBar

    width = projection.extent[1] - projection.extent[0]
    length = nice_length(width, 0.1)
    text = f"{length:g} m" if length >= 1 else f"{length * 100:g} cm"
    bar = AnchoredSizeBar(ax.transData, length, text, loc="lower left", pad=0.4, borderpad=0.6, sep=4,
                          frameon=True, size_vertical=0.0, color="black", fontproperties={"size": FONT_SIZE - 1})
    bar.patch.set_alpha(0.85)
    bar.patch.set_edgecolor("0.6")
    bar.size_bar.get_children()[0].set_linewidth(2.5)
    ax.add_artist(bar)


def _dimension_labels(ax: Any, picture: Picture, projection: Projection) -> None:
    """Perspective views: the tank's length, width and depth with their axes ("9 m (x)")
    written on three of its edges: the lowest on the screen along x and along y, the
    left-most vertical one. Without a tank: a scale bar along x under the region."""
    if picture.tank_bounds_m is None:
        _scale_bar_3d(ax, picture, projection)
        return
    lo, hi = np.asarray(picture.tank_bounds_m, dtype=float)
    corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
    px = projection.to_data(corners)
    size = hi - lo
    for axis in range(3):
        others = [a for a in range(3) if a != axis]
        best = None
        for i in range(8):
            for j in range(i + 1, 8):
                d = corners[j] - corners[i]
                if abs(d[axis]) > 0 and all(abs(d[o]) < 1e-12 for o in others):
                    middle = 0.5 * (px[i] + px[j])
                    if not (_on_picture(px[i], projection) and _on_picture(px[j], projection)):
                        continue
                    score = middle[1] if axis != 2 else middle[0]
                    if best is None or score < best[0]:
                        best = (score, middle)
        if best is not None and _on_picture(best[1], projection):
            ax.text(best[1][0], best[1][1], f"{size[axis]:g} m ({'xyz'[axis]})", fontsize=FONT_SIZE, ha="center",
                    va="center", zorder=5,
                    bbox=dict(boxstyle="round,pad=0.2", facecolor="white", edgecolor="0.5", linewidth=0.5))


def _scale_bar_3d(ax: Any, picture: Picture, projection: Projection) -> None:
    """A bar of a round length along the tank frame's x axis from ``picture.scale_start_m``
    (default the region's lower front corner), with its length, drawn in perspective (true
    length at that depth)."""
    lo, hi = np.asarray(picture.region_m, dtype=float)
    length = nice_length(hi[0] - lo[0], 0.3)
    start = np.array([lo[0], lo[1], lo[2]]) if picture.scale_start_m is None else np.asarray(picture.scale_start_m)
    ends = projection.to_data(np.array([start, start + np.array([length, 0.0, 0.0])]))
    ax.plot(ends[:, 0], ends[:, 1], color="black", linewidth=2.5, zorder=5, solid_capstyle="butt")
    middle = ends.mean(axis=0)
    text = f"{length:g} m (x)" if length >= 1 else f"{length * 100:g} cm (x)"
    ax.annotate(text, xy=middle, xytext=(0, -12), textcoords="offset points", ha="center", va="top",
                fontsize=FONT_SIZE, zorder=5)


def _legend_panel(fig: Any, picture: Picture, fig_w: int, fig_h: int, x_px: float) -> Any:
    """The legend by group in a panel right of the scene, and the notes (the numbered
    estimates) under it; returns the legend (None without entries)."""
    handles, labels, headings = legend_handles(picture.legend)
    top_px = MARGINS_PX[2]
    legend_ax = fig.add_axes((x_px / fig_w, 0.02, 1.0 - x_px / fig_w - 0.005, 1.0 - top_px / fig_h - 0.02))
    legend_ax.set_axis_off()
    if handles:
        legend = legend_ax.legend(handles, labels, loc="upper left", frameon=False, fontsize=FONT_SIZE - 0.5,
                                  handlelength=1.8, handletextpad=0.7, labelspacing=0.45, borderaxespad=0.0)
        for k, text in enumerate(legend.get_texts()):
            if k in headings:
                text.set_fontweight("bold")
                text.set_x(-26)  # headings start where the swatches do
    if picture.notes:
        canvas = fig.canvas
        canvas.draw()
        box = legend_ax.get_legend().get_window_extent(canvas.get_renderer()) if handles else None
        y_px = (box.y0 - 14) if box is not None else fig_h - top_px
        fig.text(x_px / fig_w, y_px / fig_h, "\n".join(picture.notes), fontsize=FONT_SIZE - 1.5, va="top",
                 family="monospace", linespacing=1.35)
    return legend_ax.get_legend()
