"""Builders: closed meshes with outward normals, exact primitives, placement and repair."""

import math

import numpy as np
import pytest
import trimesh

from acoustisim.errors import InputError
from acoustisim.geometry import CylinderPrimitive, SpherePrimitive
from scenes import builders
from scenes.tessellation import SAGITTA_TOLERANCE_M, circle_segments, icosphere_subdivisions


def assert_closed_outward(mesh: trimesh.Trimesh) -> None:
    """Watertight, consistently wound, positive volume; for a convex mesh every face normal
    points away from the centroid (a stronger, per-face outward check)."""
    assert mesh.is_watertight
    assert mesh.is_winding_consistent
    assert mesh.volume > 0.0


def assert_convex_outward(mesh: trimesh.Trimesh) -> None:
    assert_closed_outward(mesh)
    outward = np.einsum("ij,ij->i", mesh.triangles_center - mesh.centroid, mesh.face_normals)
    assert np.all(outward > 0.0)


def test_circle_segments_meet_the_sagitta_criterion_and_are_minimal():
    for radius in (0.01, 0.025, 0.075, 0.3, 1.0):
        n = circle_segments(radius)
        assert radius * (1.0 - math.cos(math.pi / n)) <= SAGITTA_TOLERANCE_M
        if n > 24:  # above the floor, one segment fewer would break the criterion
            assert radius * (1.0 - math.cos(math.pi / (n - 1))) > SAGITTA_TOLERANCE_M
    assert circle_segments(0.025) == 24  # 19 needed, the floor is 24
    assert circle_segments(0.3) == 63


def test_icosphere_level_meets_the_criterion():
    for radius in (0.02, 0.05, 0.2):
        level = icosphere_subdivisions(radius)
        mesh = trimesh.creation.icosphere(subdivisions=level, radius=radius)
        # Largest gap between the facets and the sphere: at the face centres.
        gap = radius - np.linalg.norm(mesh.triangles_center, axis=1).min()
        assert gap <= SAGITTA_TOLERANCE_M


def test_cylinder_mesh_primitive_and_volume():
    obj = builders.cylinder("c", (1.0, 2.0, 0.5), (1.0, 1.0, 0.0), 0.1, 0.4, "pvc")
    assert obj.kind == "cylinder" and obj.material.name == "pvc"
    assert_convex_outward(obj.mesh)
    p = obj.primitive
    assert isinstance(p, CylinderPrimitive)
    np.testing.assert_allclose(p.axis, np.array([1.0, 1.0, 0.0]) / math.sqrt(2.0), atol=1e-15)
    # Every vertex lies on the true surface: radius from the axis = a or on a cap.
    d = obj.mesh.vertices - np.asarray(p.center_m)
    along = d @ np.asarray(p.axis)
    radial = np.linalg.norm(d - np.outer(along, p.axis), axis=1)
    np.testing.assert_allclose(np.abs(along), 0.2, atol=1e-12)
    np.testing.assert_allclose(radial[radial > 1e-9], 0.1, atol=1e-12)
    # Volume of an inscribed regular n-gon prism, exactly.
    n = circle_segments(0.1)
    assert obj.mesh.volume == pytest.approx(0.5 * n * 0.1**2 * math.sin(2 * math.pi / n) * 0.4, rel=1e-9)


def test_post_spans_floor_to_surface():
    obj = builders.post("p", (3.0, 1.2), 0.025, 1.0)
    assert obj.kind == "post" and obj.material.name == "pvc"
    assert_convex_outward(obj.mesh)
    np.testing.assert_allclose(obj.bounds_m[:, 2], [0.0, 1.0], atol=1e-12)
    assert obj.primitive == CylinderPrimitive((3.0, 1.2, 0.5), (0.0, 0.0, 1.0), 0.025, 1.0)
    free = builders.post("p", (1.0, 0.0), 0.025, 0.5, bottom_m=-0.5)
    np.testing.assert_allclose(free.bounds_m[:, 2], [-0.5, 0.5], atol=1e-12)


