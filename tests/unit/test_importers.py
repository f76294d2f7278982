"""Importers: each format gives back exactly the samples written into it (codes or volts), its
layouts, its [import] settings, and one line for each bad file."""

from __future__ import annotations

import numpy as np
import pytest

from binsonar.array_description import ArrayDescription, ChannelDescription, ElectricalChain, PistonDirectivity
from binsonar.errors import InputError
from binsonar.importers import open_foreign, open_source
from support.foreign_files import array_toml, frames_of, write_mat73, write_wav
from support.hostile_recordings import clean_codes, pulse

FS = 20e6
STEP = 2.0 / 4096


def seed_array(volts_per_code=STEP, adc_bits=12) -> ArrayDescription:
    chain = ElectricalChain(volts_per_code=volts_per_code, adc_bits=adc_bits)
    roles = ("receive", "both", "receive")
    return ArrayDescription(tuple(
        ChannelDescription(name, role, (x, 0.0, 0.0), directivity=PistonDirectivity(0.019), electrical=chain)
        for name, role, x in zip(("left", "centre", "right"), roles, (-0.065, 0.0, 0.065))), FS)


@pytest.fixture()
def pings():
    return clean_codes(3, 1024, seed=9)


def _describe(tmp_path, array=None, **settings):
    np.save(tmp_path / "pulse.npy", pulse())
    table = {"template": "pulse.npy", "template_t0_s": -100 / FS, "sound_speed_m_s": 1482.0, **settings}
    path = tmp_path / "array.toml"
    path.write_text(array_toml(array or seed_array(), table))
    return path


def test_16_bit_wav_pings_come_back_as_the_same_codes(tmp_path, pings):
    wav = write_wav(tmp_path / "daq.wav", pings, FS, "PCM_16")
    with open_foreign(wav, _describe(tmp_path, samples_per_ping=1024)) as source:
        recording = source.read(keep_codes=True)
    np.testing.assert_array_equal(recording.codes, pings)
    assert recording.volts_per_code == STEP and recording.adc_bits == 12
    assert recording.template.t0_s == -100 / FS and recording.sound_speed_m_s == 1482.0
    assert recording.array.describes_beams


@pytest.mark.parametrize("subtype", ["PCM_24", "PCM_32"])
def test_wide_integer_wavs_become_volts_of_each_code(tmp_path, pings, subtype):
    wide = pings.astype(np.int32) * 100  # codes beyond int16: a 24- or 32-bit ADC
    wav = write_wav(tmp_path / "daq.wav", wide, FS, subtype)
    step = 1e-7
    with open_foreign(wav, _describe(tmp_path, seed_array(step, 24), samples_per_ping=1024)) as source:
        recording = source.read(keep_codes=True)
    assert recording.codes is None
    np.testing.assert_array_equal(recording.waveforms, wide * step)  # integers times the step: exact


def test_float_wav_samples_are_volts_times_volts_per_unit(tmp_path, pings):
    unit = (pings / 2048.0).astype(np.float32)
    wav = write_wav(tmp_path / "daq.wav", unit, FS, "FLOAT")
    with open_foreign(wav, _describe(tmp_path, samples_per_ping=1024, volts_per_unit=2.5)) as source:
        recording = source.read()
    np.testing.assert_allclose(recording.waveforms, unit.astype(np.float64) * 2.5, rtol=0, atol=0)


@pytest.mark.parametrize("layout", ["pings-channels-samples", "channels-samples", "samples-channels", "fortran"])
def test_npy_layouts(tmp_path, pings, layout):
    data = {"pings-channels-samples": pings, "channels-samples": pings[0], "samples-channels": pings[0].T,
            "fortran": np.asfortranarray(pings)}[layout]
    np.save(tmp_path / "ping.npy", data)
    with open_foreign(tmp_path / "ping.npy", _describe(tmp_path)) as source:
        recording = source.read(keep_codes=True)
    expected = pings if data.ndim == 3 else pings[:1]
    np.testing.assert_array_equal(recording.codes, expected)


