"""The shadow references of tests/support/diffraction_references.py, checked where exact answers
exist: the wedge eigenseries against the free field and image (theta_w = pi) and against the
Biot-Tolstoy-Medwin closed form of a thin screen; the Kirchhoff integral against the exact
half-plane near its shadow boundary."""

import numpy as np
import pytest

from acoustisim.propagation.reference.btm import infinite_wedge_impulse_response
from support.diffraction_references import (btm_spectrum, half_plane_diffracted, kirchhoff_post_shadow,
                                            wedge_point_source)

C = 1482.4


def test_wedge_series_of_a_rigid_plane_is_the_free_field_plus_its_image():
    # theta_w = pi: G = free field + image exactly; the k_z superposition leaves out the
    # evanescent part (|k_z| > k): 1.2e-4 relative at k r ~ 100 (60 kHz, 0.5 m); tolerance 1e-3.
    k = 2 * np.pi * 60e3 / C
    r_s, th_s, z_s, r_r, th_r, z_r = 0.5, 0.7, 0.0, 0.4, 2.0, 0.05
    got = wedge_point_source(k, r_s, th_s, z_s, r_r, th_r, z_r, theta_w=np.pi, kz_points=1001)
    expected = 0.0
    for phi in (th_r - th_s, th_r + th_s):
        distance = np.sqrt(r_s**2 + r_r**2 - 2 * r_s * r_r * np.cos(phi) + (z_r - z_s) ** 2)
        expected += np.exp(1j * k * distance) / distance
    assert abs(got / expected - 1.0) < 1e-3


@pytest.mark.parametrize("pressure_release", [False, True], ids=["rigid", "soft"])
@pytest.mark.parametrize("receiver_deg", [200.0, 235.0, 245.0, 300.0])
def test_half_plane_eigenseries_matches_the_btm_closed_form(receiver_deg, pressure_release):
    # The thin screen (nu = 1/2): Medwin's closed-form impulse response, Fourier transformed
    # (t = onset + s^2 removes the inverse-square-root onset), against the exact eigenseries
    # minus the geometrical field, across the shadow boundary (240 deg) and deep in the shadow:
    # measured within 0.01 dB and 0.001 rad; tolerance 0.05 dB (issue 17 asks 0.5 dB), 0.01 rad.
    k = 2 * np.pi * 60e3 / C
    geometry = dict(r_s=0.5, th_s=np.radians(60.0), z_s=0.0, r_r=0.4, th_r=np.radians(receiver_deg), z_r=0.05)
    exact = half_plane_diffracted(k, pressure_release=pressure_release, kz_points=1001, **geometry)
    onset = np.hypot(geometry["r_s"] + geometry["r_r"], geometry["z_r"] - geometry["z_s"]) / C

    def impulse(t):
        return infinite_wedge_impulse_response(
            t, nu=0.5, sound_speed_m_s=C, pressure_release=pressure_release, r_s=geometry["r_s"],
            theta_s=geometry["th_s"], z_s=geometry["z_s"], r_r=geometry["r_r"], theta_r=geometry["th_r"],
            z_r=geometry["z_r"])

    btm = btm_spectrum(impulse, onset, np.array([k]), C)[0]
    assert abs(20 * np.log10(abs(exact / btm))) < 0.05
    assert abs(np.angle(exact / btm)) < 0.01


def test_kirchhoff_integral_matches_the_exact_half_plane_near_its_shadow_boundary():
    # A strip 0.8 m wide whose near edge grazes the line of sight acts as a half-plane near the
    # boundary (its far edge's diffraction is a small ripple); the Kirchhoff integral is
    # accurate there to a fraction of a dB (the exact rigid and soft fields straddle it):
    # within 0.5 dB of the mean of the exact rigid and soft fields, 100 kHz, receivers from
    # the lit side into the shadow.
    k = 2 * np.pi * 100e3 / C
    source = np.array([-0.03, -0.5, 0.0])
    for x in (-0.05, 0.0, 0.05):
        receiver = np.array([x, 0.4, 0.05])
        kirchhoff = kirchhoff_post_shadow(np.array([k]), source, receiver, (0.4, 0.0), 0.4)[0]

        def polar(q):
            return np.hypot(q[0], q[1]), np.arctan2(q[1], q[0]) % (2 * np.pi), q[2]

        exact = np.mean([wedge_point_source(k, *polar(source), *polar(receiver), 2 * np.pi, soft, kz_points=1001)
                         for soft in (False, True)])
        assert abs(20 * np.log10(abs(kirchhoff / exact))) < 0.5


def test_kirchhoff_post_shadow_levels():
    # A 25 mm post halfway on a 2 m leg (Fresnel number a^2 / (lambda d) = 0.21 at 500 kHz):
    # on the axis the shadow is partial (the Poisson-like bright line of a small obstacle),
    # deeper than -3 dB but far from a hard cut; off the axis by several post radii the field is
    # the free field to within 1 dB; at 100 kHz (Fresnel number 0.04) the post hardly shadows.
    source, receiver = np.array([0.0, 0.0, 0.5]), np.array([0.0, 2.0, 0.5])
    free = 1.0 / 2.0
    k = 2 * np.pi * np.array([100e3, 500e3]) / C
    on_axis = np.abs(kirchhoff_post_shadow(k, source, receiver, (0.0, 1.0), 0.025)) / free
    assert 20 * np.log10(on_axis[1]) < -3.0
    assert 20 * np.log10(on_axis[0]) > 20 * np.log10(on_axis[1])
    aside = np.abs(kirchhoff_post_shadow(k, source, receiver, (0.2, 1.0), 0.025)) / free
    assert np.all(np.abs(20 * np.log10(aside)) < 1.0)


def test_thesis_tank_post_three_behind_post_one_matches_the_issue_estimate():
    # Issue 17: from the default pose the legs to post-3 graze post-1; "a Kirchhoff estimate
    # puts post-3's echo at about -18 / -9 / -16 dB (centre / right / left) relative to
    # unobstructed". This reference, coded independently, at 500 kHz, both legs through the
    # Kirchhoff integral (reflection point on post-3 facing the midpoint of transmitter and
    # receiver): -18.0 / -8.1 / -15.6 dB; the issue's figures are rounded (and may average the
    # band): within 1.5 dB.
    from scenes.builtin import builtin_scene

    scene = builtin_scene("thesis-tank")
    objects = {o.name: o for o in scene.objects}
    post1, post3 = objects["post-1"].primitive, objects["post-3"].primitive
    transmitter, receivers = scene.sonar.transmitter_position, scene.sonar.receiver_positions
    k = np.array([2 * np.pi * 500e3 / scene.medium.sound_speed])
    levels = {}
    for name, receiver in zip(("left", "centre", "right"), receivers):
        middle = 0.5 * (transmitter + receiver)
        facing = (middle[:2] - np.asarray(post3.center_m[:2])) / np.linalg.norm(middle[:2] - post3.center_m[:2])
        point = np.r_[np.asarray(post3.center_m[:2]) + post3.radius_m * facing, middle[2]]
        gain = 1.0
        for a, b in ((transmitter, point), (point, receiver)):
            field = kirchhoff_post_shadow(k, a, b, post1.center_m[:2], post1.radius_m)[0]
            gain *= abs(field) * np.linalg.norm(b - a)
        levels[name] = 20 * np.log10(gain)
    for name, issue in (("centre", -18.0), ("right", -9.0), ("left", -16.0)):
        assert abs(levels[name] - issue) < 1.5, (name, levels[name])
