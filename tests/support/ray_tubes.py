"""Geometric-optics amplitude by brute force: a bundle of rays traced through exact surfaces.

An independent evaluation of the ray-tube amplitude (no curvature matrices, no Hessians): rays
leave a point source with directions perturbed by small angles, reflect by the law of
reflection off exact spheres, infinite cylinders and planes (analytic intersections), and land
on the plane through the receiver normal to the arriving ray. Energy is conserved in the tube,
so the pressure factor (re the source at 1 m) is sqrt(d Omega / dA) = 1 / sqrt|det J|, J the
Jacobian of the landing point with respect to the two departure angles.

J is taken by the complex-step derivative (Squire & Trapp, SIAM Rev. 40, 110, 1998):
every operation of the tracer is analytic (no absolute values or conjugates: |v| is
sqrt(v . v)), so with an imaginary angle i h, Im(landing point) / h is the derivative with no
subtraction, exact to round-off whatever h (1e-20) and however anisotropic the tube (a thin
cylinder can make it 1e6 times wider one way than the other, where central differences lose
every digit). Such a tube also magnifies the last digit of a departure direction: a float64
direction lands up to ~1e-8 m from the receiver, where the amplitude already differs by
~1e-8 m / (the wavefront's smallest radius, ~1 cm). So the tracer runs in extended precision
(``numpy.longdouble``, 64-bit mantissa where the platform has it) and first aims the central
ray at the receiver by Newton's method on the departure angles.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

COMPLEX_STEP_RAD = 1e-30
"""The imaginary departure-angle step (rad): anything far below round-off of the angle."""

AIMING_STEPS = 4
"""Newton steps aiming the central ray at the receiver (each squares the miss)."""


def _norm(v: NDArray) -> NDArray:
    """sqrt(v . v), analytic in complex v (not |v|)."""
    return np.sqrt(v @ v)


@dataclass(frozen=True)
class Plane:
    point: NDArray[np.float64]
    normal: NDArray[np.float64]

    def hit(self, origin: NDArray, direction: NDArray) -> NDArray:
        return (self.point - origin) @ self.normal / (direction @ self.normal)

    def normal_at(self, x: NDArray) -> NDArray:
        return self.normal


@dataclass(frozen=True)
class Sphere:
    centre: NDArray[np.float64]
    radius: float

    def hit(self, origin: NDArray, direction: NDArray) -> NDArray:
        w = origin - self.centre
        b = w @ direction
        return -b - np.sqrt(b * b - (w @ w - self.radius ** 2))  # the near root: outside, convex

    def normal_at(self, x: NDArray) -> NDArray:
        return (x - self.centre) / _norm(x - self.centre)


@dataclass(frozen=True)
class Cylinder:
    centre: NDArray[np.float64]
    axis: NDArray[np.float64]
    radius: float

    def _across(self, v: NDArray) -> NDArray:
        return v - (v @ self.axis) * self.axis

    def hit(self, origin: NDArray, direction: NDArray) -> NDArray:
        w, d = self._across(origin - self.centre), self._across(direction)
        a, b, c = d @ d, w @ d, w @ w - self.radius ** 2
        return (-b - np.sqrt(b * b - a * c)) / a

    def normal_at(self, x: NDArray) -> NDArray:
        radial = self._across(x - self.centre)
        return radial / _norm(radial)


def _perpendicular_pair(d: NDArray) -> tuple[NDArray, NDArray]:
    helper = np.array([1.0, 0.0, 0.0]) if abs(d[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    u = np.cross(d, helper.astype(d.dtype))
    u /= np.sqrt(u @ u)
    return u, np.cross(d, u)


def trace(source: NDArray, direction: NDArray, surfaces) -> tuple[NDArray, NDArray]:
    """The last reflection point and the direction leaving it, of a ray from ``source`` (real or
    complex arithmetic)."""
    origin, d = np.asarray(source), direction / _norm(direction)
    for surface in surfaces:
        origin = origin + surface.hit(origin, d) * d
        n = surface.normal_at(origin)
        d = d - 2.0 * (d @ n) * n
    return origin, d


class RayTube(NamedTuple):
    """A traced ray tube: the pressure factor 1 / sqrt|det J| of the ray aimed at the receiver,
    how far (m) the ray leaving along the given departure direction passes from the receiver
    (0 up to round-off if it is the specular path's), and the Jacobian J (2, 2) (m/rad) of the
    landing point (its singular values: the tube's widths)."""

    pressure: float
    miss_m: float
    jacobian: NDArray[np.float64]


def ray_tube_pressure(source: NDArray[np.float64], departure: NDArray[np.float64], surfaces,
                      receiver: NDArray[np.float64]) -> RayTube:
    """The ray tube leaving ``source`` near ``departure`` through ``surfaces`` (in order), at
    the plane through ``receiver`` normal to its arrival."""
    real, cplx = np.longdouble, np.clongdouble
    source, receiver = np.asarray(source, dtype=real), np.asarray(receiver, dtype=real)
    d0 = np.asarray(departure, dtype=real)
    d0 = d0 / np.sqrt(d0 @ d0)
    u, v = _perpendicular_pair(d0)
    _, arrival = trace(source, d0, surfaces)
    p, q = _perpendicular_pair(arrival)
    target = np.array([receiver @ p, receiver @ q])

    def land(alpha, beta) -> NDArray:
        origin, d = trace(source.astype(cplx), d0 + alpha * u + beta * v, surfaces)
        y = origin + ((receiver - origin) @ arrival) / (d @ arrival) * d
        return np.array([y @ p, y @ q])

    def jacobian(alpha: real, beta: real) -> NDArray:
        h = real(COMPLEX_STEP_RAD)
        return np.column_stack([land(alpha + 1j * h, beta).imag / h, land(alpha, beta + 1j * h).imag / h])

    miss = float(np.hypot(*(land(real(0), real(0)).real - target)))
    alpha, beta = real(0), real(0)
    for _ in range(AIMING_STEPS):
        j = jacobian(alpha, beta)
        r0, r1 = land(alpha, beta).real - target
        det = j[0, 0] * j[1, 1] - j[0, 1] * j[1, 0]
        alpha, beta = alpha - (j[1, 1] * r0 - j[0, 1] * r1) / det, beta - (j[0, 0] * r1 - j[1, 0] * r0) / det
    j = jacobian(alpha, beta)
    det = j[0, 0] * j[1, 1] - j[0, 1] * j[1, 0]
    return RayTube(float(1 / np.sqrt(abs(det))), miss, j.astype(float))


__all__ = ("AIMING_STEPS", "COMPLEX_STEP_RAD", "Cylinder", "Plane", "RayTube", "Sphere", "ray_tube_pressure", "trace")
