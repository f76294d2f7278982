"""Edge diffraction combined with reflections: the fast engine against the reference, and its
leg screen against Embree."""

from __future__ import annotations

import numpy as np
import pytest

from acoustisim.propagation import SolverConfig, prepare, solve
from acoustisim.propagation.context import SolveContext
from acoustisim.propagation.fast.edge_reflections import fast_path_visibility
from acoustisim.propagation.reference.edge_reflections import boundary_faces, reference_path_visibility
from support.parity import assert_rows_match



def both_engines(scene, config, sonar=None):
    prepared = prepare(scene)
    fast = solve(prepared, sonar, config)
    reference = solve(prepared, sonar, SolverConfig(**{**config.__dict__, "backend": "reference"}))
    return fast.rows, reference.rows


def test_engines_agree_on_the_thesis_tank_with_one_reflection(thesis_tank) -> None:
    config = SolverConfig(mechanisms=("edge",), edge_reflections=1, edge_reflection_fresnel_v=None, amplitude_floor_db=None)
    fast, reference = both_engines(thesis_tank, config)
    assert np.count_nonzero(reference["order"] == 2) > 100_000
    assert_rows_match(fast, reference, label="thesis-tank/edge+1")


@pytest.mark.slow
def test_engines_agree_on_the_thesis_tank_at_other_poses(thesis_tank) -> None:
    config = SolverConfig(mechanisms=("edge",), edge_reflections=1, edge_reflection_fresnel_v=None, amplitude_floor_db=None)
    for position, yaw in (((1.3, 1.2, 0.3), 10.0), ((2.0, 2.2, 0.7), -25.0)):
        sonar = thesis_tank.sonar.with_pose(position_m=position, yaw_deg=yaw)
        fast, reference = both_engines(thesis_tank, config, sonar)
        assert_rows_match(fast, reference, label=f"thesis-tank/edge+1/{position}")


def test_engines_agree_with_two_reflections(builtin_scenes) -> None:
    # the free-edge prism has only its own facets to reflect on: every split of two reflections
    config = SolverConfig(mechanisms=("edge",), edge_reflections=2, edge_reflection_fresnel_v=None, amplitude_floor_db=None)
    scene = builtin_scenes("free-edge")
    sonar = scene.sonar.with_pose(position_m=(-1.0, 0.3, 0.2), yaw_deg=-10.0)
    fast, reference = both_engines(scene, config, sonar)
    assert_rows_match(fast, reference, label="free-edge/edge+2")


def test_leg_screen_answers_as_embree(thesis_tank) -> None:
    # Random paths transmitter -> a point on the floor (or a wall) -> a point in the water ->
    # receiver, many of them grazing or crossing the posts, the prism and the pipe, ending
    # within a millimetre of a wall, or leaving the floor or the wall at grazing angles (where
    # Embree's repeated hits on the ignored face make the reference call a leg blocked): the
    # screen's answers (and Embree's for the legs it leaves undecided) must be the reference's.
    prepared = prepare(thesis_tank)
    context = SolveContext.build(thesis_tank, thesis_tank.sonar, prepared.raycaster)
    rng = np.random.default_rng(23)
    n = 4000
    mirrors = prepared.mirrors
    names = thesis_tank.surface_names
    floor = int(np.flatnonzero(mirrors.surface == names.index("floor"))[0])
    wall = int(np.flatnonzero(mirrors.surface == names.index("wall-y0"))[0])
    on_floor = np.column_stack([rng.uniform(0.0, 9.0, n), rng.uniform(0.0, 3.0, n), np.zeros(n)])
    on_wall = np.column_stack([rng.uniform(0.0, 9.0, n), np.zeros(n), rng.uniform(0.0, 1.0, n)])
    which = rng.random(n) < 0.5
    reflection = np.where(which[:, None], on_floor, on_wall)
    mirror = np.where(which, floor, wall)
    # water points: near the objects (within 5 cm of their boxes) or anywhere, some near walls
    boxes = prepared.object_bounds
    pick = rng.integers(0, boxes.shape[0], n)
    near = boxes[pick, 0] - 0.05 + rng.random((n, 3)) * (boxes[pick, 1] - boxes[pick, 0] + 0.1)
    anywhere = rng.random((n, 3)) * [9.0, 3.0, 1.0]
    water = np.where((rng.random(n) < 0.6)[:, None], near, anywhere)
    water[:50, 1] = rng.uniform(0.0, 1e-3, 50)  # within a millimetre of wall-y0
    grazing = np.arange(50, 400)  # within 2 mm of the reflection's own plane
    height = rng.uniform(0.0, 2e-3, grazing.size)
    water[grazing, 2] = np.where(which[grazing], height, water[grazing, 2])
    water[grazing, 1] = np.where(which[grazing], water[grazing, 1], height)
    tx = np.broadcast_to(context.transmitter_m, (n, 3))
    rx = context.receivers_m[rng.integers(0, 3, n)]
    vertices = np.stack([tx, reflection, water, rx], axis=1)
    none = np.full(n, -1, dtype=np.int64)
    patches = np.column_stack([none, mirrors.patch[mirror], none, none])
    faces = np.column_stack([none, boundary_faces(prepared)[mirror], none, none])
    fast = fast_path_visibility(context, prepared, vertices, patches, faces)
    reference = reference_path_visibility(context, prepared, vertices, patches, faces)
    assert 0.1 < reference.mean() < 0.9  # both answers well represented
    assert np.array_equal(fast, reference)
