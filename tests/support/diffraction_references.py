"""Reference solutions for diffraction into shadows (tests only; phase 2's shadow model is
validated against them).

Time dependence exp(-i w t); fields per unit source pressure at 1 m (free field e^{ikR} / R).

Half-plane, point source: the exact eigenfunction solution (Macdonald's series)
---------------------------------------------------------------------------------
A screen on the half-plane theta = 0 (edge on the z axis, theta measured around the edge from
one face to the other, 0 .. 2 pi; the wedge of exterior angle 2 pi, nu = 1/2). The 2-D Green's
function of the wedge, (lap + kappa^2) G = -delta, is the eigenfunction series
(Macdonald 1902; Bowman, Senior & Uslenghi ch. 6)

    G_rigid = (i pi / (2 theta_w)) sum_{m>=0} eps_m J_{nu m}(kappa r_<) H_{nu m}(kappa r_>) cos(nu m th_s) cos(nu m th_r)
    G_soft  = (i pi / theta_w)      sum_{m>=1}       J_{nu m}(kappa r_<) H_{nu m}(kappa r_>) sin(nu m th_s) sin(nu m th_r)

(theta_w = pi gives the free field plus its image: the check of the normalisation), and the
point source is the superposition over axial wavenumbers, e^{ikR}/R = 4 pi G_3D,

    p = 2 int dk_z e^{i k_z (z_r - z_s)} G(kappa = sqrt(k^2 - k_z^2)),

summed numerically over |k_z| < 0.98 k with cosine-tapered ends (relative error about 1e-4
at k r ~ 100-200, measured on the free field and its image, theta_w = pi). Exact otherwise, and independent of the Biot-Tolstoy-Medwin solution; the cost
(orders up to 2 (k r_> + 30), a few thousand k_z) keeps it to modest k r (tens to a few
hundred). :func:`half_plane_diffracted` removes the geometrical direct and reflected fields
where they exist, leaving the diffracted field that BTM gives.

Smooth cylinder obstacle: Kirchhoff (Fresnel) integral over the unobstructed aperture
-------------------------------------------------------------------------------------
A vertical post (radius a, axis through c) between a source S and a receiver P. The aperture is
the vertical plane through the axis normal to the horizontal S -> P direction; the post blocks
the strip |u - u_c| < a of it (its silhouette). By Babinet, the field at P is the free field
minus the Kirchhoff integral over the strip,

    p = e^{i k R} / R - (1 / (i lambda)) int_strip int_z e^{i k (r_1 + r_2)} / (r_1 r_2) (cos t_1 + cos t_2) / 2 dz du,

the z integral by stationary phase (the post spans many vertical Fresnel zones: exact to
O(1 / (k rho)) ~ 1e-3), the u integral by composite Gauss-Legendre quadrature with exact
distances.
Valid where the Kirchhoff approximation is: Fresnel numbers a^2 / (lambda d) of order 0.1-1,
angles near the shadow boundary (physics.md section 8).
"""

from __future__ import annotations

import numpy as np


def _cylinder_functions(kind, orders, x):
    """Z_nu(x) for nu in ``orders`` (multiples of 1/2), x (n,) real: (n, len(orders)); the
    package's recurrences (validated against scipy in test_elastic_series.py) for integer and
    half-integer orders, 100 times faster than scipy per order."""
    from acoustisim.scattering.special import bessel_table

    out = np.empty((x.size, orders.size), dtype=complex)
    top = int(np.ceil(orders.max())) + 1
    whole = np.isclose(orders, np.round(orders))
    table = bessel_table(kind, top, x.astype(complex))
    out[:, whole] = table[:, np.round(orders[whole]).astype(int)]
    if np.any(~whole):
        half = bessel_table(kind, top, x.astype(complex), spherical=True) / np.sqrt(0.5 * np.pi / x)[:, None]
        out[:, ~whole] = half[:, np.floor(orders[~whole]).astype(int)]
    return out


