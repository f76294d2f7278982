"""Diffraction into the shadows of smooth obstacles (acoustisim.propagation.shadows), against
independent references: the exact-distance Kirchhoff integral of a post, the exact modal series
of rigid, soft and elastic cylinders, the exact half-plane, brute-force aperture integrals; then
in scenes on both engines: the level across the shadow boundary and the thesis tank's post-3
behind post-1 (issue 17)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.special import hankel1

from acoustisim.medium import Medium
from acoustisim.propagation.apex_response import ApexResponse
from acoustisim.propagation import SolverConfig, prepare, solve
from acoustisim.propagation.paths import PathKind
from acoustisim.propagation.shadows import ApertureTerms, Legs, aperture_terms, blocked_integral, shadow_factor
from acoustisim.scene import Scene, Tank
from scenes.builders import default_sonar, post
from support.diffraction_references import kirchhoff_post_shadow, wedge_point_source
from support.response_spans import worst_outside_span_db

C = 1482.38


def tank_with(*objects, depth: float = 1.0) -> Scene:
    """The thesis tank's water and walls with only ``objects`` in it."""
    return Scene(name="shadow-test", medium=Medium(water="fresh", temperature_c=20.0, salinity_ppt=0.0, depth_m=0.5),
                 sonar=default_sonar(), tank=Tank(length_m=9.0, width_m=3.0, water_depth_m=depth), objects=objects)


def leg_factor(scene: Scene, source, receiver, frequency_hz) -> np.ndarray:
    """The shadow factor H (physics convention) of the single leg source -> receiver in ``scene``."""
    obstacles = prepare(scene).smooth_obstacles
    none = np.array([-1])
    legs = Legs(np.atleast_2d(source).astype(float), np.atleast_2d(receiver).astype(float), np.array([0]), none, none)
    terms = aperture_terms(legs, obstacles, 500e3, C)
    if terms.row.size == 0:
        return np.ones(np.size(frequency_hz), dtype=complex)
    return shadow_factor(terms, np.asarray(frequency_hz, dtype=float), C)


def one_term(**values) -> ApertureTerms:
    """A one-row ApertureTerms from keyword values (missing ones 0 / False)."""
    columns = {name: np.array([values.get(name, 0)], dtype=float) for name in ApertureTerms._fields}
    columns["row"] = columns["row"].astype(np.int64)
    columns["obstacle"] = columns["obstacle"].astype(np.int64)
    columns["infinite"] = np.array([bool(values.get("infinite", False))])
    return ApertureTerms(**columns)


@pytest.mark.parametrize("case", [
    ((1.0, 1.5, 0.5), (3.0, 1.5, 0.3), (2.0, 1.52)),  # through the post, oblique in elevation
    ((1.0, 1.5, 0.5), (3.5, 1.2, 0.9), (2.0, 1.36)),  # near the shadow boundary
    ((1.0, 1.5, 0.5), (6.5, 0.6, 0.5), (3.0, 1.2)),  # the thesis tank's post-3 behind post-1
    ((1.0, 1.5, 0.5), (3.0, 1.5, 0.5), (2.0, 1.58)),  # lit, 3 radii off the line of sight
])
def test_strip_factor_matches_the_exact_distance_kirchhoff_integral(case) -> None:
    # The Fresnel (paraxial) strip formula against the Kirchhoff integral over the post's
    # silhouette with exact distances and obliquities (tests/support, coded independently):
    # measured within 0.012 dB and 0.002 rad; tolerance 0.05 dB, 0.01 rad (the paraxial error
    # goes as (a / d)^2 ~ 1e-4 in level).
    source, receiver, centre = (np.array(v, dtype=float) for v in case)
    scene = tank_with(post("obstacle", tuple(centre), 0.025, 1.0, "pvc"))
    f = np.array([300e3, 500e3, 700e3])
    k = 2 * np.pi * f / C
    distance = np.linalg.norm(receiver - source)
    exact = kirchhoff_post_shadow(k, source, receiver, centre, 0.025) * distance * np.exp(-1j * k * distance)
    model = leg_factor(scene, source, receiver, f)
    assert np.all(np.abs(20 * np.log10(np.abs(model / exact))) < 0.05)
    assert np.all(np.abs(np.angle(model / exact)) < 0.01)


