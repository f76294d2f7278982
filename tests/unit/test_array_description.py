"""The array description: directivities (analytic), the TOML file, the recording's /array group."""

from __future__ import annotations

import math

import numpy as np
import pytest

from binsonar.array_description import (
    ArrayDescription,
    ArrayDescriptionError,
    BeamTable,
    BeamTableTransducers,
    ChannelDescription,
    ElectricalChain,
    PistonDirectivity,
)
from binsonar.recording import Recording, RecordingError, read_recording, write_recording

C = 1482.0
FS = 20e6


def head(directivity=PistonDirectivity(0.019), d=0.065) -> ArrayDescription:
    chain = ElectricalChain(gain_db=0.0, receive_sensitivity_db=-190.0, volts_per_code=2.0 / 4096, adc_bits=12)
    roles = ("receive", "both", "receive")
    return ArrayDescription(tuple(
        ChannelDescription(name, role, (x, 0.0, 0.0), (0.0, 1.0, 0.0), directivity, chain)
        for name, role, x in zip(("left", "centre", "right"), roles, (-d, 0.0, d))), FS)


# --------------------------------------------------------------------------------- directivities
def test_piston_nulls_and_half_power_are_where_bessel_puts_them():
    # 2 J1(x)/x: first zero at x = 3.8317 (j_{1,1}), -3 dB (1/sqrt 2) at x = 1.6163.
    piston = PistonDirectivity(0.019)
    k_a = 2 * math.pi * 500e3 / C * piston.radius_m
    null = math.asin(3.8317 / k_a)
    half_power = math.asin(1.6163 / k_a)
    assert abs(piston.response(null, 500e3, C)) < 1e-4  # x known to 1e-4 relative
    assert piston.response(half_power, 500e3, C) == pytest.approx(1 / math.sqrt(2), abs=1e-4)
    assert piston.response(0.0, 500e3, C) == 1.0
    assert piston.response(math.radians(120), 500e3, C) == 0.0  # behind the baffle


def test_a_beam_table_interpolates_bilinearly_and_holds_its_edges():
    f = np.array([300e3, 500e3, 700e3])
    a = np.array([0.0, 10.0, 20.0, 40.0])
    # g = 1 - 0.01 a (1 + f / 1 MHz) / 2: bilinear in (f, a) (with 1 on axis), so interpolation is exact.
    gain = 1.0 - 0.01 * a[np.newaxis, :] * (1 + f[:, np.newaxis] / 1e6) / 2
    table = BeamTable(f, a, gain)
    angles = np.radians([3.0, 17.0, 33.0, -17.0])
    freqs = np.array([350e3, 620e3, 410e3, 620e3])
    expected = 1.0 - 0.01 * np.degrees(np.abs(angles)) * (1 + freqs / 1e6) / 2
    np.testing.assert_allclose(table.response(angles, freqs), expected, rtol=0, atol=1e-12)
    # Outside the grid the edge values hold: 900 kHz is the 700 kHz row, 60 deg the 40 deg column.
    assert table.response(math.radians(60.0), 900e3) == pytest.approx(gain[2, 3], abs=1e-12)
    assert table.response(math.radians(10.0), 100e3) == pytest.approx(gain[0, 1], abs=1e-12)


def test_a_table_sampled_from_the_piston_reproduces_it_to_the_interpolation_bound():
    piston = PistonDirectivity(0.019)
    f = np.linspace(200e3, 1e6, 81)
    a = np.linspace(0.0, 30.0, 241)  # 0.125 deg
    grid = piston.response(np.radians(a)[np.newaxis, :], f[:, np.newaxis], C)
    table = BeamTable(f, a, grid)
    rng = np.random.default_rng(3)
    angles = np.radians(rng.uniform(0, 30, 2000))
    freqs = rng.uniform(200e3, 1e6, 2000)
    error = np.abs(table.response(angles, freqs) - piston.response(angles, freqs, C))
    # Bilinear error <= (h_1^2 |f_11| + h_2^2 |f_22|) / 8. D = 2J1(x)/x with |D''(x)| <= 1/4 and
    # x = (2 pi f / c) a sin(theta). Along theta: h = 0.125 deg = 2.2e-3 rad moves x by <= k a h = 0.088
    # at 1 MHz (k a = 40.3), plus D' x'' h^2 / 8 < 5e-6 from sin's curvature. Along f (x linear in f):
    # 10 kHz moves x by 2 pi a sin(30 deg) / c 10 kHz = 0.20. Bound: (0.088^2 + 0.20^2) / 8 / 4 = 1.6e-3;
    # nearest-neighbour lookup would be off by |D'| h / 2 ~ 1e-2.
    assert error.max() < 1.6e-3


