"""Echo factors of curved and planar reflectors against closed forms and a Kirchhoff integral."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
import trimesh

from acoustisim.geometry import CylinderPrimitive, SpherePrimitive
from acoustisim.materials import get_material
from acoustisim.medium import Medium
from acoustisim.propagation import PathKind, SolverConfig, prepare, solve
from acoustisim.propagation.reference.curved import circle_specular_point
from acoustisim.scene import Scene, SceneObject, Tank
from acoustisim.sonar import SonarHead
from scenes.builders import cylinder, plate, sphere

CONFIG = SolverConfig(max_order=3, mechanisms=("direct", "specular"), amplitude_floor_db=None)
FREQUENCY = 500e3


def _free_scene(obj: SceneObject, sonar: SonarHead) -> Scene:
    return Scene("free", Medium(), sonar, None, (obj,))


def _sonar(left_head=(-0.065, 0.0, 0.0)) -> SonarHead:
    """Sonar at the origin looking along +x; head (x, y, z) maps to tank (y, -x, z)."""
    return SonarHead(position_m=(0.0, 0.0, 0.0), channel_positions_m=(left_head, (0.0, 0.0, 0.0), (0.065, 0.0, 0.0)))


def _echo(paths, channel: int, name: str) -> np.void:
    labels = paths.object_labels()
    idx = [i for i, lab in enumerate(labels) if lab == name and paths["channel"][i] == channel]
    assert len(idx) == 1, (name, channel, labels)
    return paths.rows[idx[0]]


@pytest.mark.parametrize("r", [0.3, 1.0, 3.0])
def test_sphere_monostatic_closed_form(r, backend):
    a = 0.05
    obj = sphere("ball", (r + a, 0.0, 0.0), a, "rigid")
    row = _echo(solve(_free_scene(obj, _sonar()), config=replace(CONFIG, backend=backend)), 1, "ball")
    # a / (2 r (r + a)) is what the bistatic Hessian formula reduces to at normal incidence:
    # only round-off separates them (the 1 % is met with a huge margin)
    assert row["geometric_gain"] == pytest.approx(a / (2 * r * (r + a)), rel=1e-9)
    assert row["delay_s"] == pytest.approx(2 * r / Medium().sound_speed, rel=1e-12)


@pytest.mark.parametrize("r", [0.5, 2.0])
def test_long_cylinder_monostatic_closed_form(r, backend):
    a = 0.04
    obj = cylinder("pipe", (r + a, 0.0, 0.0), (0.0, 0.0, 1.0), a, 40.0, "rigid")
    row = _echo(solve(_free_scene(obj, _sonar()), config=replace(CONFIG, backend=backend)), 1, "pipe")
    expected = np.sqrt(a / (a + r)) / (2 * r)
    assert row["geometric_gain"] == pytest.approx(expected, rel=1e-9)


def test_plane_image_with_angle_dependent_coefficient(backend):
    medium = Medium()
    obj = plate("wall", (1.01, 0.0, 0.0), (-1.0, 0.0, 0.0), 3.0, 3.0, 0.02, "steel")
    sonar = _sonar(left_head=(-0.3, 0.0, 0.1))
    paths = solve(_free_scene(obj, sonar), config=replace(CONFIG, backend=backend))
    for channel in (0, 1, 2):
        row = _echo(paths, channel, "wall")
        tx, rx = sonar.transmitter_position, sonar.receiver_positions[channel]
        image = tx * np.array([-1.0, 1.0, 1.0]) + np.array([2.0, 0.0, 0.0])  # mirror across x = 1
        length = np.linalg.norm(rx - image)
        cos_i = abs(rx[0] - image[0]) / length
        coefficient = get_material("steel").reflection_coefficient(cos_i, medium.density, medium.sound_speed)
        # Steel's elastic coefficient is complex (its losses): |R| / (r1 + r2) exactly (same
        # arithmetic up to round-off), and the phase -arg R (phase_rad's convention).
        assert abs(coefficient.imag) > 1e-6
        assert row["geometric_gain"] == pytest.approx(abs(coefficient) / length, rel=1e-12)
        assert row["phase_rad"] == pytest.approx(-np.angle(coefficient), rel=1e-9)
        assert row["path_length_m"] == pytest.approx(length, rel=1e-14)


def _planck_taper(x: np.ndarray, flat: float, end: float) -> np.ndarray:
    """1 for |x| <= flat, 0 for |x| >= end, C-infinity in between."""
    t = np.clip((np.abs(x) - flat) / (end - flat), 0.0, 1.0)
    inner = (t > 0) & (t < 1)
    out = np.where(t <= 0, 1.0, 0.0)
    ti = t[inner]
    out[inner] = 1.0 / (1.0 + np.exp(np.minimum(1.0 / (1.0 - ti) - 1.0 / ti, 700.0)))
    return out


def _kirchhoff(points: np.ndarray, normals: np.ndarray, weights: np.ndarray, tx: np.ndarray,
               rx: np.ndarray, k: float) -> float:
    """|p_s| of a rigid surface in the Kirchhoff approximation, source of unit pressure at 1 m.

    p_s = (i k / 2 pi) Int (n . s2) exp(i k (r1 + r2)) / (r1 r2) dS over the (windowed) lit
    surface; s2 the unit vector from the surface to the receiver.
    """
    d1 = points - tx
    d2 = rx - points
    r1 = np.linalg.norm(d1, axis=-1)
    r2 = np.linalg.norm(d2, axis=-1)
    cos2 = np.einsum("...k,...k->...", normals, d2) / r2
    integrand = cos2 * np.exp(1j * k * (r1 + r2)) / (r1 * r2) * weights
    return float(abs(1j * k / (2 * np.pi) * integrand.sum()))


def _sphere_kirchhoff(centre, a, x0, tx, rx, k):
    n0 = (x0 - centre) / a
    e1 = np.cross(n0, [0.0, 0.0, 1.0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(n0, e1)
    # Gauss-Legendre in the polar angle about the specular normal, uniform (spectral) in azimuth;
    # the window is flat to 30 deg and smoothly zero at 60 deg, inside the lit region of both ends
    nodes, w = np.polynomial.legendre.leggauss(900)
    theta = 0.5 * np.radians(60.0) * (nodes + 1.0)
    wt = 0.5 * np.radians(60.0) * w
    phi = np.linspace(0.0, 2 * np.pi, 720, endpoint=False)
    th, ph = np.meshgrid(theta, phi, indexing="ij")
    normals = (np.sin(th)[..., None] * (np.cos(ph)[..., None] * e1 + np.sin(ph)[..., None] * e2)
               + np.cos(th)[..., None] * n0)
    points = centre + a * normals
    weights = a * a * np.sin(th) * wt[:, None] * (2 * np.pi / phi.size) * _planck_taper(th, np.radians(30), np.radians(60))
    return _kirchhoff(points, normals, weights, tx, rx, k)


def test_bistatic_sphere_against_kirchhoff_integral(backend):
    a = 0.05
    centre = np.array([0.9, 0.1, 0.05])
    obj = sphere("ball", tuple(centre), a, "rigid")
    sonar = _sonar(left_head=(-0.35, 0.0, 0.15))
    scene = _free_scene(obj, sonar)
    row = _echo(solve(scene, config=replace(CONFIG, backend=backend)), 0, "ball")
    k = 2 * np.pi * FREQUENCY / scene.medium.sound_speed
    reference = _sphere_kirchhoff(centre, a, row["points_m"][0], sonar.transmitter_position,
                                  sonar.receiver_positions[0], k)
    # stationary phase (GO) and the physical-optics integral differ by O(1/(k a)) terms, ka ~ 106,
    # and by the integral's quadrature error; measured agreement 7e-5, asserted 2e-3 (issue: 1 %)
    assert row["geometric_gain"] == pytest.approx(reference, rel=2e-3)


def test_bistatic_cylinder_against_kirchhoff_integral(backend):
    a = 0.1
    centre = np.array([1.1, 0.05, 0.0])
    obj = cylinder("pipe", tuple(centre), (0.0, 0.0, 1.0), a, 1.2, "rigid")
    sonar = _sonar(left_head=(-0.3, 0.0, 0.1))
    scene = _free_scene(obj, sonar)
    row = _echo(solve(scene, config=replace(CONFIG, backend=backend)), 0, "pipe")
    x0 = row["points_m"][0]
    k = 2 * np.pi * FREQUENCY / scene.medium.sound_speed
    psi0 = np.arctan2(x0[1] - centre[1], x0[0] - centre[0])
    # Gauss-Legendre over +/-45 deg of azimuth and +/-0.2 m of height (phase excursions ~130 and
    # ~90 rad: 400 and 500 nodes resolve them), windows flat to 20 deg and 0.07 m
    nodes, w = np.polynomial.legendre.leggauss(400)
    psi = psi0 + np.radians(45.0) * nodes
    wpsi = np.radians(45.0) * w
    zn, wz = np.polynomial.legendre.leggauss(500)
    z = x0[2] + 0.2 * zn
    wz = 0.2 * wz
    ps, zz = np.meshgrid(psi, z, indexing="ij")
    normals = np.stack([np.cos(ps), np.sin(ps), np.zeros_like(ps)], axis=-1)
    points = np.stack([centre[0] + a * np.cos(ps), centre[1] + a * np.sin(ps), zz], axis=-1)
    weights = (a * wpsi[:, None] * wz[None, :] * _planck_taper(ps - psi0, np.radians(20), np.radians(45))
               * _planck_taper(zz - x0[2], 0.07, 0.2))
    reference = _kirchhoff(points, normals, weights, sonar.transmitter_position, sonar.receiver_positions[0], k)
    # same O(1/(k a)) argument as the sphere (ka ~ 212); measured 1.3e-4, asserted 2e-3 (issue: 1 %)
    assert row["geometric_gain"] == pytest.approx(reference, rel=2e-3)
    # the vertical lift: straight in the unrolled (horizontal distance, z) plane
    tx, rx = sonar.transmitter_position, sonar.receiver_positions[0]
    h1 = np.linalg.norm((x0 - tx)[:2])
    h2 = np.linalg.norm((x0 - rx)[:2])
    assert row["path_length_m"] == pytest.approx(np.hypot(h1 + h2, rx[2] - tx[2]), rel=1e-12)


def test_circle_specular_point_against_brute_force_minimum():
    rng = np.random.default_rng(3)
    a2 = rng.uniform(-3, 3, (60, 2))
    b2 = rng.uniform(-3, 3, (60, 2))
    x, valid = circle_specular_point(a2, b2, 0.5)
    phi = np.linspace(-np.pi, np.pi, 100001)
    ring = 0.5 * np.stack([np.cos(phi), np.sin(phi)], axis=1)
    for i in np.flatnonzero(valid):
        lengths = np.linalg.norm(a2[i] - ring, axis=1) + np.linalg.norm(b2[i] - ring, axis=1)
        lit = (ring @ a2[i] > 0.25) & (ring @ b2[i] > 0.25)  # (P - X).n > 0 on the circle r = 0.5
        best = ring[lit][np.argmin(lengths[lit])]
        # grid spacing 3.1e-5 m: the brute-force minimum is within a few spacings
        assert np.linalg.norm(best - x[i]) < 1e-4
    assert valid.sum() > 15


def test_object_via_free_surface_equals_image_receiver(backend):
    """Mixed chain: sphere then free surface (order 2) = -1 x the bistatic sphere echo at the
    receiver's image above the surface (an independent free-field solve)."""
    depth = 1.0
    sonar = SonarHead(position_m=(1.0, 1.5, 0.6), channel_positions_m=((-0.2, 0.0, 0.0), (0.0, 0.0, 0.0),
                                                                         (0.065, 0.0, 0.0)))
    obj = sphere("ball", (2.0, 1.45, 0.5), 0.06, "rigid")
    tank_scene = Scene("tank", Medium(), sonar, Tank(9.0, 3.0, depth), (obj,))
    row = _echo(solve(tank_scene, config=replace(CONFIG, backend=backend)), 0, "ball>surface")
    rx = sonar.receiver_positions[0]
    image = rx * np.array([1.0, 1.0, -1.0]) + np.array([0.0, 0.0, 2 * depth])
    free_sonar = replace(sonar, channel_positions_m=(tuple(sonar.tank_to_head(image[None])[0]), (0.0, 0.0, 0.0),
                                                     (0.065, 0.0, 0.0)))
    free_row = _echo(solve(_free_scene(obj, free_sonar), config=replace(CONFIG, backend=backend)), 0, "ball")
    assert row["geometric_gain"] == pytest.approx(-free_row["geometric_gain"], rel=1e-12)
    assert row["path_length_m"] == pytest.approx(free_row["path_length_m"], rel=1e-14)


