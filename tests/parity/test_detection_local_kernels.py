"""The local matched filter's compiled kernels against its numpy definitions in the package (an
independent implementation of each step: ``local.block_tone_power``, ``coarse_lags``,
``segment_correlation``, ``numpy_peaks``; ``matched.lags_time_domain`` minus
``matched.dc_correlation``, ``matched.refine``, ``matched.echo_values``)."""

from __future__ import annotations

import numpy as np
import pytest

from binsonar.detection.kernel_types import ECHO
from binsonar.detection.local import (
    REFINE_HALF_WIDTH,
    block_tone_power,
    candidate_correlations,
    coarse_lags,
    detect_local_matched,
    numpy_peaks,
    plan_local,
    segment_correlation,
)
from binsonar.detection.matched import dc_correlation, lags_time_domain, refine
from binsonar.recording import Template

FS = 20e6
N = 60_000


def _template() -> Template:
    t = (np.arange(201) - 100) / FS
    return Template(np.exp(-13.8 * t**2 / 5e-6**2) * np.cos(2 * np.pi * 500e3 * t), FS, -100 / FS)


def _dc(offsets: np.ndarray | None) -> np.ndarray:
    """The kernels' offsets: zeros for none."""
    return np.zeros(3) if offsets is None else offsets


def _rows(seed: int, dc: bool) -> tuple[np.ndarray, np.ndarray | None]:
    rng = np.random.default_rng(seed)
    s = _template().samples
    rows = rng.standard_normal((3, N)) * np.sqrt(np.sum(s**2) / 100.0)  # 2E/N0 = 20 dB
    for r, start in enumerate((1000, 31_234, N - 201)):  # the last at the record's very end
        rows[r, start:start + s.size] += s
    rows[1, 5000:5201] += 0.6 * s  # a weaker second echo: a second candidate
    offsets = rng.normal(0.0, 0.05, 3) if dc else None
    return (rows + offsets[:, None] if dc else rows), offsets


@pytest.mark.parametrize("dc", [False, True])
@pytest.mark.parametrize("bounds", [(0, N - 201), (0, 20_000), (4000, 40_000)])
def test_candidates_and_stretch_correlations_match_the_numpy_definitions(dc, bounds):
    plan = plan_local(_template(), N, FS)
    rows, offsets = _rows(1, dc)
    k = 3
    z, start = candidate_correlations(plan, rows, k, bounds, offsets)
    coarse = coarse_lags(plan, rows, k, bounds, offsets)
    width = 2 * plan.half + 1
    expected_start = np.maximum(np.minimum(coarse - plan.half, bounds[1] - (width - 1)), bounds[0]).reshape(-1)
    # Integer picks: equal exactly (the sums' rounding, ~1e-16 relative, cannot reorder windows
    # whose statistics differ by the noise's scatter).
    assert np.array_equal(start, expected_start)
    expected = segment_correlation(plan, rows, np.repeat(np.arange(3), k), expected_start, offsets)
    # The same FFTs of the same stretches, the kernel's in single precision: float32 rounding
    # (6e-8) of the samples and of ~10 FFT stages leaves errors well below 1e-6 of the peak |z|
    # (measured 1.5e-7); a wrong stretch, lag or weight would be wrong by O(1).
    assert np.max(np.abs(z[:, :width] - expected)) < 1e-6 * np.max(np.abs(expected))


