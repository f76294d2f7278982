"""Detectors that fold the DC offset into their arithmetic (``DetectionMethod.folds_dc``) give, on the
record as recorded plus its offsets, what they give on the offset-free copy.

The folded path subtracts the same per-row median from the same samples (block by block
instead of in one copy), so the floating-point results are identical, not merely close: the
test compares with ``==``. A fold that forgot a term (the offset in the comparisons, the
noise estimate, the amplitude window or the interpolation) would shift the TOF or amplitude
by a large fraction of the 2 V offset used here.
"""

from __future__ import annotations

import numpy as np
import pytest

from binsonar.detection.inputs import as_signals
from binsonar.detection.noise import noise_sigma
from binsonar.detection.threshold import detect_threshold, first_crossings
from support.detection_signals import FS, echo_rows, noise_sigma_for, pulse_template

N = 8192
DELAYS = np.array([150e-6, 200e-6, 250e-6])
OFFSETS = np.array([2.0, -1.5, 0.3])  # V, per channel, >> the 0.5 V echoes


def _record(seed: int = 5) -> np.ndarray:
    rng = np.random.default_rng(seed)
    sigma = noise_sigma_for(30.0, 0.5)
    return echo_rows(DELAYS, N, 0.5) + rng.standard_normal((3, N)) * sigma + OFFSETS[:, np.newaxis]


def test_as_signals_can_carry_the_offsets_instead_of_removing_them():
    x = _record()
    kept = as_signals(x, FS, remove_dc=False)
    removed = as_signals(x, FS)
    assert kept.waveforms is x or np.shares_memory(kept.waveforms, x)  # no copy
    assert kept.dc_v.shape == (1, 3)
    assert removed.dc_v is None
    # The median of noise around the offset: within 0.1 sigma (~0.02 sigma standard error).
    assert np.allclose(kept.dc_v[0], OFFSETS, rtol=0.0, atol=0.1 * noise_sigma_for(30.0, 0.5))
    assert np.array_equal(kept.without_dc().waveforms, removed.waveforms)


@pytest.mark.parametrize("level_v", [None, 0.4])  # 0.4 V: 6.2 sigma, below the 0.5 V echoes
def test_threshold_folded_equals_threshold_on_the_offset_free_copy(level_v):
    x = _record()
    kept = as_signals(x, FS, remove_dc=False)
    rows = kept.waveforms[0]
    dc = kept.dc_v[0]
    common = dict(sample_rate_hz=FS, t0_s=0.0, template=pulse_template(), level_v=level_v)
    folded = detect_threshold(rows, dc_v=dc, **common)
    copied = detect_threshold(kept.without_dc().waveforms[0], **common)
    assert folded == copied
    assert [len(e) for e in folded] == [1, 1, 1]
    for c, echoes in enumerate(folded):
        assert abs(echoes[0][0] - DELAYS[c]) < 2e-6  # the echo, not the offset


def test_first_crossings_with_offset_matches_a_brute_force_scan():
    rng = np.random.default_rng(3)
    # Ragged length (not a multiple of the chunk or block), a crossing in the ragged end, a
    # row with none, and offsets large enough that ignoring them would cross at sample 0.
    rows = rng.standard_normal((4, 40_003)) + np.array([[5.0], [-5.0], [0.0], [1.0]])
    rows[0, 20_000] += 9.0
    rows[1, 39_999] -= 9.0
    level = np.full(4, 7.0)
    offset = np.array([5.0, -5.0, 0.0, 1.0])
    expected = [int(np.argmax(hit)) if hit.any() else -1 for hit in np.abs(rows - offset[:, None]) >= level[:, None]]
    assert first_crossings(rows, level, offset).tolist() == expected
    assert expected[0] == 20_000 and expected[1] == 39_999 and expected[3] == -1


def test_noise_sigma_with_offset_is_that_of_the_shifted_rows():
    x = _record()
    dc = np.array([2.0, -1.5, 0.3])
    shifted = x - dc[:, np.newaxis]
    assert np.array_equal(noise_sigma(x, sample_rate_hz=FS, t0_s=0.0, offset_v=dc),
                          noise_sigma(shifted, sample_rate_hz=FS, t0_s=0.0))