def test_tables_are_normalised_on_axis_and_read_from_db():
    table = BeamTable.from_db([500e3], [0.0, 10.0], [[6.0, 0.0]])  # 6 dB on axis: the chain's, not the beam's
    assert table.response(0.0, 500e3) == pytest.approx(1.0)
    assert table.response(math.radians(10.0), 500e3) == pytest.approx(10 ** (-6 / 20))


@pytest.mark.parametrize("kwargs, message", [
    ({"frequencies_hz": [5e5, 4e5]}, "increasing"),
    ({"angles_deg": [1.0, 10.0]}, "start at 0"),
    ({"gain": [[0.0, 0.5]]}, "on-axis gain"),
    ({"gain": [[1.0, 0.5, 0.1]]}, "one row per frequency"),
])
def test_bad_beam_tables_are_one_line(kwargs, message):
    arguments = {"frequencies_hz": [5e5], "angles_deg": [0.0, 10.0], "gain": [[1.0, 0.5]]}
    arguments.update(kwargs)
    if len(arguments["frequencies_hz"]) == 2:
        arguments["gain"] = [[1.0, 0.5], [1.0, 0.5]]
    with pytest.raises(ArrayDescriptionError, match=message):
        BeamTable(**arguments)


# -------------------------------------------------------------------------------- for localisers
def test_transducers_and_geometry_for_the_localisers():
    from binsonar.localization.array_geometry import ArrayGeometry
    from binsonar.localization.beam_model import PistonTransducers

    array = head()
    transducers = array.transducers()
    assert isinstance(transducers, PistonTransducers)
    assert transducers.diameters_m == (0.019,) * 3 and transducers.transmitter_channel == 1
    geometry = array.geometry()
    assert isinstance(geometry, ArrayGeometry) and geometry.is_seed and geometry.half_baseline_m == 0.065
    table = BeamTable([5e5], [0.0, 20.0], [[1.0, 0.5]])
    mixed = ArrayDescription((array.channels[0], ChannelDescription("centre", "both", (0.0, 0.0, 0.0),
                                                                  directivity=table), array.channels[2]), FS)
    beams = mixed.transducers()
    assert isinstance(beams, BeamTableTransducers)
    assert beams.directivity(1, math.radians(10.0), 5e5, C) == pytest.approx(0.75)
    assert beams.directivity(0, 0.3, 5e5, C) == pytest.approx(PistonDirectivity(0.019).response(0.3, 5e5, C))
    assert mixed.directivity(1, math.radians(20.0), 5e5, C) == pytest.approx(0.5)
    assert head(directivity=None).transducers() is None
    with pytest.raises(ArrayDescriptionError, match="no directivity"):
        head(directivity=None).directivity(0, 0.1, 5e5, C)


@pytest.mark.parametrize("change, message", [
    (lambda ch: (ch[0], ch[1], ChannelDescription("right", "both", (0.065, 0, 0))), "exactly one channel must transmit"),
    (lambda ch: (ch[0], ch[1], ChannelDescription("right", "receive", (0.0, 0, 0))), "same position"),
    (lambda ch: (ch[0], ch[1], ChannelDescription("right", "sideways", (0.065, 0, 0))), "role"),
    (lambda ch: (ch[0], ch[1], ChannelDescription("right", "receive", (0.065, 0, 0), axis=(0, 0, 0))), "axis"),
    (lambda ch: ch[:2], "3 ChannelDescription"),
])
def test_inconsistent_arrays_are_one_line(change, message):
    with pytest.raises(ArrayDescriptionError, match=message):
        ArrayDescription(change(head().channels), FS)