@pytest.mark.parametrize("dc", [False, True])
def test_refinement_matches_the_full_filters_refinement(dc):
    from binsonar.detection import local_kernels

    plan = plan_local(_template(), N, FS)
    matched = plan.matched
    rows, offsets = _rows(2, dc)
    lo, hi = 0, N - 201
    z, start = candidate_correlations(plan, rows, 3, (lo, hi), offsets)
    n_lags = 2 * REFINE_HALF_WIDTH + 1
    values = np.empty((3, n_lags), dtype=complex)
    refined = np.empty((3, 2))
    local_kernels.local_peaks(z, start, rows, _dc(offsets), plan.tap_parts, plan.search((lo, hi), 3, stride=1),
                              values, refined)
    # The numpy definition: the largest |z| over the candidates' lags, then the direct z.
    width = 2 * plan.half + 1
    power = np.abs(z[:, :width]) ** 2
    lags = start[:, None] + np.arange(width)
    best = np.argmax(power.reshape(3, -1), axis=1)
    peak_lag = lags.reshape(3, -1)[np.arange(3), best]
    refine_lags = peak_lag[:, None] + np.arange(-REFINE_HALF_WIDTH, REFINE_HALF_WIDTH + 1)
    direct = lags_time_domain(matched, rows, np.arange(3), refine_lags)
    if offsets is not None:
        direct -= dc_correlation(matched, N, offsets, refine_lags, plan.tap_partial)
    direct[(refine_lags < lo) | (refine_lags > hi)] = 0.0
    lag, peak = refine(direct, refine_lags)
    # Dot products of ~1000 taps in another order: 1e-12 of the peak; the vertex then moves by
    # ~1e-12 samples; 1e-9 samples (50 fs) and 1e-9 relative leave room.
    assert np.max(np.abs(values - direct)) < 1e-12 * np.max(np.abs(direct))
    assert np.max(np.abs(refined[:, 0] - lag)) < 1e-9
    assert np.max(np.abs(refined[:, 1] / peak - 1.0)) < 1e-9
    # Echoes where they were put (row 2's at the last full-overlap lag): the TOF's Cramer-Rao
    # bound at 20 dB is ~135 ns (2.7 samples; 42 ns at 30 dB in benchmarks/bench_detection.py),
    # so 15 samples is > 5 standard deviations, and far below the 3,000+ between the echoes.
    assert np.max(np.abs(refined[:, 0] - [1000, 31_234, N - 201])) < 15.0


def test_non_contiguous_rows_give_the_same_echoes():
    plan = plan_local(_template(), N, FS)
    rows, _ = _rows(3, False)
    strided = np.asfortranarray(rows)
    assert detect_local_matched(strided, plan, t0_s=0.0) == detect_local_matched(rows, plan, t0_s=0.0)


@pytest.mark.parametrize(
    "n, bounds, k, dc",
    [
        (N, (0, N - 201), 1, False),
        (N, (0, N - 201), 5, True),
        (N, (30_000, 30_100), 3, True),  # a window narrower than a stretch
        (N, (N - 400, N - 201), 3, False),  # at the record's end
        (700, (0, 499), 3, True),  # a record of a few blocks: fewer windows than picks
        (260, (0, 59), 2, False),  # barely longer than the template: one block window
    ],
)
def test_detection_path_equals_the_numpy_path_at_edges(n, bounds, k, dc):
    from binsonar.detection import local_kernels

    plan = plan_local(_template(), n, FS)
    rows, offsets = _rows(5, dc)
    rows = np.ascontiguousarray(rows[:, :n])
    lag_ref, peak_ref = numpy_peaks(plan, rows, k, bounds, offsets)
    z, start, *_ = candidate_correlations(plan, rows, k, bounds, offsets)
    values = np.empty((3, 2 * REFINE_HALF_WIDTH + 1), dtype=complex)
    refined = np.empty((3, 2))
    local_kernels.local_peaks(z, start, rows, _dc(offsets), plan.tap_parts, plan.search(bounds, k, stride=1),
                              values, refined)
    # Same picks and the same refinement up to the order of ~1000-term sums: lags to 1e-9
    # samples (50 fs) and powers to 1e-9 relative, as above.
    assert np.max(np.abs(refined[:, 0] - lag_ref)) < 1e-9
    assert np.max(np.abs(refined[:, 1] / peak_ref - 1.0)) < 1e-9
    assert np.all((refined[:, 0] >= bounds[0] - 0.5) & (refined[:, 0] <= bounds[1] + 0.5))


@pytest.mark.parametrize("bounds", [(1000, 1300), (N - 600, N - 201), (0, 64 * 42 * 3)])
@pytest.mark.parametrize("flat", [False, True])
def test_candidate_search_in_groups_keeps_ties_and_exhausted_windows(bounds, flat):
    # The kernel scans groups of windows (``local_kernels``' groups of 64) for each pick; the numpy
    # definition scans every window. Few windows (every window blanked before the last pick:
    # the first one again), windows spanning exactly whole groups, and exactly equal windows
    # (zero rows: every statistic exactly 0, ties, the first window wins; a constant nonzero row
    # would tie only to rounding, which the kernel's and numpy's sums break differently) must
    # give the same picks.
    plan = plan_local(_template(), N, FS)
    rows = np.zeros((3, N)) if flat else _rows(3, False)[0]
    z, start = candidate_correlations(plan, rows, 3, bounds)
    coarse = coarse_lags(plan, rows, 3, bounds)
    width = 2 * plan.half + 1
    expected = np.maximum(np.minimum(coarse - plan.half, bounds[1] - (width - 1)), bounds[0]).reshape(-1)
    assert np.array_equal(start, expected)


