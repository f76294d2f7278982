"""Draw one sample's scene, sonar pose and SNR from the spec, from the sample's own seed.

Sample ``i`` of a spec with seed ``s`` is drawn from
``numpy.random.default_rng(SeedSequence([s, i]).spawn(2)[0])``, its simulation (noise,
diffuse rays) seeded from the second child: sample ``i`` is the same whatever the worker
count, the order of execution or which samples an interrupted run already made.

Placement is rejection sampling, vectorised over the tries: each object draws
``placement.max_tries`` candidate poses at once and keeps the first that fits (inside the
tank with ``wall_clearance_m``, ``min_gap_m`` clear of the head and of every object placed
before it). When none fits, :class:`~acoustisim.datasets.spec.SpecError` names the object
entry and the placement keys; :func:`plan_samples` draws every sample before any simulation
starts, so an impossible spec fails before any work.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any, Iterable

import numpy as np
from numpy.typing import NDArray

from acoustisim.datasets.spec import DatasetSpec, ObjectSpec, SpecError


@dataclass(frozen=True)
class PlacedObject:
    """One drawn object.

    Attributes
    ----------
    name : str
        ``object-<slot>``, slot = position in the sample's object list.
    kind, label, material : str
        Builder kind, class label and library material.
    parameters : tuple of (str, value)
        The builder's arguments (m, degrees), e.g. ("center_m", (x, y, z)), ("radius_m", r).
    reference_m : tuple of 3 float
        The point a sonar localises (tank frame, m): the centre of a sphere, cylinder or
        plate; the axis of a post and the sharp edge of a prism at the head's height.
    bound_center_m : tuple of 3 float
        Centre of the bounding sphere (vertical objects: bounding circle at any height) (m).
    bound_radius_m : float
        Its radius (m).
    vertical : bool
        True for floor-to-surface objects (posts, edges): collisions are tested in plan view.
    """

    name: str
    kind: str
    label: str
    material: str
    parameters: tuple[tuple[str, Any], ...]
    reference_m: tuple[float, float, float]
    bound_center_m: tuple[float, float, float]
    bound_radius_m: float
    vertical: bool


@dataclass(frozen=True)
class SampleDescription:
    """Everything drawn for one sample (numbers only; meshes are built by :func:`build_scene`).

    Attributes
    ----------
    index : int
        Sample index in the dataset.
    water : str
    temperature_c, salinity_ppt : float
    tank_m : tuple of 3 float
        Length, width, water depth (m).
    wall_material, floor_material : str
    pose : tuple of 6 float
        x_m, y_m, z_m, yaw_deg, pitch_deg, roll_deg of the head (tank frame).
    snr_db : float or None
    simulation_seed : int
        Seed of the simulation (noise, diffuse rays).
    objects : tuple of PlacedObject
    """

    index: int
    water: str
    temperature_c: float
    salinity_ppt: float
    tank_m: tuple[float, float, float]
    wall_material: str
    floor_material: str
    pose: tuple[float, float, float, float, float, float]
    snr_db: float | None
    simulation_seed: int
    objects: tuple[PlacedObject, ...]

    def to_json(self) -> dict[str, Any]:
        """A JSON-ready dictionary (the ``scene_json`` stored with the sample)."""
        return dataclasses.asdict(self)


def sample_seeds(seed: int, index: int) -> tuple[np.random.Generator, int]:
    """The scene generator and the simulation seed of sample ``index``."""
    scene_seq, simulation_seq = np.random.SeedSequence([seed, index]).spawn(2)
    simulation_seed = int(simulation_seq.generate_state(1, np.uint64)[0] >> np.uint64(1))
    return np.random.default_rng(scene_seq), simulation_seed


def _choice(rng: np.random.Generator, options: tuple[str, ...]) -> str:
    return options[0] if len(options) == 1 else options[int(rng.integers(len(options)))]


def _uniform(rng: np.random.Generator, low: float, high: float, n: int) -> NDArray[np.float64]:
    return np.full(n, low) if low == high else rng.uniform(low, high, n)


def _candidates(
    spec: DatasetSpec,
    obj: ObjectSpec,
    rng: np.random.Generator,
    pose: tuple[float, ...],
    depth: float,
) -> tuple[dict[str, Any], dict[str, NDArray[np.float64]]]:
    """Draw an object's size once and ``max_tries`` candidate poses (vectorised)."""
    p = spec.placement
    n = p.max_tries
    sizes = {key: r.draw(rng) for key, r in obj.ranges}
    rng_m = _uniform(rng, p.min_range_m, p.max_range_m, n)
    bearing = np.radians(_uniform(rng, -p.half_angle_deg, p.half_angle_deg, n))
    azimuth = math.radians(pose[3]) - bearing  # bearing is positive toward the right receiver
    x = pose[0] + rng_m * np.cos(azimuth)
    y = pose[1] + rng_m * np.sin(azimuth)
    clear = p.wall_clearance_m
    kind = obj.kind
    cand: dict[str, NDArray[np.float64]] = {"x": x, "y": y}
    toward_sonar = np.arctan2(pose[1] - y, pose[0] - x)  # azimuth from the object to the head (rad)
    if kind in ("post", "edge"):
        cand["z"] = np.full(n, pose[2])
        cand["vertical"] = np.ones(n, bool)
        if kind == "post":
            cand["bx"], cand["by"], cand["R"] = x, y, np.full(n, sizes["radius_m"])
        else:
            facing = toward_sonar + np.radians(_uniform(rng, *_lh(obj, "facing_jitter_deg"), n))
            back = facing + np.pi
            half = math.radians(sizes["interior_angle_deg"]) / 2.0
            size = sizes["size_m"]
            vx = np.stack([x, x + size * np.cos(back + half), x + size * np.cos(back - half)])
            vy = np.stack([y, y + size * np.sin(back + half), y + size * np.sin(back - half)])
            cx, cy = vx.mean(axis=0), vy.mean(axis=0)
            cand["bx"], cand["by"] = cx, cy
            cand["R"] = np.sqrt((vx - cx) ** 2 + (vy - cy) ** 2).max(axis=0)
            cand["facing_deg"] = np.degrees(facing)
    else:
        if kind == "sphere":
            radius = np.full(n, sizes["radius_m"])
        elif kind == "cylinder":
            radius = np.full(n, math.hypot(sizes["radius_m"], 0.5 * sizes["length_m"]))
            if obj.axis == "vertical":
                axis = np.tile([0.0, 0.0, 1.0], (n, 1))
            elif obj.axis == "horizontal":
                phi = rng.uniform(0.0, 2.0 * np.pi, n)
                axis = np.column_stack([np.cos(phi), np.sin(phi), np.zeros(n)])
            else:
                v = rng.standard_normal((n, 3))
                axis = v / np.linalg.norm(v, axis=1, keepdims=True)
            cand["axis"] = axis
        else:  # plate, its normal toward the head, turned by the tilt
            radius = np.full(n, 0.5 * math.sqrt(sizes["width_m"] ** 2 + sizes["height_m"] ** 2 + sizes["thickness_m"] ** 2))
            normal_az = toward_sonar + np.radians(_uniform(rng, *_lh(obj, "tilt_deg"), n))
            cand["normal"] = np.column_stack([np.cos(normal_az), np.sin(normal_az), np.zeros(n)])
        low, high = clear + radius, depth - clear - radius
        cand["z"] = low + rng.uniform(0.0, 1.0, n) * (high - low)
        cand["z_ok"] = high >= low
        cand["vertical"] = np.zeros(n, bool)
        cand["bx"], cand["by"], cand["R"] = x, y, radius
    return sizes, cand


