"""The matched filter's decimated envelope by overlap-save (``binsonar.detection.overlap_save``).

It must be the record-size FFT's envelope (``matched.filtered_spectrum`` / ``envelope``) on
another decimated grid, to the truncation of the analytic template's Hilbert tails, and give
``detect_matched`` the same TOFs (the refinement is the same time-domain evaluation).
"""

from __future__ import annotations

import numpy as np
import pytest

from binsonar.detection.matched import (
    band_edge_cycles,
    detect_matched,
    filtered_spectrum,
    lags_from_spectrum,
    plan_matched,
    white_noise_power,
)
from binsonar.detection.overlap_save import block_envelope, block_samples, plan_blocks
from support.detection_signals import FS, echo_rows, noise_sigma_for, pulse_template

N = 30000


def _grid_lags(plan, limit: int) -> tuple[np.ndarray, np.ndarray]:
    """Cells of the blocks' grid that fall on whole lags (D = L / n_env is fractional), their lags."""
    lags = np.arange(plan.n_cells) * plan.decimation
    cells = np.flatnonzero(np.abs(lags - np.rint(lags)) < 1e-9)[:limit]
    return cells, np.rint(lags[cells]).astype(np.intp)


def _records(seed: int) -> np.ndarray:
    # Three rows: echoes at 20 dB near the record's start, middle and end (the first and last
    # blocks are partly outside the record), in white noise; a DC offset on row 1.
    rng = np.random.default_rng(seed)
    delays = np.array([8e-6, 0.7e-3, N / FS - 8e-6])
    rows = echo_rows(delays, N) + noise_sigma_for(20.0) * rng.standard_normal((3, N))
    rows[1] += 0.3
    return rows


@pytest.mark.parametrize("block", [None, 2048, 4096])
def test_block_envelope_equals_the_record_fft_envelope(block):
    # Reference: the record-size spectrum's analytic z at the same lags (``lags_from_spectrum``,
    # an exact DFT of the band). Both are the band-limited analytic correlation; they differ by
    # the analytic template's Hilbert tails, which the record-size FFT sums over the whole
    # record and a block only over its span (wrapping the rest): the tails decay like 1/t from
    # ~400 samples out, so the difference is a few 1e-3 of the noise's RMS |z| at a block's
    # first lags and less further in (measured: 5.7e-3 at most on 12.5 ms records, 8,192-sample
    # blocks). Asserted: below 1.5e-2 of the noise RMS everywhere and 1e-3 of the peak at the
    # echoes (measured 1.4e-4; at 20 dB the noise moves |z| there by ~1e-1 of it). DC folded: row 1
    # carries an offset.
    template = pulse_template()
    rows = _records(3)
    dc = np.array([0.0, 0.3, 0.0])
    full = plan_matched(template, N, FS)
    plain = plan_matched(template, N, FS, full=False)
    blocks = plan_blocks(template.samples, N, band_edge_cycles(template.samples), plain.analytic_offset,
                         plain.analytic_template_conj.size, block=block)
    z = block_envelope(blocks, rows, dc, single=False)
    assert z.shape == (3, blocks.n_cells)
    assert blocks.n_cells == int((N - template.samples.size) / blocks.decimation) + 1  # every full-overlap lag
    cells, lags = _grid_lags(blocks, 120)
    spectrum = filtered_spectrum(full, rows, dc=dc)
    reference = lags_from_spectrum(full, spectrum, np.tile(lags, (3, 1)))
    noise_rms = np.sqrt(np.median(np.abs(reference) ** 2, axis=1) / np.log(2.0))
    error = np.abs(z[:, cells] - reference)
    assert np.all(error.max(axis=1) < 1.5e-2 * noise_rms), error.max(axis=1) / noise_rms
    # At each echo's peak cell: the record-size envelope at that (fractional) lag, by its DFT.
    bins = np.arange(full.k_hi)
    cell_lags = np.arange(blocks.n_cells) * blocks.decimation
    for r, delay in enumerate((8e-6, 0.7e-3, N / FS - 8e-6)):
        near = np.flatnonzero(np.abs(cell_lags - (delay * FS - 100)) < 60)
        cell = near[np.argmax(np.abs(z[r, near]))]
        value = np.sum(spectrum[r] * np.exp(2j * np.pi * bins * cell_lags[cell] / full.n_fft)) / full.n_fft
        assert abs(z[r, cell] - value) < 1e-3 * abs(value), abs(z[r, cell] - value) / abs(value)


