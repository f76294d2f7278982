"""The threshold detector's compiled loop (``threshold_kernels``) against its numpy definitions
in the package (``threshold.first_crossings``, ``crossing_measures``, ``crossing_echo_values``)."""

from __future__ import annotations

import numpy as np
import pytest

from binsonar.detection.kernel_types import CROSSING_SEARCH, ECHO, record
from binsonar.detection.threshold import crossing_echo_values, crossing_measures, first_crossings
from binsonar.detection.threshold_kernels import CHUNK, crossings


def _search(first: int, stop: int, window: int, fs: float = 20e6, t0_s: float = 0.0, offset_s: float = 0.0,
            scale: float = 1.0) -> np.ndarray:
    return record(CROSSING_SEARCH, scale=scale, first=first, stop=stop, window=window, sample_rate_hz=fs, t0_s=t0_s,
                  offset_s=offset_s)


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
    crossings(rows, offset, level, _search(first, stop, 201), found, measures)
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


@pytest.mark.parametrize("first, stop", [(0, 5000), (10, 4990)])
def test_compiled_echo_values_equal_the_numpy_definition(first, stop):
    from binsonar.detection.threshold_kernels import threshold_echoes

    rows, level, offset = _case(2)
    sigma = np.array([0.1, 0.2, 1e-30, 0.05, 0.1, 0.1])  # 1e-30: a noise-free row (SNR capped)
    found = np.empty(6, dtype=np.int64)
    measures = np.empty((6, 4))
    crossings(rows, offset, level, _search(first, stop, 201), found, measures)
    fs, t0_s, offset_s = 20e6, 1e-4, 3e-7
    found_too = np.empty(6, dtype=np.int64)
    values = np.empty(6, dtype=ECHO)
    threshold_echoes(rows, offset, level, sigma, _search(first, stop, 201, fs, t0_s, offset_s), found_too, values)
    assert np.array_equal(found_too, found)
    echoes = np.stack([values[name] for name in ECHO.names], axis=1)
    expected = crossing_echo_values(found, measures, level, sigma, 201, fs, t0_s, offset_s)
    # The same operations in the same order (numpy's log10 and numba's may differ by an ulp).
    np.testing.assert_allclose(echoes[found >= 0], expected, rtol=1e-15, atol=0.0)
    assert np.isnan(echoes[found < 0]).all()


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
    crossings(codes, offset, level, _search(0, 3000, 50, scale=step), found_codes, measures_codes)
    crossings(codes * step, offset, level, _search(0, 3000, 50), found_volts, measures_volts)
    assert found_codes.tolist() == found_volts.tolist() == [CHUNK, 2 * CHUNK - 1, 0, -1]
    np.testing.assert_array_equal(measures_codes[:3, :3], measures_volts[:3, :3])
    np.testing.assert_allclose(measures_codes[:3, 3], measures_volts[:3, 3], rtol=1e-12)