def test_curved_objects_never_use_their_facets_as_mirrors(backend):
    def ball(subdivisions: int) -> SceneObject:
        mesh = trimesh.creation.icosphere(subdivisions=subdivisions, radius=0.05)
        mesh.apply_translation((1.2, 0.03, 0.02))
        return SceneObject("ball", "sphere", get_material("rigid"), mesh, SpherePrimitive((1.2, 0.03, 0.02), 0.05))

    def pipe(sections: int) -> SceneObject:
        mesh = trimesh.creation.cylinder(radius=0.04, height=0.5, sections=sections)
        mesh.apply_translation((0.9, -0.2, 0.0))
        return SceneObject("pipe", "cylinder", get_material("rigid"), mesh,
                           CylinderPrimitive((0.9, -0.2, 0.0), (0.0, 0.0, 1.0), 0.04, 0.5))

    sonar = _sonar()
    coarse = Scene("c", Medium(), sonar, None, (ball(3), pipe(48)))
    fine = Scene("f", Medium(), sonar, None, (ball(4), pipe(96)))  # 4x / 2x the triangles
    prepared = prepare(coarse)
    # the sphere gives no mirror; the cylinder only its two flat caps, as exact discs
    surfaces = prepared.mirrors.surface.tolist()
    assert 0 not in surfaces and surfaces.count(1) == 2
    assert np.all(np.isfinite(prepared.mirrors.disc_radius))
    a = solve(prepared, config=replace(CONFIG, backend=backend))
    b = solve(fine, config=replace(CONFIG, backend=backend))
    for name in ("ball", "pipe"):
        for channel in (0, 1, 2):
            # traced on the primitive: a finer tessellation changes nothing (issue: < 0.5 %)
            assert _echo(a, channel, name)["geometric_gain"] == pytest.approx(
                _echo(b, channel, name)["geometric_gain"], rel=1e-12)


