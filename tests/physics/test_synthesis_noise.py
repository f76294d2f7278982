"""Noise of synthesised pings: SNR definition, noise spectra, ping-to-ping level, main bang."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import signal

from acoustisim.errors import InputError
from acoustisim.medium import Medium
from acoustisim.propagation.paths import PathKind, empty_paths_array
from acoustisim.sonar import SonarHead
from acoustisim.synthesis import InterferenceLine, PingSynthesiser, ReceiverChain
from acoustisim.synthesis.noise import mellen_thermal_noise_psd_pa2_per_hz

FS = 20e6


def one_echo(delay=2.0e-3, gain=2e-3, channels=(0, 1, 2)):
    rows = empty_paths_array(len(channels))
    rows["path_id"] = 0
    rows["channel"] = channels
    rows["kind"] = PathKind.SPECULAR
    rows["order"] = 1
    rows["delay_s"] = delay
    rows["geometric_gain"] = gain
    return rows


def short_sonar(record_length_s=2.5e-3):
    return SonarHead(record_length_s=record_length_s)


def test_mellen_thermal_noise_level():
    # physics.md: 39 dB re 1 uPa^2/Hz at 500 kHz; +6 dB per octave.
    level = 10 * np.log10(mellen_thermal_noise_psd_pa2_per_hz([500e3, 1e6]) / 1e-12)
    assert level[0] == pytest.approx(-15 + 20 * np.log10(500), abs=1e-9)
    assert level[1] - level[0] == pytest.approx(6.02, abs=0.01)


def test_snr_db_sets_2e_over_n0_of_the_echo():
    sonar = short_sonar()
    chain = ReceiverChain(main_bang_peak_v=0.0)
    synth = PingSynthesiser.create(sonar, Medium(), chain)
    rows = one_echo()
    snr_db = 12.0
    pings = synth.render(rows, seed=3, n_pings=12, snr_db=snr_db, snr_rows=(rows[:1], rows[1:2], rows[2:]))
    energy = np.sum(pings.clean**2, axis=1)  # only the echo is deterministic here
    noise = pings.volts - pings.clean
    measured = 10 * np.log10(energy / np.mean(noise**2, axis=(0, 2)))
    # 12 pings x 50000 samples: the variance estimate is good to 0.03 dB; the 0.3 dB of the
    # issue also covers the quantisation noise (step^2/12, 1e-5 of sigma^2 here).
    assert np.all(np.abs(measured - snr_db) < 0.3)
    # Noise is white and independent between pings: neighbouring samples and pings uncorrelated.
    assert abs(np.corrcoef(noise[0, 1, :-1], noise[0, 1, 1:])[0, 1]) < 0.02
    assert abs(np.corrcoef(noise[0, 1], noise[1, 1])[0, 1]) < 0.02


def test_snr_needs_an_existing_echo():
    synth = PingSynthesiser.create(short_sonar(), Medium(), ReceiverChain())
    rows = one_echo(delay=5e-3)  # past the 2.5 ms record: no energy inside
    with pytest.warns(UserWarning, match="too short"):
        with pytest.raises(InputError, match="no energy"):
            synth.render(rows, snr_db=10.0, snr_rows=(rows[:1], rows[1:2], rows[2:]))
    with pytest.raises(InputError, match="snr_db"):
        synth.render(one_echo(), snr_db=float("nan"), snr_rows=(rows[:1], rows[1:2], rows[2:]))


def test_electrical_noise_spectrum_follows_the_model():
    # Broadband electrical noise only: its measured PSD at the ADC equals the model's
    # S(f) |gain H(f)|^2 (checks the frequency-domain draw's scaling end to end).
    sonar = short_sonar(5e-3)
    chain = ReceiverChain(
        main_bang_peak_v=0.0,
        thermal_noise=False,
        interference_lines=(),
        electrical_noise_level_sigma_db=0.0,
        attenuation_db=(30.0, 30.0, 30.0),
    )
    synth = PingSynthesiser.create(sonar, Medium(), chain)
    pings = synth.render(one_echo()[:0], seed=1, n_pings=4)
    f, psd = signal.welch(pings.volts.reshape(-1, pings.volts.shape[-1]), FS, nperseg=2048, axis=-1)
    psd = psd.mean(axis=0)
    from acoustisim.synthesis.noise import electrical_noise_psd_v2_per_hz

    model = electrical_noise_psd_v2_per_hz(f, chain) * np.abs(chain.bandpass_response(f)) ** 2 * chain.net_gain[0] ** 2
    band = (f > 300e3) & (f < 1.5e6)
    ratio_db = 10 * np.log10(psd[band] / model[band])
    # 12 channel-records x 48 Welch segments: each bin's estimate has ~0.3 dB std; the mean over
    # the band is good to 0.05 dB, single bins to about 1.2 dB (4 sigma).
    assert abs(np.mean(ratio_db)) < 0.15
    assert np.max(np.abs(ratio_db)) < 1.5


def test_interference_lines_and_ping_to_ping_level():
    sonar = short_sonar()
    line = InterferenceLine(400e3, 2e-3)
    chain = ReceiverChain(main_bang_peak_v=0.0, thermal_noise=False, interference_lines=(line,))
    synth = PingSynthesiser.create(sonar, Medium(), chain)
    pings = synth.render(one_echo()[:0], seed=5, n_pings=40)
    f, psd = signal.welch(pings.volts[:, 1], FS, nperseg=4096, axis=-1)
    mean_psd = psd.mean(axis=0)
    at_line = mean_psd[np.argmin(np.abs(f - 400e3))]
    nearby = np.median(mean_psd[(f > 300e3) & (f < 500e3)])
    assert at_line > 30 * nearby  # the line stands well out of the broadband noise
    power_db = 10 * np.log10(np.mean(pings.volts[:, 1] ** 2, axis=-1))
    # Log-normal level with sigma 3 dB: the 40-ping sample std lies in [2, 4] dB with
    # probability > 0.999 (chi distribution with 39 degrees of freedom).
    assert 2.0 < np.std(power_db, ddof=1) < 4.0


def test_noise_is_dominated_by_electrical_noise_by_default():
    # The seed: electrical noise "many orders of magnitude larger" than thermal noise.
    sonar = short_sonar()
    medium = Medium()
    both = PingSynthesiser.create(sonar, medium, ReceiverChain(main_bang_peak_v=0.0, interference_lines=(),
                                                               electrical_noise_level_sigma_db=0.0))
    thermal_only = PingSynthesiser.create(
        sonar, medium, ReceiverChain(main_bang_peak_v=0.0, electrical_noise_v_per_rthz=0.0, interference_lines=())
    )
    p_both = np.var(both.render(one_echo()[:0], seed=2).volts)
    p_thermal = np.var(thermal_only.render(one_echo()[:0], seed=2).volts)
    assert 10 * np.log10(p_both / max(p_thermal, 1e-30)) > 20.0


def test_main_bang_and_crosstalk_at_time_zero():
    sonar = short_sonar()
    chain = ReceiverChain(thermal_noise=False, electrical_noise_v_per_rthz=0.0, interference_lines=())
    synth = PingSynthesiser.create(sonar, Medium(), chain)
    clean = synth.render(one_echo()[:0], seed=0).clean
    early = np.abs(clean[:, : int(20e-6 * FS)]).max(axis=1)
    late = np.abs(clean[:, int(100e-6 * FS) :]).max(axis=1)
    # main_bang_peak_v is the unfiltered peak; the 2 MHz low-pass rounds the abrupt onset off
    # and lowers the first peak by 10-20 %.
    assert 0.75 * chain.main_bang_peak_v < early[1] < chain.main_bang_peak_v
    assert early[0] / early[1] == pytest.approx(10 ** (chain.crosstalk_db / 20), rel=1e-6)
    assert np.all(late < 1e-6 * early[1])  # rung down long before the first echo


def test_noise_variance_equals_the_integrated_model():
    # The per-ping noise bins are drawn in single precision (float32 normal deviates, scaled
    # and inverse-FFT'd in float32): the ADC-input variance must still be the model's one-sided
    # PSD integrated over 0..fs/2, electrical plus thermal, times |gain H(f)|^2, plus the
    # quantisation noise step^2/12 -- computed here independently of the rfft grid by the
    # trapezoid rule on a fine grid.
    from acoustisim.synthesis.adc import adc_step_v
    from acoustisim.synthesis.noise import electrical_noise_psd_v2_per_hz, thermal_noise_psd_v2_per_hz

    sonar = short_sonar()
    medium = Medium()
    chain = ReceiverChain(
        main_bang_peak_v=0.0,
        interference_lines=(),
        electrical_noise_level_sigma_db=0.0,
        electrical_noise_v_per_rthz=2e-9,  # thermal and electrical of comparable size
        attenuation_db=(0.0, 0.0, 0.0),
        adc_full_scale_v=0.05,  # a fine step: the quantisation noise is a small correction
    )
    synth = PingSynthesiser.create(sonar, medium, chain)
    pings = synth.render(one_echo()[:0], seed=11, n_pings=6)
    f = np.linspace(0.0, FS / 2, 400001)
    psd = electrical_noise_psd_v2_per_hz(f, chain) + thermal_noise_psd_v2_per_hz(
        f, chain, sonar.piston_radius_m, medium.sound_speed
    )
    thermal_share = np.trapezoid(thermal_noise_psd_v2_per_hz(f, chain, sonar.piston_radius_m, medium.sound_speed)
                                 * np.abs(chain.bandpass_response(f)) ** 2, f) / np.trapezoid(
        psd * np.abs(chain.bandpass_response(f)) ** 2, f)
    assert 0.2 < thermal_share < 0.8  # both parts are tested
    step = adc_step_v(chain.adc_full_scale_v, sonar.adc_bits)
    for c in range(3):
        model = np.trapezoid(psd * np.abs(chain.bandpass_response(f)) ** 2, f) * chain.net_gain[c] ** 2
        model += step**2 / 12.0
        assert model > 100 * step**2  # well above the quantisation step
        measured = np.var(pings.volts[:, c])
        # 6 pings x 50000 samples of noise band-limited to ~2 MHz (fs 20 MHz): >= 6e4
        # independent samples, a variance estimate good to sqrt(2 / 6e4) = 0.6 %; 3 % is
        # 5 sigma. A wrong bin scaling (a factor 2 in power, a missed thermal part) is >= 20 %.
        assert measured == pytest.approx(model, rel=0.03)
