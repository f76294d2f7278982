"""Chains between two objects: the fast engine against the reference engine.

Kernel level: the compiled joint specular points and ray-tube factors against
:mod:`acoustisim.propagation.reference.curved_pairs` on random pairs (spheres, cylinders,
images of cylinders across planes). Engine level: every specular row of a tank with two posts,
a sphere and a tilted cylinder, at random poses, orders 3 and 4 (delays within 1 ps, amplitudes
within 1e-9 relative: :mod:`support.parity`).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from acoustisim.medium import Medium
from acoustisim.propagation import SolverConfig, prepare, solve
from acoustisim.propagation.curved import (CYLINDER_END_TOLERANCE_M, PAIR_MIN_COSINE, PAIR_NEWTON_STEPS,
                                          PAIR_NEWTON_TOLERANCE_M, PAIR_STATIONARY_TOLERANCE, CurvedSet,
                                          cylinder_frame, reflect_primitives)
from acoustisim.propagation.fast.curved_kernels import specular_points
from acoustisim.propagation.fast.pair_kernels import (JointSettings, PairCandidates, joint_specular_points,
                                                      ray_tube_factors)
from acoustisim.propagation.reference.curved_pairs import pair_specular_points, ray_tube_amplitude
from acoustisim.geometry import CylinderPrimitive
from acoustisim.scene import Scene, Tank
from acoustisim.sonar import SonarHead
from scenes.builders import cylinder, post, sphere
from support.parity import assert_rows_match


def _random_pairs(rng: np.random.Generator, n: int) -> tuple[CurvedSet, CurvedSet, np.ndarray, np.ndarray]:
    """n (C1, C2, a, b): spheres and cylinders of random axes near the origin, C2 mirrored
    across a random plane half of the time, a and b a metre or two away."""
    is_sphere = rng.random((2, n)) < 0.4
    centre = rng.uniform(-0.4, 0.4, (2, n, 3))
    radius = rng.uniform(0.02, 0.1, (2, n))
    length = np.where(is_sphere, np.inf, rng.uniform(0.3, 1.5, (2, n)))
    frames = np.empty((2, n, 3, 3))
    for k in range(2):
        for i in range(n):
            axis = rng.normal(size=3)
            frames[k, i] = np.eye(3) if is_sphere[k, i] else cylinder_frame(
                CylinderPrimitive(tuple(centre[k, i]), tuple(axis / np.linalg.norm(axis)), radius[k, i], length[k, i]))
    first, second = (CurvedSet(is_sphere[k], centre[k], frames[k], radius[k], length[k]) for k in range(2))
    mirrored = rng.random(n) < 0.5
    normal = rng.normal(size=(n, 3))
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    image = reflect_primitives(second, normal * 1.5, normal)
    second = CurvedSet(*(np.where(mirrored.reshape((n,) + (1,) * (mine.ndim - 1)), theirs, mine)
                         for mine, theirs in zip(second, image)))
    direction = rng.normal(size=(2, n, 3))
    direction /= np.linalg.norm(direction, axis=2, keepdims=True)
    a, b = direction * rng.uniform(1.0, 2.0, (2, n, 1))
    return first, second, a, b


def test_joint_specular_points_and_ray_tube_match_the_reference():
    rng = np.random.default_rng(29)
    first, second, a, b = _random_pairs(rng, 1500)
    x1, x2, valid = pair_specular_points(first, second, a, b)
    rows = np.arange(a.shape[0])
    # the fast engine's start: the same alternating single-surface solves (compiled)
    start = specular_points(first, rows, a, second.centre).point
    second_start = specular_points(second, rows, start, b).point
    first_start = specular_points(first, rows, a, second_start).point
    n = a.shape[0]
    candidates = PairCandidates(rows, rows, rows, rows, rows, a, b, np.ascontiguousarray(second.centre),
                                np.ascontiguousarray(second.frame))
    settings = JointSettings(PAIR_NEWTON_STEPS, PAIR_NEWTON_TOLERANCE_M, PAIR_STATIONARY_TOLERANCE,
                             CYLINDER_END_TOLERANCE_M, PAIR_MIN_COSINE)
    y1, y2, fast_valid = joint_specular_points(first, second, candidates, first_start, second_start, settings)
    assert np.array_equal(valid, fast_valid)
    assert 0.2 * n < valid.sum() < 0.9 * n  # both outcomes are exercised
    for mine, theirs in ((x1, y1), (x2, y2)):
        # Newton converged to ~1e-15 m in both: 1e-12 m is round-off, not a method difference
        assert np.abs(mine.point[valid] - theirs.point[valid]).max() < 1e-12
        assert np.abs(mine.normal[valid] - theirs.normal[valid]).max() < 1e-10
    keep = np.flatnonzero(valid)
    pick = (lambda x: type(x)(*(field[keep] for field in x)))
    reference = ray_tube_amplitude(a[keep], [pick(x1), pick(x2)], b[keep])
    fast = ray_tube_factors(keep, a, b, y1, y2)
    np.testing.assert_allclose(fast, reference, rtol=1e-10, atol=0)


OBJECTS = (post("post-1", (3.0, 1.2), 0.025, 1.0, "pvc"), post("post-2", (3.25, 1.8), 0.03, 1.0, "pvc"),
           sphere("ball", (3.6, 1.5, 0.45), 0.06, "steel"),
           cylinder("log", (4.0, 0.9, 0.35), (0.3, 1.0, 0.1), 0.04, 0.6, "rigid"))
SONAR = SonarHead(position_m=(2.2, 1.4, 0.42), yaw_deg=8.0, pitch_deg=2.0)


def _poses(n: int, seed: int):
    rng = np.random.default_rng(seed)
    yield SONAR
    for _ in range(n):
        yield SONAR.with_pose(position_m=tuple(np.asarray(SONAR.position_m) + rng.uniform(-0.15, 0.15, 3)),
                              yaw_deg=float(SONAR.yaw_deg + rng.uniform(-25, 25)),
                              pitch_deg=float(rng.uniform(-5, 5)))


def _between_objects(rows: np.ndarray) -> np.ndarray:
    """The rows reflected by two of the scene's curved objects (surfaces 6 to 9)."""
    return rows[np.isin(rows["object_ids"], [6, 7, 8, 9]).sum(axis=1) == 2]