def test_kirchhoff_factor_lies_between_the_exact_rigid_and_soft_cylinders() -> None:
    # Plane wave on a 25 mm cylinder, field 1.5 m behind it, from the axis to two radii off it
    # (Fresnel numbers 0.08-0.2: the partial shadow), 300-700 kHz, against the exact 2-D modal
    # series (acoustisim.scattering): Kirchhoff's opaque screen lies between the rigid and the
    # pressure-release cylinders (measured within 0.013 dB of that interval: the classical
    # result that it averages the two boundary conditions), tolerance 0.1 dB; the elastic PVC
    # post differs from it by up to 1.17 dB (its field inside the shadow is not zero),
    # tolerance 1.5 dB: what the model neglects, stated in its Accuracy.
    from acoustisim.materials import get_material
    from acoustisim.scattering.bodies import Fluid, PressureRelease, Rigid, body_from_material
    from acoustisim.scattering.modal import modal_coefficients

    radius, distance = 0.025, 1.5
    f = np.array([300e3, 400e3, 500e3, 600e3, 700e3])
    k = 2 * np.pi * f / C
    water = Fluid(1000.0, C)
    exact = {}
    for name, body in (("rigid", Rigid()), ("soft", PressureRelease()),
                       ("pvc", body_from_material(get_material("pvc")))):
        coefficients = modal_coefficients("cylinder", body, radius, f, water)
        n = coefficients.orders
        weights = np.where(n == 0, 1.0, 2.0) * 1j**n
        levels = []
        for offset in (0.0, 0.01, 0.02, 0.03, 0.04, 0.05):
            r, phi = np.hypot(distance, offset), np.arctan2(offset, distance)
            scattered = np.sum(weights * coefficients.coefficients * hankel1(n[None, :], k[:, None] * r)
                               * np.cos(n * phi), axis=1)
            levels.append(20 * np.log10(np.abs(np.exp(1j * k * distance) + scattered)))
        exact[name] = np.array(levels)
    model = np.array([20 * np.log10(np.abs(1 - blocked_integral(
        one_term(inverse_distance=1 / distance, w_centre=-offset, radius=radius, infinite=True), f, C)[0]))
        for offset in (0.0, 0.01, 0.02, 0.03, 0.04, 0.05)])
    low, high = np.minimum(exact["rigid"], exact["soft"]), np.maximum(exact["rigid"], exact["soft"])
    assert np.all(model >= low - 0.1) and np.all(model <= high + 0.1)
    assert np.all(np.abs(model - exact["pvc"]) < 1.5)
    assert np.min(model) < -9.0  # the comparison reaches into the shadow


def test_wide_obstacle_matches_the_exact_half_plane() -> None:
    # A post of radius 0.4 m whose near rim grazes the line of sight acts as a half-plane near
    # its shadow boundary: the model's field against the exact half-plane (eigenfunction series
    # summed over axial wavenumbers, tests/support), the mean of its rigid and soft solutions
    # (Kirchhoff's screen averages them), 100 kHz, receivers from the lit side into the shadow:
    # measured within 0.08 dB; tolerance 0.5 dB (issue 17).
    k = 2 * np.pi * 100e3 / C
    edge = np.array([2.0, 2.0, 0.5])
    scene = tank_with(post("wide", (2.4, 2.0), 0.4, 1.0, "pvc"))
    source = edge + np.array([-0.03, -0.5, 0.0])

    def polar(q):
        return np.hypot(q[0], q[1]), np.arctan2(q[1], q[0]) % (2 * np.pi), q[2]

    levels = []
    for x in (-0.05, 0.0, 0.05):
        receiver = edge + np.array([x, 0.4, 0.05])
        exact = np.mean([wedge_point_source(k, *polar(source - edge), *polar(receiver - edge), 2 * np.pi, soft,
                                            kz_points=1001) for soft in (False, True)])
        distance = np.linalg.norm(receiver - source)
        model = leg_factor(scene, source, receiver, np.array([100e3]))[0] / distance
        levels.append(20 * np.log10(abs(model / exact)))
    assert np.all(np.abs(levels) < 0.5), levels


