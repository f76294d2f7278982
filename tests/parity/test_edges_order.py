"""The fast engine's packed-key ordering of the edge rows against ``np.lexsort``, the stable sort
by (channel, delay) the reference assembly applies."""

from __future__ import annotations

import numpy as np
import pytest

from acoustisim.propagation.fast.edge_order import solver_order

C = 1482.38


def _lexsort_order(keep, point_pair, path_length, pair_rx, c):
    return keep[np.lexsort((path_length[keep] / c, pair_rx[point_pair[keep]]))]


@pytest.mark.parametrize(("n_rx", "longest_m"), [(3, 20.0), (4, 20.0), (1, 20.0), (3, 2.5 * C), (5, 20.0)])
def test_order_equals_the_stable_lexsort(n_rx, longest_m):
    # (3 and 4 channels and delays below 2 s: the packed key; 2.5 s delays or 5 channels: the
    # lexsort fallback)
    rng = np.random.default_rng(n_rx)
    n_points, n_pairs = 6000, 40
    point_pair = np.sort(rng.integers(0, n_pairs, n_points))
    pair_rx = rng.integers(0, n_rx, n_pairs)
    # path lengths from a small set, so that many delays tie exactly (within and across channels)
    path_length = rng.choice(rng.uniform(0.5, longest_m, 500), n_points)
    path_length[:10] = longest_m  # the largest delay present
    keep = np.flatnonzero(rng.random(n_points) < 0.9)
    got = solver_order(keep, point_pair, path_length, pair_rx, C, n_rx)
    want = _lexsort_order(keep, point_pair, path_length, pair_rx, C)
    np.testing.assert_array_equal(got, want)
    # the ties are real: many equal (channel, delay) keys, kept in index order
    delay = path_length[got] / C
    assert np.sum((np.diff(delay) == 0.0) & (np.diff(pair_rx[point_pair[got]]) == 0)) > 100


def test_order_of_nothing():
    empty = np.zeros(0, dtype=np.int64)
    assert solver_order(empty, np.zeros(3, dtype=np.int64), np.ones(3), np.zeros(1, dtype=np.int64), C, 3).size == 0