def test_edge_prism_geometry():
    obj = builders.edge_prism("e", (2.5, 1.5), 60.0, 180.0, 0.10, 1.0)
    assert obj.kind == "edge" and obj.material.name == "steel" and obj.primitive is None
    assert_convex_outward(obj.mesh)
    assert len(obj.mesh.faces) == 8
    # Volume = (1/2) s^2 sin(alpha) h.
    assert obj.mesh.volume == pytest.approx(0.5 * 0.1**2 * math.sin(math.radians(60.0)) * 1.0, rel=1e-12)
    # The sharp edge is at edge_m, and is the point of the prism farthest along facing (-x).
    xy = obj.mesh.vertices[:, :2]
    tip = xy[np.argmin(xy[:, 0])]
    np.testing.assert_allclose(tip, [2.5, 1.5], atol=1e-12)
    # Interior angle at the edge: the two bottom faces meeting there open at 60 degrees.
    others = np.unique(np.round(xy[np.linalg.norm(xy - [2.5, 1.5], axis=1) > 1e-9], 12), axis=0)
    v1, v2 = others - [2.5, 1.5]
    assert math.degrees(math.acos(v1 @ v2 / np.linalg.norm(v1) / np.linalg.norm(v2))) == pytest.approx(60.0)
    np.testing.assert_allclose(np.linalg.norm([v1, v2], axis=1), 0.10)
    # The prism is symmetric about the facing direction (its bisector is the tank x axis here).
    assert (v1 + v2)[1] == pytest.approx(0.0, abs=1e-12) and (v1 + v2)[0] > 0


def test_edge_facing_follows_yaw_convention():
    obj = builders.edge_prism("e", (1.0, 1.0), 90.0, 90.0, 0.2, 1.0)  # points toward +y
    xy = obj.mesh.vertices[:, :2]
    np.testing.assert_allclose(xy[np.argmax(xy[:, 1])], [1.0, 1.0], atol=1e-12)


def test_sphere_mesh_and_primitive():
    obj = builders.sphere("s", (1.0, 2.0, 0.3), 0.05)
    assert obj.primitive == SpherePrimitive((1.0, 2.0, 0.3), 0.05)
    assert_convex_outward(obj.mesh)
    r = np.linalg.norm(obj.mesh.vertices - [1.0, 2.0, 0.3], axis=1)
    np.testing.assert_allclose(r, 0.05, atol=1e-12)  # vertices on the sphere
    exact = 4.0 / 3.0 * math.pi * 0.05**3
    # Inscribed polyhedron: volume below the sphere's, above that of the sphere shrunk by the sagitta.
    assert exact * (1 - SAGITTA_TOLERANCE_M / 0.05) ** 3 < obj.mesh.volume < exact


def test_plate_orientation_and_extents():
    normal = np.array([-1.0, 1.0, 0.0]) / math.sqrt(2.0)
    obj = builders.plate("w", (2.0, 1.0, 0.5), normal * 3.0, 0.8, 0.6, 0.02)
    assert_convex_outward(obj.mesh)
    assert obj.mesh.volume == pytest.approx(0.8 * 0.6 * 0.02, rel=1e-12)
    along = (obj.mesh.vertices - [2.0, 1.0, 0.5]) @ normal
    np.testing.assert_allclose(np.abs(along), 0.01, atol=1e-12)
    np.testing.assert_allclose(obj.bounds_m[:, 2], [0.2, 0.8], atol=1e-12)  # height along up = z
    big_faces = obj.mesh.area_faces > 0.1 * 0.8 * 0.6
    np.testing.assert_allclose(np.abs(obj.mesh.face_normals[big_faces] @ normal), 1.0, atol=1e-12)


def _write_box(path, faces_to_drop=0, invert=False, offset=(0.0, 0.0, 0.0)):
    box = trimesh.creation.box(extents=(0.2, 0.1, 0.05))
    box.apply_translation(offset)
    faces = box.faces[faces_to_drop:]
    if invert:
        faces = faces[:, ::-1]
    trimesh.Trimesh(box.vertices, faces, process=False).export(path)


def test_user_mesh_is_scaled_rotated_and_placed(tmp_path):
    path = tmp_path / "box.stl"
    _write_box(path)
    obj = builders.user_mesh("b", path, (2.0, 1.0, 0.3), yaw_deg=90.0, scale=2.0)
    assert obj.kind == "mesh" and obj.material.name == "concrete"
    assert_convex_outward(obj.mesh)
    # The 0.4 m (scaled) length along the mesh's x turns to the tank's y by a 90 degree yaw.
    # STL stores float32 coordinates: 1e-7 m covers their rounding (scaled by 2).
    np.testing.assert_allclose(obj.bounds_m, [[1.9, 0.8, 0.25], [2.1, 1.2, 0.35]], rtol=0, atol=1e-7)
    assert dict(obj.parameters)["path"] == str(path.resolve())


