"""The threshold detector's compiled loop (``threshold_kernels``) against its numpy definition
(``threshold.first_crossings`` and the numpy ``crossing_measures`` below)."""

from __future__ import annotations

import numpy as np
import pytest

from numpy.typing import NDArray

from binsonar.detection.threshold import first_crossings
from binsonar.detection.threshold_kernels import CHUNK, crossings


def crossing_measures(
    rows: NDArray[np.float64], found: NDArray[np.intp], offset: NDArray[np.float64], window: int
) -> NDArray[np.float64]:
    """What the detector measures at each row's crossing (the numpy reference of the compiled
    ``threshold_kernels.crossings``).

    Parameters
    ----------
    rows : ndarray, shape (n_rows, n_samples)
    found : ndarray of int, shape (n_rows,)
        Crossing sample of each row (``first_crossings``; -1: none).
    offset : ndarray, shape (n_rows,)
        DC offset of each row.
    window : int
        Samples measured from the crossing on (indices clipped to the row).

    Returns
    -------
    ndarray, shape (n_rows, 4)
        |x - offset| before the crossing (at it for sample 0) and at it, the largest |x - offset|
        and the sum of (x - offset)^2 over the window; NaN where there is no crossing.
    """
    n_rows, n = rows.shape
    out = np.full((n_rows, 4), np.nan)
    hit = np.flatnonzero(found >= 0)
    i = found[hit]
    out[hit, 0] = np.abs(rows[hit, np.maximum(i - 1, 0)] - offset[hit])
    out[hit, 1] = np.abs(rows[hit, i] - offset[hit])
    segment = rows[hit[:, np.newaxis], np.clip(i[:, np.newaxis] + np.arange(window), 0, n - 1)] - offset[hit, np.newaxis]
    out[hit, 2] = np.abs(segment).max(axis=1)
    out[hit, 3] = (segment ** 2).sum(axis=1)
    return out


def _case(seed: int, n: int = 5000) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    # Rows of noise with offsets, one level per row; crossings placed at chunk edges, at sample
    # 0, at the last sample, inside a chunk, and a row that never crosses.
    rng = np.random.default_rng(seed)
    offset = np.array([0.0, 0.5, -2.0, 1e-3, 3.0, 0.0])
    rows = rng.standard_normal((6, n)) * 0.1 + offset[:, np.newaxis]
    level = np.full(6, 1.0)
    rows[0, 3 * CHUNK] = offset[0] + 1.0  # exactly at the level (>=), on a chunk's first sample
    rows[1, 0] = offset[1] - 1.5  # below the offset: |x - offset| counts
    rows[2, n - 1] = offset[2] + 1.2  # the last sample (a window past the end repeats it)
    rows[3, 777] = offset[3] + 1.0 + 1e-12
    rows[3, 4000] = offset[3] + 5.0  # a later, larger one must not win
    rows[4, 2 * CHUNK - 1] = offset[4] - 1.0  # a chunk's last sample
    return rows, level, offset


@pytest.mark.parametrize("first, stop", [(0, 5000), (10, 4990), (700, 800), (0, 1)])
def test_compiled_crossings_equal_the_numpy_definition(first, stop):
    rows, level, offset = _case(1)
    found = np.empty(6, dtype=np.int64)
    measures = np.empty((6, 4))
    crossings(rows, 1.0, level, offset, first, stop, 201, found, measures)
    reference = first_crossings(rows[:, first:stop], level, offset)
    reference = np.where(reference >= 0, reference + first, -1)
    assert np.array_equal(found, reference)
    if first == 0 and stop == 5000:  # the planted crossings are found where they are
        assert found.tolist() == [3 * CHUNK, 0, 4999, 777, 2 * CHUNK - 1, -1]
    # Same samples, so the same values; the energy is summed in another order (1e-12 relative).
    expected = crossing_measures(rows, reference, offset, 201)
    assert np.array_equal(np.isnan(measures), np.isnan(expected))
    ok = ~np.isnan(expected)
    assert np.array_equal(measures[:, :3][ok[:, :3]], expected[:, :3][ok[:, :3]])
    assert np.allclose(measures[:, 3][ok[:, 3]], expected[:, 3][ok[:, 3]], rtol=1e-12, atol=0.0)


