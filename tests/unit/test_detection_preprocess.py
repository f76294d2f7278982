"""Pre-processing: ping averaging (seed eq. 4.33) and the zero-phase band-pass."""

from __future__ import annotations

import numpy as np
import pytest

from binsonar.detection import detect
from binsonar.preprocess import average_pings, bandpass, butterworth_bandpass_power, template_band_hz
from binsonar.recording import RecordingError
from support.detection_signals import FS, echo_rows, noise_sigma_for, pulse_template

N = 4096


def test_averaging_n_pings_divides_the_noise_variance_by_n():
    # 16 pings of the same echo with independent noise: the average keeps the echo exactly and
    # its noise variance is 1/16 (measured over 3 x 4096 samples: relative standard error of
    # a variance estimate 1/sqrt(6144) = 1.3 %, tolerance 6 %).
    rng = np.random.default_rng(41)
    clean = echo_rows(np.array([50e-6, 51e-6, 52e-6]), N)
    noise = rng.standard_normal((16, 3, N))
    averaged = average_pings(clean[np.newaxis] + noise)
    assert averaged.shape == (1, 3, N)
    residual = averaged[0] - clean
    assert abs(residual.var() * 16 - 1) < 0.06
    with pytest.raises(RecordingError):
        average_pings(np.zeros((3, N)))


def test_bandpass_is_zero_phase_so_the_tof_is_unbiased():
    # A band-pass narrower than the pulse reshapes it, but a zero-phase (real) response keeps
    # its envelope symmetric about the same instant: the matched filter's TOF on the filtered,
    # noise-free echo stays within 0.1 ns of the truth at every fractional delay.
    delays = 40e-6 + np.arange(9) * 5.1e-9
    rows = echo_rows(delays, N)
    filtered = bandpass(rows, FS, 400e3, 600e3, order=4)
    result = detect(filtered.reshape(-1, 3, N), "matched", sample_rate_hz=FS, template=pulse_template())
    tofs = np.array([ch[0].tof_s for ping in result.echoes for ch in ping])
    assert np.max(np.abs(tofs - delays)) < 0.1e-9


def test_bandpass_response_is_the_squared_butterworth_magnitude():
    # Sinusoids through the filter (long record, steady state in the middle) come out scaled by
    # |H|^2 of the analog Butterworth band-pass: 1 at sqrt(low high), 1/2 at the -3 dB edges.
    n = 1 << 16
    t = np.arange(n) / FS
    low, high = 300e3, 800e3
    for f in (np.sqrt(low * high), low, high, 100e3, 2e6):
        f = float(f)
        x = np.cos(2 * np.pi * f * t)
        y = bandpass(x, FS, low, high, order=4)
        middle = slice(n // 4, 3 * n // 4)
        gain = np.sqrt(2 * np.mean(y[middle] ** 2))
        expected = float(butterworth_bandpass_power(np.array([f]), low, high, 4)[0])
        assert abs(gain - expected) < 1e-3 + 0.01 * expected
    assert abs(float(butterworth_bandpass_power(np.array([low]), low, high, 4)[0]) - 0.5) < 1e-12


def test_bandpass_raises_the_snr_of_an_out_of_band_noisy_echo():
    # White noise over 0-10 MHz, echo band ~0.15-0.85 MHz: band-passing to the template's
    # -20 dB band removes ~90 % of the noise power; the threshold detector then finds echoes
    # it missed (seed methods 1 versus 5), at 2E/N0 = 25 dB.
    rng = np.random.default_rng(42)
    k = 60
    delays = rng.uniform(40e-6, 150e-6, k)
    records = echo_rows(delays, N) + rng.standard_normal((k, N)) * noise_sigma_for(25.0)
    low, high = template_band_hz(pulse_template().samples, FS)
    assert 100e3 < low < 250e3 and 750e3 < high < 900e3
    plain = detect(records.reshape(-1, 3, N), "seed-1", sample_rate_hz=FS, template=pulse_template())
    filtered = detect(records.reshape(-1, 3, N), "seed-5", sample_rate_hz=FS, template=pulse_template())

    def found(result):
        tofs = np.array([ch[0].tof_s if ch else np.nan for ping in result.echoes for ch in ping])
        return int(np.sum(np.abs(tofs - delays) < 3e-6))

    assert found(filtered) > found(plain) + 10


def test_bad_band_is_rejected():
    with pytest.raises(RecordingError, match="bandpass"):
        bandpass(np.zeros(100), FS, 600e3, 400e3)
    with pytest.raises(RecordingError, match="bandpass_hz"):
        detect(np.zeros((3, N)), "matched", sample_rate_hz=FS, template=pulse_template(), bandpass_hz=(1.0, 2.0, 3.0))


def test_seed_comparison_reruns_the_nine_combinations():
    # 20 pings of one position at a low SNR (2E/N0 = 8 dB per ping, 21 dB after averaging):
    # the seed's ordering must appear, matched-filter combinations on averaged pings correct
    # everywhere and more often right than the single-waveform threshold detector.
    from binsonar.detection.comparison import compare_seed_methods

    rng = np.random.default_rng(43)
    delays = np.array([80e-6, 81e-6, 82e-6])
    clean = echo_rows(delays, N)
    pings = clean[np.newaxis] + rng.standard_normal((20, 3, N)) * noise_sigma_for(8.0)
    rows = compare_seed_methods(pings, delays, sample_rate_hz=FS, template=pulse_template())
    by_name = {row.method: row for row in rows}
    assert [row.method for row in rows] == [f"seed-{k}" for k in range(1, 10)]
    for name in ("seed-4", "seed-8", "seed-9"):
        assert by_name[name].correct_rate == 1.0
        assert by_name[name].mean_abs_error_s < 0.2e-6
    assert by_name["seed-1"].correct_rate < by_name["seed-4"].correct_rate
    assert all(row.seconds_per_position > 0 for row in rows)
