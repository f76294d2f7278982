"""The Biot-Tolstoy-Medwin line integral, discretised and integrated by each engine, against
Medwin's closed form and the boundary physics; the angular factor beta against its symmetries."""

from __future__ import annotations

from functools import lru_cache

import numpy as np
import pytest
from scipy.integrate import quad

from acoustisim.propagation.reference import btm
from acoustisim.propagation.reference.edge_elements import Discretisation, PairGeometry
from support.edge_engines import edge_engine

C = 1482.38
F0 = 500e3
STEP_M = C / (16 * F0)  # the engine's path-length step: 1/(16 f0) in delay
STEP_S = STEP_M / C
THETA_W = 2 * np.pi - np.pi / 3  # a 60-degree prism edge
NU = np.pi / THETA_W


def element_rows(backend, length, rs, ts, zs, rr, tr, zr, soft=False, nu=NU, max_element=5e-4):
    """The fine discretisation's impulses (delay, gain) and elements of one edge and receiver."""
    engine = edge_engine(backend)
    geometry = PairGeometry(*(np.array([v], dtype=float) for v in (length, rs, zs, rr, zr)),
                            np.array([False]), np.array([False]))
    elements = engine.discretise_edges(geometry, Discretisation(STEP_M, max_element))
    wedge = btm.WedgePairs(*(np.array([v], dtype=float) for v in (nu, rs, ts, zs, rr, tr, zr)), np.array([soft]))
    gains = engine.element_gains(elements, btm.pair_constants(wedge))
    return elements.path_length_m / C, gains, elements


@lru_cache(maxsize=None)
def closed_form_bins(bin_edges, nu, rs, ts, zs, rr, tr, zr, soft):
    """Medwin's closed form integrated over each bin by adaptive quadrature (an independent
    evaluation of the same response); cached, as both engines compare against it."""
    def h(t):
        return float(btm.infinite_wedge_impulse_response(
            t, nu=nu, r_s=rs, theta_s=ts, z_s=zs, r_r=rr, theta_r=tr, z_r=zr, sound_speed_m_s=C,
            pressure_release=soft))

    return np.array([quad(h, a, b, limit=200)[0] for a, b in zip(bin_edges[:-1], bin_edges[1:])])


GEOMETRIES = [
    # rs, ts, zs, rr, tr, zr: monostatic on the bisector, bistatic with height offsets, near grazing
    (2.0, THETA_W / 2, 1.5, 2.0, THETA_W / 2, 1.5),
    (1.0, 1.0, 1.5, 0.7, 2.5, 1.8),
    (0.5, 0.05, 1.3, 1.5, 4.9, 1.6),
]


@pytest.mark.parametrize("soft", [False, True])
@pytest.mark.parametrize("geometry", GEOMETRIES)
def test_long_edge_matches_medwin_closed_form(backend, geometry, soft):
    rs, ts, zs, rr, tr, zr = geometry
    length = 3.0  # both branches reach beyond the compared 40 us window (ends >= 100 us later)
    delay, gain, _ = element_rows(backend, length, rs, ts, zs, rr, tr, zr, soft)
    tau0 = np.hypot(rs + rr, zr - zs) / C
    # 1 us bins aligned on the onset: eight element steps each, so no element straddles a bin
    bin_edges = tau0 + 1e-6 * np.arange(41)
    binned, _ = np.histogram(delay, bin_edges, weights=gain)
    reference = closed_form_bins(tuple(bin_edges), NU, rs, ts, zs, rr, tr, zr, soft)
    rel = np.abs(binned - reference) / np.abs(reference)
    # Both sides are exact forms of one integral (z-domain quadrature against a t-domain closed
    # form integrated by quad), so we hold 1e-4 everywhere, the onset bin included: anything
    # larger is a bug, not round-off (a wrong sign or term is O(1)).
    assert np.all(rel < 1e-4), rel.max()


