"""The compiled candidate-to-chain loops of the specular solver against straightforward code.

``specular_rows`` builds its chains, legs, duplicate keys and rows with the compiled loops of
:mod:`acoustisim.propagation.specular_chains` and :mod:`acoustisim.propagation.specular_kernels`;
the rows as a whole are checked against the frozen numpy solver in
``test_propagation_specular_fast.py``. Here each loop is checked on its own against the numpy
(or plain-loop) expression it replaced, exactly where the arithmetic is the same.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from numba import njit
from numpy.typing import NDArray

from acoustisim.propagation.context import SolveContext
from acoustisim.propagation.curved import go_amplitude_general, go_factors_at
from acoustisim.propagation.image_source import unfold
from acoustisim.propagation.paths import MAX_INTERACTIONS
from acoustisim.propagation.prepared import PreparedScene, prepare
from acoustisim.propagation.specular import _planar_and_mixed, _receivers_in_front, _unblocked, first_distinct_rows
from acoustisim.propagation.specular_chains import duplicate_keys
from acoustisim.propagation.specular_kernels import circle_newton, unfold_reversed


@njit(cache=False)
def _newton_every_row(ax, ay, bx, by, rad, phi, max_steps, tol):  # pragma: no cover - compiled
    """The Newton loop before the fixed-point skip: every row steps until none moves."""
    n = phi.shape[0]
    for _ in range(max_steps):
        moving = False
        for i in range(n):
            r = rad[i]
            c, s = math.cos(phi[i]), math.sin(phi[i])
            xx, xy = r * c, r * s
            dax, day, dbx, dby = ax[i] - xx, ay[i] - xy, bx[i] - xx, by[i] - xy
            ra, rb = math.hypot(dax, day), math.hypot(dbx, dby)
            rpa = -r * (-dax * s + day * c) / ra
            rpb = -r * (-dbx * s + dby * c) / rb
            d1 = rpa + rpb
            r2 = r * r
            d2 = (r2 + dax * xx + day * xy - rpa * rpa) / ra + (r2 + dbx * xx + dby * xy - rpb * rpb) / rb
            step = d1 / (d2 if abs(d2) > 1e-300 else 1e-300)
            if step < -0.5:
                step = -0.5
            elif step > 0.5:
                step = 0.5
            phi[i] = phi[i] - step
            if abs(step) > tol:
                moving = True
        if not moving:
            break
    return phi


@pytest.fixture(scope="module")
def thesis_tank() -> PreparedScene:
    from scenes.builtin import builtin_scene

    return prepare(builtin_scene("thesis-tank"))


def _poses(prepared: PreparedScene, n: int, seed: int) -> list[SolveContext]:
    from dataclasses import replace

    from acoustisim.errors import InputError
    from acoustisim.propagation.solver import check_sonar

    rng = np.random.default_rng(seed)
    contexts = [SolveContext.build(prepared.scene, prepared.scene.sonar, prepared.raycaster)]
    while len(contexts) < n:
        sonar = replace(prepared.scene.sonar, position_m=tuple(rng.uniform((0.3, 0.3, 0.15), (8.7, 2.7, 0.85))),
                        yaw_deg=float(rng.uniform(-180, 180)), pitch_deg=float(rng.uniform(-20, 20)))
        try:
            check_sonar(prepared, sonar)
        except InputError:
            continue
        contexts.append(SolveContext.build(prepared.scene, sonar, prepared.raycaster))
    return contexts


def _chains(prepared: PreparedScene, context: SolveContext):
    mirrors = prepared.mirrors
    first = mirrors.signed_distance(np.broadcast_to(context.transmitter_m, (mirrors.count, 3)),
                                    np.arange(mirrors.count)) > 0
    return _planar_and_mixed(context, prepared, 3, first, _receivers_in_front(context, mirrors))[0]


def test_newton_skipping_fixed_points_is_bit_for_bit_stepping_every_row():
    rng = np.random.default_rng(2)
    n = 4000
    rad = rng.uniform(0.01, 0.3, n)
    angle_a, angle_b = rng.uniform(-np.pi, np.pi, (2, n))
    dist_a, dist_b = rng.uniform(1.05, 40.0, (2, n)) * rad
    ax, ay = dist_a * np.cos(angle_a), dist_a * np.sin(angle_a)
    bx, by = dist_b * np.cos(angle_b), dist_b * np.sin(angle_b)
    # monostatic rows (the bisector start is already the answer), opposite ends (degenerate)
    bx[:500], by[:500] = ax[:500], ay[:500]
    bx[500:600], by[500:600] = -ax[500:600], -ay[500:600]
    sx, sy = ax / np.hypot(ax, ay) + bx / np.hypot(bx, by), ay / np.hypot(ax, ay) + by / np.hypot(bx, by)
    start = np.arctan2(sy, sx)
    for max_steps in (1, 2, 3, 5, 40):
        skipped = circle_newton(ax, ay, bx, by, rad, start.copy(), max_steps, 1e-10)
        every = _newton_every_row(ax, ay, bx, by, rad, start.copy(), max_steps, 1e-10)
        np.testing.assert_array_equal(skipped, every)
    # and the answer is the specular point, d/dphi (|a - X| + |b - X|) = 0, on the rows where it
    # is lit from both ends (the solver's validity; the others are discarded) and both ends are
    # beyond 1.5 radii (a known limitation: from the bisector start, the clipped Newton steps can
    # cycle between two angles when an end is within a few percent of a radius of the surface;
    # no such row occurred among the 80,000 valid specular points of 60 random thesis-tank poses)
    c, s = np.cos(skipped), np.sin(skipped)
    x, y = rad * c, rad * s
    lit = ((ax - x) * c + (ay - y) * s > 0) & ((bx - x) * c + (by - y) * s > 0)
    lit &= (np.minimum(dist_a, dist_b) > 1.5 * rad)
    lit[500:600] = False
    derivative = (rad * (ax * s - ay * c) / np.hypot(ax - x, ay - y)
                  + rad * (bx * s - by * c) / np.hypot(bx - x, by - y))
    assert np.count_nonzero(lit) > n // 3
    # |d| of a converged angle: round-off of terms of size rad, about 1e-16 rad
    assert np.max(np.abs(derivative[lit]) / rad[lit]) < 1e-12


def test_go_factors_match_the_numpy_formula():
    rng = np.random.default_rng(4)
    n = 5000
    a, b, x, normal, e1, e2 = (rng.normal(size=(n, 3)) for _ in range(6))
    k11, k22, k12 = (rng.normal(size=n) for _ in range(3))

    def dot(u: NDArray[np.float64], v: NDArray[np.float64]) -> NDArray[np.float64]:
        return np.einsum("ij,ij->i", u, v)

    d1, d2 = x - a, x - b
    r1, r2 = np.linalg.norm(d1, axis=1), np.linalg.norm(d2, axis=1)
    s1, s2 = d1 / r1[:, None], d2 / r2[:, None]
    cos_i, cos_s = np.abs(dot(s1, normal)), np.abs(dot(s2, normal))
    a1, a2, b1, b2 = dot(e1, s1), dot(e2, s1), dot(e1, s2), dot(e2, s2)
    c = cos_i + cos_s
    h11 = (1.0 - a1 * a1) / r1 + (1.0 - b1 * b1) / r2 + c * k11
    h22 = (1.0 - a2 * a2) / r1 + (1.0 - b2 * b2) / r2 + c * k22
    h12 = -a1 * a2 / r1 - b1 * b2 / r2 + c * k12
    det = h11 * h22 - h12 * h12
    signature = np.where(det < 0, 0, np.where(h11 + h22 > 0, 2, -2))
    amplitude = cos_i / (r1 * r2 * np.sqrt(np.abs(det)))
    phase = -(np.pi / 4.0) * (signature - 2)
    got_amplitude, got_phase = go_amplitude_general(a, b, x, normal, e1, e2, k11, k22, k12)
    # the same terms in the same order; only the summation order of numpy's 3-term dot
    # products (einsum's, version dependent) may differ, a few ulps of each dot product, which
    # |det H| can amplify where it nearly cancels (hence not exact, and 1e-9 relative on the
    # rows whose det is not within 1e-6 of cancelling)
    well = np.abs(det) > 1e-6 * (np.abs(h11 * h22) + h12 * h12)
    np.testing.assert_allclose(got_amplitude[well], amplitude[well], rtol=1e-9, atol=0.0)
    np.testing.assert_array_equal(got_phase[well], phase[well])
    rows = rng.permutation(n)[:700]
    picked = go_factors_at(rows, a, b, x, normal, e1, e2, k11, k22, k12)
    np.testing.assert_array_equal(picked[0], got_amplitude[rows])
    np.testing.assert_array_equal(picked[1], got_phase[rows])


def test_first_distinct_rows_equals_numpy_unique_on_large_keys():
    rng = np.random.default_rng(8)
    for n, columns, spread in ((1, 3, 2), (2, 3, 1), (5000, 18, 2), (20000, 4, 3)):
        key = rng.integers(-spread, spread, (n, columns))
        expected = np.sort(np.unique(key, axis=0, return_index=True)[1])
        np.testing.assert_array_equal(first_distinct_rows(key), expected)


def test_unfold_reversed_equals_unfold_of_the_repeated_rows(thesis_tank: PreparedScene):
    mirrors = thesis_tank.mirrors
    receivers = np.random.default_rng(1).uniform((0.5, 0.5, 0.2), (8.5, 2.5, 0.8), (3, 3))
    for length in (0, 1, 2, 3):
        seqs = mirrors.sequences(length)
        rows = np.repeat(np.arange(seqs.shape[0]), 3)
        expected = unfold(mirrors, receivers[np.tile(np.arange(3), seqs.shape[0])], seqs[rows][:, ::-1])
        got = unfold_reversed(mirrors.point, mirrors.normal, receivers, seqs)
        np.testing.assert_array_equal(got[0], expected[0])
        np.testing.assert_array_equal(got[1], expected[1])


def test_unblocked_chains_equal_one_occlusion_query_over_the_padded_legs(thesis_tank: PreparedScene):
    total = 0
    for context in _poses(thesis_tank, 4, seed=6):
        chains = _chains(thesis_tank, context)
        n, big = chains.surface.shape
        legs = np.arange(big + 1) <= chains.order[:, None]
        pad = np.full((n, 1), -1, dtype=np.int64)
        start_patch = np.concatenate([pad, chains.patch], axis=1)
        end_patch = np.concatenate([chains.patch, pad], axis=1)
        blocked_legs = thesis_tank.raycaster.occluded(
            chains.vertices[:, :-1][legs], chains.vertices[:, 1:][legs],
            exclude_patches=np.stack([start_patch, end_patch], axis=2)[legs])
        blocked = np.zeros((n, big + 1), dtype=bool)
        blocked[legs] = blocked_legs
        expected = np.flatnonzero(~blocked.any(axis=1))
        got = _unblocked(chains, thesis_tank)
        np.testing.assert_array_equal(got, expected)
        assert 0 < got.size < n  # some chains blocked, some not
        total += n
    assert total > 2000


def test_duplicate_keys_equal_the_numpy_key(thesis_tank: PreparedScene):
    for context in _poses(thesis_tank, 3, seed=9):
        chains = _chains(thesis_tank, context)
        rows = np.arange(0, chains.length.size, 2)
        n = rows.size
        m = min(chains.surface.shape[1], MAX_INTERACTIONS)
        ids = np.full((n, MAX_INTERACTIONS), -1, dtype=np.int64)
        ids[:, :m] = chains.surface[rows, :m]
        ids.sort(axis=1)
        points = np.zeros((n, MAX_INTERACTIONS, 3))
        points[:, :m] = chains.vertices[rows, 1:1 + m]
        points[:, :m][np.arange(m) >= chains.order[rows, None]] = 0.0
        expected = np.column_stack([chains.channel[rows], chains.order[rows], ids,
                                    np.round(points.reshape(n, -1) / 1e-9)]).astype(np.int64)
        got = duplicate_keys(rows, chains.channel, chains.order, chains.surface, chains.vertices, MAX_INTERACTIONS,
                             1e-9)
        np.testing.assert_array_equal(got, expected)
