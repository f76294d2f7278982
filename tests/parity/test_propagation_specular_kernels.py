"""The fast engine's specular kernels against the reference engine's functions, one by one.

``tests/parity/test_engine_parity.py`` compares the two engines' rows on the canonical scenes
(and the thesis tank under ``slow``); here each compiled step is checked against its reference
twin (:mod:`acoustisim.propagation.reference.image_source`, ``.curved``, ``.specular``), and the
whole specular solve on a scene with a smooth mesh (which no canonical scene has).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from acoustisim.errors import InputError
from acoustisim.propagation import SolverConfig, prepare, solve
from acoustisim.propagation.context import SolveContext
from acoustisim.propagation.curved import CurvedSet, SurfacePoints
from acoustisim.propagation.fast import curved_kernels
from acoustisim.propagation.fast.chain_kernels import ChainEnds, duplicate_keys, path_columns, write_rows
from acoustisim.propagation.fast.mirror_kernels import backtrace_chains, mirror_arrays, unfold_reversed
from acoustisim.propagation.fast.specular import Pose, first_distinct_rows, planar_and_mixed, unblocked
from acoustisim.propagation.solver import check_sonar
from acoustisim.propagation.paths import MAX_INTERACTIONS, PathKind, empty_paths_array
from acoustisim.propagation.prepared import PreparedScene
from acoustisim.propagation.reference import curved as reference_curved
from acoustisim.propagation.reference.image_source import backtrace, unfold
from acoustisim.propagation.reference.specular import duplicate_key, receivers_in_front
from acoustisim.geometry import CylinderPrimitive, SpherePrimitive
from support.parity import assert_rows_match


@pytest.fixture(scope="module")
def thesis_tank(builtin_scenes) -> PreparedScene:
    return prepare(builtin_scenes("thesis-tank"))


def _poses(prepared: PreparedScene, n: int, seed: int) -> list[SolveContext]:
    """The default pose and n - 1 random ones the solver accepts (anywhere in the tank, any yaw)."""
    rng = np.random.default_rng(seed)
    contexts = [SolveContext.build(prepared.scene, prepared.scene.sonar, prepared.raycaster)]
    while len(contexts) < n:
        sonar = replace(prepared.scene.sonar, position_m=tuple(rng.uniform((0.3, 0.3, 0.15), (8.7, 2.7, 0.85))),
                        yaw_deg=float(rng.uniform(-180, 180)), pitch_deg=float(rng.uniform(-20, 20)))
        try:
            check_sonar(prepared, sonar)
        except InputError:
            continue
        contexts.append(SolveContext.build(prepared.scene, sonar, prepared.raycaster))
    return contexts


def _pose(prepared: PreparedScene, context: SolveContext) -> Pose:
    mirrors = prepared.mirrors
    first = mirrors.signed_distance(np.broadcast_to(context.transmitter_m, (mirrors.count, 3)),
                                    np.arange(mirrors.count)) > 0
    return Pose(mirrors, mirror_arrays(mirrors), ChainEnds(context.transmitter_m, context.receivers_m.copy()), first,
                receivers_in_front(context, mirrors))


def _random_pairs(rng: np.random.Generator, curved: CurvedSet, n: int) -> tuple[np.ndarray, ...]:
    """Sources and receivers 1.05 to 40 radii from random primitives of ``curved``, some
    monostatic, some opposite (no lit point)."""
    which = rng.integers(0, curved.radius.size, n)
    radius = curved.radius[which]

    def around() -> np.ndarray:
        direction = rng.normal(size=(n, 3))
        direction /= np.linalg.norm(direction, axis=1, keepdims=True)
        return curved.centre[which] + direction * (rng.uniform(1.05, 40.0, n) * radius)[:, None]

    a, b = around(), around()
    b[:300] = a[:300]
    b[300:400] = 2 * curved.centre[which[300:400]] - a[300:400]
    return which, a, b


def test_specular_points_on_primitives_match_the_reference():
    curved = CurvedSet.from_primitives([SpherePrimitive((1.0, 2.0, 0.5), 0.05), SpherePrimitive((0.0, 0.0, 0.0), 0.3),
                                        CylinderPrimitive((3.0, 1.0, 0.5), (0.0, 0.0, 1.0), 0.025, 1.0),
                                        CylinderPrimitive((2.0, 2.0, 0.4), (0.3, 1.0, 0.1), 0.1, 0.6)])
    which, a, b = _random_pairs(np.random.default_rng(2), curved, 6000)
    fast = curved_kernels.specular_points(curved, which, a, b)
    reference = reference_curved.specular_points(curved, which, a, b)
    np.testing.assert_array_equal(fast.valid, reference.valid)
    valid = fast.valid
    assert 1000 < valid.sum() < valid.size  # lit and unlit pairs, on every primitive
    assert set(which[valid].tolist()) == {0, 1, 2, 3}
    # the same Newton iterations (the compiled loop stops a row at its fixed point, which the
    # reference's further steps leave unchanged) and the same formulas, numpy's sums reordered:
    # a few ulps of the tank's coordinates
    for name in ("point", "normal", "e1", "e2"):
        np.testing.assert_allclose(getattr(fast, name)[valid], getattr(reference, name)[valid], rtol=0, atol=1e-13,
                                   err_msg=name)
    for name in ("k11", "k22", "k12"):
        np.testing.assert_array_equal(getattr(fast, name), getattr(reference, name), err_msg=name)


def test_specular_points_are_stationary():
    """The compiled solve's answer is the specular point: the path length a -> X -> b does not
    change to first order along the surface at X (both tangent directions)."""
    curved = CurvedSet.from_primitives([SpherePrimitive((0.0, 0.0, 0.0), 0.2),
                                        CylinderPrimitive((1.0, 0.0, 0.0), (0.0, 0.6, 0.8), 0.05, 5.0)])
    which, a, b = _random_pairs(np.random.default_rng(3), curved, 3000)
    x = curved_kernels.specular_points(curved, which, a, b)

    def distance(p: np.ndarray) -> np.ndarray:
        """From the sphere's centre, or from the cylinder's axis (the circle problem's plane)."""
        u = p - curved.centre[which]
        axis = curved.frame[which, 2]
        along = np.where(curved.is_sphere[which], 0.0, np.einsum("ij,ij->i", u, axis))
        return np.linalg.norm(u - along[:, None] * axis, axis=1)

    # both ends beyond 1.5 radii: from the bisector start, the clipped Newton steps can cycle
    # between two angles when an end is within a few percent of a radius of the surface (a
    # known limitation; no such pair occurred among 80,000 valid specular points of 60 random
    # thesis-tank poses)
    valid = x.valid & (np.minimum(distance(a), distance(b)) > 1.5 * curved.radius[which])
    assert valid.sum() > 500
    for tangent in (x.e1, x.e2):
        s1 = x.point - a
        s2 = x.point - b
        derivative = (np.einsum("ij,ij->i", s1, tangent) / np.linalg.norm(s1, axis=1)
                      + np.einsum("ij,ij->i", s2, tangent) / np.linalg.norm(s2, axis=1))
        # d(r1 + r2)/dt = (s1/r1 + s2/r2) . t = 0 at a specular point; round-off ~1e-15
        assert np.max(np.abs(derivative[valid])) < 1e-10


def test_go_factors_match_the_reference():
    rng = np.random.default_rng(4)
    n = 5000
    a, b, x, normal, e1, e2 = (rng.normal(size=(n, 3)) for _ in range(6))
    k11, k22, k12 = (rng.normal(size=n) for _ in range(3))
    surface = SurfacePoints(x, normal, np.ones(n, dtype=bool), e1, e2, k11, k22, k12)
    amplitude, phase = reference_curved.go_amplitude(a, b, x, normal, e1, e2, k11, k22, k12)
    rows = rng.permutation(n)[:2000]
    got_amplitude, got_phase = curved_kernels.go_factors(rows, a, b, surface)
    # the same terms in the same order but for numpy's 3-term dot products (einsum's order),
    # a few ulps each, which |det H| amplifies where it nearly cancels: 1e-9 relative on the
    # rows whose det is not within 1e-6 of cancelling
    d1, d2 = x - a, x - b
    s1 = d1 / np.linalg.norm(d1, axis=1, keepdims=True)
    # |det H| (from the reference amplitude) against the size of H's terms (c <= 2)
    scale = 2.0 * (2.0 * (np.abs(k11) + np.abs(k22) + np.abs(k12)) + 1.0 / np.linalg.norm(d1, axis=1)
                   + 1.0 / np.linalg.norm(d2, axis=1)) ** 2
    det = (amplitude / np.abs(np.einsum("ij,ij->i", s1, normal)) * np.linalg.norm(d1, axis=1)
           * np.linalg.norm(d2, axis=1)) ** -2.0
    well = (det > 1e-6 * scale)[rows]
    assert well.mean() > 0.9
    np.testing.assert_allclose(got_amplitude[well], amplitude[rows][well], rtol=1e-9, atol=0.0)
    np.testing.assert_array_equal(got_phase[well], phase[rows][well])
    assert {0.0, np.pi / 2, np.pi} <= set(got_phase.tolist())  # minima, saddles and maxima


def test_unfold_reversed_equals_the_reference_unfold(thesis_tank: PreparedScene):
    mirrors = thesis_tank.mirrors
    receivers = np.random.default_rng(1).uniform((0.5, 0.5, 0.2), (8.5, 2.5, 0.8), (3, 3))
    for length in (0, 1, 2, 3):
        seqs = mirrors.sequences(length)
        rows = np.repeat(np.arange(seqs.shape[0]), 3)
        expected = unfold(mirrors, receivers[np.tile(np.arange(3), seqs.shape[0])], seqs[rows][:, ::-1])
        got = unfold_reversed(mirror_arrays(mirrors), receivers, seqs)
        # the same operations in the same order but numpy's 3-term sums (einsum): a few ulps
        np.testing.assert_allclose(got[0], expected[0], rtol=0, atol=1e-13)
        np.testing.assert_array_equal(got[1], expected[1])


def test_backtrace_equals_the_reference_backtrace(thesis_tank: PreparedScene):
    mirrors = thesis_tank.mirrors
    rng = np.random.default_rng(7)
    transmitter = np.array([1.2, 1.4, 0.45])
    for length in (1, 2, 3):
        seqs = mirrors.sequences(length)
        images, _ = unfold(mirrors, transmitter, seqs)
        ends = rng.uniform((0.2, 0.2, 0.1), (8.8, 2.8, 0.9), (seqs.shape[0], 3))
        expected_points, expected_valid = backtrace(mirrors, images, seqs, ends)
        points, valid = backtrace_chains(mirror_arrays(mirrors), images, seqs, ends)
        np.testing.assert_array_equal(valid, expected_valid)
        assert 0 < valid.sum() < valid.size
        np.testing.assert_allclose(points[valid], expected_points[valid], rtol=0, atol=1e-12)


def test_unblocked_chains_equal_one_occlusion_query_over_every_leg(thesis_tank: PreparedScene):
    """The fast OCCLUDED pre-pass then exclusion passes on its hits give the reference rule: one
    ``RayCaster.occluded`` over every leg, the patches at its ends excluded."""
    total = 0
    for context in _poses(thesis_tank, 4, seed=6):
        chains, _ = planar_and_mixed(_pose(thesis_tank, context), thesis_tank, 3)
        n, big = chains.surface.shape
        legs = np.arange(big + 1) <= chains.order[:, None]
        none = np.full((n, 1), -1, dtype=np.int64)
        exclude = np.stack([np.concatenate([none, chains.patch], axis=1), np.concatenate([chains.patch, none], axis=1)],
                           axis=2)
        blocked = np.zeros((n, big + 1), dtype=bool)
        blocked[legs] = thesis_tank.raycaster.occluded(chains.vertices[:, :-1][legs], chains.vertices[:, 1:][legs],
                                                       exclude_patches=exclude[legs])
        got = unblocked(chains, thesis_tank)
        np.testing.assert_array_equal(got, np.flatnonzero(~blocked.any(axis=1)))
        assert 0 < got.size < n  # some chains blocked, some not
        total += n
    assert total > 2000


def test_duplicate_keys_equal_the_reference_key(thesis_tank: PreparedScene):
    for context in _poses(thesis_tank, 3, seed=9):
        chains, _ = planar_and_mixed(_pose(thesis_tank, context), thesis_tank, 3)
        rows = np.arange(0, chains.length.size, 2)
        written = empty_paths_array(rows.size)
        write_rows(rows, 0, int(PathKind.SPECULAR), chains, path_columns(written))
        np.testing.assert_array_equal(duplicate_keys(rows, chains, MAX_INTERACTIONS, 1e-9), duplicate_key(written))


def test_first_distinct_rows_equals_numpy_unique_even_on_hash_collisions():
    rng = np.random.default_rng(8)
    for n, columns, spread in ((1, 3, 2), (2, 3, 1), (500, 6, 3), (5000, 18, 2), (20000, 4, 3)):
        key = rng.integers(-spread, spread, (n, columns))
        expected = np.sort(np.unique(key, axis=0, return_index=True)[1])
        np.testing.assert_array_equal(first_distinct_rows(key), expected)
    # two different rows with the same wrapping hash: the second column offsets the first's
    # change (m0 + d1 m1 = 0 mod 2^64 with d1 = -m0 / m1, m1 odd hence invertible)
    m0, m1 = (np.arange(1, 5, 2, dtype=np.uint64) * np.uint64(0x9E3779B97F4A7C15)).tolist()
    d1 = (-m0 * pow(m1, -1, 2 ** 64)) % 2 ** 64
    a = np.array([[5, 7]], dtype=np.int64)
    b = a.view(np.uint64) + np.array([[1, d1]], dtype=np.uint64)
    collide = np.concatenate([a, b.view(np.int64), a])
    hashes = (collide.view(np.uint64) * np.array([m0, m1], dtype=np.uint64)).sum(axis=1, dtype=np.uint64)
    assert hashes[0] == hashes[1]
    np.testing.assert_array_equal(first_distinct_rows(collide), [0, 1])


def test_engines_agree_on_a_smooth_mesh_with_primitives_and_a_prism():
    """Every chain kind (planar, mixed with primitives, mixed with a smooth mesh), random poses."""
    import trimesh

    from acoustisim.materials import get_material
    from acoustisim.medium import Medium
    from acoustisim.scene import Scene, SceneObject, Tank
    from acoustisim.sonar import SonarHead
    from scenes.builders import cylinder, edge_prism, sphere

    mesh = trimesh.creation.icosphere(subdivisions=3, radius=0.08)
    mesh.apply_translation((5.0, 1.2, 0.5))
    objects = (SceneObject("blob", "mesh", get_material("rigid"), mesh), sphere("ball", (3.0, 2.0, 0.4), 0.1, "steel"),
               cylinder("pipe", (6.5, 1.0, 0.5), (0.0, 1.0, 0.0), 0.05, 0.6, "pvc"),
               edge_prism("prism", (2.0, 1.0), 60.0, 180.0, 0.1, 1.0, "steel"))
    prepared = prepare(Scene("mix", Medium(), SonarHead(), Tank(9.0, 3.0, 1.0), objects))
    assert prepared.smooth and prepared.curved
    config = SolverConfig(max_order=2, mechanisms=("direct", "specular"), amplitude_floor_db=None)
    smooth_rows = 0
    for i, context in enumerate(_poses(prepared, 4, seed=5)):
        fast = solve(prepared, context.sonar, config).rows
        reference = solve(prepared, context.sonar, replace(config, backend="reference")).rows
        assert_rows_match(fast, reference, label=f"mix/pose {i}")
        smooth_rows += int(np.sum(np.any(fast["object_ids"] == prepared.scene.surface_names.index("blob"), axis=1)))
    assert smooth_rows > 10
