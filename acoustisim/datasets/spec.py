"""The dataset specification: a TOML file describing the distribution samples are drawn from.

A spec is parsed into frozen dataclasses and validated completely before any work starts:
every problem raises :class:`SpecError` naming the key and the value. Ranges are written as
``[low, high]`` (uniform draw, inclusive) or as one number (fixed). See
``examples/dataset_spec.toml`` for a documented example of every key.

Sections
--------
``[dataset]``  name, n_samples, seed, n_pings, max_arrivals, samples_per_chunk
``[medium]``   water, temperature_c, salinity_ppt
``[tank]``     length_m, width_m, water_depth_m, wall_materials, floor_materials
``[sonar]``    the pose ranges x_m, y_m, z_m, yaw_deg, pitch_deg, roll_deg, and fixed
               overrides of the default sonar (record_length_s, sample_rate_hz, ...)
``[snr]``      snr_db (range, dB) or absent (the receiver chain's own noise)
``[solver]``   fields of :class:`acoustisim.propagation.SolverConfig` (fidelity knobs)
``[placement]`` min_range_m, max_range_m, half_angle_deg, min_gap_m, wall_clearance_m, max_tries
``[[objects]]`` kind, class, count, materials and the kind's size ranges
"""

from __future__ import annotations

import dataclasses
import json
import math
from dataclasses import dataclass
from pathlib import Path
from types import MappingProxyType
from typing import Any, Mapping

import numpy as np

from acoustisim.checks import shown
from acoustisim.errors import InputError
from acoustisim.materials import material_library
from acoustisim.ranges import LENGTH_M

MAX_SPEC_FILE_BYTES = 1 << 20
"""Largest spec file read (bytes)."""

MAX_SAMPLES = 10_000_000
"""Most samples in one dataset: the driver draws every sample's plan before any work."""

MAX_ARRIVALS = 1_000_000
"""Most arrival rows stored per sample (a dense array per sample in every chunk)."""

ARRIVAL_ROW_BYTES = 8 * 24
"""Bytes of one stored arrival row (float64 fields)."""

REFLECTORS_PER_KIND: Mapping[str, int] = MappingProxyType({"sphere": 1, "post": 3, "cylinder": 3, "edge": 5, "plate": 6})
"""Reflecting surfaces of one object of each kind (see :func:`acoustisim.resources.reflector_count`)."""


class SpecError(InputError):
    """A dataset specification that cannot be used; the message names the key and the value."""


@dataclass(frozen=True)
class Range:
    """A uniform distribution on [low, high] (low == high: a fixed value)."""

    low: float
    high: float

    def draw(self, rng: np.random.Generator) -> float:
        """One value; a fixed range consumes no random number."""
        if self.low == self.high:
            return float(self.low)
        return float(rng.uniform(self.low, self.high))


@dataclass(frozen=True)
class IntRange:
    """A uniform distribution on the integers low..high (inclusive)."""

    low: int
    high: int

    def draw(self, rng: np.random.Generator) -> int:
        """One value; a fixed range consumes no random number."""
        if self.low == self.high:
            return int(self.low)
        return int(rng.integers(self.low, self.high + 1))


@dataclass(frozen=True)
class MediumSpec:
    """Water type and the temperature (deg C) and salinity (ppt) ranges."""

    water: str = "fresh"
    temperature_c: Range = Range(20.0, 20.0)
    salinity_ppt: Range = Range(0.0, 0.0)


@dataclass(frozen=True)
class TankSpec:
    """Tank size ranges (m) and the wall/floor materials drawn from (their roughness is the
    material's Lambert scattering strength ``diffuse_mu``)."""

    length_m: Range = Range(9.0, 9.0)
    width_m: Range = Range(3.0, 3.0)
    water_depth_m: Range = Range(1.0, 1.0)
    wall_materials: tuple[str, ...] = ("concrete",)
    floor_materials: tuple[str, ...] = ("concrete",)


