"""Several echoes per channel -> groups (left, centre, right) that belong to one reflector.

Gates (geometric consistency):

1. Each side path is longer than its transmitter-receiver distance, and
   |L_left - L_right| <= |R_right - R_left| (= 2 d; triangle inequality), widened by
   ``n_sigma`` standard deviations.
2. The centre path agrees with the pair: with the left/right pair solved as a point (the seed's
   exact solution), the centre path of a point is Mc_point; a convex reflector's lies between
   that and the plane's, which is larger by about d^2 cos^2(theta) / (4 r) (second-order
   expansion of the three paths). The gate is that interval widened by ``n_sigma`` stds.

Triples are accepted greedily by increasing normalised distance to the interval's middle, each
echo used once; left/right pairs left over (no centre echo in their gate) are then accepted the
same way by increasing |L_left - L_right|. On request (``centre_side_pairs``, when a cued
search can look for the missing side: ``beam_cue``), the centre echoes left over are paired
with side echoes left over, gated by |L_side - L_centre| <= |R_side - R_centre| (the triangle
inequality), nearest first.

Ringing first-come: a body's elastic and internal echoes (a post's compressional echo through
its diameter 4 a / c_L = 42 us behind its specular echo, a pipe wall's reverberations) arrive at nearly the
specular echo's bearing, often on only some channels, and with another reflector's echo on the
remaining channel they can make a triple that fits the gate better than the body's own (whose
centre lies half the point/plane spread off the gate's middle): greedily accepted first, it
takes the body's specular echo and the body is lost. With ``trailing`` flags
(``trailing_echoes``: echoes within a ringing span after an earlier echo that is not much
weaker), each stage groups the leading echoes first and only then the trailing ones, so a
body's earliest strong arrivals are grouped together before its ringing can claim one of them.
The flags only order the search: a trailing echo that belongs to a weaker reflector of its own
is still grouped, with what is left.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from binsonar.localization.array_geometry import ArrayGeometry
from binsonar.localization.point import point_from_path_lengths


@dataclass(frozen=True)
class Association:
    """Indices of one reflector's echoes in each channel's list (None: no echo on that channel).

    Attributes
    ----------
    left, centre, right : int or None
    cost : float
        Normalised centre-path mismatch (0 at the middle of the gate; inf without a centre echo).
    """

    left: int | None
    centre: int | None
    right: int | None
    cost: float


def trailing_echoes(lengths_m: ArrayLike, strengths: ArrayLike, span_m: float,
                    margin_db: float = 6.0) -> NDArray[np.bool_]:
    """Which of one channel's echoes lie in an earlier, strong echo's ringing.

    Echo j trails when an echo i on the same channel arrives before it by at most ``span_m`` of
    path (0 < L_j - L_i <= span_m) and is at most ``margin_db`` weaker than it
    (20 log10(s_i / s_j) >= -margin_db). A body's elastic and internal echoes (a post's
    compressional echo through its diameter, a pipe wall's reverberations, a creeping wave)
    follow its specular echo on every channel at nearly the same bearing, usually weaker; the
    association tries the leading echoes first (module docstring).

    Parameters
    ----------
    lengths_m : array_like (n,)
        Path lengths of the channel's echoes (m).
    strengths : array_like (n,)
        Their amplitudes (any unit common to the channel; NaN: compared as absent).
    span_m : float
        Ringing span in path length (m); 0 marks nothing.
    margin_db : float
        How much weaker (dB) the earlier echo may be.

    Returns
    -------
    ndarray of bool (n,)
    """
    length = np.asarray(lengths_m, dtype=float).reshape(-1)
    strength = np.asarray(strengths, dtype=float).reshape(-1)
    if length.shape != strength.shape:
        raise ValueError(f"trailing_echoes: {length.size} lengths but {strength.size} strengths")
    if not span_m > 0 or length.size < 2:
        return np.zeros(length.size, dtype=bool)
    lag = length[None, :] - length[:, None]  # (earlier i, later j)
    with np.errstate(invalid="ignore"):
        strong = strength[:, None] >= strength[None, :] * 10.0 ** (-margin_db / 20.0)
        return np.any((lag > 0) & (lag <= span_m) & strong, axis=0)


def associate(lengths_m: Sequence[ArrayLike], sigma_m: Sequence[ArrayLike], geometry: ArrayGeometry,
              n_sigma: float = 4.0, min_range_m: float = 0.0, centre_side_pairs: bool = False,
              trailing: Sequence[ArrayLike] | None = None) -> list[Association]:
    """Group one ping's echoes into reflectors by geometric consistency.

    Parameters
    ----------
    lengths_m : sequence of 3 array_like, shapes (n_left,), (n_centre,), (n_right,)
        Path lengths of each channel's echoes (m).
    sigma_m : sequence of 3 array_like, same shapes
        Their standard deviations (m).
    geometry : ArrayGeometry
    n_sigma : float
        Gate width in standard deviations.
    min_range_m : float
        Pairs whose point solution lies closer to the transmitter than this (m) are not
        reflectors: the transmitter's direct cross-talk to the side receivers and the ringing
        around it.
    centre_side_pairs : bool
        Also pair the centre echoes left over with one side's (the other side None).
    trailing : sequence of 3 array_like of bool, same shapes, optional
        Echoes in an earlier strong echo's ringing (``trailing_echoes``): each stage (triples,
        pairs, centre/side pairs) first groups the other echoes, then everything left.

    Returns
    -------
    list of Association
        Sorted by the first channel's path length.
    """
    ll, lc, lr = (np.asarray(v, dtype=float).reshape(-1) for v in lengths_m)
    sl, sc, sr = (np.asarray(v, dtype=float).reshape(-1) for v in sigma_m)
    if trailing is None:
        trailing = (np.zeros(ll.size, bool), np.zeros(lc.size, bool), np.zeros(lr.size, bool))
    late = tuple(np.asarray(v, dtype=bool).reshape(-1) for v in trailing)
    if tuple(v.size for v in late) != (ll.size, lc.size, lr.size):
        raise ValueError("associate: trailing must have one flag per echo on each channel")
    # The stages' echo masks: the leading echoes first, then all (once when none trails).
    tiers = [tuple(~v for v in late), tuple(np.ones(v.size, bool) for v in late)]
    if not any(v.any() for v in late):
        tiers = tiers[1:]
    used: tuple[set[int], set[int], set[int]] = (set(), set(), set())
    out: list[Association] = []
    if ll.size and lr.size:
        triple_cost, pair_cost = _side_costs(ll, lc, lr, sl, sc, sr, geometry, n_sigma, min_range_m)
        for tier in tiers:
            _accept_triples(triple_cost, tier, used, out)
        for tier in tiers:
            _accept_pairs(pair_cost, tier, used, out)
    if centre_side_pairs and lc.size:
        candidates = _centre_side_candidates(lc, sc, (ll, lr), (sl, sr), geometry, n_sigma, min_range_m)
        for tier in tiers:
            _accept_centre_side(candidates, tier, used, out)

    def first_length(x: Association) -> float:
        return float(ll[x.left] if x.left is not None else lc[x.centre] if x.centre is not None else np.inf)

    out.sort(key=first_length)
    return out


def _side_costs(ll: NDArray[np.float64], lc: NDArray[np.float64], lr: NDArray[np.float64],
                sl: NDArray[np.float64], sc: NDArray[np.float64], sr: NDArray[np.float64],
                geometry: ArrayGeometry, n_sigma: float,
                min_range_m: float) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Costs of every triple, shape (n_left, n_right, n_centre), and of every left/right pair,
    shape (n_left, n_right) (module docstring); inf outside the gates."""
    d = geometry.half_baseline_m
    direct = geometry.direct_distance_m()
    a, b = ll[:, None], lr[None, :]
    s_pair = np.hypot(sl[:, None], sr[None, :])
    with np.errstate(invalid="ignore"):
        pair_ok = (np.isfinite(a) & np.isfinite(b) & (a > direct[0]) & (b > direct[2])
                   & (np.abs(a - b) <= geometry.max_path_difference_m + n_sigma * s_pair))
    # Point solution of each pair (nearest consistent bearing when noise pushes |sin| past 1).
    r, th = point_from_path_lengths(a, np.clip(b, a - 2 * d * (1 - 1e-12), a + 2 * d * (1 - 1e-12)), d)
    pair_ok &= np.isfinite(r) & (r > max(float(min_range_m), 0.0))
    t = geometry.transmitter_m
    pos = np.stack([t[0] + r * np.sin(th), t[1] + r * np.cos(th), np.full_like(r, t[2])], axis=-1)
    mc_point = np.linalg.norm(pos - t, axis=-1) + np.linalg.norm(pos - geometry.receivers_m[1], axis=-1)
    with np.errstate(invalid="ignore", divide="ignore"):
        spread = d * d * np.cos(th) ** 2 / (4 * r)
    middle = mc_point + 0.5 * spread
    # The centre's noise plus the pair's (the pair's point solution carries the side noise).
    s_tot = np.hypot(sc[None, None, :], s_pair[:, :, None])  # no overflow for huge stds
    half = 0.5 * spread[:, :, None] + n_sigma * s_tot
    dev = np.abs(lc[None, None, :] - middle[:, :, None])
    with np.errstate(invalid="ignore"):
        ok = pair_ok[:, :, None] & np.isfinite(dev) & (dev <= half)
        triple_cost = np.where(ok, dev / half, np.inf)
    return triple_cost, np.where(pair_ok, np.abs(a - b), np.inf)