def test_finite_silhouettes_against_closed_forms_and_brute_force() -> None:
    # A disc centred on the leg: |H| = 1, H = exp(i pi v^2 / 2) exactly in the Fresnel
    # approximation (Poisson's spot); an off-axis disc (sphere) and an oblique cylinder's
    # silhouette (rectangle + caps) against a brute-force trapezoid integral of (1) over the
    # silhouette, Fresnel integrals along its chords and 20 001 trapezoid points across them
    # (measured agreement 3e-7, the trapezoid's error at the rim): tolerance 1e-6.
    f = np.array([300e3, 500e3, 900e3])
    sigma = np.sqrt(2 * f / C / 0.6)
    disc = one_term(inverse_distance=1 / 0.6, radius=0.05, cap=0.05)
    assert np.allclose(1 - blocked_integral(disc, f, C)[0], np.exp(0.5j * np.pi * (sigma * 0.05) ** 2), atol=1e-12)
    from scipy.special import fresnel

    def F(v):
        s, c = fresnel(v)
        return c + 1j * s

    for x0, w0, h, a, cap in ((0.01, 0.03, 0.0, 0.05, 0.05), (0.01, 0.02, 0.04, 0.025, 0.015)):
        model = blocked_integral(one_term(inverse_distance=1 / 0.6, x_centre=x0, w_centre=w0, half_length=h,
                                          radius=a, cap=cap), f, C)[0]
        w = np.linspace(-a, a, 20001)
        chord = h + cap * np.sqrt(np.maximum(1 - (w / a) ** 2, 0.0))
        brute = [np.trapezoid(np.exp(0.5j * np.pi * (s * (w0 + w)) ** 2) * (F(s * (x0 + chord)) - F(s * (x0 - chord)))
                              * s, w) / 2j for s in sigma]
        assert np.allclose(model, brute, atol=1e-6)


def specular_row(scene: Scene, backend: str, shadows: bool, target: str, channel: int = 1):
    """The order-1 specular rows of ``target`` on ``channel`` (amplitudes at f0), without the
    elastic echoes (whose responses would multiply the shadow's)."""
    paths = solve(scene, config=SolverConfig(mechanisms=("specular",), amplitude_floor_db=None, shadows=shadows,
                                             elastic_echoes=False, backend=backend))
    index = paths.surface_names.index(target)
    rows = paths.rows
    mask = ((rows["kind"] == PathKind.SPECULAR) & (rows["order"] == 1) & (rows["object_ids"][:, 0] == index)
            & (rows["channel"] == channel))
    return rows[mask], paths


def test_level_is_continuous_across_the_shadow_boundary(backend: str) -> None:
    # A target post 3 m ahead, a 25 mm blocker post halfway, moved across the monostatic leg
    # (the same leg out and back on the centre channel) in 0.2 mm steps straddling the geometric
    # boundary: with shadows the echo's level changes smoothly through it (the step across the
    # boundary equals the mean of its neighbours, 0.31 dB, within 0.01 dB: no jump) and falls
    # below -6 dB with the leg through the blocker's centre; without shadows the echo is whole
    # on one side and gone on the other (the hard cut).
    radius, step = 0.025, 2e-4
    clear = specular_row(tank_with(post("target", (4.0, 1.5), 0.025, 1.0, "pvc")), backend, True, "target")[0]
    levels = []
    for offset in (radius - 1.5 * step, radius - 0.5 * step, radius + 0.5 * step, radius + 1.5 * step, 0.0):
        scene = tank_with(post("target", (4.0, 1.5), 0.025, 1.0, "pvc"),
                          post("blocker", (2.5, 1.5 + offset), radius, 1.0, "pvc"))
        shadowed, _ = specular_row(scene, backend, True, "target")
        hard, _ = specular_row(scene, backend, False, "target")
        assert shadowed.size == 1
        levels.append(20 * np.log10(shadowed["amplitude"][0] / clear["amplitude"][0]))
        if offset > radius:
            assert hard.size == 1 and hard["amplitude"][0] == pytest.approx(clear["amplitude"][0], rel=1e-12)
        else:
            assert hard.size == 0
    steps = np.diff(levels[:4])
    assert abs(steps[1] - 0.5 * (steps[0] + steps[2])) < 0.01, steps
    assert steps.min() > 0.0
    assert levels[4] < -6.0


