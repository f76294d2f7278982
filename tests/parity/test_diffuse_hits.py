"""The fast engine's first hits in a box tank with convex objects, found without Embree, against
Embree's INTERSECT and against the reference tracer (which asks Embree for every hit)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
import trimesh

from acoustisim.materials import get_material
from acoustisim.propagation.config import SolverConfig
from acoustisim.propagation.context import SolveContext
from acoustisim.propagation.fast.diffuse import diffuse_rows, trace_diffuse
from acoustisim.propagation.fast.diffuse_hits import BoxTank, box_tank, first_hits
from acoustisim.propagation.raycast import RayCaster
from acoustisim.propagation.reference import diffuse as reference
from support.parity import assert_rows_match
from acoustisim.scene import SceneObject, Tank
from scenes.builtin import builtin_scene

GRAZING_M = 1e-6
"""Where the float64 answer and float32 Embree may name triangles of different planes, the ray
passes within this of an edge: Embree rounds the coordinates near 5 m from the scene's centre
to about 5e-7 m (the ray caster's docstring)."""


class _OpenTank(Tank):
    """The thesis tank without its free surface: the top face of the box has no triangles."""

    @property
    def boundaries(self):
        return tuple(b for b in Tank.boundaries.func(self) if b.name != "surface")


@pytest.fixture(scope="module")
def tank():
    scene = builtin_scene("thesis-tank")
    return scene, RayCaster.from_scene(scene)


def _run(hits: BoxTank, origins: np.ndarray, directions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """first_hits of rows (n, 3) (origins (n, 3), or (3,): one shared, as the tracer's first
    bounce passes the transmitter): the triangles (-9 where pending) and the pending rays."""
    n = directions.shape[0]
    triangle, pending = np.full(n, -9, dtype=np.int32), np.empty(n, dtype=np.int64)
    columns = np.asarray(origins, dtype=float).reshape(-1, 3).T
    k = first_hits(np.ascontiguousarray(columns), np.ascontiguousarray(directions.T), hits, triangle, pending)
    return triangle, pending[:k]


def _edge_distance(raycaster: RayCaster, triangle: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Distance (m) of each point (n, 3) from the nearest edge of its triangle (n,)."""
    corners = raycaster.vertices[raycaster.faces[triangle]]  # (n, 3, 3)
    best = np.full(points.shape[0], np.inf)
    for a, b in ((0, 1), (1, 2), (2, 0)):
        edge = corners[:, b] - corners[:, a]
        s = np.clip(np.einsum("ij,ij->i", points - corners[:, a], edge) / np.einsum("ij,ij->i", edge, edge), 0, 1)
        best = np.minimum(best, np.linalg.norm(points - corners[:, a] - s[:, None] * edge, axis=1))
    return best


def _same_plane(raycaster: RayCaster, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Whether triangles a and b (n,) lie on the same plane of the same surface: normals and
    offsets equal to 1e-12 (two triangles of one tessellated cap differ by an ulp, 3e-17 m, in
    their offsets; the face planes merge planes within 1e-9 m)."""
    return (np.all(np.abs(raycaster.face_normals[a] - raycaster.face_normals[b]) < 1e-12, axis=1)
            & (np.abs(raycaster.plane_offset[a] - raycaster.plane_offset[b]) < 1e-12)
            & (raycaster.surface_index[a] == raycaster.surface_index[b]))


@pytest.mark.parametrize("origin", ["transmitter", "random"])
def test_first_hits_equal_embree_but_for_grazing_rays(tank, origin):
    # 50k rays from the transmitter (through the prism's box: the beam points at it) or from
    # random points of the water (in every object's box too). Every decided ray names a triangle
    # of Embree's plane (its normal, offset and surface: all the tracer reads of it); where the
    # planes differ, Embree's float32 hit lies within GRAZING_M of an edge. The rays left
    # pending are those starting inside an object (the random origins only).
    scene, raycaster = tank
    hits = box_tank(raycaster)
    assert hits is not None
    rng = np.random.default_rng(4)
    n = 50_000
    if origin == "transmitter":
        origins = np.broadcast_to(np.asarray(scene.sonar.position_m, dtype=float), (n, 3))
        axis = np.array([1.0, 0.0, 0.0])  # the default pose looks along +x
        directions = rng.normal(size=(n, 3)) + 4.0 * axis  # a third in the main lobe's cone
    else:
        origins = rng.uniform([0.01, 0.01, 0.01], [8.99, 2.99, 0.99], (n, 3))
        directions = rng.normal(size=(n, 3))
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    triangle, pending = _run(hits, origins[0] if origin == "transmitter" else origins, directions)
    embree = raycaster.intersect(origins, directions)
    decided = np.ones(n, dtype=bool)
    decided[pending] = False
    if origin == "transmitter":
        assert pending.size == 0
    else:  # exactly the origins inside an object: the nearest hit is a back face seen from inside
        inside = np.zeros(n, dtype=bool)
        for k, obj in enumerate(scene.objects):
            rows = raycaster.surface_index == len(scene.boundaries) + k
            inside |= trimesh.Trimesh(raycaster.vertices, raycaster.faces[rows]).contains(origins)
        assert np.array_equal(~decided, inside) and 10 < pending.size < 2_500
    assert np.all(triangle[decided] >= 0) and np.all(embree.triangle[decided] >= 0)
    objects = raycaster.surface_index[triangle[decided]] >= len(scene.boundaries)
    assert objects.mean() > (0.1 if origin == "transmitter" else 0.005)  # objects are hit, not only the tank
    same = _same_plane(raycaster, triangle[decided], embree.triangle[decided])
    other = np.flatnonzero(decided)[~same]
    assert other.size <= 10
    hit_points = origins[other] + embree.distance_m[other, None] * directions[other]
    assert np.all(_edge_distance(raycaster, embree.triangle[other], hit_points) < GRAZING_M)


def test_rays_it_cannot_decide_are_pending(tank):
    # An origin outside the tank box, one inside the prism, and a ray through a hole in a face
    # (the floor's triangles removed from the description): pending, for Embree; a ray from the
    # water to an intact face is decided.
    scene, raycaster = tank
    hits = box_tank(raycaster)
    prism = raycaster.vertices[raycaster.faces[raycaster.surface_index == 6]].reshape(-1, 3).mean(axis=0)
    origins = np.array([[-0.5, 1.5, 0.5], prism, [1.0, 1.5, 0.5], [1.0, 1.5, 0.5]])
    directions = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, 0.0, -1.0], [0.0, 0.0, 1.0]])
    triangle, pending = _run(hits, origins, directions)
    assert pending.tolist() == [0, 1]
    assert raycaster.surface_names[raycaster.surface_index[triangle[2]]] == "floor"
    assert raycaster.surface_names[raycaster.surface_index[triangle[3]]] == "surface"
    floor = 4  # face 2 axis + side: z, lo
    start = hits.face_start.copy()
    start[floor + 1:] -= start[floor + 1] - start[floor]
    keep = np.r_[0:hits.face_start[floor], hits.face_start[floor + 1]:hits.face_triangle.size]
    holed = hits._replace(face_start=start, face_triangle=hits.face_triangle[keep], face_edges=hits.face_edges[keep])
    intact = triangle[3]
    triangle, pending = _run(holed, origins[2:], directions[2:])
    assert pending.tolist() == [0] and triangle[1] == intact