def test_engines_agree_on_chains_between_posts_a_sphere_and_a_cylinder():
    """Every specular row, order 3, three poses."""
    prepared = prepare(Scene("posts", Medium(), SONAR, Tank(9.0, 3.0, 1.0), OBJECTS))
    config = SolverConfig(max_order=3, mechanisms=("specular",), amplitude_floor_db=None)
    n_pairs = 0
    for i, sonar in enumerate(_poses(2, seed=31)):
        fast = solve(prepared, sonar, config).rows
        reference = solve(prepared, sonar, replace(config, backend="reference")).rows
        assert_rows_match(fast, reference, label=f"posts/pose {i}")
        n_pairs += _between_objects(fast).size
    assert n_pairs > 300  # the chains between objects are there to compare


def test_engines_agree_on_order_four_chains_between_objects():
    """The chains between two objects of order 4 (two mirrors before, between or after them).

    Only these: at this pose a single-object chain of order 4 (wall, wall, ball, wall) meets
    the ball within 0.02 degrees of grazing, where its specular point is fixed by the float64
    geometry only to ~1e-13 m, and the two engines' single-surface solves (whose dot products
    are summed in different orders) give gains 1e-7 apart: a pre-existing difference of the
    one-curved-surface chains, which ``max_curved_per_path`` does not touch."""
    prepared = prepare(Scene("posts", Medium(), SONAR, Tank(9.0, 3.0, 1.0), OBJECTS))
    config = SolverConfig(max_order=4, mechanisms=("specular",), amplitude_floor_db=None)
    fast = _between_objects(solve(prepared, SONAR, config).rows)
    reference = _between_objects(solve(prepared, SONAR, replace(config, backend="reference")).rows)
    assert_rows_match(fast, reference, label="posts/order 4")
    assert np.sum(fast["order"] == 4) > 1000