def assert_folded_like_copied(folded, copied) -> None:
    """One echo per channel, at the true delay, from the folded run and from the run on the
    offset-free copy, equal within rounding.

    Rounding of terms of up to |dc| sum|taps| ~ 2 V x 100 against a 0.5 V echo's z: relative
    errors ~1e-13, i.e. 1e-13 of a 50 ns sample in the TOF. Tolerances 1e-15 s and 1e-9
    relative: many orders above the rounding, many below a forgotten term (the 2 V offset's
    correlation with the taps, or its energy, would move the peak or the noise estimate grossly).
    """
    assert [len(e) for e in folded] == [len(e) for e in copied] == [1, 1, 1]
    for a, b in zip(folded, copied):
        assert abs(a[0][0] - b[0][0]) < 1e-15
        assert np.allclose(a[0][1:], b[0][1:], rtol=1e-9, atol=0.0)
    for c, echoes in enumerate(folded):
        assert abs(echoes[0][0] - DELAYS[c]) < 0.1e-6


def test_local_matched_folded_equals_local_matched_on_the_offset_free_copy():
    from binsonar.detection.local import detect_local_matched, plan_local

    x = _record()
    kept = as_signals(x, FS, remove_dc=False)
    plan = plan_local(pulse_template(), N, FS)
    folded = detect_local_matched(kept.waveforms[0], plan, t0_s=0.0, dc_v=kept.dc_v[0])
    copied = detect_local_matched(kept.without_dc().waveforms[0], plan, t0_s=0.0)
    # Not bit-identical: the folded correlation is z(x) - dc * sum(taps) instead of z(x - dc),
    # and the block correlations are those of x minus dc times the tone's sum.
    assert_folded_like_copied(folded, copied)


def test_dc_correlation_is_the_correlation_of_a_constant_record():
    from binsonar.detection.local import block_tone_power, plan_local
    from binsonar.detection.matched import dc_correlation, lags_time_domain, plan_matched

    plan = plan_matched(pulse_template(), 1000, FS, full=False)
    constant = np.full((2, 1000), 1.0) * np.array([[0.7], [-2.0]])
    # Lags where the analytic taps overlap the record partly (both edges) and fully.
    lags = np.array([[-50, 0, 400], [10, 790, 999]])
    for k in range(2):
        direct = lags_time_domain(plan, constant, np.array([k, k, k]), lags[k][:, np.newaxis])[:, 0]
        assert np.allclose(dc_correlation(plan, 1000, constant[k, :1], lags[k][np.newaxis])[0], direct,
                           rtol=1e-12, atol=1e-12)
    # Block tone powers of x - dc, against the direct sums (rounding only); the record length
    # is not a multiple of the block (the ragged end is left out).
    local = plan_local(pulse_template(), 5000, FS)
    rng = np.random.default_rng(1)
    rows = rng.standard_normal((2, 5000)) + 3.0
    dc = np.array([3.0, 2.5])
    b = local.block
    n_blocks = 5000 // b
    assert 5000 % b  # a ragged end
    k = np.arange(b)
    tone = np.exp(-2j * np.pi * local.centre_hz / FS * k)
    expected = np.abs(((rows[:, : n_blocks * b] - dc[:, None]).reshape(2, n_blocks, b) * tone).sum(axis=2)) ** 2
    assert np.allclose(block_tone_power(local, rows, dc), expected, rtol=1e-9, atol=1e-12 * expected.max())
    # The offset matters (a forgotten fold would leave 3 V x the tone's sum in every block).
    assert not np.allclose(block_tone_power(local, rows), expected, rtol=1e-3)


