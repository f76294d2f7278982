"""Diffraction into the shadows of smooth obstacles: the Kirchhoff (Fresnel) factor of a leg.

Physics
-------
A leg from A to B (the transmitter, a reflection point or a receiver) passes a smooth convex
obstacle: a sphere or a circular cylinder (:mod:`acoustisim.propagation.obstacles`). In the
Kirchhoff approximation the field at B is the integral of A's free field over the unobstructed
part of a surface between A and B (Born & Wolf, Principles of Optics, 8.3; physics.md section 8);
by Babinet's principle, the free field minus the same integral over the obstacle's silhouette.
Take the surface as the plane normal to the leg through the obstacle (distances d1 from A and d2
from B along the leg). In the paraxial (Fresnel) approximation, with the Fresnel scale
sigma = sqrt((2 f / c) (1 / d1 + 1 / d2)) and v = sigma rho for a point of the plane at rho
from the leg (time dependence exp(-i w t)),

    H = p / p_free = 1 - (1 / 2i) Int_silhouette exp(i pi |v|^2 / 2) d^2 v,            (1)

the integral over the whole plane being 2i (H = 1 without the obstacle). The silhouette is the
obstacle's projection along the leg, in coordinates (x along p, w along t x p) about the leg:

* a cylinder of unit axis a_c, radius a, half-length h_c: the Minkowski sum of its projected
  axis (half-length h = h_c |a_perp| along p = a_perp / |a_perp|, a_perp = a_c - (a_c . t) t)
  and its projected cap (an ellipse of semi-axes a across, a |a_c . t| along p): the chord
  |x - x_c| <= h + a |a_c . t| sqrt(1 - ((w - w_c) / a)^2) for |w - w_c| <= a;
* a sphere: the disc of radius a (the same with h = 0 and the semi-axis a along p);
* a cylinder spanning the water (a post from the floor to the free surface, continued by its
  images in both): the infinite strip |w - w_c| <= a, for which (1) is two Fresnel integrals,

      H = 1 - ((1 - i) / 2) (F(sigma (w_c + a)) - F(sigma (w_c - a))),
      F(v) = C(v) + i S(v) = Int_0^v exp(i pi s^2 / 2) ds.                              (2)

A finite silhouette is the rectangle |x - x_c| <= h, |w - w_c| <= a, whose integral is a product of
Fresnel integrals, plus the two cap segments beyond it, whose integrals are contour integrals
along their boundaries (Green's theorem in polar coordinates about the leg; the boundary
diffraction wave of Maggi and Rubinowicz):

    Int_R exp(i pi sigma^2 rho^2 / 2) d^2 x = oint_dR (exp(i pi sigma^2 rho^2 / 2) - 1) / (i pi sigma^2) dtheta.   (3)

A leg passing several obstacles gets the product of their factors (each as if alone); a path's
legs multiply, its reflection points acting as secondary sources (the estimate of issue 17). H
is 1 at f = 0; its impulse response runs from the leg's geometric delay (the unblocked part, a
delta) to the delay of the silhouette's farthest point, rho_max^2 (1/d1 + 1/d2) / (2 c), the
edge waves from the silhouette's rim starting at their own delays rho^2 (1/d1 + 1/d2) / (2 c).

Method
------
1. The specular mechanism tests its legs against the scene without the obstacles
   (:meth:`~acoustisim.propagation.prepared.PreparedScene.without_smooth_obstacles`): a chain blocked
   only by obstacles is kept, one blocked by anything else is dropped as before.
2. :func:`row_legs` takes every leg of the direct and specular rows; :func:`aperture_terms`
   pairs each with every obstacle that lies between its ends (the leg's point nearest the
   cylinder's axis segment, or the sphere's centre, strictly inside the leg, and the obstacle
   not the surface the leg starts or ends on) and whose silhouette comes within
   :data:`FRESNEL_REACH` Fresnel units of the leg at the centre frequency.
3. :func:`shadow_rows`: a row with such terms gets |H(f0)| (the product over its terms at the
   centre frequency f0) folded into its ``geometric_gain``, so that the amplitude columns, the
   amplitude floor and the ground truth hold the shadowed level, and a :class:`ShadowResponse`,
   H(f) / |H(f0)| in the engineering convention (the complex conjugate of (1)), that synthesis
   multiplies per frequency bin (:mod:`acoustisim.propagation.responses`).

Accuracy
--------
Kirchhoff's approximation: the obstacle is opaque, its edges sharp, the field in its silhouette
zero. Against the exact modal series of a 25 mm cylinder, the field 1.5 m behind it in its
partial shadow (300-700 kHz, Fresnel numbers 0.08-0.2; ``tests/physics/test_shadows.py``), the
factor lies between the rigid and the pressure-release cylinders' (within 0.013 dB: it averages
the two boundary conditions, which differ by up to 1.4 dB) and within 1.2 dB of an elastic PVC
post's; against the exact half-plane, a wide post's shadow boundary within 0.08 dB; deep in the
shadow of a large obstacle (Fresnel number well above 1) it is an estimate only. The Fresnel
form (1) against the exact-distance Kirchhoff integral of a post
(``tests/support/diffraction_references.py``): 0.012 dB, 0.002 rad at the thesis tank's
geometries; the contour quadrature of finite silhouettes against closed forms (Poisson's spot
behind a disc) and brute-force integrals: 1e-7. Reach: an obstacle farther than
:data:`FRESNEL_REACH` Fresnel units leaves the row's main arrival unchanged; what is left out is its edge wave, a separate arrival at least
FRESNEL_REACH^2 / (4 f0) (4.5 us) later, about 22 dB below the row. Not modelled: shadows of
edge-diffracted and diffuse rows (their legs are blocked outright), of the direct path by an
obstacle (the transducers are on one head), and shadows cast by non-convex or faceted objects.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, NamedTuple

import numpy as np
from numpy.typing import NDArray
from scipy.special import fresnel

from acoustisim.propagation.context import SolveContext
from acoustisim.propagation.obstacles import SmoothObstacles
from acoustisim.propagation.paths import PathKind

FRESNEL_REACH = 3.0
"""An obstacle's silhouette farther than this many Fresnel units (sigma rho at the centre
frequency) from a leg leaves it alone: its edge wave would start FRESNEL_REACH^2 / (4 f0) =
4.5 us after the leg's arrival, where the pulse's envelope is 97 dB down, and lie about
20 log10(pi FRESNEL_REACH sqrt 2) = 22.5 dB below it (the knife edge's asymptote)."""

GAUSS_NODES = 24
"""Gauss-Legendre nodes per panel of the contour quadrature of a finite silhouette's caps."""

PANEL_PHASE_RAD = 20.0
"""Most phase (rad) the contour integrand turns through across one panel (at the highest
frequency asked for): 24 Gauss-Legendre nodes integrate exp(i phase) over it to about 1e-13
(the rule's error for exp(i k x) on [-1, 1] is about k^48 / 48!, k = 10)."""

TAIL_S = 100e-6
"""Added to the latest edge-wave delay in a response's ``span_s`` (s). An edge wave is a
half-integrated impulse (a 1 / sqrt(t) onset; H - 1 goes as sqrt(f) at low frequencies for a
strip), so the echo of a pulse with some energy near 0 Hz (the seed's Gaussian pulse: -33 dB)
has a slowly decaying tail: 100 us after the latest edge wave it is below -80 dB of the echo's
peak on every shadowed row of the thesis tank (-52 dB after 6 us; ``tests/physics/test_shadows.py``)."""

TINY_RHO2 = 1e-30
"""A contour node's squared distance from the leg is taken as at least this (m^2), so that a node
on the leg itself divides nothing by zero (its term is then its exact limit sigma^2 / 2 times the
vanishing weight)."""

MIN_SCALE = 1e-12
"""|H(f0)| below this is taken as this (a row at an exact null of its shadow factor)."""


class Legs(NamedTuple):
    """Straight legs of path rows, shape (l,) or (l, 3) each.

    ``start_m``, ``end_m`` (m); ``row`` the row each belongs to; ``start_surface``,
    ``end_surface`` the surface each starts and ends on (-1 for a transducer).
    """

    start_m: NDArray[np.float64]
    end_m: NDArray[np.float64]
    row: NDArray[np.int64]
    start_surface: NDArray[np.int64]
    end_surface: NDArray[np.int64]


class ApertureTerms(NamedTuple):
    """(leg, obstacle) pairs and their silhouettes in the aperture plane, shape (t,) each.

    Attributes
    ----------
    row, obstacle : ndarray of int64
        The path row and the obstacle (index into :class:`SmoothObstacles`).
    inverse_distance : ndarray
        1 / d1 + 1 / d2 (1/m): sigma = sqrt((2 f / c) inverse_distance).
    x_centre, w_centre : ndarray
        The silhouette's centre about the leg, along p and across (w) (m).
    half_length : ndarray
        Half-length of the projected axis h (m); 0 for spheres.
    radius : ndarray
        a (m): the silhouette's half-width across.
    cap : ndarray
        The projected cap's semi-axis along p (m): a |a_c . t| (cylinders), a (spheres).
    infinite : ndarray of bool
        The infinite strip (2) of a spanning cylinder.
    """

    row: NDArray[np.int64]
    obstacle: NDArray[np.int64]
    inverse_distance: NDArray[np.float64]
    x_centre: NDArray[np.float64]
    w_centre: NDArray[np.float64]
    half_length: NDArray[np.float64]
    radius: NDArray[np.float64]
    cap: NDArray[np.float64]
    infinite: NDArray[np.bool_]

    def select(self, index: NDArray[np.intp] | NDArray[np.bool_] | slice) -> "ApertureTerms":
        """The terms ``index`` (a slice gives views)."""
        return ApertureTerms(*(column[index] for column in self))

    def farthest_m(self) -> NDArray[np.float64]:
        """Distance (m) from the leg of each silhouette's farthest point (across only, for a strip)."""
        across = np.abs(self.w_centre) + self.radius
        along = np.abs(self.x_centre) + self.half_length + self.cap
        return np.where(self.infinite, across, np.hypot(along, across))

    def nearest_m(self) -> NDArray[np.float64]:
        """A lower bound (m) on each silhouette's distance from the leg (0 when it covers it):
        the projected axis segment's distance less the radius (the cap's semi-axes are <= a)."""
        strip = np.abs(self.w_centre) - self.radius
        axis = np.hypot(np.maximum(np.abs(self.x_centre) - self.half_length, 0.0), self.w_centre) - self.radius
        return np.maximum(np.where(self.infinite, strip, axis), 0.0)


def fresnel_scale(inverse_distance: NDArray[np.float64], frequency_hz: NDArray[np.float64],
                  sound_speed_m_s: float) -> NDArray[np.float64]:
    """sigma = sqrt((2 f / c) (1/d1 + 1/d2)) (1/m), shape broadcast of the two inputs."""
    return np.sqrt(2.0 * np.asarray(frequency_hz, dtype=float) / float(sound_speed_m_s)
                   * np.asarray(inverse_distance, dtype=float))


def fresnel_integral(v: NDArray[np.float64]) -> NDArray[np.complex128]:
    """F(v) = C(v) + i S(v) = Int_0^v exp(i pi s^2 / 2) ds (scipy's Fresnel integrals)."""
    s, c = fresnel(v)
    return c + 1j * s


def row_legs(rows: NDArray[Any], context: SolveContext) -> Legs:
    """Every leg of the direct and specular ``rows`` (PATH_DTYPE): transmitter, interaction
    points in order, receiver."""
    kinds = rows["kind"]
    index = np.flatnonzero((kinds == PathKind.DIRECT) | (kinds == PathKind.SPECULAR))
    starts, ends, row, start_surface, end_surface = [], [], [], [], []
    orders = rows["order"][index].astype(np.int64)
    tx = np.asarray(context.transmitter_m, dtype=float)
    rx = np.asarray(context.receivers_m, dtype=float)
    for k in np.unique(orders):  # a loop over the few path orders, vectorised over rows
        mine = index[orders == k]
        r = rows[mine]
        vertices = np.concatenate([np.broadcast_to(tx, (mine.size, 1, 3)), r["points_m"][:, :k],
                                   rx[r["channel"].astype(np.int64)][:, None, :]], axis=1)
        none = np.full((mine.size, 1), -1, dtype=np.int64)
        surfaces = np.concatenate([none, r["object_ids"][:, :k].astype(np.int64), none], axis=1)
        starts.append(vertices[:, :-1].reshape(-1, 3))
        ends.append(vertices[:, 1:].reshape(-1, 3))
        row.append(np.repeat(mine, k + 1))
        start_surface.append(surfaces[:, :-1].reshape(-1))
        end_surface.append(surfaces[:, 1:].reshape(-1))
    if not starts:
        empty = np.zeros(0, dtype=np.int64)
        return Legs(np.zeros((0, 3)), np.zeros((0, 3)), empty, empty, empty)
    return Legs(np.concatenate(starts), np.concatenate(ends), np.concatenate(row), np.concatenate(start_surface),
                np.concatenate(end_surface))


def perpendicular_unit(direction: NDArray[np.float64], t: NDArray[np.float64]) -> tuple[NDArray[np.float64],
                                                                                      NDArray[np.float64]]:
    """The unit component of ``direction`` (n, 3) perpendicular to the unit ``t`` (n, 3), and
    its length before normalising; where that is below 1e-9, the component of z (or of x,
    for t along z) instead."""
    along = np.einsum("ij,ij->i", direction, t)
    perp = direction - along[:, None] * t
    norm = np.linalg.norm(perp, axis=1)
    fallback = np.where((np.abs(t[:, 2]) < 0.9)[:, None], np.array([0.0, 0.0, 1.0]), np.array([1.0, 0.0, 0.0]))
    fallback = fallback - np.einsum("ij,ij->i", fallback, t)[:, None] * t
    degenerate = norm < 1e-9
    chosen = np.where(degenerate[:, None], fallback, perp)
    return chosen / np.linalg.norm(chosen, axis=1, keepdims=True), np.where(degenerate, 0.0, norm)


def aperture_terms(legs: Legs, obstacles: SmoothObstacles, centre_frequency_hz: float,
                   sound_speed_m_s: float) -> ApertureTerms:
    """Every (leg, obstacle) pair with the obstacle between the leg's ends and its silhouette
    within :data:`FRESNEL_REACH` Fresnel units of the leg at ``centre_frequency_hz`` (see the
    module's Method), leg-major."""
    n_legs, n_obstacles = legs.row.size, obstacles.count
    leg = np.repeat(np.arange(n_legs), n_obstacles)
    k = np.tile(np.arange(n_obstacles), n_legs)
    a = legs.start_m[leg]
    segment = legs.end_m[leg] - a
    length = np.linalg.norm(segment, axis=1)
    # a first cut: the obstacle's bounding sphere (a post's within the water: every leg is) farther
    # from the segment than the reach can be anywhere along it (sigma is least at its middle,
    # where 1/d1 + 1/d2 = 4 / L)
    bounding = np.hypot(obstacles.radius_m, obstacles.half_length_m)[k]
    to_centre = obstacles.centre_m[k] - a
    along = np.clip(np.einsum("ij,ij->i", to_centre, segment) / np.maximum(length * length, 1e-300), 0.0, 1.0)
    gap = np.linalg.norm(to_centre - along[:, None] * segment, axis=1) - bounding
    reach = FRESNEL_REACH * np.sqrt(length * sound_speed_m_s / (8.0 * centre_frequency_hz))
    near = np.flatnonzero(gap < reach)
    leg, k, a, segment, length = leg[near], k[near], a[near], segment[near], length[near]
    t = segment / np.where(length > 0.0, length, 1.0)[:, None]
    centre, axis = obstacles.centre_m[k], obstacles.axis[k]
    sphere, infinite = obstacles.sphere[k], obstacles.infinite[k]
    # the leg's point nearest the obstacle: the centre's projection (sphere), the closest point
    # to the axis line, on the axis segment unless infinite (cylinder)
    to_centre = centre - a
    cos_axis = np.einsum("ij,ij->i", axis, t)
    across = 1.0 - cos_axis**2
    d = np.einsum("ij,ij->i", t, to_centre)
    e = np.einsum("ij,ij->i", axis, to_centre)
    along_axis = np.where(across > 1e-12, (cos_axis * d - e) / np.where(across > 1e-12, across, 1.0), 0.0)
    half = obstacles.half_length_m[k]
    along_axis = np.where(sphere, 0.0, np.where(infinite, along_axis, np.clip(along_axis, -half, half)))
    s = np.einsum("ij,ij->i", centre + along_axis[:, None] * axis - a, t)
    own = (legs.start_surface[leg] == obstacles.surface[k]) | (legs.end_surface[leg] == obstacles.surface[k])
    between = (s > 0.0) & (s < length) & ~own & (length > 0.0)
    p, axis_perp = perpendicular_unit(axis, t)
    w = np.cross(t, p)
    offset = centre - (a + s[:, None] * t)
    radius = obstacles.radius_m[k]
    with np.errstate(divide="ignore", invalid="ignore"):
        inverse_distance = np.where(between, 1.0 / s + 1.0 / (length - s), 0.0)
    terms = ApertureTerms(
        row=legs.row[leg], obstacle=k, inverse_distance=inverse_distance,
        x_centre=np.einsum("ij,ij->i", offset, p), w_centre=np.einsum("ij,ij->i", offset, w),
        half_length=np.where(sphere, 0.0, half * axis_perp), radius=radius,
        cap=np.where(sphere, radius, radius * np.abs(cos_axis)), infinite=infinite)
    sigma = fresnel_scale(terms.inverse_distance, centre_frequency_hz, sound_speed_m_s)
    near = between & (sigma * terms.nearest_m() < FRESNEL_REACH)
    return terms.select(np.flatnonzero(near))


def blocked_integral(terms: ApertureTerms, frequency_hz: NDArray[np.float64],
                     sound_speed_m_s: float) -> NDArray[np.complex128]:
    """The silhouette's integral (1 / 2i) Int exp(i pi |v|^2 / 2) d^2 v of each term at each
    frequency, shape (t, n) (physics convention; H = 1 - this).

    A strip is (2); a finite silhouette is the rectangle |x - x_c| <= h, |w - w_c| <= a (a
    product of Fresnel integrals) plus its two cap segments beyond |x - x_c| = h
    (:func:`cap_integral`, only where the caps have a width).
    """
    f = np.atleast_1d(np.asarray(frequency_hz, dtype=float))
    sigma = fresnel_scale(terms.inverse_distance[:, None], f[None, :], sound_speed_m_s)  # (t, n)
    w, a = terms.w_centre[:, None], terms.radius[:, None]
    across = fresnel_integral(sigma * (w + a)) - fresnel_integral(sigma * (w - a))
    x, h = terms.x_centre[:, None], terms.half_length[:, None]
    along = np.where(terms.infinite[:, None], 1.0 + 1.0j,
                     fresnel_integral(sigma * (x + h)) - fresnel_integral(sigma * (x - h)))
    out = along * across / 2j
    caps = np.flatnonzero(~terms.infinite & (terms.cap > 0.0))
    if caps.size:
        out[caps] += cap_integral(terms.select(caps), sigma[caps])
    return out


class ContourNodes(NamedTuple):
    """Quadrature nodes on the boundaries of regions of the aperture plane, shape (q,) each:
    ``term`` the region (term) each belongs to (non-decreasing), ``rho2`` the squared distance
    from the leg (m^2) and ``weight`` (x w' - w x') ds (m^2), so that Int_region
    exp(i pi sigma^2 |x|^2 / 2) d^2 x = sum over its nodes of weight (exp(i pi sigma^2 rho2 / 2)
    - 1) / (i pi sigma^2 rho2) (the contour form, :func:`cap_contours`)."""

    term: NDArray[np.int64]
    rho2: NDArray[np.float64]
    weight: NDArray[np.float64]


SAMPLES = 257
"""Points per boundary piece at which the phase's variation is sampled to place the panels."""


def cap_pieces(terms: ApertureTerms, u: NDArray[np.float64], shared: bool) -> tuple[NDArray[np.float64], ...]:
    """The four boundary pieces of each term's two caps, counter-clockwise in (x, w): x, w,
    dx/du, dw/du (m) at parameters ``u`` in [0, 1] (pieces: the arc beyond x_c + h, its chord
    x = x_c + h downwards, the arc beyond x_c - h, its chord upwards).

    ``shared``: ``u`` (k,) for every term, results (t, 4, k); else one ``u`` per term (t,),
    results (t, 4).
    """
    shape = (-1, 1, 1) if shared else (-1, 1)
    x_c, w_c, h, a, cap = (v.reshape(shape) for v in
                           (terms.x_centre, terms.w_centre, terms.half_length, terms.radius, terms.cap))
    pieces = (1, 4, 1) if shared else (1, 4)
    side = np.array([1.0, 1.0, -1.0, -1.0]).reshape(pieces)
    arc = np.array([True, False, True, False]).reshape(pieces)
    u = u.reshape((1, 1, -1) if shared else (-1, 1))
    phi = np.pi * (u - 0.5)
    x = np.where(arc, x_c + side * (h + cap * np.cos(phi)), x_c + side * h)
    w = np.where(arc, w_c + side * a * np.sin(phi), w_c + side * a * (1.0 - 2.0 * u))
    dx = np.where(arc, -side * np.pi * cap * np.sin(phi), 0.0)
    dw = np.where(arc, side * np.pi * a * np.cos(phi), -2.0 * side * a)
    return x, w, dx, dw


def cap_contours(terms: ApertureTerms, sigma_max: NDArray[np.float64]) -> ContourNodes:
    """The boundary nodes of the two cap segments of every finite silhouette of ``terms`` (each
    cap's elliptical arc and the straight chord it shares with the rectangle), Gauss-Legendre
    (:data:`GAUSS_NODES` per panel) on panels over which the phase pi sigma_max^2 rho^2 / 2 of
    the term turns by at most :data:`PANEL_PHASE_RAD` (panel ends at equal steps of the
    phase's variation, sampled on :data:`SAMPLES` points per piece).

    By Green's theorem in polar coordinates about the leg, Int_R g(|x|) d^2 x =
    oint (Int_0^rho g(r) r dr) dtheta, and Int_0^rho exp(i pi sigma^2 r^2 / 2) r dr =
    (exp(i pi sigma^2 rho^2 / 2) - 1) / (i pi sigma^2); dtheta = (x dw - w dx) / rho^2.
    """
    t = terms.row.size
    u = np.linspace(0.0, 1.0, SAMPLES)
    x, w, _, _ = cap_pieces(terms, u, shared=True)  # (t, 4, SAMPLES)
    phase = 0.5 * np.pi * sigma_max[:, None, None] ** 2 * (x * x + w * w)
    variation = np.concatenate([np.zeros((t, 4, 1)), np.cumsum(np.abs(np.diff(phase, axis=2)), axis=2)], axis=2)
    total = variation[:, :, -1].reshape(-1)  # per piece
    panels = np.ceil(total / PANEL_PHASE_RAD).astype(np.int64) + 1
    # panel ends: equal steps of each piece's variation, by one interpolation over all pieces
    # laid end to end (each piece's variation offset past the previous ones')
    offset = np.cumsum(np.r_[0.0, total[:-1] + 1.0])
    piece_of_bound = np.repeat(np.arange(total.size), panels + 1)
    step_index = np.arange(piece_of_bound.size) - np.repeat(np.cumsum(panels + 1) - (panels + 1), panels + 1)
    target = offset[piece_of_bound] + total[piece_of_bound] * step_index / panels[piece_of_bound]
    flat_variation = (variation.reshape(total.size, SAMPLES) + offset[:, None]).reshape(-1)
    flat_u = np.tile(u, total.size)
    bounds = np.interp(target, flat_variation, flat_u)
    flat = total[piece_of_bound] < PANEL_PHASE_RAD * 1e-6  # (nearly) no variation: equal steps of u
    bounds[flat] = (step_index / panels[piece_of_bound])[flat]
    # each piece from exactly 0 to exactly 1 (the offsets may absorb a flat end's last increments)
    bounds[step_index == 0] = 0.0
    bounds[step_index == panels[piece_of_bound]] = 1.0
    # Gauss nodes of every panel (a panel: bounds j, j + 1 of one piece)
    last = np.cumsum(panels + 1) - 1
    starts = np.setdiff1d(np.arange(bounds.size), last)
    lo, hi = bounds[starts], bounds[starts + 1]
    nodes, weights = np.polynomial.legendre.leggauss(GAUSS_NODES)
    half = 0.5 * (hi - lo)
    at = (0.5 * (lo + hi))[:, None] + half[:, None] * nodes[None, :]  # (panels, g)
    piece = np.repeat(piece_of_bound[starts], GAUSS_NODES)
    term = piece // 4
    x, w, dx, dw = cap_pieces(terms.select(term), at.reshape(-1), shared=False)  # (q, 4)
    which = piece % 4
    pick = np.arange(which.size)
    x, w, dx, dw = x[pick, which], w[pick, which], dx[pick, which], dw[pick, which]
    return ContourNodes(term, x * x + w * w, (x * dw - w * dx) * (half[:, None] * weights[None, :]).reshape(-1))


def cap_integral(terms: ApertureTerms, sigma: NDArray[np.float64]) -> NDArray[np.complex128]:
    """(1) over the cap segments of finite silhouettes (t terms, sigma (t, n)) by the contour
    form (:func:`cap_contours`), the nodes placed for the largest sigma of each term."""
    nodes = cap_contours(terms, np.max(sigma, axis=1))
    # (1 / 2i) sum weight (exp(i phi) - 1) / (i pi rho2), phi = pi sigma^2 rho2 / 2, in real
    # arithmetic: exp(i phi) - 1 = -2 sin^2(phi / 2) + i sin(phi), exact as rho2 -> 0
    per_node = nodes.weight / (np.pi * np.maximum(nodes.rho2, TINY_RHO2))
    half_phase = 0.25 * np.pi * sigma[nodes.term] ** 2 * nodes.rho2[:, None]  # (q, n)
    sine = np.sin(half_phase)
    value = (sine * sine - 0.5j * np.sin(2.0 * half_phase)) * per_node[:, None]
    first = np.searchsorted(nodes.term, np.arange(terms.row.size))
    return np.add.reduceat(value, first, axis=0)


def shadow_factor(terms: ApertureTerms, frequency_hz: NDArray[np.float64],
                  sound_speed_m_s: float) -> NDArray[np.complex128]:
    """H = prod over ``terms`` of (1 - their silhouette's integral), shape (n,) (physics
    convention): the factor of one row whose terms these are."""
    return np.prod(1.0 - blocked_integral(terms, frequency_hz, sound_speed_m_s), axis=0)


@dataclass(frozen=True, eq=False)
class ShadowResponse:
    """The shadow factor of one row, an :class:`~acoustisim.propagation.responses.EchoResponse`.

    Attributes
    ----------
    label : str
        The obstacles and the factor at the centre frequency.
    span_s : tuple of 2 float
        (0, the latest edge wave's delay + :data:`TAIL_S`) (s).
    terms : ApertureTerms
        The solve's (leg, obstacle) terms, grouped by row (shared by its responses).
    first, stop : int
        This row's terms: ``terms`` rows ``first:stop``.
    scale : float
        |H(f0)|, already in the row's gain: :meth:`transfer` divides by it.
    """

    label: str
    span_s: tuple[float, float]
    terms: ApertureTerms = field(repr=False)
    first: int
    stop: int
    scale: float

    @property
    def own_terms(self) -> ApertureTerms:
        """This row's terms."""
        return self.terms.select(slice(self.first, self.stop))

    def transfer(self, frequency_hz: NDArray[np.float64], sound_speed_m_s: float) -> NDArray[np.complex128]:
        """H(f) / |H(f0)| in the engineering convention (complex conjugate of (1)), shape (n,)."""
        return np.conj(shadow_factor(self.own_terms, frequency_hz, sound_speed_m_s)) / self.scale


def shadow_rows(rows: NDArray[Any], context: SolveContext, obstacles: SmoothObstacles,
                first_response_id: int = 0) -> tuple[NDArray[Any], tuple[ShadowResponse, ...]]:
    """The direct and specular ``rows`` (PATH_DTYPE, geometric columns) with the shadows of
    ``obstacles`` (see the module's Method), and their responses.

    Returns
    -------
    rows : structured ndarray of PATH_DTYPE
        A copy of ``rows``; each shadowed row's ``geometric_gain`` multiplied by |H(f0)| and its
        ``response_id`` set, numbered from ``first_response_id`` in row order.
    responses : tuple of ShadowResponse
    """
    if obstacles.count == 0 or rows.size == 0:
        return rows, ()
    f0, c = context.centre_frequency_hz, context.sound_speed_m_s
    legs = row_legs(rows, context)
    if legs.row.size == 0:
        return rows, ()
    terms = aperture_terms(legs, obstacles, f0, c)
    if terms.row.size == 0:
        return rows, ()
    order = np.argsort(terms.row, kind="stable")
    terms = terms.select(order)  # grouped by row, each row's terms a slice
    at_f0 = 1.0 - blocked_integral(terms, np.array([f0]), c)[:, 0]
    shadowed, first = np.unique(terms.row, return_index=True)
    bounds = np.r_[first, terms.row.size]
    factor = np.multiply.reduceat(at_f0, first)
    scale = np.maximum(np.abs(factor), MIN_SCALE)
    out = rows.copy()
    out["geometric_gain"][shadowed] *= scale
    out["response_id"][shadowed] = first_response_id + np.arange(shadowed.size)
    latest = np.maximum.reduceat(terms.farthest_m() ** 2 * terms.inverse_distance / (2.0 * c), first) + TAIL_S
    names = context.scene.surface_names
    obstacle_names = [names[s] for s in obstacles.surface[terms.obstacle]]
    levels = 20.0 * np.log10(scale)
    responses = []
    for j in range(shadowed.size):  # a loop over the shadowed rows (hundreds), sharing the terms
        lo, hi = int(bounds[j]), int(bounds[j + 1])
        label = (f"shadow of {', '.join(dict.fromkeys(obstacle_names[lo:hi]))} (Kirchhoff-Fresnel), "
                 f"{levels[j]:+.1f} dB at {f0 / 1e3:g} kHz")
        responses.append(ShadowResponse(label, (0.0, float(latest[j])), terms, lo, hi, float(scale[j])))
    return out, tuple(responses)


__all__ = ("ApertureTerms", "ContourNodes", "FRESNEL_REACH", "GAUSS_NODES", "Legs", "MIN_SCALE", "PANEL_PHASE_RAD",
           "SAMPLES", "ShadowResponse", "TAIL_S", "TINY_RHO2", "aperture_terms", "blocked_integral", "cap_contours",
           "cap_integral", "cap_pieces", "fresnel_integral", "fresnel_scale", "perpendicular_unit", "row_legs",
           "shadow_factor", "shadow_rows")
