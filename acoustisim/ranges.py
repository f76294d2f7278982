"""The physical ranges the simulator accepts, each with its reason, in one visible place.

A range refuses only what cannot be simulated or is certainly a mistake: the 500 kHz sonar in
a 9 m tank sits deep inside every one of them, and so do sea scenes (kilometre ranges, sea
water, low frequencies, long records). Whether a legal scene fits the machine is a separate
question, answered by :mod:`acoustisim.resources` against limits the user can raise.

Every descriptor (``Medium``, ``Tank``, ``SonarHead``, the object builders) and the pre-flight
(:mod:`acoustisim.preflight`) check values against these ranges through
:func:`acoustisim.checks.real`, so a message always quotes the same bounds and reason.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class PhysicalRange:
    """An interval of accepted values and why it ends where it does.

    Attributes
    ----------
    low, high : float
        The bounds, in the quantity's unit.
    unit : str
        Printed after the bounds ("m", "Hz", ""...).
    reason : str
        Why values outside are refused (printed in the message).
    low_open : bool
        The low bound itself is refused (``x > low`` instead of ``x >= low``).
    """

    low: float
    high: float
    unit: str
    reason: str
    low_open: bool = False

    def contains(self, value: float) -> bool:
        """Whether ``value`` lies in the range."""
        above = value > self.low if self.low_open else value >= self.low
        return above and value <= self.high

    def describe(self) -> str:
        """``"in (0, 3600] s"`` and the like."""
        bracket = "(" if self.low_open else "["
        unit = f" {self.unit}" if self.unit else ""
        return f"must lie in {bracket}{self.low:g}, {self.high:g}]{unit} ({self.reason})"


FLOAT32_REASON = "the ray tracer works in float32: 1 um steps at 10 m, 8 mm at 100 km"

COORDINATE_M = PhysicalRange(-1.0e5, 1.0e5, "m", "scenes reach at most 100 km; " + FLOAT32_REASON)
"""Any position in the tank frame (m), and the extent of every object."""

LENGTH_M = PhysicalRange(1.0e-5, 1.0e5, "m", "sizes from 10 um to 100 km; " + FLOAT32_REASON)
"""Sizes: tank dimensions, object radii and lengths, transducer diameter and separation (m)."""

ANGLE_DEG = PhysicalRange(-3600.0, 3600.0, "deg", "more than ten turns is certainly a mistake")
"""Orientation angles (yaw, pitch, roll, facing; degrees)."""

INTERIOR_ANGLE_DEG = PhysicalRange(
    0.1, 179.9, "deg", "a thinner or flatter wedge has faces closer than float32 ray tracing resolves")
"""Interior angle of an edge prism at its sharp edge (degrees)."""

CENTRE_FREQUENCY_HZ = PhysicalRange(
    1.0, 1.0e8, "Hz", "acoustic sonars work between a few hertz and a few tens of megahertz")
"""Pulse carrier f0 (Hz)."""

PULSE_DURATION_S = PhysicalRange(
    1.0e-9, 100.0, "s", "no transducer makes a pulse shorter than 1 ns; 100 s is longer than any sonar pulse")
"""Gaussian pulse duration T (s)."""

PULSE_OFFSET_S = PhysicalRange(-3600.0, 3600.0, "s", "a sampled pulse starts within an hour of its reference instant")
"""Time of a sampled pulse's first sample relative to its reference instant (s)."""

SOURCE_LEVEL_PA = PhysicalRange(
    1.0e-6, 1.0e9, "Pa", "from 1 uPa at 1 m (0 dB re 1 uPa), below the thermal noise of water, to 1e9 Pa (300 dB),"
    " far beyond cavitation; beyond either the receiver chain's arithmetic underflows or overflows")
"""Peak source pressure at 1 m on axis (Pa)."""

SAMPLE_RATE_HZ = PhysicalRange(
    2.0, 1.0e11, "Hz", "twice the lowest centre frequency, up to 100 GS/s (no digitiser is faster)")
"""Digitiser sample rate (Hz); the pulse's band sets a lower bound (the pre-flight checks it)."""

RECORD_LENGTH_S = PhysicalRange(
    0.0, 3600.0, "s", "sound crosses 5,400 km of water in an hour; a longer record is certainly a mistake",
    low_open=True)
"""Record length after the trigger (s); the pulse sets a lower bound (the pre-flight checks it)."""

ADC_BITS = PhysicalRange(2.0, 24.0, "bits", "digitisers have 2 to 24 bits")
"""Digitiser resolution."""

TEMPERATURE_C = PhysicalRange(-2.0, 95.0, "C", "liquid water; the sound-speed fits (Marczak, UNESCO) end there")
"""Water temperature (degrees Celsius)."""

SALINITY_PPT = PhysicalRange(0.0, 45.0, "ppt", "fresh water to the saltiest open sea")
"""Salinity (parts per thousand)."""

DEPTH_M = PhysicalRange(0.0, 12000.0, "m", "the deepest ocean is 11 km")
"""Depth used for the pressure terms of sound speed and absorption (m)."""

PH = PhysicalRange(0.0, 14.0, "", "the pH scale of water")
"""pH, for the boric-acid relaxation."""

SOUND_SPEED_M_S = PhysicalRange(1300.0, 1700.0, "m/s", "water at any temperature, salinity and depth")
"""An explicit sound speed (m/s)."""

SNR_DB = PhysicalRange(-300.0, 300.0, "dB", "10^(SNR/10) must stay inside float64's range")
"""A requested echo signal-to-noise ratio 2E/N0 (dB)."""

SCALE = PhysicalRange(1.0e-9, 1.0e9, "", "a mesh's unit conversion (nanometres to gigametres)", low_open=False)
"""Uniform scale of a user mesh (file units to metres)."""


__all__ = (
    "ADC_BITS",
    "ANGLE_DEG",
    "CENTRE_FREQUENCY_HZ",
    "COORDINATE_M",
    "DEPTH_M",
    "INTERIOR_ANGLE_DEG",
    "LENGTH_M",
    "PH",
    "PULSE_DURATION_S",
    "PULSE_OFFSET_S",
    "PhysicalRange",
    "RECORD_LENGTH_S",
    "SALINITY_PPT",
    "SAMPLE_RATE_HZ",
    "SCALE",
    "SNR_DB",
    "SOUND_SPEED_M_S",
    "SOURCE_LEVEL_PA",
    "TEMPERATURE_C",
)
