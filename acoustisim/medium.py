"""The propagation medium: water type, temperature, salinity, depth.

Sound speed
    fresh water: Marczak (1997), 0-95 C;
    sea water: Mackenzie (1981) or UNESCO Chen-Millero with the Wong & Zhu (1995) ITS-90
    coefficients. An explicit ``sound_speed_m_s`` overrides the formula.
Absorption
    Francois & Garrison (1982): boric acid and MgSO4 relaxations plus the viscous
    pure-water term. Fresh water is the S = 0 case (only the viscous f^2 term survives).
Density
    pure water from Kell (1975), plus 0.76 kg/m^3 per ppt of salinity (a linear fit to
    UNESCO EOS-80 at the surface, within 0.1 % for 0-35 ppt and 0-30 C).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from acoustisim import checks, ranges

WaterKind = Literal["fresh", "sea"]
SoundSpeedFormula = Literal["auto", "marczak", "mackenzie", "unesco"]


def marczak_sound_speed(temperature_c: float) -> float:
    """Sound speed in pure water (m/s), Marczak (1997), valid 0-95 C."""
    t = temperature_c
    return (
        1402.385
        + 5.038813 * t
        - 5.799136e-2 * t**2
        + 3.287156e-4 * t**3
        - 1.398845e-6 * t**4
        + 2.787860e-9 * t**5
    )


def mackenzie_sound_speed(temperature_c: float, salinity_ppt: float, depth_m: float) -> float:
    """Sound speed in sea water (m/s), Mackenzie (1981); 2-30 C, 25-40 ppt, 0-8000 m."""
    t, s, d = temperature_c, salinity_ppt, depth_m
    return (
        1448.96
        + 4.591 * t
        - 5.304e-2 * t**2
        + 2.374e-4 * t**3
        + 1.340 * (s - 35.0)
        + 1.630e-2 * d
        + 1.675e-7 * d**2
        - 1.025e-2 * t * (s - 35.0)
        - 7.139e-13 * t * d**3
    )


def _poly(t: float, coefficients: tuple[float, ...]) -> float:
    return sum(c * t**i for i, c in enumerate(coefficients))


def unesco_sound_speed(temperature_c: float, salinity_ppt: float, depth_m: float) -> float:
    """Sound speed in sea water (m/s), UNESCO Chen & Millero (1977), Wong & Zhu (1995) coefficients.

    The gauge pressure is taken as 0.1 bar per metre of depth (hydrostatic, rho g = 1.0e4 Pa/m
    within 1.5 %), which is ample for tank and shelf depths.
    """
    t, s = temperature_c, salinity_ppt
    p = 0.1 * depth_m  # bar
    cw = (
        _poly(t, (1402.388, 5.03830, -5.81090e-2, 3.3432e-4, -1.47797e-6, 3.1419e-9))
        + _poly(t, (0.153563, 6.8999e-4, -8.1829e-6, 1.3632e-7, -6.1260e-10)) * p
        + _poly(t, (3.1260e-5, -1.7111e-6, 2.5986e-8, -2.5353e-10, 1.0415e-12)) * p**2
        + _poly(t, (-9.7729e-9, 3.8513e-10, -2.3654e-12)) * p**3
    )
    a = (
        _poly(t, (1.389, -1.262e-2, 7.166e-5, 2.008e-6, -3.21e-8))
        + _poly(t, (9.4742e-5, -1.2583e-5, -6.4928e-8, 1.0515e-8, -2.0142e-10)) * p
        + _poly(t, (-3.9064e-7, 9.1061e-9, -1.6009e-10, 7.994e-12)) * p**2
        + _poly(t, (1.100e-10, 6.651e-12, -3.391e-13)) * p**3
    )
    b = -1.922e-2 - 4.42e-5 * t + (7.3637e-5 + 1.7950e-7 * t) * p
    d = 1.727e-3 - 7.9836e-6 * p
    return cw + a * s + b * s**1.5 + d * s**2


def francois_garrison_absorption_db_per_m(
    frequency_hz: ArrayLike,
    temperature_c: float,
    salinity_ppt: float,
    depth_m: float,
    ph: float,
    sound_speed_m_s: float,
) -> NDArray[np.float64]:
    """Absorption coefficient (dB/m) per frequency, Francois & Garrison (1982).

    Parameters
    ----------
    frequency_hz : array_like, any shape
        Frequencies (Hz); negative frequencies are treated by their magnitude.
    temperature_c, salinity_ppt, depth_m, ph, sound_speed_m_s : float
        The water's state.

    Returns
    -------
    ndarray, same shape as ``frequency_hz``
        Absorption in dB per metre.
    """
    f = np.abs(np.asarray(frequency_hz, dtype=float)) * 1e-3  # kHz
    t, s, z, c = temperature_c, salinity_ppt, depth_m, sound_speed_m_s
    theta = 273.0 + t
    f2 = f * f
    # Boric acid relaxation.
    a1 = 8.86 / c * 10.0 ** (0.78 * ph - 5.0)
    f1 = 2.8 * math.sqrt(max(s, 0.0) / 35.0) * 10.0 ** (4.0 - 1245.0 / theta)
    boric = np.zeros_like(f) if f1 == 0.0 else a1 * f1 * f2 / (f1 * f1 + f2)
    # Magnesium sulphate relaxation.
    a2 = 21.44 * s / c * (1.0 + 0.025 * t)
    p2 = 1.0 - 1.37e-4 * z + 6.2e-9 * z * z
    f_2 = 8.17 * 10.0 ** (8.0 - 1990.0 / theta) / (1.0 + 0.0018 * (s - 35.0))
    mgso4 = a2 * p2 * f_2 * f2 / (f_2 * f_2 + f2)
    # Pure water (viscous).
    if t <= 20.0:
        a3 = 4.937e-4 - 2.59e-5 * t + 9.11e-7 * t**2 - 1.50e-8 * t**3
    else:
        a3 = 3.964e-4 - 1.146e-5 * t + 1.45e-7 * t**2 - 6.5e-10 * t**3
    p3 = 1.0 - 3.83e-5 * z + 4.9e-10 * z * z
    water = a3 * p3 * f2
    return (boric + mgso4 + water) * 1e-3


def kell_density_kg_m3(temperature_c: float) -> float:
    """Density of air-free pure water (kg/m^3) at 1 atm, Kell (1975), 0-150 C."""
    t = temperature_c
    num = (
        999.83952
        + 16.945176 * t
        - 7.9870401e-3 * t**2
        - 46.170461e-6 * t**3
        + 105.56302e-9 * t**4
        - 280.54253e-12 * t**5
    )
    return num / (1.0 + 16.879850e-3 * t)


@dataclass(frozen=True)
class Medium:
    """The water the sound travels through.

    Attributes
    ----------
    water : {"fresh", "sea"}
        Fresh water uses Marczak; sea water uses ``formula``.
    temperature_c : float
        Temperature in degrees Celsius.
    salinity_ppt : float
        Salinity in parts per thousand (0 for fresh water).
    depth_m : float
        Depth used for pressure terms (m); a tank is ~0.5 m.
    ph : float
        pH, for the boric-acid relaxation (sea water only matters).
    sound_speed_m_s : float or None
        Overrides the formula when given.
    formula : {"auto", "marczak", "mackenzie", "unesco"}
        "auto" is Marczak for fresh water and UNESCO for sea water.
    """

    water: WaterKind = "fresh"
    temperature_c: float = 20.0
    salinity_ppt: float = 0.0
    depth_m: float = 0.5
    ph: float = 8.0
    sound_speed_m_s: float | None = None
    formula: SoundSpeedFormula = "auto"

    def __post_init__(self) -> None:
        owner = "medium"
        checks.choice(owner, "water", self.water, ("fresh", "sea"))
        checks.choice(owner, "formula", self.formula, ("auto", "marczak", "mackenzie", "unesco"))
        for name, allowed in (("temperature_c", ranges.TEMPERATURE_C), ("salinity_ppt", ranges.SALINITY_PPT),
                              ("depth_m", ranges.DEPTH_M), ("ph", ranges.PH)):
            object.__setattr__(self, name, checks.real(owner, name, getattr(self, name), allowed))
        if self.sound_speed_m_s is not None:
            object.__setattr__(self, "sound_speed_m_s",
                               checks.real(owner, "sound_speed_m_s", self.sound_speed_m_s, ranges.SOUND_SPEED_M_S))

    @property
    def sound_speed(self) -> float:
        """Sound speed c (m/s)."""
        if self.sound_speed_m_s is not None:
            return float(self.sound_speed_m_s)
        formula = self.formula
        if formula == "auto":
            formula = "marczak" if self.water == "fresh" else "unesco"
        if formula == "marczak":
            return marczak_sound_speed(self.temperature_c)
        if formula == "mackenzie":
            return mackenzie_sound_speed(self.temperature_c, self.salinity_ppt, self.depth_m)
        return unesco_sound_speed(self.temperature_c, self.salinity_ppt, self.depth_m)

    @property
    def density(self) -> float:
        """Density rho (kg/m^3)."""
        return kell_density_kg_m3(self.temperature_c) + 0.76 * self.salinity_ppt

    @property
    def impedance(self) -> float:
        """Characteristic impedance rho c (kg m^-2 s^-1)."""
        return self.density * self.sound_speed

    def absorption_db_per_m(self, frequency_hz: ArrayLike) -> NDArray[np.float64]:
        """Absorption (dB/m) at each frequency (Hz), Francois-Garrison; any array shape."""
        salinity = self.salinity_ppt if self.water == "sea" else 0.0
        return francois_garrison_absorption_db_per_m(
            frequency_hz, self.temperature_c, salinity, self.depth_m, self.ph, self.sound_speed
        )

    def wavenumber(self, frequency_hz: ArrayLike) -> NDArray[np.float64]:
        """Acoustic wavenumber k = 2 pi f / c (rad/m)."""
        return 2.0 * np.pi * np.asarray(frequency_hz, dtype=float) / self.sound_speed
