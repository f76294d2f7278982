"""The named internal arrivals of an elastic echo: ground truth a truth table can hold.

Physics (monostatic backscatter of a plane wave; delays after the specular echo)
--------------------------------------------------------------------------------
Internal rays (cylinder, and sphere in its meridian plane): a ray at impact parameter b enters
at incidence theta_i (sin theta_i = b / a), travels chords of 2 a cos(theta_j) in the modes
M_j (compressional L or shear T, Snell: sin(theta_j) / c_j = sin(theta_i) / c_w), converting
mode at each internal reflection, and leaves; it is a backscatter arrival where it leaves
exactly backwards. Its delay after the specular echo (reflected at x = -a) is

    dt = (x_in + x_out + 2 a) / c_w + sum_j 2 a cos(theta_j) / c_j,

x_in, x_out the coordinates of the entry and exit points along the incidence. The axial ray
(b = 0) gives the diameter paths, e.g. "compressional through the diameter" at 4 a / c_L
(+42.0 us for a 25 mm PVC post), and, weaker (mode conversion vanishes at normal incidence,
so only rays near the axis convert), "compressional-shear" (2a/c_L + 2a/c_S, +68.2 us) and
"shear through the diameter" (4 a / c_S, +94.3 us); rays off the axis that leave backwards are
the glories, e.g. L-L-T at +75.8 us and L-T-T at +97.0 us for the PVC post (issue 17: "shear
and circumferential arrivals at +76..101 us"). Found by scanning b and
refining the roots of the exit angle (Brent).
Circumferential waves: the creeping (Franz) wave in the water around the back,
dt = (2 + pi) a / c_w (58-63 dB below the specular echo on rigid bodies, physics.md section 8);
for a solid whose Rayleigh speed c_R exceeds c_w, the leaky Rayleigh wave launched at
sin(theta_R) = c_w / c_R: dt = 2 a (1 - cos theta_R) / c_w + 2 a (pi - theta_R) / c_R (once
around; each further turn adds 2 pi a / c_R).
Shells: wall reverberations m 2 h / c_L (m = 1, 2, 3); a water-filled pipe's echo from the back
wall through the fill, 2 h / c_L + 4 b / c_fill (b = a - h).

Accuracy
--------
Delays of the ray model, exact for the ray paths; the echo's peak lies within about a period of
them (tests compare with the time-domain form function). Monostatic: the tank's bistatic angles
(a few degrees) shift them by O(beta^2). Amplitudes are not predicted here (the modal series
carries them).
"""

from __future__ import annotations

import itertools
import math
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import brentq

from acoustisim.scattering.bodies import Elastic, Fluid, Shell

__all__ = ("InternalArrival", "internal_arrivals", "rayleigh_speed", "shell_arrivals")

_SCAN_POINTS = 4001


class InternalArrival(NamedTuple):
    """One arrival after the specular echo.

    Attributes
    ----------
    name : str
        What it is, e.g. "compressional through the diameter".
    path : str
        Modes of the legs inside ("LL", "LLT", ...) or "creeping", "rayleigh", "wall", "fill".
    delay_s : float
        After the specular echo (s).
    impact_parameter : float
        b / a of the ray (0 for the diameter paths; nan where it does not apply).
    """

    name: str
    path: str
    delay_s: float
    impact_parameter: float


def rayleigh_speed(solid: Elastic) -> float:
    """Rayleigh-wave speed (m/s) of the solid's free surface: the root xi = c_R / c_S in (0, 1)
    of (2 - xi^2)^2 = 4 sqrt(1 - xi^2 c_S^2 / c_L^2) sqrt(1 - xi^2)."""
    ratio = solid.shear_speed_m_s / solid.compressional_speed_m_s

    def rayleigh(xi: float) -> float:
        return (2.0 - xi * xi) ** 2 - 4.0 * math.sqrt(1.0 - xi * xi * ratio * ratio) * math.sqrt(1.0 - xi * xi)

    return brentq(rayleigh, 0.5, 1.0 - 1e-12) * solid.shear_speed_m_s


def _refract(point: NDArray[np.float64], direction: NDArray[np.float64], speed_before: float, speed_after: float,
             inward: bool) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.bool_]]:
    """New directions (n, 2), cos of the new angle from the normal (n,) and validity (n,) at
    points of the unit circle (the outward normal is the point), Snell's law, keeping the
    tangential sense; ``inward`` for entry and internal reflections, else leaving."""
    along = np.sum(direction * point, axis=-1)[:, None]
    tangent = direction - along * point
    sin_in = np.linalg.norm(tangent, axis=-1)
    tangent = tangent / np.where(sin_in > 0.0, sin_in, 1.0)[:, None]
    sin_out = speed_after / speed_before * sin_in
    cos_out = np.sqrt(np.clip(1.0 - sin_out**2, 0.0, 1.0))
    normal_part = -point if inward else point
    return cos_out[:, None] * normal_part + sin_out[:, None] * tangent, cos_out, sin_out < 1.0


