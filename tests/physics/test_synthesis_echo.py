"""Synthesised echoes against analytic answers: amplitude, delay, directivity, absorption."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import signal
from scipy.special import j1

from acoustisim.medium import Medium
from acoustisim.propagation.paths import PathKind, empty_paths_array
from acoustisim.sonar import SonarHead
from acoustisim.synthesis import PingSynthesiser, ReceiverChain
from support.waveforms import matched_filter

FS = 20e6
QUIET = dict(main_bang_peak_v=0.0, thermal_noise=False, electrical_noise_v_per_rthz=0.0, interference_lines=())


def rows_of(delays, gains, *, channels=None, angles_tx=0.0, angles_rx=0.0, lengths=0.0, phases=0.0):
    n = len(delays)
    rows = empty_paths_array(n)
    rows["path_id"] = np.arange(n)
    rows["channel"] = channels if channels is not None else np.ones(n, dtype=int)
    rows["kind"] = PathKind.SPECULAR
    rows["order"] = 1
    rows["delay_s"] = delays
    rows["geometric_gain"] = gains
    rows["angle_tx_rad"] = angles_tx
    rows["angle_rx_rad"] = angles_rx
    rows["path_length_m"] = lengths
    rows["phase_rad"] = phases
    return rows


@pytest.fixture(scope="module")
def medium():
    return Medium()


def test_plane_echo_matches_analytic_waveform_without_bandpass(medium):
    # A plane echo at 1.5 m (wall, R = 0.72): pressure factor R / (r1 + r2) on axis, no filter.
    sonar = SonarHead()
    chain = ReceiverChain(bandpass_low_hz=None, bandpass_high_hz=None, **QUIET)
    synth = PingSynthesiser.create(sonar, medium, chain)
    gain = 0.72 / 3.0
    delays = np.array([3.0 / medium.sound_speed + f / FS for f in (0.0, 0.37)])  # on and between samples
    rows = rows_of(delays, [gain, gain], channels=[0, 2])
    volts = synth.echo_volts(rows)
    t = np.arange(sonar.n_samples) / FS
    scale = chain.sensitivity_v_per_pa * chain.net_gain[0]
    for channel, delay in zip((0, 2), delays):
        analytic = scale * gain * sonar.pulse.waveform(t - delay)
        # The kernels drop the pulse's spectrum below -100 dB and work in complex64: a few 1e-6
        # of the peak; 1e-4 is a 0.001 dB amplitude bound.
        assert np.max(np.abs(volts[channel] - analytic)) < 1e-4 * np.max(np.abs(analytic))
        envelope = np.abs(signal.hilbert(volts[channel]))
        peak_db = 20 * np.log10(envelope.max() / (scale * gain * sonar.source_level_pa))
        assert abs(peak_db) < 0.1  # the tolerance; sampling a 500 kHz envelope peak costs < 0.01 dB
    assert np.all(volts[1] == 0.0)


@pytest.mark.parametrize("fraction", [0.13, 0.5, 0.77])
def test_matched_filter_delay_and_amplitude_with_bandpass(medium, fraction):
    # The causal band-pass delays the echo; the template carries the same chain and its t0_s,
    # so the matched filter's peak must land on the path delay (no TOF bias).
    sonar = SonarHead()
    chain = ReceiverChain(**QUIET)
    synth = PingSynthesiser.create(sonar, medium, chain)
    template, t0 = synth.template()
    gain = 0.72 / 3.0
    delay = 3.0 / medium.sound_speed + fraction / FS
    rows = rows_of([delay], [gain])
    volts = synth.echo_volts(rows)[1]
    tof, ratio = matched_filter(volts, template, FS, t0)
    assert abs(tof - delay) < 1e-9  # the 1 ns (a fiftieth of a sample)
    assert abs(20 * np.log10(ratio / gain)) < 0.1  # echo = gain x template: amplitude within 0.1 dB


def test_template_matches_an_independent_filter_simulation(medium):
    # Independent method: scipy's lsim of the same analog Butterworth on the analytic pulse.
    sonar = SonarHead()
    chain = ReceiverChain(**QUIET)
    template, t0 = PingSynthesiser.create(sonar, medium, chain).template()
    t = t0 + np.arange(template.size) / FS
    fine = np.arange(t[0], t[-1], 1.0 / (8 * FS))
    b_hp, a_hp = signal.butter(2, 2 * np.pi * chain.bandpass_low_hz, "highpass", analog=True)
    b_lp, a_lp = signal.butter(2, 2 * np.pi * chain.bandpass_high_hz, "lowpass", analog=True)
    system = (np.polymul(b_hp, b_lp), np.polymul(a_hp, a_lp))
    _, out, _ = signal.lsim(system, sonar.pulse.waveform(fine), fine - fine[0])
    expected = np.interp(t, fine, out) * chain.sensitivity_v_per_pa * chain.net_gain[1]
    # lsim's linear-hold integration at 160 MS/s of a 500 kHz pulse: errors ~1e-3 of the peak.
    assert np.max(np.abs(template - expected)) < 5e-3 * np.max(np.abs(expected))


def test_off_axis_echo_spectrum_is_pulse_times_both_directivities(medium):
    sonar = SonarHead()
    chain = ReceiverChain(bandpass_low_hz=None, bandpass_high_hz=None, **QUIET)
    synth = PingSynthesiser.create(sonar, medium, chain)
    theta = math.radians(8.0)
    gain = 0.05
    rows = rows_of([2.0e-3 + 0.3 / FS], [gain], angles_tx=theta, angles_rx=theta)
    volts = synth.echo_volts(rows)[1] / (chain.sensitivity_v_per_pa * chain.net_gain[1] * gain)
    f = np.fft.rfftfreq(volts.size, 1.0 / FS)
    measured = np.abs(np.fft.rfft(volts)) / FS
    k = 2 * np.pi * f / medium.sound_speed
    x = k * sonar.piston_radius_m * math.sin(theta)
    directivity = np.where(x > 0, 2 * j1(np.maximum(x, 1e-12)) / np.maximum(x, 1e-12), 1.0)
    expected = np.abs(sonar.pulse.spectrum(f)) * directivity**2
    band = expected >= 0.1 * expected.max()  # the -20 dB band of the off-axis echo
    assert band.sum() > 1000
    error_db = 20 * np.log10(measured[band] / expected[band])
    # 0.2 dB is the tolerance; the directivity table's error is < 0.03 dB here.
    assert np.max(np.abs(error_db)) < 0.2
    # Off axis is low-passed: at 8 deg the echo's spectral centroid is below the pulse's.
    pulse = np.abs(sonar.pulse.spectrum(f))
    assert np.sum(f * measured) / np.sum(measured) < np.sum(f * pulse) / np.sum(pulse) - 20e3


def test_absorption_over_18_m_of_fresh_water(medium):
    sonar = SonarHead()
    chain = ReceiverChain(bandpass_low_hz=None, bandpass_high_hz=None, **QUIET)
    synth = PingSynthesiser.create(sonar, medium, chain)
    delay = 18.0 / medium.sound_speed
    rows = rows_of([delay, delay], [0.1, 0.1], channels=[0, 2], lengths=[18.0, 0.0])
    volts = synth.echo_volts(rows)
    f = np.fft.rfftfreq(volts.shape[1], 1.0 / FS)
    spectra = np.abs(np.fft.rfft(volts, axis=1))
    band = spectra[2] >= 0.1 * spectra[2].max()
    measured_db = 20 * np.log10(spectra[2][band] / spectra[0][band])
    # Francois-Garrison for fresh water (S = 0): pure-water term A3 P3 f^2 dB/km, f in kHz.
    t, z = medium.temperature_c, medium.depth_m
    a3 = 4.937e-4 - 2.59e-5 * t + 9.11e-7 * t**2 - 1.50e-8 * t**3
    p3 = 1.0 - 3.83e-5 * z + 4.9e-10 * z * z
    expected_db = a3 * p3 * (f[band] / 1e3) ** 2 / 1e3 * 18.0
    # The absorption factor is computed in float32: 1e-6 relative, far below 0.01 dB.
    assert np.max(np.abs(measured_db - expected_db)) < 0.01
    at_500k = np.interp(500e3, f[band], measured_db)
    assert at_500k == pytest.approx(18 * 0.055, abs=0.01)  # physics.md: 0.055 dB/m at 500 kHz


def test_constant_phase_and_many_elements_sum_like_the_integral(medium):
    # A row with phase pi/2 (exp(+j pi/2) on positive frequencies) is minus the Hilbert
    # transform of the zero-phase echo; and many close-spaced elements of one path (as an edge
    # is discretised) sum like the continuous integral: the pulse convolved with a box.
    sonar = SonarHead()
    chain = ReceiverChain(bandpass_low_hz=None, bandpass_high_hz=None, **QUIET)
    synth = PingSynthesiser.create(sonar, medium, chain)
    delay = 1.0e-3 + 0.21 / FS
    volts = synth.echo_volts(rows_of([delay, delay], [0.1, 0.1], channels=[0, 2], phases=[0.0, 0.5 * np.pi]))
    hilbert = np.imag(signal.hilbert(volts[0]))
    assert np.max(np.abs(volts[2] + hilbert)) < 1e-3 * np.max(np.abs(volts[0]))
    n = 400
    spread = 2e-6
    element_delays = delay + (np.arange(n) + 0.5) * spread / n
    summed = synth.echo_volts(rows_of(element_delays, np.full(n, 1.0 / n)))[1]
    window = slice(int(0.99e-3 * FS), int(1.01e-3 * FS))
    t = np.arange(sonar.n_samples)[window] / FS
    fine = np.linspace(0.0, spread, 2001)
    box = np.trapezoid(sonar.pulse.waveform(t[:, None] - delay - fine[None, :]), fine, axis=1) / spread
    scale = chain.sensitivity_v_per_pa * chain.net_gain[1]
    # Midpoint rule with 400 elements vs trapezoid with 2000: both ~1e-4 of the peak.
    assert np.max(np.abs(summed[window] / scale - box)) < 2e-3 * np.max(np.abs(box))


def test_rows_behind_the_transducer_are_silent(medium):
    sonar = SonarHead()
    chain = ReceiverChain(bandpass_low_hz=None, bandpass_high_hz=None, **QUIET)
    synth = PingSynthesiser.create(sonar, medium, chain)
    volts = synth.echo_volts(rows_of([1e-3, 2e-3], [0.3, 0.3], angles_tx=[math.pi, 0.0], angles_rx=[0.0, 2.0]))
    assert np.all(volts == 0.0)
    # At exactly 90 deg (the direct path to a side receiver) the piston still radiates:
    # D = 2 J1(ka)/ka, 0.0087 at 500 kHz, strongly low-passed.
    grazing = synth.echo_volts(rows_of([1e-3], [1.0], angles_tx=0.5 * math.pi, angles_rx=0.5 * math.pi))[1]
    assert 0 < np.max(np.abs(grazing)) < 1e-2 * chain.sensitivity_v_per_pa * chain.net_gain[1] * sonar.source_level_pa


def test_many_rows_equal_the_sum_of_single_rows(medium):
    # Chunking, kernel-size classes, same-sample groups and the overlap-add are linear: 3000
    # random rows at once equal the sum of the same rows synthesised in three parts. Rows that
    # start on one sample have their float32 spectra summed before the inverse FFT (relative
    # rounding 6e-8 per addition, so a group's kernel differs from the sum of its rows' by
    # ~1e-7 of the group's peak): 1e-6 of the peak; a lost, doubled or misplaced row would be
    # O(1e-3) or more (3000 rows of similar weight).
    sonar = SonarHead()
    chain = ReceiverChain(**QUIET)
    synth = PingSynthesiser.create(sonar, medium, chain)
    rng = np.random.default_rng(7)
    n = 3000
    rows = rows_of(
        rng.uniform(1e-4, 12e-3, n),
        rng.normal(0, 0.01, n),
        channels=rng.integers(0, 3, n),
        angles_tx=rng.uniform(0, 1.5, n),
        angles_rx=rng.uniform(0, 1.5, n),
        lengths=rng.uniform(0, 18, n),
        phases=rng.uniform(0, 6.28, n),
    )
    together = synth.echo_volts(rows)
    parts = sum(synth.echo_volts(rows[i::3]) for i in range(3))
    assert np.max(np.abs(together - parts)) < 1e-6 * np.max(np.abs(together))


def test_user_chirp_pulse_lands_at_its_delay(medium):
    # A user-supplied sampled pulse (a Tukey-windowed 300-700 kHz chirp, 40 us) is synthesised
    # from its own band-limited spectrum: on a sample it reproduces the samples; between
    # samples the matched filter against the file's template finds the delay.
    from scipy.signal import chirp, windows

    from acoustisim.pulse import SampledPulse

    t = np.arange(int(40e-6 * FS)) / FS
    samples = 1e5 * chirp(t, 300e3, t[-1], 700e3) * windows.tukey(t.size, 0.25)
    pulse = SampledPulse(samples, FS, t0_s=-20e-6)  # reference instant in the middle
    sonar = SonarHead(custom_pulse=pulse, record_length_s=2e-3)
    chain = ReceiverChain(bandpass_low_hz=None, bandpass_high_hz=None, **QUIET)
    synth = PingSynthesiser.create(sonar, medium, chain)
    scale = chain.sensitivity_v_per_pa * chain.net_gain[1]
    delay = 1.0e-3  # exactly on sample 20000
    volts = synth.echo_volts(rows_of([delay], [0.1]))[1] / (scale * 0.1)
    first = int(round((delay + pulse.t0_s) * FS))
    # The tapered chirp's spectrum above the synthesised band (-100 dB) is all that is lost.
    assert np.max(np.abs(volts[first : first + t.size] - samples)) < 1e-3 * np.max(np.abs(samples))
    template, t0 = synth.template()
    delay = 1.0e-3 + 0.42 / FS
    volts = synth.echo_volts(rows_of([delay], [0.1]))[1]
    tof, ratio = matched_filter(volts, template, FS, t0)
    assert abs(tof - delay) < 1e-9
    assert abs(20 * np.log10(ratio / 0.1)) < 0.1


def test_rows_sharing_a_sample_keep_their_own_response(medium):
    # Rows on one channel that start on the same sample (close-spaced edge elements, speckle)
    # have their spectra summed before one inverse FFT, each with its own delay, weight,
    # directivities and absorption: the result equals one-row-at-a-time synthesis to float32
    # rounding (~1e-7 of the peak, see test_many_rows_equal_the_sum_of_single_rows). The rows
    # differ widely in angle (D from 1 to 0.1 at 500 kHz) and length, so a shared factor would
    # be off by tens of percent.
    sonar = SonarHead(record_length_s=2e-3)
    synth = PingSynthesiser.create(sonar, medium, ReceiverChain(**QUIET)).paths
    n = 120
    rows = rows_of(
        1.0e-3 + np.arange(n) * 2e-9,
        np.linspace(1.0, 0.5, n) / n,
        angles_tx=np.linspace(0.0, 0.3, n),
        angles_rx=np.linspace(0.25, 0.0, n),
        lengths=1.48 + np.arange(n) * 0.1,
        phases=np.linspace(0.0, 3.0, n),
    )
    fs_dec = synth.grid.sample_rate_hz / synth.grid.decimation
    assert np.unique(np.floor(rows["delay_s"] * fs_dec)).size <= 2  # they do share start samples
    together = synth.decimated_record(rows)
    exact = sum(synth.decimated_record(rows[i : i + 1]) for i in range(n))
    assert np.max(np.abs(together - exact)) < 1e-6 * np.max(np.abs(exact))



def test_rows_in_any_byte_order_and_layout(medium):
    # The compiled loops read the path columns in place (strided views of the structured rows);
    # rows in big-endian byte order (e.g. read back from a file) or as a non-contiguous slice
    # give the same record.
    synth = PingSynthesiser.create(SonarHead(record_length_s=2e-3), medium, ReceiverChain(**QUIET)).paths
    rng = np.random.default_rng(3)
    n = 40
    rows = rows_of(
        rng.uniform(1e-4, 1.5e-3, n), rng.normal(0, 0.1, n), channels=rng.integers(0, 3, n),
        angles_tx=rng.uniform(0, 1.0, n), angles_rx=rng.uniform(0, 1.0, n), lengths=rng.uniform(0, 2, n),
        phases=rng.uniform(0, 6.28, n),
    )
    native = synth.decimated_record(rows)
    assert np.max(np.abs(native)) > 0
    swapped = rows.astype(rows.dtype.newbyteorder(">"))
    assert np.array_equal(synth.decimated_record(swapped), native)
    halves = synth.decimated_record(rows[::2]) + synth.decimated_record(rows[1::2])
    # Float32 sums of same-sample spectra differ with the grouping (see
    # test_many_rows_equal_the_sum_of_single_rows): 1e-6 of the peak.
    assert np.max(np.abs(halves - native)) < 1e-6 * np.max(np.abs(native))
