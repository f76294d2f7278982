"""``inputs.robust_offsets``: the DC offsets and the robust noise estimate from one subsample,
identical to ``row_offsets`` and ``noise.noise_sigma``, and never touching the caller's samples."""

from __future__ import annotations

import numpy as np
import pytest

from binsonar.detection import detect
from binsonar.detection.inputs import as_signals, robust_offsets, row_offsets
from binsonar.detection.noise import noise_sigma
from support.detection_signals import FS, echo_rows, pulse_template


@pytest.mark.parametrize("n", [3000, 4096, 4100, 60_000])  # whole rows; exactly 16 x 256 (a view); subsampled
def test_robust_offsets_equal_the_separate_estimates(n):
    rng = np.random.default_rng(n)
    waveforms = rng.standard_normal((2, 3, n)) * 0.1 + rng.normal(0.0, 1.0, (2, 3, 1))
    waveforms[:, :, n // 3: n // 3 + 201] += 3.0 * pulse_template().samples  # an echo moves neither much
    before = waveforms.copy()
    dc, sigma = robust_offsets(waveforms)
    assert np.array_equal(waveforms, before)  # partitioned copies only
    assert np.array_equal(dc, row_offsets(waveforms))
    rows = waveforms.reshape(6, n)
    expected = noise_sigma(rows, sample_rate_hz=FS, t0_s=0.0, offset_v=dc.reshape(-1))
    assert np.array_equal(sigma.reshape(-1), expected)
    assert np.all(np.abs(sigma / 0.1 - 1.0) < 0.1)  # and it is the noise's sigma (2 % standard error)


def test_zero_offsets_are_none_and_a_zero_estimate_is_floored_downstream():
    # Constant-zero rows (a quantised record below one code step): no offsets (None, as
    # ``row_offsets``), a zero estimate, which ``noise_sigma`` floors to a tiny positive value.
    dc, sigma = robust_offsets(np.zeros((1, 3, 5000)))
    assert dc is None and np.all(sigma == 0.0)
    floored = noise_sigma(np.zeros((3, 5000)), sample_rate_hz=FS, t0_s=0.0, robust_v=sigma.reshape(-1))
    assert np.all(floored > 0.0)
    assert np.array_equal(floored, noise_sigma(np.zeros((3, 5000)), sample_rate_hz=FS, t0_s=0.0))


@pytest.mark.parametrize("method", ["threshold", "local-matched"])
def test_detectors_given_the_measured_estimate_report_what_they_measure_themselves(method):
    # ``detect`` passes ``Signals.noise_sigma_v`` to these methods; measuring again inside the
    # method (the options' path when a record is averaged, or called directly) must agree.
    from binsonar.detection.local import detect_local_matched, plan_local
    from binsonar.detection.threshold import detect_threshold

    rng = np.random.default_rng(9)
    n = 20_000
    records = echo_rows(np.array([200e-6, 300e-6, 400e-6]), n) + 0.05 * rng.standard_normal((3, n)) + 0.2
    signals = as_signals(records.reshape(1, 3, n), FS, remove_dc=False)
    assert signals.noise_sigma_v is not None
    result = detect(records, method, sample_rate_hz=FS, template=pulse_template())
    dc = signals.dc_v.reshape(-1)
    if method == "threshold":
        direct = detect_threshold(records, sample_rate_hz=FS, t0_s=0.0, template=pulse_template(), dc_v=dc)
    else:
        direct = detect_local_matched(records, plan_local(pulse_template(), n, FS), t0_s=0.0, dc_v=dc)
    got = [(e.tof_s, e.amplitude, e.snr_db, e.score, e.tof_std_s) for ch in result.echoes[0] for e in ch]
    assert got == [e for row in direct for e in row] and len(got) == 3
