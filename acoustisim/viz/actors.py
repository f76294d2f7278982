"""Layers for the 3-D view: tank, objects, sonar head and beam, paths, time-of-flight
ellipsoids, localisation estimates against the truth.

Every builder returns a list of :class:`~acoustisim.viz.layers.Layer` in the tank frame (m).
Paths are drawn as ONE merged line mesh per kind (direct, specular, edge, diffuse) with a
per-segment colour whose opacity fades with the path's amplitude, so tens of thousands of
paths make four actors, not tens of thousands.
"""

from __future__ import annotations

import math
import zlib
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from types import MappingProxyType

import numpy as np
import pyvista as pv
from numpy.typing import NDArray

from acoustisim.propagation.paths import PathKind, Paths
from acoustisim.scene import Scene
from acoustisim.sonar import CHANNEL_NAMES, SonarHead
from acoustisim.viz.beam import piston_beam_angles
from acoustisim.viz.layers import RGBA_ARRAY, Layer

RGB = tuple[float, float, float]

# The palette: Okabe & Ito's eight colours, distinguishable with every common colour-vision
# deficiency (Okabe M., Ito K., "Color Universal Design", 2008), one meaning each, plus greys.
OKABE_ITO: Mapping[str, RGB] = MappingProxyType({
    "black": (0.0, 0.0, 0.0),
    "orange": (0.902, 0.624, 0.0),
    "sky blue": (0.337, 0.706, 0.914),
    "bluish green": (0.0, 0.620, 0.451),
    "yellow": (0.941, 0.894, 0.259),
    "blue": (0.0, 0.447, 0.698),
    "vermillion": (0.835, 0.369, 0.0),
    "reddish purple": (0.800, 0.475, 0.655),
})

KIND_COLORS: Mapping[PathKind, RGB] = MappingProxyType({
    PathKind.DIRECT: OKABE_ITO["black"],
    PathKind.SPECULAR: OKABE_ITO["blue"],
    PathKind.EDGE: OKABE_ITO["vermillion"],
    PathKind.DIFFUSE: (0.75, 0.75, 0.75),
})
"""Colour of each path kind: the discrete echoes in strong colours, the diffuse reverberation
(thousands of weak rays) in grey."""

PATH_DRAW_ORDER: tuple[PathKind, ...] = (PathKind.DIFFUSE, PathKind.SPECULAR, PathKind.EDGE, PathKind.DIRECT)
"""Order the path layers are drawn in (translucent lines: the later on top): the diffuse
background first, so that it never covers an echo's path."""

CHANNEL_COLORS: tuple[RGB, RGB, RGB] = (OKABE_ITO["orange"], OKABE_ITO["bluish green"], OKABE_ITO["sky blue"])
"""Left, centre (the transmitter), right: the transducers and their time-of-flight ellipses."""

MATERIAL_COLORS: Mapping[str, RGB] = MappingProxyType({
    # Dark, low-saturation tones: objects must stand out on the light tank floor and must not
    # be mistaken for the palette's meanings (paths, receivers, beam, estimates).
    "concrete": (0.62, 0.62, 0.58),
    "glass": (0.45, 0.62, 0.66),
    "pvc": (0.48, 0.40, 0.33),
    "pvc-pipe-air": (0.54, 0.45, 0.36),
    "pvc-pipe-water": (0.42, 0.34, 0.28),
    "steel": (0.28, 0.31, 0.36),
    "steel-machined": (0.36, 0.40, 0.46),
    "aluminium": (0.52, 0.55, 0.60),
    "rubber": (0.15, 0.15, 0.15),
    "sand": (0.70, 0.62, 0.44),
    "rigid": (0.35, 0.35, 0.40),
    "pressure-release": (0.50, 0.66, 0.80),
    "air": (0.50, 0.66, 0.80),
})

DIFFUSE_OPACITY_SCALE = 0.25
"""Opacity factor of diffuse paths relative to discrete echoes of the same amplitude."""

EDGE_GROUP_WEIGHT = 20.0
"""With edge elements drawn one by one, a diffraction's opacity is spread as if over this many lines."""