def test_thesis_tank_post_three_behind_post_one(backend: str, thesis_tank) -> None:
    # Issue 17: from the default pose the legs to post-3 graze post-1 (1.9 mm to spare on the
    # way out; the left receiver's leg back is blocked). Phase 1's independent Kirchhoff
    # estimate (tests/physics/test_elastic_diffraction_refs.py: exact-distance integral, both
    # legs, reflection point facing the midpoint of transmitter and receiver) gives -18.0 / -8.1
    # / -15.6 dB (centre / right / left) re unobstructed at 500 kHz; the issue rounds to
    # -18 / -9 / -16. The simulator now keeps the echo on every channel at the shadowed level:
    # within 0.3 dB of the estimate (its reflection point is approximate; the row's is the
    # exact specular point), 1.5 dB of the issue's rounding.
    for channel, estimate, issue in ((1, -18.0, -18.0), (2, -8.1, -9.0), (0, -15.6, -16.0)):
        rows, paths = specular_row(thesis_tank, backend, True, "post-3", channel)
        assert rows.size == 1
        response = paths.responses[int(rows["response_id"][0])]
        level = 20 * np.log10(response.scale)
        assert abs(level - estimate) < 0.3, (channel, level)
        assert abs(level - issue) < 1.5
        assert "post-1" in response.label
        # the response is normalised at f0: the shadowed level is in the gain
        assert abs(response.transfer(np.array([500e3]), paths.sound_speed_m_s)[0]) == pytest.approx(1.0, rel=1e-12)
    hard_left, _ = specular_row(thesis_tank, backend, False, "post-3", 0)
    assert hard_left.size == 0  # the hard cut the shadows replace


def test_shadowed_echo_is_synthesised_with_its_response(thesis_tank) -> None:
    # The spectral path multiplies the row's spectrum by its response: the post-3 echo on the
    # centre channel synthesised with its response has, against the same row without it (its
    # unshadowed gain, the table-driven path), the energy ratio the frequency domain gives,
    # sum |Q D_tx D_rx H|^2 / sum |Q D_tx D_rx|^2 over the band (the pulse, the pistons'
    # directivities at the row's angles, whose beams narrow with frequency: post-3 is 9 deg off
    # axis, near the first null), within 0.1 dB; and it stays at the row's delay (its peak
    # within one period of the unshadowed echo's).
    from acoustisim.propagation.directivity import piston_directivity
    from acoustisim.synthesis.synthesiser import PathSynthesiser
    from acoustisim.synthesis.transducer import pulse_spectrum

    paths = solve(thesis_tank, config=SolverConfig(mechanisms=("specular",), elastic_echoes=False))
    index = paths.surface_names.index("post-3")
    rows = paths.rows
    row = rows[np.flatnonzero((rows["order"] == 1) & (rows["object_ids"][:, 0] == index) & (rows["channel"] == 1))]
    response = paths.responses[int(row["response_id"][0])]
    plain = row.copy()
    plain["response_id"] = -1
    plain["geometric_gain"] /= response.scale
    plain["amplitude"] /= response.scale
    sonar = thesis_tank.sonar
    synthesiser = PathSynthesiser.create(sonar, thesis_tank.medium)
    shadowed = synthesiser.decimated_record(row, responses=paths.responses)
    whole = synthesiser.decimated_record(plain)
    ratio = 10 * np.log10(np.sum(shadowed**2) / np.sum(whole**2))
    f = np.linspace(1e3, synthesiser.band_top_hz, 4000)
    c = paths.sound_speed_m_s
    weight = np.abs(pulse_spectrum(sonar.pulse, f)
                    * piston_directivity(row["angle_tx_rad"][0], f, sonar.piston_radius_m, c)
                    * piston_directivity(row["angle_rx_rad"][0], f, sonar.piston_radius_m, c)) ** 2
    expected = 10 * np.log10(np.sum(weight * np.abs(response.transfer(f, c) * response.scale) ** 2) / np.sum(weight))
    assert abs(ratio - expected) < 0.1, (ratio, expected)
    period = synthesiser.grid.sample_rate_hz / synthesiser.grid.decimation / 500e3
    assert abs(int(np.argmax(np.abs(shadowed[1]))) - int(np.argmax(np.abs(whole[1])))) <= period