@pytest.mark.parametrize("n", [260, 700, 4 * 42 + 47, 4 * 42 + 48, 60_000, 60_001])
@pytest.mark.parametrize("first_block", [0, 1, 3])
def test_block_powers_with_padded_taps_equal_the_numpy_definition(n, first_block):
    # The kernel reads each group of four blocks with the tone zero padded to a multiple of 8
    # taps wherever the row holds the extra samples, and the last blocks with their own taps:
    # both must give block_tone_power's |z_b|^2 (the padded taps multiply the next block's
    # samples by exactly 0; the sums' order differs, 1e-12 of the largest block power). Lengths
    # around the split (the last padded read ending exactly at, or one sample past, the row's end)
    # and every first block.
    from binsonar.detection import local_kernels

    plan = plan_local(_template(), 60_000, FS)
    assert plan.tone_lanes.shape[1] % 8 == 0 and plan.tone_lanes.shape[1] > plan.block
    rows, offsets = _rows(7, True)
    rows = np.ascontiguousarray(rows[:, :n])
    n_blocks = n // plan.block - first_block
    energy = np.empty((3, n_blocks))
    local_kernels.block_powers(rows, plan.tone_lanes, plan.search((0, n), 1), first_block, energy,
                               *local_kernels.tone_offsets(_dc(offsets), plan.tone_lanes, plan.block))
    expected = block_tone_power(plan, rows, offsets)[:, first_block:]
    assert np.max(np.abs(energy - expected)) < 1e-12 * np.max(expected)


@pytest.mark.parametrize("t0_s, pfa", [(0.0, 1e-3), (-2.5e-4, 1e-6)])
def test_compiled_echo_values_equal_the_matched_filters(t0_s, pfa):
    # ``local_kernels.echo_rows`` is ``matched.echo_values`` with ``white_noise_power`` for the
    # noise, compiled: the same operations in the same order, so the same values up to the last
    # bit of the library's log10/sqrt (1e-15 relative leaves that room, and nothing else: a
    # wrong constant or order of terms would be off by far more). Rows: an echo, a noise-free
    # row (SNR capped), a weak peak (score < 1).
    from binsonar.detection import local_kernels
    from binsonar.detection.matched import echo_values, white_noise_power

    plan = plan_local(_template(), N, FS)
    refined = np.array([[1234.37, 5.2e3], [40_000.0, 2.0e2], [7.5, 3.1]])
    sigma = np.array([0.1, 0.0, 0.2])
    factor = plan.threshold_factor(pfa, N - 201)
    assert factor == plan.matched.threshold_factor(pfa, N - 201)
    values = np.empty(3, dtype=ECHO)
    local_kernels.echo_rows(refined, sigma, plan.echo_constants(t0_s, factor), values)
    echoes = np.stack([values[name] for name in ECHO.names], axis=1)
    expected = np.stack(echo_values(plan.matched, refined[:, 0], refined[:, 1], white_noise_power(plan.matched, sigma),
                                    factor, t0_s), axis=1)
    assert np.all(np.abs(echoes - expected) <= 1e-15 * np.abs(expected))
    assert echoes[2, 3] < 1.0 < echoes[0, 3]


