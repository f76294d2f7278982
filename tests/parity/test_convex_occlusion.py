"""Convex objects' face planes, and the fast engine's exact occlusion by them (face-plane
clipping), against Embree's occlusion query and against the reference tracer."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
import trimesh

from acoustisim.materials import get_material
from acoustisim.propagation.config import SolverConfig
from acoustisim.propagation.context import SolveContext
from acoustisim.propagation.convex_planes import mesh_planes
from acoustisim.propagation.fast.convex_occlusion import plane_set, segment_crosses_convex
from acoustisim.propagation.fast.diffuse import diffuse_rows, trace_diffuse
from acoustisim.propagation.raycast import DEFAULT_EPS_M, RayCaster
from acoustisim.propagation.reference import diffuse as reference
from support.parity import assert_rows_match
from acoustisim.scene import SceneObject
from scenes.builtin import builtin_scene

GRAZING_M = 1e-6
"""A leg on which the plane test and Embree may disagree passes within this of the surface:
Embree intersects in float32, whose rounding of coordinates near 5 m from the scene's centre is
about 5e-7 m (the ray caster's docstring); the plane test is float64."""


@pytest.fixture(scope="module")
def tank():
    scene = builtin_scene("thesis-tank")
    return scene, RayCaster.from_scene(scene)


def _object_embree(raycaster, surface):
    """An Embree scene of one object's triangles, in the ray caster's float32 frame."""
    from embreex import rtcore_scene
    from embreex.mesh_construction import TriangleMesh

    rows = raycaster.surface_index == surface
    embree = rtcore_scene.EmbreeScene()
    TriangleMesh(embree, np.ascontiguousarray(raycaster.vertices - raycaster.shift_m, dtype=np.float32),
                 np.ascontiguousarray(raycaster.faces[rows], dtype=np.int32))
    return embree


def _depth(start, unit, t0, t1, normal, offset):
    """Largest depth (m) of the segment start + t unit, t0 <= t <= t1, inside the planes'
    half-spaces: max over t of min over planes of (d - n . x(t)) (positive: it enters the solid
    that deep; negative: it stays outside by at least that in one plane's distance). The
    function of t is concave and piecewise linear: its maximum lies at an end or where two
    planes' lines cross, all of which are evaluated."""
    a = offset - normal @ start  # (k,)
    b = normal @ unit
    with np.errstate(divide="ignore", invalid="ignore"):
        cross = (a[:, None] - a[None, :]) / (b[:, None] - b[None, :])
    candidates = np.concatenate([[t0, t1], cross[np.isfinite(cross)]])
    candidates = candidates[(candidates >= t0) & (candidates <= t1)]
    return float(np.max(np.min(a[None, :] - candidates[:, None] * b[None, :], axis=1)))


def _compare(raycaster, surface, row, starts, ends):
    """The plane test and Embree's OCCLUDED on the legs (shrunk by eps at both ends, as the
    diffuse tracer queries them) against object ``row``: (kernel, embree, depth of disagreements)."""
    seg = ends - starts
    length = np.linalg.norm(seg, axis=1)
    unit = seg / length[:, None]
    planes = raycaster.convex_planes
    compiled = plane_set(planes)
    kernel = np.array([segment_crosses_convex(tuple(p), tuple(u), DEFAULT_EPS_M, t - DEFAULT_EPS_M, compiled, row)
                       for p, u, t in zip(starts.tolist(), unit.tolist(), length.tolist())])
    first, last = int(planes.start[row]), int(planes.start[row + 1])
    embree = _object_embree(raycaster, surface)
    start32 = np.ascontiguousarray(starts + DEFAULT_EPS_M * unit - raycaster.shift_m, dtype=np.float32)
    hits = embree.run(start32, np.ascontiguousarray(unit, dtype=np.float32),
                      dists=np.ascontiguousarray(length - 2 * DEFAULT_EPS_M, dtype=np.float32), query="OCCLUDED")
    blocked = np.asarray(hits) >= 0
    normal, offset = planes.normal[first:last], planes.offset[first:last]
    depth = [_depth(starts[i], unit[i], DEFAULT_EPS_M, length[i] - DEFAULT_EPS_M, normal, offset)
             for i in np.flatnonzero(kernel != blocked)]
    return kernel, blocked, np.array(depth)


def _surface_points(raycaster, surface, n, rng):
    """Uniform random points (n, 3) on an object's triangles and their outward normals."""
    rows = np.flatnonzero(raycaster.surface_index == surface)
    v = raycaster.vertices[raycaster.faces[rows]]  # (m, 3, 3)
    area = 0.5 * np.linalg.norm(np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0]), axis=1)
    pick = rng.choice(rows.size, n, p=area / area.sum())
    r1, r2 = rng.random(n), rng.random(n)
    s = np.sqrt(r1)
    w = np.column_stack([1 - s, s * (1 - r2), s * r2])
    return np.einsum("ij,ijk->ik", w, v[pick]), raycaster.face_normals[rows[pick]]



