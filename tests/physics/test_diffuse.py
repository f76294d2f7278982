"""Diffuse reverberation: Lambert energy against quadrature, Monte Carlo noise, determinism."""

from __future__ import annotations

import numpy as np
import pytest

from acoustisim.materials import Material
from acoustisim.propagation.fast.columns import complete_columns
from acoustisim.propagation.config import SolverConfig
from acoustisim.propagation.context import SolveContext
from acoustisim.propagation.diffuse import ObjectScreen, diffuse_paths, sample_directions, speckle, trace_diffuse
from acoustisim.propagation.paths import PathKind
from acoustisim.propagation.raycast import RayCaster
from acoustisim.scene import Scene
from scenes.builders import plate
from scenes.builtin import builtin_scene

MU = 0.02
ROUGH = Material("rough", 2000.0, 3000.0, diffuse_mu=MU)
PLATE_X = 1.0  # front face of the plate (m); the sonar is at the origin looking along +x
HALF = 2.0  # the plate's front face spans |y|, |z| <= 2 m


def plate_context():
    base = builtin_scene("free-plane")
    slab = plate("rough", (PLATE_X + 0.005, 0.0, 0.0), (-1.0, 0.0, 0.0), 2 * HALF, 2 * HALF, 0.01, ROUGH)
    scene = Scene(name="rough-plate", medium=base.medium, sonar=base.sonar, tank=None, objects=(slab,))
    return SolveContext.build(scene, scene.sonar, RayCaster.from_scene(scene))


def lambert_energy(tx, rx, n=400):
    """Int_plate mu sin(g_i) sin(g_s) / (r1^2 r2^2) dA by Gauss-Legendre (smooth integrand:
    400 x 400 nodes converge to 1e-10)."""
    x, w = np.polynomial.legendre.leggauss(n)
    y, z = np.meshgrid(HALF * x, HALF * x, indexing="ij")
    wy = HALF * w
    p = np.stack([np.full_like(y, PLATE_X), y, z], axis=-1)
    d1 = p - tx
    d2 = p - rx
    r1 = np.linalg.norm(d1, axis=-1)
    r2 = np.linalg.norm(d2, axis=-1)
    sin_i = np.abs(d1[..., 0]) / r1
    sin_s = np.abs(d2[..., 0]) / r2
    return float(np.einsum("i,j,ij->", wy, wy, MU * sin_i * sin_s / (r1**2 * r2**2)))


def front_face_energy(context, rays, seed):
    events = trace_diffuse(context, SolverConfig(diffuse_rays=rays, seed=seed))
    on_front = np.abs(events.points_m[events.event, 0] - PLATE_X) < 1e-6
    energy = np.zeros(3)
    np.add.at(energy, events.channel[on_front], events.gain[on_front] ** 2)
    return energy


def test_sampling_weights_cover_the_sphere():
    context = plate_context()
    rng = np.random.default_rng(1)
    directions, solid_angle = sample_directions(200_000, context.boresight, context, rng)
    np.testing.assert_allclose(np.linalg.norm(directions, axis=1), 1.0, atol=1e-12)
    # dOmega = 1 / (N pdf) integrates 1 over the sphere: 4 pi, to the Monte Carlo error of an
    # estimator whose relative spread is below 2 (pdf >= a / 4 pi): 3 sigma < 1.5 %
    assert solid_angle.sum() == pytest.approx(4 * np.pi, rel=0.015)
    # every hemisphere is sampled (side lobes and back)
    assert np.mean(directions @ context.boresight < 0) > 0.2


def test_lambert_energy_of_a_large_plate_matches_quadrature():
    context = plate_context()
    tx, rx = context.transmitter_m, context.receivers_m
    expected = np.array([lambert_energy(tx, r) for r in rx])
    estimates = np.array([front_face_energy(context, 100_000, seed) for seed in range(2)])
    mean = estimates.mean(axis=0)
    # the measured relative spread of one 100k-ray estimate is 0.9 % (ten seeds; speckle
    # |X|^2 ~ Exp(1) doubles the variance), so the mean of two has ~0.65 % and the 5 %
    # is over 7 sigma; a bias (a wrong footprint, pdf or weight) shows at any ray count
    np.testing.assert_allclose(mean, expected, rtol=0.05)


