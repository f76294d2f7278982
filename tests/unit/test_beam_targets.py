"""Beam-aware timing of the pipeline's targets: the TOF variance, the noise spectrum, refine_target.

The echoes are the independent frequency-domain construction of ``support.beam_echoes`` (the
Gaussian pulse's analytic spectrum, scipy's J1, exact delays); noise is drawn here.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from binsonar.bounds import rms_bandwidth_hz, tof_crlb_s
from binsonar.detection.echo import Echo
from binsonar.localization.beam_model import PistonTransducers
from binsonar.localization.beam_targets import (
    BeamSetup, NoiseSpectrum, PingNoise, refine_target, tof_variance_s2)
from support.beam_echoes import FS, C, POSITIONS, RADIUS, point_echoes, template

TRANSDUCERS = PistonTransducers.uniform(2 * RADIUS)
BOARD = np.tile([0.0, 1.0, 0.0], (3, 1))


def setup_for(t0: float) -> BeamSetup:
    return BeamSetup(TRANSDUCERS, template(), FS, t0, POSITIONS, C)


def echoes_at(tof: np.ndarray) -> tuple[Echo, Echo, Echo]:
    return tuple(Echo(ch, float(t), 1.0, 30.0, 2.0) for ch, t in enumerate(tof))  # type: ignore[return-value]


def test_white_noise_variance_is_the_crlb_of_the_filtered_echo() -> None:
    # Identity (module docstring): with P_k = P the variance is 1 / ((2 pi beta)^2 2E/N0), beta the
    # RMS bandwidth of |A|^2 about its centroid and 2E/N0 = 2 |z_s|^2 / (P sum |A|^2).
    f = np.linspace(300e3, 700e3, 201)
    a = np.exp(-((f - 480e3) / 90e3) ** 2) * (1 + 0.3 * (f - 480e3) / 200e3) * np.exp(0.4j)
    p, zs2 = 3.0, 2.5e4
    variance = tof_variance_s2(a[np.newaxis], np.full((1, f.size), p), f, np.array([zs2]))
    w = np.abs(a) ** 2
    beta = math.sqrt(np.sum(w * (f - np.sum(w * f) / w.sum()) ** 2) / w.sum())
    snr = 2 * zs2 / (p * w.sum())
    assert variance[0] == pytest.approx(float(tof_crlb_s(snr, beta)) ** 2, rel=1e-12)


def test_noise_spectrum_of_white_noise_ignores_the_echoes() -> None:
    # White noise of variance s^2 has the one-sided density 2 s^2 / fs. A strong echo in a few
    # segments moves a median by far less than a mean; left out by its detected time, not at all.
    rng = np.random.default_rng(1)
    s, n = 0.01, 40_000
    rows = s * rng.standard_normal((3, n))
    rows[:, 20_000:20_400] += 2.0 * np.sin(2 * np.pi * 5e5 * np.arange(400) / FS)
    for busy in (((), (), ()), tuple(np.array([20_200 / FS]) for _ in range(3))):
        spectrum = NoiseSpectrum.estimate(rows, FS, 0.0, busy, 30e-6)
        inband = (spectrum.frequency_hz > 3e5) & (spectrum.frequency_hz < 7e5)
        # 3 %: the median's scatter over ~80 segments and ~50 bins averaged is about 1 %.
        assert np.mean(spectrum.density[:, inband]) == pytest.approx(2 * s * s / FS, rel=0.03)


def _trials(target: np.ndarray, n_trials: int, colour: bool, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """TOF errors and reported stds (n, 3) of refine_target on noisy copies of a point echo."""
    rows, tof, t0 = point_echoes(target, BOARD)
    energy = np.sum(rows ** 2, axis=1)
    rng = np.random.default_rng(seed)
    setup = setup_for(t0)
    errors, stds = [], []
    f = np.fft.rfftfreq(rows.shape[1], 1.0 / FS)
    # Coloured: PSD ∝ (f / 500 kHz)^4 (5x across the band), the white one's at 500 kHz.
    shape = (f / 5e5) ** 2 if colour else np.ones_like(f)
    sigma = np.sqrt(energy / 10 ** 3.0)[:, np.newaxis]  # white: 2E/N0 = 30 dB on each channel
    for _ in range(n_trials):
        noise = np.fft.irfft(np.fft.rfft(rng.standard_normal(rows.shape), axis=1) * shape, rows.shape[1], axis=1)
        x = rows + sigma * noise
        ping = PingNoise(x, FS, t0, tuple(np.array([t]) for t in tof), setup.busy_half_width_s)
        refined = refine_target(echoes_at(tof + 40e-9), setup, ping, "point")
        assert refined is not None and refined.model == "point"
        errors.append([e.tof_s for e in refined.echoes] - tof)
        stds.append([e.tof_std_s for e in refined.echoes])
    return np.array(errors), np.array(stds)


@pytest.mark.parametrize("colour", [False, True], ids=["white", "coloured"])
def test_reported_tof_std_is_honest_near_the_first_null(colour: bool) -> None:
    # 0.5 m at 3 deg: the left receiver sees the target 10.3 deg off its axis, at the 500 kHz null's
    # door (11 deg): its echo is weaker and narrower in band than the template. 300 noisy copies:
    # the errors are unbiased (3 standard errors) and var(error / reported std) is 1 within 0.25
    # (its sampling std is sqrt(2/300) = 0.08), white or coloured (PSD ∝ f^4) noise alike.
    target = 0.5 * np.array([math.sin(math.radians(3.0)), math.cos(math.radians(3.0)), 0.0])
    errors, stds = _trials(target, 300, colour, seed=7 if colour else 3)
    se = errors.std(axis=0, ddof=1) / math.sqrt(errors.shape[0])
    assert np.all(np.abs(errors.mean(axis=0)) < 3 * se)
    assert np.var(errors / stds, axis=0, ddof=1) == pytest.approx(np.ones(3), abs=0.25)
    # The left echo's std exceeds the on-axis template's CRLB at the same 2E/N0: its band narrows.
    plain = float(tof_crlb_s(1e3, rms_bandwidth_hz(template().samples, FS)))
    if not colour:
        assert np.mean(stds[:, 0]) > 1.1 * plain


def test_refine_target_needs_two_sides_to_locate() -> None:
    target = 0.8 * np.array([0.0, 1.0, 0.0])
    rows, tof, t0 = point_echoes(target, BOARD)
    setup = setup_for(t0)
    ping = PingNoise(rows + 1e-6 * np.random.default_rng(0).standard_normal(rows.shape), FS, t0,
                     ((), (), ()), setup.busy_half_width_s)
    only_left = (Echo(0, float(tof[0]), 1.0, 30.0, 2.0), None, None)
    assert refine_target(only_left, setup, ping, "point") is None
    refined = refine_target(echoes_at(tof), setup, ping, "point")
    assert refined is not None
    # noise-free up to 1 uV: the refined TOFs are the true ones (the model is exact for a point)
    assert np.max(np.abs(np.array([e.tof_s for e in refined.echoes]) - tof)) < 1e-10
    with pytest.raises(ValueError, match="model must be one of"):
        refine_target(echoes_at(tof), setup, ping, "plane")


def test_model_comparison_has_the_likelihood_ratios_scatter() -> None:
    # A point echo at 0.3 m, 10 deg (the left receiver 16 deg off axis, past the 500 kHz null),
    # 2E/N0 = 30 dB per channel, 40 noisy copies, both models fitted. The difference of their
    # fits (edge - point) is a log-likelihood ratio: mean -mu, sd sqrt(2 mu) at high SNR (module
    # docstring). Weighting each model by the per-bin noise estimate instead gave sd 27 for
    # mu = 32 (theory 8) and chose the edge model in 12 % of the copies. Bound 1.5 x theory:
    # the sd's sampling error over 40 copies is 11 %, and the delay refits add a little.
    target = 0.3 * np.array([math.sin(math.radians(10.0)), math.cos(math.radians(10.0)), 0.0])
    rows, tof, t0 = point_echoes(target, BOARD)
    setup = setup_for(t0)
    sigma = np.sqrt(np.sum(rows ** 2, axis=1) / 1e3)[:, np.newaxis]
    rng = np.random.default_rng(5)
    gaps = []
    for _ in range(40):
        ping = PingNoise(rows + sigma * rng.standard_normal(rows.shape), FS, t0, tuple(np.array([t]) for t in tof),
                         setup.busy_half_width_s)
        point = refine_target(echoes_at(tof + 40e-9), setup, ping, "point")
        assert point is not None
        edge = refine_target(point.echoes, setup, ping, "vertical-edge")
        assert edge is not None
        gaps.append(edge.output_snr - point.output_snr)
    gap = np.array(gaps)
    mu = -float(np.mean(gap))
    assert mu > 20.0  # the shapes differ by tens of noise units here (measured 55)
    assert np.all(gap < 0.0)
    assert float(np.std(gap, ddof=1)) < 1.5 * math.sqrt(2.0 * mu)
