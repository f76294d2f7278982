"""A DC offset (real ADC data carry one) must not change what the detectors find.

``as_signals`` removes each ping-channel's median before any detector runs. Without that, the
energy and DWT detectors see the offset as energy switched on and off at the record's edges
(with 10 V of DC on 1 mV of noise: echoes at the first and last cells).
"""

from __future__ import annotations

import numpy as np
import pytest

from binsonar.detection import detect
from binsonar.detection.inputs import as_signals
from support.detection_signals import FS, echo_rows, noise_sigma_for, pulse_template

N = 8192
DELAYS = np.array([150e-6, 200e-6, 250e-6])


def _record(seed: int = 11) -> np.ndarray:
    rng = np.random.default_rng(seed)
    sigma = noise_sigma_for(30.0, 0.5)  # 2E/N0 = 30 dB for the 0.5 V echoes
    return echo_rows(DELAYS, N, 0.5) + rng.standard_normal((3, N)) * sigma


def _tofs(result) -> list[list[float]]:
    return [[e.tof_s for e in echoes] for echoes in result.echoes[0]]


@pytest.mark.parametrize("method", ["energy", "dwt", "matched", "ca-cfar", "threshold", "whitened-matched"])
def test_dc_offset_gives_the_same_echoes(method):
    x = _record()
    plain = _tofs(detect(x, method, sample_rate_hz=FS, template=pulse_template()))
    offset = _tofs(detect(x + 10.0, method, sample_rate_hz=FS, template=pulse_template()))
    assert [len(t) for t in plain] == [1, 1, 1]  # one echo per channel, none at the edges
    assert [len(t) for t in offset] == [len(t) for t in plain]
    # x + 10 - median(x + 10) equals x - median(x) up to the rounding of adding 10 V (~2e-15
    # V on samples of ~0.5 V): the TOFs agree to far better than 1 ps.
    for a, b in zip(plain, offset):
        assert np.allclose(a, b, rtol=0.0, atol=1e-12)
    for c, t in enumerate(plain):
        assert abs(t[0] - DELAYS[c]) < 2e-6  # the echo itself (coarsest detector: ~1 us cells)


def test_median_removal_is_robust_to_the_echoes_and_copies_only_when_needed():
    x = _record()
    # A record whose medians are all 0 is passed through without a copy.
    zero_median = np.zeros((1, 3, 64))
    zero_median[0, :, 10] = 1.0
    assert as_signals(zero_median, FS).waveforms is zero_median
    signals = as_signals(x + 3.0, FS)
    residual = np.median(signals.waveforms, axis=-1)
    # The subsample median's error: 1.25 sigma / sqrt(4096) = 0.02 sigma (sigma ~ 0.2 mV);
    # the echoes occupy ~5 % of the samples, shifting it by less than 0.1 sigma. 0.2 sigma.
    sigma = noise_sigma_for(30.0, 0.5)
    assert np.all(np.abs(residual) < 0.2 * sigma)
