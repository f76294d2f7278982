"""Several echoes per channel: association into targets by geometric consistency."""

import numpy as np
import pytest

from binsonar.localization.array_geometry import ArrayGeometry
from binsonar.localization.association import associate
from binsonar.localization.circle import circle_path_lengths
from binsonar.localization.estimate import target_from_path_lengths
from binsonar.localization.point import point_path_lengths

G = ArrayGeometry.seed(0.065)
SIG = 2e-4


def _ping(targets, rng, sig=SIG):
    """Path lengths per channel (sorted, like a detector's output) of point targets, with noise."""
    per = np.array([point_path_lengths(p, G)[0] for p in targets])  # (n, 3)
    per = per + sig * rng.standard_normal(per.shape)
    return [np.sort(per[:, c]) for c in range(3)], per


@pytest.mark.parametrize("seed", range(5))
def test_three_targets_separated_and_localised(seed):
    rng = np.random.default_rng(seed)
    # Three points whose ranges lie within 2 d of each other in pairs, so side-channel orderings
    # interleave and ghost left/right pairs pass the first gate; the centre channel must resolve them.
    truth = np.array([[0.35, 1.50, 0.0], [-0.40, 1.52, 0.0], [0.05, 1.56, 0.0]])
    lengths, _ = _ping(truth, rng)
    groups = associate(lengths, [np.full(3, SIG)] * 3, G)
    assert len(groups) == 3 and all(g.centre is not None for g in groups)
    found = []
    for g in groups:
        L = np.array([lengths[0][g.left], lengths[1][g.centre], lengths[2][g.right]])
        t = target_from_path_lengths(L, np.full(3, SIG), G)
        # The class is not checked: at 1.5 m the point and plane centre paths differ by
        # d^2 / (4 r) = 0.7 mm ~ 3.5 sigma, so a single ping may call a point "plane" or "ambiguous".
        point = t.fit("point")
        assert point is not None and point.ok
        found.append([*point.parameters, 0.0])
    found = np.array(sorted(found, key=lambda p: p[0]))
    expected = truth[np.argsort(truth[:, 0])]
    # Position errors: range ~ sigma, cross-range ~ sigma D / d ~ 5 mm at 1.5 m; 3 cm is > 5 sigma.
    np.testing.assert_allclose(found, expected, atol=0.03)


def test_unmatched_side_echoes_and_missing_centre():
    rng = np.random.default_rng(1)
    lengths, _ = _ping(np.array([[0.2, 1.0, 0.0], [0.0, 2.5, 0.0]]), rng)
    # Drop the far target's centre echo and add an isolated left echo with no partner within 2 d.
    lengths[1] = lengths[1][:1]
    lengths[0] = np.sort(np.append(lengths[0], 4.0))
    groups = associate(lengths, [np.full(lengths[c].size, SIG) for c in range(3)], G)
    assert len(groups) == 2
    near = [g for g in groups if g.centre is not None]
    far = [g for g in groups if g.centre is None]
    assert len(near) == 1 and len(far) == 1
    assert lengths[0][far[0].left] == pytest.approx(point_path_lengths([0.0, 2.5, 0.0], G)[0][0], abs=2e-3)


def test_cylinders_pass_the_centre_gate():
    # A convex reflector's centre path lies between the point's and the plane's: cylinders of any
    # radius must be associated.
    rng = np.random.default_rng(2)
    for rc in (0.01, 0.1, 1.0, 10.0):
        L, _ = circle_path_lengths((0.3, 1.2 + rc), rc, np.zeros((3, 3)), G.receivers_m)
        L = L + SIG * rng.standard_normal(3)
        groups = associate([L[:1], L[1:2], L[2:]], [np.full(1, SIG)] * 3, G)
        assert len(groups) == 1 and groups[0].centre == 0, rc


def test_empty_channels():
    assert associate([np.zeros(0), np.zeros(0), np.zeros(0)], [np.zeros(0)] * 3, G) == []


def test_huge_tof_stds_do_not_overflow():
    # A detector without a timing model may report stds of 1e200 m (or more): squaring them
    # overflowed (a RuntimeWarning, an error under the project's warning filter). The gate is
    # then effectively open: the one target is still grouped, with its centre echo.
    rng = np.random.default_rng(0)
    lengths, _ = _ping(np.array([[0.1, 1.2, 0.0]]), rng)
    groups = associate(lengths, [np.full(1, 1e200)] * 3, G)
    assert len(groups) == 1 and groups[0].centre is not None


def test_centre_echo_with_one_side_is_paired_only_on_request():
    # A weak target seen by the centre and right receivers only (the left near its null) next to
    # a strong one seen by all three: with centre_side_pairs the centre echo left over is paired
    # with the right echo left over (|L_right - L_centre| <= d by the triangle inequality), never
    # with an echo beyond that.
    rng = np.random.default_rng(3)
    lengths, per = _ping(np.array([[0.1, 1.3, 0.0], [0.2, 1.39, 0.0]]), rng)
    lengths[0] = np.array([per[1, 0]])          # the weak target (index 0) missing on the left
    lengths[2] = np.sort(np.append(lengths[2], 1.0))  # and an unrelated right echo far from it
    sigmas = [np.full(lengths[c].size, SIG) for c in range(3)]
    plain = associate(lengths, sigmas, G)
    assert [(g.left is None, g.centre is None, g.right is None) for g in plain] == [(False, False, False)]
    paired = associate(lengths, sigmas, G, centre_side_pairs=True)
    assert len(paired) == 2
    weak = next(g for g in paired if g.left is None)
    assert lengths[1][weak.centre] == pytest.approx(per[0, 1]) and lengths[2][weak.right] == pytest.approx(per[0, 2])
    # The pairs come after the triple they must not take echoes from, sorted by path length.
    assert [g.left is None for g in paired] == [True, False]
