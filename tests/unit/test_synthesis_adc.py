"""The digitiser model: quantisation noise, clipping flags, bad settings."""

from __future__ import annotations

import math

import numpy as np
import pytest

from acoustisim.errors import InputError
from acoustisim.medium import Medium
from acoustisim.sonar import SonarHead
from acoustisim.synthesis import PingSynthesiser, ReceiverChain, TimeVaryingGain
from acoustisim.synthesis.adc import adc_step_v, quantise


def test_quantisation_noise_variance_is_step_squared_over_12():
    rng = np.random.default_rng(0)
    t = np.arange(250_000) / 20e6
    volts = 0.7 * np.sin(2 * np.pi * 500e3 * t[None, :] + rng.uniform(0, 6.28, (3, 1))) + 1e-3 * rng.standard_normal(
        (3, t.size)
    )
    codes, clipped, step = quantise(volts, 12, 1.0)
    assert step == pytest.approx(2.0 / 4096)
    error = codes * step - volts
    # 750k samples: the variance estimate of a uniform error is good to 0.1 % (1 sigma).
    assert np.var(error) == pytest.approx(step**2 / 12, rel=0.01)
    assert np.max(np.abs(error)) <= step / 2 + 1e-15
    assert not clipped.any()
    assert codes.dtype == np.int16


def test_clipping_is_flagged_per_channel():
    volts = np.zeros((2, 3, 100))
    volts[0, 2, 10] = 1.2  # above +FS
    volts[1, 0, 50] = -1.0 - 0.75 * adc_step_v(1.0, 12)  # just below -2048 codes
    codes, clipped, _ = quantise(volts, 12, 1.0)
    assert clipped.tolist() == [[False, False, True], [True, False, False]]
    assert codes.max() == 2047 and codes.min() == -2048


def test_bad_adc_bits():
    with pytest.raises(InputError, match="adc_bits"):
        quantise(np.zeros((3, 4)), 20, 1.0)


def test_chain_rejects_bad_settings():
    with pytest.raises(InputError, match="attenuation_db"):
        ReceiverChain(attenuation_db=(0.0, 70.0, 0.0))
    with pytest.raises(InputError, match="gain_db"):
        ReceiverChain(gain_db=(40.0, math.nan, 40.0))
    with pytest.raises(InputError, match="bandpass_low_hz"):
        ReceiverChain(bandpass_low_hz=3e6)
    with pytest.raises(InputError, match="electrical_noise_v_per_rthz"):
        ReceiverChain(electrical_noise_v_per_rthz=math.inf)
    with pytest.raises(InputError, match="tvg.start_s"):
        TimeVaryingGain(start_s=-1.0)


def test_sample_rate_below_twice_the_band_top_is_refused():
    # The 500 kHz, 5 us pulse is 40 dB down at about 1.0 MHz: 1.5 MS/s is too slow.
    with pytest.raises(InputError, match="sample_rate_hz"):
        PingSynthesiser.create(SonarHead(sample_rate_hz=1.5e6), Medium(), ReceiverChain(bandpass_high_hz=None))
    with pytest.raises(InputError, match="Nyquist"):
        PingSynthesiser.create(SonarHead(sample_rate_hz=3e6), Medium(), ReceiverChain(bandpass_high_hz=2e6))
    PingSynthesiser.create(SonarHead(sample_rate_hz=3e6), Medium(), ReceiverChain(bandpass_high_hz=1.2e6))


def test_time_varying_gain():
    tvg = TimeVaryingGain(start_s=1e-4, slope_db_per_decade=20.0, max_gain_db=30.0)
    gain_db = 20 * np.log10(tvg.gain([5e-5, 1e-4, 1e-3, 1e-1]))
    assert gain_db == pytest.approx([0.0, 0.0, 20.0, 30.0])


@pytest.mark.parametrize("dtype", [np.float64, np.float32])
def test_compiled_adc_pass_equals_quantise(dtype):
    # render() digitises each ping in one compiled pass (TVG, rounding, clipping, volts); it
    # must give exactly quantise()'s codes, flags and volts (the same IEEE operations in the
    # same order), here with samples beyond +/-FS on some channels and a record longer than
    # the kept samples (the FFT's padding).
    from acoustisim.synthesis.adc import adc_code_range
    from acoustisim.synthesis.ping_loops import digitise

    rng = np.random.default_rng(4)
    n = 5000
    signal = (rng.standard_normal((3, n + 77)) * [[0.2], [0.5], [0.05]]).astype(dtype)
    gain = np.linspace(1.0, 3.0, n)
    step = adc_step_v(1.0, 12)
    lowest, highest = adc_code_range(12)
    codes = np.empty((3, n), dtype=np.int16)
    volts = np.empty((3, n))
    clipped = np.empty(3, dtype=bool)
    digitise(signal, gain, step, lowest, highest, codes, volts, clipped)
    expected_codes, expected_clipped, _ = quantise(signal[:, :n].astype(np.float64) * gain, 12, 1.0)
    assert np.array_equal(codes, expected_codes)
    assert clipped.tolist() == expected_clipped.tolist() == [True, True, False]
    assert np.array_equal(volts, expected_codes * step)
    digitise(signal, np.empty(0), step, lowest, highest, codes, volts, clipped)  # no TVG
    assert np.array_equal(codes, quantise(signal[:, :n].astype(np.float64), 12, 1.0)[0])


def test_render_flags_clipping_per_ping_and_channel():
    # A ~30 V echo (1e5 Pa x -190 dB re 1 V/uPa) on the centre channel only, ADC range +/-10 mV,
    # no noise and no main bang: only that channel clips, in every ping.
    from acoustisim.propagation.paths import PathKind, empty_paths_array

    chain = ReceiverChain(
        main_bang_peak_v=0.0, thermal_noise=False, electrical_noise_v_per_rthz=0.0, interference_lines=(),
        adc_full_scale_v=0.01,
    )
    synth = PingSynthesiser.create(SonarHead(record_length_s=1e-3), Medium(), chain)
    rows = empty_paths_array(1)
    rows["channel"] = 1
    rows["kind"] = PathKind.SPECULAR
    rows["delay_s"] = 5e-4
    rows["geometric_gain"] = 1.0
    pings = synth.render(rows, seed=0, n_pings=2)
    assert pings.clipped.tolist() == [[False, True, False]] * 2
    assert pings.codes[:, 1].max() == 2047 and pings.codes[:, 1].min() == -2048
