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


def test_the_table_azimuth_equals_cos_and_sin():
    # unit_azimuth rotates a 1024-entry table by Taylor polynomials (truncation < 1e-16): over
    # 200k uniform turns and the ends of [0, 1), within 4 float64 ulps of 1 (8.9e-16) of numpy's
    # cos and sin of 2 pi u (whose own argument 2 pi u is rounded by up to 4.4e-16 near 2 pi),
    # and of unit length to 2 ulps; a wrong table row, sign or series term would be off by > 1e-6
    from numba import njit

    from acoustisim.propagation.diffuse_kernels import azimuth_table, unit_azimuth

    @njit(cache=False)
    def evaluate(u, table, out):
        for i in range(u.size):
            out[i, 0], out[i, 1] = unit_azimuth(u[i], table)

    u = np.concatenate([[0.0, 0.25, 0.5, 1.0 - 2.0**-53, 1023.5 / 1024], np.random.default_rng(5).random(200_000)])
    out = np.empty((u.size, 2))
    evaluate(u, azimuth_table(), out)
    assert np.max(np.abs(out[:, 0] - np.cos(2 * np.pi * u))) < 1e-15
    assert np.max(np.abs(out[:, 1] - np.sin(2 * np.pi * u))) < 1e-15
    assert np.max(np.abs(np.hypot(out[:, 0], out[:, 1]) - 1.0)) < 5e-16


def test_directions_drawn_in_the_kernel_equal_those_of_the_stream_numbers():
    # draw_transmit_directions draws numbers start .. start + 2n - 1 of the chunk's stream in its
    # loop; transmit_directions of the same numbers as an array (2, n) must give bit-identical
    # directions and solid angles (a stream offset or row swap would change every ray); the
    # directions are unit vectors (to 4 ulps) whatever the draw
    from acoustisim.propagation import diffuse_kernels as kernels
    from acoustisim.propagation.diffuse import _basis

    n, start, n_uniform = 5_000, 123, 2_500
    key = _seed_hash(11)
    guide = (np.arange(1 << 16) // 8).astype(np.int16)  # 8192 cells, 8 bins each
    cells = np.empty(8192)
    kernels.cell_table(np.full(8192, 1.0 / (4 * np.pi)), n_uniform / (4 * np.pi), float(n - n_uniform), cells)
    axis = np.array([0.6, 0.0, 0.8])
    frame = (*_basis(axis), axis)
    table = kernels.azimuth_table()
    fused = np.empty((3, n)), np.empty(n)
    kernels.draw_transmit_directions(key, start, n, n_uniform, guide, cells, 2.0 / 8192, table, *frame, *fused)
    u = np.empty(start + 2 * n)
    kernels.splitmix_uniforms(key, 0, u)
    reference = np.empty((3, n)), np.empty(n)
    kernels.transmit_directions(np.ascontiguousarray(u[start:].reshape(2, n)), n_uniform, guide, cells, 2.0 / 8192,
                                table, *frame, *reference)
    np.testing.assert_array_equal(fused[0], reference[0])
    np.testing.assert_array_equal(fused[1], reference[1])
    assert np.max(np.abs(np.linalg.norm(fused[0], axis=0) - 1.0)) < 1e-15
