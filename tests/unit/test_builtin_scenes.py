"""The built-in scenes: valid, closed meshes, and targets where the sonar can see them."""

import math

import numpy as np
import pytest
import trimesh

from acoustisim.scene import Scene
from scenes.builtin import builtin_scene, builtin_scene_names
from scenes.tessellation import SAGITTA_TOLERANCE_M
from scenes.validation import validate_scene

FIRST_NULL_DEG = 11.0  # 2 J1(ka sin t)/(ka sin t) first null at 500 kHz, a = 9.5 mm (physics.md)


@pytest.fixture(scope="module")
def scenes() -> dict[str, Scene]:
    return {name: builtin_scene(name) for name in builtin_scene_names()}


def test_names():
    assert builtin_scene_names()[0] == "thesis-tank"
    assert set(builtin_scene_names()) == {"thesis-tank", "free-sphere", "free-plane", "free-post", "free-edge",
                                          "free-cylinder"}


def test_every_builtin_scene_validates_and_is_closed(scenes):
    for name, scene in scenes.items():
        assert scene.name == name
        validate_scene(scene)
        for obj in scene.objects:
            assert obj.mesh.is_watertight and obj.mesh.is_winding_consistent and obj.mesh.volume > 0, obj.name


def test_builds_are_deterministic(scenes):
    assert builtin_scene("thesis-tank") == scenes["thesis-tank"]
    again = builtin_scene("thesis-tank")
    for a, b in zip(again.objects, scenes["thesis-tank"].objects):
        np.testing.assert_array_equal(a.mesh.vertices, b.mesh.vertices)


def test_thesis_tank_layout(scenes):
    scene = scenes["thesis-tank"]
    assert scene.tank is not None
    assert (scene.tank.length_m, scene.tank.width_m, scene.tank.water_depth_m) == (9.0, 3.0, 1.0)
    assert scene.medium.water == "fresh" and scene.medium.temperature_c == 20.0
    assert scene.sonar.position_m == (1.0, 1.5, 0.5) and scene.sonar.yaw_deg == 0.0
    kinds = sorted(o.kind for o in scene.objects)
    assert kinds.count("post") >= 2 and "edge" in kinds and "cylinder" in kinds
    assert scene.triangle_count < 200_000
    edge = scene.object("edge-1")
    assert edge.material.name == "steel-machined" and edge.parameter("interior_angle_deg") == 60.0
    # The edge faces the sonar about 1.5 m ahead on its bearing: its nearest point is the edge.
    nearest = edge.mesh.vertices[np.argmin(np.linalg.norm(edge.mesh.vertices - scene.sonar.position_m, axis=1))]
    np.testing.assert_allclose(nearest[:2], [2.5, 1.5])
    assert scene.object("pipe-1").material.name == "pvc"


def test_thesis_tank_clearances(scenes):
    # Design rule: objects >= 5 cm from the walls and from each other (vertex-to-surface
    # distance; the meshes are convex, so the closest approach is at a vertex or within 1 mm
    # of one with these tessellations).
    scene = scenes["thesis-tank"]
    for obj in scene.objects:
        lo, hi = obj.bounds_m
        assert np.all(lo[:2] >= 0.05) and np.all(hi[:2] <= [9.0 - 0.05, 3.0 - 0.05]), obj.name
    for i, a in enumerate(scene.objects):
        for b in scene.objects[i + 1:]:
            _, distance, _ = trimesh.proximity.closest_point(b.mesh, a.mesh.vertices)
            assert distance.min() >= 0.05 - 1e-3, (a.name, b.name)


def _bearing_deg(scene: Scene, point: np.ndarray) -> float:
    x, y, _ = scene.sonar.tank_to_head(point[None])[0]
    return math.degrees(math.atan2(x, y))


def test_thesis_tank_targets_in_view_and_unoccluded(scenes):
    scene = scenes["thesis-tank"]
    tx = scene.sonar.transmitter_position
    visible = ["edge-1", "post-1", "post-2", "pipe-1"]
    for name in visible:
        obj = scene.object(name)
        target = np.array([*obj.mesh.bounds.mean(axis=0)[:2], tx[2]])
        assert abs(_bearing_deg(scene, target)) < FIRST_NULL_DEG, name
        # The line of sight from the transmitter to the target's centre meets no other object.
        direction = target - tx
        length = float(np.linalg.norm(direction))
        for other in scene.objects:
            if other.name == name:
                continue
            hits, _, _ = other.mesh.ray.intersects_location([tx], [direction / length], multiple_hits=False)
            assert len(hits) == 0 or np.linalg.norm(hits[0] - tx) > length, (name, other.name)


@pytest.mark.parametrize("name", ["free-sphere", "free-plane", "free-post", "free-edge", "free-cylinder"])
def test_free_field_scene_has_one_object_1m_ahead(scenes, name):
    scene = scenes[name]
    assert scene.tank is None and scene.boundaries == ()
    assert len(scene.objects) == 1
    obj = scene.objects[0]
    assert obj.material.name == "rigid"
    tx = scene.sonar.transmitter_position
    # The first hit along the boresight is 1.0 m ahead (front of the object).
    hits, _, _ = obj.mesh.ray.intersects_location([tx], [scene.sonar.boresight], multiple_hits=False)
    assert len(hits) == 1
    # Flat faces: exact up to the float32 ray tracer (1e-6 m). Curved faces: the facets lie
    # inside the true surface by at most the tessellation sagitta.
    tolerance = 1e-6 if obj.primitive is None else SAGITTA_TOLERANCE_M
    assert 1.0 - 1e-6 <= np.linalg.norm(hits[0] - tx) <= 1.0 + tolerance


def test_free_field_curved_objects_keep_primitives(scenes):
    sphere = scenes["free-sphere"].objects[0].primitive
    assert np.linalg.norm(sphere.center_m) - sphere.radius_m == pytest.approx(1.0)
    post = scenes["free-post"].objects[0]
    assert post.primitive is not None and post.primitive.length_m == 1.0  # 1 m tall, centred on the sonar
    assert post.bounds_m[0, 2] == pytest.approx(-0.5) and post.bounds_m[1, 2] == pytest.approx(0.5)
    cylinder = scenes["free-cylinder"].objects[0].primitive
    assert cylinder.center_m[0] - cylinder.radius_m == pytest.approx(1.0)
    assert scenes["free-edge"].objects[0].bounds_m[0, 2] == pytest.approx(-0.5)
