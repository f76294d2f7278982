"""The geometry of diffracted shadows: which objects are smooth obstacles, the ray caster
without them, which legs pair with which obstacle, the response's conventions, the knobs."""

from __future__ import annotations

import numpy as np
import pytest

from acoustisim.errors import InputError
from acoustisim.propagation import SolverConfig, prepare
from acoustisim.propagation.shadows import (FRESNEL_REACH, ApertureTerms, Legs, ShadowResponse, aperture_terms,
                                            fresnel_scale, shadow_factor)

C = 1482.38


def test_smooth_obstacles_of_the_thesis_tank(thesis_tank) -> None:
    prepared = prepare(thesis_tank)
    obstacles = prepared.smooth_obstacles
    names = [thesis_tank.surface_names[s] for s in obstacles.surface]
    assert names == ["post-1", "post-2", "post-3", "pipe-1"]
    # the posts stand on the floor and reach the surface: continued by their images
    assert obstacles.infinite.tolist() == [True, True, True, False]
    assert not obstacles.sphere.any()
    assert obstacles.half_length_m[3] == pytest.approx(0.3)
    assert prepared.smooth_obstacles is obstacles  # built once per prepared scene


def test_free_field_post_is_finite_and_sphere_is_a_sphere(builtin_scenes) -> None:
    assert not prepare(builtin_scenes("free-post")).smooth_obstacles.infinite[0]
    sphere = prepare(builtin_scenes("free-sphere")).smooth_obstacles
    assert sphere.sphere.tolist() == [True] and sphere.half_length_m[0] == 0.0
    assert prepare(builtin_scenes("free-edge")).smooth_obstacles.count == 0


def test_ray_caster_without_the_obstacles(thesis_tank) -> None:
    prepared = prepare(thesis_tank)
    full, shadow = prepared.raycaster, prepared.smooth_obstacles.raycaster
    post1 = np.array(thesis_tank.object("post-1").primitive.center_m)
    prism = np.array([2.5, 1.5, 0.5])
    start = np.array([[1.0, 1.2, 0.5], [1.0, 1.5, 0.5]])
    end = np.array([post1 + [1.0, 0.0, 0.0], prism + [1.0, 0.0, 0.0]])
    assert full.occluded(start, end).tolist() == [True, True]
    assert shadow.occluded(start, end).tolist() == [False, True]  # the post is gone, the prism is not
    # patch labels keep their meaning: excluding the prism's patches unblocks the second leg
    prism_patches = np.unique(full.patch_index[full.surface_index == thesis_tank.surface_names.index("edge-1")])
    exclude = np.tile(np.r_[prism_patches, -1][None, :], (2, 1))
    assert shadow.occluded(start, end, exclude_patches=exclude).tolist() == [False, False]
    assert shadow.triangle_count < full.triangle_count


def legs(start, end, start_surface=-1, end_surface=-1) -> Legs:
    return Legs(np.atleast_2d(np.asarray(start, float)), np.atleast_2d(np.asarray(end, float)), np.array([0]),
                np.array([start_surface]), np.array([end_surface]))


def test_legs_pair_with_obstacles_between_their_ends_within_reach(thesis_tank) -> None:
    obstacles = prepare(thesis_tank).smooth_obstacles
    post1 = thesis_tank.surface_names.index("post-1")
    source = np.array([1.0, 1.2, 0.5])
    # through post-1: a strip term centred on the leg
    terms = aperture_terms(legs(source, [5.0, 1.2, 0.5]), obstacles, 500e3, C)
    assert obstacles.surface[terms.obstacle].tolist() == [post1]
    assert terms.w_centre[0] == pytest.approx(0.0, abs=1e-12) and terms.infinite[0]
    assert 1.0 / terms.inverse_distance[0] == pytest.approx(2.0 * 2.0 / 4.0)
    # the leg ending on post-1 itself: post-1 does not shadow it
    assert aperture_terms(legs(source, [2.975, 1.2, 0.5], end_surface=post1), obstacles, 500e3, C).row.size == 0
    # post-1 beyond the leg's end: no term
    assert aperture_terms(legs(source, [2.5, 1.2, 0.5]), obstacles, 500e3, C).row.size == 0
    # reach: the silhouette FRESNEL_REACH Fresnel units away at f0, just inside and just outside
    sigma = fresnel_scale(1.0 / 1.0, 500e3, C)
    for factor, count in ((0.99, 1), (1.01, 0)):
        clearance = 0.025 + factor * FRESNEL_REACH / sigma
        found = aperture_terms(legs([1.0, 1.2 + clearance, 0.5], [5.0, 1.2 + clearance, 0.5]), obstacles, 500e3, C)
        assert found.row.size == count


def test_response_is_normalised_and_in_the_engineering_convention(thesis_tank) -> None:
    # A post 0.2 m beside a 1 m leg (d1 = d2 = 2 m): H = 1 + the edge waves of its silhouette's
    # two edges, which arrive after the leg's own field by their extra paths rho^2 (1/d1 +
    # 1/d2) / (2 c), 10.3 and 17.1 us. In the engineering convention (a delay tau is
    # exp(-j 2 pi f tau)) the pulse's echo through H - 1 peaks between those delays; in the
    # physics one it would peak before the leg's arrival.
    from acoustisim.synthesis.transducer import pulse_spectrum

    terms = ApertureTerms(np.array([0]), np.array([0]), np.array([1.0]), np.array([0.0]), np.array([0.2]),
                          np.array([0.0]), np.array([0.025]), np.array([0.0]), np.array([True]))
    scale = float(np.abs(shadow_factor(terms, np.array([500e3]), C))[0])
    response = ShadowResponse("test", (0.0, 1e-4), terms, 0, 1, scale)
    assert abs(response.transfer(np.array([500e3]), C)[0]) == pytest.approx(1.0, rel=1e-14)
    fs, n = 4e6, 1 << 12
    f = np.fft.rfftfreq(n, 1 / fs)
    echo = np.fft.irfft(pulse_spectrum(thesis_tank.sonar.pulse, f) * (response.transfer(f, C) * scale - 1.0), n)
    peak = (np.fft.fftfreq(n) * n / fs)[np.argmax(np.abs(echo))]
    assert (0.175**2 / (2 * C)) < peak < (0.225**2 / (2 * C))


@pytest.mark.parametrize("field, value", [("shadows", 1), ("edge_reflections", -1), ("edge_reflections", 3),
                                          ("edge_reflections", True), ("edge_reflections", 1.0),
                                          ("edge_reflection_fresnel_v", -1.0), ("edge_reflection_fresnel_v", float("nan")),
                                          ("edge_reflection_fresnel_v", True), ("edge_reflection_fresnel_v", "3")])
def test_knobs_refuse_bad_values(field: str, value: object) -> None:
    with pytest.raises(InputError, match=f"solver.{field}"):
        SolverConfig(**{field: value})