def test_kinds_and_orders_are_labelled(backend):
    obj = sphere("ball", (1.05, 0.0, 0.0), 0.05, "rigid")
    paths = solve(_free_scene(obj, _sonar()), config=replace(CONFIG, backend=backend))
    assert set(paths["kind"].tolist()) == {PathKind.DIRECT, PathKind.SPECULAR}
    assert np.all(paths["order"][paths["kind"] == PathKind.SPECULAR] == 1)


def test_wall_object_wall_equals_free_field_between_images(backend):
    """Order-3 mixed chain [wall, sphere, wall] in a rigid-walled tank = the free-field bistatic sphere
    echo between the transmitter's and the receiver's images across that wall (R = 1)."""
    sonar = SonarHead(position_m=(1.0, 0.6, 0.5), yaw_deg=10.0,
                      channel_positions_m=((-0.2, 0.0, 0.05), (0.0, 0.0, 0.0), (0.065, 0.0, 0.0)))
    obj = sphere("ball", (2.2, 0.9, 0.45), 0.07, "rigid")
    tank = Tank(9.0, 3.0, 1.0, wall_material="rigid", floor_material="rigid", surface_material="rigid")
    paths = solve(Scene("tank", Medium(), sonar, tank, (obj,)), config=replace(CONFIG, backend=backend))
    row = _echo(paths, 0, "wall-y0>ball>wall-y0")
    mirror = np.array([1.0, -1.0, 1.0])  # across the wall y = 0
    tx_image = sonar.transmitter_position * mirror
    rx_image = sonar.receiver_positions[0] * mirror
    free = replace(sonar, position_m=tuple(tx_image), yaw_deg=0.0, pitch_deg=0.0, roll_deg=0.0)
    free = replace(free, channel_positions_m=(tuple(free.tank_to_head(rx_image[None])[0]), (0.0, 0.0, 0.0),
                                              (0.065, 0.0, 0.0)))
    free_row = _echo(solve(_free_scene(obj, free), config=replace(CONFIG, backend=backend)), 0, "ball")
    # plane mirrors keep the wavefront curvature: identical to round-off
    assert row["geometric_gain"] == pytest.approx(free_row["geometric_gain"], rel=1e-12)
    assert row["path_length_m"] == pytest.approx(free_row["path_length_m"], rel=1e-14)
