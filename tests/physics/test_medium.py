"""Sound speed, absorption and density of water against published check values."""

import numpy as np
import pytest

from acoustisim.medium import (
    Medium,
    mackenzie_sound_speed,
    marczak_sound_speed,
    unesco_sound_speed,
)


def test_marczak_fresh_water_at_20c():
    # Check value 1482.38 m/s (physics.md), printed to 0.01 m/s: tolerance half a digit.
    assert Medium(water="fresh", temperature_c=20.0).sound_speed == pytest.approx(1482.38, abs=0.005)


def test_marczak_slope_about_3_m_s_per_kelvin():
    # physics.md: dc/dT is about 3 m/s per K at 20 C; the polynomial's derivative is 3.07.
    slope = (marczak_sound_speed(20.5) - marczak_sound_speed(19.5)) / 1.0
    assert slope == pytest.approx(3.07, abs=0.02)


@pytest.mark.parametrize("formula", [unesco_sound_speed, mackenzie_sound_speed])
def test_sea_water_check_value(formula):
    # Check value "about 1521.5 m/s" at 20 C, 35 ppt, 0 m. Mackenzie's own fit error is
    # 0.07 m/s and UNESCO's 0.05 m/s, so the two must land within 0.1 m/s of 1521.5.
    assert formula(20.0, 35.0, 0.0) == pytest.approx(1521.5, abs=0.1)


def test_unesco_pure_water_agrees_with_marczak():
    # Independent fits of pure-water data: Chen-Millero's S = 0 polynomial and Marczak's agree
    # to a few hundredths of a m/s between 0 and 40 C (Marczak 1997 compares them: < 0.05 m/s).
    for t in (0.0, 10.0, 20.0, 30.0, 40.0):
        assert unesco_sound_speed(t, 0.0, 0.0) == pytest.approx(marczak_sound_speed(t), abs=0.05)


def test_unesco_pressure_increases_speed():
    # About 1.6 m/s per 100 m (Mackenzie's depth term 0.0163 m/s per m): 1000 m adds ~16.5 m/s.
    dc = unesco_sound_speed(10.0, 35.0, 1000.0) - unesco_sound_speed(10.0, 35.0, 0.0)
    assert dc == pytest.approx(16.5, abs=0.6)


def test_formula_choice_and_override():
    sea = Medium(water="sea", temperature_c=20.0, salinity_ppt=35.0, depth_m=0.0)
    assert sea.sound_speed == unesco_sound_speed(20.0, 35.0, 0.0)  # "auto" is UNESCO for sea water
    mack = Medium(water="sea", temperature_c=20.0, salinity_ppt=35.0, depth_m=0.0, formula="mackenzie")
    assert mack.sound_speed == mackenzie_sound_speed(20.0, 35.0, 0.0)
    assert Medium(sound_speed_m_s=1500.0).sound_speed == 1500.0


@pytest.mark.parametrize("f_hz, expected", [(325e3, 0.023), (500e3, 0.055), (675e3, 0.100)])
def test_fresh_water_absorption(f_hz, expected):
    # physics.md values (Francois-Garrison pure-water term, A3 = 2.201e-4 dB/(km kHz^2) at
    # 20 C), printed to 3 decimals: tolerance half the last digit.
    value = float(Medium(water="fresh", temperature_c=20.0).absorption_db_per_m(f_hz))
    assert value == pytest.approx(expected, abs=0.0005)


def test_fresh_water_absorption_scales_as_f_squared_and_keeps_shape():
    # Fresh water keeps only the viscous A3 f^2 term: doubling f multiplies alpha by 4 exactly.
    medium = Medium(water="fresh", temperature_c=20.0)
    f = np.array([[100e3, 200e3], [-300e3, 600e3]])
    alpha = medium.absorption_db_per_m(f)
    assert alpha.shape == f.shape
    assert alpha[0, 1] / alpha[0, 0] == pytest.approx(4.0, rel=1e-12)
    assert alpha[1, 1] / alpha[1, 0] == pytest.approx(4.0, rel=1e-12)  # |f| for negative bins


def test_sea_water_absorption_at_500khz():
    # "About 0.147 dB/m" at 500 kHz, 20 C, 35 ppt (physics.md): 1.5 % tolerance covers the
    # unstated depth and pH of the check value (pH 7.7-8.3 moves it by < 1 %).
    sea = Medium(water="sea", temperature_c=20.0, salinity_ppt=35.0, depth_m=0.0)
    assert float(sea.absorption_db_per_m(500e3)) == pytest.approx(0.147, rel=0.015)


def test_sea_absorbs_more_than_fresh():
    f = np.linspace(10e3, 1e6, 20)
    sea = Medium(water="sea", temperature_c=20.0, salinity_ppt=35.0).absorption_db_per_m(f)
    fresh = Medium(water="fresh", temperature_c=20.0).absorption_db_per_m(f)
    assert np.all(sea > fresh)


def test_density_of_pure_water():
    # Kell (1975): 998.204 kg/m^3 at 20 C, maximum 999.972 near 4 C; tables give 998.20 / 999.97.
    assert Medium(temperature_c=20.0).density == pytest.approx(998.20, abs=0.01)
    assert Medium(temperature_c=4.0).density == pytest.approx(999.97, abs=0.01)


@pytest.mark.parametrize(
    "kwargs",
    [
        {"temperature_c": float("nan")},
        {"temperature_c": 120.0},
        {"salinity_ppt": -1.0},
        {"water": "lake"},
        {"formula": "guess"},
        {"sound_speed_m_s": 900.0},
        {"depth_m": -2.0},
    ],
)
def test_bad_medium_is_rejected(kwargs):
    with pytest.raises(ValueError):
        Medium(**kwargs)