def _lh(obj: ObjectSpec, key: str) -> tuple[float, float]:
    r = obj.range(key)
    return r.low, r.high


def _valid(
    spec: DatasetSpec,
    cand: dict[str, NDArray[np.float64]],
    tank: tuple[float, float, float],
    pose: tuple[float, ...],
    placed: list[PlacedObject],
) -> NDArray[np.bool_]:
    """Which candidates fit in the tank, clear of the head and of the objects placed so far."""
    p = spec.placement
    bx, by, bz, R, vertical = cand["bx"], cand["by"], cand["z"], cand["R"], cand["vertical"]
    clear = p.wall_clearance_m
    ok = (bx - R >= clear) & (bx + R <= tank[0] - clear) & (by - R >= clear) & (by + R <= tank[1] - clear)
    if "z_ok" in cand:
        ok &= cand["z_ok"]
    horizontal_to_head = np.hypot(bx - pose[0], by - pose[1])
    to_head = np.where(vertical, horizontal_to_head, np.hypot(horizontal_to_head, bz - pose[2]))
    ok &= to_head - R >= max(p.min_gap_m, 1e-3)
    for other in placed:
        ox, oy, oz = other.bound_center_m
        d_xy = np.hypot(bx - ox, by - oy)
        d = d_xy if other.vertical else np.where(vertical, d_xy, np.hypot(d_xy, bz - oz))
        ok &= d >= R + other.bound_radius_m + p.min_gap_m
    return ok


