"""Sharp-edge extraction: which mesh edges are wedges, with which angles and orientation."""

from __future__ import annotations

import numpy as np
import pytest

from acoustisim.propagation.edge_extraction import is_pressure_release, sharp_edges
from acoustisim.propagation.raycast import RayCaster
from acoustisim.materials import get_material
from acoustisim.scene import Scene
from scenes.builders import cylinder, edge_prism, sphere
from scenes.builtin import builtin_scene


def extract(scene):
    return sharp_edges(RayCaster.from_scene(scene), scene)


def test_tank_has_its_twelve_right_angle_corners():
    scene = Scene(name="empty", objects=())
    edges = extract(scene)
    assert len(edges) == 12
    np.testing.assert_allclose(edges.wedge_angle_rad, np.pi / 2, atol=1e-12)
    # the corner edges add up to the box's perimeter: 4 (L + W + D)
    tank = scene.tank
    assert edges.length_m.sum() == pytest.approx(4 * (tank.length_m + tank.width_m + tank.water_depth_m))
    # every edge lies on two faces of the box
    lo, hi = tank.bounds_m
    mid = 0.5 * (edges.start_m + edges.end_m)
    on_face = (np.abs(mid - lo) < 1e-9) | (np.abs(mid - hi) < 1e-9)
    assert np.all(on_face.sum(axis=1) == 2)


def test_prism_edges_and_wedge_frame():
    prism = edge_prism("p", (2.0, 1.0), 60.0, 180.0, 0.1, 1.0, "steel", bottom_m=0.0)
    edges = extract(Scene(name="s", tank=None, objects=(prism,)))
    # 3 vertical edges (exterior 300 deg: an equilateral prism) and 2 x 3 rim edges (270 deg)
    theta = np.degrees(edges.wedge_angle_rad)
    assert len(edges) == 9
    assert np.sum(np.isclose(theta, 300.0)) == 3 and np.sum(np.isclose(theta, 270.0)) == 6
    vertical = np.isclose(theta, 300.0)
    front = vertical & np.all(np.isclose(edges.start_m[:, :2], [2.0, 1.0]), axis=1)
    assert front.sum() == 1
    # the frame: direction = face_dir x face_normal, face_dir in face 1 pointing away from the edge,
    # and a point on the bisector in front of the edge is at theta_w / 2
    i = int(np.flatnonzero(front)[0])
    np.testing.assert_allclose(np.cross(edges.face_dir[i], edges.face_normal[i]), edges.direction[i], atol=1e-12)
    sel = edges.select(np.arange(len(edges)) == i)
    r, th, z = sel.local_coordinates(np.array([[1.0, 1.0, 0.25]]))  # 1 m in front, on the bisector
    assert r[0] == pytest.approx(1.0) and th[0] == pytest.approx(np.radians(150.0))
    assert 0.0 <= z[0] <= 1.0
    # face 1 is at theta = 0; the other face of the prism's edge at theta_w (300 degrees)
    _, th1, _ = sel.local_coordinates((edges.start_m[i] + 0.05 * edges.face_dir[i])[None, :])
    assert th1[0] == pytest.approx(0.0, abs=1e-9)
    corners = np.asarray(prism.mesh.vertices)
    ends = corners[~np.all(np.isclose(corners[:, :2], [2.0, 1.0]), axis=1)]
    _, th_corner, _ = sel.local_coordinates(ends)
    assert np.sort(np.round(np.degrees(th_corner), 6)).tolist() == [0.0, 0.0, 300.0, 300.0]


def test_cylinder_side_is_not_sharp_but_rims_are():
    cyl = cylinder("c", (1.0, 0.0, 0.0), (0.0, 0.0, 1.0), 0.1, 0.6, "pvc")
    edges = extract(Scene(name="s", tank=None, objects=(cyl,)))
    # every sharp edge lies on a rim (z = +/- 0.3), at 90 degrees between cap and side
    assert len(edges) > 16
    for p in (edges.start_m, edges.end_m):
        assert np.all(np.isclose(np.abs(p[:, 2]), 0.3))
        assert np.allclose(np.hypot(p[:, 0] - 1.0, p[:, 1]), 0.1, rtol=1e-6)
    np.testing.assert_allclose(np.degrees(edges.wedge_angle_rad), 270.0, atol=1e-6)
    # the two rims are two chains (one physical edge each)
    assert len(np.unique(edges.chain)) == 2


def test_sphere_has_no_sharp_edges():
    edges = extract(Scene(name="s", tank=None, objects=(sphere("s", (1.0, 0.0, 0.0), 0.05, "steel"),)))
    assert len(edges) == 0


def test_threshold_controls_sharpness():
    """A coarse cylinder's side (32 segments: 11.25 degree turns) becomes sharp below that angle."""
    cyl = cylinder("c", (1.0, 0.0, 0.0), (0.0, 0.0, 1.0), 0.1, 0.6, "pvc")
    scene = Scene(name="s", tank=None, objects=(cyl,))
    rc = RayCaster.from_scene(scene)
    assert len(sharp_edges(rc, scene, sharp_angle_deg=5.0)) > len(sharp_edges(rc, scene))


def test_boundary_conditions_from_materials():
    assert not is_pressure_release(get_material("steel"))  # fluid: treated as rigid
    assert not is_pressure_release(get_material("rigid"))
    assert is_pressure_release(get_material("pressure-release"))
    assert is_pressure_release(get_material("pvc-pipe-air"))  # fixed R = -0.9
    assert not is_pressure_release(get_material("pvc-pipe-water"))


def test_thesis_tank_edges():
    scene = builtin_scene("thesis-tank")
    edges = extract(scene)
    names = np.asarray(scene.surface_names)[edges.surface]
    assert np.sum(np.char.startswith(names.astype(str), "wall") | (names == "floor") | (names == "surface")) == 12
    assert np.sum(names == "edge-1") == 9