def test_float32_blocks_leave_the_tofs_unchanged_and_differ_only_by_rounding():
    # As for the record-size FFT (test_detection_matched): float32 blocks only locate the peak
    # cell and the noise floor; the TOF is refined from the float64 samples. TOFs within 0.1 ns
    # (in fact equal), SNRs within 0.01 dB; the envelopes differ at float32's level (relative
    # 1e-9 .. 1e-4 of the peak: a test that would pass with identical paths shows nothing).
    rows = _records(5)
    plan = plan_matched(pulse_template(), N, FS, full=False, overlap_save=True)
    single = detect_matched(rows, plan, t0_s=0.0, single=True)
    double = detect_matched(rows, plan, t0_s=0.0, single=False)
    assert all(len(a) == len(b) == 1 for a, b in zip(single, double))
    assert max(abs(a[0][0] - b[0][0]) for a, b in zip(single, double)) < 1e-10
    assert max(abs(a[0][2] - b[0][2]) for a, b in zip(single, double)) < 0.01
    z32 = block_envelope(plan.blocks, rows, single=True)
    z64 = block_envelope(plan.blocks, rows, single=False)
    relative = np.max(np.abs(z32 - z64)) / np.max(np.abs(z64))
    assert 1e-9 < relative < 1e-4, relative


def test_overlap_save_detection_gives_the_record_fft_tofs():
    # The refinement (z at integer lags around the best cell, by direct dot products, then the
    # log-parabolic vertex) is the same for both plans, so whenever both find the same echo the
    # TOFs agree to rounding (1e-15 s asserted as 1e-13: the window of lags evaluated differs,
    # not the values). 60 rows at 20 dB, echoes anywhere in a 30,000-sample record.
    rng = np.random.default_rng(8)
    delays = rng.uniform(20e-6, N / FS - 20e-6, 60)
    rows = echo_rows(delays, N) + noise_sigma_for(20.0) * rng.standard_normal((60, N))
    blocked = detect_matched(rows, plan_matched(pulse_template(), N, FS, full=False, overlap_save=True), t0_s=0.0)
    record = detect_matched(rows, plan_matched(pulse_template(), N, FS), t0_s=0.0)
    tof_a = np.array([r[0][0] for r in blocked])
    tof_b = np.array([r[0][0] for r in record])
    assert np.max(np.abs(tof_a - tof_b)) < 1e-13
    assert np.max(np.abs(tof_a - delays)) < 1e-6  # the echoes themselves (CRLB 135 ns at 20 dB)


def test_block_envelope_noise_power_is_the_white_noise_prediction():
    # Invariant: for white noise of variance sigma^2, E|z|^2 = sigma^2 sum |w_k|^2 / L
    # (Parseval; ``noise_gain``) = 2 sigma^2 sum s^2 for the plain filter up to the band's
    # truncation (1e-12 of the energy). Measured over 3 x ~2,000 cells of |z|^2 (exponential,
    # correlated over ~1.7 cells): relative standard error ~3 %, asserted within 10 %; and the
    # plan's gain equals the analytic one to 1e-6.
    rng = np.random.default_rng(12)
    sigma = 0.2
    plan = plan_matched(pulse_template(), N, FS, full=False, overlap_save=True)
    z = block_envelope(plan.blocks, sigma * rng.standard_normal((3, N)))
    measured = float(np.mean(np.abs(z.astype(np.complex128)) ** 2))
    predicted = float(white_noise_power(plan, sigma))
    assert abs(measured / predicted - 1.0) < 0.10, measured / predicted
    assert abs(plan.blocks.noise_gain / (2.0 * np.sum(pulse_template().samples ** 2)) - 1.0) < 1e-6