def test_thesis_objects_are_convex_with_their_face_planes(tank):
    scene, raycaster = tank
    planes = raycaster.convex_planes
    assert planes.convex.tolist() == [True] * len(scene.objects)
    counts = np.diff(planes.start)
    # the prism: 3 sides + 2 caps; the posts: 32 facets + 2 caps; coplanar cap triangles merged
    assert counts[0] == 5
    for k, obj in enumerate(scene.objects):
        if k:
            assert 3 < counts[k] < len(obj.mesh.faces)
        # every vertex of the object lies on or inside every plane; each plane holds a vertex
        vertices = np.asarray(obj.mesh.vertices)
        height = vertices @ planes.normal[planes.start[k]:planes.start[k + 1]].T - planes.offset[
            planes.start[k]:planes.start[k + 1]]
        assert height.max() < 1e-12 and np.all(np.abs(height).min(axis=0) < 1e-12)
    # each plane is its source triangle's, bit for bit (the fast first hits name that triangle)
    np.testing.assert_array_equal(planes.normal, raycaster.face_normals[planes.triangle])
    np.testing.assert_array_equal(planes.offset, raycaster.plane_offset[planes.triangle])
    assert np.all(raycaster.surface_index[planes.triangle] == len(scene.boundaries)
                  + np.repeat(np.arange(len(scene.objects)), counts))


def test_non_convex_open_and_inverted_meshes_get_no_planes():
    ring = trimesh.creation.annulus(r_min=0.05, r_max=0.1, height=0.3, sections=24)
    box = trimesh.creation.box((0.2, 0.3, 0.4))

    def planes(mesh):
        v, f = np.asarray(mesh.vertices, float), np.asarray(mesh.faces, np.int64)
        n = np.asarray(mesh.face_normals, float)
        return mesh_planes(v, f, n, np.einsum("ij,ij->i", n, v[f[:, 0]]))

    assert planes(ring) is None  # not convex (the hole)
    assert planes(box) is not None and planes(box).size == 6
    open_box = box.copy()
    open_box.update_faces(np.arange(len(box.faces)) != 0)
    assert planes(open_box) is None  # one triangle missing: Embree sees through the hole
    inverted = box.copy()
    inverted.invert()
    assert planes(inverted) is None


def test_plane_test_equals_embree_occlusion_on_random_legs(tank):
    # Legs with both ends in a box twice each object's size (crossing it, missing it, ending
    # inside it, lying inside it), and legs starting on the object's surface in every direction
    # (outwards: clear; inwards: through the body, blocked), against Embree's OCCLUDED on the
    # same triangles with the tracer's eps shrink. They may disagree only on grazing legs.
    scene, raycaster = tank
    rng = np.random.default_rng(12)
    n_boundaries = len(scene.boundaries)
    total = 0
    for k, obj in enumerate(scene.objects):
        surface = n_boundaries + k
        lo, hi = obj.bounds_m
        centre, half = 0.5 * (lo + hi), (hi - lo)
        n = 10_000
        starts = rng.uniform(centre - half, centre + half, (n, 3))
        ends = rng.uniform(centre - half, centre + half, (n, 3))
        kernel, embree, depth = _compare(raycaster, surface, k, starts, ends)
        assert 0.1 < kernel.mean() < 0.9  # both outcomes common
        assert np.all(np.abs(depth) < GRAZING_M), (obj.name, depth)
        assert depth.size <= 5, (obj.name, depth.size)
        # self-occlusion: legs from the surface, outwards and inwards
        points, normals = _surface_points(raycaster, surface, 5_000, rng)
        directions = rng.normal(size=(5_000, 3))
        directions /= np.linalg.norm(directions, axis=1, keepdims=True)
        ends = points + rng.uniform(0.01, 0.5, (5_000, 1)) * directions
        kernel, embree, depth = _compare(raycaster, surface, k, points, ends)
        outwards = np.einsum("ij,ij->i", directions, normals) > 0
        # outwards legs leave a convex body for good; an inward leg crosses it (or ends in it
        # when it is short: then no triangle is met, as in Embree)
        assert not kernel[outwards].any()
        assert kernel[~outwards].mean() > 0.3
        assert np.all(np.abs(depth) < GRAZING_M), (obj.name, depth)
        assert depth.size <= 5, (obj.name, depth.size)
        total += depth.size
    assert total <= 10


def test_a_non_convex_object_falls_back_to_embree():
    # The pipe replaced by a thick ring (non-convex: legs through its hole are clear): its legs
    # go to Embree, the convex objects' legs are decided by their planes, and the rows are the
    # reference tracer's, which tests every leg with Embree.
    scene = builtin_scene("thesis-tank")
    ring = trimesh.creation.annulus(r_min=0.06, r_max=0.12, height=0.6, sections=24)
    ring.apply_translation((3.6, 1.5, 0.5))
    objects = scene.objects[:-1] + (SceneObject("ring-1", "mesh", get_material("pvc"), ring),)
    scene = replace(scene, objects=objects)
    raycaster = RayCaster.from_scene(scene)
    assert raycaster.convex_planes.convex.tolist() == [True] * 4 + [False]
    context = SolveContext.build(scene, scene.sonar, raycaster)
    config = SolverConfig(diffuse_rays=20_000, seed=3)
    traced = trace_diffuse(context, config)
    assert traced.embree_legs > 100 and traced.convex_legs > 100
    rows = diffuse_rows(context, config)
    assert_rows_match(rows, reference.diffuse_rows(context, config), label="ring")
    # the ring scatters to the receivers
    assert np.any(rows["object_ids"][:, 0] == len(scene.boundaries) + 4)
