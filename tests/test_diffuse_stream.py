"""The diffuse tracer's per-chunk random numbers: a counter-based SplitMix64 stream."""

from __future__ import annotations

import numpy as np

from acoustisim.propagation.diffuse import _ChunkStream, _seed_hash


def test_the_stream_is_uniform_reproducible_and_counter_based():
    # 200k numbers of one chunk's stream: in [0, 1), mean 1/2 and variance 1/12 (to 4 sigma:
    # 4 / sqrt(12 n) = 2.6e-3 and 4 sqrt(1/180 n) = 6.7e-4), a Kolmogorov-Smirnov distance
    # under its 0.1 % quantile 1.95 / sqrt(n), no lag-1 correlation beyond 4 / sqrt(n); drawn
    # in pieces (the tracer's first bounce, then later ones) the same numbers as in one call;
    # the same seed and chunk give the same stream, another chunk or seed an uncorrelated one.
    n = 200_000
    key = _seed_hash(7)
    whole = _ChunkStream.create(key, 3).random(n)
    stream = _ChunkStream.create(key, 3)
    pieces = np.concatenate([stream.random(1), stream.random((2, 500)).ravel(), stream.random(n - 1001)])
    np.testing.assert_array_equal(whole, pieces)
    assert stream.drawn == n
    assert np.all((whole >= 0.0) & (whole < 1.0))
    assert abs(whole.mean() - 0.5) < 4 / np.sqrt(12 * n)
    assert abs(whole.var() - 1 / 12) < 4 * np.sqrt(1 / (180 * n))
    ordered = np.sort(whole)
    ks = max(np.max(np.arange(1, n + 1) / n - ordered), np.max(ordered - np.arange(n) / n))
    assert ks < 1.95 / np.sqrt(n)
    centred = whole - 0.5
    assert abs(np.mean(centred[1:] * centred[:-1]) * 12) < 4 / np.sqrt(n)
    for other in (_ChunkStream.create(key, 4).random(n), _ChunkStream.create(_seed_hash(8), 3).random(n)):
        assert abs(np.corrcoef(whole, other)[0, 1]) < 4 / np.sqrt(n)
        assert not np.array_equal(whole[:10], other[:10])
    out = np.empty((2, 50))
    assert _ChunkStream.create(key, 3).random(out=out) is out
    np.testing.assert_array_equal(out.ravel(), whole[:100])