def _place(
    spec: DatasetSpec, entry: int, obj: ObjectSpec, rng: np.random.Generator, slot: int,
    tank: tuple[float, float, float], pose: tuple[float, ...], placed: list[PlacedObject], sample: int,
) -> PlacedObject:
    sizes, cand = _candidates(spec, obj, rng, pose, tank[2])
    material = _choice(rng, obj.materials)
    hits = np.flatnonzero(_valid(spec, cand, tank, pose, placed))
    if hits.size == 0:
        p = spec.placement
        drawn = ", ".join(f"{k} = {v:.4g}" for k, v in sizes.items())
        raise SpecError(
            f"{spec.source + ': ' if spec.source else ''}placement.max_tries = {p.max_tries}: sample {sample} could not "
            f"place objects[{entry}] (kind {obj.kind!r}, {drawn}) with {len(placed)} object(s) already placed, "
            f"range {p.min_range_m}-{p.max_range_m} m, half_angle_deg = {p.half_angle_deg}, in a "
            f"{tank[0]:.3g} x {tank[1]:.3g} x {tank[2]:.3g} m tank; widen [placement] or reduce the count/size"
        )
    k = int(hits[0])
    x, y, z = float(cand["x"][k]), float(cand["y"][k]), float(cand["z"][k])
    name = f"object-{slot}"
    if obj.kind == "sphere":
        params: tuple[tuple[str, Any], ...] = (("center_m", (x, y, z)), ("radius_m", sizes["radius_m"]))
    elif obj.kind == "post":
        params = (("center_m", (x, y)), ("radius_m", sizes["radius_m"]))
    elif obj.kind == "edge":
        params = (
            ("edge_m", (x, y)),
            ("interior_angle_deg", sizes["interior_angle_deg"]),
            ("facing_deg", float(cand["facing_deg"][k])),
            ("size_m", sizes["size_m"]),
        )
    elif obj.kind == "cylinder":
        axis = tuple(float(v) for v in cand["axis"][k])
        params = (("center_m", (x, y, z)), ("axis", axis), ("radius_m", sizes["radius_m"]), ("length_m", sizes["length_m"]))
    else:
        normal = tuple(float(v) for v in cand["normal"][k])
        params = (
            ("center_m", (x, y, z)),
            ("normal", normal),
            ("width_m", sizes["width_m"]),
            ("height_m", sizes["height_m"]),
            ("thickness_m", sizes["thickness_m"]),
        )
    return PlacedObject(
        name=name,
        kind=obj.kind,
        label=obj.label,
        material=material,
        parameters=params,
        reference_m=(x, y, z),
        bound_center_m=(float(cand["bx"][k]), float(cand["by"][k]), z),
        bound_radius_m=float(cand["R"][k]),
        vertical=bool(cand["vertical"][k]),
    )