@pytest.mark.parametrize(
    "n, bounds, k, dc",
    [
        (N, (0, N - 201), 3, False),
        (N, (0, N - 201), 5, True),
        (N, (30_000, 30_100), 3, True),
        (N, (30_000, 30_002), 2, False),  # fewer lags than the decimation
        (N, (N - 400, N - 201), 3, False),
        (700, (0, 499), 3, True),
    ],
)
def test_decimated_candidate_correlations_find_the_full_rate_peak(n, bounds, k, dc):
    # The detection path's z at every ``decimation``-th lag (a short inverse FFT of the band)
    # and the wider direct search around its largest sample give the full-rate path's vertex.
    from binsonar.detection import local_kernels

    plan = plan_local(_template(), n, FS)
    stride = plan.decimation
    assert stride == 5 and plan.segment_fft // stride >= 2 * plan.segment_weights.size  # 625 -> 125 >= 90
    rows, offsets = _rows(5, dc)
    rows = np.ascontiguousarray(rows[:, :n])
    lag_ref, peak_ref = numpy_peaks(plan, rows, k, bounds, offsets)
    z_full, start = candidate_correlations(plan, rows, k, bounds, offsets)
    z, start_decimated = candidate_correlations(plan, rows, k, bounds, offsets, 1.0, stride)
    assert np.array_equal(start, start_decimated)
    # Exact sampling of the band-limited z, times the stride (the inverse FFT normalises by its
    # length, N / stride); float32 FFTs: 1e-6 of the peak, as above.
    width = 2 * plan.half + 1
    sampled = z_full[:, :width:stride]
    assert np.max(np.abs(z[:, :sampled.shape[1]] / stride - sampled)) < 1e-6 * np.max(np.abs(z_full))
    values = np.empty((3, 2 * (REFINE_HALF_WIDTH + stride - 1) + 1), dtype=complex)
    refined = np.empty((3, 2))
    local_kernels.local_peaks(z, start, rows, _dc(offsets), plan.tap_parts, plan.search(bounds, k, stride=stride),
                              values, refined)
    # The same direct values around the same largest |z|: the vertex to 1e-9 samples, as above.
    assert np.max(np.abs(refined[:, 0] - lag_ref)) < 1e-9
    assert np.max(np.abs(refined[:, 1] / peak_ref - 1.0)) < 1e-9


@pytest.mark.parametrize(
    "n, bounds, k, dc",
    [
        (N, (0, N - 201), 3, False),
        (N, (0, N - 201), 5, True),
        (N, (30_000, 30_100), 3, True),  # a window narrower than a stretch
        (N, (30_000, 30_002), 2, False),  # fewer lags than the decimation
        (N, (N - 400, N - 201), 3, False),  # at the record's end
        (700, (0, 499), 3, True),  # a record of a few blocks
        (260, (0, 59), 2, False),  # one block window
    ],
)
@pytest.mark.parametrize("seed", [5, 6])
def test_one_call_equals_the_fft_route_and_the_numpy_path(n, bounds, k, dc, seed):
    # ``local_echoes`` (coarse pass, direct search every ``decimation`` lags, refinement, echo
    # values in one call) against the FFT route it replaced (``candidate_correlations``, then
    # ``local_peaks`` and ``echo_rows``) and against the all-numpy path.
    from binsonar.detection import local_kernels

    plan = plan_local(_template(), n, FS)
    stride = plan.decimation
    rows, offsets = _rows(seed, dc)
    rows = np.ascontiguousarray(rows[:, :n])
    dc = _dc(offsets)
    sigma = np.array([0.01, 0.02, 0.03])
    t0_s = 1e-4
    constants = plan.echo_constants(t0_s, 2.5)
    search = plan.search(bounds, k)
    echoes, extremes = np.empty(3, dtype=ECHO), np.empty((3, 2))
    local_kernels.local_echoes(rows, dc, sigma, plan.tone_lanes, plan.tap_parts, plan.tap_parts32, search, constants,
                               echoes, extremes)
    assert np.array_equal(extremes, np.stack([rows.max(axis=1), rows.min(axis=1)], axis=1))

    z, start = candidate_correlations(plan, rows, k, bounds, offsets, 1.0, stride)
    values = np.empty((3, 2 * search[0]["reach"] + 1), dtype=complex)
    refined = np.empty((3, 2))
    local_kernels.local_peaks(z, start, rows, dc, plan.tap_parts, search, values, refined)
    expected = np.empty(3, dtype=ECHO)
    local_kernels.echo_rows(refined, sigma, constants, expected)
    # The same direct z at the same lags, whichever sampled lag each search found largest (the
    # FFT's float32 |z| and the direct float64 |z| differ by ~1e-6 of the peak): bit-identical.
    assert np.array_equal(echoes, expected)
    lag_ref, peak_ref = numpy_peaks(plan, rows, k, bounds, offsets)
    # The numpy path: lags to 1e-9 samples and powers to 1e-9 relative (sums of ~1000 terms in
    # another order), as above; a wrong pick would be off by whole samples.
    lag = (echoes["tof_s"] - t0_s + plan.matched.template.t0_s) * FS
    # Back from a TOF of <= 3 ms: its float64 rounding (~4e-19 s) is ~1e-11 samples, far below 1e-9.
    assert np.max(np.abs(lag - lag_ref)) < 1e-9
    amplitude = np.sqrt(peak_ref) / plan.matched.peak_response * np.max(np.abs(plan.matched.template.samples))
    assert np.max(np.abs(echoes["amplitude"] / amplitude - 1.0)) < 1e-9