def _wedge_green(kappa, r_s, th_s, r_r, th_r, theta_w, pressure_release, extra_orders=30):
    """The 2-D wedge Green's function at real kappa values (n,) by its eigenseries (theta_w =
    pi or 2 pi: integer and half-integer orders)."""
    nu = np.pi / theta_w
    r_small, r_big = min(r_s, r_r), max(r_s, r_r)
    top = int(np.ceil((np.max(kappa) * r_big + extra_orders) / nu))
    m = np.arange(top + 1)
    order = nu * m
    with np.errstate(all="ignore"):
        terms = _cylinder_functions("J", order, kappa * r_small) * _cylinder_functions("H", order, kappa * r_big)
    terms = np.where(np.isfinite(terms), terms, 0.0)
    if pressure_release:
        angular = np.sin(order * th_s) * np.sin(order * th_r)
        return (1j * np.pi / theta_w) * (terms[:, 1:] @ angular[1:])
    eps = np.where(m == 0, 1.0, 2.0)
    angular = eps * np.cos(order * th_s) * np.cos(order * th_r)
    return (1j * np.pi / (2.0 * theta_w)) * (terms @ angular)


def wedge_point_source(k, r_s, th_s, z_s, r_r, th_r, z_r, theta_w=2.0 * np.pi, pressure_release=False,
                       kz_points=2001, kz_fraction=0.98):
    """Total field of a unit point source (e^{ikR}/R free field) and a wedge of exterior angle
    ``theta_w`` (2 pi: the half-plane), by the k_z superposition of the 2-D eigenseries; one
    wavenumber ``k`` (1/m).

    ``kz_fraction``: the integral runs over |k_z| < kz_fraction k, tapered over its outer 40 %
    (the evanescent part |k_z| > k is left out: it decays as exp(-|kappa| |r_r - r_s|) and
    weighs about 1e-4 at k r ~ 200; measured against the free field and its image for
    theta_w = pi in tests/physics/test_elastic_diffraction_refs.py).
    """
    kz_max = kz_fraction * k
    kz = np.linspace(-kz_max, kz_max, kz_points)
    kappa = np.sqrt(k * k - kz * kz)
    green = _wedge_green(kappa, r_s, th_s, r_r, th_r, theta_w, pressure_release)
    edge = np.abs(kz) / kz_max
    taper = np.where(edge < 0.6, 1.0, 0.5 * (1.0 + np.cos(np.pi * (edge - 0.6) / 0.4)))
    return 2.0 * np.sum(np.exp(1j * kz * (z_r - z_s)) * green * taper) * (kz[1] - kz[0])


def half_plane_diffracted(k, r_s, th_s, z_s, r_r, th_r, z_r, pressure_release=False, **options):
    """The diffracted part of the half-plane field: total minus the geometrical direct and
    reflected fields where they exist (one wavenumber ``k``)."""
    dz2 = (z_r - z_s) ** 2
    geometric = 0.0
    for sign, phi in ((1.0, th_r - th_s), (-1.0 if pressure_release else 1.0, th_r + th_s)):
        if np.cos(0.5 * phi) > 0.0:  # the ray exists
            distance = np.sqrt(r_s**2 + r_r**2 - 2.0 * r_s * r_r * np.cos(phi) + dz2)
            geometric = geometric + sign * np.exp(1j * k * distance) / distance
    total = wedge_point_source(k, r_s, th_s, z_s, r_r, th_r, z_r, 2.0 * np.pi, pressure_release, **options)
    return total - geometric


def btm_spectrum(h_of_t, onset_s, k, sound_speed, duration_s=4e-3, points=400_001):
    """Physics-convention spectrum int h(t) e^{i w t} dt of an impulse response with an inverse
    square-root onset at ``onset_s``: t = onset + s^2 removes the singularity; trapezoid in s
    over ``duration_s`` (the tail beyond it is below 1e-6 of the integral for the tank's
    geometries), shape of ``k``."""
    s = np.linspace(0.0, np.sqrt(duration_s), points)
    t = onset_s + s * s
    integrand = h_of_t(t) * 2.0 * s  # dt = 2 s ds
    omega = np.asarray(k, dtype=float) * sound_speed
    out = np.empty(omega.shape, dtype=complex)
    for index, w in np.ndenumerate(omega):
        out[index] = np.trapezoid(integrand * np.exp(1j * w * t), s)
    return out


