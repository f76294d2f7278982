"""Angles of a circular piston's transmit beam, from its far-field directivity.

The one-way directivity of a baffled circular piston of radius ``a`` is
D(theta) = 2 J1(x) / x with x = k a sin(theta), k = 2 pi f / c (``physics.md`` section 2).
The beam's edges are where D takes given values: -3 dB, the first null (the first zero of J1)
and the first side lobe's peak (where d/dx [J1(x)/x] = -J2(x)/x = 0, the first zero of J2).
At 500 kHz with a = 9.5 mm and c = 1482 m/s: ka = 20.1, -3 dB at 4.60 deg, first null at
11.0 deg, side-lobe peak at 14.8 deg, 17.6 dB down.
"""

from __future__ import annotations

import math
from dataclasses import dataclass


@dataclass(frozen=True)
class BeamAngles:
    """Half-angles (degrees, off the acoustic axis) of a piston's one-way beam.

    Attributes
    ----------
    ka : float
        Wavenumber times piston radius (dimensionless).
    half_power_deg : float
        Where D = 10^(-3/20) (the -3 dB edge of the main lobe).
    first_null_deg : float or None
        First zero of D (None when ka is too small for the beam to have a null).
    side_lobe_deg : float or None
        Peak of the first side lobe (None when ka is too small).
    side_lobe_db : float or None
        Level of that peak relative to the axis (dB, negative).
    """

    ka: float
    half_power_deg: float
    first_null_deg: float | None
    side_lobe_deg: float | None
    side_lobe_db: float | None


def piston_beam_angles(radius_m: float, frequency_hz: float, sound_speed_m_s: float) -> BeamAngles:
    """The -3 dB, first-null and first-side-lobe half-angles of a circular piston.

    Parameters
    ----------
    radius_m : float
        Piston radius a (m).
    frequency_hz : float
        Frequency (Hz).
    sound_speed_m_s : float
        Sound speed of the water (m/s).

    Returns
    -------
    BeamAngles
        When ka is too small for D to fall to -3 dB before 90 degrees, ``half_power_deg`` is 90.
    """
    from scipy.optimize import brentq
    from scipy.special import j1, jn_zeros

    for name, value in (("radius_m", radius_m), ("frequency_hz", frequency_hz), ("sound_speed_m_s", sound_speed_m_s)):
        if not (math.isfinite(value) and value > 0):
            raise ValueError(f"piston_beam_angles: {name} must be a finite number > 0, got {value!r}")
    ka = 2.0 * math.pi * frequency_hz / sound_speed_m_s * radius_m
    target = 10.0 ** (-3.0 / 20.0)

    def directivity(x: float) -> float:
        return 2.0 * j1(x) / x

    # D falls monotonically from 1 to 0 on (0, j_{1,1}); the -3 dB point is inside.
    j11 = float(jn_zeros(1, 1)[0])
    x_half = brentq(lambda x: directivity(x) - target, 1e-9, j11)

    def angle(x: float) -> float | None:
        return math.degrees(math.asin(x / ka)) if x <= ka else None

    half_power = angle(x_half)
    j21 = float(jn_zeros(2, 1)[0])
    side_angle = angle(j21)
    side_db = 20.0 * math.log10(abs(directivity(j21))) if side_angle is not None else None
    return BeamAngles(
        ka=ka,
        half_power_deg=90.0 if half_power is None else half_power,
        first_null_deg=angle(j11),
        side_lobe_deg=side_angle,
        side_lobe_db=side_db,
    )
