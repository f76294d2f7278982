"""Smooth user meshes (no primitive): specular points on interpolated normals (order 1)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
import trimesh

from acoustisim.geometry import SpherePrimitive
from acoustisim.materials import get_material
from acoustisim.medium import Medium
from acoustisim.propagation import SolverConfig, prepare, solve
from acoustisim.scene import Scene, SceneObject
from acoustisim.sonar import SonarHead
from scenes.builders import edge_prism

CONFIG = SolverConfig(max_order=1, mechanisms=("specular",), amplitude_floor_db=None)
SONAR = SonarHead(position_m=(0.0, 0.0, 0.0), channel_positions_m=((-0.35, 0.0, 0.15), (0.0, 0.0, 0.0),
                                                                      (0.065, 0.0, 0.0)))
CENTRE = (0.9, 0.1, 0.05)


def _blob(subdivisions: int, primitive: bool = False) -> SceneObject:
    mesh = trimesh.creation.icosphere(subdivisions=subdivisions, radius=0.05)
    mesh.apply_translation(CENTRE)
    return SceneObject("blob", "mesh", get_material("rigid"), mesh,
                       SpherePrimitive(CENTRE, 0.05) if primitive else None)


def _gains(obj: SceneObject, backend: str) -> np.ndarray:
    paths = solve(Scene("s", Medium(), SONAR, None, (obj,)), config=replace(CONFIG, backend=backend))
    assert paths.object_labels() == ["blob"] * 3 or sorted(paths["channel"].tolist()) == [0, 1, 2]
    return paths.rows[np.argsort(paths["channel"])]


def test_mesh_sphere_matches_the_analytic_sphere_and_converges(backend):
    exact = _gains(_blob(4, primitive=True), backend)
    coarse = _gains(_blob(4), backend)
    fine = _gains(_blob(5), backend)  # edges halved (2x finer)
    # monostatic a / (2 r (r + a)): Max-weighted vertex normals of an icosphere are exactly radial,
    # so the interpolated normal at X on a flat triangle is radial too and only the sagitta
    # (X inside the sphere) errs, O(h^2): measured 1e-3 (subdivision 4), 2.5e-4 (5)
    r = np.linalg.norm(CENTRE) - 0.05
    assert coarse["geometric_gain"][1] == pytest.approx(0.05 / (2 * r * (r + 0.05)), rel=1e-2)
    assert fine["geometric_gain"][1] == pytest.approx(0.05 / (2 * r * (r + 0.05)), rel=5e-4)
    # bistatic: the same O(h^2) convergence to the primitive's answer; the 1 % and
    # "2x finer changes < 0.5 %"
    np.testing.assert_allclose(coarse["geometric_gain"], exact["geometric_gain"], rtol=1e-2)
    np.testing.assert_allclose(fine["geometric_gain"], exact["geometric_gain"], rtol=5e-4)
    assert np.max(np.abs(fine["geometric_gain"] / coarse["geometric_gain"] - 1)) < 5e-3
    # delays: the point lies on the flat triangle, inside the sphere by at most the sagitta
    np.testing.assert_allclose(fine["path_length_m"], exact["path_length_m"], atol=2e-4)


def test_concave_cavity_gives_both_walls_with_the_focusing_phase(backend):
    """Inside a spherical cavity of radius R0, off centre by d, looking along the diameter: the near
    wall (r = R0 - d < R0) echoes R0 / (2 r d) with no extra phase; the far wall (r = R0 + d > R0,
    beyond the centre of curvature: the Hessian of the path length is negative definite, a
    maximum) echoes R0 / (2 r d) with a phase of pi, i.e. a negative gain."""
    radius, offset = 1.0, 0.3
    sphere = trimesh.creation.icosphere(subdivisions=5, radius=radius)
    cavity = trimesh.Trimesh(sphere.vertices + (offset, 0.0, 0.0), sphere.faces[:, ::-1], process=False)
    obj = SceneObject("cavity", "mesh", get_material("rigid"), cavity)
    paths = solve(Scene("c", Medium(), SonarHead(position_m=(0.0, 0.0, 0.0)), None, (obj,)),
                  config=replace(CONFIG, backend=backend))
    mono = paths.for_channel(1).rows
    mono = mono[np.argsort(mono["path_length_m"])]
    near, far = radius - offset, radius + offset
    np.testing.assert_allclose(mono["path_length_m"], [2 * near, 2 * far], rtol=1e-9)
    # exact to round-off: on the diameter the specular points are icosphere vertices (radial
    # normals, on the true sphere)
    np.testing.assert_allclose(mono["geometric_gain"], [radius / (2 * near * offset), -radius / (2 * far * offset)],
                               rtol=1e-9)


def test_polyhedra_stay_mirrors_and_smooth_meshes_do_not():
    prism = edge_prism("prism", (1.0, 0.0), 60.0, 180.0, 0.1, 0.5, "steel", bottom_m=-0.5)
    blob = _blob(3)
    prepared = prepare(Scene("p", Medium(), SONAR, None, (prism, blob)))
    # the prism's 5 planar faces are mirrors; the blob is traced through its normals, not facets
    assert prepared.mirrors.count == 5 and set(prepared.mirrors.surface.tolist()) == {0}
    assert [r.surface for r in prepared.smooth] == [1]


def test_smooth_mesh_via_the_free_surface_equals_the_image_receiver(backend):
    """Mixed chain [mesh, surface]: -1 x the free-field echo of the same mesh at the receiver's image."""
    from acoustisim.scene import Tank

    sonar = SonarHead(position_m=(1.0, 1.5, 0.6), channel_positions_m=((-0.2, 0.0, 0.0), (0.0, 0.0, 0.0),
                                                                         (0.065, 0.0, 0.0)))
    mesh = trimesh.creation.icosphere(subdivisions=4, radius=0.06)
    mesh.apply_translation((2.0, 1.45, 0.5))
    blob = SceneObject("blob", "mesh", get_material("rigid"), mesh)
    config = SolverConfig(max_order=2, mechanisms=("specular",), amplitude_floor_db=None, backend=backend)
    tank = solve(Scene("t", Medium(), sonar, Tank(9.0, 3.0, 1.0), (blob,)), config=config)
    labels = np.array(tank.object_labels(), dtype=object)
    row = tank.rows[(labels == "blob>surface") & (tank["channel"] == 0)]
    assert row.size == 1
    image = sonar.receiver_positions[0] * np.array([1.0, 1.0, -1.0]) + np.array([0.0, 0.0, 2.0])
    free_sonar = replace(sonar, channel_positions_m=(tuple(sonar.tank_to_head(image[None])[0]), (0.0, 0.0, 0.0),
                                                     (0.065, 0.0, 0.0)))
    free = solve(Scene("f", Medium(), free_sonar, None, (blob,)), config=config)
    free_row = free.rows[free["channel"] == 0]
    assert free_row.size == 1
    # the same specular-point solve between the same two points: identical to round-off
    assert row["geometric_gain"][0] == pytest.approx(-free_row["geometric_gain"][0], rel=1e-9)
    assert row["path_length_m"][0] == pytest.approx(free_row["path_length_m"][0], rel=1e-12)