def test_npz_and_matlab_files_choose_their_variable(tmp_path, pings):
    import scipy.io

    np.savez(tmp_path / "two.npz", other=np.zeros(3), waveforms=pings)
    scipy.io.savemat(tmp_path / "v5.mat", {"note": "x", "scan": pings[0].T.astype(np.float64) * STEP})
    write_mat73(tmp_path / "v73.mat", {"waveforms": pings})
    write_mat73(tmp_path / "v73cols.mat", {"scan": pings[0].T.copy()})  # MATLAB (n, 3): a column per channel
    description = _describe(tmp_path)
    with open_foreign(tmp_path / "two.npz", description) as source:
        np.testing.assert_array_equal(source.read(keep_codes=True).codes, pings)
    with open_foreign(tmp_path / "v5.mat", description) as source:
        np.testing.assert_array_equal(source.read().waveforms, pings[:1] * STEP)
    with open_foreign(tmp_path / "v73.mat", description) as source:
        np.testing.assert_array_equal(source.read(keep_codes=True).codes, pings)
        np.testing.assert_array_equal(source.read(1, 2, keep_codes=True).codes, pings[1:2])
    with open_foreign(tmp_path / "v73cols.mat", description) as source:
        np.testing.assert_array_equal(source.read(keep_codes=True).codes, pings[:1])


def test_csv_columns_by_name_and_codes(tmp_path, pings):
    frames = frames_of(pings)
    volts = "\n".join(f"{r:.17g},{l:.17g},{c:.17g}" for l, c, r in frames * STEP)
    (tmp_path / "volts.csv").write_text("right,left,centre\n" + volts + "\n")
    (tmp_path / "codes.csv").write_text("\n".join(",".join(str(v) for v in row) for row in frames) + "\n")
    with open_foreign(tmp_path / "volts.csv", _describe(tmp_path, samples_per_ping=1024)) as source:
        np.testing.assert_array_equal(source.read().waveforms, pings * STEP)
    with open_foreign(tmp_path / "codes.csv", _describe(tmp_path, samples_per_ping=1024, samples="codes")) as source:
        np.testing.assert_array_equal(source.read(keep_codes=True).codes, pings)


@pytest.mark.parametrize("make, settings, message", [
    (lambda p, x: write_wav(p / "a.wav", x, 44100.0), {}, "44100 Hz"),
    (lambda p, x: write_wav(p / "a.wav", x, FS), {"samples_per_ping": 1000}, "cannot be split"),
    (lambda p, x: np.save(p / "a.npy", x[:, :2]), {}, "three channels"),
    (lambda p, x: np.save(p / "a.npy", x.astype(np.uint16)), {}, "not supported"),
    (lambda p, x: np.savez(p / "a.npz", a=x, b=x), {}, "name the one"),
    (lambda p, x: np.savez(p / "a.npz", waveforms=x), {"variable": "scan"}, "no .npz variable 'scan'"),
    (lambda p, x: (p / "a.csv").write_text("left,centre,right\n1,2,3\n4,five,6\n"), {}, "five"),
    (lambda p, x: np.save(p / "a.npy", x), {"colour": "blue"}, "unknown key"),
    (lambda p, x: np.save(p / "a.npy", x), {"template": "absent.npy"}, "no such file"),
    (lambda p, x: (p / "a.txt").write_text("1,2,3"), {}, "unknown format"),
    # shorter than a MAT-file's 128-byte header, not a v4 one (hypothesis found it)
    (lambda p, x: (p / "a.mat").write_bytes(b"\x01\x01\x01\x01" + bytes(16)), {}, "not a MATLAB file"),
])
def test_bad_files_are_one_line(tmp_path, pings, make, settings, message):
    path = make(tmp_path, pings)
    path = path if path is not None and not isinstance(path, int) else next(
        p for p in tmp_path.iterdir() if p.stem == "a")
    with pytest.raises(InputError, match=message) as exc:
        with open_foreign(path, _describe(tmp_path, **settings)) as source:
            source.read()
    assert "\n" not in str(exc.value)


def test_integer_samples_need_every_channels_step(tmp_path, pings):
    np.save(tmp_path / "a.npy", pings)
    with pytest.raises(InputError, match="volts_per_code"):
        open_foreign(tmp_path / "a.npy", _describe(tmp_path, seed_array(volts_per_code=None)))


def test_open_source_needs_array_for_foreign_files_and_refuses_it_for_recordings(tmp_path, pings):
    np.save(tmp_path / "a.npy", pings)
    with pytest.raises(InputError, match="--array"):
        open_source(tmp_path / "a.npy")
    (tmp_path / "ping.h5").write_bytes(b"x")
    with pytest.raises(InputError, match="carries its own"):
        open_source(tmp_path / "ping.h5", _describe(tmp_path))
