"""Energy conservation of rough reflections: what the coherent reflection loses, the diffuse
tracer scatters (``reference.diffuse`` (3), both engines).

A point source 0.5 m above a 4 m x 4 m rough plate (concrete, h = 0.5 mm, no Lambert mu of its
own, so that every diffuse row comes from the roughness). The coherent reflection keeps
|R|^2 chi^2 of the power incident on each patch (chi = exp(-2 (k0 h sin g)^2), what the
specular rows apply); energy is conserved when the diffuse rows carry the rest,
|R|^2 (1 - chi^2): coherent + diffuse = the smooth plate's |R|^2.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from acoustisim.materials import get_material
from acoustisim.medium import Medium
from acoustisim.propagation import SolverConfig, prepare
from acoustisim.propagation.context import SolveContext
from acoustisim.propagation.engine import engine_for
from acoustisim.propagation.reference.diffuse import ray_counts, speckle_polar
from acoustisim.scattering.roughness import coherent_factor
from acoustisim.scene import Scene
from scenes.builders import default_sonar, plate

HEIGHT_M = 0.5  # source above the plate's top face
HALF_WIDTH_M = 2.0
RMS_M = 0.5e-3
HEMISPHERE_M = 10.0  # receivers' distance from the top face's centre (plate half-diagonal / 3.5)


def plate_scene(material) -> Scene:
    """Free field: the sonar at the origin looking straight up (its lobe away from the plate, so
    that only the uniformly drawn rays, of equal solid angle 4 pi / N_u, reach the plate) and a
    plate whose top face is the plane z = -HEIGHT_M."""
    slab = plate("floor", (0.0, 0.0, -HEIGHT_M - 0.025), (0.0, 0.0, 1.0), 2 * HALF_WIDTH_M, 2 * HALF_WIDTH_M, 0.05,
                 material, up=(0.0, 1.0, 0.0))
    sonar = replace(default_sonar(), position_m=(0.0, 0.0, 0.0), pitch_deg=90.0)
    return Scene(name="rough-plate", medium=Medium(water="fresh", temperature_c=20.0), sonar=sonar, tank=None,
                 objects=(slab,))


def rough_concrete():
    return replace(get_material("concrete"), name="concrete-rough", roughness_rms_m=RMS_M, diffuse_mu=0.0)


def hemisphere(n_polar: int = 6, n_azimuth: int = 12):
    """Receivers (n, 3) on the upper hemisphere of radius HEMISPHERE_M about the top face's centre,
    their outward normals (n, 3) and area weights (n,) (m^2): Gauss-Legendre in cos(polar angle),
    uniform in azimuth. For a Lambert point scatterer up to 0.35 radii off the centre this rule
    integrates the flux (sin g_s / r^2)(u . n) dA to pi within 6e-6 (checked below)."""
    x, w = np.polynomial.legendre.leggauss(n_polar)
    cos_polar, polar_weight = 0.5 * (x + 1.0), 0.5 * w
    azimuth = (np.arange(n_azimuth) + 0.5) * (2 * np.pi / n_azimuth)
    c, a = np.meshgrid(cos_polar, azimuth, indexing="ij")
    s = np.sqrt(1.0 - c * c)
    normal = np.stack([s * np.cos(a), s * np.sin(a), c], axis=-1).reshape(-1, 3)
    area = np.outer(polar_weight, np.full(n_azimuth, 2 * np.pi / n_azimuth)).ravel() * HEMISPHERE_M**2
    return np.array([0.0, 0.0, -HEIGHT_M]) + HEMISPHERE_M * normal, normal, area


def reflected_energy(material, sin_g, medium: Medium):
    return np.abs(material.reflection_coefficient(sin_g, medium.density, medium.sound_speed)) ** 2


def coherent_loss_over_the_plate(material, medium: Medium, k0: float) -> float:
    """The power the coherent reflection loses over the top face, per unit source power per
    steradian: the integral of |R|^2 (1 - chi^2) dOmega, dOmega = sin g dA / r^2 = H dA / r^3,
    by Gauss-Legendre on 16 x 16 panels of 24 x 24 points (the kink of |R| at the critical
    angle limits the rule: 16, 32 and 64 panels agree to 3e-5)."""
    nodes, weights = np.polynomial.legendre.leggauss(24)
    edges = np.linspace(-HALF_WIDTH_M, HALF_WIDTH_M, 17)
    half = 0.5 * np.diff(edges)
    x = ((edges[:-1] + half)[:, None] + half[:, None] * nodes).ravel()
    wx = (half[:, None] * weights).ravel()
    gx, gy = np.meshgrid(x, x, indexing="ij")
    r = np.sqrt(gx**2 + gy**2 + HEIGHT_M**2)
    sin_g = HEIGHT_M / r
    chi = coherent_factor([k0], RMS_M, sin_g.ravel())[:, 0].reshape(sin_g.shape)
    lost = reflected_energy(material, sin_g.ravel(), medium).reshape(sin_g.shape) * (1.0 - chi**2)
    return float(np.sum(lost * sin_g / r**2 * np.outer(wx, wx)))


def test_the_hemisphere_rule_integrates_a_lambert_scatterer():
    # The flux of a Lambert point scatterer (intensity sin g_s / r^2) through the hemisphere is pi
    # wherever the scatterer lies on the top face (it radiates into the half space above it).
    points, normal, area = hemisphere()
    for corner in ([0.0, 0.0], [HALF_WIDTH_M, HALF_WIDTH_M], [HALF_WIDTH_M, -0.3]):
        source = np.array([*corner, -HEIGHT_M])
        leg = points - source
        r = np.linalg.norm(leg, axis=1)
        u = leg / r[:, None]
        flux = np.sum(u[:, 2] / r**2 * np.einsum("ij,ij->i", u, normal) * area)
        assert flux == pytest.approx(np.pi, rel=6e-6)


def test_diffuse_rows_carry_the_coherent_loss_of_a_rough_plate(backend):
    # The diffuse power through the hemisphere, from the rows: per row the mean-square pressure
    # g^2 (speckle |X|^2 divided out: it is an unbiased factor of mean 1 that would only add
    # noise) times the flux factor (u . n) dA. Against the coherent loss integrated over the
    # plate. Every event comes from a uniform ray (solid angle 4 pi / N_u), so the estimate is
    # a sum of N_u independent terms: its standard error is measured from them (1.4 % here;
    # over 12 seeds the errors in standard errors had mean 0.16 and spread 0.76, as for an
    # unbiased estimate); allowed: 4 standard errors (the quadratures add < 1e-4).
    material = rough_concrete()
    scene = plate_scene(material)
    prepared = prepare(scene)
    context = SolveContext.build(scene, scene.sonar, prepared.raycaster)
    receivers, normal, area = hemisphere()
    context = replace(context, receivers_m=receivers)
    n_rays = 20000
    config = SolverConfig(diffuse_rays=n_rays, diffuse_bounces=1, seed=7, backend=backend)
    rows = engine_for(config).diffuse_rows(context, config, prepared)
    top = np.abs(rows["points_m"][:, 0, 2] + HEIGHT_M) < 1e-9  # not the plate's sides
    magnitude, _ = speckle_polar(rows["points_m"][top, 0], config.seed)
    flux = (rows["geometric_gain"][top] / magnitude) ** 2 * np.einsum(
        "ij,ij->i", rows["arrival_dir"][top], normal[rows["channel"][top]]) * area[rows["channel"][top]]
    _, per_event = np.unique(rows["path_id"][top], return_inverse=True)
    event_power = np.bincount(per_event, weights=flux)
    n_uniform = ray_counts(n_rays)[0]
    assert np.all(rows["departure_dir"][:, 2] < 0.0)  # down: no lobe ray (theta < 90 deg of up) among them
    total = event_power.sum()
    standard_error = np.sqrt(n_uniform / (n_uniform - 1.0) * (np.sum(event_power**2) - total**2 / n_uniform))
    k0 = 2 * np.pi * context.centre_frequency_hz / context.sound_speed_m_s
    expected = coherent_loss_over_the_plate(material, scene.medium, k0)
    assert standard_error < 0.02 * expected
    assert abs(total - expected) <= 4.0 * standard_error, (total, expected, standard_error)


def test_each_event_scatters_what_its_coherent_reflection_loses(backend):
    # Event by event, without Monte Carlo error: the rough plate's rows against those of a
    # smooth plate with mu = 1/pi (which scatters all the power incident on it) from the same
    # rays. Their squared gain ratio is pi mu_rough = the fraction of the incident power the
    # rough surface scatters at that event's grazing angle; adding the coherent reflection's
    # |R|^2 chi^2 gives the smooth plate's |R|^2 to rounding (1e-12).
    rough = rough_concrete()
    lambert = replace(get_material("concrete"), name="white", diffuse_mu=1.0 / np.pi)
    config = SolverConfig(diffuse_rays=3000, diffuse_bounces=1, seed=2, backend=backend)
    rows = {}
    for label, material in (("rough", rough), ("lambert", lambert)):
        scene = plate_scene(material)
        prepared = prepare(scene)
        context = SolveContext.build(scene, scene.sonar, prepared.raycaster)
        rows[label] = engine_for(config).diffuse_rows(context, config, prepared)
    a, b = rows["rough"], rows["lambert"]
    assert a.size == b.size > 1000
    assert np.array_equal(a["path_id"], b["path_id"]) and np.array_equal(a["channel"], b["channel"])
    scattered = (a["geometric_gain"] / b["geometric_gain"]) ** 2
    top = np.abs(a["points_m"][:, 0, 2] + HEIGHT_M) < 1e-9
    sin_g = -a["departure_dir"][top, 2]  # first hits: the incoming direction is the departure
    medium = plate_scene(rough).medium
    k0 = 2 * np.pi * 500e3 / medium.sound_speed
    r2 = reflected_energy(rough, sin_g, medium)
    chi = coherent_factor([k0], RMS_M, sin_g)[:, 0]
    np.testing.assert_allclose(scattered[top] + r2 * chi**2, r2, rtol=1e-12)
    assert np.ptp(scattered[top]) > 0.3  # grazing to near normal incidence: a real range of losses
