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


def associate(lengths_m: Sequence[ArrayLike], sigma_m: Sequence[ArrayLike], geometry: ArrayGeometry,
              n_sigma: float = 4.0, min_range_m: float = 0.0, centre_side_pairs: bool = False) -> list[Association]:
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

    Returns
    -------
    list of Association
        Sorted by the first channel's path length.
    """
    ll, lc, lr = (np.asarray(v, dtype=float).reshape(-1) for v in lengths_m)
    sl, sc, sr = (np.asarray(v, dtype=float).reshape(-1) for v in sigma_m)
    used_l: set[int] = set()
    used_c: set[int] = set()
    used_r: set[int] = set()
    out: list[Association] = []
    if ll.size and lr.size:
        _associate_sides(ll, lc, lr, sl, sc, sr, geometry, n_sigma, min_range_m, (used_l, used_c, used_r), out)
    if centre_side_pairs and lc.size:
        _pair_centre(lc, sc, (ll, lr), (sl, sr), geometry, n_sigma, min_range_m, (used_l, used_c, used_r), out)

    def first_length(x: Association) -> float:
        return float(ll[x.left] if x.left is not None else lc[x.centre] if x.centre is not None else np.inf)

    out.sort(key=first_length)
    return out


def _associate_sides(ll: NDArray[np.float64], lc: NDArray[np.float64], lr: NDArray[np.float64],
                     sl: NDArray[np.float64], sc: NDArray[np.float64], sr: NDArray[np.float64],
                     geometry: ArrayGeometry, n_sigma: float, min_range_m: float,
                     used: tuple[set[int], set[int], set[int]], out: list[Association]) -> None:
    """Triples, then left/right pairs (module docstring), appended to ``out``."""
    used_l, used_c, used_r = used
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
    if lc.size:
        # The centre's noise plus the pair's (the pair's point solution carries the side noise).
        s_tot = np.hypot(sc[None, None, :], s_pair[:, :, None])  # no overflow for huge stds
        half = 0.5 * spread[:, :, None] + n_sigma * s_tot
        dev = np.abs(lc[None, None, :] - middle[:, :, None])
        with np.errstate(invalid="ignore"):
            ok = pair_ok[:, :, None] & np.isfinite(dev) & (dev <= half)
            cost = np.where(ok, dev / half, np.inf)
        order = np.argsort(cost, axis=None, kind="stable")
        for flat in order:
            i, j, k = np.unravel_index(flat, cost.shape)   # (left, right, centre)
            if not np.isfinite(cost[i, j, k]):
                break
            if i in used_l or j in used_r or k in used_c:
                continue
            used_l.add(int(i)), used_r.add(int(j)), used_c.add(int(k))
            out.append(Association(int(i), int(k), int(j), float(cost[i, j, k])))
    pair_cost = np.where(pair_ok, np.abs(a - b), np.inf)
    for flat in np.argsort(pair_cost, axis=None, kind="stable"):
        i, j = np.unravel_index(flat, pair_cost.shape)
        if not np.isfinite(pair_cost[i, j]):
            break
        if i in used_l or j in used_r:
            continue
        used_l.add(int(i)), used_r.add(int(j))
        out.append(Association(int(i), None, int(j), float("inf")))


def _pair_centre(lc: NDArray[np.float64], sc: NDArray[np.float64], sides: tuple[NDArray[np.float64], NDArray[np.float64]],
                 side_sigmas: tuple[NDArray[np.float64], NDArray[np.float64]], geometry: ArrayGeometry, n_sigma: float,
                 min_range_m: float, used: tuple[set[int], set[int], set[int]], out: list[Association]) -> None:
    """Centre echoes left over paired with one side's left over, nearest in path length first."""
    used_l, used_c, used_r = used
    direct = geometry.direct_distance_m()
    candidates = []  # (cost, side channel, side index, centre index)
    for side, (lengths, sigmas, taken) in ((0, (sides[0], side_sigmas[0], used_l)), (2, (sides[1], side_sigmas[1], used_r))):
        if not lengths.size:
            continue
        spacing = float(np.linalg.norm(geometry.receivers_m[side] - geometry.receivers_m[1]))
        difference = lengths[:, None] - lc[None, :]
        gate = spacing + n_sigma * np.hypot(sigmas[:, None], sc[None, :])
        with np.errstate(invalid="ignore"):
            ok = (np.isfinite(difference) & (np.abs(difference) <= gate) & (lengths[:, None] > direct[side])
                  & (0.5 * lc[None, :] > max(float(min_range_m), 0.0)))
        for i, k in zip(*np.nonzero(ok)):
            if int(i) not in taken and int(k) not in used_c:
                candidates.append((abs(float(difference[i, k])), side, int(i), int(k)))
    for _, side, i, k in sorted(candidates):
        taken = used_l if side == 0 else used_r
        if i in taken or k in used_c:
            continue
        taken.add(i), used_c.add(k)
        out.append(Association(i if side == 0 else None, k, i if side == 2 else None, float("inf")))
