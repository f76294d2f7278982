"""``peaks_above``: one refined peak per region of a statistic above a threshold (the peak
picking shared by the energy and DWT detectors)."""

from __future__ import annotations

import numpy as np

from binsonar.detection.peaks import parabolic_offset, peaks_above


def _reference(values: np.ndarray, threshold: float):
    """The straightforward per-region loop, as an independent reference for the vectorised search."""
    out = []
    above = values > threshold
    bounds = np.flatnonzero(np.diff(np.concatenate([[0], above.astype(np.int8), [0]])))
    for a, b in zip(bounds[::2], bounds[1::2]):
        c = a + int(np.argmax(values[a:b]))
        if 0 < c < values.size - 1:
            o, p = parabolic_offset(values[c - 1:c], values[c:c + 1], values[c + 1:c + 2])
            out.append((a, c, float(o[0]), float(p[0])))
        else:
            out.append((a, c, 0.0, float(values[c])))
    return out


def test_vertex_of_a_sampled_parabola_is_exact():
    # A parabola with its vertex at 10.3 and value 5: the three-point vertex is exact (to rounding).
    x = np.arange(21, dtype=float)
    values = 5.0 - 0.2 * (x - 10.3) ** 2
    start, index, offset, peak = peaks_above(values, 0.0)
    assert start.tolist() == [int(np.argmax(values > 0.0))] and index.tolist() == [10]
    assert abs(offset[0] - 0.3) < 1e-12 and abs(peak[0] - 5.0) < 1e-12


def test_regions_at_the_edges_plateaus_and_none():
    values = np.array([3.0, 2.0, 0.0, 1.0, 2.0, 2.0, 1.0, 0.0, 4.0])
    start, index, offset, peak = peaks_above(values, 0.5)
    # Edge maxima are not interpolated (a neighbour is missing); a plateau gives its first sample.
    assert start.tolist() == [0, 3, 8] and index.tolist() == [0, 4, 8]
    assert offset[0] == 0.0 and peak[0] == 3.0 and offset[2] == 0.0 and peak[2] == 4.0
    assert all(v.size == 0 for v in peaks_above(values, 10.0))


def test_agrees_with_the_per_region_loop_on_noise():
    rng = np.random.default_rng(2)
    for _ in range(20):
        values = np.convolve(rng.standard_normal(500), np.ones(7) / 7, mode="same")
        start, index, offset, peak = peaks_above(values, 0.3)
        expected = _reference(values, 0.3)
        assert len(expected) > 0
        assert start.tolist() == [e[0] for e in expected] and index.tolist() == [e[1] for e in expected]
        assert np.array_equal(offset, [e[2] for e in expected]) and np.array_equal(peak, [e[3] for e in expected])
