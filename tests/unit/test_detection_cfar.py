"""CA- and OS-CFAR: false-alarm rate against design, and two close echoes resolved."""

from __future__ import annotations

import numpy as np
import pytest

from binsonar.detection import detect
from binsonar.detection.cfar import ca_alpha, cfar_layout, cfar_threshold, os_alpha, os_pfa
from binsonar.detection.matched import envelope, filtered_spectrum, plan_matched
from support.detection_signals import FS, echo_rows, noise_sigma_for, pulse_template


def test_threshold_factors_match_closed_forms():
    # CA: (1 + alpha/N)^-N = Pfa exactly; OS with k = N reduces to the largest of N cells,
    # whose Pfa is prod (N - i)/(N - i + alpha); check the bisection inverts it to 1e-9.
    n, pfa = 24, 1e-4
    assert abs((1 + ca_alpha(n, pfa) / n) ** (-n) - pfa) < 1e-12
    for k in (12, 18, 24):
        assert abs(os_pfa(os_alpha(n, k, pfa), n, k) / pfa - 1) < 1e-9
    # Rohling's classic numbers: N = 24, k = 18 needs a larger factor than CA for the same Pfa.
    assert os_alpha(24, 18, 1e-6) > 0


@pytest.mark.parametrize("kind", ["ca", "os"])
def test_false_alarm_rate_on_noise_is_within_a_factor_2_of_design(kind):
    # Noise only, white: the fraction of cells above the CFAR threshold estimates the per-cell
    # Pfa. Design 1e-3; 400 records of 20,000 samples give 530,000 cells, i.e. about 150
    # effectively independent exceedances (cells are correlated over tau_c = 3.6 cells), a
    # Poisson standard error of 8 %: the factor-2 band is more than 8 standard errors wide.
    # The reference cells are spaced by tau_c, which is what makes N the effective number.
    pfa = 1e-3
    n = 20000
    plan = plan_matched(pulse_template(), n, FS)
    offsets, step = cfar_layout(plan, 3e-6, 24)
    assert step >= 3  # the correlated-sample correction is active (tau_c = 2.4 us)
    rng = np.random.default_rng(11 if kind == "ca" else 12)
    exceed, cells = 0, 0
    for _ in range(8):  # 8 chunks of 50 records keep the memory small
        rows = rng.standard_normal((50, n))
        z = envelope(plan, filtered_spectrum(plan, rows))
        power = z.real ** 2 + z.imag ** 2
        # As the detector does: CA censors +/- one main-lobe FWHM around first-pass detections.
        censor = int(np.ceil(plan.mainlobe_fwhm_s * FS / plan.decimation)) if kind == "ca" else 0
        threshold = cfar_threshold(power, offsets, kind, pfa, None, censor)
        exceed += int(np.count_nonzero(power > threshold))
        cells += power.size
    rate = exceed / cells
    assert 0.5 * pfa < rate < 2 * pfa, f"measured {rate:.2e} for design {pfa:.0e}"


@pytest.mark.parametrize("method", ["ca-cfar", "os-cfar"])
def test_two_echoes_10_mm_apart_are_resolved(method):
    # Two echoes 13.5 us apart (10 mm of range at 1482 m/s, out and back), amplitudes 1 and
    # 0.5, 2E/N0 = 30 and 24 dB: each record must give exactly these two echoes, each TOF
    # within 5 CRLB-sigmas (43 and 85 ns) of the truth; noise-only records give no echo at
    # the default Pfa = 1e-6 per cell (expected false alarms in 20 records: 0.03).
    rng = np.random.default_rng(3)
    n, k = 8192, 20
    first = rng.uniform(80e-6, 200e-6, k)
    second = first + 13.5e-6
    sigma = noise_sigma_for(30.0)
    records = echo_rows(first, n) + echo_rows(second, n, 0.5) + rng.standard_normal((k, n)) * sigma
    result = detect(records[:, np.newaxis, :].repeat(3, axis=1), method, sample_rate_hz=FS, template=pulse_template())
    for p in range(k):
        echoes = result.echoes[p][0]
        assert len(echoes) == 2, [e.tof_s for e in echoes]
        assert abs(echoes[0].tof_s - first[p]) < 5 * 43e-9
        assert abs(echoes[1].tof_s - second[p]) < 5 * 85e-9
        assert echoes[1].amplitude < echoes[0].amplitude
    noise = detect(rng.standard_normal((20, 3, n)) * sigma, method, sample_rate_hz=FS, template=pulse_template())
    assert sum(len(ch) for ping in noise.echoes for ch in ping) == 0


def test_sidelobe_suppression_and_minimum_separation():
    # A template with strong envelope side lobes (two Gaussian bursts 8 us apart, the second
    # at 0.5): one echo of it yields a matched-filter response with side lobes at +/-8 us at
    # -6 dB, which CFAR would otherwise report as echoes. Side-lobe suppression keeps one.
    from binsonar.recording import Template

    t = (np.arange(-300, 301)) / FS
    burst = np.exp(-13.8 * t ** 2 / 5e-6 ** 2) * np.cos(2 * np.pi * 500e3 * t)
    shifted = np.exp(-13.8 * (t - 8e-6) ** 2 / 5e-6 ** 2) * np.cos(2 * np.pi * 500e3 * (t - 8e-6))
    samples = burst + 0.5 * shifted
    tpl = Template(samples, FS, -300 / FS)
    n = 8192
    rng = np.random.default_rng(4)
    record = np.zeros((1, 3, n))
    record[0, :, 3000:3601] = samples
    record += rng.standard_normal(record.shape) * 0.01
    kept = detect(record, "os-cfar", sample_rate_hz=FS, template=tpl)
    assert [len(ch) for ch in kept.echoes[0]] == [1, 1, 1]
    assert abs(kept.echoes[0][0][0].tof_s - 3300 / FS) < 5e-9
    unsuppressed = detect(record, "os-cfar", sample_rate_hz=FS, template=tpl, sidelobe_margin_db=-300.0)
    assert all(len(ch) == 3 for ch in unsuppressed.echoes[0])