def threshold_echo_values(found: NDArray[np.intp], measures: NDArray[np.float64], level: NDArray[np.float64],
                          sigma: NDArray[np.float64], window: int, fs: float, t0_s: float,
                          offset_s: float) -> NDArray[np.float64]:
    """The echo values of each crossing: the numpy reference of the compiled
    ``threshold_kernels.threshold_echoes`` (what ``detect_threshold`` computed with numpy).

    Returns
    -------
    ndarray, shape (n_hit, 5)
        tof_s, amplitude, snr_db, score, tof_std_s of the rows that cross, in row order.
    """
    from binsonar.detection.threshold import _fraction

    hit = np.flatnonzero(found >= 0)
    i = found[hit]
    before, after, amplitude, total = measures[hit].T
    frac = np.where(i > 0, _fraction(before, after, level[hit]), 0.0)
    tof = t0_s + (i - 1 + frac) / fs - offset_s
    noise_var = np.maximum(sigma[hit] ** 2, 1e-20 * total)
    snr = np.maximum((total - window * sigma[hit] ** 2) / noise_var, 1e-3)
    slope = np.maximum((after - before) * fs, np.finfo(float).tiny)
    return np.stack([tof, amplitude, 10 * np.log10(snr), amplitude / level[hit], sigma[hit] / slope], axis=1)


@pytest.mark.parametrize("first, stop", [(0, 5000), (10, 4990)])
def test_compiled_echo_values_equal_the_numpy_definition(first, stop):
    from binsonar.detection.threshold_kernels import threshold_echoes

    rows, level, offset = _case(2)
    sigma = np.array([0.1, 0.2, 1e-30, 0.05, 0.1, 0.1])  # 1e-30: a noise-free row (SNR capped)
    found = np.empty(6, dtype=np.int64)
    measures = np.empty((6, 4))
    crossings(rows, 1.0, level, offset, first, stop, 201, found, measures)
    fs, t0_s, offset_s = 20e6, 1e-4, 3e-7
    echoes = np.empty((6, 6))
    threshold_echoes(rows, 1.0, np.stack([level, offset, sigma], axis=1), np.array([first, stop, 201]),
                     np.array([fs, t0_s, offset_s]), echoes)
    assert echoes[:, 0].tolist() == (found >= 0).astype(float).tolist()
    expected = threshold_echo_values(found, measures, level, sigma, 201, fs, t0_s, offset_s)
    # The same operations in the same order (numpy's log10 and numba's may differ by an ulp).
    np.testing.assert_allclose(echoes[found >= 0, 1:], expected, rtol=1e-15, atol=0.0)
    assert np.isnan(echoes[found < 0, 1:]).all()


def test_codes_cross_where_their_volts_do():
    # int16 codes searched as they are (integer extremes per chunk) against their volts
    # (float chunk extremes), with the crossings planted at chunk edges as above.
    rng = np.random.default_rng(4)
    step = 1.0 / 1024
    codes = rng.integers(-200, 200, (4, 3000)).astype(np.int16)
    codes[0, CHUNK] = 1024  # exactly at the level (1 V): on a chunk's first sample
    codes[1, 2 * CHUNK - 1] = -1500  # below the offset, a chunk's last sample
    codes[2, 0] = 1200  # 1.17 V - 0.1 V offset: crosses on sample 0
    offset = np.array([0.0, -0.25, 0.1, 0.0])
    level = np.full(4, 1.0)
    found_codes = np.empty(4, dtype=np.int64)
    found_volts = np.empty(4, dtype=np.int64)
    measures_codes = np.empty((4, 4))
    measures_volts = np.empty((4, 4))
    crossings(codes, step, level, offset, 0, 3000, 50, found_codes, measures_codes)
    crossings(codes * step, 1.0, level, offset, 0, 3000, 50, found_volts, measures_volts)
    assert found_codes.tolist() == found_volts.tolist() == [CHUNK, 2 * CHUNK - 1, 0, -1]
    np.testing.assert_array_equal(measures_codes[:3, :3], measures_volts[:3, :3])
    np.testing.assert_allclose(measures_codes[:3, 3], measures_volts[:3, 3], rtol=1e-12)