@dataclass(frozen=True)
class SonarSpec:
    """Pose ranges of the head (tank frame, m and degrees) and fixed overrides of the default
    sonar (``scenes.builders.default_sonar``), as (key, value) pairs."""

    x_m: Range = Range(1.0, 1.0)
    y_m: Range = Range(1.5, 1.5)
    z_m: Range = Range(0.5, 0.5)
    yaw_deg: Range = Range(0.0, 0.0)
    pitch_deg: Range = Range(0.0, 0.0)
    roll_deg: Range = Range(0.0, 0.0)
    overrides: tuple[tuple[str, Any], ...] = ()


@dataclass(frozen=True)
class PlacementSpec:
    """Where objects may go: a sector ahead of the sonar, clear of walls and of each other.

    Attributes
    ----------
    min_range_m, max_range_m : float
        Horizontal distance from the head to the object's reference point (m); the object's
        bounding circle must also stay ``min_range_m`` clear of the head.
    half_angle_deg : float
        Largest |bearing| from the boresight (degrees).
    min_gap_m : float
        Smallest gap between two objects' bounding spheres/circles (m).
    wall_clearance_m : float
        Smallest gap between an object and the walls, floor and surface (m).
    max_tries : int
        Rejection-sampling tries per object before the sample is declared impossible.
    """

    min_range_m: float = 0.3
    max_range_m: float = 3.0
    half_angle_deg: float = 30.0
    min_gap_m: float = 0.05
    wall_clearance_m: float = 0.05
    max_tries: int = 200


DEFAULT_SAMPLES_PER_CHUNK = 4
"""``[dataset] samples_per_chunk`` when not given: a chunk file's fixed write cost is shared
by 4 samples, and a 2-worker run of a few dozen samples still splits into several tasks per
worker (load balance at the end of a run)."""

OBJECT_KINDS: Mapping[str, tuple[tuple[str, bool], ...]] = {
    # kind: ((range key, required), ...)
    "sphere": (("radius_m", True),),
    "post": (("radius_m", True),),
    "edge": (("interior_angle_deg", True), ("size_m", True), ("facing_jitter_deg", False)),
    "cylinder": (("radius_m", True), ("length_m", True)),
    "plate": (("width_m", True), ("height_m", True), ("thickness_m", True), ("tilt_deg", False)),
}
"""Object kinds a spec may draw, with the range keys each takes."""

CYLINDER_AXES: tuple[str, ...] = ("vertical", "horizontal", "random")


@dataclass(frozen=True)
class ObjectSpec:
    """One ``[[objects]]`` entry: how many objects of one kind, their sizes and materials.

    Attributes
    ----------
    kind : str
        One of :data:`OBJECT_KINDS`.
    label : str
        The class label written to the dataset (``class`` in the file; default: the kind).
    count : IntRange
        Number of such objects per sample.
    materials : tuple of str
        Library materials drawn uniformly.
    ranges : tuple of (str, Range)
        The kind's size and angle ranges (m, degrees); optional ones default to 0.
    axis : str
        Cylinders only: "vertical", "horizontal" (random azimuth) or "random" (isotropic).
    """

    kind: str
    label: str
    count: IntRange
    materials: tuple[str, ...]
    ranges: tuple[tuple[str, Range], ...]
    axis: str = "vertical"

    def range(self, key: str) -> Range:
        """The named range (Range(0, 0) for an optional key not given)."""
        return dict(self.ranges).get(key, Range(0.0, 0.0))