def test_shadow_responses_hold_their_echo_within_their_span(thesis_tank) -> None:
    # The EchoResponse promise: the pulse's echo through H lies within span_s (plus the pulse's
    # own support, 6 us either side of its centre), the rest below -80 dB of its peak: every
    # shadowed row of the thesis tank's default pose (measured worst -81.7 dB, with the
    # half-integrated edge waves' slow tails; 2 ms window at 4 MHz). The elastic echoes are off:
    # their responses state their own level (-60 dB, tests/physics/test_elastic_echo_responses.py).
    paths = solve(thesis_tank, config=SolverConfig(elastic_echoes=False))
    shadowed = [r for r in paths.responses if not isinstance(r, ApexResponse)]  # the apex's: test_edge_apex.py
    worst = worst_outside_span_db(shadowed, thesis_tank.sonar.pulse, paths.sound_speed_m_s, (-6e-6, 6e-6))
    assert len(shadowed) > 100
    assert worst < -80.0, worst


def test_legs_through_a_sphere_are_kept_at_their_shadowed_level(backend) -> None:
    # A 15 cm steel ball in the tank, the sonar looking past it: with shadows the specular
    # chains whose legs cross the ball (the hard cut drops them) are kept, weaker than without
    # the ball by their shadow factor: a disc's, at most the Poisson spot's 0 dB (a leg through
    # the centre), here from -5 to -51 dB (legs crossing it twice; Fresnel numbers up to 10,
    # where the Kirchhoff factor is an estimate), on average below -6 dB; the
    # chains the hard cut keeps keep their gains but for the factor near the ball's rim
    # (within +/- 6 dB, the bright fringe included), and those farther from it than the reach
    # from every leg are not touched at all.
    from acoustisim.geometry import SpherePrimitive
    from acoustisim.materials import get_material
    from acoustisim.scene import SceneObject
    import trimesh

    centre, radius = np.array([3.4, 1.4, 0.45]), 0.15
    mesh = trimesh.creation.icosphere(subdivisions=4, radius=radius)
    mesh.apply_translation(centre)
    ball = SceneObject("ball", "sphere", get_material("steel"), mesh, SpherePrimitive(tuple(centre), radius))
    sonar = default_sonar().with_pose(position_m=(2.3, 1.1, 0.37), yaw_deg=20.0, pitch_deg=3.0)
    config = SolverConfig(max_order=3, mechanisms=("direct", "specular"), amplitude_floor_db=None, backend=backend)
    alone = solve(tank_with(), sonar, config)
    with_ball = solve(tank_with(ball), sonar, config)
    hard = solve(tank_with(ball), sonar, SolverConfig(**{**config.__dict__, "shadows": False}))

    def by_key(paths):
        return {(int(r["channel"]), tuple(r["object_ids"]), round(float(r["delay_s"]), 12)): r for r in paths.rows}

    plain, shadowed, cut = by_key(alone), by_key(with_ball), by_key(hard)
    through = [key for key in plain if key in shadowed and key not in cut]
    levels = np.array([20 * np.log10(abs(shadowed[key]["geometric_gain"] / plain[key]["geometric_gain"]))
                       for key in through])
    assert len(through) > 10 and all(shadowed[key]["response_id"] >= 0 for key in through)
    assert np.all(levels < 0.5) and np.all(np.isfinite(levels)) and np.mean(levels) < -6.0
    kept = [key for key in cut if key in plain]
    untouched = [key for key in kept if shadowed[key]["response_id"] < 0]
    assert len(untouched) > 100
    assert all(shadowed[key]["geometric_gain"] == plain[key]["geometric_gain"] for key in untouched)
    near = [key for key in kept if shadowed[key]["response_id"] >= 0]
    assert all(abs(20 * np.log10(abs(shadowed[key]["geometric_gain"] / plain[key]["geometric_gain"]))) < 6.0
               for key in near)