def kirchhoff_post_shadow(k, source_m, receiver_m, post_centre_m, radius_m, nodes_per_panel=8):
    """Field at ``receiver_m`` of a unit point source at ``source_m`` behind a vertical post
    (Kirchhoff integral, module docstring), shape of ``k``.

    Parameters
    ----------
    k : array_like
        Wavenumbers (1/m).
    source_m, receiver_m : array_like, shape (3,)
        Tank frame (m); the post is vertical, centred at ``post_centre_m`` (x, y).
    radius_m : float
    nodes_per_panel : int
        Gauss-Legendre nodes per panel; the strip is cut into panels over which the integrand's
        phase turns by at most pi / 2 (bound k (1 + a (1/d_1 + 1/d_2))), so the composite rule is
        accurate to rounding.
    """
    k = np.atleast_1d(np.asarray(k, dtype=float))
    s = np.asarray(source_m, dtype=float)
    p = np.asarray(receiver_m, dtype=float)
    c = np.asarray(post_centre_m, dtype=float)[:2]
    horizontal = p[:2] - s[:2]
    along = horizontal / np.linalg.norm(horizontal)
    across = np.array([-along[1], along[0]])
    # aperture plane through the axis, normal to `along`: the post's silhouette |u| < a
    nearest = max(1e-3, min(np.linalg.norm(c - s[:2]), np.linalg.norm(c - p[:2])) - radius_m)
    phase_rate = float(np.max(k)) * (1.0 + 2.0 * radius_m / nearest)
    panels = int(np.ceil(phase_rate * 2.0 * radius_m / (0.5 * np.pi))) + 1
    x_panel, w_panel = np.polynomial.legendre.leggauss(nodes_per_panel)
    edges = np.linspace(-radius_m, radius_m, panels + 1)
    half = 0.5 * np.diff(edges)
    u = (0.5 * (edges[:-1] + edges[1:]))[:, None] + half[:, None] * x_panel[None, :]
    weights = (half[:, None] * w_panel[None, :]).ravel()
    points = c[None, :] + np.outer(u.ravel(), across)  # (nodes, 2)
    d1 = np.linalg.norm(points - s[:2], axis=1)  # horizontal distances
    d2 = np.linalg.norm(points - p[:2], axis=1)
    dz = p[2] - s[2]
    # stationary point in z on the straight line in the unrolled vertical plane
    z_rel = dz * d1 / (d1 + d2)
    r1 = np.hypot(d1, z_rel)
    r2 = np.hypot(d2, dz - z_rel)
    # obliquities: angle between each ray and the aperture normal `along`
    cos1 = np.abs((points - s[:2]) @ along) / d1 * (d1 / r1)
    cos2 = np.abs((p[:2] - points) @ along) / d2 * (d2 / r2)
    # stationary-phase z integral of e^{ik(r1 + r2)} / (r1 r2): second derivative of the phase
    # d^2(r1 + r2)/dz^2 = d1^2 / r1^3 + d2^2 / r2^3
    curvature = d1**2 / r1**3 + d2**2 / r2**3
    z_factor = np.sqrt(2.0 * np.pi / (k[:, None] * curvature[None, :])) * np.exp(0.25j * np.pi)
    integrand = np.exp(1j * k[:, None] * (r1 + r2)[None, :]) / (r1 * r2)[None, :] * z_factor \
        * (0.5 * (cos1 + cos2))[None, :]
    strip = (k / (2j * np.pi)) * (integrand @ weights)
    free_distance = np.linalg.norm(p - s)
    return np.exp(1j * k * free_distance) / free_distance - strip
