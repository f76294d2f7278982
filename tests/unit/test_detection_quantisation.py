"""ADC quantisation: noise below one code step must not look like no noise.

A recording stored as int16 codes whose noise is sub-LSB (sigma = 0.2 code steps) is exactly
constant over most quiet stretches: only about 1.2 % of its samples (|n| > 0.5 step, 2.5
sigma) differ from zero. Its noise estimates must be floored at the quantisation noise
q / sqrt(12) (``Signals.noise_floor_v``), or the detectors see a noise-free record: a zero TOF
std, SNRs of 150 dB and more, CFAR echoes on every isolated code flip, a threshold at zero.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from binsonar.bounds import tof_crlb_s
from binsonar.detection import detect
from binsonar.detection.inputs import as_signals
from binsonar.detection.matched import envelope, filtered_spectrum, plan_matched, white_noise_power
from binsonar.recording import Recording, RecordingError
from support.detection_signals import FS, echo_rows, pulse_energy, pulse_template

Q = 1.0 / 2048  # volts per code
N = 8192
DELAY = 200e-6
AMPLITUDE = 0.5  # V: 1024 codes, far from the int16 full scale
SIGMA_Q = Q / math.sqrt(12.0)


def _quantised_recording(seed: int = 7) -> Recording:
    rng = np.random.default_rng(seed)
    clean = echo_rows(np.full(3, DELAY), N, AMPLITUDE)
    codes = np.rint((clean + rng.standard_normal(clean.shape) * 0.2 * Q) / Q).astype(np.int16)
    return Recording(waveforms=codes[np.newaxis] * Q, sample_rate_hz=FS, template=pulse_template(),
                     volts_per_code=Q, adc_bits=16)


def test_signals_carry_the_quantisation_noise_floor():
    rec = _quantised_recording()
    assert as_signals(rec).noise_floor_v == pytest.approx(SIGMA_Q, rel=1e-12)
    # A float array has no known step unless given one.
    assert as_signals(rec.waveforms[0], FS).noise_floor_v == 0.0
    assert as_signals(rec.waveforms[0], FS, adc_step_v=Q).noise_floor_v == pytest.approx(SIGMA_Q, rel=1e-12)
    with pytest.raises(RecordingError, match="adc_step_v"):
        as_signals(rec.waveforms[0], FS, adc_step_v=-1.0)


def test_white_noise_power_is_the_analytic_filter_output_power():
    # E|z|^2 = 2 sigma^2 sum s^2 for the analytic correlation with a real template. Checked on
    # 12 x 16384 samples of white noise: the mean of |z|^2 over the record is an average of
    # about 12 x 16384 / 30 = 6500 independent exponentials (correlation time ~1.5 us = 30
    # samples), a relative standard error of 1.2 %: 5 % is 4 standard errors.
    n = 16384
    plan = plan_matched(pulse_template(), n, FS)
    sigma = 0.3
    # Parseval over the plan's kept bins: the band edge and the DC bin (weighted once: the
    # analytic signal's DC is not doubled) move the sum by 5e-7 of it; 1e-5 allows for that.
    assert float(white_noise_power(plan, sigma)) == pytest.approx(2 * sigma ** 2 * pulse_energy(), rel=1e-5)
    noise = np.random.default_rng(3).standard_normal((12, n)) * sigma
    z = envelope(plan, filtered_spectrum(plan, noise))
    measured = float(np.mean(z.real ** 2 + z.imag ** 2))
    assert measured == pytest.approx(float(white_noise_power(plan, sigma)), rel=0.05)
    # The same Parseval sum for a weighted (whitened) plan: a flat PSD P scales the weights
    # by 1 / P, the output power by 1 / P^2.
    psd = 4.0
    weighted = plan_matched(pulse_template(), n, FS, lambda f: np.full(np.shape(f), psd))
    z_w = envelope(weighted, filtered_spectrum(weighted, noise))
    measured_w = float(np.mean(z_w.real ** 2 + z_w.imag ** 2))
    assert measured_w == pytest.approx(float(white_noise_power(weighted, sigma)), rel=0.05)
    # (1e-7: the plain plan's template spectrum comes from a float32 FFT, relative errors ~1e-7
    # of its peak, measured 1.6e-9 on this sum; the weighted plan's from a float64 one.)
    assert float(white_noise_power(weighted, sigma)) == pytest.approx(
        float(white_noise_power(plan, sigma)) / psd ** 2, rel=1e-7)


def _echoes(result):
    return [e for channels in result.echoes for echoes in channels for e in echoes]


def test_matched_filter_snr_and_tof_std_use_the_quantisation_floor():
    result = detect(_quantised_recording(), "matched")
    echoes = _echoes(result)
    assert len(echoes) == 3
    # Expected 2E/N0 with the floor as the noise: a^2 E_s / sigma_q^2 (83.3 dB). The quantised
    # echo's own peak differs from the analytic one by the rounding error correlated with the
    # template (< 1e-3 relative here) and the real sub-LSB noise sits below the floor, so 0.1 dB.
    expected_db = 10 * math.log10(AMPLITUDE ** 2 * pulse_energy() / SIGMA_Q ** 2)
    for e in echoes:
        assert abs(e.snr_db - expected_db) < 0.1
        assert e.tof_std_s > 0.0
        assert e.tof_std_s == pytest.approx(float(tof_crlb_s(10 ** (e.snr_db / 10), 118.2e3)), rel=0.01)
        assert abs(e.tof_s - DELAY) < 1e-9  # 1 ns: the 83 dB CRLB is 0.1 ns


@pytest.mark.parametrize("method", ["ca-cfar", "os-cfar"])
def test_cfar_reports_only_the_echo_on_sub_lsb_noise(method):
    result = detect(_quantised_recording(), method)
    for channels in result.echoes:
        for echoes in channels:
            assert len(echoes) == 1, [e.tof_s for e in echoes]
            assert abs(echoes[0].tof_s - DELAY) < 1e-9
            assert echoes[0].tof_std_s > 0.0


def test_threshold_fires_on_the_echo_not_on_the_first_sample():
    result = detect(_quantised_recording(), "threshold")
    for e in _echoes(result):
        # 6 sigma_q = 1.7 code steps: crossed on the echo's rising edge, within 5 us (the
        # template's half-length) before its peak; sub-LSB noise never reaches 2 steps.
        assert DELAY - 5e-6 < e.tof_s < DELAY
        assert e.score < 1e4  # peak 1024 codes over a 1.7-code level: about 600
        assert e.tof_std_s > 0.0


@pytest.mark.parametrize("method", ["local-matched", "whitened-matched", "energy", "dwt"])
def test_other_detectors_see_one_echo_with_a_finite_snr(method):
    result = detect(_quantised_recording(), method)
    echoes = _echoes(result)
    assert len(echoes) == 3
    expected_db = 10 * math.log10(AMPLITUDE ** 2 * pulse_energy() / SIGMA_Q ** 2)
    for e in echoes:
        # The echo timing of the coarse detectors (energy, dwt) is within a cell (~1 us).
        assert abs(e.tof_s - DELAY) < 1e-6
        # None sees more than the floor allows (+1 dB for their rougher SNR estimates).
        assert e.snr_db < expected_db + 1.0
        assert e.tof_std_s != 0.0


def test_whitened_matched_on_a_dead_channel():
    # An all-zero channel has a zero noise spectrum: whitening would divide by zero. Without a
    # known ADC step that is an error naming the problem; with one, the PSD is floored at the
    # quantisation noise's 2 sigma_q^2 / fs and the dead channel simply has no echo.
    rng = np.random.default_rng(5)
    x = echo_rows(np.full(3, DELAY), N, AMPLITUDE) + rng.standard_normal((3, N)) * 1e-3
    x[1] = 0.0
    with pytest.raises(RecordingError, match="no noise"):
        detect(x, "whitened-matched", sample_rate_hz=FS, template=pulse_template())
    result = detect(x, "whitened-matched", sample_rate_hz=FS, template=pulse_template(), adc_step_v=Q)
    assert result.echoes[0][1] == ()
    for c in (0, 2):
        (echo,) = result.echoes[0][c]
        # 2E/N0 = 66 dB: CRLB 0.65 ns; 5 ns is ~8 of them (the whitening filter is itself
        # estimated from this noisy record, so its TOF is not quite efficient).
        assert abs(echo.tof_s - DELAY) < 5e-9