def test_monte_carlo_noise_falls_as_one_over_sqrt_rays():
    context = plate_context()
    tx, rx = context.transmitter_m, context.receivers_m[1]
    expected = lambert_energy(tx, rx)
    counts = np.array([1_000, 4_000, 16_000])
    seeds = (96, 48, 24)
    rms = []
    for n, k in zip(counts, seeds):
        errors = [front_face_energy(context, int(n), 1000 + seed)[1] / expected - 1 for seed in range(k)]
        rms.append(np.sqrt(np.mean(np.square(errors))))
    slope = np.polyfit(np.log(counts), np.log(rms), 1)[0]
    # unbiased estimator of iid rays: RMS error ~ N^-1/2. With half these seeds, six repeats
    # gave slopes -0.53 +/- 0.11 (the RMS of a few dozen heavy-tailed errors is itself noisy);
    # with these seeds sigma ~0.075, so +/- 0.2 is ~2.7 sigma, and a non-converging
    # estimator (slope 0) or correlated rays (slope > -0.3) fails
    assert slope == pytest.approx(-0.5, abs=0.2)
    assert rms[-1] < 0.05


def test_rows_are_deterministic_for_a_seed_and_change_with_it():
    scene = builtin_scene("thesis-tank")
    context = SolveContext.build(scene, scene.sonar, RayCaster.from_scene(scene), first_path_id=7)
    a = complete_columns(diffuse_paths(context, SolverConfig(diffuse_rays=3000, diffuse_bounces=2, seed=5)), context)
    b = complete_columns(diffuse_paths(context, SolverConfig(diffuse_rays=3000, diffuse_bounces=2, seed=5)), context)
    c = complete_columns(diffuse_paths(context, SolverConfig(diffuse_rays=3000, diffuse_bounces=2, seed=6)), context)
    assert a.tobytes() == b.tobytes()
    assert a.tobytes() != c.tobytes()
    assert np.all(a["kind"] == PathKind.DIFFUSE)
    assert set(np.unique(a["order"])) == {1, 2}
    assert a["path_id"].min() == 7
    for column in ("delay_s", "geometric_gain", "amplitude", "phase_rad"):
        assert np.all(np.isfinite(a[column]))
    # second-order rows name two surfaces and have two points
    second = a[a["order"] == 2]
    assert np.all(second["object_ids"][:, :2] >= 0) and np.all(np.isfinite(second["points_m"][:, :2]))
    # path length = legs through the chain
    p = second["points_m"]
    legs = (
        np.linalg.norm(p[:, 0] - context.transmitter_m, axis=1)
        + np.linalg.norm(p[:, 1] - p[:, 0], axis=1)
        + np.linalg.norm(context.receivers_m[second["channel"]] - p[:, 1], axis=1)
    )
    np.testing.assert_allclose(second["path_length_m"], legs, atol=1e-4)  # the 2e-5 m start offset
    assert diffuse_paths(context, SolverConfig(diffuse_rays=0)).size == 0


def test_speckle_is_frozen_to_the_world_position():
    rng = np.random.default_rng(0)
    points = rng.uniform(-5, 5, (20_000, 3))
    x = speckle(points, 3)
    # same cube -> same value; independent of call order or batch
    np.testing.assert_array_equal(speckle(points[::-1], 3), x[::-1])
    np.testing.assert_array_equal(speckle(points + 1e-5 * (0.5 - (points % 1e-3 > 0.5e-3)), 3), x)
    assert not np.allclose(speckle(points, 4), x)
    # circular complex Gaussian with E|X|^2 = 1 (20k samples: 3 sigma ~2 %)
    assert np.mean(np.abs(x) ** 2) == pytest.approx(1.0, rel=0.03)
    assert abs(np.mean(x)) < 0.03
    # every receiver sees one event with the same speckle phase
    scene = builtin_scene("thesis-tank")
    context = SolveContext.build(scene, scene.sonar, RayCaster.from_scene(scene))
    rows = diffuse_paths(context, SolverConfig(diffuse_rays=2000))
    for pid in np.unique(rows["path_id"])[:50]:
        assert np.unique(rows[rows["path_id"] == pid]["phase_rad"]).size == 1


def test_no_scatterers_no_rows():
    """Free field with a rigid sphere (mu = 0) and rays that mostly escape: nothing scatters."""
    scene = builtin_scene("free-sphere")
    context = SolveContext.build(scene, scene.sonar, RayCaster.from_scene(scene))
    assert scene.objects[0].material.diffuse_mu == 0.0
    rows = diffuse_paths(context, SolverConfig(diffuse_rays=500, diffuse_bounces=2))
    assert rows.size == 0 and rows.dtype == diffuse_paths(context, SolverConfig(diffuse_rays=0)).dtype


