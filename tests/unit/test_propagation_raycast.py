"""The Embree ray caster, the piston directivity and the derived columns."""

from __future__ import annotations

import numpy as np
import pytest

from acoustisim.medium import Medium
from acoustisim.propagation import SolverConfig, solve
from acoustisim.propagation.directivity import piston_directivity
from acoustisim.propagation.raycast import RayCaster
from acoustisim.propagation.responses import evaluate_transfers
from acoustisim.scene import Scene, Tank
from acoustisim.sonar import SonarHead
from scenes.builders import sphere


def _scene() -> Scene:
    ball = sphere("ball", (4.0, 1.5, 0.5), 0.2, "steel")
    return Scene("rc", Medium(), SonarHead(), Tank(9.0, 3.0, 1.0), (ball,))


def test_intersect_distances_surfaces_and_normals():
    scene = _scene()
    rc = RayCaster.from_scene(scene)
    origins = np.array([[1.0, 1.5, 0.5]] * 4)
    directions = np.array([[1.0, 0.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, -1.0]])
    hits = rc.intersect(origins, directions)
    names = [scene.surface_names[s] for s in hits.surface]
    assert names == ["ball", "wall-x0", "surface", "floor"]
    # float32 Embree: coordinates shifted to the scene centre, ~5e-7 m round-off; the sphere's
    # tessellation (sagitta criterion of the builder) puts its hit within 1 mm of the true 2.8 m
    np.testing.assert_allclose(hits.distance_m[1:], [1.0, 0.5, 0.5 * np.sqrt(2.0)], atol=1e-5)
    assert abs(hits.distance_m[0] - 2.8) < 1e-3
    np.testing.assert_allclose(hits.normal[1], [1.0, 0.0, 0.0])
    np.testing.assert_allclose(hits.normal[2], [0.0, 0.0, -1.0])
    assert hits.normal[0] @ np.array([-1.0, 0.0, 0.0]) > 0.99  # outward from the ball
    np.testing.assert_allclose(hits.points(origins, directions)[2], [1.0, 1.5, 1.0], atol=1e-5)


def test_occluded_segments_and_patch_exclusion():
    scene = _scene()
    rc = RayCaster.from_scene(scene)
    a = np.array([[1.0, 1.5, 0.5], [1.0, 1.5, 0.5], [1.0, 1.5, 0.5], [1.0, 0.5, 0.5]])
    b = np.array([[8.0, 1.5, 0.5], [3.5, 1.5, 0.5], [5.0, 1.5, 1.0], [8.0, 0.5, 0.5]])
    # through the ball; stopping short of it; ending on the surface (eps keeps it clear);
    # passing beside it
    np.testing.assert_array_equal(rc.occluded(a, b), [True, False, False, False])
    # a leg ending just inside the tessellated ball (as a specular point on a circumscribed mesh
    # would) is blocked by the ball, but not once the ball's patch is excluded
    end = np.array([[3.81, 1.5, 0.5]])
    ball_patch = rc.patch_index[rc.surface_index == 6][0]
    assert rc.occluded(a[:1], end)[0]
    assert not rc.occluded(a[:1], end, exclude_patches=[[ball_patch]])[0]
    # a segment through the ball and then a wall patch is still blocked when only the wall is excluded
    wall_patch = rc.patch_index[rc.surface_index == 1][0]
    assert rc.occluded(a[:1], [[9.0, 1.5, 0.5]], exclude_patches=[[wall_patch]])[0]


def test_piston_directivity_reference_values():
    c = 1482.38
    a = 0.0095
    # physics.md section 2: -3 dB at 4.60 deg, first null 11.0 deg at 500 kHz
    d3 = piston_directivity(np.radians(4.60), 500e3, a, c)
    assert 20 * np.log10(d3) == pytest.approx(-3.0, abs=0.05)
    angles = np.radians(np.linspace(10.0, 12.0, 2001))
    values = piston_directivity(angles, 500e3, a, c)
    null = np.degrees(angles[np.argmin(np.abs(values))])
    assert null == pytest.approx(11.0, abs=0.05)
    assert piston_directivity(0.0, 500e3, a, c) == 1.0
    assert piston_directivity(np.radians(120.0), 500e3, a, c) == 0.0  # behind the baffle
    grid = piston_directivity(np.zeros((3, 1)), np.array([1e5, 5e5, 9e5]), a, c)
    assert grid.shape == (3, 3)


def test_derived_columns_follow_their_definitions():
    scene = _scene()
    paths = solve(scene, config=SolverConfig(mechanisms=("direct", "specular"), amplitude_floor_db=None))
    rows = paths.rows
    c = scene.medium.sound_speed
    np.testing.assert_allclose(rows["delay_s"], rows["path_length_m"] / c, rtol=1e-15)
    bore = scene.sonar.boresight
    np.testing.assert_allclose(np.cos(rows["angle_tx_rad"]), rows["departure_dir"] @ bore, atol=1e-12)
    np.testing.assert_allclose(np.cos(rows["angle_rx_rad"]), -rows["arrival_dir"] @ bore, atol=1e-12)
    alpha = float(scene.medium.absorption_db_per_m(500e3))
    np.testing.assert_allclose(rows["absorption_db"], alpha * rows["path_length_m"], rtol=1e-12)
    expected = (np.abs(rows["geometric_gain"] * rows["directivity_tx"] * rows["directivity_rx"])
                * 10 ** (-rows["absorption_db"] / 20))
    # echoes of elastic objects: times |H(f0)| of their transfer function (none here: the 20 cm
    # steel ball is beyond the series' k a = 600; tests/physics/test_elastic_echoes_solve.py)
    with_response = rows["response_id"] >= 0
    factor = np.abs(evaluate_transfers(paths.responses, np.array([500e3]), c)[:, 0])
    expected[with_response] *= factor[rows["response_id"][with_response]]
    np.testing.assert_allclose(rows["amplitude"], expected, rtol=1e-12)
    assert len(np.unique(rows["path_id"][rows["channel"] == 1])) == np.sum(rows["channel"] == 1)


def test_empty_free_field_gives_the_direct_paths_only():
    sonar = SonarHead(position_m=(0.0, 0.0, 0.0))
    config = SolverConfig(mechanisms=("direct", "specular"), amplitude_floor_db=None)
    paths = solve(Scene("empty", Medium(), sonar, None, ()), config=config)
    assert sorted(paths["channel"].tolist()) == [0, 2]
    np.testing.assert_allclose(paths["geometric_gain"], 1.0 / sonar.separation_m, rtol=1e-12)
    hits = RayCaster.from_scene(Scene("empty", Medium(), sonar, None, ())).intersect([[0.0, 0, 0]], [[1.0, 0, 0]])
    assert not hits.hit[0] and np.isinf(hits.distance_m[0])