def test_first_crossings_at_part_and_block_boundaries_match_a_brute_force_scan():
    # Crossings at the first/last sample of a 1024-sample part and of a 16384-sample block,
    # rows crossing in different blocks (the pending rows change between blocks), one
    # crossing downwards only, and a record length that leaves a ragged final block.
    rng = np.random.default_rng(8)
    n = 100_001
    positions = [0, 1023, 1024, 16383, 16384, 99_999]
    rows = rng.standard_normal((len(positions), n)) * 0.1 - 0.4
    for r, i in enumerate(positions):
        rows[r, i] += 5.0 if r % 2 else -5.0
    offset = np.full(len(positions), -0.4)
    level = np.full(len(positions), 3.0)
    expected = [int(np.argmax(h)) if h.any() else -1 for h in np.abs(rows - offset[:, None]) >= level[:, None]]
    assert expected == positions
    assert first_crossings(rows, level, offset).tolist() == positions


# TOF tolerances: local 1e-10 s (1/500 of a sample); threshold 5e-9 s (1/10 of a sample): its
# level is 6 noise sigmas, and the ~1e-3 change of the sigma estimate moves the crossing
# along the echo's rising edge by ~1e-3 of the level over its slope (measured 0.5 ns).
@pytest.mark.parametrize("method, base, tof_tol", [("seed-9", "local-matched", 1e-10), ("seed-2", "threshold", 5e-9)])
def test_averaging_methods_fold_the_mean_offset(method, base, tof_tol):
    # Four pings whose offsets differ from ping to ping: the averaged methods average the
    # waveforms as recorded and carry the mean offset (mean(x - dc) = mean(x) - mean(dc)), so
    # they must give what the base method gives on the average of the offset-free pings.
    # That average's own median is not exactly 0 (noise), so the base method removes a
    # residual offset of a few hundredths of sigma: it shifts the noise estimate (median of
    # |x - dc|) by ~1e-3 relative (SNR by ~0.02 dB) and z by that offset times the sum of the
    # analytic taps (measured for local: TOF by ~2 ps, amplitude by ~3e-5). Tolerances below,
    # 0.1 sigma in amplitude (the threshold's is a peak |x - dc|) and 0.1 dB; a forgotten offset (volts, against 0.5 V echoes)
    # would move the TOF by microseconds (local) or cross at sample 0 (threshold).
    from binsonar.detection import detect
    from binsonar.detection.inputs import row_offsets

    rng = np.random.default_rng(21)
    sigma = noise_sigma_for(30.0, 0.5)
    pings = np.stack([echo_rows(DELAYS, N, 0.5) + rng.standard_normal((3, N)) * sigma + OFFSETS[:, None] * (1 + 0.3 * p)
                      for p in range(4)])
    averaged = (pings - row_offsets(pings)[:, :, None]).mean(axis=0)
    options = dict(sample_rate_hz=FS, template=pulse_template())
    folded = detect(pings, method, **options)
    reference = detect(averaged, base, **options)
    for c in range(3):
        (a,), (b,) = folded.echoes[0][c], reference.echoes[0][c]
        assert abs(a.tof_s - b.tof_s) < tof_tol
        assert abs(a.tof_s - DELAYS[c]) < 3e-6
        assert abs(a.amplitude - b.amplitude) < 0.1 * sigma  # the residual offset is a few hundredths of sigma
        assert abs(a.snr_db - b.snr_db) < 0.1
    # One ping is its own average: exactly the base method.
    assert detect(pings[:1], method, **options).echoes == detect(pings[:1], base, **options).echoes


@pytest.mark.parametrize("single", [True, False])
def test_matched_folded_equals_matched_on_the_offset_free_copy(single):
    from binsonar.detection.matched import detect_matched, plan_matched

    x = _record()
    kept = as_signals(x, FS, remove_dc=False)
    plan = plan_matched(pulse_template(), N, FS)
    folded = detect_matched(kept.waveforms[0], plan, t0_s=0.0, dc_v=kept.dc_v[0], single=single)
    copied = detect_matched(kept.without_dc().waveforms[0], plan, t0_s=0.0, single=single)
    # The FFT input is x - dc either way (subtracted in the cast copy or in a float64 copy);
    # the direct correlations differ by rounding of z(x) - dc * sum(taps) against z(x - dc).
    assert_folded_like_copied(folded, copied)
