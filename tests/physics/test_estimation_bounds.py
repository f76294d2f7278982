"""Cramer-Rao bounds of ``binsonar.estimation`` against analytic answers and independent methods
(binsonar's tests need no simulator: the echoes are the thesis pulse, ``support.detection_signals``)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from binsonar.bounds import rms_bandwidth_hz, tof_crlb_s
from binsonar.estimation import (
    analytic_correlation,
    echo_tof_crlb_s,
    interference_snr,
    matched_snr,
    noise_bound,
    point_bound,
    reverberation_bound,
)
from support.detection_signals import FS, pulse_template

GEOMETRY = (1.0, 2.0, 1482.0, 0.065)  # range (m), bearing (deg), sound speed (m/s), half baseline (m)


def test_echo_crlb_is_the_template_bound_in_white_noise_and_scales_with_the_noise_psd() -> None:
    # Independent method: the white-noise bound 1 / (2 pi beta sqrt(2E/N0)) from the template's RMS
    # bandwidth and sum(s^2) / sigma^2, for a Gaussian pulse in white noise of known variance.
    fs, n, sigma = 20e6, 1 << 16, 1e-3
    t = (np.arange(n) - n / 2) / fs
    pulse = 0.01 * np.exp(-((t / 2.5e-6) ** 2)) * np.cos(2 * np.pi * 500e3 * t)
    noise = np.random.default_rng(1).normal(0.0, sigma, (1, n))
    expected = tof_crlb_s(np.sum(pulse**2) / sigma**2, rms_bandwidth_hz(pulse, fs))
    std, snr_db = echo_tof_crlb_s(pulse[np.newaxis], noise, fs)
    # Welch over 128 segments: the in-band PSD estimate is good to ~1 %; 3 % margin.
    assert std[0] == pytest.approx(float(expected), rel=0.03)
    assert snr_db[0] == pytest.approx(10 * np.log10(np.sum(pulse**2) / sigma**2), abs=0.15)
    # Four times the noise power: twice the bound.
    std4, _ = echo_tof_crlb_s(pulse[np.newaxis], 2.0 * noise, fs)
    assert std4[0] == pytest.approx(2.0 * std[0], rel=1e-9)


def test_analytic_correlation_is_the_direct_sum_with_the_analytic_template() -> None:
    # Independent method: z[k] = sum_t x[k + t] conj(a[t]) summed directly at a few lags.
    from scipy.signal import hilbert

    template = pulse_template().samples
    rng = np.random.default_rng(4)
    x = rng.standard_normal((2, 900))
    z = analytic_correlation(x, template)
    assert z.shape == (2, 900 - template.size + 1)
    a = hilbert(template)
    for k in (0, 123, 699):
        direct = np.sum(x[:, k:k + template.size] * np.conj(a), axis=1)
        assert np.allclose(z[:, k], direct, rtol=1e-12, atol=1e-10)  # FFT rounding of ~200-term sums


def test_matched_snr_is_2e_over_n0_for_the_template_in_white_noise() -> None:
    # Analytic answer: for the template in white noise of variance s^2, 2 max|z_s|^2 / mean|z_n|^2
    # = sum(s^2) / s^2. mean|z_n|^2 = 2 s^2 sum(s^2) is estimated over ~30,000 correlated lags
    # (~150 independent values a pulse length apart, times 3 channels): ~3 % standard error; 10 %.
    template = pulse_template().samples
    sigma = 0.05
    echo = np.zeros((3, 30_000))
    echo[:, 10_000:10_000 + template.size] = template
    noise = np.random.default_rng(2).normal(0.0, sigma, echo.shape)
    snr = matched_snr(echo, noise, template)
    assert snr == pytest.approx(np.full(3, np.sum(template**2) / sigma**2), rel=0.1)
    # Without interference, the interference SNR is this one exactly (the same sums).
    none = interference_snr(echo, noise, [np.zeros_like(noise)], template)
    assert np.array_equal(none.snr, snr) and np.all(none.interference_level == 0.0)


def test_point_bound_is_the_jacobian_propagation_of_the_localiser() -> None:
    # Independent method: the Jacobian of the seed's point solution (range, bearing) from the two
    # path lengths by central differences (steps of 1 um: truncation ~1e-12 relative), propagated
    # as J diag(sigma_L^2) J^T.
    from binsonar.localization.point import point_from_path_lengths, seed_path_lengths

    r, bearing_deg, c, d = 1.3, 7.0, 1482.0, 0.065
    left, right = (float(v) for v in seed_path_lengths(r, math.radians(bearing_deg), d))
    h = 1e-6
    jacobian = np.empty((2, 2))
    for j, (dl, dr) in enumerate(((h, 0.0), (0.0, h))):
        plus = point_from_path_lengths(left + dl, right + dr, d)
        minus = point_from_path_lengths(left - dl, right - dr, d)
        jacobian[:, j] = (np.asarray(plus, dtype=float) - np.asarray(minus, dtype=float)) / (2 * h)
    stds_s = (3e-9, 5e-9)
    covariance = jacobian @ np.diag((c * np.asarray(stds_s)) ** 2) @ jacobian.T
    bound = point_bound(*stds_s, r, bearing_deg, c, d)
    assert bound.range_m == pytest.approx(math.sqrt(covariance[0, 0]), rel=1e-6)
    assert bound.bearing_deg == pytest.approx(math.degrees(math.sqrt(covariance[1, 1])), rel=1e-6)


N_GATE = 8000
ECHO_AT = 4000


def _echo_in_noise(seed: int = 3) -> tuple:
    """An echo (the template at sample ``ECHO_AT``) in white noise, over an ``N_GATE``-sample gate."""
    template = pulse_template().samples
    rng = np.random.default_rng(seed)
    echo = np.zeros((3, N_GATE))
    for ch in range(3):
        echo[ch, ECHO_AT:ECHO_AT + template.size] = 5e-3 * template / np.max(np.abs(template))
    noise = 1e-4 * rng.standard_normal((3, N_GATE))
    return echo, noise, template, rng


def test_noise_bound_is_the_white_noise_crlb_propagated() -> None:
    # The measured bound is binsonar.bounds' CRLB at matched_snr's SNR, through point_bound.
    echo, noise, template, _ = _echo_in_noise()
    bound = noise_bound(echo, noise, template, FS, *GEOMETRY)
    std = tof_crlb_s(matched_snr(echo, noise, template), rms_bandwidth_hz(template, FS))
    assert bound.measured == point_bound(std[0], std[2], *GEOMETRY)
    assert bound.snr_db == tuple(float(v) for v in 10 * np.log10(matched_snr(echo, noise, template)))
    optimal, _ = echo_tof_crlb_s(echo, noise, FS)
    assert bound.optimal == point_bound(optimal[0], optimal[2], *GEOMETRY)


def test_reverberation_bound_counts_the_reverberation_only_at_the_echo_s_delay() -> None:
    echo, noise, template, rng = _echo_in_noise()
    args = (template, FS, *GEOMETRY)
    plain = noise_bound(echo, noise, *args).measured
    # No reverberation: the noise-only bound (the same 2E/N0 as ``matched_snr``).
    zero = reverberation_bound(echo, noise, [np.zeros_like(noise)], *args)
    assert zero.bound.range_m == pytest.approx(plain.range_m, rel=1e-12)
    # Reverberation only well before the echo (outside one template length of its peak): unchanged.
    early = np.zeros_like(noise)
    early[:, :200] = 1e-2 * rng.standard_normal((3, 200))
    assert reverberation_bound(echo, noise, [early], *args).bound.range_m == pytest.approx(plain.range_m, rel=1e-9)
    # White reverberation as strong as the white noise, around the echo, raises the bound: with its
    # level at the matched filter's output equal to the noise's, 2E/N0 halves and the bound grows by
    # sqrt(2). The filter's output decorrelates over ~1 / (2 pi beta) = 1.3 us (27 samples): the
    # level over one template length (201 lags) of 64 realisations holds ~480 independent values
    # (4.5 % standard error), the noise's over the gate ~290 (6 %): the ratio scatters by ~0.4 dB
    # (largest of 111 channels over 37 seeds: 1.3 dB), so +/-1.5 dB; the bound's ratio to sqrt(2)
    # within 10 % (largest over those seeds: 4.3 %). A level counted twice (+3 dB) or not at all
    # (no change of the bound) fails both.
    scale = float(np.std(noise))
    reverbs = []
    for _ in range(64):
        r = np.zeros_like(noise)
        r[:, ECHO_AT - 150:ECHO_AT + 400] = scale * rng.standard_normal((3, 550))
        reverbs.append(r)
    out = reverberation_bound(echo, noise, reverbs, *args)
    assert all(-1.5 < v < 1.5 for v in out.reverb_to_noise_db)
    assert out.bound.range_m / plain.range_m == pytest.approx(math.sqrt(2.0), rel=0.1)
    # Averaging over realisations averages their levels: with as many zero ones, half the level.
    half = reverberation_bound(echo, noise, reverbs + [np.zeros_like(noise)] * 64, *args)
    assert np.allclose(np.subtract(out.reverb_to_noise_db, half.reverb_to_noise_db), 10 * np.log10(2.0), atol=1e-9)
    assert plain.range_m < half.bound.range_m < out.bound.range_m
