"""Dataset spec validation and per-sample drawing (no simulation: fast)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from acoustisim.datasets.sampling import draw_sample, plan_samples
from acoustisim.datasets.spec import SpecError, load_spec, loads_spec, spec_from_dict

ROOT = Path(__file__).resolve().parents[2]
EXAMPLE = ROOT / "examples" / "dataset_spec.toml"

BASE = """
[dataset]
n_samples = 40
seed = 3
[sonar]
x_m = [0.8, 1.2]
y_m = [1.2, 1.8]
yaw_deg = [-20.0, 20.0]
record_length_s = 0.002
[solver]
max_order = 1
[placement]
min_range_m = 0.3
max_range_m = 2.0
half_angle_deg = 20.0
min_gap_m = 0.05
wall_clearance_m = 0.05
[[objects]]
kind = "sphere"
count = [1, 3]
radius_m = [0.02, 0.08]
[[objects]]
kind = "post"
count = [0, 2]
radius_m = [0.01, 0.04]
[[objects]]
kind = "edge"
count = [0, 1]
interior_angle_deg = [40.0, 90.0]
size_m = [0.05, 0.12]
[[objects]]
kind = "cylinder"
count = [0, 1]
radius_m = [0.03, 0.06]
length_m = [0.1, 0.3]
axis = "random"
[[objects]]
kind = "plate"
count = [0, 1]
width_m = [0.1, 0.2]
height_m = [0.1, 0.2]
thickness_m = 0.01
"""


def test_example_spec_loads_and_round_trips_through_the_card() -> None:
    spec = load_spec(EXAMPLE)
    assert spec.n_samples > 0 and spec.max_objects == sum(o.count.high for o in spec.objects)
    assert spec_from_dict(spec.to_dict()) == spec
    plan_samples(spec, range(5))  # its placements are satisfiable


@pytest.mark.parametrize(
    ("edit", "key"),
    [
        (("radius_m = [0.02, 0.08]", "radius_m = [0.08, 0.02]"), "objects[0].radius_m"),  # empty range
        (("count = [1, 3]", "count = [3, 1]"), "objects[0].count"),
        (('kind = "sphere"', 'kind = "torus"'), "objects[0].kind"),  # unknown kind
        (("n_samples = 40", "n_samples = 0"), "dataset.n_samples"),
        (("max_order = 1", "max_order = 0"), "solver.max_order"),
        (("max_order = 1", "max_rays = 1"), "solver.max_rays"),  # unknown solver knob
        (("record_length_s = 0.002", "record_length_s = -1.0"), "sonar.record_length_s"),
        (("x_m = [0.8, 1.2]", "x_m = [0.8, 12.0]"), "sonar.x_m"),  # head outside the tank
        (("min_range_m = 0.3", "min_range_m = 2.5"), "placement.max_range_m"),
        (('axis = "random"', 'axis = "diagonal"'), "objects[3].axis"),
        (("thickness_m = 0.01", 'thickness_m = 0.01\nmaterials = ["unobtainium"]'), "objects[4].materials"),
        (("seed = 3", "seed = 3\nseeds = 4"), "dataset.seeds"),  # typo: unknown key
        (("seed = 3", "seed = 3\nsamples_per_chunk = 0"), "dataset.samples_per_chunk"),
    ],
)
def test_bad_specs_name_the_key(edit: tuple[str, str], key: str) -> None:
    text = BASE.replace(*edit)
    assert text != BASE
    with pytest.raises(SpecError) as info:
        loads_spec(text, "bad.toml")
    message = str(info.value)
    assert key in message and message.startswith("bad.toml")
    assert "\n" not in message
    section = key.split(".")[0]
    assert f"{section}: {section}." not in message  # the section is named once


@pytest.mark.parametrize(
    ("edit", "message"),
    [
        # A sphere wider than the 3 m tank at its smallest: its size is to blame, not placement.
        (("radius_m = [0.02, 0.08]", "radius_m = [1.6, 2.0]"),
         r"^bad\.toml: objects\[0\]\.radius_m = \[1\.6, 2\.0\]: even the smallest sphere drawn \(bounding radius "
         r"1\.6 m\) needs 3\.3 m of water across .* tank\.width_m = 3 m$"),
        # A horizontal cylinder 2 m long does not fit under 1 m of water (bounding sphere).
        (("radius_m = [0.03, 0.06]\nlength_m = [0.1, 0.3]", "radius_m = [0.03, 0.06]\nlength_m = [2.0, 2.4]"),
         r"^bad\.toml: objects\[3\]\.radius_m = .*tank\.water_depth_m = 1 m$"),
    ],
)
def test_an_object_larger_than_the_tank_is_blamed_on_its_size(edit: tuple[str, str], message: str) -> None:
    text = BASE.replace(*edit)
    assert text != BASE
    with pytest.raises(SpecError, match=message):
        loads_spec(text, "bad.toml")


def test_solver_errors_name_the_section_once() -> None:
    with pytest.raises(SpecError, match=r"^bad\.toml: solver\.max_order = 0: must be"):
        loads_spec(BASE.replace("max_order = 1", "max_order = 0"), "bad.toml")


def test_impossible_placement_fails_before_any_work(tmp_path: Path) -> None:
    from acoustisim.datasets.generate import generate

    # Ten 0.2 m spheres within a 0.3-0.5 m, +/-5 degree sector cannot fit.
    text = BASE.replace("count = [1, 3]\nradius_m = [0.02, 0.08]", "count = 10\nradius_m = 0.2")
    spec = loads_spec(text.replace("half_angle_deg = 20.0", "half_angle_deg = 5.0").replace("max_range_m = 2.0", "max_range_m = 0.5"),
                      "tight.toml")
    out = tmp_path / "never.zarr"
    with pytest.raises(SpecError, match=r"placement\.max_tries = 200: sample 0 could not place objects\[0\]"):
        generate(spec, out, workers=0, progress=False)
    assert not out.exists()  # nothing written


def test_sample_i_is_independent_of_order_and_of_the_other_samples() -> None:
    spec = loads_spec(BASE)
    forward = plan_samples(spec)
    backward = [draw_sample(spec, i) for i in reversed(range(spec.n_samples))][::-1]
    assert forward == backward
    bigger = loads_spec(BASE.replace("n_samples = 40", "n_samples = 400"))
    assert [draw_sample(bigger, i) for i in range(spec.n_samples)] == forward
    other_seed = loads_spec(BASE.replace("seed = 3", "seed = 4"))
    assert draw_sample(other_seed, 0) != forward[0]
    assert len({s.simulation_seed for s in forward}) == spec.n_samples


def test_placements_obey_every_rule() -> None:
    """Invariants over many draws: inside the tank with clearance, clear of each other and of
    the head, within the range/bearing sector; counts within their ranges."""
    spec = loads_spec(BASE.replace("n_samples = 40", "n_samples = 300"))
    p = spec.placement
    kinds_seen = set()
    for sample in plan_samples(spec):
        length, width, depth = sample.tank_m
        x0, y0, z0, yaw = sample.pose[:4]
        counts = {}
        for obj in sample.objects:
            kinds_seen.add(obj.kind)
            counts[obj.kind] = counts.get(obj.kind, 0) + 1
            bx, by, bz = obj.bound_center_m
            r = obj.bound_radius_m
            assert p.wall_clearance_m - 1e-12 <= bx - r and bx + r <= length - p.wall_clearance_m + 1e-12
            assert p.wall_clearance_m - 1e-12 <= by - r and by + r <= width - p.wall_clearance_m + 1e-12
            if not obj.vertical:
                assert p.wall_clearance_m - 1e-12 <= bz - r and bz + r <= depth - p.wall_clearance_m + 1e-12
            x, y, _ = obj.reference_m
            rng_m = math.hypot(x - x0, y - y0)
            assert p.min_range_m - 1e-9 <= rng_m <= p.max_range_m + 1e-9
            azimuth = math.degrees(math.atan2(y - y0, x - x0))
            bearing = (yaw - azimuth + 180.0) % 360.0 - 180.0  # positive toward the right receiver
            assert abs(bearing) <= p.half_angle_deg + 1e-9
        for a in range(len(sample.objects)):
            for b in range(a):
                oa, ob = sample.objects[a], sample.objects[b]
                d_xy = math.dist(oa.bound_center_m[:2], ob.bound_center_m[:2])
                d = d_xy if (oa.vertical or ob.vertical) else math.dist(oa.bound_center_m, ob.bound_center_m)
                assert d >= oa.bound_radius_m + ob.bound_radius_m + p.min_gap_m - 1e-9
        for obj_spec in spec.objects:
            assert obj_spec.count.low <= counts.get(obj_spec.kind, 0) <= obj_spec.count.high
    assert kinds_seen == {"sphere", "post", "edge", "cylinder", "plate"}


def test_bearing_convention_matches_the_sonar_frame() -> None:
    """An object drawn at a positive bearing lies toward the right receiver in the head frame."""
    from acoustisim.datasets.sampling import build_scene

    spec = loads_spec(BASE)
    for sample in plan_samples(spec, range(10)):
        scene = build_scene(spec, sample)
        head = scene.sonar.tank_to_head(np.array([o.reference_m for o in sample.objects]))
        x0, y0, _, yaw = sample.pose[:4]
        for obj, h in zip(sample.objects, head):
            azimuth = math.degrees(math.atan2(obj.reference_m[1] - y0, obj.reference_m[0] - x0))
            bearing = (yaw - azimuth + 180.0) % 360.0 - 180.0
            # head-frame bearing atan2(x, y) of the same point (pitch and roll are 0 here)
            assert math.degrees(math.atan2(h[0], h[1])) == pytest.approx(bearing, abs=1e-9)