@dataclass(frozen=True)
class DatasetSpec:
    """A whole dataset specification (see the module docstring)."""

    name: str
    n_samples: int
    seed: int
    n_pings: int
    max_arrivals: int
    medium: MediumSpec
    tank: TankSpec
    sonar: SonarSpec
    snr_db: Range | None
    solver: tuple[tuple[str, Any], ...]
    placement: PlacementSpec
    objects: tuple[ObjectSpec, ...]
    samples_per_chunk: int = DEFAULT_SAMPLES_PER_CHUNK
    """Samples per Zarr chunk, the unit of work and of resume (see :mod:`acoustisim.datasets.store`)."""
    source: str = dataclasses.field(default="", compare=False)

    @property
    def max_objects(self) -> int:
        """Most objects one sample can hold (sum of the largest counts)."""
        return sum(o.count.high for o in self.objects)

    @property
    def class_names(self) -> tuple[str, ...]:
        """Class labels in order of first appearance in ``[[objects]]``."""
        return tuple(dict.fromkeys(o.label for o in self.objects))

    def to_dict(self) -> dict[str, Any]:
        """A JSON-ready canonical form (the dataset card's ``spec``; compared on resume)."""
        data = dataclasses.asdict(self)
        data.pop("source", None)
        return json.loads(json.dumps(data))


