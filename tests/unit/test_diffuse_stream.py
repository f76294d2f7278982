"""The diffuse tracer's random draws: the counter-based SplitMix64 stream (reference numpy), and the
fast engine's compiled draws against it, bit for bit."""

from __future__ import annotations

import numpy as np
import pytest

from acoustisim.propagation import prepare
from acoustisim.propagation.context import SolveContext
from acoustisim.propagation.fast import diffuse_sampling as compiled
from acoustisim.propagation.reference import diffuse as reference


@pytest.fixture(scope="module")
def context(thesis_tank) -> SolveContext:
    return SolveContext.build(thesis_tank, thesis_tank.sonar, prepare(thesis_tank).raycaster)


def test_the_stream_is_uniform_reproducible_and_counter_based():
    # 200k numbers of one chunk's stream: in [0, 1), mean 1/2 and variance 1/12 (to 4 sigma:
    # 4 / sqrt(12 n) = 2.6e-3 and 4 sqrt(1/180 n) = 6.7e-4), a Kolmogorov-Smirnov distance
    # under its 0.1 % quantile 1.95 / sqrt(n), no lag-1 correlation beyond 4 / sqrt(n); drawn
    # in pieces (the tracer's first bounce, then later ones) the same numbers as in one call;
    # another chunk or seed gives an uncorrelated stream.
    n = 200_000
    whole = reference.RayStream(7, 3).next(1, n)[0]
    stream = reference.RayStream(7, 3)
    pieces = np.concatenate([stream.next(1, 1).ravel(), stream.next(2, 500).ravel(), stream.next(1, n - 1001).ravel()])
    np.testing.assert_array_equal(whole, pieces)
    assert stream.drawn == n
    np.testing.assert_array_equal(reference.stream_uniforms(reference.stream_key(7, 3), 1000, 50), whole[1000:1050])
    assert np.all((whole >= 0.0) & (whole < 1.0))
    assert abs(whole.mean() - 0.5) < 4 / np.sqrt(12 * n)
    assert abs(whole.var() - 1 / 12) < 4 * np.sqrt(1 / (180 * n))
    ordered = np.sort(whole)
    ks = max(np.max(np.arange(1, n + 1) / n - ordered), np.max(ordered - np.arange(n) / n))
    assert ks < 1.95 / np.sqrt(n)
    centred = whole - 0.5
    assert abs(np.mean(centred[1:] * centred[:-1]) * 12) < 4 / np.sqrt(n)
    for other in (reference.RayStream(7, 4).next(1, n)[0], reference.RayStream(8, 3).next(1, n)[0]):
        assert abs(np.corrcoef(whole, other)[0, 1]) < 4 / np.sqrt(n)
        assert not np.array_equal(whole[:10], other[:10])


def test_splitmix64_matches_its_published_outputs():
    # SplitMix64 seeded with 0: the first outputs of the generator (state += gamma, then the
    # output function), as in Vigna's reference C implementation (splitmix64.c)
    first = reference.splitmix64(np.arange(3, dtype=np.uint64) * reference.SPLITMIX_GAMMA)
    assert first.tolist() == [0xE220A8397B1DCDAF, 0x6E789E6AA1B965F4, 0x06C45D188009454F]
    # the compiled version, scalar by scalar, and the stream keys
    for x in (0, 1, 2**63 + 12345, 2**64 - 1):
        assert int(compiled.splitmix64(np.uint64(x))) == int(reference.splitmix64(np.array([x], dtype=np.uint64))[0])
    for seed, chunk in ((0, 0), (7, 3), (123456, 99)):
        assert compiled.stream_key(reference.seed_hash(seed), chunk) == reference.stream_key(seed, chunk)


def test_the_compiled_lobe_table_is_the_reference_sampler(context):
    sampler = reference.TransmitSampler.create(context, 50_000)
    table = compiled.lobe_table(context, reference.ray_counts(50_000))
    np.testing.assert_array_equal(table.guide, sampler.guide)
    np.testing.assert_array_equal(table.solid_angle, sampler.solid_angle)
    np.testing.assert_array_equal(table.azimuth, reference.azimuth_table())


