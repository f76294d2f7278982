"""Echo transfer functions of posts and spheres for the simulator, relative to today's echo.

Today the simulator gives an object's bistatic echo as one geometric-optics row: the
specular-point amplitude g = R(cos theta_i) G at the delay L / c, G = cos theta_i /
(r1 r2 sqrt|det H|) (``acoustisim.propagation.curved.go_amplitude``; physics.md section 3) and R
the material's plane-wave coefficient at the specular point. This module gives, per row and
frequency bin, the factor H(f) that turns that row into the exact echo of the elastic body:
the synthesiser's row spectrum multiplied by H(f) is the exact echo (specular part, internal
arrivals and creeping waves; H's impulse response starts at the specular delay).

Physics (time dependence exp(-i w t) in the derivation)
-------------------------------------------------------
Sphere (exact): a point source of unit pressure at 1 m, at distance r_s from the centre, and a
receiver at r_r, seen from the centre at the angle beta apart (the bistatic angle; 0 is
monostatic), give the scattered pressure (addition theorem of e^{ikR}/R)

    p = i k sum_n (2n + 1) A_n h_n(k r_s) h_n(k r_r) P_n(cos beta).

Post (finite vertical cylinder, both ends far outside the first Fresnel zone; physics.md
section 8): with e^{ikR}/R = (i/2) int dk_z e^{i k_z dz} H_0(kappa d), each axial wavenumber
scatters as the 2-D problem; the integral over k_z by stationary phase gives

    p = (i/2) sqrt(2 pi k / L) cos(e) e^{-i pi/4} e^{i k sin(e) dz}
        sum_n eps_n A_n(kappa a) H_n(kappa rho_s) H_n(kappa rho_r) cos(n beta),

rho_s, rho_r the distances of source and receiver from the axis, dz their offset along it,
kappa = k cos(e), tan(e) = dz / L_h, L_h the specular path's length projected on the plane normal
to the axis and L = sqrt(L_h^2 + dz^2) the specular path length: the stationary-phase length is
that of the specular ray (the phase of the sum at the specular point varies as kappa L_h), so the
rigid limit tends to geometric optics at high ka (the axial spreading of the specular echo is
exact; internal arrivals, whose axial curvature differs, are off by sqrt(L / L_eff), L_eff
adding d c_L / c for d travelled in the solid: 0.2 dB for the PVC post's +42 us echo at 1 m).
The 2-D coefficients are those of normal incidence (the tank's direct post echoes have
|e| < 1 deg; rows via the floor or surface, |e| up to ~30 deg, take kappa = k cos e but neglect
the elastic coupling of oblique incidence, an approximation of order e^2 for those rows).

Transfer function: H_phys(f) = p(f) e^{-i k L} / (R G), and the returned engineering-convention
factor (exp(+j 2 pi f t), the synthesiser's: rows multiply exp(-j 2 pi f tau)) is its conjugate,
H(f) = conj(H_phys(f)), so that the impulse response of H is real and causal about the
specular delay.

Method
------
The coefficients once per body and band (:mod:`.modal`), the Hankel functions of every row, bin
and order in one ``scipy.special`` call each, the sums as batched products. The specular point
(Alhazen's problem on the circle in the plane of the axis-normal or of the centre, source and
receiver) by Newton's method from the bisector, in this module (checked against the
simulator's own in ``tests/physics/test_elastic_echo.py``).

Accuracy
--------
Rigid body: H -> 1 up to the creeping waves (58-63 dB down) and the 1/(ka) corrections of the
stationary phase (0.02 dB at the tank's 500 kHz, ka = 53 for a 25 mm post). Series truncation
and rounding: below 1e-10.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import special

from acoustisim.errors import InputError
from acoustisim.materials import Material
from acoustisim.scattering.bodies import Body, Fluid, body_from_material, pipe_fill
from acoustisim.scattering.modal import modal_coefficients
from acoustisim.scattering.series import DEFAULT_EXTRA_ORDERS, ModalCoefficients
from acoustisim.scattering.special import bessel_table

if TYPE_CHECKING:
    from acoustisim.scene import SceneObject

__all__ = ("EchoGeometry", "EchoTarget", "SpecularPoint", "echo_target_for", "echo_transfer", "exact_echo",
           "object_body", "specular_point")

TargetShape = Literal["post", "sphere"]

_NEWTON_STEPS = 30


@dataclass(frozen=True)
class EchoGeometry:
    """Where the (image) transmitter and the receiver of each echo row are, relative to the object.

    Attributes (arrays of shape (n_rows,))
    --------------------------------------
    source_distance_m, receiver_distance_m : ndarray
        Distances (m) from the post's axis (post) or the sphere's centre (sphere).
    bistatic_angle_rad : ndarray
        Angle at the axis (in the plane normal to it) or the centre between the directions to
        source and receiver; 0 is monostatic.
    axial_offset_m : ndarray
        Receiver minus source along the post's axis (m); 0 for spheres.
    """

    source_distance_m: NDArray[np.float64]
    receiver_distance_m: NDArray[np.float64]
    bistatic_angle_rad: NDArray[np.float64]
    axial_offset_m: NDArray[np.float64]

    @classmethod
    def from_points(cls, source_m: ArrayLike, receiver_m: ArrayLike, centre_m: ArrayLike,
                    axis: ArrayLike | None = None) -> "EchoGeometry":
        """The geometry of rows given by points.

        Parameters
        ----------
        source_m, receiver_m : array_like, shape (n_rows, 3)
            (Image) transmitter and (image) receiver (m), tank frame.
        centre_m : array_like, shape (3,) or (n_rows, 3)
            A point on the post's axis, or the sphere's centre (m).
        axis : array_like, shape (3,), optional
            The post's axis direction (None for a sphere).
        """
        src = np.atleast_2d(np.asarray(source_m, dtype=float))
        rcv = np.atleast_2d(np.asarray(receiver_m, dtype=float))
        centre = np.broadcast_to(np.asarray(centre_m, dtype=float), src.shape)
        ds, dr = src - centre, rcv - centre
        if axis is None:
            offset = np.zeros(len(src))
        else:
            e = np.asarray(axis, dtype=float)
            e = e / np.linalg.norm(e)
            zs, zr = ds @ e, dr @ e
            ds, dr = ds - np.outer(zs, e), dr - np.outer(zr, e)
            offset = zr - zs
        rho_s, rho_r = np.linalg.norm(ds, axis=1), np.linalg.norm(dr, axis=1)
        cos_beta = np.clip(np.einsum("ij,ij->i", ds, dr) / (rho_s * rho_r), -1.0, 1.0)
        return cls(rho_s, rho_r, np.arccos(cos_beta), offset)

    @property
    def n_rows(self) -> int:
        """Number of rows."""
        return int(np.size(self.source_distance_m))


@dataclass(frozen=True)
class EchoTarget:
    """An object whose echo is replaced by the exact one.

    Attributes
    ----------
    shape : {"post", "sphere"}
    radius_m : float
    body : Body
        What it is made of (:func:`acoustisim.scattering.bodies.body_from_material`).
    material : Material
        The material today's echo used (its plane-wave R at the specular point is divided out).
    """

    shape: TargetShape
    radius_m: float
    body: Body
    material: Material

    def __post_init__(self) -> None:
        if self.shape not in ("post", "sphere"):
            raise InputError(f"echo target shape = {self.shape!r}: expected 'post' or 'sphere'")
        if not self.radius_m > 0.0:
            raise InputError(f"echo target radius_m = {self.radius_m!r}: must be > 0")


def object_body(obj: "SceneObject", water: Fluid) -> Body:
    """What a scene object is made of: its material's body, or, for a pipe (a ``cylinder`` whose
    scene-file table gives ``wall_thickness_m`` and ``fill``), a :class:`Shell` of that wall
    around :func:`~acoustisim.scattering.bodies.pipe_fill` (rigid and pressure-release
    materials stay those limits).

    Raises
    ------
    InputError
        A pipe whose material is not a solid, or an unknown fill.
    """
    wall = obj.parameter("wall_thickness_m")
    fill = obj.parameter("fill")
    if wall is None or fill is None or obj.material.model in ("rigid", "pressure-release"):
        return body_from_material(obj.material)
    return body_from_material(obj.material, wall_thickness_m=float(wall), fill=pipe_fill(str(fill), water))


def echo_target_for(obj: "SceneObject", body: Body | None = None, water: Fluid | None = None
                    ) -> tuple[EchoTarget, NDArray[np.float64], NDArray[np.float64] | None] | None:
    """The exact-echo description of a scene object, with its centre and axis for
    :meth:`EchoGeometry.from_points`, or None when no series describes it.

    Posts and cylinders (a finite cylinder: the axial stationary phase needs its ends outside
    the first Fresnel zone) become "post" targets, spheres "sphere" targets; their body is
    ``body`` if given, else :func:`object_body` (a pipe's :class:`Shell` from its scene-file
    ``wall_thickness_m`` and ``fill``, which needs ``water``), else the material's.

    Returns
    -------
    (EchoTarget, centre (3,), axis (3,) or None) or None
    """
    primitive = obj.primitive
    if primitive is None or obj.kind not in ("post", "cylinder", "sphere"):
        return None
    if body is not None:
        chosen = body
    elif water is not None:
        chosen = object_body(obj, water)
    else:
        chosen = body_from_material(obj.material)
    if obj.kind == "sphere":
        return (EchoTarget("sphere", float(primitive.radius_m), chosen, obj.material),
                np.asarray(primitive.center_m, dtype=float), None)
    return (EchoTarget("post", float(primitive.radius_m), chosen, obj.material),
            np.asarray(primitive.center_m, dtype=float), np.asarray(primitive.axis, dtype=float))


@dataclass(frozen=True)
class SpecularPoint:
    """Today's geometric-optics echo of each row (arrays (n_rows,)).

    Attributes
    ----------
    path_length_m : ndarray
        L = r1 + r2 (m).
    planar_length_m : ndarray
        L_h: L projected on the plane normal to the post's axis (= L for a sphere).
    cos_incidence : ndarray
        cos theta_i at the specular point.
    spreading : ndarray
        G = cos theta_i / (r1 r2 sqrt|det H|) (1/m).
    """

    path_length_m: NDArray[np.float64]
    planar_length_m: NDArray[np.float64]
    cos_incidence: NDArray[np.float64]
    spreading: NDArray[np.float64]


def specular_point(shape: TargetShape, radius_m: float, geometry: EchoGeometry) -> SpecularPoint:
    """The specular reflection of each row on the post's side or the sphere (geometric optics).

    In the plane (normal to the axis, or through centre, source and receiver) the source is at
    (rho_s, 0) and the receiver at rho_r (cos beta, sin beta); the specular point a (cos t,
    sin t) makes d/dt (|S - P| + |P - R|) = 0, found by Newton's method from t = beta / 2.
    """
    a = float(radius_m)
    rho_s, rho_r = geometry.source_distance_m, geometry.receiver_distance_m
    beta, dz = geometry.bistatic_angle_rad, geometry.axial_offset_m
    if np.any(rho_s <= a) or np.any(rho_r <= a):
        raise InputError("echo geometry: source and receiver must lie outside the object")
    t = 0.5 * beta
    for _ in range(_NEWTON_STEPS):
        # f(t) = d/dt |S - P| + d/dt |P - R| with S = (rho_s, 0), R = rho_r (cos b, sin b)
        d1 = np.sqrt(rho_s**2 + a * a - 2.0 * a * rho_s * np.cos(t))
        d2 = np.sqrt(rho_r**2 + a * a - 2.0 * a * rho_r * np.cos(beta - t))
        g1, g2 = a * rho_s * np.sin(t) / d1, -a * rho_r * np.sin(beta - t) / d2
        h1 = a * rho_s * np.cos(t) / d1 - g1 * g1 / d1
        h2 = a * rho_r * np.cos(beta - t) / d2 - g2 * g2 / d2
        step = (g1 + g2) / (h1 + h2)
        t = t - step
        if np.all(np.abs(step) < 1e-14):
            break
    d1 = np.sqrt(rho_s**2 + a * a - 2.0 * a * rho_s * np.cos(t))
    d2 = np.sqrt(rho_r**2 + a * a - 2.0 * a * rho_r * np.cos(beta - t))
    planar = d1 + d2
    # cos theta_i: outward normal (cos t, sin t) against the unit vector from P to S
    cos_i = (rho_s * np.cos(t) - a) / d1
    # in-plane tangent components of the unit vectors S -> P and R -> P: a_1 = e1 . s1 etc.
    a1 = rho_s * np.sin(t) / d1  # e1 = (-sin t, cos t) against s1 = (P - S) / d1
    b1 = -rho_r * np.sin(beta - t) / d2
    length = np.hypot(planar, dz)
    if shape == "post":
        scale = length / planar  # r_j = d_j L / L_h, the vertical components +-dz / L
        r1, r2 = d1 * scale, d2 * scale
        a1, b1 = a1 / scale, b1 / scale
        cos_i3 = cos_i / scale
        a2, b2 = dz / length, -dz / length
        h11 = (1 - a1**2) / r1 + (1 - b1**2) / r2 + 2.0 * cos_i3 / a
        h22 = (1 - a2**2) / r1 + (1 - b2**2) / r2
        h12 = -a1 * a2 / r1 - b1 * b2 / r2
        spreading = cos_i3 / (r1 * r2 * np.sqrt(np.abs(h11 * h22 - h12**2)))
        return SpecularPoint(length, planar, cos_i3, spreading)
    h11 = (1 - a1**2) / d1 + (1 - b1**2) / d2 + 2.0 * cos_i / a
    h22 = 1.0 / d1 + 1.0 / d2 + 2.0 * cos_i / a
    spreading = cos_i / (d1 * d2 * np.sqrt(h11 * h22))
    return SpecularPoint(planar, planar, cos_i, spreading)


def _hankel_products(shape: TargetShape, coefficients: ModalCoefficients, kappa: NDArray[np.float64],
                     geometry: EchoGeometry) -> NDArray[np.complex128]:
    """sum_n w_n A_n Z_n(kappa rho_s) Z_n(kappa rho_r) X_n(beta), (n_rows, n_bins)."""
    n = coefficients.orders.astype(float)
    keep = coefficients.coefficients != 0.0
    top = int(coefficients.orders[-1])
    spherical = shape == "sphere"
    shape_rfn = (geometry.n_rows, kappa.size, top + 1)
    h_s = bessel_table("H", top, np.multiply.outer(geometry.source_distance_m, kappa).ravel(),
                       spherical=spherical).reshape(shape_rfn)
    h_r = bessel_table("H", top, np.multiply.outer(geometry.receiver_distance_m, kappa).ravel(),
                       spherical=spherical).reshape(shape_rfn)
    if spherical:
        angular = special.eval_legendre(n[None, :], np.cos(geometry.bistatic_angle_rad)[:, None])
        weights = 2.0 * n + 1.0
    else:
        angular = np.cos(np.multiply.outer(geometry.bistatic_angle_rad, n))
        weights = np.where(n == 0.0, 1.0, 2.0)
    with np.errstate(over="ignore", invalid="ignore"):  # orders beyond a bin's truncation are masked out
        terms = np.where(keep[None], coefficients.coefficients[None] * h_s * h_r, 0.0)
    return np.einsum("rfn,rn->rf", terms, weights[None, :] * angular)


def exact_echo(target: EchoTarget, geometry: EchoGeometry, water: Fluid, frequencies_hz: ArrayLike,
               extra_orders: int = DEFAULT_EXTRA_ORDERS) -> NDArray[np.complex128]:
    """The exact scattered pressure of each row per unit source pressure at 1 m, physics
    convention (exp(-i w t)), including the propagation phase e^{i k L}: (n_rows, n_bins)."""
    f = np.atleast_1d(np.asarray(frequencies_hz, dtype=float))
    k = np.real(water.wavenumber(2.0 * np.pi * f))
    if target.shape == "sphere":
        coefficients = modal_coefficients("sphere", target.body, target.radius_m, f, water, extra_orders)
        return 1j * k[None, :] * _hankel_products("sphere", coefficients, k, geometry)
    specular = specular_point("post", target.radius_m, geometry)
    length, planar = specular.path_length_m, specular.planar_length_m
    cos_e = planar / length
    sin_e = geometry.axial_offset_m / length
    exact = np.empty((geometry.n_rows, f.size), dtype=complex)
    # rows of one elevation share kappa; the tank's rows come in a few distinct elevations
    elevations, which = np.unique(np.round(cos_e, 12), return_inverse=True)
    for index, cos_value in enumerate(elevations):
        rows = np.flatnonzero(which == index)
        kappa = k * cos_value
        # normal-incidence coefficients at the frequency f cos(e) (module docstring)
        coefficients = modal_coefficients("cylinder", target.body, target.radius_m, f * cos_value, water,
                                          extra_orders)
        sub = EchoGeometry(geometry.source_distance_m[rows], geometry.receiver_distance_m[rows],
                           geometry.bistatic_angle_rad[rows], geometry.axial_offset_m[rows])
        series = _hankel_products("post", coefficients, kappa, sub)
        phase = np.exp(1j * np.multiply.outer(sin_e[rows] * geometry.axial_offset_m[rows], k))
        factor = 0.5j * np.sqrt(2.0 * np.pi * k[None, :] / length[rows, None]) * cos_e[rows, None]
        exact[rows] = factor * np.exp(-0.25j * np.pi) * phase * series
    return exact


def echo_transfer(target: EchoTarget, geometry: EchoGeometry, water: Fluid, frequencies_hz: ArrayLike,
                  extra_orders: int = DEFAULT_EXTRA_ORDERS) -> NDArray[np.complex128]:
    """H(f) per row and bin: the exact echo over today's geometric-optics row.

    Parameters
    ----------
    target : EchoTarget
    geometry : EchoGeometry
        n_rows rows (one per echo path and receiver).
    water : Fluid
        The host water (its density and sound speed; loss 0: absorption is applied per path).
    frequencies_hz : array_like, shape (n_bins,)
    extra_orders : int

    Returns
    -------
    ndarray of complex, shape (n_rows, n_bins)
        Engineering convention (module docstring): multiply each row's spectrum (which already
        carries R G and exp(-j 2 pi f L / c)) by it.

    Raises
    ------
    InputError
        Today's row has no amplitude (R = 0: a material matching the water).
    """
    f = np.atleast_1d(np.asarray(frequencies_hz, dtype=float))
    k = np.real(water.wavenumber(2.0 * np.pi * f))
    specular = specular_point(target.shape, target.radius_m, geometry)
    today = target.material.reflection_coefficient(specular.cos_incidence, water.density_kg_m3,
                                                   water.sound_speed_m_s) * specular.spreading
    if np.any(np.abs(today) == 0.0):
        raise InputError(f"material {target.material.name!r}: today's echo is zero (R = 0); no transfer function")
    exact = exact_echo(target, geometry, water, f, extra_orders)
    ratio = exact * np.exp(-1j * np.multiply.outer(specular.path_length_m, k)) / today[:, None]
    return np.conj(ratio)