def test_onset_at_least_time_point_within_1ns(backend):
    for rs, ts, zs, rr, tr, zr in GEOMETRIES:
        delay, _, _ = element_rows(backend, 3.0, rs, ts, zs, rr, tr, zr)
        tau0 = np.hypot(rs + rr, zr - zs) / C
        assert tau0 <= delay.min() < tau0 + 1e-9


def test_finite_edge_end_steps(backend):
    """Each branch of the response stops when the edge ends: h drops to half, then to zero."""
    rs, ts, zs, rr, tr, zr = 1.0, 1.0, 0.3, 0.8, 2.0, 0.45
    length = 1.0
    delay, gain, _ = element_rows(backend, length, rs, ts, zs, rr, tr, zr)
    tau0 = np.hypot(rs + rr, zr - zs) / C
    t_low = (np.hypot(rs, zs) + np.hypot(rr, zr)) / C  # the z = 0 end
    t_high = (np.hypot(rs, length - zs) + np.hypot(rr, length - zr)) / C  # the z = L end
    assert tau0 < t_low < t_high
    bin_edges = tau0 + 0.5e-6 * np.arange(int((t_high - tau0) / 0.5e-6) + 10)
    binned, _ = np.histogram(delay, bin_edges, weights=gain)
    reference = closed_form_bins(tuple(bin_edges), NU, rs, ts, zs, rr, tr, zr, False)
    both = bin_edges[1:] <= t_low
    one = (bin_edges[:-1] >= t_low) & (bin_edges[1:] <= t_high)
    none = bin_edges[:-1] >= t_high
    assert both.sum() > 10 and one.sum() > 10 and none.sum() > 3
    # the two branches of an infinite edge carry equal halves of h(t) at every t
    np.testing.assert_allclose(binned[both], reference[both], rtol=1e-4)
    np.testing.assert_allclose(binned[one], 0.5 * reference[one], rtol=1e-4)
    assert np.all(binned[none] == 0.0)
    # the last element of each branch ends exactly at its end's delay
    assert delay.max() <= t_high and delay.max() > t_high - STEP_S


@pytest.mark.parametrize(
    "name, boundary, jump_rigid, jump_soft",
    [
        # receiver crossing the shadow boundary of the direct sound: the diffraction jumps by
        # the direct field 1/D it replaces, for both boundary conditions
        ("shadow", lambda ts: ts + np.pi, -1.0, -1.0),
        # the reflection boundaries of face 1 and face 2: the jump is R / D with R = +1 (rigid)
        # or -1 (pressure release), the image path having the same length D at the boundary
        ("face-1 reflection", lambda ts: np.pi - ts, -1.0, 1.0),
        ("face-2 reflection", lambda ts: 2 * THETA_W - np.pi - ts, 1.0, -1.0),
    ],
)
def test_boundary_jumps_equal_the_geometrical_field(backend, name, boundary, jump_rigid, jump_soft):
    rs, ts, zs, rr, zr = 1.0, 1.0, 0.5, 0.7, 0.6
    d0 = np.hypot(rs + rr, zr - zs)
    for soft, expected in ((False, jump_rigid), (True, jump_soft)):
        totals = []
        for delta in (-1e-7, 0.0, 1e-7):
            _, gain, _ = element_rows(backend, 1.0, rs, ts, zs, rr, boundary(ts) + delta, zr, soft, max_element=2e-3)
            assert np.all(np.isfinite(gain))
            totals.append(gain.sum())
        # total diffracted field (time integral) just before minus just after the boundary;
        # 1e-7 rad from the boundary the jump is complete to O(1e-7), and the apex model makes
        # it exact otherwise: 1e-5 relative.
        assert (totals[0] - totals[2]) * d0 == pytest.approx(expected, rel=1e-5), name
        # exactly on the boundary the field is the mean of the two sides (half the jump)
        assert totals[1] == pytest.approx(0.5 * (totals[0] + totals[2]), rel=1e-9, abs=1e-12)