def _trace(b_over_a: NDArray[np.float64], speeds: tuple[float, ...], c_water: float
           ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.bool_]]:
    """Exit angle from backwards (rad), delay per unit radius (s/m) and validity of rays at
    impact parameters b / a (unit circle, incidence along +x), legs in the ``speeds``."""
    point = np.stack([-np.sqrt(1.0 - b_over_a**2), b_over_a], axis=-1)
    entry_x = point[:, 0].copy()
    direction = np.tile([1.0, 0.0], (b_over_a.size, 1))
    valid = np.ones(b_over_a.size, dtype=bool)
    time = np.zeros(b_over_a.size)
    before = c_water
    for speed in speeds:
        direction, cos_leg, ok = _refract(point, direction, before, speed, inward=True)
        valid &= ok
        chord = 2.0 * cos_leg
        time += chord / speed
        point = point + chord[:, None] * direction
        before = speed
    direction, _, ok = _refract(point, direction, before, c_water, inward=False)
    valid &= ok
    angle = np.arctan2(direction[:, 1], -direction[:, 0])
    delay = (entry_x + point[:, 0] + 2.0) / c_water + time
    return angle, delay, valid


def _diameter_name(counts: tuple[str, ...]) -> str:
    """'compressional through the diameter', 'shear through the diameter', 'compressional-shear
    through the diameter' (the legs' modes; more legs: 'x2' and so on)."""
    kinds = "-".join(dict.fromkeys("compressional" if m == "L" else "shear" for m in counts))
    times = len(counts) // 2
    return f"{kinds} through the diameter" + (f" x{times}" if times > 1 else "")


def internal_arrivals(solid: Elastic, radius_m: float, water: Fluid, max_legs: int = 3
                      ) -> tuple[InternalArrival, ...]:
    """Internal rays and circumferential waves of a solid cylinder or sphere (monostatic).

    Parameters
    ----------
    solid : Elastic
        A solid (c_S > 0) or a fluid body (c_S = 0: compressional legs only).
    radius_m : float
    water : Fluid
    max_legs : int
        Most chords inside (2 = one internal reflection).

    Returns
    -------
    tuple of InternalArrival
        Sorted by delay.
    """
    a = float(radius_m)
    water_speed_m_s = water.sound_speed_m_s
    modes = {"L": solid.compressional_speed_m_s}
    if not solid.is_fluid:
        modes["T"] = solid.shear_speed_m_s
    arrivals: list[InternalArrival] = []
    b = np.linspace(1e-6, 1.0 - 1e-9, _SCAN_POINTS)
    for legs in range(2, max_legs + 1):
        # rays off the axis, grouped by their legs' modes (L-L-T, L-T-L and T-L-L share one delay)
        for counts in itertools.combinations_with_replacement(modes, legs):
            if legs % 2 == 0:  # the axial ray comes back after an even number of diameters
                arrivals.append(InternalArrival(_diameter_name(counts), "".join(counts),
                                                float(sum(2.0 * a / modes[m] for m in counts)), 0.0))
            found: dict[float, float] = {}
            for path in sorted(set(itertools.permutations(counts))):
                speeds = tuple(modes[m] for m in path)
                angle, _, valid = _trace(b, speeds, water_speed_m_s)
                change = np.flatnonzero(valid[:-1] & valid[1:] & (np.sign(angle[:-1]) != np.sign(angle[1:]))
                                        & (np.abs(angle[:-1]) < 0.5) & (np.abs(angle[1:]) < 0.5))
                for index in change:
                    root = brentq(lambda x: _trace(np.array([x]), speeds, water_speed_m_s)[0][0], b[index],
                                  b[index + 1], xtol=1e-14)
                    delay = float(_trace(np.array([root]), speeds, water_speed_m_s)[1][0] * a)
                    found.setdefault(round(delay, 10), root)
            n_shear = counts.count("T")
            legs_text = ", ".join(f"{count} {mode}" for count, mode in ((legs - n_shear, "compressional"),
                                                                       (n_shear, "shear")) if count)
            for delay, root in found.items():
                arrivals.append(InternalArrival(f"glory ray: {legs_text} legs", "".join(counts), delay, float(root)))
    arrivals.append(InternalArrival("creeping (Franz) wave", "creeping", (2.0 + math.pi) * a / water_speed_m_s,
                                    math.nan))
    if not solid.is_fluid:
        c_r = rayleigh_speed(solid)
        if c_r > water_speed_m_s:
            theta = math.asin(water_speed_m_s / c_r)
            delay = 2.0 * a * (1.0 - math.cos(theta)) / water_speed_m_s + 2.0 * a * (math.pi - theta) / c_r
            arrivals.append(InternalArrival("leaky Rayleigh wave, once around", "rayleigh", delay, math.sin(theta)))
    return tuple(sorted(arrivals, key=lambda arrival: arrival.delay_s))


def shell_arrivals(shell: Shell, radius_m: float, water: Fluid, reverberations: int = 3
                   ) -> tuple[InternalArrival, ...]:
    """Wall reverberations and the back-wall echo through the fill (when the fill carries sound:
    its impedance at least a tenth of the water's, i.e. not air), monostatic."""
    h, c_l = shell.thickness_m, shell.wall.compressional_speed_m_s
    arrivals = [InternalArrival(f"wall reverberation {m}", "wall", m * 2.0 * h / c_l, 0.0)
                for m in range(1, reverberations + 1)]
    fill = shell.fill
    if fill.density_kg_m3 * fill.sound_speed_m_s >= 0.1 * water.density_kg_m3 * water.sound_speed_m_s:
        inner = radius_m - h
        arrivals.append(InternalArrival("back wall through the fill", "fill",
                                        2.0 * h / c_l + 4.0 * inner / fill.sound_speed_m_s, 0.0))
    return tuple(sorted(arrivals, key=lambda arrival: arrival.delay_s))