def _accept_triples(cost: NDArray[np.float64], tier: tuple[NDArray[np.bool_], ...],
                    used: tuple[set[int], set[int], set[int]], out: list[Association]) -> None:
    """Triples of the tier's echoes accepted greedily by increasing cost, each echo used once."""
    used_l, used_c, used_r = used
    left, centre, right = tier
    cost = np.where(left[:, None, None] & right[None, :, None] & centre[None, None, :], cost, np.inf)
    for flat in np.argsort(cost, axis=None, kind="stable"):
        i, j, k = (int(v) for v in np.unravel_index(flat, cost.shape))   # (left, right, centre)
        if not np.isfinite(cost[i, j, k]):
            break
        if i in used_l or j in used_r or k in used_c:
            continue
        used_l.add(i), used_r.add(j), used_c.add(k)
        out.append(Association(i, k, j, float(cost[i, j, k])))


def _accept_pairs(cost: NDArray[np.float64], tier: tuple[NDArray[np.bool_], ...],
                  used: tuple[set[int], set[int], set[int]], out: list[Association]) -> None:
    """Left/right pairs of the tier's echoes left over, by increasing |L_left - L_right|."""
    used_l, _, used_r = used
    left, _, right = tier
    cost = np.where(left[:, None] & right[None, :], cost, np.inf)
    for flat in np.argsort(cost, axis=None, kind="stable"):
        i, j = (int(v) for v in np.unravel_index(flat, cost.shape))
        if not np.isfinite(cost[i, j]):
            break
        if i in used_l or j in used_r:
            continue
        used_l.add(i), used_r.add(j)
        out.append(Association(i, None, j, float("inf")))