# ----------------------------------------------------------------------------- parsing
def _finite(value: Any) -> bool:
    """A real number (not a bool) that converts to a finite float."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        return False
    try:
        return math.isfinite(float(value))
    except OverflowError:
        return False


def _where(source: str, key: str) -> str:
    return f"{source}: {key}" if source else key


class _Reader:
    """Pops keys from one TOML table, naming ``section.key`` in every error."""

    def __init__(self, table: Any, section: str, source: str) -> None:
        if not isinstance(table, dict):
            raise SpecError(f"{_where(source, section)} = {table!r}: expected a table")
        self.table = dict(table)
        self.section = section
        self.source = source

    def key(self, key: str) -> str:
        return _where(self.source, f"{self.section}.{key}" if self.section else key)

    def fail(self, key: str, value: Any, problem: str) -> SpecError:
        return SpecError(f"{self.key(key)} = {shown(value)}: {problem}")

    def number(self, key: str, default: float | None = None, *, positive: bool = False, minimum: float | None = None) -> float:
        if key not in self.table:
            if default is None:
                raise SpecError(f"{self.key(key)}: required key missing")
            return float(default)
        value = self.table.pop(key)
        if not _finite(value):
            raise self.fail(key, value, "expected a finite number")
        if positive and value <= 0:
            raise self.fail(key, value, "must be > 0")
        if minimum is not None and value < minimum:
            raise self.fail(key, value, f"must be >= {minimum}")
        return float(value)

    def integer(self, key: str, default: int | None = None, *, minimum: int = 0, maximum: int | None = None,
                reason: str = "") -> int:
        if key not in self.table:
            if default is None:
                raise SpecError(f"{self.key(key)}: required key missing")
            return int(default)
        value = self.table.pop(key)
        if isinstance(value, bool) or not isinstance(value, int):
            raise self.fail(key, value, "expected an integer")
        if value < minimum:
            raise self.fail(key, value, f"must be >= {minimum}")
        if maximum is not None and value > maximum:
            raise self.fail(key, value, f"must be <= {maximum:,}" + (f" ({reason})" if reason else ""))
        return int(value)

    def string(self, key: str, default: str | None = None, choices: tuple[str, ...] | None = None) -> str:
        if key not in self.table:
            if default is None:
                raise SpecError(f"{self.key(key)}: required key missing")
            return default
        value = self.table.pop(key)
        if not isinstance(value, str) or not value:
            raise self.fail(key, value, "expected a non-empty string")
        if choices is not None and value not in choices:
            raise self.fail(key, value, f"unknown value (choose from {', '.join(choices)})")
        return value

    def range(
        self, key: str, default: tuple[float, float] | None = None, *, positive: bool = False,
        minimum: float | None = None, maximum: float | None = None,
    ) -> Range:
        if key not in self.table:
            if default is None:
                raise SpecError(f"{self.key(key)}: required key missing")
            return Range(float(default[0]), float(default[1]))
        value = self.table.pop(key)
        pair = [value, value] if isinstance(value, (int, float)) and not isinstance(value, bool) else value
        if not isinstance(pair, list) or len(pair) != 2 or not all(_finite(v) for v in pair):
            raise self.fail(key, value, "expected a number or a [low, high] pair of finite numbers")
        low, high = float(pair[0]), float(pair[1])
        if low > high:
            raise self.fail(key, value, "empty range (low > high)")
        if positive and low <= 0:
            raise self.fail(key, value, "must be > 0")
        if minimum is not None and low < minimum:
            raise self.fail(key, value, f"must be >= {minimum}")
        if maximum is not None and high > maximum:
            raise self.fail(key, value, f"must be <= {maximum}")
        return Range(low, high)

    def length(self, key: str, default: tuple[float, float] | None = None) -> Range:
        """A range of sizes (m), inside :data:`acoustisim.ranges.LENGTH_M`."""
        r = self.range(key, default, positive=True)
        if not (LENGTH_M.contains(r.low) and LENGTH_M.contains(r.high)):
            raise self.fail(key, [r.low, r.high], LENGTH_M.describe())
        return r

    def int_range(self, key: str, default: tuple[int, int]) -> IntRange:
        if key not in self.table:
            return IntRange(*default)
        value = self.table.pop(key)
        pair = [value, value] if isinstance(value, int) and not isinstance(value, bool) else value
        if not isinstance(pair, list) or len(pair) != 2 or any(isinstance(v, bool) or not isinstance(v, int) for v in pair):
            raise self.fail(key, value, "expected an integer or a [low, high] pair of integers")
        if pair[0] > pair[1]:
            raise self.fail(key, value, "empty range (low > high)")
        if pair[0] < 0:
            raise self.fail(key, value, "must be >= 0")
        return IntRange(int(pair[0]), int(pair[1]))

    def materials(self, key: str, default: tuple[str, ...]) -> tuple[str, ...]:
        if key not in self.table:
            return default
        value = self.table.pop(key)
        names = [value] if isinstance(value, str) else value
        if not isinstance(names, list) or not names or not all(isinstance(v, str) for v in names):
            raise self.fail(key, value, "expected a non-empty list of material names")
        library = material_library()
        for name in names:
            if name not in library:
                raise self.fail(key, value, f"unknown material {name!r} (known: {', '.join(sorted(library))})")
        return tuple(names)

    def done(self) -> None:
        if self.table:
            key = sorted(self.table)[0]
            raise self.fail(key, self.table[key], "unknown key")


def _sonar_overrides(reader: _Reader) -> tuple[tuple[str, Any], ...]:
    """The fixed sonar keys left in ``[sonar]`` after the pose ranges, checked against SonarHead."""
    from acoustisim.sonar import SonarHead

    allowed = {f.name for f in dataclasses.fields(SonarHead)} - {
        "position_m", "yaw_deg", "pitch_deg", "roll_deg", "custom_pulse", "channel_positions_m",
    }
    overrides = []
    for key in sorted(reader.table):
        if key not in allowed:
            raise reader.fail(key, reader.table[key], f"unknown key (pose ranges: x_m, y_m, z_m, yaw_deg, pitch_deg, "
                              f"roll_deg; fixed: {', '.join(sorted(allowed))})")
        value = reader.table.pop(key)
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise reader.fail(key, value, "expected a number")
        overrides.append((key, value))
    try:
        from scenes.builders import default_sonar

        dataclasses.replace(default_sonar(), **dict(overrides))
    except (ValueError, TypeError) as exc:
        raise SpecError(_section_message(reader, exc)) from None
    return tuple(overrides)


def _section_message(reader: _Reader, exc: Exception) -> str:
    """``file: section.key ...: problem`` from a constructor's error, naming the section once
    (the constructors already write ``section.key`` in their messages)."""
    text = str(exc)
    prefix = f"{reader.section}."
    return _where(reader.source, text if text.startswith(prefix) else f"{reader.section}: {text}")


def _solver_options(reader: _Reader) -> tuple[tuple[str, Any], ...]:
    """``[solver]`` keys, checked by building a ``SolverConfig`` from them."""
    from acoustisim.propagation.config import SolverConfig

    allowed = {f.name for f in dataclasses.fields(SolverConfig)} - {"seed"}
    options = []
    for key in sorted(reader.table):
        value = reader.table.pop(key)
        if key not in allowed:
            raise reader.fail(key, value, f"unknown key (known: {', '.join(sorted(allowed))})")
        options.append((key, tuple(value) if isinstance(value, list) else value))
    try:
        SolverConfig(**dict(options))
    except (ValueError, TypeError) as exc:
        raise SpecError(_section_message(reader, exc)) from None
    return tuple(options)


def bounding_radius_m(obj: ObjectSpec) -> float:
    """Radius (m) of the bounding sphere (posts and edges: bounding circle in plan) of the
    smallest object ``obj`` can draw, as :mod:`acoustisim.datasets.sampling` places it."""
    low = {key: r.low for key, r in obj.ranges}
    if obj.kind in ("sphere", "post"):
        return low["radius_m"]
    if obj.kind == "cylinder":
        return math.hypot(low["radius_m"], 0.5 * low["length_m"])
    if obj.kind == "plate":
        return 0.5 * math.sqrt(low["width_m"] ** 2 + low["height_m"] ** 2 + low["thickness_m"] ** 2)
    # Edge: the prism's triangle (apex at the edge, two sides of size_m), circle about its centroid.
    size = low["size_m"]
    radii = []
    for angle in (obj.range("interior_angle_deg").low, obj.range("interior_angle_deg").high):
        half = math.radians(angle) / 2.0
        vertices = np.array([[0.0, 0.0], [size * math.cos(half), size * math.sin(half)],
                             [size * math.cos(half), -size * math.sin(half)]])
        radii.append(float(np.linalg.norm(vertices - vertices.mean(axis=0), axis=1).max()))
    return min(radii)


def check_objects_fit(objects: tuple[ObjectSpec, ...], tank: TankSpec, placement: PlacementSpec,
                      source: str = "") -> None:
    """Refuse an object that cannot fit in the smallest tank even at its smallest size.

    Placement would otherwise try ``placement.max_tries`` poses and blame that key.

    Raises
    ------
    SpecError
        Naming the object's size key and its value, the room it needs and the room there is.
    """
    clear = placement.wall_clearance_m
    for index, obj in enumerate(objects):
        if obj.count.high == 0:
            continue
        radius = bounding_radius_m(obj)
        need = 2.0 * (radius + clear)
        limits = [("length_m", tank.length_m.low), ("width_m", tank.width_m.low)]
        if obj.kind not in ("post", "edge"):  # posts and edges run from the floor to the surface
            limits.append(("water_depth_m", tank.water_depth_m.low))
        key = next(k for k, _ in OBJECT_KINDS[obj.kind] if k != "interior_angle_deg")
        for name, available in limits:
            if need > available:
                value = obj.range(key)
                shown = value.low if value.low == value.high else [value.low, value.high]
                raise SpecError(
                    f"{_where(source, f'objects[{index}].{key}')} = {shown!r}: even the smallest {obj.kind} "
                    f"drawn (bounding radius {radius:.3g} m) needs {need:.3g} m of water across with "
                    f"placement.wall_clearance_m = {clear:g}, more than the smallest tank's "
                    f"tank.{name} = {available:g} m")


def _object_spec(table: Any, index: int, source: str) -> ObjectSpec:
    reader = _Reader(table, f"objects[{index}]", source)
    kind = reader.string("kind", choices=tuple(OBJECT_KINDS))
    label = reader.string("class", default=kind)
    count = reader.int_range("count", (1, 1))
    default_material = {"post": "pvc", "cylinder": "pvc"}.get(kind, "steel")
    materials = reader.materials("materials", (default_material,))
    ranges = []
    for key, required in OBJECT_KINDS[kind]:
        angle = key.endswith("_deg")
        if required:
            if key == "interior_angle_deg":
                r = reader.range(key, minimum=1.0, maximum=179.0)
            else:
                r = reader.length(key)
        elif key in reader.table:
            r = reader.range(key, minimum=-180.0 if angle else None, maximum=180.0 if angle else None)
        else:
            continue
        ranges.append((key, r))
    axis = reader.string("axis", default="vertical", choices=CYLINDER_AXES) if kind == "cylinder" else "vertical"
    reader.done()
    return ObjectSpec(kind, label, count, materials, tuple(ranges), axis)


def parse_spec(data: Mapping[str, Any], source: str = "") -> DatasetSpec:
    """Validate a parsed TOML mapping into a :class:`DatasetSpec`.

    Parameters
    ----------
    data : mapping
        The TOML document (``tomllib.loads`` output).
    source : str
        File name used in error messages.

    Raises
    ------
    SpecError
        Naming the first bad key and its value.
    """
    top = _Reader(data, "", source)
    sections = {}
    for name in ("dataset", "medium", "tank", "sonar", "snr", "solver", "placement"):
        sections[name] = _Reader(top.table.pop(name, {}), name, source)
    objects_raw = top.table.pop("objects", None)
    top.done()

    d = sections["dataset"]
    name = d.string("name", default="dataset")
    n_samples = d.integer("n_samples", minimum=1, maximum=MAX_SAMPLES,
                          reason="the driver plans every sample before any work")
    seed = d.integer("seed", minimum=0, maximum=2**63 - 1)
    n_pings = d.integer("n_pings", default=1, minimum=1)
    max_arrivals = d.integer("max_arrivals", default=1024, minimum=1, maximum=MAX_ARRIVALS,
                             reason="each sample stores this many rows")
    samples_per_chunk = d.integer("samples_per_chunk", default=DEFAULT_SAMPLES_PER_CHUNK, minimum=1)
    d.done()

    m = sections["medium"]
    water = m.string("water", default="fresh", choices=("fresh", "sea"))
    medium = MediumSpec(
        water,
        m.range("temperature_c", (20.0, 20.0), minimum=0.0, maximum=40.0),
        m.range("salinity_ppt", (0.0, 0.0), minimum=0.0, maximum=45.0),
    )
    m.done()

    t = sections["tank"]
    tank = TankSpec(
        t.length("length_m", (9.0, 9.0)),
        t.length("width_m", (3.0, 3.0)),
        t.length("water_depth_m", (1.0, 1.0)),
        t.materials("wall_materials", ("concrete",)),
        t.materials("floor_materials", ("concrete",)),
    )
    t.done()

    s = sections["sonar"]
    sonar_ranges = {
        "x_m": s.range("x_m", (1.0, 1.0)),
        "y_m": s.range("y_m", (1.5, 1.5)),
        "z_m": s.range("z_m", (0.5, 0.5)),
        "yaw_deg": s.range("yaw_deg", (0.0, 0.0), minimum=-360.0, maximum=360.0),
        "pitch_deg": s.range("pitch_deg", (0.0, 0.0), minimum=-90.0, maximum=90.0),
        "roll_deg": s.range("roll_deg", (0.0, 0.0), minimum=-180.0, maximum=180.0),
    }
    for key, limit in (("x_m", tank.length_m.low), ("y_m", tank.width_m.low), ("z_m", tank.water_depth_m.low)):
        r = sonar_ranges[key]
        if r.low <= 0.0 or r.high >= limit:
            raise s.fail(key, [r.low, r.high], f"the head must stay inside the smallest tank (0, {limit}) m")
    sonar = SonarSpec(**sonar_ranges, overrides=_sonar_overrides(s))

    snr_reader = sections["snr"]
    snr_db = snr_reader.range("snr_db", minimum=-60.0, maximum=200.0) if "snr_db" in snr_reader.table else None
    snr_reader.done()

    solver = _solver_options(sections["solver"])

    p = sections["placement"]
    placement = PlacementSpec(
        min_range_m=p.number("min_range_m", 0.3, minimum=0.0),
        max_range_m=p.number("max_range_m", 3.0, positive=True),
        half_angle_deg=p.number("half_angle_deg", 30.0, minimum=0.0),
        min_gap_m=p.number("min_gap_m", 0.05, minimum=0.0),
        wall_clearance_m=p.number("wall_clearance_m", 0.05, minimum=0.0),
        max_tries=p.integer("max_tries", 200, minimum=1),
    )
    if placement.max_range_m <= placement.min_range_m:
        raise p.fail("max_range_m", placement.max_range_m, f"empty range (must exceed min_range_m = {placement.min_range_m})")
    if placement.half_angle_deg > 180.0:
        raise p.fail("half_angle_deg", placement.half_angle_deg, "must be <= 180")
    p.done()

    if objects_raw is None:
        objects_raw = []
    if not isinstance(objects_raw, list):
        raise SpecError(f"{_where(source, 'objects')} = {objects_raw!r}: expected an array of tables [[objects]]")
    objects = tuple(_object_spec(table, i, source) for i, table in enumerate(objects_raw))
    check_objects_fit(objects, tank, placement, source)

    spec = DatasetSpec(
        name=name,
        n_samples=n_samples,
        seed=seed,
        n_pings=n_pings,
        max_arrivals=max_arrivals,
        medium=medium,
        tank=tank,
        sonar=sonar,
        snr_db=snr_db,
        solver=solver,
        placement=placement,
        objects=objects,
        samples_per_chunk=samples_per_chunk,
        source=source,
    )
    check_spec_resources(spec)
    return spec


def _worst_triangles(obj: ObjectSpec) -> int:
    """Triangles of the largest object an ``[[objects]]`` entry can draw."""
    from scenes.tessellation import circle_segments, icosphere_subdivisions

    if obj.kind == "sphere":
        return 20 * 4 ** icosphere_subdivisions(obj.range("radius_m").high)
    if obj.kind in ("post", "cylinder"):
        return 4 * circle_segments(obj.range("radius_m").high)
    return 8 if obj.kind == "edge" else 12


def check_spec_resources(spec: DatasetSpec) -> None:
    """The pre-flight of a dataset: the sampling of its sonar, and the worst sample and chunk
    against the limits in force (:func:`acoustisim.resources.current_limits`; a worker checks
    every sample again when it simulates it).

    Raises
    ------
    SpecError
        The message names the spec file, the estimate and the limit.
    """
    from acoustisim.preflight import check_resources, check_sampling
    from acoustisim.propagation.config import SolverConfig
    from acoustisim.resources import PATH_ROW_BYTES, ResourceEstimate, chain_bound, current_limits, signal_estimate
    from scenes.builders import default_sonar

    where = spec.source or spec.name
    sonar = dataclasses.replace(default_sonar(), **dict(spec.sonar.overrides))
    config = SolverConfig(**dict(spec.solver))
    try:
        check_sampling(sonar, source=f"{where}: [sonar]")
        signal = signal_estimate(sonar, spec.n_pings)
        chunk = spec.samples_per_chunk
        reflectors = 6 + sum(REFLECTORS_PER_KIND[o.kind] * o.count.high for o in spec.objects)
        mechanisms = tuple(config.mechanisms)
        rays = int(config.diffuse_rays) * int(config.diffuse_bounces) if "diffuse" in mechanisms else 0
        triangles = sum(_worst_triangles(o) * o.count.high for o in spec.objects)
        estimate = ResourceEstimate(
            n_pings=spec.n_pings, n_samples=signal.n_samples,
            recording_bytes=chunk * (signal.recording_bytes + spec.max_arrivals * ARRIVAL_ROW_BYTES),
            synthesis_bytes=signal.synthesis_bytes, path_rows=3 + 3 * rays, path_table_bytes=(3 + 3 * rays) * PATH_ROW_BYTES,
            objects=spec.max_objects, triangles=triangles, rays=rays, reflectors=reflectors,
            max_order=int(config.max_order),
            chains=chain_bound(reflectors, int(config.max_order)) if "specular" in mechanisms else 0.0)
        check_resources(estimate, current_limits(), sonar, source=where, pings_key="[dataset] n_pings",
                        order_key="[solver] max_order", flags=False)
    except InputError as exc:
        raise SpecError(str(exc)) from None


def loads_spec(text: str, source: str = "") -> DatasetSpec:
    """Parse and validate spec text (TOML): bounded nesting, every key checked, the pre-flight."""
    from scenes.scene_file import parse_toml

    try:
        data = parse_toml(text, source or "spec")
    except InputError as exc:
        raise SpecError(str(exc)) from None
    return parse_spec(data, source)


def load_spec(path: str | Path) -> DatasetSpec:
    """Read and validate a spec file (a regular file of at most :data:`MAX_SPEC_FILE_BYTES`)."""
    from scenes.file_access import path_text, read_regular_file, shown_path

    try:
        text_path = path_text(path, "spec file")
        source = shown_path(text_path)
        raw = read_regular_file(text_path, max_bytes=MAX_SPEC_FILE_BYTES, label=source)
    except InputError as exc:
        message = str(exc)
        raise SpecError(message.replace(": no such file", ": spec file not found")) from None
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise SpecError(f"{source}: cannot read (not UTF-8 text: {exc.reason} at byte {exc.start})") from None
    return loads_spec(text, text_path)


def spec_from_dict(data: Mapping[str, Any]) -> DatasetSpec:
    """Rebuild a spec from :meth:`DatasetSpec.to_dict` output (as stored in a dataset card)."""

    def rng(v: Mapping[str, float]) -> Range:
        return Range(float(v["low"]), float(v["high"]))

    def pairs(items: Any) -> tuple[tuple[str, Any], ...]:
        return tuple((k, tuple(v) if isinstance(v, list) else v) for k, v in items)

    sonar = dict(data["sonar"])
    return DatasetSpec(
        name=data["name"],
        n_samples=int(data["n_samples"]),
        seed=int(data["seed"]),
        n_pings=int(data["n_pings"]),
        max_arrivals=int(data["max_arrivals"]),
        medium=MediumSpec(data["medium"]["water"], rng(data["medium"]["temperature_c"]), rng(data["medium"]["salinity_ppt"])),
        tank=TankSpec(
            rng(data["tank"]["length_m"]), rng(data["tank"]["width_m"]), rng(data["tank"]["water_depth_m"]),
            tuple(data["tank"]["wall_materials"]), tuple(data["tank"]["floor_materials"]),
        ),
        sonar=SonarSpec(
            **{k: rng(sonar[k]) for k in ("x_m", "y_m", "z_m", "yaw_deg", "pitch_deg", "roll_deg")},
            overrides=pairs(sonar["overrides"]),
        ),
        snr_db=None if data["snr_db"] is None else rng(data["snr_db"]),
        solver=pairs(data["solver"]),
        placement=PlacementSpec(**data["placement"]),
        objects=tuple(
            ObjectSpec(
                o["kind"], o["label"], IntRange(int(o["count"]["low"]), int(o["count"]["high"])),
                tuple(o["materials"]), tuple((k, rng(v)) for k, v in o["ranges"]), o["axis"],
            )
            for o in data["objects"]
        ),
        samples_per_chunk=int(data.get("samples_per_chunk", DEFAULT_SAMPLES_PER_CHUNK)),
    )