@pytest.mark.parametrize("n, bounds", [(N, (0, N - 201)), (N, (30_000, 30_100)), (N, (N - 400, N - 201)),
                                       (700, (0, 499)), (260, (0, 59))])
@pytest.mark.parametrize("codes", [False, True])
def test_coarse_pass_measures_every_samples_extremes(n, bounds, codes):
    # The clipping test read with the coarse pass (chunk by chunk, then the samples outside the
    # searched blocks): every sample's largest and smallest value, exactly, and the same picks
    # as the coarse pass alone.
    from binsonar.detection import local_kernels

    plan = plan_local(_template(), n, FS)
    rows, _ = _rows(8, False)
    rows = rows[:, :n] * 1000.0
    if codes:
        rows = np.rint(rows).astype(np.int16)
    rows = np.ascontiguousarray(rows)
    rows[0, 0], rows[1, -1], rows[2, n // 2] = 3000, -3000, 2500  # first, last and a middle sample
    search = plan.search(bounds, 3)
    starts, alone = np.empty(9, dtype=np.int64), np.empty(9, dtype=np.int64)
    extremes = np.empty((3, 2))
    local_kernels.coarse_starts(rows, np.zeros(3), plan.tone_lanes, search, starts, extremes)
    local_kernels.coarse_starts(rows, np.zeros(3), plan.tone_lanes, search, alone, np.empty((0, 2)))
    assert np.array_equal(extremes, np.stack([rows.max(axis=1), rows.min(axis=1)], axis=1).astype(float))
    assert np.array_equal(starts, alone)


@pytest.mark.parametrize("n, bounds", [(N, (0, N - 201)), (N, (30_000, 30_100)), (700, (0, 499))])
@pytest.mark.parametrize("dc", [False, True])
def test_codes_coarse_pass_in_single_precision(n, bounds, dc):
    # int16 codes: block sums in float32 (``LocalPlan.tone_lanes32``). The block powers agree
    # with the float64 definition to ~1e-7 of the largest (48-term float32 sums; a wrong tap or
    # block would be off by O(1)), and the whole one-call path gives the float64 table's echoes.
    from binsonar.detection import local_kernels

    plan = plan_local(_template(), n, FS)
    volts, offsets = _rows(9, dc)
    step = 2.5 / 2048
    codes = np.ascontiguousarray(np.rint(volts[:, :n] / step).astype(np.int16))
    dc_v = np.zeros(3) if offsets is None else np.rint(offsets / step) * step
    energy = np.empty((3, n // plan.block))
    search = plan.search(bounds, 3, step)
    local_kernels.block_powers(codes, plan.tone_lanes32, search, 0, energy,
                               *local_kernels.tone_offsets(dc_v, plan.tone_lanes32, plan.block))
    expected = block_tone_power(plan, codes.astype(float) * step, dc_v)
    assert np.max(np.abs(energy - expected)) < 1e-6 * np.max(expected)
    constants = plan.echo_constants(0.0, 2.5)
    single, double = np.empty(3, dtype=ECHO), np.empty(3, dtype=ECHO)
    for lanes, echoes in ((plan.tone_lanes32, single), (plan.tone_lanes, double)):
        local_kernels.local_echoes(codes, dc_v, np.full(3, 0.01), lanes, plan.tap_parts, plan.tap_parts32, search,
                                   constants, echoes, np.empty((0, 2)))
    assert np.array_equal(single, double)