@pytest.mark.parametrize("field, value", [("adc_bits", 0), ("adc_bits", 40), ("volts_per_code", 0.0),
                                          ("volts_per_code", 1e300), ("gain_db", float("nan"))])
def test_bad_electrical_chains_are_one_line(field, value):
    with pytest.raises(ArrayDescriptionError, match=field):
        ElectricalChain(**{field: value})


@pytest.mark.parametrize("rate", [1.0, 1e300, float("inf"), -20e6])
def test_sample_rates_outside_any_digitiser_are_refused(rate):
    with pytest.raises(ArrayDescriptionError, match="sample_rate_hz"):
        ArrayDescription(head().channels, rate)


# ----------------------------------------------------------------------------------------- files
def test_the_toml_file_round_trips(tmp_path):
    table = BeamTable([4e5, 6e5], [0.0, 10.0, 30.0], [[1.0, 0.7, -0.1], [1.0, 0.5, 0.05]])
    base = head()
    array = ArrayDescription((base.channels[0], ChannelDescription(
        "centre", "both", (0.0, 0.0, 0.0), (0.0, 0.9, 0.1), table, base.channels[1].electrical), base.channels[2]), FS)
    path = tmp_path / "array.toml"
    path.write_text(array.to_toml())
    again = ArrayDescription.from_toml(path)
    assert again.matches(array)
    assert again.channels[1].axis == pytest.approx((0.0, 0.9 / math.hypot(0.9, 0.1), 0.1 / math.hypot(0.9, 0.1)))


@pytest.mark.parametrize("edit, message", [
    (lambda m: m.update(colour="red"), "unknown key"),
    (lambda m: m.update(version="2.0"), "not supported"),
    (lambda m: m.pop("sample_rate_hz"), "missing sample_rate_hz"),
    (lambda m: m["channels"][0].pop("position_m"), "channels\\[0\\]: missing position_m"),
    (lambda m: m["channels"][1].update(directivity={"kind": "horn"}), "piston' or 'table"),
    (lambda m: m["channels"][1].update(directivity={"kind": "piston", "diameter_m": "big"}), "diameter_m"),
    (lambda m: m["channels"][2]["electrical"].update(adc_bits=0), "adc_bits"),
    (lambda m: m["channels"].pop(), "exactly 3"),
])
def test_bad_toml_files_name_the_file_and_key(tmp_path, edit, message):
    import tomli_w

    mapping = head().to_mapping()
    edit(mapping)
    path = tmp_path / "array.toml"
    path.write_text(tomli_w.dumps(mapping))
    with pytest.raises(ArrayDescriptionError, match=message) as exc:
        ArrayDescription.from_toml(path)
    assert str(exc.value).startswith(str(path)) and "\n" not in str(exc.value)


def test_recordings_carry_the_description_and_old_ones_get_the_default(tmp_path):
    table = BeamTable([4e5, 6e5], [0.0, 10.0, 30.0], [[1.0, 0.7, -0.1], [1.0, 0.5, 0.05]])
    base = head()
    array = ArrayDescription((base.channels[0], base.channels[1], ChannelDescription(
        "right", "receive", (0.065, 0.0, 0.0), directivity=table, electrical=base.channels[2].electrical)), FS)
    waveforms = np.zeros((2, 3, 64))
    path = write_recording(tmp_path / "ping.h5", Recording(waveforms, FS, array=array))
    assert read_recording(path).array.matches(array)
    # Without a description: the recording's own fields, no directivity.
    plain = Recording(waveforms, FS, channel_positions_m=[[-0.04, 0, 0], [0, 0, 0], [0.04, 0, 0]])
    assert plain.array.positions_m[0, 0] == -0.04 and not plain.array.describes_beams
    assert plain.array.transmitter_channel == 1
    with pytest.raises(RecordingError, match="sample_rate_hz"):
        Recording(waveforms, 10e6, array=array)
    with pytest.raises(RecordingError, match="positions differ"):
        Recording(waveforms, FS, channel_positions_m=[[-0.04, 0, 0], [0, 0, 0], [0.04, 0, 0]], array=array)