def test_user_mesh_pitch_raises_the_nose(tmp_path):
    path = tmp_path / "box.stl"
    _write_box(path, offset=(0.1, 0.0, 0.0))  # the box reaches from x = 0 to x = 0.2 (its nose)
    obj = builders.user_mesh("b", path, (0.0, 0.0, 0.0), pitch_deg=90.0)
    np.testing.assert_allclose(obj.bounds_m[:, 2], [0.0, 0.2], rtol=0, atol=1e-7)  # nose now points up
    turned = builders.user_mesh("b", path, (0.0, 0.0, 0.0), yaw_deg=180.0)
    np.testing.assert_allclose(turned.bounds_m[:, 0], [-0.2, 0.0], rtol=0, atol=1e-7)


def test_user_mesh_inverted_winding_is_fixed(tmp_path):
    path = tmp_path / "inside_out.stl"
    _write_box(path, invert=True)
    assert trimesh.load(path).volume < 0
    assert_convex_outward(builders.user_mesh("b", path, (0.0, 0.0, 0.0)).mesh)


def test_user_mesh_small_hole_is_repaired(tmp_path):
    path = tmp_path / "open_box.stl"
    _write_box(path, faces_to_drop=1)  # one triangle missing: trimesh fills it
    assert not trimesh.load(path).is_watertight
    obj = builders.user_mesh("b", path, (0.0, 0.0, 0.0))
    assert_convex_outward(obj.mesh)
    # STL stores float32 coordinates (relative rounding 6e-8 per coordinate): 1e-6 on the volume.
    assert obj.mesh.volume == pytest.approx(0.2 * 0.1 * 0.05, rel=1e-6)


def test_user_mesh_large_hole_is_rejected(tmp_path):
    sphere = trimesh.creation.icosphere(subdivisions=2)
    keep = sphere.triangles_center[:, 2] < 0.5  # cut the cap off: a hole with many edges
    path = tmp_path / "bowl.stl"
    trimesh.Trimesh(sphere.vertices, sphere.faces[keep]).export(path)
    with pytest.raises(InputError, match="not watertight"):
        builders.user_mesh("bowl", path, (0.0, 0.0, 0.0))


def test_user_mesh_missing_file(tmp_path):
    with pytest.raises(InputError, match="no such file"):
        builders.user_mesh("m", tmp_path / "nope.stl", (0.0, 0.0, 0.0))


@pytest.mark.parametrize(
    "call",
    [
        lambda: builders.post("p", (1.0, 1.0), -0.1, 1.0),
        lambda: builders.post("p", (1.0, 1.0), 0.1, 1.0, bottom_m=1.0),
        lambda: builders.edge_prism("e", (1.0, 1.0), 180.0, 0.0, 0.1, 1.0),
        lambda: builders.sphere("s", (0.0, 0.0, float("nan")), 0.1),
        lambda: builders.cylinder("c", (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), 0.1, 1.0),
        lambda: builders.plate("w", (0.0, 0.0, 0.0), (0.0, 0.0, 1.0), 1.0, 1.0, 0.1),  # up // normal
        lambda: builders.sphere("s", (0.0, 0.0, 0.0), 0.1, "wood"),
        lambda: builders.sphere("s", (0.0, 0.0, 0.0), True),
    ],
)
def test_bad_arguments_raise_input_error(call):
    with pytest.raises(InputError):
        call()


@pytest.mark.parametrize("suffix", ["stl", "obj", "ply"])
def test_user_mesh_formats(tmp_path, suffix):
    path = tmp_path / f"box.{suffix}"
    _write_box(path)
    obj = builders.user_mesh("b", path, (1.0, 1.0, 0.5))
    assert_convex_outward(obj.mesh)
    assert obj.mesh.volume == pytest.approx(0.2 * 0.1 * 0.05, rel=1e-6)  # float32 in STL: see above