def test_a_tank_that_is_not_a_box_is_left_to_embree(tank):
    # A free field (one plane, no box) gets no description, so the tracer asks Embree for
    # every first hit; the thesis tank's box is its boundaries' bounds, every face tiled.
    free_scene = builtin_scene("free-plane")
    assert box_tank(RayCaster.from_scene(free_scene)) is None
    hits = box_tank(tank[1])
    np.testing.assert_array_equal(hits.bounds, [[0.0, 0.0, 0.0], [9.0, 3.0, 1.0]])
    assert np.all(np.diff(hits.face_start) == 2) and np.all(np.diff(hits.planes.start) > 0)


@pytest.mark.parametrize("top", ["closed", "open"])
def test_tracer_rows_equal_the_reference_rows(tank, top):
    # The fast tracer with its first hits found here, against the reference tracer, which asks
    # Embree for every hit: the same rows over two bounces (a ray grazing an edge within float32
    # rounding could differ: none in 20k x 2). Without the free surface (an open top: a face
    # without triangles), the rays leaving through the top are pending and Embree finds they
    # hit nothing.
    scene, raycaster = tank
    if top == "open":
        scene = replace(scene, tank=_OpenTank())
        raycaster = RayCaster.from_scene(scene)
    context = SolveContext.build(scene, scene.sonar, raycaster)
    config = SolverConfig(diffuse_rays=20_000, diffuse_bounces=2, seed=5)
    assert_rows_match(diffuse_rows(context, config), reference.diffuse_rows(context, config), label=top)
    traced = trace_diffuse(context, config)
    if top == "closed":
        assert traced.embree_rays == 0
    else:  # the rays through the top: about a third of the first bounce's (the upper hemisphere,
        # less the beam), fewer of the second's (which the floor and walls send up)
        assert 2_000 < traced.embree_rays < 15_000