def test_reciprocity_of_the_line_integral(backend):
    """Swapping source and receiver leaves the response unchanged (the integrand is symmetric in
    them): the summed gains agree to the quadrature's accuracy, although the discretisations
    (graded about the same apex, with the roles of m and l swapped) differ."""
    rs, ts, zs, rr, tr, zr = 1.0, 1.0, 0.3, 0.8, 2.0, 0.45
    _, forward, _ = element_rows(backend, 1.0, rs, ts, zs, rr, tr, zr)
    _, backward, _ = element_rows(backend, 1.0, rr, tr, zr, rs, ts, zs)
    assert forward.sum() == pytest.approx(backward.sum(), rel=1e-9)


def test_pressure_release_vanishes_on_the_faces_and_rigid_is_even():
    ts = 1.3
    eta_m1 = np.linspace(1e-4, 2.0, 50)
    # Dirichlet faces: beta = 0 for a receiver on face 1 (theta = 0) or face 2 (theta = theta_w)
    for tr in (0.0, THETA_W):
        np.testing.assert_allclose(btm.beta(NU, eta_m1, ts, tr, True), 0.0, atol=1e-12)
    # Neumann faces: beta is even about each face (theta -> -theta, theta_w + d -> theta_w - d)
    for d in (0.05, 0.3):
        np.testing.assert_allclose(btm.beta(NU, eta_m1, ts, d, False), btm.beta(NU, eta_m1, ts, -d, False), rtol=1e-12)
        np.testing.assert_allclose(
            btm.beta(NU, eta_m1, ts, THETA_W + d, False), btm.beta(NU, eta_m1, ts, THETA_W - d, False), rtol=1e-12
        )
    # and the sign pattern itself
    np.testing.assert_array_equal(btm.btm_signs(False), [1, 1, 1, 1])
    np.testing.assert_array_equal(btm.btm_signs(True), [-1, 1, 1, -1])
    # the rigid and soft responses differ: not the same function under another name
    assert not np.allclose(btm.beta(NU, eta_m1, ts, 2.0, False), btm.beta(NU, eta_m1, ts, 2.0, True))


def test_integer_nu_wedges_do_not_diffract():
    """theta_w = pi / n (the tank's 90-degree corners): the image-source field is exact."""
    eta_m1 = np.linspace(0.0, 3.0, 40)
    for nu in (2.0, 3.0):
        for soft in (False, True):
            np.testing.assert_allclose(btm.beta(nu, eta_m1, 0.4, 0.9, soft), 0.0, atol=1e-12)


def test_elements_respect_the_delay_step_and_the_length_cap(backend):
    _, _, elements = element_rows(backend, 3.0, 1.0, 1.0, 1.0, 0.8, 2.0, 1.4, max_element=1e-3)
    lengths = elements.z_end_m - elements.z_start_m
    assert np.all(lengths > 0) and lengths.max() <= 1e-3 * (1 + 1e-12)
    # the elements tile the edge exactly
    assert lengths.sum() == pytest.approx(3.0, rel=1e-12)
    # path length of each element is within its own delay step of its neighbours
    order = np.argsort(elements.path_length_m)
    assert np.max(np.diff(elements.path_length_m[order])) <= STEP_M * (1 + 1e-9)


def test_no_nan_on_boundary_at_the_apex_and_with_the_source_near_the_edge(backend):
    for tr in (np.pi - 1.0, 1.0 + np.pi, 0.0, THETA_W):
        for rs in (1e-5, 1.0):
            _, gain, _ = element_rows(backend, 0.5, rs, 1.0, 0.25, 0.5, tr, 0.25)
            assert gain.size > 0 and np.all(np.isfinite(gain))


def test_absurd_element_length_is_refused_with_its_true_count(backend):
    # 1e30 elements: counted in floating point (an integer count would overflow int64 and
    # could wrap below the limit)
    geometry = PairGeometry(*(np.array([v]) for v in (1.0, 0.5, 0.2, 0.6, 0.4)), np.array([False]), np.array([False]))
    with pytest.raises(ValueError, match=r"at least 1e\+30 elements"):
        edge_engine(backend).discretise_edges(geometry, Discretisation(1e-4, 1e-30, coarsening_levels=2,
                                                                       max_elements=1e7))
