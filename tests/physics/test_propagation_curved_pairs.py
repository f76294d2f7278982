"""Specular chains between two objects (two curved reflections): closed forms, an independent ray
tube, stationary phase, the planar limit, reciprocity, the reflection law and Fermat."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
import trimesh

from acoustisim.geometry import CylinderPrimitive, SpherePrimitive
from acoustisim.medium import Medium
from acoustisim.propagation import PathKind, SolverConfig, prepare, solve
from acoustisim.propagation.config import BACKENDS
from acoustisim.scene import Scene, SceneObject, Tank
from acoustisim.sonar import SonarHead
from scenes.builders import cylinder, plate, post, sphere
from support.ray_tubes import Cylinder, Plane, Sphere, ray_tube_pressure

CONFIG = SolverConfig(max_order=3, mechanisms=("direct", "specular"), amplitude_floor_db=None, shadows=False)
"""Geometric optics alone: without the diffracted shadows (a chain grazing an object would carry
their factor, tests/physics/test_shadows.py)."""


def _sonar(channels=((-0.065, 0.0, 0.0), (0.0, 0.0, 0.0), (0.065, 0.0, 0.0)), position=(0.0, 0.0, 0.0),
           **pose) -> SonarHead:
    """Sonar at ``position`` looking along +x (head (x, y, z) maps to tank (y, -x, z))."""
    return SonarHead(position_m=position, channel_positions_m=channels, **pose)


def _free_scene(objects: tuple[SceneObject, ...], sonar: SonarHead) -> Scene:
    return Scene("free", Medium(), sonar, None, objects)


def _curved_surfaces(scene: Scene) -> set[int]:
    first = len(scene.boundaries)
    return {first + j for j, obj in enumerate(scene.objects)
            if isinstance(obj.primitive, (SpherePrimitive, CylinderPrimitive))}


def _pair_rows(paths, scene: Scene) -> np.ndarray:
    """The specular rows reflected by two curved objects."""
    curved = np.array(sorted(_curved_surfaces(scene)))
    n_curved = np.isin(paths["object_ids"], curved).sum(axis=1)
    return paths.rows[(paths["kind"] == PathKind.SPECULAR) & (n_curved == 2)]


def _row(paths, channel: int, label: str) -> np.void:
    labels = paths.object_labels()
    rows = [i for i, lab in enumerate(labels) if lab == label and paths["channel"][i] == channel]
    assert len(rows) == 1, (label, channel, [lab for lab in labels if ">" in lab])
    return paths.rows[rows[0]]


def _ray_surface(scene: Scene, surface: int, point: np.ndarray):
    """The exact surface the ray tracer reflects from at ``point``: the object's primitive, or
    the plane of the mesh face there (a plate)."""
    obj = scene.objects[surface - len(scene.boundaries)]
    prim = obj.primitive
    if isinstance(prim, SpherePrimitive):
        return Sphere(np.asarray(prim.center_m), prim.radius_m)
    if isinstance(prim, CylinderPrimitive):
        return Cylinder(np.asarray(prim.center_m), np.asarray(prim.axis), prim.radius_m)
    _, distance, face = trimesh.proximity.closest_point(obj.mesh, point[None])
    assert distance[0] < 1e-9
    return Plane(point, np.asarray(obj.mesh.face_normals[face[0]]))


def on_primitive(surface: Sphere | Cylinder, x: np.ndarray) -> np.ndarray:
    """``x`` moved radially onto the exact sphere or (infinite) cylinder (in ``x``'s precision)."""
    axis = getattr(surface, "axis", np.zeros(3))
    along = (x - surface.centre) @ axis
    radial = x - surface.centre - along * axis
    return surface.centre + along * axis + surface.radius * radial / np.sqrt(radial @ radial)


def _vertices(row: np.void, sonar: SonarHead) -> np.ndarray:
    k = int(row["order"])
    return np.vstack([sonar.transmitter_position, row["points_m"][:k], sonar.receiver_positions[row["channel"]]])


def _objects_ahead() -> tuple[SceneObject, ...]:
    """Rigid (R = 1) objects around the sonar's axis: two spheres, a vertical post, a tilted
    cylinder and a flat plate (a planar mirror) behind them."""
    return (sphere("ball", (1.2, 0.3, 0.1), 0.06, "rigid"), sphere("bead", (0.85, 0.4, -0.15), 0.04, "rigid"),
            cylinder("post", (1.0, -0.25, 0.0), (0.0, 0.0, 1.0), 0.03, 1.0, "rigid"),
            cylinder("log", (1.6, -0.05, -0.1), (0.3, 1.0, 0.2), 0.04, 0.8, "rigid"),
            plate("wall", (2.3, 0.0, 0.0), (-1.0, 0.1, 0.0), 2.0, 1.2, 0.02, "rigid"))


OBLIQUE_SONAR = _sonar(channels=((-0.07, 0.01, 0.05), (0.0, 0.0, 0.0), (0.065, -0.02, -0.04)), pitch_deg=4.0)


@pytest.fixture(scope="module", params=BACKENDS)
def oblique_paths(request):
    scene = _free_scene(_objects_ahead(), OBLIQUE_SONAR)
    return scene, solve(scene, config=replace(CONFIG, backend=request.param))


def test_two_spheres_in_line_closed_form(backend):
    """On one line the ray tube is stigmatic: each convex sphere turns a wavefront of radius rho
    into one of radius 1 / (1 / rho + 2 / a), and the pressure falls as rho / (rho + s) over a
    leg s: the product of the single-sphere factors with the unfolded distances."""
    a1, a2, d, e = 0.05, 0.08, 0.6, 0.9
    scene = _free_scene((sphere("front", (d + a1, 0.0, 0.0), a1, "rigid"),
                         sphere("back", (-(e + a2), 0.0, 0.0), a2, "rigid")), _sonar())
    paths = solve(scene, config=replace(CONFIG, backend=backend))

    def in_line(r0: float, first: float, r1: float, second: float, r2: float) -> float:
        rho1 = 1.0 / (1.0 / r0 + 2.0 / first)
        rho2 = 1.0 / (1.0 / (rho1 + r1) + 2.0 / second)
        return (1.0 / r0) * rho1 / (rho1 + r1) * rho2 / (rho2 + r2)

    forward, backward = _row(paths, 1, "front>back"), _row(paths, 1, "back>front")
    expected = in_line(d, a1, d + e, a2, e)
    # the same formula evaluated two ways (ray tube vs closed form): round-off only
    assert forward["geometric_gain"] == pytest.approx(expected, rel=1e-12)
    # reciprocity of the closed form itself: the reversed chain, source and receiver swapped
    assert backward["geometric_gain"] == pytest.approx(in_line(e, a2, d + e, a1, d), rel=1e-12)
    assert expected == pytest.approx(in_line(e, a2, d + e, a1, d), rel=1e-12)
    for row in (forward, backward):
        assert row["path_length_m"] == pytest.approx(2 * (d + e), rel=1e-14)
        assert row["order"] == 2


def test_oblique_pairs_against_a_traced_ray_tube(oblique_paths):
    """Every chain through two curved objects (and through the plate between or around them)
    against brute-force geometric optics: a bundle of rays reflected off the exact surfaces,
    its Jacobian by the complex-step derivative (``support.ray_tubes``)."""
    scene, paths = oblique_paths
    rows = _pair_rows(paths, scene)
    labels = set()
    for row in rows:
        vertices = _vertices(row, OBLIQUE_SONAR)
        surfaces = [_ray_surface(scene, int(row["object_ids"][j]), vertices[j + 1]) for j in range(int(row["order"]))]
        tube = ray_tube_pressure(vertices[0], row["departure_dir"], surfaces, vertices[-1])
        widths = np.linalg.svd(tube.jacobian, compute_uv=False)
        # the central ray lands on the receiver: the specular points are the path's (a
        # departure direction off by ~1e-15 rad, magnified by the tube's largest width)
        assert tube.miss_m < 1e-14 * widths[0], (tube.miss_m, widths)
        # the complex-step Jacobian, in extended precision at the aimed ray, is exact to
        # ~1e-19 x the tube's condition number (up to 5e6 here): 1e-11; the engines' amplitude is
        # the ray tube's at points converged to ~1e-15 m; 1e-9 leaves a margin for both
        assert row["geometric_gain"] == pytest.approx(tube.pressure, rel=1e-9)
        labels.add(">".join(scene.surface_names[s] for s in row["object_ids"][:row["order"]]))
    # the check covers sphere-sphere, sphere-cylinder, cylinder-cylinder (via the plate), an object via the
    # plate back to itself, and the plate before, between and after the two objects
    assert {"ball>bead", "ball>post", "post>ball", "log>ball", "log>wall>log", "wall>log>post"} <= labels, labels
    for position in range(3):
        assert any(label.count(">") == 2 and label.split(">")[position] == "wall" for label in labels), labels
    assert len(rows) > 60


def test_oblique_pairs_against_stationary_phase(oblique_paths):
    """Every chain through two curved objects against the iterated Kirchhoff integral over both
    surfaces evaluated by stationary phase: |p| = cos1 cos2 / (r0 r1 r2 sqrt|det H4|), H4 the
    Hessian of the path length in the two tangent planes (by finite differences of the exact
    path length, each point moved along its surface, the plate's reflection by its image), r_j
    the unfolded lengths of the three stretches."""
    scene, paths = oblique_paths
    rows = _pair_rows(paths, scene)
    curved = _curved_surfaces(scene)
    labels = set()
    for row in rows:
        v = _vertices(row, OBLIQUE_SONAR)
        ids = [int(i) for i in row["object_ids"][:row["order"]]]
        surfaces = [_ray_surface(scene, i, v[j + 1]) for j, i in enumerate(ids)]
        at = [j for j, i in enumerate(ids) if i in curved]  # the two curved reflections
        frames = []
        for j in at:
            n = surfaces[j].normal_at(v[j + 1])
            t1 = np.cross(n, [0.3, 0.2, 1.0])
            t1 /= np.linalg.norm(t1)
            frames.append((surfaces[j], v[j + 1], np.column_stack([t1, np.cross(n, t1)])))
        # the three stretches (vertex index ranges) between the ends and the curved points
        ends = [0, at[0] + 1, at[1] + 1, len(v) - 1]
        planes = [[surfaces[j - 1] for j in range(a + 1, b)] for a, b in zip(ends[:-1], ends[1:])]

        # the path length in extended precision: the 4-point second differences lose
        # 1e-16 L / h^2 in float64, too much near grazing (cos 0.003 here), where the Hessian's
        # smallest eigenvalue is only ~2 cos K ~ 0.15 / m
        wide = np.longdouble
        ends_wide = (v[0].astype(wide), v[-1].astype(wide))
        frames_wide = [(surface, x.astype(wide), tangent.astype(wide)) for surface, x, tangent in frames]

        def length(u: np.ndarray) -> np.longdouble:
            points = [ends_wide[0]] + [on_primitive(surface, x + tangent @ du)
                                       for (surface, x, tangent), du in zip(frames_wide, (u[:2], u[2:]))]
            points.append(ends_wide[1])
            total = wide(0.0)
            for start, end, mirrors in zip(points[:-1], points[1:], planes):
                for plane in mirrors:  # the start's image across the stretch's mirrors
                    start = start - 2 * ((start - plane.point) @ plane.normal) * plane.normal
                total += np.sqrt((end - start) @ (end - start))
            return total

        h = wide(3e-6)
        hessian = np.empty((4, 4))
        for i in range(4):
            for j in range(4):
                e_i, e_j = np.eye(4, dtype=wide)[i] * h, np.eye(4, dtype=wide)[j] * h
                hessian[i, j] = (length(e_i + e_j) - length(e_i - e_j) - length(-e_i + e_j)
                                 + length(-e_i - e_j)) / (4 * h * h)
        legs = np.diff(v, axis=0)
        r = np.linalg.norm(legs, axis=1)
        stretches = [r[a:b].sum() for a, b in zip(ends[:-1], ends[1:])]
        cosines = [abs(legs[j] @ surfaces[j].normal_at(v[j + 1])) / r[j] for j in at]
        expected = cosines[0] * cosines[1] / (np.prod(stretches) * np.sqrt(abs(np.linalg.det(hessian))))
        # h = 3e-6 m: truncation (h^2 / 12) x 4th derivatives and round-off 1e-19 L / h^2 ~ 5e-8
        # on an eigenvalue of 0.15: the worst row agrees to 1e-7; 1e-6 leaves a margin
        assert row["geometric_gain"] == pytest.approx(expected, rel=1e-6)
        labels.add(">".join(scene.surface_names[s] for s in ids))
    assert {"ball>bead", "bead>ball", "log>wall>log", "post>wall>post", "ball>post"} <= labels, labels
    assert len(rows) > 60


def test_large_spheres_converge_to_the_two_plates_image_path(backend):
    """Two spheres tangent to two facing planes converge, as their radius R grows, to the image
    path of the two plates (itself the closed-form image of the transmitter across both
    planes): delay and amplitude errors fall as 1 / R."""
    sonar = _sonar(channels=((-0.07, 0.02, 0.04), (0.0, 0.0, 0.0), (0.065, -0.03, -0.02)), yaw_deg=4.0,
                   pitch_deg=2.0)
    near, far = 0.8, 1.1  # the planes x = near (facing -x) and x = -far (facing +x)
    plates = (plate("p1", (near + 0.01, 0.0, 0.0), (-1.0, 0.0, 0.0), 2.0, 2.0, 0.02, "rigid"),
              plate("p2", (-far - 0.01, 0.0, 0.0), (1.0, 0.0, 0.0), 2.0, 2.0, 0.02, "rigid"))
    planar = solve(_free_scene(plates, sonar), config=replace(CONFIG, backend=backend))
    tx = sonar.transmitter_position
    errors = []
    for radius in (100.0, 10000.0):
        balls = (sphere("p1", (near + radius, 0.0, 0.0), radius, "rigid"),
                 sphere("p2", (-far - radius, 0.0, 0.0), radius, "rigid"))
        curved = solve(_free_scene(balls, sonar), config=replace(CONFIG, backend=backend))
        worst = [0.0, 0.0]
        for channel in range(3):
            flat = _row(planar, channel, "p1>p2")
            image = np.array([-2 * far - (2 * near - tx[0]), tx[1], tx[2]])  # across x = near, then x = -far
            length = np.linalg.norm(sonar.receiver_positions[channel] - image)
            assert flat["path_length_m"] == pytest.approx(length, rel=1e-14)
            assert flat["geometric_gain"] == pytest.approx(1.0 / length, rel=1e-14)
            row = _row(curved, channel, "p1>p2")
            worst[0] = max(worst[0], abs(row["path_length_m"] - length) / length)
            worst[1] = max(worst[1], abs(row["geometric_gain"] * length - 1.0))
        errors.append(worst)
    (delay_near, gain_near), (delay_far, gain_far) = errors
    # the amplitude's relative error is ~ L / R (a few % at R = 100 m) and falls 100-fold (to
    # within the second-order terms, ~(L / R)^2 / (L / R) ~ 3 %); the delay's, ~ offset^2 / (R L),
    # falls as fast
    assert 1e-3 < gain_near < 0.1 and gain_far == pytest.approx(gain_near / 100, rel=0.05)
    assert delay_near > 1e-7 and delay_far == pytest.approx(delay_near / 100, rel=0.05)


TANK_OBJECTS = (post("post-1", (3.0, 1.2), 0.025, 1.0, "pvc"), post("post-2", (3.25, 1.8), 0.03, 1.0, "pvc"),
                sphere("ball", (3.6, 1.5, 0.45), 0.06, "steel"),
                cylinder("log", (4.0, 0.9, 0.35), (0.3, 1.0, 0.1), 0.04, 0.6, "rigid"))
TANK_SONAR = SonarHead(position_m=(2.2, 1.4, 0.42), yaw_deg=8.0, pitch_deg=2.0,
                       channel_positions_m=((-0.3, 0.05, 0.12), (0.0, 0.0, 0.0), (0.065, 0.0, 0.0)))


def _tank_scene(sonar: SonarHead = TANK_SONAR) -> Scene:
    return Scene("posts", Medium(), sonar, Tank(9.0, 3.0, 1.0), TANK_OBJECTS)


@pytest.fixture(scope="module", params=BACKENDS)
def tank_paths(request):
    scene = _tank_scene()
    config = replace(CONFIG, max_order=4, backend=request.param)
    return scene, solve(prepare(scene), config=config)


def test_reflection_law_coplanarity_and_fermat_at_every_vertex(tank_paths):
    """Every chain through two curved objects in a tank, walls, floor and surface before, between
    and after them (order <= 4): at each vertex the reflection law against the true normal
    (incidence = reflection, in the plane of incidence: the mirrored incoming direction is the
    outgoing one), and Fermat (a tangent move of any vertex lengthens the path to second order)."""
    scene, paths = tank_paths
    rows = _pair_rows(paths, scene)
    curved = _curved_surfaces(scene)
    labels = set()
    for row in rows:
        v = _vertices(row, TANK_SONAR)
        legs = np.linalg.norm(np.diff(v, axis=0), axis=1)

        def normal(j: int) -> np.ndarray:
            surface = int(row["object_ids"][j - 1])
            if surface in curved:
                return _ray_surface(scene, surface, v[j]).normal_at(v[j])
            return np.asarray(scene.boundaries[surface].plane.normal)

        for j in range(1, int(row["order"]) + 1):
            surface = int(row["object_ids"][j - 1])
            if surface in curved:  # the point is on the exact surface
                assert np.linalg.norm(on_primitive(_ray_surface(scene, surface, v[j]), v[j]) - v[j]) < 1e-12
            if legs[j - 1] < 1e-9:
                continue  # the second vertex of a corner-line pair, checked with the first
            n = normal(j)
            d_in = (v[j] - v[j - 1]) / legs[j - 1]
            end = j
            while legs[end] < 1e-9:
                end += 1  # a right-angle corner line (a post meeting the floor): coincident vertices
            d_out = (v[end + 1] - v[end]) / legs[end]
            if end > j:
                # the wave leaves after reflecting on every plane of the corner
                mirrored = d_in
                for k in range(j, end + 1):
                    mirrored = mirrored - 2.0 * (mirrored @ normal(k)) * normal(k)
                assert np.linalg.norm(mirrored - d_out) < 1e-9
                continue
            # incidence = reflection angle, and the two legs coplanar with the normal; points
            # exact to ~1e-15 m over legs of >= 2 cm: 1e-9 is 1e5 x round-off
            assert abs(abs(d_in @ n) - abs(d_out @ n)) < 1e-9
            assert abs(np.linalg.det(np.stack([d_in, n, d_out]))) < 1e-9
            assert d_in @ n < 0 < d_out @ n  # arrives at and leaves the water side
            if surface not in curved:
                continue
            exact = _ray_surface(scene, surface, v[j])
            # Fermat: stationary (central difference over a tangent move of +-1e-6 m: round-off
            # 1e-8, while a reflection-law mismatch eps would show as eps) and a minimum (a move
            # of 1e-4 m along the surface lengthens the path by h^2 lambda / 2, >= 3e-11 here
            # even along a cylinder's axis; the sum of the legs is exact to ~1e-15 m)
            for t in np.linalg.svd(n[None])[2][1:]:
                lengths = []
                for h in (1e-6, -1e-6):
                    moved = v.copy()
                    moved[j] = moved[j] + h * t
                    lengths.append(np.sum(np.linalg.norm(np.diff(moved, axis=0), axis=1)))
                assert abs(lengths[0] - lengths[1]) / 2e-6 < 1e-7
                for h in (1e-4, -1e-4):
                    moved = v.copy()
                    moved[j] = on_primitive(exact, moved[j] + h * t)
                    assert np.sum(np.linalg.norm(np.diff(moved, axis=0), axis=1)) > row["path_length_m"] + 1e-13
        labels.add(">".join(scene.surface_names[s] for s in row["object_ids"][:row["order"]]))
    names = {name for label in labels for name in label.split(">")}
    # posts, the sphere, the tilted cylinder, walls and the floor and surface all take part,
    # including post -> wall -> post and a chain of order 4
    assert {"post-1", "post-2", "ball", "log", "floor", "surface"} <= names, names
    assert any(label.startswith("post") and label.count(">") == 2 and label.split(">")[2].startswith("post")
               and label.split(">")[1].startswith("wall") for label in labels), sorted(labels)
    assert rows["order"].max() == 4 and rows.size > 200


def test_reciprocity_swapping_transmitter_and_receiver(backend):
    """Swap the transmitter and the left receiver: every chain between two objects comes back
    reversed with the same delay and the same amplitude (reflection coefficients included)."""
    a = TANK_SONAR
    p, q = a.transmitter_position, a.receiver_positions[0]
    b0 = a.with_pose(q)
    b = replace(b0, channel_positions_m=(tuple(b0.tank_to_head(p[None])[0]), (0.0, 0.0, 0.0), (0.065, 0.0, 0.0)))
    np.testing.assert_allclose(b.receiver_positions[0], p, atol=1e-12)
    prepared = prepare(_tank_scene())
    config = replace(CONFIG, backend=backend)
    forward = _pair_rows(solve(prepared, a, config).for_channel(0), prepared.scene)
    backward = _pair_rows(solve(prepared, b, config).for_channel(0), prepared.scene)
    assert forward.size == backward.size and forward.size > 30
    fr = forward[np.lexsort((forward["geometric_gain"], forward["delay_s"]))]
    br = backward[np.lexsort((backward["geometric_gain"], backward["delay_s"]))]
    # different but equivalent arithmetic (Newton from other starts, the ray tube run backwards):
    # delays to 1e-12, amplitudes to 1e-9 relative
    np.testing.assert_allclose(fr["delay_s"], br["delay_s"], rtol=1e-12, atol=0)
    np.testing.assert_allclose(fr["geometric_gain"], br["geometric_gain"], rtol=1e-9, atol=0)
    for f, g in zip(fr, br):
        k = int(f["order"])
        assert list(f["object_ids"][:k]) == list(g["object_ids"][:k][::-1])


def test_one_curved_reflection_per_path_gives_exactly_the_other_rows(backend):
    """``max_curved_per_path`` = 1 drops the chains between two objects and changes nothing
    else (the new chains are numbered after every other). Elastic echoes off: their transfer
    functions are numbered over every echo, so ``response_id`` would shift with the new rows."""
    prepared = prepare(_tank_scene())
    two = solve(prepared, config=replace(CONFIG, backend=backend, elastic_echoes=False))
    one = solve(prepared, config=replace(CONFIG, backend=backend, max_curved_per_path=1, elastic_echoes=False))
    pairs = _pair_rows(two, prepared.scene)
    assert pairs.size > 30 and _pair_rows(one, prepared.scene).size == 0
    curved = np.array(sorted(_curved_surfaces(prepared.scene)))
    others = two.rows[np.isin(two["object_ids"], curved).sum(axis=1) < 2]
    assert others.tobytes() == one.rows.tobytes()