def test_bounce_energies_inside_a_lambert_sphere():
    """Source and receiver at the centre of a Lambertian spherical shell of radius R.

    The first bounce carries Int mu / R^4 dA = 4 pi mu / R^2. Inside a sphere the kernel
    cos(t1) cos(t2) / r12^2 between two wall points is 1 / (4 R^2) (cos t = r12 / 2R), so each
    further bounce multiplies the energy by mu 4 pi R^2 / (4 R^2) = pi mu: E_k = 4 pi^k mu^k / R^2.
    """
    import trimesh
    from dataclasses import replace

    from acoustisim.scene import SceneObject

    radius, mu = 0.5, 0.2
    shell = trimesh.creation.icosphere(subdivisions=4, radius=radius)
    shell = trimesh.Trimesh(shell.vertices, shell.faces[:, ::-1], process=False)  # normals inward
    base = builtin_scene("free-sphere")
    obj = SceneObject("shell", "mesh", Material("white", 2000.0, 3000.0, diffuse_mu=mu), shell)
    scene = Scene(name="shell", medium=base.medium, sonar=base.sonar, tank=None, objects=(obj,))
    context = SolveContext.build(scene, scene.sonar, RayCaster.from_scene(scene))
    centre = np.zeros(3)
    context = replace(context, transmitter_m=centre, receivers_m=np.array([centre]))
    events = trace_diffuse(context, SolverConfig(diffuse_rays=40_000, diffuse_bounces=3, seed=2))
    bounce = events.bounce[events.event]
    energy = np.array([np.sum(events.gain[bounce == k] ** 2) for k in (1, 2, 3)])
    expected = 4 * np.pi ** np.arange(1, 4) * mu ** np.arange(1, 4) / radius**2
    # 40k rays: Monte Carlo spread ~1 % per bounce (speckle and the sampling weights; the wall
    # geometry is the same for every ray); the 5120-facet shell lies up to 0.2 % inside the
    # sphere (R^-2: 0.4 %); 5 % leaves margin while a wrong albedo factor (pi mu = 0.63) or a
    # missing cosine fails by tens of percent
    np.testing.assert_allclose(energy, expected, rtol=0.05)
    # every path is tx -> wall -> ... -> centre: (k + 1) R to within the facets' sag
    lengths = events.path_length_m
    assert np.all(np.abs(lengths[bounce == 1] - 2 * radius) < 0.01)


def test_absurd_ray_count_is_refused_not_allocated():
    from acoustisim.errors import InputError

    scene = builtin_scene("thesis-tank")
    context = SolveContext.build(scene, scene.sonar, RayCaster.from_scene(scene))
    with pytest.raises(InputError, match="solver.diffuse_rays = 2000000000"):
        diffuse_paths(context, SolverConfig(diffuse_rays=2_000_000_000))


def test_object_screen_skips_only_legs_embree_finds_clear():
    # The screen lets Embree skip the legs that miss every object's box: exact only if each
    # skipped leg is one Embree reports clear. On the thesis tank (prism, posts, pipe) both
    # outcomes occur (else this checks nothing), and every skipped leg to every receiver is
    # clear by Embree; a leg ending on an object is never skipped (its end is in the box).
    scene = builtin_scene("thesis-tank")
    context = SolveContext.build(scene, scene.sonar, RayCaster.from_scene(scene))
    events = trace_diffuse(context, SolverConfig(diffuse_rays=20_000, diffuse_bounces=2, seed=3))
    screen = ObjectScreen.create(scene, context.receivers_m)
    near = screen.near(events.points_m)
    assert 0.05 < near.mean() < 0.95
    skipped = events.points_m[~near]
    for receiver in context.receivers_m:
        blocked = context.raycaster.occluded(skipped, np.broadcast_to(receiver, skipped.shape))
        assert not blocked.any()
    on_object = events.surface >= len(scene.boundaries)
    assert on_object.any() and near[on_object].all()
    # a first hit's leg back to a receiver at the transmitter (the centre transducer) is not
    # tested: it is the ray itself, clear by Embree too
    assert np.array_equal(context.receivers_m[1], context.transmitter_m)
    first = events.points_m[events.bounce == 1]
    assert not context.raycaster.occluded(first, np.broadcast_to(context.transmitter_m, first.shape)).any()
    # legs the screen keeps include blocked ones (second-bounce points in the shadows of the
    # prism and posts: first hits are all seen from the transmitter, the centre receiver)
    kept = events.points_m[near]
    assert context.raycaster.occluded(kept, np.broadcast_to(context.receivers_m[1], kept.shape)).any()


def test_an_empty_free_field_gives_no_diffuse_rows():
    """Nothing to scatter from: the tracer returns no rows (it used to index an empty table)."""
    from acoustisim.propagation import SolverConfig, solve
    from acoustisim.propagation.paths import PathKind
    from acoustisim.scene import Scene

    paths = solve(Scene(tank=None, objects=()), config=SolverConfig())
    kinds = set(int(k) for k in paths.rows["kind"])
    assert PathKind.DIFFUSE not in kinds
    assert kinds == {int(PathKind.DIRECT)}  # the two side receivers hear the transmitter