def test_a_non_convex_object_sends_only_the_rays_near_it_to_embree():
    # The pipe replaced by a ring (non-convex): rays whose way crosses its box go to Embree, the
    # others are decided here; the events are Embree's.
    scene = builtin_scene("thesis-tank")
    ring = trimesh.creation.annulus(r_min=0.06, r_max=0.12, height=0.6, sections=24)
    ring.apply_translation((3.6, 1.5, 0.5))
    scene = replace(scene, objects=scene.objects[:-1] + (SceneObject("ring-1", "mesh", get_material("pvc"), ring),))
    raycaster = RayCaster.from_scene(scene)
    hits = box_tank(raycaster)
    assert hits.planes.start[-1] == hits.planes.start[-2]  # the ring: no planes
    rng = np.random.default_rng(8)
    origins = np.broadcast_to(np.asarray(scene.sonar.position_m, dtype=float), (20_000, 3))
    directions = rng.normal(size=(20_000, 3))
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    triangle, pending = _run(hits, origins[0], directions)
    embree = raycaster.intersect(origins, directions)
    assert 0 < pending.size < 2_000
    ring_box = (hits.boxes[-1, 0], hits.boxes[-1, 1])
    t = (np.stack(ring_box)[:, None, :] - origins[0]) / directions  # (2, n, 3)
    crossing = np.max(np.minimum(t[0], t[1]), axis=1) <= np.min(np.maximum(t[0], t[1]), axis=1)
    assert np.all(crossing[pending])
    decided = np.ones(20_000, dtype=bool)
    decided[pending] = False
    assert _same_plane(raycaster, triangle[decided], embree.triangle[decided]).mean() > 0.9995


def test_rays_aimed_at_every_object_are_decided_as_embree_decides(tank):
    # Rays from the transmitter to every vertex of every object, pulled 0.1 mm towards the
    # object's centre (the silhouette's extreme points are the nearest the edge of the cone of
    # directions that screens the boxes for a shared origin: a cone too narrow misses them),
    # and to random points of each object's box: the answers are Embree's planes but for
    # grazing rays.
    scene, raycaster = tank
    hits = box_tank(raycaster)
    origin = np.asarray(scene.sonar.position_m, dtype=float)
    rng = np.random.default_rng(12)
    targets = []
    for k, (lo, hi) in enumerate(hits.boxes):
        rows = raycaster.surface_index == len(scene.boundaries) + k
        vertices = raycaster.vertices[np.unique(raycaster.faces[rows])]
        inward = vertices.mean(axis=0) - vertices
        targets += [vertices + 1e-4 * inward / np.linalg.norm(inward, axis=1, keepdims=True),
                    rng.uniform(lo, hi, (2_000, 3))]
    directions = np.concatenate(targets) - origin
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    origins = np.broadcast_to(origin, directions.shape)
    triangle, pending = _run(hits, origin, directions)  # one origin: the boxes' cones screen the rays
    assert pending.size == 0
    embree = raycaster.intersect(origins, directions)
    on_objects = raycaster.surface_index[triangle] >= len(scene.boundaries)
    assert on_objects.mean() > 0.3  # the objects are hit
    other = np.flatnonzero(~_same_plane(raycaster, triangle, embree.triangle))
    assert other.size <= 5
    hit_points = origins[other] + embree.distance_m[other, None] * directions[other]
    assert np.all(_edge_distance(raycaster, embree.triangle[other], hit_points) < GRAZING_M)