def test_gathered_blocks_equal_the_numpy_reference():
    # The compiled gather against plain indexing: blocks b start at b * hop - lead, samples
    # outside the record are 0, the offset is subtracted; float64 exactly, float32 as its cast.
    rng = np.random.default_rng(2)
    rows = rng.standard_normal((2, 9000))
    dc = np.array([0.25, -1.5])
    plan = plan_matched(pulse_template(), 9000, FS, full=False, overlap_save=True).blocks
    index = np.arange(plan.n_blocks)[:, np.newaxis] * plan.hop - plan.lead + np.arange(plan.block)
    inside = (index >= 0) & (index < rows.shape[1])
    reference = np.where(inside, rows[:, np.clip(index, 0, rows.shape[1] - 1)] - dc[:, None, None], 0.0)
    assert np.array_equal(block_samples(plan, rows, dc, single=False), reference)
    assert np.array_equal(block_samples(plan, rows, dc), reference.astype(np.float32))
    assert inside[0, 0] == False and not inside[-1, -1]  # noqa: E712  both edges padded


def test_a_forced_block_too_short_for_the_template_is_refused():
    template = pulse_template()
    plan = plan_matched(template, N, FS, full=False)
    with pytest.raises(ValueError, match="block must be an even integer"):
        plan_blocks(template.samples, N, band_edge_cycles(template.samples), plan.analytic_offset,
                    plan.analytic_template_conj.size, block=512)


def test_false_alarm_rate_over_the_whole_record_matches_the_design():
    # Noise only, 100 pings x 3 channels of 16,384 samples, pfa 0.2 over every full-overlap lag:
    # 60 false alarms designed (Rice's up-crossing rate, ``MatchedPlan.threshold_factor``). The
    # overlap-save path must hold the design as the record-size FFT does: both counts within a
    # factor 2 of it (Poisson sd ~8, plus Rice's approximation), and within a few of each other
    # (the same noise; the two envelopes differ by ~1e-2 of the noise at most, so only rows
    # whose peak sits at the threshold can differ). Measured: 59 and 56.
    from binsonar.detection import detect
    from binsonar.detection.inputs import row_offsets

    n = 16384
    noise = np.random.default_rng(17).standard_normal((100, 3, n))
    result = detect(noise, "matched", sample_rate_hz=FS, template=pulse_template(), pfa=0.2)
    blocked = sum(len(ch) for ping in result.echoes for ch in ping)
    record = detect_matched(noise.reshape(-1, n), plan_matched(pulse_template(), n, FS), t0_s=0.0, pfa=0.2,
                            dc_v=row_offsets(noise).reshape(-1))
    full = sum(len(r) for r in record)
    assert 30 <= blocked <= 120 and 30 <= full <= 120, (blocked, full)
    assert abs(blocked - full) <= 4, (blocked, full)


def test_cell_bounds_are_the_cell_masks_range():
    # ``cell_bounds`` replaces the mask in ``detect_matched``: the same cells for any lag range
    # (fractional decimations of both grids, ranges at the record's ends, a range inside one cell).
    from binsonar.detection.matched import cell_bounds, cell_mask

    rng = np.random.default_rng(6)
    record = plan_matched(pulse_template(), N, FS)
    blocked = plan_matched(pulse_template(), N, FS, full=False, overlap_save=True)
    top = N - pulse_template().samples.size
    ranges = [(0, top), (0, 0), (top, top), (5, 6), (1000, 1001)]
    ranges += [tuple(sorted(rng.integers(0, top, 2))) for _ in range(200)]
    for plan in (record, blocked):
        n_cells = plan.n_valid
        for lo, hi in ranges:
            mask = cell_mask(plan, n_cells, (int(lo), int(hi)))
            first, stop = cell_bounds(plan, n_cells, (int(lo), int(hi)))
            expected = np.flatnonzero(mask)
            assert np.array_equal(np.arange(first, stop), expected), (lo, hi)