def draw_sample(spec: DatasetSpec, index: int) -> SampleDescription:
    """Draw sample ``index`` (independent of every other sample).

    Raises
    ------
    SpecError
        When an object cannot be placed in ``placement.max_tries`` tries.
    """
    if not 0 <= index < spec.n_samples:
        raise SpecError(f"sample index {index} outside 0..{spec.n_samples - 1} (dataset.n_samples)")
    rng, simulation_seed = sample_seeds(spec.seed, index)
    temperature = spec.medium.temperature_c.draw(rng)
    salinity = spec.medium.salinity_ppt.draw(rng)
    tank = (spec.tank.length_m.draw(rng), spec.tank.width_m.draw(rng), spec.tank.water_depth_m.draw(rng))
    wall = _choice(rng, spec.tank.wall_materials)
    floor = _choice(rng, spec.tank.floor_materials)
    s = spec.sonar
    pose = (s.x_m.draw(rng), s.y_m.draw(rng), s.z_m.draw(rng), s.yaw_deg.draw(rng), s.pitch_deg.draw(rng), s.roll_deg.draw(rng))
    snr_db = None if spec.snr_db is None else spec.snr_db.draw(rng)
    placed: list[PlacedObject] = []
    for entry, obj in enumerate(spec.objects):
        for _ in range(obj.count.draw(rng)):
            placed.append(_place(spec, entry, obj, rng, len(placed), tank, pose, placed, index))
    return SampleDescription(
        index=index,
        water=spec.medium.water,
        temperature_c=temperature,
        salinity_ppt=salinity,
        tank_m=tank,
        wall_material=wall,
        floor_material=floor,
        pose=pose,  # type: ignore[arg-type]
        snr_db=snr_db,
        simulation_seed=simulation_seed,
        objects=tuple(placed),
    )


def plan_samples(spec: DatasetSpec, indices: Iterable[int] | None = None) -> list[SampleDescription]:
    """Draw the given samples (default: all) before any simulation; raises on the first
    impossible one."""
    chosen = range(spec.n_samples) if indices is None else indices
    return [draw_sample(spec, int(i)) for i in chosen]


def build_scene(spec: DatasetSpec, sample: SampleDescription):  # -> acoustisim.scene.Scene
    """The :class:`acoustisim.scene.Scene` of a drawn sample (meshes built by ``scenes.builders``)."""
    from acoustisim.medium import Medium
    from acoustisim.scene import Scene, Tank
    from scenes import builders

    length, width, depth = sample.tank_m
    tank = Tank(length, width, depth, wall_material=sample.wall_material, floor_material=sample.floor_material)
    medium = Medium(water=sample.water, temperature_c=sample.temperature_c, salinity_ppt=sample.salinity_ppt,
                    depth_m=0.5 * depth)
    sonar = dataclasses.replace(builders.default_sonar(), **dict(spec.sonar.overrides))
    x, y, z, yaw, pitch, roll = sample.pose
    sonar = sonar.with_pose((x, y, z), yaw, pitch, roll)
    objects = []
    for obj in sample.objects:
        kw = dict(obj.parameters)
        if obj.kind == "sphere":
            objects.append(builders.sphere(obj.name, kw["center_m"], kw["radius_m"], obj.material))
        elif obj.kind == "post":
            objects.append(builders.post(obj.name, kw["center_m"], kw["radius_m"], depth, obj.material))
        elif obj.kind == "edge":
            objects.append(builders.edge_prism(obj.name, kw["edge_m"], kw["interior_angle_deg"], kw["facing_deg"],
                                               kw["size_m"], depth, obj.material))
        elif obj.kind == "cylinder":
            objects.append(builders.cylinder(obj.name, kw["center_m"], kw["axis"], kw["radius_m"], kw["length_m"],
                                             obj.material))
        else:
            objects.append(builders.plate(obj.name, kw["center_m"], kw["normal"], kw["width_m"], kw["height_m"],
                                          kw["thickness_m"], obj.material))
    return Scene(name=f"{spec.name}-{sample.index}", medium=medium, sonar=sonar, tank=tank, objects=tuple(objects))