def _centre_side_candidates(lc: NDArray[np.float64], sc: NDArray[np.float64],
                            sides: tuple[NDArray[np.float64], NDArray[np.float64]],
                            side_sigmas: tuple[NDArray[np.float64], NDArray[np.float64]], geometry: ArrayGeometry,
                            n_sigma: float, min_range_m: float) -> list[tuple[float, int, int, int]]:
    """Gated (|L_side - L_centre|, side channel, side index, centre index), nearest first."""
    direct = geometry.direct_distance_m()
    candidates = []
    for side, lengths, sigmas in ((0, sides[0], side_sigmas[0]), (2, sides[1], side_sigmas[1])):
        if not lengths.size:
            continue
        spacing = float(np.linalg.norm(geometry.receivers_m[side] - geometry.receivers_m[1]))
        difference = lengths[:, None] - lc[None, :]
        gate = spacing + n_sigma * np.hypot(sigmas[:, None], sc[None, :])
        with np.errstate(invalid="ignore"):
            ok = (np.isfinite(difference) & (np.abs(difference) <= gate) & (lengths[:, None] > direct[side])
                  & (0.5 * lc[None, :] > max(float(min_range_m), 0.0)))
        for i, k in zip(*np.nonzero(ok)):
            candidates.append((abs(float(difference[i, k])), side, int(i), int(k)))
    return sorted(candidates)


def _accept_centre_side(candidates: list[tuple[float, int, int, int]], tier: tuple[NDArray[np.bool_], ...],
                        used: tuple[set[int], set[int], set[int]], out: list[Association]) -> None:
    """Centre echoes left over paired with one side's left over (both in the tier), nearest first."""
    used_l, used_c, used_r = used
    for _, side, i, k in candidates:
        taken = used_l if side == 0 else used_r
        if i in taken or k in used_c or not (tier[side][i] and tier[1][k]):
            continue
        taken.add(i), used_c.add(k)
        out.append(Association(i if side == 0 else None, k, i if side == 2 else None, float("inf")))