def test_the_compiled_draws_are_the_reference_draws(context):
    # directions drawn inside the compiled loops from the chunk's stream against the reference's
    # numpy draws from the same numbers: the same bits (an offset in the stream or a swapped
    # row would change every ray)
    n, chunk = 5_000, 2
    key = reference.stream_key(11, chunk)
    sampler = reference.TransmitSampler.create(context, 3 * reference.CHUNK_RAYS)
    table = compiled.lobe_table(context, sampler.counts)
    frame = reference.transmitter_frame(context.boresight)
    stream = reference.RayStream(11, chunk)
    expected, expected_weight = sampler.draw(stream.next(2, n), frame)
    directions, weight = np.empty((3, n)), np.empty(n)
    compiled.draw_transmit_directions(key, 0, reference.uniform_count(n), table, np.array(frame), directions, weight)
    np.testing.assert_array_equal(directions.T, expected)
    np.testing.assert_array_equal(weight, expected_weight)
    assert np.max(np.abs(np.linalg.norm(directions, axis=0) - 1.0)) < 1e-15
    # a later bounce: cosine-weighted directions about normals of every orientation
    normals = np.random.default_rng(3).normal(size=(n, 3))
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    expected = reference.lambert_directions(stream.next(2, n), normals)
    scattered = np.empty((3, n))
    compiled.draw_lambert_directions(key, 2 * n, np.ascontiguousarray(normals.T), table.azimuth, scattered)
    np.testing.assert_array_equal(scattered.T, expected)
    assert np.all(np.einsum("ij,ij->i", expected, normals) >= 0.0)


def test_the_table_azimuth_equals_cos_and_sin():
    # the azimuth rotated from a 1024-entry table by Taylor polynomials (truncation < 1e-16):
    # over 200k uniform turns and the ends of [0, 1), within 4 float64 ulps of 1 (8.9e-16) of
    # numpy's cos and sin of 2 pi u (whose own argument 2 pi u is rounded by up to 4.4e-16 near
    # 2 pi), and of unit length to 2 ulps; a wrong table row, sign or series term would be off
    # by > 1e-6. The compiled rotation gives the same bits.
    u = np.concatenate([[0.0, 0.25, 0.5, 1.0 - 2.0**-53, 1023.5 / 1024], np.random.default_rng(5).random(200_000)])
    cos_phi, sin_phi = reference.azimuth_cos_sin(u)
    assert np.max(np.abs(cos_phi - np.cos(2 * np.pi * u))) < 1e-15
    assert np.max(np.abs(sin_phi - np.sin(2 * np.pi * u))) < 1e-15
    assert np.max(np.abs(np.hypot(cos_phi, sin_phi) - 1.0)) < 5e-16
    table = reference.azimuth_table()
    pairs = np.array([compiled.unit_azimuth(float(x), table) for x in u[:2000]])
    np.testing.assert_array_equal(pairs, np.column_stack([cos_phi[:2000], sin_phi[:2000]]))


def test_the_compiled_speckle_is_the_reference_speckle():
    # points on cube faces too (whole millimetres, like the tank's walls), where floor() decides
    rng = np.random.default_rng(2)
    points = np.concatenate([rng.uniform(-5, 5, (2000, 3)), np.round(rng.uniform(-5, 5, (500, 3)), 3)])
    magnitude, phase = reference.speckle_polar(points, 9)
    per_cell, key = 1.0 / reference.SPECKLE_CELL_M, reference.seed_hash(9)
    fast = np.array([compiled.speckle_of(x, y, z, per_cell, key) for x, y, z in points.tolist()])
    # numpy's and the compiled log may differ in the last bit
    np.testing.assert_allclose(fast[:, 0], magnitude, rtol=1e-15)
    np.testing.assert_array_equal(fast[:, 1], phase)