ESTIMATE_COLOR: RGB = OKABE_ITO["yellow"]
"""Estimates: yellow markers with a black outline (and yellow error ellipsoids)."""
TRUTH_COLOR: RGB = OKABE_ITO["black"]
BEAM_COLOR: RGB = OKABE_ITO["reddish purple"]
SIDE_LOBE_COLOR: RGB = (0.86, 0.62, 0.76)
WALL_COLOR: RGB = (0.62, 0.72, 0.82)
SURFACE_COLOR: RGB = (0.70, 0.85, 0.95)
OUTLINE_COLOR: RGB = (0.15, 0.25, 0.40)


def material_color(name: str) -> RGB:
    """A fixed colour per material; unknown materials get a stable colour from their name."""
    if name in MATERIAL_COLORS:
        return MATERIAL_COLORS[name]
    hue = (zlib.crc32(name.encode()) % 360) / 360.0
    import colorsys

    r, g, b = colorsys.hsv_to_rgb(hue, 0.55, 0.75)
    return (r, g, b)


# ------------------------------------------------------------------------------ geometry helpers
def scene_bounds(scene: Scene, sonar: SonarHead | None = None, pad_m: float = 0.25) -> NDArray[np.float64]:
    """The region to show (2, 3) (m): the tank's water, or in free field the objects and the sonar
    padded by ``pad_m``."""
    if scene.tank is not None:
        return scene.tank.bounds_m
    sonar = scene.sonar if sonar is None else sonar
    points = [sonar.receiver_positions]
    points += [obj.bounds_m for obj in scene.objects]
    allp = np.vstack(points)
    return np.array([allp.min(axis=0) - pad_m, allp.max(axis=0) + pad_m])


def _ray_box_exit(origin: NDArray[np.float64], direction: NDArray[np.float64], bounds: NDArray[np.float64]) -> float:
    """Distance (m) from ``origin`` (inside ``bounds``) along unit ``direction`` to the box's boundary."""
    with np.errstate(divide="ignore", invalid="ignore"):
        t_hi = (bounds[1] - origin) / direction
        t_lo = (bounds[0] - origin) / direction
    t = np.where(direction > 0, t_hi, np.where(direction < 0, t_lo, np.inf))
    return float(np.min(t))


def _clip_to_box(mesh: pv.PolyData, bounds: NDArray[np.float64]) -> pv.PolyData:
    """The part of a mesh inside the axis-aligned box ``bounds`` (2, 3)."""
    lo, hi = bounds
    inside = mesh.points
    if np.all((inside >= lo - 1e-9) & (inside <= hi + 1e-9)):
        return mesh
    clipped = mesh.clip_box([lo[0], hi[0], lo[1], hi[1], lo[2], hi[2]], invert=False)
    return clipped.extract_surface(algorithm=None) if clipped.n_points else pv.PolyData()


def _orthonormal_frame(axis: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Two unit vectors orthogonal to unit ``axis`` and to each other."""
    helper = np.array([0.0, 0.0, 1.0]) if abs(axis[2]) < 0.9 else np.array([1.0, 0.0, 0.0])
    e2 = np.cross(axis, helper)
    e2 /= np.linalg.norm(e2)
    return e2, np.cross(axis, e2)


def ellipsoid_mesh(center_m: NDArray[np.float64], axes: NDArray[np.float64], resolution: int = 48) -> pv.PolyData:
    """An ellipsoid x = center + axes @ u over the unit sphere u.

    Parameters
    ----------
    center_m : ndarray, shape (3,)
    axes : ndarray, shape (3, 3)
        Columns are the semi-axis vectors (m).
    """
    sphere = pv.Sphere(radius=1.0, theta_resolution=resolution, phi_resolution=max(8, resolution // 2))
    unit = np.asarray(sphere.points, dtype=float)
    unit /= np.linalg.norm(unit, axis=1, keepdims=True)  # the sphere's float32 points, back on |u| = 1
    points = unit @ np.asarray(axes, dtype=float).T + np.asarray(center_m, dtype=float)
    return pv.PolyData(points, faces=np.asarray(sphere.faces))


def _cylinder(center: NDArray[np.float64], direction: NDArray[np.float64], radius: float, height: float) -> pv.PolyData:
    return pv.Cylinder(center=center, direction=direction, radius=radius, height=height, resolution=32).triangulate()


# ------------------------------------------------------------------------------------ the tank
def tank_layers(scene: Scene) -> list[Layer]:
    """Translucent walls and floor, their outline, and the free surface (nothing in free field)."""
    if scene.tank is None:
        return []
    walls = [b.mesh for b in scene.boundaries if b.kind != "surface"]
    surface = [b.mesh for b in scene.boundaries if b.kind == "surface"]
    wall_mesh = pv.merge([pv.wrap(m) for m in walls]) if walls else pv.PolyData()
    lo, hi = scene.tank.bounds_m
    outline = pv.Box(bounds=(lo[0], hi[0], lo[1], hi[1], lo[2], hi[2])).extract_feature_edges(
        boundary_edges=False, non_manifold_edges=False, feature_angle=60, manifold_edges=False
    )
    layers = [
        Layer("tank-walls", wall_mesh, WALL_COLOR, 0.12, "surface", label=f"walls, floor ({scene.tank.wall_material})",
              group="tank"),
        Layer("tank-outline", outline, OUTLINE_COLOR, 1.0, "lines", line_width=2.0, group="tank"),
    ]
    if surface:
        layers.append(Layer("free-surface", pv.wrap(surface[0]), SURFACE_COLOR, 0.10, "surface",
                            label="free surface", group="tank"))
    return layers


def object_layers(scene: Scene) -> list[Layer]:
    """One opaque layer per object ("object:<name>"), coloured by material; the legend names each
    material once, with the objects made of it ("pvc: post-1, post-2")."""
    by_material: dict[str, list[str]] = {}
    for obj in scene.objects:
        by_material.setdefault(obj.material.name, []).append(obj.name)
    layers = []
    seen: set[str] = set()
    for obj in scene.objects:
        material = obj.material.name
        label = "" if material in seen else f"{material}: {', '.join(by_material[material])}"
        seen.add(material)
        layers.append(Layer(f"object:{obj.name}", pv.wrap(obj.mesh), material_color(material), 1.0, "surface",
                            label=label, group="object"))
    return layers


# ------------------------------------------------------------------------------------ the sonar
def sonar_layers(sonar: SonarHead) -> list[Layer]:
    """The head's body, its three transducers (short cylinders along their axes, the centre one
    the transmitter) and a marker of fixed pixel size so the sonar shows at tank scale."""
    boresight = sonar.boresight
    a = sonar.piston_radius_m
    depth = 4.0 * a
    positions = sonar.receiver_positions
    layers = []
    for channel, name in enumerate(CHANNEL_NAMES):
        cyl = _cylinder(positions[channel] - 0.5 * depth * boresight, boresight, a, depth)
        role = "transmitter/receiver" if channel == 1 else "receiver"
        layers.append(Layer(f"transducer-{name}", cyl, CHANNEL_COLORS[channel], 1.0, "surface",
                            label=f"{name} {role}", group="sonar"))
    head = sonar.channel_positions_head
    lo = head.min(axis=0) + np.array([-2.0 * a, -depth - 8.0 * a, -1.5 * a])
    hi = head.max(axis=0) + np.array([2.0 * a, 0.0, 1.5 * a])
    lo[1] = min(lo[1], -depth - 8.0 * a)
    hi[1] = lo[1] + 8.0 * a
    body = pv.Box(bounds=(lo[0], hi[0], lo[1], hi[1], lo[2], hi[2])).triangulate()
    body.points = sonar.head_to_tank(np.asarray(body.points, dtype=float))
    layers.append(Layer("sonar-head", body, (0.25, 0.25, 0.28), 1.0, "surface", group="sonar"))
    marker = pv.PolyData(positions)
    marker.point_data["channel"] = np.arange(3)
    layers.append(Layer("sonar-marker", marker, (0.1, 0.1, 0.1), 1.0, "points", point_size=9.0, group="sonar"))
    return layers


def cone_lines(apex_m: NDArray[np.float64], axis: NDArray[np.float64], half_angle_deg: float,
               bounds: NDArray[np.float64], n_generators: int = 4, resolution: int = 72) -> pv.PolyData:
    """A cone drawn as lines: ``n_generators`` straight generators from the apex to where they
    leave ``bounds`` (2, 3) (m), and the rim circle where the axis leaves it (clipped to
    ``bounds``).

    Lines instead of a surface: a translucent cone covers whatever lies in the beam (the
    targets). With 4 generators in the head's horizontal and vertical planes, a top or side
    view shows the beam's wedge and its axis.
    """
    axis = np.asarray(axis, dtype=float) / np.linalg.norm(axis)
    apex = np.asarray(apex_m, dtype=float)
    horizontal = np.cross(np.array([0.0, 0.0, 1.0]), axis)
    e2 = horizontal / np.linalg.norm(horizontal) if np.linalg.norm(horizontal) > 1e-9 else _orthonormal_frame(axis)[0]
    e3 = np.cross(axis, e2)
    tan = math.tan(math.radians(half_angle_deg))
    points, lines = [], []
    for phi in np.linspace(0.0, 2.0 * math.pi, n_generators, endpoint=False):
        direction = axis + tan * (math.cos(phi) * e2 + math.sin(phi) * e3)
        direction /= np.linalg.norm(direction)
        length = _ray_box_exit(apex, direction, bounds)
        if math.isfinite(length) and length > 0:
            lines.append([2, len(points), len(points) + 1])
            points += [apex, apex + length * direction]
    axial = _ray_box_exit(apex, axis, bounds)
    if math.isfinite(axial) and axial > 0:
        phi = np.linspace(0.0, 2.0 * math.pi, resolution + 1)
        ring = (apex + axial * axis)[None, :] + axial * tan * (np.cos(phi)[:, None] * e2 + np.sin(phi)[:, None] * e3)
        inside = np.all((ring >= bounds[0] - 1e-9) & (ring <= bounds[1] + 1e-9), axis=1)
        for k in np.flatnonzero(inside[:-1] & inside[1:]):  # arcs of the rim inside the box
            lines.append([2, len(points), len(points) + 1])
            points += [ring[k], ring[k + 1]]
    if not lines:
        return pv.PolyData()
    return pv.PolyData(np.asarray(points, dtype=float), lines=np.asarray(lines).ravel())


def beam_layers(sonar: SonarHead, sound_speed_m_s: float, bounds: NDArray[np.float64]) -> list[Layer]:
    """The transmit beam's -3 dB cone and first side-lobe cone, from the piston formula, drawn
    as lines (:func:`cone_lines`) inside ``bounds`` (2, 3) (m)."""
    angles = piston_beam_angles(sonar.piston_radius_m, sonar.centre_frequency_hz, sound_speed_m_s)
    apex = sonar.transmitter_position
    axis = sonar.boresight
    main = cone_lines(apex, axis, angles.half_power_deg, bounds)
    if main.n_points == 0:
        return []
    layers = [
        Layer("beam-3db", main, BEAM_COLOR, 1.0, "lines", line_width=1.6,
              label=f"transmit beam, -3 dB ({angles.half_power_deg:.1f} deg)", group="beam"),
    ]
    if angles.side_lobe_deg is not None and angles.side_lobe_db is not None:
        layers.append(
            Layer("beam-side-lobe", cone_lines(apex, axis, angles.side_lobe_deg, bounds), SIDE_LOBE_COLOR, 1.0,
                  "lines", line_width=1.0,
                  label=f"1st side lobe ({angles.side_lobe_deg:.1f} deg, {angles.side_lobe_db:.1f} dB)", group="beam")
        )
    return layers


# ------------------------------------------------------------------------------------- the paths
def path_amplitudes(paths: Paths) -> NDArray[np.float64]:
    """The amplitude drawn for each row: the ``amplitude`` column, or |geometric_gain| when the
    amplitude column is all zero (paths built without directivity)."""
    amplitude = np.abs(np.asarray(paths["amplitude"], dtype=float))
    if not np.any(amplitude > 0):
        amplitude = np.abs(np.asarray(paths["geometric_gain"], dtype=float))
    return amplitude


def path_opacity(amplitude: NDArray[np.float64], reference: float, dynamic_range_db: float = 40.0,
                 min_opacity: float = 0.04) -> NDArray[np.float64]:
    """Opacity in [min_opacity, 1] rising linearly with level in dB over ``dynamic_range_db`` below
    ``reference`` (rows at or above the reference are opaque)."""
    with np.errstate(divide="ignore"):
        level_db = 20.0 * np.log10(np.maximum(amplitude, 1e-300) / reference)
    t = np.clip(1.0 + level_db / dynamic_range_db, 0.0, 1.0)
    return min_opacity + (1.0 - min_opacity) * t


def path_polylines(paths: Paths, sonar: SonarHead) -> tuple[NDArray[np.float64], NDArray[np.int64], NDArray[np.int64]]:
    """Every row as a polyline transmitter -> interaction points -> its receiver.

    Returns
    -------
    points : ndarray, shape (m, 3)
        Vertices (m).
    segments : ndarray, shape (k, 2)
        Vertex indices of each straight segment.
    segment_row : ndarray, shape (k,)
        The row of ``paths`` each segment belongs to.
    """
    rows = paths.rows
    n = rows.size
    chain = np.empty((n, 6, 3))
    chain[:, 0] = sonar.transmitter_position
    chain[:, 1:5] = rows["points_m"]
    chain[:, 5] = sonar.receiver_positions[np.clip(rows["channel"].astype(int), 0, 2)]
    valid = np.all(np.isfinite(chain), axis=2)
    row_of_vertex = np.nonzero(valid)[0]
    points = chain[valid]
    same = row_of_vertex[1:] == row_of_vertex[:-1]
    start = np.flatnonzero(same)
    segments = np.column_stack([start, start + 1]).astype(np.int64)
    return points, segments, row_of_vertex[start]


def path_layers(paths: Paths, sonar: SonarHead, *, channels: Sequence[int] = (0, 1, 2), max_paths: int | None = 10_000,
                dynamic_range_db: float = 40.0, edge_elements: bool = False,
                max_diffuse: int | None = 400) -> list[Layer]:
    """One merged line layer per path kind ("paths-direct", "paths-specular", "paths-edge",
    "paths-diffuse"), opacity fading with amplitude.

    Parameters
    ----------
    paths : Paths
    sonar : SonarHead
        The sonar the paths were traced for (its transmitter and receivers close each path).
    channels : sequence of int
        Receiver channels to draw (0 left, 1 centre, 2 right).
    max_paths : int or None
        Draw only the strongest rows (None: all).
    dynamic_range_db : float
        Rows this far below the strongest echo are drawn at the minimum opacity. The reference is
        the strongest non-direct row (the direct transmitter-receiver coupling would otherwise
        fade every echo).
    edge_elements : bool
        Draw every discretised element of an edge diffraction (a fan along the edge) instead of
        one polyline per arrival through its least-time point, with the group's amplitude
        (:meth:`Paths.arrivals`).
    max_diffuse : int or None
        Of the diffuse rows, draw only this many strongest (None: all). The diffuse rows are a
        random sample of the scattering (the solver's thousands of rays): a few hundred show
        the fan; thousands, all starting at the transmitter, paint a solid area over the
        targets and the echoes. The legend gives both counts.
    """
    if len(paths) == 0:
        return []
    if not edge_elements:
        paths = Paths(paths.arrivals(), paths.surface_names, paths.centre_frequency_hz, paths.sound_speed_m_s)
    rows_mask = np.isin(paths["channel"], np.asarray(channels, dtype=int))
    selected = paths.select(rows_mask)
    amplitude = path_amplitudes(selected)
    if max_paths is not None and len(selected) > max_paths:
        keep = np.sort(np.argpartition(-amplitude, max_paths - 1)[:max_paths])
        mask = np.zeros(len(selected), dtype=bool)
        mask[keep] = True
        selected = selected.select(mask)
        amplitude = amplitude[mask]
    if len(selected) == 0:
        return []
    kinds = np.asarray(selected["kind"], dtype=int)
    total = {kind: int(np.count_nonzero(kinds == kind)) for kind in PathKind}
    diffuse = np.flatnonzero(kinds == PathKind.DIFFUSE)
    if max_diffuse is not None and diffuse.size > max_diffuse:
        weakest = diffuse[np.argsort(-amplitude[diffuse], kind="stable")[max_diffuse:]]
        mask = np.ones(len(selected), dtype=bool)
        mask[weakest] = False
        selected = selected.select(mask)
        amplitude = amplitude[mask]
        kinds = kinds[mask]
    echoes = amplitude[kinds != PathKind.DIRECT]
    reference = float(echoes.max()) if echoes.size and echoes.max() > 0 else float(max(amplitude.max(), 1e-300))
    alpha = path_opacity(amplitude, reference, dynamic_range_db)
    # Diffuse rows are a random sample of the scattering whose size is a solver setting
    # (thousands of rays): drawn fainter so that their number does not paint over the echoes.
    alpha = np.where(kinds == PathKind.DIFFUSE, DIFFUSE_OPACITY_SCALE * alpha, alpha)
    if edge_elements:
        # A diffraction drawn element by element gets the visual weight of about
        # EDGE_GROUP_WEIGHT lines whatever the discretisation step (else it is a solid fan).
        group_key = selected["path_id"].astype(np.int64) * 8 + selected["channel"]
        _, inverse, counts = np.unique(group_key, return_inverse=True, return_counts=True)
        group_size = counts[inverse]
        alpha = np.where(kinds == PathKind.EDGE, alpha * np.minimum(1.0, EDGE_GROUP_WEIGHT / group_size), alpha)
    points, segments, segment_row = path_polylines(selected, sonar)
    layers = []
    for kind in PATH_DRAW_ORDER:
        seg_mask = kinds[segment_row] == kind
        if not np.any(seg_mask):
            continue
        seg = segments[seg_mask]
        used, inverse = np.unique(seg.ravel(), return_inverse=True)
        local = inverse.reshape(-1, 2)
        lines = np.column_stack([np.full(len(local), 2), local]).ravel()
        mesh = pv.PolyData(points[used], lines=lines)
        rgba = np.empty((len(local), 4), dtype=np.uint8)
        rgba[:, :3] = np.round(np.asarray(KIND_COLORS[kind]) * 255).astype(np.uint8)
        rgba[:, 3] = np.round(alpha[segment_row[seg_mask]] * 255).astype(np.uint8)
        mesh.cell_data[RGBA_ARRAY] = rgba
        n_rows = int(np.count_nonzero(kinds == kind))
        count = f"{n_rows:,}" if n_rows == total[kind] else f"{n_rows:,} strongest of {total[kind]:,}"
        layers.append(Layer(f"paths-{kind.label}", mesh, KIND_COLORS[kind], 1.0, "lines",
                            line_width=0.8 if kind == PathKind.DIFFUSE else 1.3,
                            label=f"{kind.label} paths ({count})", group="paths"))
    return layers


# ---------------------------------------------------------------------- time-of-flight ellipsoids
@dataclass(frozen=True)
class EchoChoice:
    """One echo seen on the receivers: its total path length per channel.

    Attributes
    ----------
    index : int
        Rank of the echo among the centre channel's specular and edge arrivals, by delay.
    path_length_m : ndarray, shape (3,)
        Transmitter-to-receiver path length (m) per channel (NaN where the echo was not found).
    points_m : ndarray, shape (k, 3)
        The echo's interaction points on the centre channel (m).
    label : str
        Kind and surfaces, e.g. "specular: post-1".
    """

    index: int
    path_length_m: NDArray[np.float64]
    points_m: NDArray[np.float64]
    label: str


def choose_echo(paths: Paths, index: int | str) -> EchoChoice:
    """The ``index``-th discrete echo (by delay) on the centre channel and the same arrival on
    the others.

    Discrete echoes are the specular and edge arrivals: the direct coupling is no echo and the
    diffuse rows are reverberation (thousands of weak scatterers).

    The same arrival on another channel is the row with the same ``path_id``; when the solver
    numbers channels separately, the row of the same kind and surfaces with the nearest delay.

    Parameters
    ----------
    paths : Paths
    index : int or str
        The echo's rank by delay, or a surface name: the earliest single-interaction echo
        off that surface.

    Raises
    ------
    IndexError
        When there are fewer echoes than ``index + 1``, or none off the named surface.
    """
    arrivals = paths.arrivals()
    discrete = np.isin(arrivals["kind"], (PathKind.SPECULAR, PathKind.EDGE))
    centre = arrivals[(arrivals["channel"] == 1) & discrete]
    centre = centre[np.argsort(centre["delay_s"], kind="stable")]
    if isinstance(index, str):
        if index not in paths.surface_names:
            raise IndexError(f"echo {index!r}: no surface of that name (surfaces: {', '.join(paths.surface_names)})")
        hits = np.flatnonzero((centre["order"] == 1) & (centre["object_ids"][:, 0] == paths.surface_names.index(index)))
        if hits.size == 0:
            raise IndexError(f"echo {index!r}: no single-bounce echo off {index!r} on the centre channel")
        index = int(hits[0])
    if not 0 <= index < centre.size:
        raise IndexError(f"echo {index} does not exist: the centre channel has {centre.size} specular or edge echoes")
    row = centre[index]
    lengths = np.full(3, np.nan)
    for channel in range(3):
        on_channel = arrivals[arrivals["channel"] == channel]
        match = on_channel[on_channel["path_id"] == row["path_id"]]
        if match.size == 0:
            same = (on_channel["kind"] == row["kind"]) & np.all(on_channel["object_ids"] == row["object_ids"], axis=1)
            match = on_channel[same]
        if match.size:
            best = match[np.argmin(np.abs(match["delay_s"] - row["delay_s"]))]
            lengths[channel] = float(best["delay_s"]) * paths.sound_speed_m_s
    points = row["points_m"][np.all(np.isfinite(row["points_m"]), axis=1)]
    names = [paths.surface_names[i] for i in row["object_ids"] if 0 <= i < len(paths.surface_names)]
    label = f"{PathKind(int(row['kind'])).label}: {'>'.join(names) if names else '?'}"
    return EchoChoice(index, lengths, points, label)


def tof_ellipsoid(transmitter_m: NDArray[np.float64], receiver_m: NDArray[np.float64], path_length_m: float,
                  resolution: int = 96) -> pv.PolyData:
    """The locus of points P with |P - transmitter| + |P - receiver| = path_length_m.

    A prolate spheroid with foci at the transmitter and the receiver: semi-major axis L/2 along
    the focal axis, semi-minor sqrt((L/2)^2 - (f/2)^2), f the focal distance; a sphere of radius
    L/2 when the receiver is the transmitter.

    Raises
    ------
    ValueError
        When ``path_length_m`` is shorter than the focal distance.
    """
    tx = np.asarray(transmitter_m, dtype=float)
    rx = np.asarray(receiver_m, dtype=float)
    focal = float(np.linalg.norm(rx - tx))
    if not path_length_m > focal:
        raise ValueError(f"path length {path_length_m!r} m is not longer than the focal distance {focal:.4g} m")
    semi_major = 0.5 * path_length_m
    semi_minor = math.sqrt(semi_major**2 - (0.5 * focal) ** 2)
    axis = (rx - tx) / focal if focal > 0 else np.array([1.0, 0.0, 0.0])
    e2, e3 = _orthonormal_frame(axis)
    axes = np.column_stack([semi_major * axis, semi_minor * e2, semi_minor * e3])
    return ellipsoid_mesh(0.5 * (tx + rx), axes, resolution)


def tof_layers(paths: Paths, sonar: SonarHead, echo: int | str, bounds: NDArray[np.float64]) -> list[Layer]:
    """For echo ``echo`` (see :func:`choose_echo`): each receiver's time-of-flight ellipsoid,
    clipped to ``bounds``, its ellipse in the horizontal plane of the transmitter, and the echo's
    interaction points."""
    choice = choose_echo(paths, echo)
    tx = sonar.transmitter_position
    layers = []
    for channel, name in enumerate(CHANNEL_NAMES):
        length = choice.path_length_m[channel]
        if not np.isfinite(length):
            continue
        ellipsoid = tof_ellipsoid(tx, sonar.receiver_positions[channel], float(length))
        color = CHANNEL_COLORS[channel]
        layers.append(Layer(f"tof-{name}", _clip_to_box(ellipsoid, bounds), color, 0.07, "surface",
                            group="tof"))
        ellipse = ellipsoid.slice(normal=(0.0, 0.0, 1.0), origin=tuple(tx))
        if ellipse.n_points:
            layers.append(Layer(f"tof-ellipse-{name}", _clip_to_box(ellipse, bounds), color, 1.0, "lines",
                                line_width=2.0, label=f"time-of-flight ellipse, {name}", group="tof"))
    if choice.points_m.size:
        layers.append(Layer("echo-point", pv.PolyData(choice.points_m), (0.0, 0.0, 0.0), 1.0, "points",
                            point_size=12.0, label=f"echo {choice.index} ({choice.label})", group="tof"))
    return layers


# ------------------------------------------------------------------------- estimates and truth
@dataclass(frozen=True)
class EstimateMarker:
    """One localised target in the tank frame.

    Attributes
    ----------
    position_m : ndarray, shape (3,)
    covariance_m2 : ndarray, shape (3, 3), or None
        Position covariance in the tank frame (m^2).
    cls : str
        "point", "cylinder", "plane" or "unknown".
    label : str
    """

    position_m: NDArray[np.float64]
    covariance_m2: NDArray[np.float64] | None = None
    cls: str = "unknown"
    label: str = ""


@dataclass(frozen=True)
class TruthMarker:
    """A true target position (tank frame, m) and its name."""

    position_m: NDArray[np.float64]
    name: str = ""


def _nice_magnification(factor: float) -> float:
    """The smallest of 1, 2, 5 x 10^n not below ``factor`` (1 when factor <= 1)."""
    if factor <= 1.0:
        return 1.0
    exponent = math.floor(math.log10(factor))
    for step in (1.0, 2.0, 5.0, 10.0):
        if step * 10.0**exponent >= factor:
            return step * 10.0**exponent
    return 10.0 ** (exponent + 1)


def estimate_layers(estimates: Sequence[EstimateMarker], truths: Sequence[TruthMarker], *, n_sigma: float = 2.0,
                    magnification: float | None = None, view_size_m: float = 1.0,
                    match_radius_m: float = 0.25) -> list[Layer]:
    """Estimated targets (markers and ``n_sigma`` error ellipsoids) against the truth (markers),
    each estimate joined by a line to its nearest true target within ``match_radius_m`` (an
    estimate with none, e.g. a wall echo, stays unjoined).

    Parameters
    ----------
    estimates, truths : sequences of EstimateMarker, TruthMarker
    n_sigma : float
        Ellipsoid semi-axes are ``n_sigma`` standard deviations along the covariance's principal
        axes.
    magnification : float or None
        Scale of the drawn ellipsoids (stated in the legend). None picks the smallest of
        1, 2, 5 x 10^n that makes the largest ellipsoid at least 2 % of ``view_size_m``:
        millimetre errors are invisible at tank scale otherwise.
    view_size_m : float
        Size of the shown region (m), for the automatic magnification.
    """
    layers: list[Layer] = []
    if estimates:
        positions = np.array([e.position_m for e in estimates], dtype=float).reshape(-1, 3)
        layers.append(Layer("estimates", pv.PolyData(positions), ESTIMATE_COLOR, 1.0, "points", point_size=11.0,
                            label=f"estimates ({len(estimates)})", group="estimate"))
        axes_list = []
        for est in estimates:
            if est.covariance_m2 is None:
                continue
            cov = 0.5 * (np.asarray(est.covariance_m2, dtype=float) + np.asarray(est.covariance_m2, dtype=float).T)
            values, vectors = np.linalg.eigh(cov)
            axes_list.append((est.position_m, vectors * (n_sigma * np.sqrt(np.clip(values, 0.0, None)))[None, :]))
        if axes_list:
            largest = max(float(np.max(np.linalg.norm(ax, axis=0))) for _, ax in axes_list)
            mag = magnification if magnification is not None else (
                _nice_magnification(0.02 * view_size_m / largest) if largest > 0 else 1.0)
            # A zero variance (a 2-D estimate's z) would make a flat disc: give it a floor so the
            # mesh stays a closed surface (1e-4 of the largest axis, invisible).
            meshes = []
            for center, ax in axes_list:
                norms = np.linalg.norm(ax, axis=0)
                floor = 1e-4 * largest
                ax = np.where(norms[None, :] < floor, np.eye(3) * floor, ax)
                meshes.append(ellipsoid_mesh(np.asarray(center, dtype=float), mag * ax, 32))
            scale = "" if mag == 1.0 else f" x{mag:g}"
            layers.append(Layer("estimate-ellipsoids", pv.merge(meshes), (0.80, 0.70, 0.05), 0.55, "surface",
                                label=f"{n_sigma:g}-sigma error ellipsoids{scale}", group="estimate"))
    if truths:
        truth_positions = np.array([t.position_m for t in truths], dtype=float).reshape(-1, 3)
        # Larger than the estimates' markers and flat, so a coincident estimate (a sphere, drawn
        # in front) leaves a frame of truth around it.
        layers.append(Layer("truth", pv.PolyData(truth_positions), TRUTH_COLOR, 1.0, "points", point_size=17.0,
                            flat_points=True,
                            label=f"true positions ({len(truths)})", group="truth"))
        if estimates:
            positions = np.array([e.position_m for e in estimates], dtype=float).reshape(-1, 3)
            distance = np.linalg.norm(positions[:, None, :] - truth_positions[None, :, :], axis=2)
            nearest = np.argmin(distance, axis=1)
            matched = np.flatnonzero(distance[np.arange(len(positions)), nearest] <= match_radius_m)
            if matched.size:
                points = np.vstack([positions[matched], truth_positions[nearest[matched]]])
                n = matched.size
                lines = np.column_stack([np.full(n, 2), np.arange(n), n + np.arange(n)]).ravel()
                layers.append(Layer("estimate-errors", pv.PolyData(points, lines=lines), (0.2, 0.2, 0.2), 1.0,
                                    "lines", line_width=1.5, group="estimate"))
    return layers
